"""End to end: the real ``actuator`` and ``simulator`` executables as separate processes, an outside
client listening, a clean exit on SIGINT."""

from __future__ import annotations

import shutil
import signal
import subprocess
import sys
from pathlib import Path

from node_helpers import Probe, stamp_s
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from ros_helpers import wait_until
from std_srvs.srv import Trigger


def _start(name: str, *ros_args: str) -> subprocess.Popen:
    exe = shutil.which(name, path=str(Path(sys.executable).parent))
    assert exe, f'console script {name!r} not installed (pip install -e .)'
    return subprocess.Popen([exe, '--ros-args', *ros_args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


def _stop(proc: subprocess.Popen) -> tuple[int, str]:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        out, _ = proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
        return -9, out
    return proc.returncode, out


def test_actuator_and_simulator_processes(ros_context: Context) -> None:
    """Up to 120 s for the first pose: a fresh process compiles the physics kernel when numba's cache is stale."""
    sim = _start('simulator', '-p', 'stroke.count:=2', '-p', 'markers_rate:=10.0')
    act = _start('actuator', '-p', 'stroke.count:=3', '-p', 'auto_start:=false')
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
        assert 'sliding' in {m.data for m in msgs['particle/contact_state']}
        assert stamp_s(msgs['particle/pose'][-1]) > 0.0
    finally:
        executor.shutdown()
        probe.destroy_node()
        results = {name: _stop(proc) for name, proc in (('actuator', act), ('simulator', sim))}
    for name, (code, out) in results.items():
        assert code == 0, f'{name} exited with {code}:\n{out}'
        assert 'Traceback' not in out, out
