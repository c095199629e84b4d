"""The ``actuator`` node: publishes the stroke waveform of the ``stroke.*`` parameters as a JointTrajectory.

``actuator/start`` sends the configured burst on ``actuator/trajectory`` (knots with positions,
velocities and accelerations sampled from the analytic waveform); ``actuator/stop`` sends an empty
trajectory, which stops the strokes where they are. With ``auto_start`` the burst is sent once, as soon
as a subscriber (the simulator) is connected. ``stroke.*`` may be changed at any time and apply to the
next ``start``. The header stamp is 0 ("start on receipt"): the burst's own ``stroke.delay`` is in the
knot times.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from ..physics.parameters import ParamSpec
from ..physics.waveforms import StrokeParams, waveform_table
from . import messages
from ._ros import topic_qos
from .commands import joint_names
from .parameters import check_changes, declare, model_specs, values
from .spin import spin_node

NODE_SPECS: dict[str, tuple[ParamSpec, Any]] = {
    'auto_start': (ParamSpec('send the burst once when a subscriber is connected', kind='bool', read_only=True),
                   True),
    'knots_per_stroke': (ParamSpec('trajectory knots per stroke period (besides the waveform breakpoints)',
                                   kind='int', ge=2, le=10000), 40),
}


def sample_waveform(params: StrokeParams, n_actuators: int, knots_per_stroke: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Knots of the burst: times (s from the start) and (n, actuators) s (m), ṡ (m/s), s̈ (m/s²).

    Knots lie on a uniform grid of ``knots_per_stroke`` per stroke period plus every segment boundary of
    every actuator (where s̈ may jump; the value there is the right-hand one), from 0 to the end of the
    burst, so a quintic Hermite through them follows the waveform closely. Grid knots where every actuator
    rests (s = ṡ = s̈ = 0, e.g. in the pauses between strokes) are left out: the boundary knots around a rest
    are kept, and a quintic between two resting knots is exactly zero.
    """
    table = waveform_table(params, n_actuators)
    end = params.burst_end_s()
    grid = np.linspace(0.0, end, int(np.ceil(end * params.frequency * knots_per_stroke)) + 1)
    bounds = [table.start[k] + j * table.period[k] + table.seg_start[k, :table.n_seg[k] + 1]
              for k in range(n_actuators) for j in range(int(table.count[k]))]
    bounds = np.unique(np.concatenate(bounds))          # computed as the kernel computes them: exact
    bounds = bounds[np.concatenate([[True], np.diff(bounds) > 1e-12])]
    # Distance from each grid time to its nearest bound (bounds are sorted): the bound at or after it
    # and the one before; O((grid + bounds) log bounds) instead of a grid × bounds matrix.
    right = np.searchsorted(bounds, grid)
    after = np.abs(grid - bounds[np.minimum(right, len(bounds) - 1)])
    before = np.abs(grid - bounds[np.maximum(right - 1, 0)])
    near = np.minimum(after, before) <= 1e-12
    times = np.sort(np.concatenate([grid[~near], bounds]))
    times = times[(times >= 0.0) & (times <= end * (1 + 1e-12))]
    values = np.stack([table.evaluate(float(t)) for t in times])       # (n, 3, actuators)
    on_boundary = np.isin(times, bounds)
    keep = on_boundary | np.any(values != 0.0, axis=(1, 2)) | (times == times[0]) | (times == times[-1])
    times, values = times[keep], values[keep]
    return times, values[:, 0, :], values[:, 1, :], values[:, 2, :]


class Actuator(Node):
    """Stroke waveform publisher: see the module docstring and docs/interface.md."""

    def __init__(self, overrides: Mapping[str, Any] | None = None, **kwargs: Any):
        super().__init__('actuator', **kwargs)
        self._stroke_specs = model_specs([StrokeParams])
        self._specs = {**self._stroke_specs, **NODE_SPECS}
        declare(self, self._specs, overrides)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._pub = self.create_publisher(JointTrajectory, 'actuator/trajectory', topic_qos('actuator/trajectory'))
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', topic_qos('/diagnostics'))
        self.create_service(Trigger, 'actuator/start', self._on_start)
        self.create_service(Trigger, 'actuator/stop', self._on_stop)
        self.bursts = 0
        self.stops = 0
        self._auto = self.create_timer(0.05, self._auto_start) if self.get_parameter('auto_start').value else None
        self.create_timer(1.0, self._publish_diagnostics)

    def trajectory(self) -> JointTrajectory:
        """The burst of the current ``stroke.*`` parameters as a JointTrajectory (stamp 0)."""
        params = StrokeParams.from_flat(values(self, self._stroke_specs))
        n = len(params.phases)
        knots = self.get_parameter('knots_per_stroke').value
        return messages.trajectory(joint_names(n), *sample_waveform(params, n, knots), Time())

    def start(self) -> str:
        """Publish the burst; returns a one-line description."""
        msg = self.trajectory()
        self._pub.publish(msg)
        self.bursts += 1
        length = messages.seconds(msg.points[-1].time_from_start)
        return f'burst sent: {len(msg.points)} knots on {len(msg.joint_names)} joints, {length:.6g} s'

    def stop(self) -> str:
        """Publish an empty trajectory (stop: hold the strokes where they are)."""
        n = len(self.get_parameter('stroke.phases').value)
        self._pub.publish(JointTrajectory(joint_names=joint_names(n)))
        self.stops += 1
        return 'stop sent'

    def _auto_start(self) -> None:
        if self._pub.get_subscription_count() > 0:
            self.get_logger().info(self.start())
            self.destroy_timer(self._auto)
            self._auto = None

    def _on_start(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = True, self.start()
        return response

    def _on_stop(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = True, self.stop()
        return response

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        reason = check_changes(self._specs, values(self, self._stroke_specs), params, [StrokeParams])
        return SetParametersResult(successful=reason is None, reason=reason or '')

    def _publish_diagnostics(self) -> None:
        status = DiagnosticStatus(name=f'{self.get_name()}: stroke', hardware_id='micro_feeder',
                                  level=DiagnosticStatus.OK, message='ok',
                                  values=[KeyValue(key='bursts_sent', value=str(self.bursts)),
                                          KeyValue(key='stops_sent', value=str(self.stops)),
                                          KeyValue(key='subscribers', value=str(self._pub.get_subscription_count()))])
        self._pub_diag.publish(DiagnosticArray(header=Header(stamp=self.get_clock().now().to_msg()),
                                               status=[status]))


def main(args: list[str] | None = None) -> int:
    """Console script ``actuator``: ``actuator --ros-args -p stroke.count:=5 -p auto_start:=false``."""
    return spin_node('actuator', Actuator, args)
