"""Stroke schedules as JointTrajectory knots, and what an interpolated trajectory does between its knots.

Pure numpy, no ROS. Three jobs:

* :func:`sample_table` evaluates any :class:`StrokeTable` (analytic waveform or Hermite trajectory) at many
  times at once (vectorised, right-continuous, as the kernel's ``channel_value``).
* :func:`waveform_knots` turns the analytic stroke schedule into knots (times in integer nanoseconds, the
  resolution of ``time_from_start``; exact s, ṡ, s̈) such that the quintic Hermite through them (what
  joint_trajectory_controller and the simulator run with positions, velocities and accelerations)
  reproduces the schedule to :data:`KNOT_TOLERANCE` at every instant. How:

  - every breakpoint b of every actuator's waveform (segment ends, where s̈ may jump) is bracketed by two
    knots, the nanosecond at or below b − 0.25 ns and the one at or above b + 0.25 ns, each carrying the
    exact values of its own side; a quintic across those ≤ 1.5 ns deviates by about Δs̈·(1.5 ns)²/8
    (< 1e-15 m for any stroke a piezo makes). Where the waveform itself jumps in ṡ (``sine`` and
    ``half_sine`` at a stroke's ends) or in s (a ``samples`` shape not starting at 0), no continuous
    trajectory can follow it: it crosses the jump within those ≤ 1.5 ns instead;
  - between breakpoints each actuator runs one segment, a degree-≤5 polynomial (reproduced exactly by
    a quintic Hermite) plus at most one trigonometric term C cos ωτ + S sin ωτ. The quintic Hermite
    error is |f⁽⁶⁾|/6!·((t−a)(b−t))³ ≤ R/720·(h/2)⁶ with R = max over actuators of √(C²+S²)·ω⁶, so a
    gap is cut into equal pieces no longer than h = 2·(720·tol/R)^(1/6).

* :func:`table_range` / :func:`check_table` locate every segment polynomial's extrema (roots of its
  derivative, batched companion-matrix eigenvalues), so a commanded trajectory whose interpolated stroke
  leaves the piezo travel between knots is found, not only one whose knots do.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._jit import jit
from .waveforms import (
    N_POLY,
    StrokeParams,
    StrokeTable,
    sample_into,
    sixth_derivative_bound,
    waveform_table,
)

KNOT_TOLERANCE = 5e-13       # m: interpolation error allowed between knots (half the 1e-12 m promised)
LIMIT_TOLERANCE = 1e-12      # m: an interpolated stroke beyond the travel by less than this is accepted
BRACKET_NS = 0.25            # ns: a breakpoint's knots keep at least this much from it (float safety)
COMMAND_FREQUENCY = 1e9      # Hz: velocity/acceleration bounds of a command: the travel crossed at this rate


# ----------------------------------------------------------------------------------------------------
# Evaluating tables

def sample_table(table: StrokeTable, times: np.ndarray) -> np.ndarray:
    """(3, n, channels) s (m), ṡ (m/s), s̈ (m/s²) of ``table`` at ``times`` (s), right-continuous, as the
    kernel evaluates them (compiled: the numpy form, gathering every channel's segment rows, cost the
    actuator most of a core under a 64-actuator stream)."""
    times = np.ascontiguousarray(times, dtype=float)
    out = np.empty((3, times.size, table.n_channels))
    sample_into(table.as_tuple(), times, out)
    return out


# ----------------------------------------------------------------------------------------------------
# Knots of the analytic schedule

def breakpoints(table: StrokeTable, t_from: float, t_to: float) -> np.ndarray:
    """Sorted segment boundaries (s) of every channel within [t_from, t_to], as the kernel computes them
    (every channel at once: a loop over channels cost the actuator ~8 µs per channel and window)."""
    first = np.maximum(0, np.floor((t_from - table.start) / table.period) - 1)
    last = np.minimum(table.count - 1, np.ceil((t_to - table.start) / table.period) + 1)
    periods = np.maximum(last - first + 1, 0).astype(np.int64)        # periods of each channel to look at
    if periods.max(initial=0) == 0:
        return np.zeros(0)
    rank = np.arange(periods.max())
    j = first[:, None] + rank[None, :]                                 # (channels, periods)
    i = np.arange(table.seg_start.shape[1])
    b = table.start[:, None, None] + j[:, :, None] * table.period[:, None, None] + table.seg_start[:, None, :]
    wanted = ((rank[None, :] < periods[:, None])[:, :, None] & (i[None, None, :] <= table.n_seg[:, None, None])
              & (b >= t_from) & (b <= t_to))
    return np.unique(b[wanted])


def table_knots(table: StrokeTable, t_from: float, t_to: float, tolerance: float = KNOT_TOLERANCE,
                max_spacing: float = math.inf) -> tuple[np.ndarray, np.ndarray]:
    """Knots reproducing ``table`` on [t_from, t_to] (s, both whole nanoseconds) within ``tolerance`` (m)
    by quintic Hermite interpolation (module docstring), no two further apart than ``max_spacing`` (s).
    Returns (times in integer ns, (3, n, channels) s, ṡ, s̈ at those times)."""
    ns_from, ns_to = round(t_from * 1e9), round(t_to * 1e9)
    b = breakpoints(table, t_from, t_to) * 1e9
    ns = np.concatenate([[ns_from, ns_to], np.floor(b - BRACKET_NS), np.ceil(b + BRACKET_NS)]).astype(np.int64)
    ns = np.unique(ns[(ns >= ns_from) & (ns <= ns_to)])
    gaps = np.diff(ns)
    mid = (ns[:-1] + gaps / 2.0) * 1e-9
    r = np.empty(mid.size)
    sixth_derivative_bound(table.as_tuple(), mid, r)
    with np.errstate(divide='ignore'):
        h_ns = np.where(r > 0, 2.0 * (720.0 * tolerance / np.where(r > 0, r, 1.0)) ** (1 / 6) * 1e9, np.inf)
    h_ns = np.minimum(h_ns, max_spacing * 1e9)
    pieces = np.maximum(np.ceil(gaps / np.maximum(h_ns, 1.0)), 1).astype(np.int64)
    extra = np.repeat(np.arange(pieces.size), pieces - 1)
    if extra.size:
        rank = np.arange(extra.size) - np.repeat(np.cumsum(pieces - 1) - (pieces - 1), pieces - 1) + 1
        inner = ns[extra] + np.round(rank * gaps[extra] / pieces[extra]).astype(np.int64)
        ns = np.unique(np.concatenate([ns, inner]))
    return ns, sample_table(table, ns * 1e-9)


def waveform_knots(params: StrokeParams, n_actuators: int, tolerance: float = KNOT_TOLERANCE,
                   min_knots_per_stroke: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The whole burst of ``params`` as knots: times (s from the burst's origin, whole nanoseconds) and
    (n, actuators) s (m), ṡ (m/s), s̈ (m/s²), from 0 to the end of the last stroke; at least
    ``min_knots_per_stroke`` per stroke period 1/f (more where ``tolerance`` needs them)."""
    table = waveform_table(params, n_actuators)
    end = burst_end_ns(params) * 1e-9
    ns, values = table_knots(table, 0.0, end, tolerance, max_spacing(params, min_knots_per_stroke))
    return ns * 1e-9, values[0], values[1], values[2]


