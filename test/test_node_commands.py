"""Pure parts of the nodes: command checks, message building, parameter descriptors, waveform knots."""

from __future__ import annotations

import array
import math
import tracemalloc

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from rcl_interfaces.msg import ParameterType
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from micro_feeder.interface.messages import tilt_quaternion
from micro_feeder.interface.stamps import to_time
from micro_feeder.nodes.parameters import descriptor
from micro_feeder.physics.waveforms import StrokeParams, waveform_table
from micro_feeder.settings import load_settings, model_specs
from micro_feeder.sim.commands import CommandRejected, parse_setpoints, parse_trajectory, start_time
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import sample_waveform

LIMITS = (-200e-6, 200e-6)


def _msg(names: list[str], rows: list[tuple[float, list[float]]]) -> JointTrajectory:
    return JointTrajectory(joint_names=names, points=[
        JointTrajectoryPoint(positions=p, time_from_start=Duration(nanosec=round(t * 1e9))) for t, p in rows])


def test_trajectory_reordered_to_the_simulator_joints() -> None:
    cmd = parse_trajectory(_msg(['piezo_1', 'piezo_0'], [(0.001, [1e-6, 2e-6])]), ['piezo_0', 'piezo_1'], LIMITS)
    assert cmd.positions.tolist() == [[2e-6, 1e-6]] and cmd.velocities is None and not cmd.is_stop


@pytest.mark.parametrize(('names', 'rows', 'words'), [
    (['piezo_9'], [(0.001, [0.0])], 'unknown joint'),
    (['piezo_0', 'piezo_0'], [(0.001, [0.0, 0.0])], 'repeated'),
    ([], [(0.001, [])], 'missing'),
    (['piezo_0'], [(0.002, [0.0]), (0.001, [0.0])], 'strictly increasing'),
    (['piezo_0'], [(0.001, [0.0]), (0.001, [0.0])], 'strictly increasing'),
    (['piezo_0'], [(0.001, [math.nan])], 'non-finite'),
    (['piezo_0'], [(0.001, [3e-4])], 'piezo limits'),
    (['piezo_0'], [(0.001, [0.0, 1.0])], 'one per joint'),
])
def test_bad_trajectories_are_named(names: list[str], rows: list, words: str) -> None:
    with pytest.raises(CommandRejected, match=words):
        parse_trajectory(_msg(names, rows), ['piezo_0'], LIMITS)


def test_accelerations_need_velocities_and_stamp_must_not_be_negative() -> None:
    msg = _msg(['piezo_0'], [(0.001, [0.0])])
    msg.points[0].accelerations = [1.0]
    with pytest.raises(CommandRejected, match='without velocities'):
        parse_trajectory(msg, ['piezo_0'], LIMITS)
    msg = _msg(['piezo_0'], [(0.001, [0.0])])
    msg.header.stamp.sec = -1
    with pytest.raises(CommandRejected, match='negative'):
        parse_trajectory(msg, ['piezo_0'], LIMITS)


def test_empty_trajectory_is_a_stop_and_start_times() -> None:
    assert parse_trajectory(JointTrajectory(), ['piezo_0'], LIMITS).is_stop
    assert start_time(0.0, 1.5) == 1.5 and start_time(1.0, 1.5) == 1.5 and start_time(2.0, 1.5) == 2.0


def test_setpoints() -> None:
    assert parse_setpoints([1e-6, 2e-6], 2, LIMITS).tolist() == [1e-6, 2e-6]
    for data, words in (([1e-6], '1 values for 2'), ([1e-6, math.inf], 'non-finite'), ([0.0, -1e-3], 'limits')):
        with pytest.raises(CommandRejected, match=words):
            parse_setpoints(data, 2, LIMITS)


def test_tilt_sign_contact_x_points_up_the_slope() -> None:
    theta = math.atan(0.1)                     # h_x > 0: the surface rises along +x
    x, y, z, w = tilt_quaternion(theta)
    # rotate the unit x axis by the quaternion: v' = v + 2w (q x v) + 2 q x (q x v)
    q = np.array([x, y, z])
    v = np.array([1.0, 0.0, 0.0])
    t = 2.0 * np.cross(q, v)
    rotated = v + w * t + np.cross(q, t)
    assert rotated == pytest.approx([math.cos(theta), 0.0, math.sin(theta)])
    assert rotated[2] > 0


def test_time_conversion_is_exact_to_the_nanosecond() -> None:
    stamp = to_time(1.000000001)
    assert (stamp.sec, stamp.nanosec) == (1, 1)


def test_descriptors_from_param_specs() -> None:
    specs = model_specs()
    spec, default = specs['stroke.frequency']
    d = descriptor('stroke.frequency', spec)
    assert d.type == ParameterType.PARAMETER_DOUBLE and '[Hz]' in d.description
    assert (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value) == (0.0, 1e7)
    d = descriptor('stroke.count', specs['stroke.count'][0])
    assert d.type == ParameterType.PARAMETER_INTEGER and d.integer_range[0].from_value == 1
    d = descriptor('stroke.waveform', specs['stroke.waveform'][0])
    assert d.type == ParameterType.PARAMETER_STRING and 'raised_cosine' in d.additional_constraints
    assert descriptor('surface.centers', specs['surface.centers'][0]).type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert isinstance(specs['surface.centers'][1], list) and default == 1000.0


@pytest.mark.parametrize('waveform', ['raised_cosine', 'trapezoid', 'asymmetric'])
def test_waveform_knots_follow_the_waveform(waveform: str) -> None:
    params = StrokeParams(waveform=waveform, count=2, pause=2e-4, phases=(0.0, 0.5))
    times, pos, _, acc = sample_waveform(params, 2, 40)
    assert np.all(np.diff(times) > 0) and times[0] == 0.0
    assert np.all(np.diff(times) <= 1 / 40e3 + 1e-12)
    assert times[-1] == pytest.approx(params.burst_end_s(), abs=2e-9)
    exact = np.stack([waveform_table(params, 2).evaluate(float(t)) for t in times])
    np.testing.assert_allclose(pos, exact[:, 0], rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(acc, exact[:, 2], rtol=1e-12, atol=1e-9)
    assert np.all(pos[-1] == 0.0) and np.all(acc[-1] == 0.0)


def test_setpoints_streamed_at_1khz_keep_the_schedule_bounded() -> None:
    """A controller streaming actuator/command at 1 kHz: 3000 set-points, the schedule keeps a few pieces
    and memory does not grow with the count."""
    stepper = Stepper(build_model(load_settings()))
    tracemalloc.start()
    try:
        for i in range(3000):
            data = array.array('d', [50e-6 * math.sin(i * 0.01)])     # Float64MultiArray.data's type
            stepper.command_setpoints(parse_setpoints(data, 1, LIMITS))
            stepper.advance((i + 1) * 1e-3)
            if i == 999:
                after_1000, _ = tracemalloc.get_traced_memory()
        current, _ = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert len(stepper.schedule.pieces) == 1     # each set-point applies from now on: the others ended
    assert current - after_1000 < 200_000, f'{(current - after_1000) / 1e3:.0f} kB over 2000 set-points'
    assert stepper.observe().strokes[0] == pytest.approx(50e-6 * math.sin(2999 * 0.01))
