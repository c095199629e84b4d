"""Every node executable answers SIGINT and SIGTERM within 1 s, without a traceback: once running, during
its imports, and with a tick stuck in the physics."""

from __future__ import annotations

import signal
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from node_helpers import proc_status, start_process, stop_process
from rcl_interfaces.srv import SetParametersAtomically
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import wait_until
from std_srvs.srv import SetBool, Trigger

from micro_feeder.nodes._ros import topic_qos

NODES = ['simulator', 'actuator', 'recorder', 'feed_controller']
ANSWER_S = 1.0


def _start(name: str, tmp_path: Path, namespace: str = '/') -> object:
    extra = ('-p', f'output:={tmp_path / "log"}') if name == 'recorder' else ()
    return start_process(name, *extra, '-r', f'__ns:={namespace}')


def _answer_time(proc, sig: int) -> float:
    start = time.monotonic()
    proc.send_signal(sig)
    try:
        proc.wait(timeout=10)
    finally:
        elapsed = time.monotonic() - start
    return elapsed


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize('name', NODES)
def test_a_running_node_stops_within_a_second(ros_context: Context, tmp_path: Path, name: str, sig: int) -> None:
    # A namespace of its own: a node of this name that an earlier test's process left in the graph (a process
    # ended by os._exit is seen until its discovery lease runs out) must not pass for this one, or the signal
    # arrives while it still imports (status 130)
    namespace = f'/signals_{tmp_path.name.replace("-", "_")}'
    proc = _start(name, tmp_path, namespace)
    graph = Node('graph', context=ros_context)
    try:
        wait_until(lambda: (name, namespace) in graph.get_node_names_and_namespaces(), 120,
                   what=f'{namespace}/{name} in the graph')
        elapsed = _answer_time(proc, sig)
    finally:
        graph.destroy_node()
        code, out = stop_process(proc)
    assert elapsed <= ANSWER_S and code == 0, f'{elapsed:.2f} s, status {code}:\n{out}'
    assert 'Traceback' not in out, out


def test_sigusr1_prints_every_threads_stack_and_the_node_runs_on(ros_context: Context, tmp_path: Path) -> None:
    """What a test (node_helpers.stop_process) or a person gets from a process that does not stop: where each
    thread is, and the process keeps running until it is stopped."""
    namespace = f'/usr1_{tmp_path.name.replace("-", "_")}'
    proc = _start('recorder', tmp_path, namespace)
    graph = Node('graph', context=ros_context)
    try:
        # its ~/stop service, made last in its constructor, after the writer thread: a node is in the graph
        # from the start of its constructor, and a signal then found one thread (CI, 3 runs on 2 cores)
        stop_service = f'{namespace}/recorder/stop'
        wait_until(lambda: any(name == stop_service for name, _ in graph.get_service_names_and_types()), 120,
                   what=f'{stop_service} in the graph')
        proc.send_signal(signal.SIGUSR1)
        time.sleep(1.0)
        assert proc.poll() is None
    finally:
        graph.destroy_node()
        code, out = stop_process(proc)
    assert code == 0, out
    assert out.count('(most recent call first)') >= 2 and 'micro_feeder/nodes/recorder.py' in out, out


def _caught_signals(pid: int) -> int:
    """The mask of signals process ``pid`` has handlers for (``SigCgt`` in /proc), 0 once it has gone."""
    return int(proc_status(pid, 'SigCgt') or '0', 16)


@pytest.mark.parametrize('name', NODES)
def test_ctrl_c_during_start_up_is_quiet(tmp_path: Path, name: str) -> None:
    """Ctrl-C while the node module is still being imported (~0.8 s of rclpy, numpy, numba). It is sent once
    the launcher's handlers are in place, seen from outside as SIGTERM caught (the interpreter catches
    only SIGINT by itself). Before that the interpreter is still starting, and its own start (its site
    packages: 0.3 s was not enough under a CI run's load) answers Ctrl-C with its traceback, whatever the
    program."""
    proc = _start(name, tmp_path)
    sigterm = 1 << (signal.SIGTERM - 1)
    wait_until(lambda: _caught_signals(proc.pid) & sigterm or proc.poll() is not None, 30.0,
               what='the launcher handling SIGTERM')
    elapsed = _answer_time(proc, signal.SIGINT)
    _, out = stop_process(proc)
    assert elapsed <= ANSWER_S and 'Traceback' not in out and 'KeyboardInterrupt' not in out, out


def test_sigterm_is_answered_while_a_tick_is_stuck_in_the_physics(ros_context: Context) -> None:
    """Legal but extreme settings applied by ~/reset (10,000 piezo-driven actuators under the part,
    integrated by RK4 at the smallest dt: ~20 s for one 1 ms tick) keep a tick in the physics: services
    answer 'busy', /diagnostics says so, and SIGTERM still ends the process within a second."""
    proc = start_process('simulator')
    client = Node('client', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client)
    reports: list[DiagnosticArray] = []
    client.create_subscription(DiagnosticArray, '/diagnostics', reports.append, topic_qos('/diagnostics'))

    def call(srv_type: type, name: str, request: object) -> object:
        service = client.create_client(srv_type, name)
        wait_until(service.service_is_ready, 120, executor=executor, what=name)
        future = service.call_async(request)
        # the reset builds a 10,000-actuator model (~1 s idle, several under CI load) before it answers
        wait_until(future.done, 60, executor=executor, what=f'answer of {name}')
        return future.result()

    try:
        actuators = 10_000
        params = [Parameter(name, value=value).to_parameter_msg() for name, value in (
            ('surface.centers', [0.0] * actuators), ('surface.widths', [1e-3] * actuators),
            ('stroke.phases', [0.0] * actuators), ('piezo.enabled', True), ('integration.method', 'rk4'),
            ('integration.dt', 1e-7))]
        result = call(SetParametersAtomically, 'simulator/set_parameters_atomically',
                      SetParametersAtomically.Request(parameters=params)).result
        assert result.successful, result.reason
        assert call(Trigger, 'simulator/reset', Trigger.Request()).success
        wait_until(lambda: any(s.level == DiagnosticStatus.ERROR and 'one tick has been working' in s.message
                               for d in reports for s in d.status), 10, executor=executor,
                   what='/diagnostics reporting the stuck tick')
        answer = call(SetBool, 'simulator/pause', SetBool.Request(data=True))
        assert not answer.success and answer.message.startswith('busy'), answer.message
        elapsed = _answer_time(proc, signal.SIGTERM)
    finally:
        executor.shutdown()
        client.destroy_node()
        code, out = stop_process(proc)
    assert elapsed <= ANSWER_S and code == 0, f'{elapsed:.2f} s, status {code}:\n{out}'
    assert 'Traceback' not in out, out
