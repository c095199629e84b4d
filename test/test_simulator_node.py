"""The simulator node in-process: real rclpy, an isolated Context per test, real topics, bounded waits."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Duration
from node_helpers import Probe, stamp_s
from rcl_interfaces.msg import ParameterType
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy
from ros_helpers import wait_until
from std_msgs.msg import Float64MultiArray, Header, String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker

from micro_feeder.interface.stamps import to_time
from micro_feeder.logs.reader import LogReader
from micro_feeder.nodes._ros import SERVICE_QOS
from micro_feeder.nodes.recorder import Recorder
from micro_feeder.nodes.simulator import Simulator, topic_qos
from micro_feeder.physics.surface import surface_profile
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.sim.commands import parse_trajectory
from micro_feeder.sim.resim import resimulate
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import sample_waveform

STEP = 1e-3


class Rig:
    """A simulator, a probe and one executor spun on the test thread."""

    def __init__(self, context: Context, **params: object):
        self.sim = Simulator(context=context, overrides=params)
        self.probe = Probe(context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.sim)
        self.executor.add_node(self.probe)

    def wait(self, predicate, what: str, timeout: float = 10.0) -> None:
        wait_until(predicate, timeout, executor=self.executor, what=what)

    def send_trajectory(self, msg: JointTrajectory) -> None:
        applied = self.command_taken()
        self.probe.publish('actuator/trajectory', msg, self.executor)
        self.wait(applied, 'trajectory applied or rejected')

    def command_taken(self) -> Callable[[], bool]:
        """Whether a command was applied (a new table at the schedule's end, or a new schedule) or refused
        since this call (the objects are held, so a new one cannot reuse an old one's id)."""
        schedule, rejected = self.sim.stepper.schedule, self.sim.rejected
        last = schedule.pieces[-1][1]
        return lambda: (self.sim.stepper.schedule is not schedule or self.sim.rejected != rejected
                        or self.sim.stepper.schedule.pieces[-1][1] is not last)

    def step(self, n: int = 1) -> None:
        self.probe.step(self.executor, n)

    def close(self) -> None:
        self.executor.shutdown()
        self.probe.destroy_node()
        self.sim.destroy_node()


@pytest.fixture
def stepped(ros_context: Context) -> Iterator[Rig]:
    rig = Rig(ros_context, start_paused=True, step_period=STEP)
    yield rig
    rig.close()


@pytest.fixture
def running(ros_context: Context) -> Iterator[Rig]:
    rig = Rig(ros_context)
    yield rig
    rig.close()


def burst_message(stamp: float, params: StrokeParams | None = None) -> JointTrajectory:
    """The actuator's default burst as a trajectory stamped at ``stamp`` (s, sim time)."""
    times, pos, vel, acc = sample_waveform(params or StrokeParams(), 1, 40)
    points = [JointTrajectoryPoint(positions=[float(pos[i, 0])], velocities=[float(vel[i, 0])],
                                   accelerations=[float(acc[i, 0])],
                                   time_from_start=Duration(sec=0, nanosec=round(t * 1e9)))
              for i, t in enumerate(times)]
    return JointTrajectory(header=_header(stamp), joint_names=['piezo_0'], points=points)


def hold_message(stamp: float, offsets: list[float], positions: list[float]) -> JointTrajectory:
    """Position-only knots (linear interpolation) stamped at ``stamp``."""
    points = [JointTrajectoryPoint(positions=[p], time_from_start=Duration(sec=0, nanosec=round(t * 1e9)))
              for t, p in zip(offsets, positions, strict=True)]
    return JointTrajectory(header=_header(stamp), joint_names=['piezo_0'], points=points)


def _header(stamp: float) -> Header:
    return Header(stamp=to_time(stamp))


def offline(commands: list[tuple[int, JointTrajectory]], n_steps: int) -> Stepper:
    """What the node should compute: the same stepper fed the same commands before the given steps."""
    stepper = Stepper(build_model({}))
    for i in range(n_steps + 1):
        for at, msg in commands:
            if at == i:
                stepper.command_trajectory(parse_trajectory(msg, ['piezo_0'], stepper.limits))
        if i < n_steps:
            stepper.advance(stepper.t + STEP)
    return stepper


def test_every_topic_with_its_type_frame_and_qos(running: Rig) -> None:
    probe = running.probe
    wanted = ['particle/pose', 'particle/twist', 'particle/contact_wrench', 'actuator/joint_states',
              'particle/contact_state', 'surface/markers', '/clock', '/diagnostics']
    running.wait(lambda: all(probe.msgs[t] for t in wanted), 'a message on every topic')
    assert probe.msgs['particle/pose'][-1].header.frame_id == 'feeder'
    assert probe.msgs['particle/twist'][-1].header.frame_id == 'feeder'
    assert probe.msgs['particle/contact_wrench'][-1].header.frame_id == 'contact'
    assert probe.msgs['actuator/joint_states'][-1].name == ['piezo_0']
    assert probe.msgs['particle/contact_state'][0].data == 'stuck'
    markers = probe.msgs['surface/markers'][-1].markers
    assert [m.header.frame_id for m in markers] == ['feeder', 'feeder'] and len(markers[0].points) > 10
    status = probe.msgs['/diagnostics'][-1].status[0]
    keys = {kv.key for kv in status.values}
    assert {'real_time_factor_achieved', 'overruns', 'rejected_commands', 'stick_to_slip', 'take_off'} <= keys
    pose = probe.msgs['particle/pose'][-1].pose
    assert pose.position.x == pytest.approx(0.5e-3) and pose.position.y == 0.0
    expected = {'particle/pose': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, 100),
                'particle/contact_state': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.TRANSIENT_LOCAL, 1000),
                'particle/transitions': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, 1000),
                'surface/markers': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, 1),
                '/clock': (ReliabilityPolicy.BEST_EFFORT, DurabilityPolicy.VOLATILE, 1),
                'actuator/joint_states': (ReliabilityPolicy.RELIABLE, DurabilityPolicy.VOLATILE, 100)}
    for topic, (reliability, durability, depth) in expected.items():
        (info,) = [i for i in probe.get_publishers_info_by_topic(topic) if i.node_name == 'simulator']
        assert (info.qos_profile.reliability, info.qos_profile.durability) == (reliability, durability), topic
        (publisher,) = [p for p in running.sim.publishers if p.topic_name == '/' + topic.lstrip('/')]
        assert publisher.qos_profile.depth == depth, topic      # the depth is not visible in the graph
    # a late subscriber still gets the latched contact state
    late: list[String] = []
    probe.create_subscription(String, 'particle/contact_state', late.append, topic_qos('particle/contact_state'))
    running.wait(lambda: late, 'latched contact state')
    assert late[0].data in ('stuck', 'sliding', 'flying')
    # sim time runs at about real time
    running.wait(lambda: running.sim.stepper.t > 0.3, 'sim time to pass 0.3 s')


