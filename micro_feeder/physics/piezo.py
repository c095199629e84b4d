"""Optional second-order piezo actuator between the commanded and the actual stroke (docs/dynamics.md §2).

    s̈ = ω_n² (clip(s_cmd, s_min, s_max) − s) − 2 ζ ω_n ṡ,   ω_n = 2π f_n.

The stroke limits saturate the drive (the command is clipped to the stack's travel); an underdamped
stack may still overshoot the limits slightly, as a real one does. Off by default: the surface then
follows the command exactly (the seed's ideal-tracking assumption).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ._jit import jit_inline
from .parameters import ParameterError, ParameterGroup, param


@dataclass(frozen=True)
class PiezoParams(ParameterGroup):
    """Dynamics and travel of the piezo stack that makes the stroke."""

    prefix = 'piezo'

    enabled: bool = param(False, 'filter the commanded stroke through the 2nd-order piezo model')
    natural_frequency: float = param(50e3, 'undamped natural frequency f_n of the loaded stack', 'Hz', gt=0)
    damping: float = param(0.7, 'damping ratio zeta', '', ge=0)
    stroke_min: float = param(-200e-6, 'lower travel limit; the command is clipped to it', 'm')
    stroke_max: float = param(200e-6, 'upper travel limit; the command is clipped to it', 'm')

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.stroke_max > self.stroke_min:
            raise ParameterError('piezo.stroke_max', self.stroke_max,
                                 f'greater than piezo.stroke_min ({self.stroke_min:g})')

    @property
    def omega_n(self) -> float:
        """Natural angular frequency ω_n (rad/s)."""
        return 2.0 * math.pi * self.natural_frequency


@jit_inline
def piezo_acceleration(command: float, s: float, sd: float, omega_n: float, damping: float,
                       stroke_min: float, stroke_max: float) -> float:
    """s̈ (m/s²) of the stack at stroke ``s`` (m), velocity ``sd`` (m/s), for a command (m)."""
    target = min(max(command, stroke_min), stroke_max)
    return omega_n * omega_n * (target - s) - 2.0 * damping * omega_n * sd
