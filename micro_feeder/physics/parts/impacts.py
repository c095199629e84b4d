"""Impacts between two equal parts along the feeder, and trains of parts pressed together (docs/parts.md).

Pure arithmetic on velocities (m/s) and positions (m): the parts model (:mod:`.model`) decides when these
apply. Equal masses throughout (the parts are of one type).
"""

from __future__ import annotations

from collections.abc import Sequence


def newton_impact(v_rear: float, v_front: float, restitution: float) -> tuple[float, float]:
    """Velocities after a central impact of two equal masses with Newton's restitution ``restitution`` e:
    the relative velocity reverses and shrinks by e, momentum is conserved.

    With u = v_rear − v_front > 0 the approach speed and v_c = (v_rear + v_front)/2 the centre-of-mass
    velocity: v_rear' = v_c − e u/2, v_front' = v_c + e u/2 (e = 1: the velocities are exchanged).
    """
    approach = v_rear - v_front
    centre = 0.5 * (v_rear + v_front)
    return centre - 0.5 * restitution * approach, centre + 0.5 * restitution * approach


def common_velocity(velocities: Sequence[float]) -> float:
    """The velocity of a train of equal parts that move as one: their mean (momentum conserved)."""
    return sum(velocities) / len(velocities)


def packed_positions(positions: Sequence[float], size: float, fixed: int | None = None) -> list[float]:
    """Positions of a train of parts put in contact (centres exactly ``size`` apart, m), in order.

    With ``fixed`` (an index), that part stays where it is and the others are placed against it (a train
    held by a stuck part); otherwise the train's mean position is kept (its centre of mass does not jump).
    """
    n = len(positions)
    if fixed is None:
        centre = sum(positions) / n
        return [centre + (k - 0.5 * (n - 1)) * size for k in range(n)]
    return [positions[fixed] + (k - fixed) * size for k in range(n)]


def pooled_velocities(velocities: Sequence[float]) -> list[float]:
    """Velocities of a row of touching equal parts after they press on each other plastically: no part faster
    than the one ahead of it, momentum conserved, groups that would approach merged into trains at their
    mean velocity (m/s, in order along the feeder).

    This is the isotonic (non-decreasing) least-squares fit of the velocities, found by pooling adjacent
    violators: for equal masses the plastic solution of simultaneous contacts in a row (the kinetic energy
    lost is the least that leaves no pair approaching).
    """
    pools: list[list[float]] = []                   # [sum of velocities, number of parts]
    for velocity in velocities:
        pools.append([velocity, 1.0])
        while len(pools) > 1 and pools[-2][0] * pools[-1][1] > pools[-1][0] * pools[-2][1]:
            total, count = pools.pop()
            pools[-1][0] += total
            pools[-1][1] += count
    return [total / count for total, count in pools for _ in range(int(count))]