def test_clock_matches_header_stamps_and_steps(stepped: Rig) -> None:
    probe = stepped.probe
    stepped.step(5)
    poses = probe.msgs['particle/pose'][-5:]
    stepped.wait(lambda: len(probe.msgs['/clock']) >= 5, 'clock')
    clocks = [stamp_s(c) for c in probe.msgs['/clock'][-5:]]
    assert [stamp_s(p) for p in poses] == pytest.approx([0.001, 0.002, 0.003, 0.004, 0.005], abs=1e-12)
    assert clocks == [stamp_s(p) for p in poses]
    for topic in ('particle/twist', 'particle/contact_wrench', 'actuator/joint_states'):
        assert stamp_s(probe.msgs[topic][-1]) == clocks[-1], topic


def test_trajectory_moves_the_part_as_the_offline_simulation(stepped: Rig) -> None:
    msg = burst_message(stamp=0.002)
    stepped.wait(lambda: stepped.probe.msgs['particle/contact_state'], 'latched initial contact state')
    stepped.step(1)
    stepped.send_trajectory(msg)
    stepped.step(9)
    assert stepped.sim.rejected == 0
    pose = stepped.probe.msgs['particle/pose'][-1]
    predicted = offline([(1, msg)], 10)
    assert abs(pose.pose.position.x - predicted.state.x) <= 1e-9
    assert predicted.state.distance < -1e-6               # the burst moved it (toward the bump's centre)
    # the same knots, integrated in one go rather than in 1 ms ticks
    one_go = Stepper(build_model({}))
    one_go.command_trajectory(parse_trajectory(msg, ['piezo_0'], one_go.limits))
    one_go.advance(0.010)
    assert abs(pose.pose.position.x - one_go.state.x) <= 1e-9
    # transitions were counted, and the contact state followed them
    assert predicted.state.transitions['stick_to_slip'] >= 1
    modes = [m.data for m in stepped.probe.msgs['particle/contact_state']]
    assert modes[0] == 'stuck' and 'sliding' in modes, modes


