"""The actuator node in-process: start/stop services, auto_start, parameters."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from node_helpers import Probe, stamp_s
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_helpers import wait_until
from std_srvs.srv import Trigger

from micro_feeder.nodes.actuator import Actuator
from micro_feeder.nodes.simulator import Simulator
from micro_feeder.physics.trajectory import sample_table, table_range
from micro_feeder.physics.waveforms import StrokeParams, trajectory_table, waveform_table
from micro_feeder.sim.commands import parse_trajectory
from micro_feeder.sim.stream import sample_waveform


def _peak(msg) -> float:
    """Highest interpolated stroke of joint 0 (between knots too)."""
    cmd = parse_trajectory(msg, msg.joint_names, (-1.0, 1.0))
    table = trajectory_table(cmd.offsets, cmd.positions, cmd.velocities, cmd.accelerations)
    return float(table_range(table)[1][0])


def _rig(context: Context, **params: object) -> tuple[Actuator, Probe, SingleThreadedExecutor]:
    actuator = Actuator(context=context, overrides=params)
    probe = Probe(context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(actuator)
    executor.add_node(probe)
    return actuator, probe, executor


def test_start_and_stop(ros_context: Context) -> None:
    actuator, probe, ex = _rig(ros_context, auto_start=False, **{'stroke.count': 3, 'stroke.phases': [0.0, 0.25]})
    try:
        trajectories = probe.msgs['actuator/trajectory']
        response = probe.call(ex, Trigger, 'actuator/start')
        assert response.success and 'knots' in response.message
        wait_until(lambda: trajectories, 10.0, executor=ex, what='burst')
        burst = trajectories[-1]
        assert burst.joint_names == ['piezo_0', 'piezo_1']
        assert (burst.header.stamp.sec, burst.header.stamp.nanosec) == (0, 0)
        point = burst.points[len(burst.points) // 3]
        assert len(point.positions) == len(point.velocities) == len(point.accelerations) == 2
        end = burst.points[-1].time_from_start
        assert end.sec + end.nanosec * 1e-9 == pytest.approx(3.25e-3)
        assert _peak(burst) == pytest.approx(100e-6, rel=1e-9)
        assert probe.call(ex, Trigger, 'actuator/stop').success
        wait_until(lambda: len(trajectories) == 2, 10.0, executor=ex, what='stop')
        assert trajectories[-1].points == [] and trajectories[-1].joint_names == ['piezo_0', 'piezo_1']
        # stroke parameters: refused with a reason, or applied to the next start
        (result,) = actuator.set_parameters([Parameter('stroke.amplitude', value=-1e-6)])
        assert not result.successful and 'stroke.amplitude' in result.reason
        (result,) = actuator.set_parameters([Parameter('stroke.amplitude', value=50e-6)])
        assert result.successful
        probe.call(ex, Trigger, 'actuator/start')
        wait_until(lambda: len(trajectories) == 3, 10.0, executor=ex, what='second burst')
        assert _peak(trajectories[-1]) == pytest.approx(50e-6, rel=1e-9)
        assert actuator.bursts == 2 and actuator.stops == 1
    finally:
        ex.shutdown()


def test_auto_start_waits_for_the_simulator_and_sends_once(ros_context: Context) -> None:
    """Another subscriber (the probe, as a recorder or a viewer would be) is not the simulator: nothing is
    sent until a simulator is there, then the burst goes once, named, and the simulator applies it once."""
    actuator, probe, ex = _rig(ros_context)
    try:
        wait_until(lambda: actuator.trajectory_subscribers() >= 1, 10.0, executor=ex, what='probe matched')
        for _ in range(40):                                   # 0.4 s of auto-start ticks with only the probe
            ex.spin_once(timeout_sec=0.01)
        assert not probe.msgs['actuator/trajectory'] and actuator.bursts == 0
        assert 'waiting for the simulator' in actuator.state()
        sim = Simulator(context=ros_context, overrides={'start_paused': True})
        ex.add_node(sim)
        wait_until(lambda: probe.msgs['actuator/trajectory'], 10.0, executor=ex, what='auto-started burst')
        wait_until(lambda: sim.commands.received == 1, 10.0, executor=ex, what='the simulator got it')
        for _ in range(40):
            ex.spin_once(timeout_sec=0.01)
        assert actuator.bursts == 1 and len(probe.msgs['actuator/trajectory']) == 1
        assert actuator._auto is None and actuator.state() == 'idle'
        command_id = probe.msgs['actuator/trajectory'][0].header.frame_id
        assert command_id.startswith('/actuator@') and command_id.endswith(':b1')
        assert command_id in sim.stepper.applied and len(sim.stepper.applied) == 1
    finally:
        ex.shutdown()


def test_long_burst_in_bounded_memory():
    params = StrokeParams(count=1000, pause=1e-4)
    tracemalloc.start()
    try:
        times, *_ = sample_waveform(params, 1, 40)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert times[-1] == pytest.approx(params.burst_end_s(), abs=2e-9)
    assert len(times) >= 1000 * 25
    assert peak < 100e6, f'{peak / 1e6:.0f} MB'  # the grid × bounds matrix took 641 MB


def test_endless_burst_streamed_to_a_stepped_simulator_follows_the_waveform(ros_context: Context) -> None:
    """stroke.count 0: windows stamped ahead of sim time, each taking over at a shared knot; the strokes
    the simulator publishes at every step equal the analytic waveform to 1e-12 m, until ~/stop."""
    stroke = {'stroke.frequency': 1234.5, 'stroke.pause': 1e-4}
    sim = Simulator(context=ros_context, overrides={'start_paused': True, **stroke})
    actuator, probe, ex = _rig(ros_context, auto_start=False, **stroke, **{'stroke.count': 0, 'stream.lead': 0.004,
                                                                           'stream.window': 0.0015})
    ex.add_node(sim)
    try:
        probe.step(ex)
        wait_until(lambda: actuator.sim_time is not None, 10.0, executor=ex, what='sim time at the actuator')
        assert 'streamed from t = 0.005000000 s' in probe.call(ex, Trigger, 'actuator/start').message
        joints = probe.msgs['actuator/joint_states']
        for _ in range(40):
            probe.step(ex)
            wait_until(lambda: abs(actuator.sim_time - sim.stepper.t) < 1e-9, 10.0, executor=ex,
                       what='actuator at sim time')
            wait_until(lambda: actuator._stream.scheduled_until >= sim.stepper.t + 0.004 - 1e-9, 10.0, executor=ex,
                       what='windows ahead')
        params = StrokeParams(count=100, frequency=1234.5, pause=1e-4)
        t = np.array([stamp_s(m) for m in joints])
        got = np.array([m.position[0] for m in joints])
        want = sample_table(waveform_table(params, 1), t - 0.005)[0][:, 0]
        assert t[-1] == pytest.approx(0.041) and np.ptp(got) > 90e-6
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        assert actuator.windows >= 40 * 1e-3 / 0.0015 and actuator.underruns == 0
        assert all(len(m.points) <= 2000 for m in probe.msgs['actuator/trajectory'])
        probe.call(ex, Trigger, 'actuator/stop')
        assert actuator._stream is None
        wait_until(lambda: probe.msgs['actuator/trajectory'][-1].points == [], 10.0, executor=ex, what='stop')
    finally:
        ex.shutdown()
        sim.destroy_node()


def test_bursts_as_follow_joint_trajectory_goals(ros_context: Context) -> None:
    """command_interface action: each burst is one goal; the actuator learns that it ran to its end, why
    one was refused (its diagnostics say it), and a stop cancels the running goal. A streamed burst is
    refused at start, nothing sent."""
    sim = Simulator(context=ros_context, overrides={'start_paused': True})
    actuator, probe, ex = _rig(ros_context, auto_start=False, command_interface='action', **{'stroke.count': 3})
    ex.add_node(sim)
    goals = actuator.goals
    try:
        wait_until(goals.ready, 10.0, executor=ex, what='the action server')
        response = probe.call(ex, Trigger, 'actuator/start')
        assert response.success and 'FollowJointTrajectory goal' in response.message
        wait_until(lambda: goals.state == 'running', 10.0, executor=ex, what='the goal running')
        probe.step(ex, 5)                                        # 3 strokes at 1 kHz: 3.25 ms
        wait_until(lambda: goals.succeeded == 1, 10.0, executor=ex, what='the goal succeeded')
        assert actuator._command_id() in sim.stepper.applied and not probe.msgs['actuator/trajectory']

        actuator.set_parameters([Parameter('stroke.amplitude', value=900e-6)])   # beyond the piezo travel
        assert probe.call(ex, Trigger, 'actuator/start').success
        wait_until(lambda: goals.refused == 1, 10.0, executor=ex, what='the goal refused')
        assert goals.state == 'aborted' and 'piezo' in goals.last and actuator._command_id() in goals.last
        actuator._publish_diagnostics()
        # the report published after the refusal (a periodic one from before it may still arrive after it)
        reports = lambda: [s for m in probe.msgs['/diagnostics'] for s in m.status if s.name.startswith('actuator')  # noqa: E731
                           and {'goals_sent': '2', 'commands_refused': '1'}.items()
                           <= {kv.key: kv.value for kv in s.values}.items()]
        wait_until(reports, 10.0, executor=ex, what='diagnostics counting the refusal')
        assert reports()[-1].level == DiagnosticStatus.WARN

        actuator.set_parameters([Parameter('stroke.amplitude', value=50e-6), Parameter('stroke.count', value=50)])
        probe.call(ex, Trigger, 'actuator/start')
        wait_until(lambda: goals.state == 'running', 10.0, executor=ex, what='the third goal running')
        probe.step(ex, 2)
        assert probe.call(ex, Trigger, 'actuator/stop').message == 'cancel sent'
        wait_until(lambda: goals.canceled == 1, 10.0, executor=ex, what='the goal canceled')
        assert 'nothing to stop' in probe.call(ex, Trigger, 'actuator/stop').message

        actuator.set_parameters([Parameter('stroke.count', value=0)])
        response = probe.call(ex, Trigger, 'actuator/start')
        assert not response.success and 'whole bursts only' in response.message and goals.sent == 3
    finally:
        ex.shutdown()
