"""Stroke schedules as trajectory knots (the actuator's), and interpolated-stroke checks (the simulator's).

The references are independent: the analytic waveform table evaluated at the same instants, and each
segment's extrema found one polynomial at a time with numpy's ``roots``.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import time

import numpy as np
import pytest
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from micro_feeder.interface import messages, stamps, trajectory_cdr
from micro_feeder.interface.names import joint_names
from micro_feeder.physics.trajectory import breakpoints, sample_table, table_range
from micro_feeder.physics.waveforms import StrokeParams, trajectory_table, waveform_table
from micro_feeder.settings import load_settings
from micro_feeder.sim.commands import CommandRejected, parse_trajectory, parse_trajectory_cdr
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import StrokeStream, sample_waveform

LIMITS = (-200e-6, 200e-6)

SCHEDULES = [
    ({'count': 3, 'pause': 0.05}, 1),                                          # the stroke-pause scenario
    ({'count': 5, 'pause': 3e-4, 'delay': 1.23456789e-4}, 1),
    ({'waveform': 'trapezoid', 'count': 3, 'phases': (0.0, 0.25, 0.5)}, 3),
    ({'waveform': 'asymmetric', 'duty': 0.3, 'count': 4, 'pause': 1e-3, 'phases': (0.0, 0.5)}, 2),
    ({'waveform': 'samples', 'count': 7, 'frequency': 1700.0, 'amplitude': 150e-6}, 1),
    ({'waveform': 'sine', 'count': 3, 'pause': 0.01, 'delay': 3e-4}, 1),
    ({'waveform': 'half_sine', 'count': 10, 'pause': 2.5e-4, 'phases': (0.0, 1.3)}, 2),
    ({'frequency': 2345.6, 'count': 4, 'phases': (0.0, 0.1, 0.77, 2.5)}, 4),
]


@pytest.fixture(scope='module')
def model():
    return build_model(load_settings())


def _jumps(table, t_from: float, t_to: float) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints where the waveform's s or ṡ jumps, and the size of the jump (m/s of ṡ, or m of s as
    m per ns) — where no continuous trajectory can follow it exactly."""
    b = breakpoints(table, t_from, t_to)
    left, right = sample_table(table, b - 1e-13), sample_table(table, b + 1e-13)
    size = np.max(np.abs(right[1] - left[1]), axis=1) + np.max(np.abs(right[0] - left[0]), axis=1) * 1e9
    jump = size > 1e-6
    return b[jump], size[jump]


@pytest.mark.parametrize(('stroke', 'n'), SCHEDULES)
def test_simulator_runs_the_configured_schedule_between_knots_too(model, stroke: dict, n: int) -> None:
    """The actuator's message, checked and applied by the simulator's stepper at an arbitrary receipt time,
    interpolates to the analytic schedule within 1e-12 m at dense instants (every knot interval's
    interior and random times), except inside the ≤ 1.5 ns where the waveform itself jumps in ṡ or s."""
    params = StrokeParams(**stroke)
    msg = messages.trajectory(joint_names(n), *sample_waveform(params, n), stamps.to_time(0.0))
    stepper = Stepper(model if n == 1 else build_model(load_settings(overrides=[
        f'surface.centers={[i * 1e-3 for i in range(n)]}', f'surface.widths={[1e-3] * n}',
        f'stroke.phases={list(params.phases)}'])))
    receipt = 0.0123456789123
    stepper.advance(receipt)
    stepper.command_trajectory(parse_trajectory(msg, joint_names(n), LIMITS))
    table = stepper.schedule.table_at(receipt)
    knots = receipt + np.array([stamps.seconds(p.time_from_start) for p in msg.points])
    end = receipt + params.burst_end_s()
    rng = np.random.default_rng(0)
    t = np.concatenate([knots[:-1] + np.diff(knots) * f for f in (0.5, 0.25, 0.8, 0.01)] +
                       [rng.uniform(receipt, end + 1e-3, 100_000), knots])
    got = sample_table(table, t)[0]
    want = sample_table(waveform_table(params, n), t - receipt)[0]
    error = np.max(np.abs(got - want), axis=1)
    allowed = np.full(t.size, 1e-12)
    jumps, size = _jumps(waveform_table(params, n), 0.0, params.burst_end_s())
    if jumps.size:
        i = np.clip(np.searchsorted(jumps, t - receipt), 1, jumps.size) - 1
        for j in (i, np.minimum(i + 1, jumps.size - 1)):
            near = np.abs(t - receipt - jumps[j]) <= 1.6e-9
            allowed = np.where(near, np.maximum(allowed, size[j] * 1.6e-9), allowed)
    assert np.all(error <= allowed), f'{error.max():.3g} m at t = {t[np.argmax(error - allowed)]:.9f} s'
    assert np.all(error[allowed == 1e-12] <= 1e-12)