def test_replacement_and_stop(stepped: Rig) -> None:
    joints = stepped.probe.msgs['actuator/joint_states']
    # ramp to 40 um over 10 ms from t = 1 ms; replaced at 4 ms by a ramp to 0 at 6 ms; stop at 5 ms
    stepped.send_trajectory(hold_message(0.001, [0.0, 0.010], [0.0, 40e-6]))
    stepped.send_trajectory(hold_message(0.004, [0.002], [0.0]))
    stepped.step(4)
    assert joints[-1].position[0] == pytest.approx(12e-6, rel=1e-9)       # 3 ms of the first ramp
    stepped.step(1)                                                        # 5 ms: half-way back to 0
    assert joints[-1].position[0] == pytest.approx(6e-6, rel=1e-9)
    stepped.send_trajectory(JointTrajectory(header=_header(0.0)))          # empty: stop on receipt
    stepped.step(3)
    assert [j.position[0] for j in joints[-3:]] == pytest.approx([6e-6] * 3, rel=1e-9)
    assert joints[-1].velocity[0] == 0.0
    assert stepped.sim.rejected == 0


def test_a_trajectory_stamped_in_the_past_is_counted_late_and_never_joined_with_a_jump(stepped: Rig) -> None:
    """Stamped 1 ms before the sim time it arrives at: counted on /diagnostics as late, not silently. Where
    the stroke in force is where the trajectory itself is now (here both at rest) it applies from now, its
    earlier knots dropped; where joining it mid-way would jump the stroke (4 µm and 4 mm/s here: the surface would be
    thrown), it is refused with that reason."""
    stepped.step(3)
    stepped.send_trajectory(hold_message(0.002, [0.0, 0.010], [0.0, 0.0]))       # at rest as the stroke is
    assert stepped.sim.commands.late == 1 and stepped.sim.rejected == 0
    assert dict((v.key, v.value) for v in stepped.sim.diagnostics().values)['commands_late'] == '1'
    stepped.send_trajectory(hold_message(0.002, [0.0, 0.010], [0.0, 40e-6]))     # 4 µm up by now: a jump
    assert stepped.sim.commands.late == 2 and stepped.sim.rejected == 1
    assert 'would jump joint 0 by 4 µm' in stepped.sim.last_rejection, stepped.sim.last_rejection
    stepped.send_trajectory(hold_message(0.004, [0.0, 0.010], [0.0, 40e-6]))     # in the future: on time
    assert stepped.sim.commands.late == 2 and stepped.sim.rejected == 1


