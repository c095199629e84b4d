"""End to end: the real ``actuator`` and ``simulator`` executables as separate processes, an outside
client listening, a clean exit on SIGINT."""

from __future__ import annotations

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from node_helpers import Probe, stamp_s, start_process, stop_process
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from ros_helpers import wait_until
from std_msgs.msg import String
from std_srvs.srv import Trigger

from micro_feeder.interface.names import TRANSITION_KINDS
from micro_feeder.nodes._ros import topic_qos


def _actuator_status(msgs: dict[str, list]) -> dict[str, str]:
    """The latest ``actuator: stroke`` status on /diagnostics, as a dict (empty before one)."""
    for array in reversed(msgs['/diagnostics']):
        for status in array.status:
            if status.name.endswith('actuator: stroke'):
                return {kv.key: kv.value for kv in status.values}
    return {}


def test_actuator_and_simulator_processes(ros_context: Context) -> None:
    """Up to 120 s for the first pose: a fresh process compiles the physics kernel when numba's cache is stale."""
    sim = start_process('simulator', '-p', 'stroke.count:=2', '-p', 'markers_rate:=10.0')
    act = start_process('actuator', '-p', 'stroke.count:=3', '-p', 'auto_start:=false')
    probe = Probe(context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(probe)
    try:
        msgs = probe.msgs
        wait_until(lambda: len(msgs['particle/pose']) > 50 and msgs['/clock'], 120, executor=executor,
                   what='poses and clock from the simulator process')
        x0 = msgs['particle/pose'][-1].pose.position.x
        # a burst started before the actuator's publisher matched the simulator's subscription would reach only
        # this client (discovery took seconds on a loaded machine): start once the actuator says it is reached
        wait_until(lambda: _actuator_status(msgs).get('simulator_reached') == 'True', 60, executor=executor,
                   what='the actuator reaching the simulator')
        assert probe.call(executor, Trigger, 'actuator/start', timeout=20).success
        wait_until(lambda: abs(msgs['particle/pose'][-1].pose.position.x - x0) > 1e-6, 20, executor=executor,
                   what='the part to move after actuator/start')
        wait_until(lambda: {'simulator: loop', 'actuator: stroke'} <= {s.name for d in msgs['/diagnostics']
                                                                        for s in d.status},
                   10, executor=executor, what='diagnostics of both nodes')
        wait_until(lambda: any(kv.key == 'stick_to_slip' and int(kv.value) > 0 for d in msgs['/diagnostics']
                               for st in d.status if st.name == 'simulator: loop' for kv in st.values),
                   10, executor=executor, what='a stick-to-slip transition counted on /diagnostics')
        assert stamp_s(msgs['particle/pose'][-1]) > 0.0
    finally:
        executor.shutdown()
        probe.destroy_node()
        results = {name: stop_process(proc) for name, proc in (('actuator', act), ('simulator', sim))}
    for name, (code, out) in results.items():
        assert code == 0, f'{name} exited with {code}:\n{out}'
        assert 'Traceback' not in out, out


def test_an_outside_client_sees_every_transition_of_a_50_slide_run(ros_context: Context) -> None:
    """50 strokes of the default scenario slide the part 50 times, each slide shorter than a tick: a client
    in this process, with the QoS of docs/interface.md, gets every contact-state change in order and every
    stamped transition, as many as /diagnostics counts."""
    sim = start_process('simulator', '-p', 'markers_rate:=1.0')
    act = start_process('actuator', '-p', 'stroke.count:=50', '-p', 'auto_start:=false')
    client = Node('transition_client', context=ros_context)
    got: dict[str, list] = {'particle/contact_state': [], 'particle/transitions': [], '/diagnostics': []}
    for topic, msg_type in (('particle/contact_state', String), ('particle/transitions', DiagnosticArray),
                            ('/diagnostics', DiagnosticArray)):
        client.create_subscription(msg_type, topic, got[topic].append, topic_qos(topic))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(client)
    missed = ''
    try:
        wait_until(lambda: client.count_publishers('particle/transitions') and got['particle/contact_state'], 120,
                   executor=executor, what='the simulator process to publish')
        start = client.create_client(Trigger, 'actuator/start')
        wait_until(start.service_is_ready, 30, executor=executor, what='actuator/start')
        wait_until(lambda: _actuator_status(got).get('simulator_reached') == 'True', 60, executor=executor,
                   what='the actuator reaching the simulator')     # else the burst reaches only this client
        future = start.call_async(Trigger.Request())
        wait_until(future.done, 10, executor=executor, what='burst sent')

        def counters() -> dict[str, int]:
            loops = [st for d in got['/diagnostics'] for st in d.status if st.name == 'simulator: loop']
            return {kv.key: int(kv.value) for kv in loops[-1].values if kv.key in TRANSITION_KINDS} if loops else {}

        try:
            wait_until(lambda: counters().get('slip_to_stick', 0) >= 50, 30, executor=executor,
                       what='50 slides counted on /diagnostics')
            expected = counters()
            wait_until(lambda: len(got['particle/transitions']) >= sum(expected.values()), 10, executor=executor,
                       what='every transition message')
        except AssertionError as err:     # what the processes said, to tell a starved run from a lost message
            missed = (f'{err}: counters {counters()}, {len(got["particle/contact_state"])} contact states, '
                      f'{len(got["particle/transitions"])} transitions received')
    finally:
        executor.shutdown()
        client.destroy_node()
        results = {name: stop_process(proc) for name, proc in (('actuator', act), ('simulator', sim))}
    assert not missed, missed + ''.join(f'\n--- {name} (exit {code}):\n{out[-3000:]}'
                                        for name, (code, out) in results.items())
    assert expected == {'stick_to_slip': 50, 'slip_to_stick': 50, 'take_off': 0, 'landing': 0}
    states = [m.data for m in got['particle/contact_state']]
    assert states == ['stuck'] + ['sliding', 'stuck'] * 50
    events = [m.status[0] for m in got['particle/transitions']]
    assert [e.message for e in events] == ['stick_to_slip', 'slip_to_stick'] * 50
    times = [float(next(kv.value for kv in e.values if kv.key == 't_s')) for e in events]
    assert times == sorted(times) and len(set(times)) == 100
    stamps = [stamp_s(m) for m in got['particle/transitions']]
    assert stamps == pytest.approx(times, abs=1e-9)
    for name, (code, out) in results.items():
        assert code == 0, f'{name} exited with {code}:\n{out}'


@pytest.mark.parametrize(('args', 'expected'), [
    (('-p', 'contact.sigmaa:=1e-8'), "unknown parameter; did you mean contact.sigma"),
    (('-p', 'surface.centers:=[0,0.002]'), 'every value of a list must have one type'),
    (('-p', 'publish_rate:=-5.0'), 'publish_rate'),
])
def test_start_up_mistakes_are_one_clear_line(args: tuple[str, ...], expected: str) -> None:
    proc = start_process('simulator', *args)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 2, out
    assert expected in out and 'Traceback' not in out, out