def test_stroke_pause_knots_are_few_and_exact_in_the_pause() -> None:
    params = StrokeParams(count=3, pause=0.05)
    times, *_ = sample_waveform(params, 1)
    assert times.size < 150                          # ~30 per stroke, nothing inside the pauses
    assert times[0] == 0.0 and times[-1] == pytest.approx(params.burst_end_s(), abs=2e-9)
    pause = (times > 1.01e-3) & (times < 0.0509)
    assert not pause.any()


def _reference_range(coef: np.ndarray, length: float) -> tuple[float, float]:
    """Extrema of one polynomial on [0, length]: ends and real roots of the derivative (numpy.roots)."""
    poly = np.polynomial.Polynomial(coef)
    roots = poly.deriv().roots() if np.any(coef[1:]) else np.zeros(0)
    inside = [r.real for r in np.atleast_1d(roots) if abs(r.imag) < 1e-9 * length and 0 < r.real < length]
    values = poly(np.array([0.0, length, *inside]))
    return float(values.min()), float(values.max())


@pytest.mark.parametrize('kind', ['quintic', 'cubic', 'linear'])
def test_interpolated_range_equals_the_extrema_of_every_segment(kind: str) -> None:
    rng = np.random.default_rng(7)
    n = 400
    times = np.cumsum(rng.uniform(1e-6, 1e-3, n))
    pos = rng.uniform(-1e-4, 1e-4, (n, 2))
    vel = rng.uniform(-0.5, 0.5, (n, 2)) if kind != 'linear' else None
    acc = rng.uniform(-2e3, 2e3, (n, 2)) if kind == 'quintic' else None
    table = trajectory_table(times, pos, vel, acc)
    low, high = table_range(table)
    for k in range(2):
        ref = [_reference_range(table.seg_coef[k, i, :6], table.seg_start[k, i + 1] - table.seg_start[k, i])
               for i in range(n - 1)]
        assert low[k] == pytest.approx(min(r[0] for r in ref), abs=1e-16)
        assert high[k] == pytest.approx(max(r[1] for r in ref), abs=1e-16)


@pytest.mark.parametrize('kind', ['quintic', 'cubic', 'linear'])
def test_range_within_limits_is_exact_where_it_leaves_them(kind: str) -> None:
    """table_range(within=...) skips exact extrema only for segments provably inside: wherever the range
    leaves the limits it equals the exact one, and inside it never claims to leave them."""
    rng = np.random.default_rng(11)
    n = 400
    times = np.cumsum(rng.uniform(1e-6, 1e-3, n))
    pos = rng.uniform(-1e-4, 1e-4, (n, 3))
    vel = rng.uniform(-0.5, 0.5, (n, 3)) if kind != 'linear' else None
    acc = rng.uniform(-2e3, 2e3, (n, 3)) if kind == 'quintic' else None
    table = trajectory_table(times, pos, vel, acc)
    exact_low, exact_high = table_range(table)
    for within in ((-2e-4, 2e-4), (-1.2e-4, 1.2e-4), (exact_low.min() + 1e-6, exact_high.max() - 1e-6)):
        low, high = table_range(table, within)
        assert np.all(np.where(exact_low < within[0], low == exact_low, low >= within[0]))
        assert np.all(np.where(exact_high > within[1], high == exact_high, high <= within[1]))