def _bad_trajectories() -> dict[str, JointTrajectory]:
    good = hold_message(0.0, [0.001, 0.002], [10e-6, 20e-6])
    unknown = hold_message(0.0, [0.001], [10e-6])
    unknown.joint_names = ['piezo_7']
    order = hold_message(0.0, [0.002, 0.001], [10e-6, 20e-6])
    nan = hold_message(0.0, [0.001, 0.002], [10e-6, math.nan])
    far = hold_message(0.0, [0.001], [1e-3])
    length = hold_message(0.0, [0.001], [10e-6])
    length.points[0].positions = [10e-6, 1e-6]
    velocities = hold_message(0.0, [0.001, 0.002], [10e-6, 20e-6])
    velocities.points[0].velocities = [0.0]
    return {'good': good, 'unknown joint': unknown, 'time order': order, 'non-finite': nan,
            'outside limits': far, 'array length': length, 'velocities on some points': velocities}


def test_bad_commands_are_rejected_counted_and_change_nothing(stepped: Rig) -> None:
    msg = burst_message(stamp=0.001)
    stepped.send_trajectory(msg)
    stepped.step(1)
    bad = _bad_trajectories()
    del bad['good']
    for name, cmd in bad.items():
        before = stepped.sim.rejected
        stepped.send_trajectory(cmd)
        assert stepped.sim.rejected == before + 1, name
    for data in ([1e-6, 2e-6], [math.inf], [5e-3]):      # wrong length, non-finite, outside the limits
        before = stepped.sim.rejected
        stepped.probe.publish('actuator/command', Float64MultiArray(data=data), stepped.executor)
        stepped.wait(lambda b=before: stepped.sim.rejected == b + 1, f'command {data} rejected')
    assert stepped.sim.rejected == len(bad) + 3
    assert 'piezo limits' in stepped.sim.last_rejection
    stepped.step(7)
    predicted = offline([(0, msg)], 8)
    assert stepped.probe.msgs['particle/pose'][-1].pose.position.x == predicted.state.x     # unaffected
    assert predicted.state.distance < -1e-6                                                # and it moved
    diag = stepped.sim.diagnostics()
    assert {kv.key: kv.value for kv in diag.values}['rejected_commands'] == str(len(bad) + 3)


def test_setpoints_through_the_piezo_model(ros_context: Context) -> None:
    rig = Rig(ros_context, start_paused=True, step_period=STEP, **{'piezo.enabled': True})
    try:
        applied = rig.command_taken()
        rig.probe.publish('actuator/command', Float64MultiArray(data=[30e-6]), rig.executor)
        rig.wait(applied, 'set-point applied')
        rig.step(3)
        positions = [j.position[0] for j in rig.probe.msgs['actuator/joint_states'][-3:]]
        assert positions[-1] == pytest.approx(30e-6, rel=1e-3)      # a 50 kHz stack settles within 1 ms
        assert rig.sim.rejected == 0
    finally:
        rig.close()


def test_pause_step_reset(stepped: Rig) -> None:
    probe, ex = stepped.probe, stepped.executor
    probe.pause(ex, False)
    response = probe.call(ex, Trigger, 'simulator/step')
    assert not response.success and 'paused' in response.message
    stepped.wait(lambda: stepped.sim.stepper.t > 0.05, 'sim time running')
    assert probe.pause(ex, True).success
    t_paused = stepped.sim.stepper.t
    stepped.step(2)
    assert stepped.sim.stepper.t == t_paused + STEP + STEP
    assert probe.call(ex, Trigger, 'simulator/reset').success
    assert stepped.sim.stepper.t == 0.0
    stepped.wait(lambda: stamp_s(probe.msgs['particle/pose'][-1]) == 0.0, 'pose after reset')


