"""Checking incoming actuator commands before they reach the model (pure functions, no node).

A command that fails a check raises :class:`CommandRejected` with a message naming the problem; the
simulator logs it, counts it on ``/diagnostics`` and carries on with the command in force unchanged.
"""

from __future__ import annotations

import array
import contextlib
import logging
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..interface import trajectory_cdr, wire
from ..interface.stamps import seconds
from ..physics.trajectory import CommandLimits
from ..physics.waveforms import StrokeTable, trajectory_table

MAX_POINTS = 100_000     # points of one trajectory message: longer strokes go in windows
_LOG = logging.getLogger('micro_feeder.commands')


_warned: set[str] = set()


def _warn_once(message: str) -> None:
    """Log ``message`` as a warning the first time only (per process)."""
    if message not in _warned:
        _warned.add(message)
        _LOG.warning(message)


class CommandRejected(ValueError):
    """An actuator command that is not applied; the message says why."""


DUPLICATE = 'a duplicate of the command applied'   # in the reason of a refused duplicate: its first copy applied


class DuplicateCommand(CommandRejected):
    """A copy of a command already applied (same identity): not applied again. A sender that resends until
    the receipt names its command (a message lost in discovery) makes these; they are not faults."""


@dataclass(frozen=True)
class TrajectoryCommand:
    """A checked ``actuator/trajectory``: knots in the simulator's joint order, SI units.

    ``command_id``: the header's frame_id, which a sender may use to name the command (the actuator does:
    ``/actuator:b1:w3``); a command whose identity was already applied is refused as a duplicate.
    ``stamp`` (s, sim time; 0 = on receipt); ``offsets`` (n,) time_from_start (s); ``positions`` (n, joints)
    (m); ``velocities`` / ``accelerations`` (n, joints) or ``None`` when absent. No knots = stop.
    """

    stamp: float
    offsets: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None
    accelerations: np.ndarray | None
    command_id: str = ''       # header.frame_id: the sender's identity for the command ('' = none)
    # the interpolation through its own knots from its stamp (a stamped command with a knot at offset 0, as a
    # stream's windows are), made when it is parsed: the simulator parses outside its lock, and applying a
    # window that starts where it is stamped then only installs this table
    own_table: StrokeTable | None = field(default=None, compare=False, repr=False)

    @property
    def is_stop(self) -> bool:
        return self.offsets.size == 0


def _check_range(values: np.ndarray, low: float, high: float, what: str, unit: str, bounds: str = '') -> None:
    """Refuse non-finite values and values outside [low, high] (one example named; ``bounds`` says what the
    interval is)."""
    if values.size == 0 or (values.min() >= low and values.max() <= high):   # a NaN fails both: checked below
        return
    if not np.all(np.isfinite(values)):
        raise CommandRejected(f'{what}: non-finite value')
    bad = float(values[(values < low) | (values > high)].flat[0])
    raise CommandRejected(f'{what} {bad:g} {unit} outside [{low:g}, {high:g}] {unit}{bounds}')


def _check_strokes(values: np.ndarray, limits: tuple[float, float], what: str) -> None:
    _check_range(values, limits[0], limits[1], f'{what}: stroke', 'm', ' (the piezo limits)')


def _field(points: Sequence[JointTrajectoryPoint], attr: str, order: list[int], required: bool) -> np.ndarray | None:
    """(points, joints) array of one field in the simulator's joint order, or None when empty on every
    point (and not ``required``). No per-value Python."""
    n_joints = len(order)
    arrays = [getattr(p, attr) for p in points]
    lengths = np.fromiter(map(len, arrays), dtype=np.int64, count=len(arrays))
    if not required and not lengths.any():
        return None
    if np.any(lengths != n_joints):
        raise CommandRejected(f'trajectory: {attr} must have {n_joints} values (one per joint) on every point'
                              f'{"" if required else " or be empty on all"}, got lengths '
                              f'{np.unique(lengths).tolist()}')
    if all(isinstance(a, array.array) for a in arrays):     # rclpy's messages: one join of the buffers
        table = np.frombuffer(b''.join(arrays), dtype=np.float64).reshape(len(points), n_joints)
    else:                                                  # decoded from a log: lists
        table = np.array(arrays, dtype=float).reshape(len(points), n_joints)
    return table[:, order]


