"""Checking incoming actuator commands before they reach the model (pure functions, no node).

A command that fails a check raises :class:`CommandRejected` with a message naming the problem; the
simulator logs it, counts it on ``/diagnostics`` and carries on with the command in force unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from trajectory_msgs.msg import JointTrajectory

from .messages import seconds


class CommandRejected(ValueError):
    """An actuator command that is not applied; the message says why."""


@dataclass(frozen=True)
class TrajectoryCommand:
    """A checked ``actuator/trajectory``: knots in the simulator's joint order, SI units.

    ``stamp`` (s, sim time; 0 = on receipt); ``offsets`` (n,) time_from_start (s); ``positions`` (n, joints)
    (m); ``velocities`` / ``accelerations`` (n, joints) or ``None`` when absent. No knots = stop.
    """

    stamp: float
    offsets: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray | None
    accelerations: np.ndarray | None

    @property
    def is_stop(self) -> bool:
        return self.offsets.size == 0


def joint_names(n_actuators: int) -> list[str]:
    """The actuator joint names ``piezo_0`` ... in actuator order."""
    return [f'piezo_{k}' for k in range(n_actuators)]


def _check_strokes(values: np.ndarray, limits: tuple[float, float], what: str) -> None:
    if not np.all(np.isfinite(values)):
        raise CommandRejected(f'{what}: non-finite value')
    low, high = limits
    outside = (values < low) | (values > high)
    if np.any(outside):
        bad = float(values[outside].flat[0])
        raise CommandRejected(f'{what}: stroke {bad:g} m outside the piezo limits [{low:g}, {high:g}] m')


def parse_trajectory(msg: JointTrajectory, joints: Sequence[str], limits: tuple[float, float]) -> TrajectoryCommand:
    """Check a JointTrajectory against the simulator's ``joints`` and stroke ``limits`` (m).

    Rules: every joint named exactly once (no unknown, missing or repeated names; an empty message may
    leave ``joint_names`` empty); ``time_from_start`` >= 0 and strictly increasing; positions on every
    knot, velocities on every knot or none, accelerations only with velocities, on every knot or none;
    every array one value per joint; all values finite; positions within the piezo limits; the header
    stamp not negative.
    """
    stamp = seconds(msg.header.stamp)
    if stamp < 0:
        raise CommandRejected(f'trajectory: negative header.stamp {stamp:g} s')
    points = msg.points
    if not points:
        return TrajectoryCommand(stamp, np.zeros(0), np.zeros((0, len(joints))), None, None)
    names = list(msg.joint_names)
    unknown = [n for n in names if n not in joints]
    if unknown:
        raise CommandRejected(f'trajectory: unknown joint names {unknown} (known: {list(joints)})')
    if len(set(names)) != len(names):
        raise CommandRejected(f'trajectory: repeated joint names in {names}')
    missing = [n for n in joints if n not in names]
    if missing:
        raise CommandRejected(f'trajectory: joints {missing} missing (every joint must be commanded)')
    order = [names.index(n) for n in joints]
    offsets = np.array([seconds(p.time_from_start) for p in points])
    if offsets[0] < 0 or np.any(np.diff(offsets) <= 0):
        raise CommandRejected(f'trajectory: time_from_start must be >= 0 and strictly increasing, got '
                              f'{offsets.tolist()}')

    def field(attr: str, required: bool) -> np.ndarray | None:
        lengths = {len(getattr(p, attr)) for p in points}
        if lengths == {0} and not required:
            return None
        if lengths != {len(joints)}:
            raise CommandRejected(f'trajectory: {attr} must have {len(joints)} values (one per joint) on '
                                  f'every point{"" if required else " or be empty on all"}, got lengths '
                                  f'{sorted(lengths)}')
        table = np.array([list(getattr(p, attr)) for p in points], dtype=float)[:, order]
        if not np.all(np.isfinite(table)):
            raise CommandRejected(f'trajectory: non-finite value in {attr}')
        return table

    positions = field('positions', True)
    velocities = field('velocities', False)
    accelerations = field('accelerations', False)
    if accelerations is not None and velocities is None:
        raise CommandRejected('trajectory: accelerations given without velocities')
    _check_strokes(positions, limits, 'trajectory')
    return TrajectoryCommand(stamp, offsets, positions, velocities, accelerations)


def parse_setpoints(data: Sequence[float], n_actuators: int, limits: tuple[float, float]) -> np.ndarray:
    """Check an ``actuator/command`` (Float64MultiArray data): one finite stroke (m) per actuator within
    the piezo ``limits``. Returns the set-points as an array."""
    values = np.array(data, dtype=float)
    if values.size != n_actuators:
        raise CommandRejected(f'command: {values.size} values for {n_actuators} actuators')
    _check_strokes(values, limits, 'command')
    return values


def start_time(stamp: float, now: float) -> float:
    """When a command takes effect (s, sim time): its stamp, or now if the stamp is 0 or already past
    (joint_trajectory_controller semantics; knots before that time are dropped)."""
    return now if stamp == 0.0 or stamp < now or math.isnan(stamp) else stamp