def test_parameters_refused_with_a_reason_and_applied_on_reset(stepped: Rig) -> None:
    sim = stepped.sim
    refused = {
        'stroke.frequency': Parameter('stroke.frequency', value=-5.0),
        'integration.dt': Parameter('integration.dt', value=0.0),                 # strict bound: > 0
        'stroke.waveform': Parameter('stroke.waveform', value='square'),
        'surface.widths': Parameter('surface.widths', value=[1e-3, 1e-3]),         # one per centre
        'real_time_factor': Parameter('real_time_factor', value=-1.0),
        'publish_rate': Parameter('publish_rate', value=10.0),                      # read-only
    }
    for name, param in refused.items():
        (result,) = sim.set_parameters([param])
        assert not result.successful and result.reason, name
    assert sim.get_parameter('stroke.frequency').value == 1000.0
    (descriptor,) = sim.describe_parameters(['stroke.frequency'])
    assert descriptor.type == ParameterType.PARAMETER_DOUBLE and descriptor.floating_point_range
    assert 'Hz' in descriptor.description
    # related parameters together, atomically; model parameters apply on reset
    result = sim.set_parameters_atomically([Parameter('surface.centers', value=[0.0, 2e-3]),
                                            Parameter('surface.widths', value=[1e-3, 1e-3]),
                                            Parameter('stroke.phases', value=[0.0, 0.25]),
                                            Parameter('particle.x0', value=1e-3)])
    assert result.successful, result.reason
    assert sim.stepper.model.n_actuators == 1
    assert stepped.probe.call(stepped.executor, Trigger, 'simulator/reset').success
    assert sim.stepper.model.n_actuators == 2 and sim.joints == ['piezo_0', 'piezo_1']
    stepped.wait(lambda: stepped.probe.msgs['particle/pose'][-1].pose.position.x == 1e-3, 'pose at the new x0')
    (result,) = sim.set_parameters([Parameter('real_time_factor', value=0.0)])     # applies at once
    assert result.successful


def _check_markers(rig: Rig, joints: list[str], min_distinct: int) -> None:
    """Every ``surface/markers`` received so far matches the state published with the same stamp: the
    LINE_STRIP is the surface profile over the actuators +- 4 widths at the strokes of that stamp's
    ``actuator/joint_states``, the sphere sits on that stamp's pose; ``min_distinct`` stroke sets seen."""
    msgs = rig.probe.msgs
    surface = rig.sim.stepper.model.surface
    c, w = np.asarray(surface.centers), np.asarray(surface.widths)
    xs = np.linspace(float(np.min(c - 4 * w)), float(np.max(c + 4 * w)), 200)
    strokes = {(j.header.stamp.sec, j.header.stamp.nanosec): list(j.position) for j in msgs['actuator/joint_states']}
    poses = {(p.header.stamp.sec, p.header.stamp.nanosec): p.pose.position for p in msgs['particle/pose']}
    seen = set()
    for array in msgs['surface/markers']:
        line, part = array.markers
        key = (line.header.stamp.sec, line.header.stamp.nanosec)
        assert key == (part.header.stamp.sec, part.header.stamp.nanosec) and key in strokes, key
        assert (line.header.frame_id, part.header.frame_id, line.ns, part.ns) == ('feeder',) * 2 + ('micro_feeder',) * 2
        assert (line.id, line.type, line.action, part.id, part.type, part.action) == (
            0, Marker.LINE_STRIP, Marker.ADD, 1, Marker.SPHERE, Marker.ADD)
        assert [p.x for p in line.points] == xs.tolist() and {p.y for p in line.points} == {0.0}
        assert [p.z for p in line.points] == surface_profile(xs, np.array(strokes[key]), c, w).tolist(), key
        assert line.scale.x == 10e-6 and line.pose.orientation.w == 1.0
        assert (line.color.r, line.color.g, line.color.b, line.color.a) == pytest.approx((0.6, 0.6, 0.7, 1.0))
        assert (part.pose.position.x, part.pose.position.y, part.pose.position.z) == (
            poses[key].x, 0.0, poses[key].z + 50e-6)
        assert (part.scale.x, part.scale.y, part.scale.z, part.pose.orientation.w) == (100e-6, 100e-6, 100e-6, 1.0)
        assert (part.color.r, part.color.g, part.color.b, part.color.a) == pytest.approx((0.2, 0.7, 0.2, 1.0))
        assert len(strokes[key]) == len(joints)
        seen.add(tuple(strokes[key]))
    assert len(seen) >= min_distinct, seen


