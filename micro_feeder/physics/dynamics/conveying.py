"""Conveying figures of a run (docs/tracks.md): the mean conveying velocity over whole stroke periods after
the transient, and the throw number Γ of a track.

The velocity is measured between two period boundaries of the burst, t_a = delay + ⌊count/2⌋·T and
t_b = delay + count·T (the second half of the burst: the first half is left to the transient, whose
relaxation time is ≈ πU/(2μg) for a tangential velocity amplitude U), from the positions the integration
reaches exactly there (:meth:`ConveyingWindow.marks` are stops of the run, not interpolated rows). On a
track x follows the track's tangential motion, which is periodic: over whole periods the part's mean
velocity relative to the track is its mean velocity over the ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..surface import SurfaceParams, TrackParams
from ..waveforms import StrokeParams, waveform_table

PHASE_SAMPLES = 4096    # samples of one stroke period for Γ of a waveform without a closed form


@dataclass(frozen=True)
class ConveyingWindow:
    """The whole periods a mean velocity is measured over: from ``t_start`` to ``t_end`` (s), ``periods``."""

    t_start: float
    t_end: float
    periods: int

    @classmethod
    def of(cls, stroke: StrokeParams) -> ConveyingWindow | None:
        """The second half of the burst's periods; None for a burst of one stroke (no period after a
        transient)."""
        if stroke.count < 2:
            return None
        first = stroke.count // 2
        period = stroke.period_s
        return cls(stroke.delay + first * period, stroke.delay + stroke.count * period, stroke.count - first)

    @property
    def marks(self) -> tuple[float, float]:
        return self.t_start, self.t_end

    def velocity(self, x_start: float, x_end: float) -> float:
        """Mean velocity (m/s) from the positions (m) at the window's two ends."""
        return (x_end - x_start) / (self.t_end - self.t_start)


def throw_number(surface: SurfaceParams, track: TrackParams, stroke: StrokeParams, gravity: float) -> float:
    """Γ = max over a stroke of the track's normal acceleration away from the part, over g cos α
    (A ω² sin β / (g cos α) for a sine); NaN for a bump surface (no single normal acceleration) or without
    gravity."""
    normal_gravity = gravity * math.cos(track.inclination)
    if surface.kind != 'track' or normal_gravity <= 0.0:
        return math.nan
    lift = math.sin(track.vibration_angle)
    if stroke.waveform == 'sine':
        peak = stroke.amplitude * (2.0 * math.pi * stroke.frequency) ** 2
    else:
        one = waveform_table(StrokeParams(**{**stroke.__dict__, 'count': 1, 'delay': 0.0, 'pause': 0.0,
                                             'phases': (0.0,)}), 1)
        times = np.linspace(0.0, 1.0 / stroke.frequency, PHASE_SAMPLES, endpoint=False)
        peak = max(float(-one.evaluate(t)[2, 0] * np.sign(lift)) for t in times) if lift else 0.0
    return peak * abs(lift) / normal_gravity
