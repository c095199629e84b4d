"""End to end: the real ``actuator`` and ``simulator`` executables as separate processes, an outside
client listening, a clean exit on SIGINT."""

from __future__ import annotations

from node_helpers import Probe, stamp_s, start_process, stop_process
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from ros_helpers import wait_until
from std_srvs.srv import Trigger


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
        assert probe.call(executor, Trigger, 'actuator/start', timeout=20).success
        wait_until(lambda: abs(msgs['particle/pose'][-1].pose.position.x - x0) > 1e-6, 20, executor=executor,
                   what='the part to move after actuator/start')
        wait_until(lambda: {'simulator: loop', 'actuator: stroke'} <= {s.name for d in msgs['/diagnostics']
                                                                        for s in d.status},
                   10, executor=executor, what='diagnostics of both nodes')
        # contact_state keeps only the latest mode (depth 1): a stuck-sliding-stuck within a millisecond may
        # reach another process as 'stuck' only, so the slip is checked on the simulator's counters
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