def parse_trajectory(msg: JointTrajectory, joints: Sequence[str], limits: tuple[float, float]) -> TrajectoryCommand:
    """Check a JointTrajectory against the simulator's ``joints`` and stroke ``limits`` (m).

    Rules: every joint named exactly once (no unknown, missing or repeated names; an empty message may
    leave ``joint_names`` empty); at most :data:`MAX_POINTS` points (refused before anything is read);
    ``time_from_start`` >= 0 and strictly increasing; positions on every knot, velocities on every knot
    or none, accelerations only with velocities, on every knot or none; every array one value per joint;
    all values finite; positions within the piezo limits, velocities and accelerations within
    :class:`~micro_feeder.physics.trajectory.CommandLimits`; the header stamp not negative. A
    positions-only trajectory is accepted with a one-time warning (its linear interpolation has zero
    acceleration between knots, so the surface pushes the part only at the knots).
    What the interpolation does between knots is checked when the trajectory is applied
    (:meth:`~micro_feeder.sim.stepper.Stepper.command_trajectory`).
    """
    points = msg.points

    def knots(order: list[int]) -> tuple[np.ndarray, ...]:
        sec = np.fromiter((p.time_from_start.sec for p in points), dtype=np.int64, count=len(points))
        nanosec = np.fromiter((p.time_from_start.nanosec for p in points), dtype=np.int64, count=len(points))
        return (sec + nanosec * 1e-9, _field(points, 'positions', order, True),
                _field(points, 'velocities', order, False), _field(points, 'accelerations', order, False))

    return _checked(seconds(msg.header.stamp), list(msg.joint_names), len(points), knots, joints, limits,
                    msg.header.frame_id)


def parse_trajectory_cdr(data: bytes, joints: Sequence[str], limits: tuple[float, float],
                         deserialize: Callable[[bytes], Any] | None = None) -> TrajectoryCommand:
    """:func:`parse_trajectory` of a serialized JointTrajectory, reading the knots of the usual layouts
    (positions, with or without velocities and accelerations, the same on every point) with numpy instead of
    deserializing one Python object per point; any other layout is deserialized by ``deserialize`` (the
    log tools give their decoder), by default rclpy's (:mod:`~micro_feeder.interface.wire`). A message of
    more than :data:`MAX_POINTS` points is refused without reading them. Raises :class:`CommandRejected`
    (also for bytes that are not a JointTrajectory)."""
    decoded = trajectory_cdr.decode(data, MAX_POINTS)
    if needs_deserializing(decoded):
        try:
            msg = (deserialize or _wire_trajectory)(data)
        except Exception as err:  # rclpy raises several types for malformed bytes
            raise CommandRejected(f'trajectory: cannot deserialize: {err}') from err
        return parse_trajectory(msg, joints, limits)
    records = decoded.records

    def knots(order: list[int]) -> tuple[np.ndarray, ...]:
        offsets = records['sec'].astype(np.int64) + records['nanosec'] * 1e-9
        columns = slice(None) if order == list(range(len(order))) else order    # no gather in joint order
        return offsets, *(records[f][:, columns] if f in records else None for f in ('pos', 'vel', 'acc'))

    return _checked(decoded.stamp, decoded.names, decoded.n_points, knots, joints, limits, decoded.frame_id)


def needs_deserializing(decoded: trajectory_cdr.Decoded | None) -> bool:
    """True when :func:`parse_trajectory_cdr` deserializes the message (its points are not in the layout
    :func:`~micro_feeder.interface.trajectory_cdr.decode` reads)."""
    return decoded is None or (decoded.records is None and 0 < decoded.n_points <= MAX_POINTS)


def _wire_trajectory(data: bytes) -> JointTrajectory:
    return wire.deserialize(data, JointTrajectory)