def test_markers_follow_the_surface_profile_and_the_part(ros_context: Context) -> None:
    """surface/markers at every step (markers_rate at its maximum, a step at least 1 ms of wall time apart):
    content against the profile at each stamp's strokes, before and after a reset to two actuators."""
    rig = Rig(ros_context, start_paused=True, step_period=STEP, markers_rate=1000.0)
    try:
        rig.send_trajectory(hold_message(0.0, [0.003], [6e-6]))      # 2, 4, 6 um at 1, 2, 3 ms: part stays stuck
        for _ in range(3):
            time.sleep(0.0015)
            rig.step(1)
        rig.wait(lambda: len(rig.probe.msgs['surface/markers']) >= 3, 'a marker per step')
        _check_markers(rig, ['piezo_0'], 3)
        result = rig.sim.set_parameters_atomically([Parameter('surface.centers', value=[0.0, 2e-3]),
                                                    Parameter('surface.widths', value=[1e-3, 0.5e-3]),
                                                    Parameter('stroke.phases', value=[0.0, 0.25])])
        assert result.successful, result.reason
        assert rig.probe.call(rig.executor, Trigger, 'simulator/reset').success
        rig.probe.msgs['surface/markers'].clear()
        msg = hold_message(0.0, [0.002], [4e-6])
        msg.joint_names = ['piezo_0', 'piezo_1']
        msg.points[0].positions = [4e-6, -3e-6]
        rig.send_trajectory(msg)
        for _ in range(2):
            time.sleep(0.0015)
            rig.step(1)
        rig.wait(lambda: len(rig.probe.msgs['surface/markers']) >= 2, 'a marker per step after the reset')
        _check_markers(rig, ['piezo_0', 'piezo_1'], 2)
        assert rig.sim.rejected == 0
    finally:
        rig.close()


def _stepped_run(context: Context) -> list[tuple]:
    rig = Rig(context, start_paused=True, step_period=STEP)
    try:
        rig.send_trajectory(burst_message(stamp=0.002, params=StrokeParams(count=3, amplitude=80e-6)))
        rig.step(3)
        rig.send_trajectory(hold_message(0.0045, [0.001], [20e-6]))      # replaces the burst mid-way
        rig.step(5)
        msgs = rig.probe.msgs
        return [(p.header.stamp.sec, p.header.stamp.nanosec, p.pose.position.x, p.pose.position.z,
                 p.pose.orientation.y, t.twist.linear.x, w.wrench.force.x, w.wrench.force.z)
                for p, t, w in zip(msgs['particle/pose'], msgs['particle/twist'], msgs['particle/contact_wrench'],
                                   strict=True)]
    finally:
        rig.close()


def test_stepped_runs_are_bit_identical() -> None:
    runs = []
    for _ in range(2):
        context = Context()
        rclpy.init(context=context)
        try:
            runs.append(_stepped_run(context))
        finally:
            rclpy.shutdown(context=context)
    assert len(runs[0]) == 8
    assert runs[0] == runs[1]
    assert len({row[2] for row in runs[0]}) > 1          # the part moved


@pytest.mark.parametrize('rtf', [0.0, 1.0])
def test_stop_at_ends_exactly_at_the_requested_sim_time(ros_context: Context, rtf: float) -> None:
    rig = Rig(ros_context, real_time_factor=rtf, start_paused=True)   # as fast as possible passes 0.05 s in
    try:                                                                # ~10 ms: set the end before it runs
        end = rig.sim.stop_at(0.05)
        assert rig.probe.pause(rig.executor, False).success
        rig.wait(end.done, 'stop_at future completed')
        time.sleep(0.05)     # the loop thread keeps ticking: sim time must stay at the end
        assert end.result() == rig.sim.stepper.t == 0.05
        assert rig.sim.paused
    finally:
        rig.close()


