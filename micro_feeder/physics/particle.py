"""The part: a point mass carrying a nominal contact area (seed Table 1), and where the parts start.

``particle.x0`` and ``particle.v0`` take one number (one part, the seed's case) or a list (one entry per
part, in order along the feeder); parts meet as hard bodies ``particle.size`` long with restitution
``particle.restitution`` between them (docs/parts.md).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

from .parameters import ParameterError, ParameterGroup, param

TOUCHING = 1e-12    # m: centres closer than particle.size by at most this (rounding) touch, not overlap


@dataclass(frozen=True)
class ParticleParams(ParameterGroup):
    """Mass, nominal contact area, size and restitution of the parts, where they start, and gravity."""

    prefix = 'particle'

    mass: float = param(2e-9, 'mass of the part (a micro-part: 1e-15 kg to 1 g)', 'kg', ge=1e-15, le=1e-3)
    area: float = param(1e-8, 'nominal contact area A_n (100 um x 100 um)', 'm^2', gt=0, le=1e-2)
    x0: float | tuple[float, ...] = param(
        0.5e-3, 'starting position along the feeder (frame feeder, x); a list places one part per entry, in '
        'increasing order, centres at least particle.size apart', 'm', kind='float_or_list', ge=-1.0, le=1.0)
    v0: float | tuple[float, ...] = param(
        0.0, 'starting velocity along the feeder (frame feeder, x); a number for every part, or a list with '
        'one entry per particle.x0 entry (0: the part starts stuck; else sliding)', 'm/s',
        kind='float_or_list', ge=-10.0, le=10.0)
    size: float = param(100e-6, 'length of a part along the feeder: the distance between two centres in contact',
                        'm', gt=0, le=1e-2)
    restitution: float = param(0.0, "Newton's restitution e between two parts (0: plastic, the parts move on "
                                    'together; 1: elastic)', '', ge=0.0, le=1.0)
    gravity: float = param(9.81, 'gravitational acceleration (along -z of frame feeder)', 'm/s^2', ge=0, le=1e3,
                           name='gravity')

    def __post_init__(self) -> None:
        super().__post_init__()
        positions = self.start_positions
        if isinstance(self.v0, tuple) and len(self.v0) != len(positions):
            raise ParameterError('particle.v0', list(self.v0),
                                 f'one entry per particle.x0 entry ({len(positions)}), or a single number')
        for left, right in itertools.pairwise(positions):
            if right - left < self.size - TOUCHING:
                raise ParameterError('particle.x0', list(positions),
                                     f'parts in increasing order with centres at least particle.size = '
                                     f'{self.size:g} m apart ({left:g} and {right:g} are not)')

    @property
    def weight_n(self) -> float:
        """Weight m g in newtons."""
        return self.mass * self.gravity

    @property
    def n_parts(self) -> int:
        """How many parts ``particle.x0`` places."""
        return len(self.start_positions)

    @property
    def start_positions(self) -> tuple[float, ...]:
        """Starting position of every part (m), in order along the feeder."""
        return self.x0 if isinstance(self.x0, tuple) else (self.x0,)

    @property
    def start_velocities(self) -> tuple[float, ...]:
        """Starting velocity of every part (m/s)."""
        return self.v0 if isinstance(self.v0, tuple) else (self.v0,) * self.n_parts