def _checked(stamp: float, names: list[str], n_points: int, knots: Callable[[list[int]], tuple[np.ndarray, ...]],
             joints: Sequence[str], limits: tuple[float, float], command_id: str = '') -> TrajectoryCommand:
    """The checks of :func:`parse_trajectory`; ``knots(order)`` reads (offsets, positions, velocities or
    None, accelerations or None) with columns in the simulator's joint ``order``, only once the cheap
    checks have passed."""
    if stamp < 0:
        raise CommandRejected(f'trajectory: negative header.stamp {stamp:g} s')
    if not n_points:
        return TrajectoryCommand(stamp, np.zeros(0), np.zeros((0, len(joints))), None, None, command_id)
    if n_points > MAX_POINTS:
        raise CommandRejected(f'trajectory: {n_points} points, more than {MAX_POINTS}: send long strokes '
                              'in windows (each replaces the schedule from its start on), as the actuator does')
    column = {name: i for i, name in enumerate(names)}
    known = set(joints)
    unknown = [n for n in names if n not in known]
    if unknown:
        raise CommandRejected(f'trajectory: unknown joint names {unknown} (known: {list(joints)})')
    if len(column) != len(names):
        raise CommandRejected(f'trajectory: repeated joint names in {names}')
    missing = [n for n in joints if n not in column]
    if missing:
        raise CommandRejected(f'trajectory: joints {missing} missing (every joint must be commanded)')
    offsets, positions, velocities, accelerations = knots([column[n] for n in joints])
    if offsets[0] < 0 or np.any(np.diff(offsets) <= 0):
        bad = int(np.argmax(offsets < 0)) if offsets[0] < 0 else int(np.argmax(np.diff(offsets) <= 0)) + 1
        raise CommandRejected(f'trajectory: time_from_start must be >= 0 and strictly increasing, got '
                              f'{offsets[max(bad - 1, 0)]:.9f} s then {offsets[bad]:.9f} s at point {bad}')
    if accelerations is not None and velocities is None:
        raise CommandRejected('trajectory: accelerations given without velocities')
    bounds = CommandLimits(*limits)
    _check_strokes(positions, limits, 'trajectory')
    if velocities is not None:
        _check_range(velocities, -bounds.velocity, bounds.velocity, 'trajectory: velocity', 'm/s')
    else:
        _warn_once('positions-only trajectory: joint_trajectory_controller interpolates it linearly, so the '
                   'stroke acceleration is zero between knots and the surface only pushes the part at the '
                   'knots (it will barely move); send velocities and accelerations for smooth strokes')
    if accelerations is not None:
        _check_range(accelerations, -bounds.acceleration, bounds.acceleration, 'trajectory: acceleration',
                     'm/s^2')
    own_table = None
    if stamp > 0.0 and offsets[0] == 0.0:
        with contextlib.suppress(ValueError):      # made again, and refused with the reason, when applied
            own_table = trajectory_table(stamp + offsets, positions, velocities, accelerations)
    return TrajectoryCommand(stamp, offsets, positions, velocities, accelerations, command_id, own_table)


def parse_setpoints(data: Sequence[float], n_actuators: int, limits: tuple[float, float]) -> np.ndarray:
    """Check an ``actuator/command`` (Float64MultiArray data): one finite stroke (m) per actuator within
    the piezo ``limits``. Returns the set-points as an array."""
    values = np.frombuffer(data, dtype=np.float64) if isinstance(data, array.array) else np.array(data, dtype=float)
    if values.size != n_actuators:
        raise CommandRejected(f'command: {values.size} values for {n_actuators} actuators')
    _check_strokes(values, limits, 'command')
    return values.copy()


def start_time(stamp: float, now: float) -> float:
    """When a command takes effect (s, sim time): its stamp, or now if the stamp is 0 or already past
    (joint_trajectory_controller semantics; knots before that time are dropped)."""
    return now if stamp == 0.0 or stamp < now or math.isnan(stamp) else stamp
