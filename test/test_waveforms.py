"""Stroke waveforms and trajectories: exact derivatives against independent numerics, conventions."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from micro_feeder.physics.parameters import ParameterError
from micro_feeder.physics.waveforms import WAVEFORMS, StrokeParams, StrokeSchedule, trajectory_table, waveform_table

F = 800.0
A = 80e-6


def table(**changes):
    return waveform_table(StrokeParams(frequency=F, amplitude=A, **changes), 1)


def interior_times(tab, n=200):
    """Times inside the burst that stay clear of the breakpoints (where one-sided values differ)."""
    bounds = np.unique(tab.seg_start[0, :tab.n_seg[0] + 1])
    t = tab.start[0] + np.linspace(0.0, tab.period[0], n)
    away = np.min(np.abs(t[:, None] - (tab.start[0] + bounds)[None, :]), axis=1) > 1e-7
    return t[away]


@pytest.mark.parametrize('shape', WAVEFORMS)
def test_derivatives_match_finite_differences(shape):
    tab = table(waveform=shape, duty=0.3, samples=(0.0, 0.2, 1.0, 0.7, 0.1))
    dt = 1e-9
    for t in interior_times(tab):
        _s, sd, sdd = tab.evaluate(t)[:, 0]
        plus, minus = tab.evaluate(t + dt)[:, 0], tab.evaluate(t - dt)[:, 0]
        assert sd == pytest.approx((plus[0] - minus[0]) / (2 * dt), rel=1e-5, abs=1e-5 * A * F)
        assert sdd == pytest.approx((plus[1] - minus[1]) / (2 * dt), rel=1e-5, abs=1e-5 * A * F * F)


@pytest.mark.parametrize('shape', WAVEFORMS)
def test_velocity_integrates_to_the_stroke(shape):
    """s(t) − s(0) = ∫ ṡ (quadrature across the segment boundaries as breakpoints)."""
    tab = table(waveform=shape, duty=0.3, delay=1e-4)
    bounds = tab.start[0] + tab.seg_start[0, :tab.n_seg[0] + 1]
    for t_end in (tab.start[0] + 0.37 / F, tab.start[0] + 0.81 / F):
        integral, _ = quad(lambda t: tab.evaluate(t)[1, 0], 0.0, t_end, points=list(bounds), limit=200,
                           epsabs=1e-14)
        assert tab.evaluate(t_end)[0, 0] - tab.evaluate(0.0)[0, 0] == pytest.approx(integral, abs=1e-11)


def test_raised_cosine_shape_and_burst_conventions():
    params = StrokeParams(frequency=F, amplitude=A, count=3, pause=2e-4, delay=5e-4)
    tab = waveform_table(params, 1)
    period = 1 / F
    for j in range(3):
        start = 5e-4 + j * (period + 2e-4)
        assert tab.evaluate(start + period / 2)[0, 0] == pytest.approx(A, rel=1e-12)
        assert tab.evaluate(start + period / 4)[0, 0] == pytest.approx(A / 2, rel=1e-12)
        assert tab.evaluate(start + period + 1e-4)[:, 0] == pytest.approx([0, 0, 0], abs=1e-20)  # pause
    assert tab.evaluate(4.9e-4)[:, 0] == pytest.approx([0, 0, 0], abs=1e-20)                  # delay
    assert tab.evaluate(params.burst_end_s() + 1e-6)[:, 0] == pytest.approx([0, 0, 0], abs=1e-20)
    # the acceleration jumps at a stroke start: the right-hand value belongs to the new stroke
    assert tab.evaluate(5e-4)[2, 0] == pytest.approx(A / 2 * (2 * np.pi * F) ** 2, rel=1e-12)


def test_phases_delay_each_actuator():
    params = StrokeParams(frequency=F, amplitude=A, phases=(0.0, 0.25))
    tab = waveform_table(params, 2)
    t = 0.3 / F
    s = tab.evaluate(t)[0]
    assert s[1] == pytest.approx(tab.evaluate(t - 0.25 / F)[0, 0], rel=1e-12)
    with pytest.raises(ParameterError, match='stroke.phases'):
        waveform_table(params, 3)


def test_asymmetric_peaks_at_duty_and_trapezoid_holds():
    asym = table(waveform='asymmetric', duty=0.2)
    assert asym.evaluate(0.2 / F)[0, 0] == pytest.approx(A, rel=1e-12)
    assert asym.evaluate(0.2 / F)[1, 0] == pytest.approx(0.0, abs=1e-9)
    trap = table(waveform='trapezoid', duty=0.4)
    ramp = 0.3 / F
    for t in np.linspace(ramp, ramp + 0.4 / F, 7):
        assert trap.evaluate(t)[0, 0] == pytest.approx(A, rel=1e-12)
    # jerk-limited: the acceleration is continuous at every breakpoint, including the stroke ends
    for b in trap.seg_start[0, 1:trap.n_seg[0]]:
        left, right = trap.evaluate(b - 1e-12)[2, 0], trap.evaluate(b)[2, 0]
        assert left == pytest.approx(right, abs=1e-6 * A * F * F)
    assert trap.evaluate(0.0)[2, 0] == pytest.approx(0.0, abs=1e-9)


def test_samples_pass_through_the_table():
    values = (0.0, 0.3, 1.0, 0.6)
    tab = table(waveform='samples', samples=values)
    for i, v in enumerate(values):
        assert tab.evaluate(i / (len(values) * F))[0, 0] == pytest.approx(A * v, abs=1e-15)


@pytest.mark.parametrize('kind', ['quintic', 'cubic', 'linear'])
def test_trajectory_hermite_through_knots(kind):
    """Each segment meets its knots' positions (and velocities, accelerations where given) at both ends."""
    times = np.array([0.1, 0.1004, 0.1011, 0.1015])
    pos = np.array([[0.0, 1e-5], [4e-5, 2e-5], [2e-5, 0.0], [0.0, 0.0]])
    vel = np.array([[0.0, 0.0], [0.05, -0.01], [-0.08, 0.0], [0.0, 0.0]]) if kind != 'linear' else None
    acc = np.array([[0.0, 0.0], [30.0, 5.0], [-20.0, 0.0], [0.0, 0.0]]) if kind == 'quintic' else None
    tab = trajectory_table(times, pos, vel, acc)
    for i, t in enumerate(times[:-1]):
        got = tab.evaluate(t)
        end = tab.evaluate(times[i + 1] - 1e-13)       # left limit at the next knot
        np.testing.assert_allclose(got[0], pos[i], atol=1e-15)
        np.testing.assert_allclose(end[0], pos[i + 1], atol=1e-13)
        if kind == 'linear':
            np.testing.assert_allclose(got[1], (pos[i + 1] - pos[i]) / (times[i + 1] - t), rtol=1e-9)
            np.testing.assert_allclose(got[2], 0.0, atol=0)
            continue
        np.testing.assert_allclose(got[1], vel[i], atol=1e-12)
        np.testing.assert_allclose(end[1], vel[i + 1], atol=1e-7)
        if kind == 'quintic':
            np.testing.assert_allclose(got[2], acc[i], atol=1e-7)
            np.testing.assert_allclose(end[2], acc[i + 1], atol=1e-3)
    np.testing.assert_allclose(tab.evaluate(0.2)[0], pos[-1])     # holds the last position