def _overshooting_trajectory() -> JointTrajectory:
    """The old actuator's stroke-pause burst around the pause: a knot resting (s̈ = 0) 50 ms before one
    with the next stroke's s̈ = 1974 m/s²: every knot is within the limits, the quintic between them
    reaches ~85 mm."""
    points = [JointTrajectoryPoint(positions=[0.0], velocities=[0.0], accelerations=[a],
                                   time_from_start=Duration(sec=0, nanosec=round(t * 1e9)))
              for t, a in ((0.001, 0.0), (0.051, 1973.92088))]
    return JointTrajectory(joint_names=['piezo_0'], points=points)


def test_trajectory_overshooting_between_knots_is_refused_and_changes_nothing(model) -> None:
    stepper = Stepper(model)
    stepper.advance(1e-3)
    with pytest.raises(CommandRejected, match='between knots.*outside the piezo limits'):
        stepper.command_trajectory(parse_trajectory(_overshooting_trajectory(), ['piezo_0'], LIMITS))
    assert len(stepper.schedule.pieces) == 1 and np.all(stepper.schedule.evaluate(0.03) == 0.0)
    cubic = JointTrajectory(joint_names=['piezo_0'], points=[  # knots inside, the cubic swings out
        JointTrajectoryPoint(positions=[1.9e-4], velocities=[v], time_from_start=Duration(nanosec=t))
        for t, v in ((100_000, 10.0), (200_000, 0.0))])
    with pytest.raises(CommandRejected, match='between knots'):
        stepper.command_trajectory(parse_trajectory(cubic, ['piezo_0'], LIMITS))
    stepper.command_trajectory(parse_trajectory(messages.trajectory(
        ['piezo_0'], *sample_waveform(StrokeParams(amplitude=200e-6), 1), stamps.to_time(0.0)),
        ['piezo_0'], LIMITS))           # a stroke up to the limit itself is accepted


@pytest.mark.parametrize(('field', 'value', 'words'), [
    ('velocities', 1e300, r'velocity 1e\+300 m/s outside'),
    ('accelerations', 1e300, r'acceleration 1e\+300 m/s\^2 outside'),
    ('velocities', -3e6, 'velocity'),
])
def test_velocities_and_accelerations_have_a_physical_range(field: str, value: float, words: str) -> None:
    point = JointTrajectoryPoint(positions=[1e-5], velocities=[0.0], accelerations=[0.0],
                                 time_from_start=Duration(nanosec=1000))
    setattr(point, field, [value])
    with pytest.raises(CommandRejected, match=words):
        parse_trajectory(JointTrajectory(joint_names=['piezo_0'], points=[point]), ['piezo_0'], LIMITS)


def test_a_million_point_trajectory_is_refused_at_once() -> None:
    point = JointTrajectoryPoint(positions=[1e-6], time_from_start=Duration(nanosec=1))
    msg = JointTrajectory(joint_names=['piezo_0'], points=[point] * 1_000_000)
    start = time.perf_counter()
    with pytest.raises(CommandRejected, match='1000000 points, more than 100000.*windows'):
        parse_trajectory(msg, ['piezo_0'], LIMITS)
    assert time.perf_counter() - start < 0.5