def test_stop_at_bounds_lockstep_grants(ros_context: Context) -> None:
    rig = Rig(ros_context, lockstep=True, step_period=STEP)
    try:
        end = rig.sim.stop_at(2.5 * STEP)
        for _ in range(5):
            rig.sim.grant_step()
        assert end.done() and rig.sim.stepper.t == end.result() == 2.5 * STEP
        ok, message = rig.sim.grant_step()
        assert not ok and 'stopped' in message and rig.sim.stepper.t == 2.5 * STEP
    finally:
        rig.close()


def test_joint_velocities_are_the_schedule_rate(stepped: Rig) -> None:
    msg = hold_message(0.0015, [0.0, 0.0025, 0.006], [0.0, 10e-6, 0.0])     # ramps up then down, off the grid
    stepped.send_trajectory(msg)
    stepped.step(8)
    schedule = stepped.sim.stepper.schedule
    joints = stepped.probe.msgs['actuator/joint_states'][-8:]
    rates = [schedule.evaluate(stamp_s(j))[1][0] for j in joints]
    assert [j.velocity[0] for j in joints] == rates
    assert any(r > 0.0 for r in rates) and any(r < 0.0 for r in rates)
    obs = stepped.sim.stepper.observe()
    assert obs.stroke_velocities.tolist() == schedule.evaluate(stepped.sim.stepper.t)[1].tolist()


def test_observed_stroke_velocities_with_the_piezo_model() -> None:
    stepper = Stepper(build_model({'piezo.enabled': True}))
    stepper.command_setpoints(np.array([30e-6]))
    stepper.advance(2e-5)
    obs = stepper.observe()
    assert obs.stroke_velocities.shape == (1,) and obs.stroke_velocities[0] == stepper.state.piezo_velocity[0] != 0.0


def test_reset_builds_the_model_without_holding_the_lock(stepped: Rig, monkeypatch) -> None:
    import threading

    import micro_feeder.nodes.simulator as simulator_module
    free: list[bool] = []

    def try_lock() -> None:      # from another thread, as the loop thread would
        acquired = stepped.sim._lock.acquire(blocking=False)
        if acquired:
            stepped.sim._lock.release()
        free.append(acquired)

    def build(flat):
        other = threading.Thread(target=try_lock)
        other.start()
        other.join()
        return build_model(flat)

    monkeypatch.setattr(simulator_module, 'build_model', build)
    stepped.step(2)
    assert stepped.probe.call(stepped.executor, Trigger, 'simulator/reset').success
    assert free == [True] and stepped.sim.stepper.t == 0.0


def test_reset_alone_recovers_from_a_simulation_failure(running: Rig) -> None:
    """A stroke velocity of 1e300 m/s (applied past the command checks) makes the physics fail: the
    simulator pauses and reports it; ~/reset alone brings it back running from t = 0."""
    sim = running.sim
    running.wait(lambda: sim.stepper.t > 0.01, 'sim time running')
    with sim._lock:     # straight into the schedule: the stepper's checks refuse such a stroke
        t = sim.stepper.t
        sim.stepper.schedule.command_trajectory(t, np.array([t + 1e-3]), np.array([[1e-5]]), np.array([[1e300]]),
                                                None)
    running.wait(lambda: sim.error, 'the simulation failure')
    assert sim.paused
    assert not running.probe.pause(running.executor, False).success         # no resuming past a failure
    response = running.probe.call(running.executor, Trigger, 'simulator/reset')
    assert response.success and 'running' in response.message, response.message
    assert not sim.error and not sim.paused
    running.wait(lambda: sim.stepper.t > 0.01, 'sim time running again after the reset')


