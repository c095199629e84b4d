"""Issue 30 item 5: no hang on shutdown, whatever is on the graph: ``micro-feeder run`` processes side by side
(two namespaces, or one namespace where the newer is refused) end within seconds of Ctrl-C, quietly, at
any moment of their life.

Real processes and real rclpy. The scenario tests are bounded: every wait has a deadline, and a process
that outlives its deadline is killed and reported.
"""

from __future__ import annotations

import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from rclpy.context import Context
from rclpy.node import Node
from ros_helpers import wait_until

BIN = Path(sys.executable).parent
ANSWER_S = 5.0          # s from SIGINT to the process gone: typically 0.06-0.13 s; one clean-clone CI run (two
                        # feeders at 1 kHz on 2 cores) took 3.20 s once, cause not found; a hang runs to the 20-s kill
UP_TIMEOUT = 60.0       # s for both feeders to be running (imports and node builds under load)


def _feeder(namespace: str, tmp_path: Path, *extra: str) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / 'micro-feeder'), 'run', '--namespace', namespace, *extra],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)


def _importing(pid: int) -> bool:
    """Has the command begun importing its libraries (numpy's extension mapped)? Its Ctrl-C handling is in
    place before that (cli.main installs it, then imports the commands). Before it the interpreter itself is
    starting (its site packages: 0.3 s after the start was not enough under a CI run's load) and answers
    Ctrl-C with its own traceback, whatever the program."""
    try:
        return '_multiarray_umath' in Path(f'/proc/{pid}/maps').read_text()
    except OSError:
        return False


def _running(graph: Node, namespaces: list[str]) -> bool:
    names = set(graph.get_node_names_and_namespaces())
    return all(('actuator', f'/{ns}') in names for ns in namespaces)


def _interrupt_all(procs: list[subprocess.Popen]) -> list[tuple[int | None, float, str]]:
    """SIGINT every process at once; (status or None when it had to be killed, seconds, stderr) each."""
    started = time.monotonic()
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
    results = []
    for proc in procs:
        try:
            proc.wait(timeout=max(0.0, started + 20.0 - time.monotonic()))
            status = proc.returncode
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            status = None
        elapsed = time.monotonic() - started
        _, err = proc.communicate()
        results.append((status, elapsed, err))
    return results


@pytest.mark.faults
@pytest.mark.parametrize('layout', ['two namespaces', 'one namespace'])
def test_two_feeders_end_within_seconds_of_ctrl_c(ros_context: Context, tmp_path: Path, layout: str) -> None:
    """Two ``micro-feeder run`` side by side (in one namespace the newer is refused, or stops once it sees
    the older: either way it must end promptly), interrupted at a random moment of their run, three
    times: every process ends within :data:`ANSWER_S` of its SIGINT, without a traceback."""
    namespaces = ['feeder_a', 'feeder_b'] if layout == 'two namespaces' else ['feeder', 'feeder']
    graph = Node('graph', context=ros_context)
    rng = random.Random(30)
    failures = []
    try:
        for trial in range(3):
            procs = [_feeder(ns, tmp_path) for ns in namespaces]
            try:
                wait_until(lambda ps=procs: _running(graph, sorted(set(namespaces)))
                           or all(p.poll() is not None for p in ps), UP_TIMEOUT, what='the feeders running')
                time.sleep(rng.uniform(0.2, 2.0))
            finally:
                results = _interrupt_all(procs)
            for k, (status, elapsed, err) in enumerate(results):
                if status is None or elapsed > ANSWER_S or 'Traceback' in err:
                    failures.append(f'trial {trial} process {k}: status {status}, {elapsed:.2f} s\n{err[-2000:]}')
                elif status not in (0, 1, 2, 130):
                    failures.append(f'trial {trial} process {k}: status {status}\n{err[-2000:]}')
    finally:
        graph.destroy_node()
    assert not failures, '\n'.join(failures)


@pytest.mark.faults
def test_ctrl_c_while_a_feeder_starts_is_quiet(tmp_path: Path) -> None:
    """SIGINT during the imports (at once, and 0.5 s after numpy's began), the node builds or the wait for
    the actuator: status 130 (or 0 when the run had begun), ``interrupted``, no traceback, within
    :data:`ANSWER_S`."""
    failures = []
    for delay in (0.0, 0.5, 1.2, 2.2, 3.7):
        proc = _feeder(f'start_{int(delay * 10)}', tmp_path)
        wait_until(lambda p=proc: _importing(p.pid) or p.poll() is not None, UP_TIMEOUT,
                   what='the command importing numpy')
        time.sleep(delay)
        ((status, elapsed, err),) = _interrupt_all([proc])
        if status not in (0, 130) or elapsed > ANSWER_S or 'Traceback' in err:
            failures.append(f'SIGINT after {delay} s: status {status}, {elapsed:.2f} s\n{err[-2000:]}')
    assert not failures, '\n'.join(failures)