def max_spacing(params: StrokeParams, knots_per_stroke: int) -> float:
    """Knot spacing (s) giving ``knots_per_stroke`` per stroke period 1/f (0: no such bound)."""
    return 1.0 / (params.frequency * knots_per_stroke) if knots_per_stroke > 0 else math.inf


def burst_end_ns(params: StrokeParams) -> int:
    """The whole nanosecond at which a burst's knots end: just past its last breakpoint's bracket."""
    return math.ceil(params.burst_end_s() * 1e9 + BRACKET_NS)


# ----------------------------------------------------------------------------------------------------
# Hermite coefficients

# ----------------------------------------------------------------------------------------------------
# What a trajectory does between knots

@dataclass(frozen=True)
class CommandLimits:
    """Physical range of every commanded value: stroke (m) within the piezo travel, |ṡ| (m/s) and |s̈|
    (m/s²) at most those of a sinusoid spanning the whole travel at :data:`COMMAND_FREQUENCY`
    (v = 2πF·Δ, a = (2πF)²·Δ, Δ = travel): far beyond any piezo, it keeps the physics finite."""

    stroke_min: float
    stroke_max: float

    @property
    def velocity(self) -> float:
        return 2.0 * math.pi * COMMAND_FREQUENCY * (self.stroke_max - self.stroke_min)

    @property
    def acceleration(self) -> float:
        return (2.0 * math.pi * COMMAND_FREQUENCY) ** 2 * (self.stroke_max - self.stroke_min)