def test_every_one_of_200_asynchronous_step_calls_is_answered(stepped: Rig) -> None:
    """A client with the documented service QoS (depth 1000) sends 200 step requests at once: 200 answers,
    200 steps."""
    client = stepped.probe.create_client(Trigger, 'simulator/step', qos_profile=SERVICE_QOS)
    stepped.wait(client.service_is_ready, 'simulator/step')
    futures = [client.call_async(Trigger.Request()) for _ in range(200)]
    stepped.wait(lambda: all(f.done() for f in futures), '200 answers', timeout=30)
    assert all(f.result().success for f in futures)
    assert stepped.sim.stepper.t == pytest.approx(200 * STEP, abs=1e-12) and stepped.sim.steps_granted == 200


@pytest.mark.parametrize('relative', [-1e-5, 1e-5])
def test_stepped_node_and_its_resim_decide_the_bump_centre_take_off_at_the_closed_form_threshold(
        ros_context: Context, tmp_path: Path, relative: float) -> None:
    """At the bump centre the part leaves when A/2 (2πf)² > g + F_po/m: the node, stepped 1 ms at a time
    on the actuator's trajectory of one stroke at f*(1 ± 1e-5), decides it as the offline model does, and
    so does ``resim`` of the recorded run (and the recorded particle/transitions agree)."""
    model = build_model({'particle.x0': 0.0})
    lift = model.particle.gravity + model.contact_model.pull_off_n / model.particle.mass
    frequency = math.sqrt(lift / (model.stroke.amplitude / 2)) / (2 * math.pi) * (1 + relative)
    expected = 0 if relative < 0 else 1
    rig = Rig(ros_context, start_paused=True, step_period=STEP, **{'particle.x0': 0.0})
    recorder = Recorder(context=ros_context, parameter_overrides=[Parameter('output', value=str(tmp_path / 'log')),
                                                                  Parameter('flush_period', value=0.2)])
    rig.executor.add_node(recorder)
    try:
        rig.wait(lambda: rig.probe.publishers_['actuator/trajectory'].get_subscription_count() == 3
                 and rig.sim.count_subscribers('particle/pose') == 2
                 and recorder.received['/simulator/parameters'] == 1, 'recorder matched')
        rig.send_trajectory(burst_message(0.0, StrokeParams(frequency=frequency, count=1)))
        rig.wait(lambda: recorder.received['/simulator/command_receipts'] == 1, 'receipt recorded')
        poses = recorder.received['/particle/pose']
        rig.step(3)
        assert rig.sim.stepper.state.transitions['take_off'] == expected
        rig.wait(lambda: recorder.received['/particle/pose'] == poses + 3, 'every pose recorded')
    finally:
        rig.executor.remove_node(recorder)
        recorder.close()
        recorder.destroy_node()
        rig.close()
    report = resimulate(LogReader(tmp_path / 'log'))
    assert report.transitions['take_off'] == expected
    # a topic with no message is not in the log (the recorder adds a topic with its first message)
    assert report.recorded_transitions == (report.transitions if expected else None)
    assert report.identical, report.verdict()


def test_the_simulator_says_when_its_command_subscription_hears_a_publisher(ros_context: Context) -> None:
    """``hears``: the simulator's own end of ``actuator/trajectory`` has matched a publisher (what ``run``
    waits for before its actuator sends: a publisher's count of matched subscriptions is the other end)."""
    sim = Simulator(context=ros_context, namespace='/hears', overrides={'start_paused': True})
    sender = rclpy.create_node('sender', namespace='/hears', context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    executor.add_node(sender)
    try:
        assert not sim.hears('actuator/trajectory')
        sender.create_publisher(JointTrajectory, 'actuator/command_elsewhere', 10)
        sender.create_publisher(JointTrajectory, 'actuator/trajectory', topic_qos('actuator/trajectory'))
        wait_until(lambda: sim.hears('actuator/trajectory'), 30, executor=executor, what='the subscription matched')
        assert not sim.hears('actuator/command')
    finally:
        executor.shutdown()
        sender.destroy_node()
        sim.destroy_node()
