"""The actuator node in-process: start/stop services, auto_start, parameters."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from node_helpers import Probe
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_helpers import wait_until
from std_srvs.srv import Trigger

from micro_feeder.nodes.actuator import Actuator, sample_waveform
from micro_feeder.physics.waveforms import StrokeParams, waveform_table


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
        assert max(p.positions[0] for p in burst.points) == pytest.approx(100e-6, rel=1e-3)
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
        assert max(p.positions[0] for p in trajectories[-1].points) == pytest.approx(50e-6, rel=1e-3)
        assert actuator.bursts == 2 and actuator.stops == 1
    finally:
        ex.shutdown()


def test_auto_start_sends_once_when_a_subscriber_appears(ros_context: Context) -> None:
    actuator, probe, ex = _rig(ros_context)
    try:
        wait_until(lambda: probe.msgs['actuator/trajectory'], 10.0, executor=ex, what='auto-started burst')
        wait_until(lambda: actuator._auto is None, 1.0, executor=ex, what='auto timer gone')
        assert actuator.bursts == 1
    finally:
        ex.shutdown()


def _reference_sample_waveform(params, n_actuators, knots_per_stroke):
    """sample_waveform as it was with the grid × bounds distance matrix (the knots must not change)."""
    table = waveform_table(params, n_actuators)
    end = params.burst_end_s()
    grid = np.linspace(0.0, end, int(np.ceil(end * params.frequency * knots_per_stroke)) + 1)
    bounds = [table.start[k] + j * table.period[k] + table.seg_start[k, :table.n_seg[k] + 1]
              for k in range(n_actuators) for j in range(int(table.count[k]))]
    bounds = np.unique(np.concatenate(bounds))
    bounds = bounds[np.concatenate([[True], np.diff(bounds) > 1e-12])]
    near = np.min(np.abs(grid[:, None] - bounds[None, :]), axis=1) <= 1e-12
    times = np.sort(np.concatenate([grid[~near], bounds]))
    times = times[(times >= 0.0) & (times <= end * (1 + 1e-12))]
    values = np.stack([table.evaluate(float(t)) for t in times])
    on_boundary = np.isin(times, bounds)
    keep = on_boundary | np.any(values != 0.0, axis=(1, 2)) | (times == times[0]) | (times == times[-1])
    times, values = times[keep], values[keep]
    return times, values[:, 0, :], values[:, 1, :], values[:, 2, :]


@pytest.mark.parametrize(('stroke', 'n', 'knots'), [
    ({}, 1, 40),
    ({'count': 5, 'pause': 3e-4, 'delay': 1e-4}, 1, 40),
    ({'waveform': 'trapezoid', 'count': 3, 'phases': (0.0, 0.25, 0.5)}, 3, 16),
    ({'waveform': 'asymmetric', 'duty': 0.3, 'count': 4, 'pause': 1e-3, 'phases': (0.0, 0.5)}, 2, 40),
    ({'waveform': 'samples', 'count': 7, 'frequency': 1700.0}, 1, 25),
    ({'waveform': 'half_sine', 'count': 10, 'pause': 2.5e-4, 'phases': (0.0, 1.0)}, 2, 8),
])
def test_sample_waveform_knots_unchanged(stroke, n, knots):
    params = StrokeParams(**stroke)
    got = sample_waveform(params, n, knots)
    want = _reference_sample_waveform(params, n, knots)
    for g, w in zip(got, want, strict=True):
        np.testing.assert_array_equal(g, w)


def test_long_burst_in_bounded_memory():
    params = StrokeParams(count=1000, pause=1e-4)
    tracemalloc.start()
    try:
        times, *_ = sample_waveform(params, 1, 40)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert times[-1] == pytest.approx(params.burst_end_s())
    assert len(times) >= 1000 * 40
    assert peak < 100e6, f'{peak / 1e6:.0f} MB'  # the grid × bounds matrix took 641 MB
