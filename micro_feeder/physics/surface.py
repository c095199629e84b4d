"""The deformed surface: one Gaussian bump per actuator, with closed-form derivatives.

h(x, t) = Σ_k s_k(t) g_k(x),  g_k(x) = exp(−(x − c_k)² / (2 w_k²))  (docs/dynamics.md §1).
Material points move vertically only, so every derivative follows from the strokes (s, ṡ, s̈) and
g, g', g'' in closed form; nothing is differentiated numerically. A bump is skipped where it is below
``surface.cutoff`` of its peak (error bound: docs/dynamics.md, "Far actuators").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._jit import jit_inline
from .parameters import ParameterError, ParameterGroup, param

SURFACE_KINDS = ('bumps', 'track')
TRACK_DRIVES = ('line', 'two_way')


@dataclass(frozen=True)
class TrackParams(ParameterGroup):
    """A rigid vibratory track (surface.kind 'track'; docs/tracks.md): flat, rising at ``inclination`` to the
    horizontal, vibrating as one body along a line at ``vibration_angle`` to its surface; its displacement
    along that line is the stroke s(t)."""

    prefix = 'track'

    inclination: float = param(0.0, 'track angle alpha to the horizontal (positive: x runs uphill)', 'rad',
                               ge=-1.2, le=1.2)
    vibration_angle: float = param(0.5235987755982988, 'angle beta of the vibration line to the track surface '
                                   '(x_p = s cos beta, z_p = s sin beta)', 'rad', ge=-1.5707963267948966,
                                   le=1.5707963267948966)
    drive: str = param('line', "'line': one stroke s along the vibration line (one actuator); 'two_way': two "
                       'actuators, the first moving the track along its surface (x_p = s_0 cos beta), the second '
                       'normal to it (z_p = s_1 sin beta), each with its stroke.phases entry: the phase between '
                       'the two motions', choices=TRACK_DRIVES)


@dataclass(frozen=True)
class SurfaceParams(ParameterGroup):
    """Where the actuators push the surface and how wide each bump is (one entry per actuator)."""

    prefix = 'surface'

    centers: tuple = param((0.0,), 'actuator positions c_k along the feeder (frame feeder, x), in increasing '
                           'order', 'm',
                           min_length=1, ge=-1.0, le=1.0)
    widths: tuple = param((1e-3,), 'Gaussian profile widths w_k (standard deviation of the bump)', 'm',
                          min_length=1, ge=1e-7, le=1.0)
    cutoff: float = param(1e-12, 'relative cutoff: an actuator is skipped where its bump is below this '
                          'fraction of its peak (0: exact full sum)', ge=0.0, le=1e-3)
    thickness: float = param(0.0, 'plate thickness t: the top surface of a bending plate also moves along the '
                             'feeder, u_x = -(t/2) dh/dx at each material point, which carries a part stuck on '
                             "it (0: the seed's surface, whose points move vertically only; bumps only)", 'm',
                             ge=0.0, le=0.1)
    kind: str = param('bumps', "'bumps': a flexible surface pushed up by the actuators (centers, widths); "
                      "'track': a rigid vibratory track moving as one body along track.vibration_angle, its "
                      'displacement the stroke (one actuator)', choices=SURFACE_KINDS)

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self.widths) != len(self.centers):
            raise ParameterError('surface.widths', list(self.widths),
                                 f'one width per actuator ({len(self.centers)} surface.centers)')
        if self.kind == 'track' and self.thickness > 0.0:
            raise ParameterError('surface.thickness', self.thickness,
                                 "0 with a rigid track (surface.kind 'track' moves as one body; thickness is a "
                                 'bending plate\'s)')
        if self.kind == 'track' and len(self.centers) > 2:
            raise ParameterError('surface.centers', list(self.centers),
                                 "a track (surface.kind 'track') moves as one body: one actuator (track.drive "
                                 "'line') or two (track.drive 'two_way'), one centre each")
        if any(b < a for a, b in zip(self.centers, self.centers[1:], strict=False)):
            raise ParameterError('surface.centers', list(self.centers),
                                 'actuators listed in increasing order along the feeder (list them by position, '
                                 'their widths and stroke phases in the same order)')

    @property
    def cutoff_radius(self) -> float:
        """u_c = sqrt(2 ln(1/cutoff)) in widths: g_k < cutoff beyond |x − c_k| > w_k u_c (inf for 0)."""
        return math.sqrt(2.0 * math.log(1.0 / self.cutoff)) if self.cutoff > 0.0 else math.inf

    @property
    def n_actuators(self) -> int:
        """Number of actuators (bumps)."""
        return len(self.centers)


@jit_inline
def surface_at(x: float, s: np.ndarray, sd: np.ndarray, sdd: np.ndarray, centers: np.ndarray,
               widths: np.ndarray, u_cut: float, first: int, stop: int) -> tuple[float, float, float, float, float,
                                                                                 float]:
    """(h, h_x, h_xx, h_t, h_tt, h_xt) at position ``x`` (m) for strokes s (m), ṡ (m/s), s̈ (m/s²).

    Only actuators ``first`` to ``stop - 1`` are summed (0 and ``centers.size`` for all), and of those only
    the ones with |x − c_k| ≤ w_k·u_cut (``SurfaceParams.cutoff_radius``; ``math.inf`` for the exact full
    sum): with centres in increasing order a caller passes the range of those near x, so that far
    actuators cost nothing. (:func:`surface_jet` without its rates: s̈ stands in for s⃛, and the compiler
    drops the sums unused.)
    """
    return surface_jet(x, s, sd, sdd, sdd, centers, widths, u_cut, first, stop)[:6]


@jit_inline
def surface_jet(x: float, s: np.ndarray, sd: np.ndarray, sdd: np.ndarray, sddd: np.ndarray, centers: np.ndarray,
                widths: np.ndarray, u_cut: float, first: int, stop: int) -> tuple[float, float, float, float, float,
                                                                                  float, float, float, float, float]:
    """:func:`surface_at`'s six values, then h_ttt, h_ttx, h_xxt, h_xxx: the rates that the margins' time
    derivatives need (s⃛ in m/s³); the third derivative of the bump is −(u³ − 3u)/w³ · g."""
    h = hx = hxx = ht = htt = hxt = httt = httx = hxxt = hxxx = 0.0
    for k in range(first, stop):
        w = widths[k]
        u = (x - centers[k]) / w
        if abs(u) > u_cut:
            continue
        g = math.exp(-0.5 * u * u)
        g1 = -u / w * g
        g2 = (u * u - 1.0) / (w * w) * g
        g3 = -u * (u * u - 3.0) / (w * w * w) * g
        h += s[k] * g
        hx += s[k] * g1
        hxx += s[k] * g2
        ht += sd[k] * g
        htt += sdd[k] * g
        hxt += sd[k] * g1
        httt += sddd[k] * g
        httx += sdd[k] * g1
        hxxt += sd[k] * g2
        hxxx += s[k] * g3
    return h, hx, hxx, ht, htt, hxt, httt, httx, hxxt, hxxx


def surface_profile(x: np.ndarray, strokes: np.ndarray, centers: np.ndarray | tuple,
                    widths: np.ndarray | tuple) -> np.ndarray:
    """Surface height h (m) at the positions ``x`` (m) for the given strokes (m), vectorised.

    For drawing the deformed surface (plots, RViz markers); the dynamics use :func:`surface_at`.
    """
    x = np.asarray(x, dtype=float)[..., None]
    u = (x - np.asarray(centers, dtype=float)) / np.asarray(widths, dtype=float)
    return np.exp(-0.5 * u * u) @ np.asarray(strokes, dtype=float)