def test_schedule_forgets_only_the_pieces_that_ended():
    schedule = StrokeSchedule(table(), 1e-4)
    for t in (3e-4, 5e-4, 7e-4):
        schedule.command_trajectory(t, [t + 1e-4], [[t / 10]], [[0.0]], [[0.0]])
    times = np.linspace(0.0, 1e-3, 41)
    before = [schedule.evaluate(t).tolist() for t in times]
    copy = StrokeSchedule.of_pieces(schedule.pieces)
    schedule.drop_ended(0.5e-4)                     # every piece starts later: nothing ended
    schedule.drop_ended(2e-4)                       # the first piece is still in force
    assert len(schedule.pieces) == 4
    schedule.drop_ended(5e-4)                       # from 5e-4 on, the pieces before it no longer count
    assert [t for t, _ in schedule.pieces] == [5e-4, 7e-4]
    assert [schedule.evaluate(t).tolist() for t in times[times >= 5e-4]] == \
        [b for t, b in zip(times, before, strict=True) if t >= 5e-4]
    assert [t for t, _ in copy.pieces] == [1e-4, 3e-4, 5e-4, 7e-4]     # a schedule of its own
    assert [copy.evaluate(t).tolist() for t in times] == before


def test_schedule_spans_are_the_pieces_in_force_during_an_interval():
    schedule = StrokeSchedule(table(), 1e-4)
    for t in (3e-4, 5e-4):
        schedule.command_trajectory(t, [t + 1e-4], [[t / 10]], [[0.0]], [[0.0]])
    (t0, first), (t1, second), (t2, third) = schedule.pieces

    def spans(a: float, b: float) -> list[tuple[float, float, object]]:
        return schedule.spans(a, b)

    assert spans(2e-4, 4e-4) == [(t0, t1, first), (t1, t2, second)]
    assert spans(3e-4, 4e-4) == [(t1, t2, second)]            # the first ended where the interval starts
    assert spans(2e-4, 3e-4) == [(t0, t1, first)]             # the interval ends where the second starts
    assert spans(0.0, 1e-3) == [(t0, t1, first), (t1, t2, second), (t2, math.inf, third)]
    assert spans(6e-4, 7e-4) == [(t2, math.inf, third)]
    # the walk it replaces: every piece whose [from, until) meets (a, b]
    bounds = [t0, t1, t2, math.inf]
    for a, b in ((0.0, 1e-4), (1e-4, 3e-4), (2.9e-4, 5.1e-4), (5e-4, 5e-4 + 1e-9)):
        expected = [(bounds[i], bounds[i + 1], tab) for i, (_, tab) in enumerate(schedule.pieces)
                    if bounds[i + 1] > a and bounds[i] < b]
        assert spans(a, b) == expected


def test_schedule_replaces_the_rest_and_stays_continuous():
    schedule = StrokeSchedule(table())
    before = schedule.evaluate(3e-4)
    schedule.command_trajectory(3e-4, [6e-4, 9e-4], [[2e-5], [0.0]], [[0.0], [0.0]], [[0.0], [0.0]])
    np.testing.assert_allclose(schedule.evaluate(3e-4), before, rtol=1e-12)
    assert schedule.evaluate(6e-4)[0, 0] == pytest.approx(2e-5)
    schedule.command_trajectory(7e-4, [8e-4], [[5e-5]], [[0.0]], [[0.0]])   # replaces the rest
    assert schedule.evaluate(8e-4)[0, 0] == pytest.approx(5e-5)
    assert schedule.evaluate(9e-4)[0, 0] == pytest.approx(5e-5)
    assert [t for t, _ in schedule.pieces][1:] == [3e-4, 7e-4]
    assert schedule.table_at(5e-4) is schedule.pieces[1][1]
    held = schedule.hold_from(8.5e-4).evaluate(1.0)[0, 0]
    assert held == pytest.approx(5e-5)
