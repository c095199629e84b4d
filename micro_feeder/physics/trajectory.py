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

from .waveforms import COEF_COS, COEF_OMEGA, COEF_SIN, N_POLY, StrokeParams, StrokeTable, waveform_table

KNOT_TOLERANCE = 1e-13       # m: interpolation error allowed between knots (10x below the 1e-12 m promised)
LIMIT_TOLERANCE = 1e-12      # m: an interpolated stroke beyond the travel by less than this is accepted
BRACKET_NS = 0.25            # ns: a breakpoint's knots keep at least this much from it (float safety)
COMMAND_FREQUENCY = 1e9      # Hz: velocity/acceleration bounds of a command: the travel crossed at this rate


# ----------------------------------------------------------------------------------------------------
# Evaluating tables

def sample_table(table: StrokeTable, times: np.ndarray) -> np.ndarray:
    """(3, n, channels) s (m), ṡ (m/s), s̈ (m/s²) of ``table`` at ``times`` (s), right-continuous.

    Every channel at once (a loop over channels cost the actuator ~0.5 ms per channel and window: a
    64-actuator stream could not keep up)."""
    times = np.asarray(times, dtype=float)
    c, tau, inside = _segments(table, times)
    powers = tau[..., None] ** np.arange(N_POLY)
    poly = c[..., :N_POLY]
    i = np.arange(1, N_POLY)
    s = np.sum(poly * powers, axis=-1)
    sd = np.sum(poly[..., 1:] * i * powers[..., :-1], axis=-1)
    sdd = np.sum(poly[..., 2:] * (i[1:] * i[:-1]) * powers[..., :-2], axis=-1)
    w = c[..., COEF_OMEGA]
    cw, sw = np.cos(w * tau), np.sin(w * tau)
    trig = c[..., COEF_COS] * cw + c[..., COEF_SIN] * sw
    s = s + trig
    sd = sd + w * (c[..., COEF_SIN] * cw - c[..., COEF_COS] * sw)
    sdd = sdd - w * w * trig
    held = np.where(times[None, :] < table.start[:, None], table.before[:, None], table.after[:, None])
    out = np.stack([np.where(inside, s, held), np.where(inside, sd, 0.0), np.where(inside, sdd, 0.0)])
    return out.transpose(0, 2, 1)


def _segments(table: StrokeTable, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(segment rows (channels, n, N_COEF), τ within the segment (s), inside mask) at ``times``."""
    rel = times[None, :] - table.start[:, None]
    period, count = table.period[:, None], table.count[:, None]
    inside = (rel >= 0.0) & (rel < count * period)
    j = np.clip(np.floor(rel / period), 0, count - 1)
    tau = rel - j * period
    i = np.empty(tau.shape, dtype=np.int64)
    for k in range(table.n_channels):      # one search per channel (rows hold n_seg[k] + 1 bounds)
        i[k] = np.searchsorted(table.seg_start[k, :table.n_seg[k] + 1], tau[k], side='right') - 1
    i = np.clip(i, 0, table.n_seg[:, None] - 1)
    rows = np.arange(table.n_channels)[:, None]
    return table.seg_coef[rows, i], tau - table.seg_start[rows, i], inside


def _sixth_derivative_bound(table: StrokeTable, times: np.ndarray) -> np.ndarray:
    """R(t) = max over channels of |C, S|·ω⁶ of the segment active at each of ``times`` (m/s⁶)."""
    c, _, inside = _segments(table, times)
    r = np.hypot(c[..., COEF_COS], c[..., COEF_SIN]) * c[..., COEF_OMEGA] ** 6
    return np.max(np.where(inside, r, 0.0), axis=0, initial=0.0)


# ----------------------------------------------------------------------------------------------------
# Knots of the analytic schedule

def breakpoints(table: StrokeTable, t_from: float, t_to: float) -> np.ndarray:
    """Sorted segment boundaries (s) of every channel within [t_from, t_to], as the kernel computes them."""
    out = []
    for k in range(table.n_channels):
        period, count, n = float(table.period[k]), int(table.count[k]), int(table.n_seg[k])
        first = max(0, math.floor((t_from - table.start[k]) / period) - 1)
        last = min(count - 1, math.ceil((t_to - table.start[k]) / period) + 1)
        if last < first:
            continue
        j = np.arange(first, last + 1)[:, None]
        b = (table.start[k] + j * period + table.seg_start[k, :n + 1][None, :]).ravel()
        out.append(b[(b >= t_from) & (b <= t_to)])
    return np.unique(np.concatenate(out)) if out else np.zeros(0)


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
    r = _sixth_derivative_bound(table, mid)
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


def table_range(table: StrokeTable, within: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) per channel of the stroke of a Hermite trajectory table (no trigonometric terms) over
    all time: its segments' extrema and the held values before and after.

    With ``within`` = (low, high), a segment whose Bernstein bound (the polynomial on u = τ/ℓ ∈ [0, 1] lies
    within the range of its Bernstein coefficients; ℓ its length) lies inside [low, high] contributes that
    bound instead of its exact extrema: the result is then exact only where it leaves [low, high], which is
    all a limit check needs (and skips the companion-matrix eigenvalues of almost every segment of a
    stroke well inside the travel).
    """
    coef = table.seg_coef[:, :, :N_POLY]
    n_act, n_seg = coef.shape[:2]
    length = np.diff(table.seg_start, axis=1)[:, :n_seg].reshape(-1)
    coef = coef.reshape(-1, N_POLY)
    bernstein = (coef * length[:, None] ** np.arange(N_POLY)) @ _POWER_TO_BERNSTEIN
    low, high = bernstein.min(axis=1), bernstein.max(axis=1)
    exact = np.ones(low.size, dtype=bool) if within is None else (low < within[0]) | (high > within[1])
    if exact.any():
        low[exact], high[exact] = _polynomial_extrema(coef[exact], length[exact])
    valid = (np.arange(n_seg)[None, :] < table.n_seg[:, None]).reshape(-1)
    low = np.where(valid, low, np.inf).reshape(n_act, n_seg).min(axis=1)
    high = np.where(valid, high, -np.inf).reshape(n_act, n_seg).max(axis=1)
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
