"""Building the simulator's messages from a physics :class:`Observation` (pure functions, no node).

Frames (docs/dynamics.md §1, REP 103): ``feeder`` has x along the feeder, z up, y to the left; ``contact`` sits
at the part with x along the surface tangent and z along its normal, tilted by θ = atan(h_x) about y.
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable, Sequence

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import Point, PoseStamped, TwistStamped, WrenchStamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint
from visualization_msgs.msg import Marker, MarkerArray

from ..physics.dynamics import Observation
from ..physics.surface import surface_profile
from . import wire
from .cdr import ENCAPSULATION, STAMP, put_string, put_uint32
from .names import CONTACT_FRAME, FEEDER_FRAME
from .stamps import stamp_parts, to_duration


def command_status(t: float, frame_id: str, name: str, topic: str, command_id: str, reason: str) -> bytes:
    """``simulator/command_status`` (a DiagnosticArray, as CDR bytes): a command refused (or dropped) at sim
    time ``t`` (s), stamped and framed as its receipt (``frame_id`` = topic[#identity]); one ERROR status
    ``name``, message = the reason, with the keys ``topic``, ``command_id``, ``t_s`` (the receipt time, a
    float's repr). Written by hand because a flood of refused commands is answered one by one: building
    the rclpy message and letting ``publish`` serialize it cost ~30 µs each, these bytes ~3 µs."""
    payload = bytearray(ENCAPSULATION + STAMP.pack(*stamp_parts(t)))
    put_string(payload, frame_id)
    put_uint32(payload, 1)                                      # one status
    payload += DiagnosticStatus.ERROR                           # level: one byte
    for text in (name, reason, 'micro_feeder'):                 # name, message, hardware_id
        put_string(payload, text)
    put_uint32(payload, 3)                                      # values
    for text in ('topic', topic, 'command_id', command_id, 't_s', repr(t)):
        put_string(payload, text)
    return bytes(payload)


def header_bytes(t: float, frame_id: str) -> bytes:
    """A ``std_msgs/Header`` stamped at sim time ``t`` (s) with ``frame_id``, as CDR bytes: the simulator's
    command receipts, up to ~200 a second with 64 actuators streaming (an rclpy Header cost ~40 µs each)."""
    payload = bytearray(ENCAPSULATION + STAMP.pack(*stamp_parts(t)))
    put_string(payload, frame_id)      # every receipt's frame is new (it names the command): nothing to cache
    return bytes(payload)


@functools.cache
def contact_state_bytes(mode: str) -> bytes:
    """The serialized ``particle/contact_state`` String of ``mode`` (one per mode, serialized once: it is
    published at every mode change, up to a few times a tick)."""
    return wire.serialize(String(data=mode))


def tilt_quaternion(theta: float) -> tuple[float, float, float, float]:
    """(x, y, z, w) of the contact frame's orientation in ``feeder``: a rotation by −θ about y, so that the
    contact x axis (cos θ, 0, sin θ) points up the slope when h_x = tan θ > 0."""
    return 0.0, math.sin(-theta / 2.0), 0.0, math.cos(-theta / 2.0)


STAMP_SENTINEL = (1589706734, 987654321)        # sec, nanosec: a stamp no real message carries


def _sentinel(i: int) -> float:
    """The i-th placeholder float64: a large finite value whose bytes occur nowhere else in a template."""
    return struct.unpack('<d', struct.pack('<Q', 0x7FE1_2345_6789_A000 + i))[0]


class SerializedTemplate:
    """A message serialized once, whose header stamp and float64 fields are then rewritten in place in its
    CDR bytes: what the simulator publishes every tick (``Publisher.publish(bytes)``).

    Building the rclpy message and letting ``publish`` convert and serialize it cost ~3x more than
    patching bytes; the subscribers receive the same CDR. ``msg``: the message with every constant field
    set; ``stamp``: its Time to patch (one header's, or one shared by several headers); ``runs``: setters
    that each put a list of placeholder values into fields laid out contiguously in CDR (e.g. a Pose's 7
    doubles, a JointState's positions), with their lengths. The placeholders are located in the serialized
    template, so no offset is computed by hand.
    """

    def __init__(self, msg: object, stamp: Time | None,
                 runs: Sequence[tuple[Callable[[list[float]], None], int]]):
        if stamp is not None:           # None: a message without a stamp
            stamp.sec, stamp.nanosec = STAMP_SENTINEL
        first = 0
        for setter, length in runs:
            setter([_sentinel(first + i) for i in range(length)])
            first += length
        template = wire.serialize(msg)
        self._buffer = bytearray(template)
        self._stamps_at = _offsets(template, STAMP.pack(*STAMP_SENTINEL)) if stamp is not None else []
        self._runs: list[tuple[int, struct.Struct]] = []
        first = 0
        for _, length in runs:
            at = _offset(template, struct.pack(f'<{length}d', *(_sentinel(first + i) for i in range(length))))
            self._runs.append((at, struct.Struct(f'<{length}d')))
            first += length
        # the runs as float64 arrays over the buffer (unaligned views: CDR counts from after its 4-byte header)
        self._views = [np.frombuffer(self._buffer, dtype='<f8', count=layout.size // 8, offset=at)
                       for at, layout in self._runs]

    def serialize(self, sec: int, nanosec: int, *runs: Sequence[float]) -> bytes:
        """The CDR bytes with the stamp (sec, nanosec) and each run's values (as many as in the template)."""
        buffer = self._buffer
        for at in self._stamps_at:
            STAMP.pack_into(buffer, at, sec, nanosec)
        for (at, layout), view, values in zip(self._runs, self._views, runs, strict=True):
            if isinstance(values, np.ndarray):      # one copy (unpacking 2 x 64 joints into struct took 10 µs)
                if values.shape != view.shape:
                    raise ValueError(f'{values.size} values for a run of {view.size} in the template')
                view[:] = values
            else:
                layout.pack_into(buffer, at, *values)
        return bytes(buffer)


def _offset(template: bytes, pattern: bytes) -> int:
    found = _occurrences(template, pattern)
    if len(found) != 1:
        raise ValueError('SerializedTemplate: a placeholder is not laid out contiguously, or not once')
    return found[0]


def _offsets(template: bytes, pattern: bytes) -> list[int]:
    """Where ``pattern`` occurs in ``template`` (at least once: a message may share one stamp among headers)."""
    found = _occurrences(template, pattern)
    if not found:
        raise ValueError('SerializedTemplate: the stamp placeholder is not in the message')
    return found


def _occurrences(template: bytes, pattern: bytes) -> list[int]:
    found = []
    at = template.find(pattern)
    while at >= 0:
        found.append(at)
        at = template.find(pattern, at + 1)
    return found


def _setter(*targets: tuple[object, str]) -> Callable[[list[float]], None]:
    """A run setter writing values one by one into the (object, attribute) ``targets``."""
    def put(values: list[float]) -> None:
        for (obj, attr), value in zip(targets, values, strict=True):
            setattr(obj, attr, value)
    return put


class StateMessages:
    """The serialized state messages published every tick (bytes, from :class:`SerializedTemplate`).

    * ``pose``: the part's position (x, 0, z) (m) in ``feeder`` with the contact-frame tilt as orientation;
    * ``twist``: its velocity (ẋ, 0, ż) (m/s) in ``feeder``; angular velocity 0 (a point mass);
    * ``wrench``: the force on the part from the surface in ``contact``: x = friction T (N), z = normal load
      N (N; > 0 presses, < 0 adhesion holding; in flight −F_att, the attraction); torque 0;
    * ``joints``: actual strokes (m) and stroke velocities (m/s) per actuator;
    * ``clock``: the sim time.
    """

    def __init__(self, joint_names: Sequence[str]):
        pose = PoseStamped(header=Header(frame_id=FEEDER_FRAME))
        p, q = pose.pose.position, pose.pose.orientation
        self._pose = SerializedTemplate(pose, pose.header.stamp,
                                        [(_setter((p, 'x'), (p, 'y'), (p, 'z'), (q, 'x'), (q, 'y'), (q, 'z'),
                                                  (q, 'w')), 7)])
        twist = TwistStamped(header=Header(frame_id=FEEDER_FRAME))
        self._twist = SerializedTemplate(twist, twist.header.stamp, [(_vector_setter(twist.twist), 6)])
        wrench = WrenchStamped(header=Header(frame_id=CONTACT_FRAME))
        self._wrench = SerializedTemplate(wrench, wrench.header.stamp, [(_vector_setter(wrench.wrench), 6)])
        joints = JointState(header=Header(frame_id=FEEDER_FRAME), name=list(joint_names))
        n = len(joint_names)
        self._joints = SerializedTemplate(joints, joints.header.stamp,
                                          [(lambda v: setattr(joints, 'position', v), n),
                                           (lambda v: setattr(joints, 'velocity', v), n)])
        clock = Clock()
        self._clock = SerializedTemplate(clock, clock.clock, [])
        self.stamp = Time()
        self.pose = self.twist = self.wrench = self.joints = self.clock = b''

    def update(self, obs: Observation, stroke_velocities: np.ndarray) -> Time:
        """Serialize every message from ``obs`` at its sim time; returns that time as a ROS Time."""
        sec, nanosec = stamp_parts(obs.t)
        self.pose = self._pose.serialize(sec, nanosec, (obs.x, 0.0, obs.z, *tilt_quaternion(obs.theta)))
        self.twist = self._twist.serialize(sec, nanosec, (obs.xdot, 0.0, obs.zdot, 0.0, 0.0, 0.0))
        self.wrench = self._wrench.serialize(sec, nanosec, (obs.friction, 0.0, obs.normal_load, 0.0, 0.0, 0.0))
        self.joints = self._joints.serialize(sec, nanosec, obs.strokes, stroke_velocities)
        self.clock = self._clock.serialize(sec, nanosec)
        self.stamp = Time(sec=sec, nanosec=nanosec)
        return self.stamp


def _vector_setter(pair: object) -> Callable[[list[float]], None]:
    """Setter of a Twist's (linear, angular) or a Wrench's (force, torque) six doubles."""
    first, second = (pair.linear, pair.angular) if hasattr(pair, 'linear') else (pair.force, pair.torque)
    return _setter(*((v, axis) for v in (first, second) for axis in 'xyz'))


class SurfaceMarkers:
    """``surface/markers`` as CDR bytes: a :class:`SerializedTemplate` per contact mode (the part's colour),
    made the first time the mode is drawn, whose heights and part position are patched each time.

    The array holds the deformed surface as a LINE_STRIP over ``xs`` (m; id 0) and the part as a sphere of
    ``part_size`` (m; id 1, coloured by contact mode), in ``feeder``, namespace ``micro_feeder``, replaced
    in place by the viewer every time. Updating the 200-point strip's rclpy objects and letting ``publish``
    serialize them cost ~0.3 ms per message; the heights come from a basis computed once (a profile is
    ``basis @ strokes``).
    """

    def __init__(self, xs: np.ndarray, centers: Sequence[float], widths: Sequence[float], part_size: float,
                 track_lift: float | None = None):
        xs = np.asarray(xs, dtype=float)
        self._part_size = part_size
        # (points, actuators); a track (``track_lift`` = sin β) is flat at s sin β, drawn around the part
        if track_lift is None:
            self._basis = surface_profile(xs, np.eye(len(centers)), centers, widths)
        else:                   # the last actuator moves the track normal to its surface (either drive)
            self._basis = np.zeros((xs.size, len(centers)))
            self._basis[:, -1] = track_lift
        self._around_part = None if track_lift is None else xs - float(np.mean(xs))
        self._line = np.zeros((xs.size, 3))                                          # x, y, z per point
        self._line[:, 0] = xs
        self._templates: dict[str, SerializedTemplate] = {}

    def update(self, obs: Observation, stamp: Time) -> bytes:
        """The serialized MarkerArray of ``obs`` at ``stamp``."""
        if self._around_part is not None:
            self._line[:, 0] = obs.x + self._around_part
        self._line[:, 2] = self._basis @ obs.strokes
        template = self._templates.get(obs.mode)
        if template is None:
            template = self._templates[obs.mode] = self._template(_mode_color(obs.mode))
        return template.serialize(stamp.sec, stamp.nanosec, self._line.reshape(-1),
                                  (obs.x, 0.0, obs.z + self._part_size / 2.0))

    def _template(self, color: tuple[float, float, float, float]) -> SerializedTemplate:
        header = Header(frame_id=FEEDER_FRAME)          # shared by both markers
        line = Marker(header=header, ns='micro_feeder', id=0, type=Marker.LINE_STRIP, action=Marker.ADD)
        line.pose.orientation.w = 1.0
        line.scale.x = self._part_size / 10.0
        line.color.r, line.color.g, line.color.b, line.color.a = 0.6, 0.6, 0.7, 1.0
        line.points = [Point() for _ in range(self._line.shape[0])]
        part = Marker(header=header, ns='micro_feeder', id=1, type=Marker.SPHERE, action=Marker.ADD)
        part.pose.orientation.w = 1.0
        part.scale.x = part.scale.y = part.scale.z = self._part_size
        part.color.r, part.color.g, part.color.b, part.color.a = color
        position = part.pose.position
        points = _setter(*((point, axis) for point in line.points for axis in 'xyz'))
        return SerializedTemplate(MarkerArray(markers=[line, part]), header.stamp,
                                  [(points, 3 * len(line.points)), (_setter((position, 'x'), (position, 'y'),
                                                                             (position, 'z')), 3)])


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

