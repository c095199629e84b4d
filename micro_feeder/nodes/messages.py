"""Building the simulator's messages from a physics :class:`Observation` (pure functions, no node).

Frames (docs/dynamics.md §1, REP 103): ``feeder`` has x along the feeder, z up, y to the left; ``contact`` sits
at the part with x along the surface tangent and z along its normal, tilted by θ = atan(h_x) about y.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Point, PoseStamped, TwistStamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from ..physics.dynamics import Observation
from ..physics.surface import surface_profile

FEEDER_FRAME = 'feeder'
CONTACT_FRAME = 'contact'


def to_time(t: float) -> Time:
    """Sim time ``t`` (s, >= 0) as a ROS Time, rounded to the nanosecond."""
    ns = round(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def to_duration(t: float) -> Duration:
    """A duration ``t`` (s, >= 0) as a ROS Duration, rounded to the nanosecond."""
    ns = round(t * 1e9)
    return Duration(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def seconds(t: Time | Duration) -> float:
    """A ROS Time or Duration in seconds (the inverse of :func:`to_time` / :func:`to_duration`)."""
    return t.sec + t.nanosec * 1e-9


def header_stamp(data: bytes) -> float:
    """``header.stamp`` (s) of a serialized message that starts with a Header (CDR, either byte order), read
    without deserializing the rest; 0 when the bytes are too short."""
    if len(data) < 12:
        return 0.0
    sec, nanosec = struct.unpack_from('<iI' if data[1] == 1 else '>iI', data, 4)
    return sec + nanosec * 1e-9


def tilt_quaternion(theta: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of the contact frame's orientation in ``feeder``: a rotation by −θ about y, so that the
    contact x axis (cos θ, 0, sin θ) points up the slope when h_x = tan θ > 0."""
    return 0.0, math.sin(-theta / 2.0), 0.0, math.cos(-theta / 2.0)


class StateMessages:
    """The state messages published every tick, allocated once and updated in place.

    Building five messages per tick (nested Header/Time/Point... constructors) was a third of the
    simulator's Python time at 1 kHz; rclpy serialises a message inside ``publish``, so reusing the same
    objects is safe.

    * ``pose``: the part's position (x, 0, z) (m) in ``feeder`` with the contact-frame tilt as orientation;
    * ``twist``: its velocity (ẋ, 0, ż) (m/s) in ``feeder``; angular velocity 0 (a point mass);
    * ``wrench``: the force on the part from the surface in ``contact``: x = friction T (N), z = normal load
      N (N; > 0 presses, < 0 adhesion holding; in flight −F_att, the attraction); torque 0;
    * ``joints``: actual strokes (m) and stroke velocities (m/s) per actuator;
    * ``clock``: the sim time.
    """

    def __init__(self, joint_names: Sequence[str]):
        self.pose = PoseStamped(header=Header(frame_id=FEEDER_FRAME))
        self.twist = TwistStamped(header=Header(frame_id=FEEDER_FRAME))
        self.wrench = WrenchStamped(header=Header(frame_id=CONTACT_FRAME))
        self.joints = JointState(header=Header(frame_id=FEEDER_FRAME), name=list(joint_names))
        self.clock = Clock()
        self._stamps = [m.header.stamp for m in (self.pose, self.twist, self.wrench, self.joints)]
        self._stamps.append(self.clock.clock)

    def update(self, obs: Observation, stroke_velocities: np.ndarray) -> Time:
        """Fill every message from ``obs`` at its sim time; returns that time as a ROS Time."""
        ns = round(obs.t * 1e9)
        sec, nanosec = ns // 1_000_000_000, ns % 1_000_000_000
        for stamp in self._stamps:
            stamp.sec, stamp.nanosec = sec, nanosec
        position = self.pose.pose.position
        position.x, position.z = obs.x, obs.z
        q = self.pose.pose.orientation
        q.x, q.y, q.z, q.w = tilt_quaternion(obs.theta)
        linear = self.twist.twist.linear
        linear.x, linear.z = obs.xdot, obs.zdot
        force = self.wrench.wrench.force
        force.x, force.z = obs.friction, obs.normal_load
        self.joints.position = obs.strokes.tolist()
        self.joints.velocity = np.asarray(stroke_velocities, dtype=float).tolist()
        return self.clock.clock


class SurfaceMarkers:
    """``surface/markers``, allocated once per model and updated in place (as :class:`StateMessages`).

    ``array`` holds the deformed surface as a LINE_STRIP over ``xs`` (m; id 0) and the part as a sphere of
    ``part_size`` (m; id 1, coloured by contact mode), in ``feeder``, namespace ``micro_feeder``, replaced
    in place by the viewer every time. Rebuilding the 200-point strip (a Point message per point) cost more
    than publishing it; updating only the heights costs a few percent of that.
    """

    def __init__(self, xs: np.ndarray, centers: Sequence[float], widths: Sequence[float], part_size: float):
        self._xs = np.asarray(xs, dtype=float)
        self._centers, self._widths = centers, widths
        self._part_size = part_size
        self._header = Header(frame_id=FEEDER_FRAME)          # shared by both markers
        line = Marker(header=self._header, ns='micro_feeder', id=0, type=Marker.LINE_STRIP, action=Marker.ADD)
        line.pose.orientation.w = 1.0
        line.scale.x = part_size / 10.0
        line.color.r, line.color.g, line.color.b, line.color.a = 0.6, 0.6, 0.7, 1.0
        line.points = [Point(x=x, y=0.0, z=0.0) for x in self._xs.tolist()]
        self._points = line.points
        part = Marker(header=self._header, ns='micro_feeder', id=1, type=Marker.SPHERE, action=Marker.ADD)
        part.pose.orientation.w = 1.0
        part.scale.x = part.scale.y = part.scale.z = part_size
        self._part = part
        self.array = MarkerArray(markers=[line, part])

    def update(self, obs: Observation, stamp: Time) -> MarkerArray:
        """Fill the markers from ``obs`` at ``stamp``; returns :attr:`array`."""
        self._header.stamp.sec, self._header.stamp.nanosec = stamp.sec, stamp.nanosec
        heights = surface_profile(self._xs, obs.strokes, self._centers, self._widths).tolist()
        for point, z in zip(self._points, heights, strict=True):
            point.z = z
        position = self._part.pose.position
        position.x, position.z = obs.x, obs.z + self._part_size / 2.0
        color = self._part.color
        color.r, color.g, color.b, color.a = _mode_color(obs.mode)
        return self.array


def _mode_color(mode: str) -> tuple[float, float, float, float]:
    return {'stuck': (0.2, 0.7, 0.2, 1.0), 'sliding': (0.9, 0.6, 0.1, 1.0)}.get(mode, (0.9, 0.2, 0.2, 1.0))


def trajectory(names: Sequence[str], offsets: np.ndarray, positions: np.ndarray, velocities: np.ndarray,
               accelerations: np.ndarray, stamp: Time) -> JointTrajectory:
    """A JointTrajectory: knots at ``offsets`` (s from the stamp) with (n, joints) positions (m),
    velocities (m/s), accelerations (m/s²)."""
    points = [JointTrajectoryPoint(positions=positions[i].tolist(), velocities=velocities[i].tolist(),
                                   accelerations=accelerations[i].tolist(),
                                   time_from_start=to_duration(float(offsets[i])))
              for i in range(len(offsets))]
    return JointTrajectory(header=Header(stamp=stamp), joint_names=list(names), points=points)