def _polynomial_extrema(coef: np.ndarray, length: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) of each polynomial Σ coef[:, i] τ^i over τ in [0, length] (vectorised).

    On u = τ/length ∈ [0, 1] the coefficients are comparable in size. The extrema lie at the ends or at
    real roots of the derivative in (0, 1): those are eigenvalues of its companion matrix, batched by
    degree (a leading coefficient below 1e-13 of the largest is dropped: its root lies far outside).
    Every root's real part clipped to [0, 1] is evaluated, so the result never exceeds the true range.
    """
    n, deg = coef.shape[0], coef.shape[1] - 1
    b = coef * length[:, None] ** np.arange(deg + 1)
    values = [b[:, 0], np.sum(b, axis=1)]
    d = b[:, 1:] * np.arange(1, deg + 1)                       # derivative coefficients in u
    scale = np.max(np.abs(d), axis=1)
    significant = np.abs(d) > 1e-13 * scale[:, None]
    order = np.where(significant.any(axis=1), deg - 1 - np.argmax(significant[:, ::-1], axis=1), 0)
    candidates = np.full((n, max(deg - 1, 1)), 0.0)
    for m in range(1, deg):
        rows = np.flatnonzero(order == m)
        if rows.size == 0:
            continue
        q = d[rows, :m + 1] / d[rows, m:m + 1]
        companion = np.zeros((rows.size, m, m))
        companion[:, 0, :] = -q[:, m - 1::-1]
        companion[:, np.arange(1, m), np.arange(m - 1)] = 1.0
        candidates[rows, :m] = np.clip(np.linalg.eigvals(companion).real, 0.0, 1.0)
    powers = candidates[:, :, None] ** np.arange(deg + 1)
    values.append(np.einsum('nri,ni->nr', powers, b).T)
    stacked = np.vstack([np.stack(values[:2]), values[2]])
    return stacked.min(axis=0), stacked.max(axis=0)


# Power basis on u ∈ [0, 1] -> Bernstein basis of degree N_POLY - 1: b_j = Σ_{i≤j} C(j, i)/C(n, i) a_i.
_POWER_TO_BERNSTEIN = np.array([[math.comb(j, i) / math.comb(N_POLY - 1, i) if i <= j else 0.0
                                 for j in range(N_POLY)] for i in range(N_POLY)])


@jit
def _bernstein_bounds(seg_coef: np.ndarray, seg_start: np.ndarray, n_seg: np.ndarray,
                      power_to_bernstein: np.ndarray, low: np.ndarray, high: np.ndarray) -> None:
    """``low``/``high`` (actuators, segments): the range of each segment polynomial's Bernstein
    coefficients on u = τ/ℓ ∈ [0, 1] (ℓ its length), which bounds the polynomial there; ±inf (empty)
    for the padding segments past ``n_seg``. Compiled: numpy's row-wise min/max over 6 coefficients cost
    ~1 ms for a 5 ms window of 64 actuators."""
    for k in range(seg_coef.shape[0]):
        for i in range(seg_coef.shape[1]):
            lo, hi = math.inf, -math.inf
            if i < n_seg[k]:
                length = seg_start[k, i + 1] - seg_start[k, i]
                for j in range(N_POLY):
                    b = 0.0
                    scale = 1.0
                    for m in range(j + 1):
                        b += power_to_bernstein[m, j] * seg_coef[k, i, m] * scale
                        scale *= length
                    lo, hi = min(lo, b), max(hi, b)
            low[k, i], high[k, i] = lo, hi


def table_range(table: StrokeTable, within: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) per channel of the stroke of a Hermite trajectory table (no trigonometric terms) over
    all time: its segments' extrema and the held values before and after.

    With ``within`` = (low, high), a segment whose Bernstein bound (the polynomial on u = τ/ℓ ∈ [0, 1] lies
    within the range of its Bernstein coefficients; ℓ its length) lies inside [low, high] contributes that
    bound instead of its exact extrema: the result is then exact only where it leaves [low, high], which is
    all a limit check needs (and skips the companion-matrix eigenvalues of almost every segment of a
    stroke well inside the travel).
    """
    n_act, n_seg = table.seg_coef.shape[:2]
    low, high = np.empty((n_act, n_seg)), np.empty((n_act, n_seg))
    _bernstein_bounds(table.seg_coef, table.seg_start, table.n_seg, _POWER_TO_BERNSTEIN, low, high)
    valid = np.arange(n_seg)[None, :] < table.n_seg[:, None]
    exact = valid if within is None else (low < within[0]) | (high > within[1])
    if exact.any():
        length = np.diff(table.seg_start, axis=1)[:, :n_seg]
        low[exact], high[exact] = _polynomial_extrema(table.seg_coef[exact][:, :N_POLY], length[exact])
    low, high = low.min(axis=1), high.max(axis=1)
    return np.minimum(low, np.minimum(table.before, table.after)), np.maximum(high, np.maximum(table.before,
                                                                                                 table.after))


def check_table(table: StrokeTable, limits: CommandLimits) -> str | None:
    """None when the interpolated stroke stays within the travel (± :data:`LIMIT_TOLERANCE`) at every
    instant, else the reason (which actuator, how far, where the limits are)."""
    low, high = table_range(table, (limits.stroke_min, limits.stroke_max))
    for k in range(low.size):
        if low[k] < limits.stroke_min - LIMIT_TOLERANCE or high[k] > limits.stroke_max + LIMIT_TOLERANCE:
            bad = low[k] if low[k] < limits.stroke_min - LIMIT_TOLERANCE else high[k]
            return (f'interpolated stroke of joint {k} reaches {bad:.6g} m between knots, outside the piezo '
                    f'limits [{limits.stroke_min:g}, {limits.stroke_max:g}] m (knots with velocities and '
                    f'accelerations are joined by quintics, with velocities only by cubics)')
    return None