def test_positions_only_trajectory_accepted_with_one_warning() -> None:
    """Three positions-only trajectories parsed in a fresh process (the warning is once per process):
    all accepted, one warning saying what linear interpolation implies."""
    code = """
from builtin_interfaces.msg import Duration
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from micro_feeder.sim.commands import parse_trajectory
msg = JointTrajectory(joint_names=['piezo_0'], points=[
    JointTrajectoryPoint(positions=[p], time_from_start=Duration(nanosec=t))
    for t, p in ((100_000, 1e-5), (200_000, 0.0))])
for _ in range(3):
    cmd = parse_trajectory(msg, ['piezo_0'], (-200e-6, 200e-6))
    assert cmd.velocities is None and cmd.positions.shape == (2, 1)
"""
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stderr.count('positions-only trajectory') == 1 and 'zero between knots' in result.stderr


def test_a_continuous_stream_over_60_s_stays_bounded_and_seamless() -> None:
    """An endless burst streamed for 60 s of sim time: every window within its knot budget and bytes,
    consecutive windows meeting at a shared knot, and the strokes exact to 1e-12 m in sampled windows."""
    params = StrokeParams(count=1, phases=(0.0, 0.25, 0.5, 0.75))
    stream = StrokeStream(params, 0, 4, origin_ns=1_000_000_007, window=0.02, max_points=2000, knots_per_stroke=1)
    reference = waveform_table(StrokeParams(count=60_100, phases=params.phases), 4)
    largest, biggest, previous_end = 0, 0, stream.origin_ns
    rng = np.random.default_rng(1)
    checked = 0
    while stream.scheduled_until < 61.0:
        stamp, offsets, knots = stream.next_window()
        assert stamp == previous_end and offsets[0] == 0 and np.all(np.diff(offsets) > 0)
        data = trajectory_cdr.encode(joint_names(4), offsets, knots[0], knots[1], knots[2],
                                       stamps.to_time(stamp * 1e-9))
        largest = max(largest, offsets.size)
        biggest = max(biggest, len(data))
        previous_end = stamp + int(offsets[-1])
        if rng.uniform() < 0.01:                     # ~30 windows checked densely
            checked += 1
            times = (stamp + offsets) * 1e-9
            table = trajectory_table(times, knots[0], knots[1], knots[2])
            t = rng.uniform(times[0], times[-1], 5000)
            burst_t = t - stream.origin_ns * 1e-9
            error = np.abs(sample_table(table, t)[0] - sample_table(reference, burst_t)[0])
            assert error.max() <= 1e-12
    assert checked > 10 and largest <= 2000
    assert biggest < 256 * 1024          # stated (docs/interface.md): < 256 KiB per message with 4 actuators


def test_a_window_applied_with_the_table_made_when_parsed_is_the_window_applied_afresh(model) -> None:
    """The simulator builds a stamped window's interpolation when it parses it (outside its lock) and only
    installs it when applying: the schedule is bit for bit the one built at apply time. A command whose knots
    do not start at its stamp has none (it is joined to the stroke in force when applied)."""
    n = model.n_actuators
    params = StrokeParams(count=1, phases=(0.0,) * n)
    stream = StrokeStream(params, 0, n, origin_ns=3_000_000, window=0.02, max_points=2000, knots_per_stroke=1)
    names = joint_names(n)
    prepared, afresh = Stepper(model), Stepper(model)
    for _ in range(6):
        stamp, offsets, knots = stream.next_window()
        data = trajectory_cdr.encode(names, offsets, knots[0], knots[1], knots[2], stamps.to_time(stamp * 1e-9))
        command = parse_trajectory_cdr(data, names, prepared.limits)
        assert command.own_table is not None
        prepared.command_trajectory(command)
        afresh.command_trajectory(dataclasses.replace(command, own_table=None))
    t = np.linspace(0.0, stream.scheduled_until, 20001)
    assert np.array_equal(np.array([prepared.schedule.evaluate(x) for x in t]),
                          np.array([afresh.schedule.evaluate(x) for x in t]))
    zeros = np.zeros((2, n))
    later = trajectory_cdr.encode(names, np.array([1_000_000, 2_000_000]), zeros, zeros, zeros, stamps.to_time(0.5))
    assert parse_trajectory_cdr(later, names, prepared.limits).own_table is None
