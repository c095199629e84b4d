"""The part: a point mass carrying a nominal contact area (seed Table 1)."""

from __future__ import annotations

from dataclasses import dataclass

from .parameters import ParameterGroup, param


@dataclass(frozen=True)
class ParticleParams(ParameterGroup):
    """Mass, nominal contact area and starting position of the part, and gravity."""

    prefix = 'particle'

    mass: float = param(2e-9, 'mass of the part (a micro-part: 1e-15 kg to 1 g)', 'kg', ge=1e-15, le=1e-3)
    area: float = param(1e-8, 'nominal contact area A_n (100 um x 100 um)', 'm^2', gt=0, le=1e-2)
    x0: float = param(0.5e-3, 'starting position along the feeder (frame feeder, x)', 'm', ge=-1.0, le=1.0)
    gravity: float = param(9.81, 'gravitational acceleration (along -z of frame feeder)', 'm/s^2', ge=0, le=1e3,
                           name='gravity')

    @property
    def weight_n(self) -> float:
        """Weight m g in newtons."""
        return self.mass * self.gravity
