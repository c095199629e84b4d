"""Actuator strokes s_k(t) with exact ṡ and s̈: analytic waveforms and commanded trajectories.

Every stroke source compiles to a :class:`StrokeTable`: per actuator (channel), a pattern of
segments repeated ``count`` times with a ``period``, starting at ``start``. Each segment is

    s(τ) = Σ_{i=0..5} c_i τ^i + Σ_{h<N_TRIG} [C_h cos(ω_h τ) + S_h sin(ω_h τ)],   τ = t − (segment start)
    (s in m, t in s),

which represents every shape exactly: the raised cosine, sine, half sine and asymmetric shapes (one
trigonometric term), a sum of up to :data:`N_TRIG` harmonics (one term each), the jerk-limited
trapezoid and the ``samples`` spline (cubics), and the quintic / cubic Hermite pieces of a commanded
trajectory. Segment boundaries are hard breakpoints: the integrator ends its steps there and evaluates
each side from its own segment (docs/dynamics.md §2). Outside the repeated pattern the stroke holds a
constant (``before`` / ``after``; 0 for a waveform burst, the last knot's position for a trajectory).

Waveform conventions (docs/dynamics.md §2): a stroke lasts 1/f; ``count`` strokes follow each other
separated by ``pause`` seconds; the burst starts after ``delay``; actuator k is delayed by
``phases[k]/f``; s = 0 outside the burst.
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from ._jit import jit, jit_inline
from .parameters import ParameterError, ParameterGroup, param

WAVEFORMS = ('raised_cosine', 'sine', 'half_sine', 'trapezoid', 'asymmetric', 'samples', 'harmonics')

# Layout of one segment's coefficient row: c_0 .. c_5, then (C_h, S_h, ω_h) for each trigonometric term h.
N_POLY = 6
N_TRIG = 3                      # trigonometric terms per segment: the most harmonics a stroke can sum
COEF_COS, COEF_SIN, COEF_OMEGA = 6, 7, 8      # of term 0; term h at + 3h
N_COEF = N_POLY + 3 * N_TRIG


@dataclass(frozen=True)
class StrokeParams(ParameterGroup):
    """The analytic stroke waveform driving every actuator (docs/dynamics.md §2)."""

    prefix = 'stroke'

    waveform: str = param('raised_cosine', 'stroke shape over one period', choices=WAVEFORMS)
    amplitude: float = param(100e-6, 'peak stroke A (raised_cosine: s goes 0 -> A -> 0)', 'm', ge=0)
    frequency: float = param(1000.0, 'stroke frequency f; one stroke lasts 1/f', 'Hz', gt=0, le=1e7)
    count: int = param(1, 'number of strokes in the burst', ge=1)
    pause: float = param(0.0, 'rest between consecutive strokes', 's', ge=0)
    delay: float = param(0.0, 'time before the burst starts', 's', ge=0)
    duty: float = param(0.5, 'asymmetric: fraction of the period spent rising; trapezoid: fraction '
                        'held at the top', '', gt=0, lt=1)
    phases: tuple = param((0.0,), 'per-actuator delay in stroke periods (0.25 = a quarter period); '
                          'one entry per surface.centers entry', '', min_length=1, ge=0)
    samples: tuple = param((0.0, 0.5, 1.0, 0.5), 'samples waveform: stroke as a fraction of amplitude '
                           'at equally spaced phases over one period (periodic cubic spline)', '',
                           min_length=4)
    harmonics: tuple = param((1, 2), 'harmonics waveform: the harmonic numbers n (whole, distinct, at most '
                             f'{N_TRIG}): term h runs at n_h·f', '', min_length=1, ge=1, le=1000)
    harmonic_amplitudes: tuple = param((1.0, 0.5), 'harmonics waveform: each term\'s amplitude as a fraction '
                                       'of stroke.amplitude (one per stroke.harmonics entry)', '', min_length=1,
                                       ge=0.0, le=1e3)
    harmonic_phases: tuple = param((0.0, 0.0), 'harmonics waveform: each term\'s phase φ_h (one per '
                                   'stroke.harmonics entry): s = A Σ a_h [sin(2π n_h f τ + φ_h) − sin φ_h]',
                                   'rad', min_length=1, ge=-100.0, le=100.0)

    def __post_init__(self) -> None:
        super().__post_init__()
        n = len(self.harmonics)
        if any(float(h) != int(h) for h in self.harmonics) or len(set(self.harmonics)) != n or n > N_TRIG:
            raise ParameterError('stroke.harmonics', list(self.harmonics),
                                 f'distinct whole numbers, at most {N_TRIG} of them')
        for name in ('harmonic_amplitudes', 'harmonic_phases'):
            if len(getattr(self, name)) != n:
                raise ParameterError(f'stroke.{name}', list(getattr(self, name)),
                                     f'one entry per stroke.harmonics entry ({n})')

    @property
    def period_s(self) -> float:
        """Time from the start of one stroke to the start of the next (1/f + pause)."""
        return 1.0 / self.frequency + self.pause

    def burst_end_s(self) -> float:
        """Time at which the last stroke of the last actuator ends."""
        return self.delay + max(self.phases) / self.frequency + self.count / self.frequency \
            + (self.count - 1) * self.pause


@dataclass(frozen=True)
class StrokeTable:
    """A compiled stroke source for the kernel: one row per channel (actuator), SI units.

    ``seg_start[k, i]`` is the start of segment i within the period (``seg_start[k, n_seg[k]]`` equals
    the period, the end of the last segment); ``seg_coef[k, i]`` its coefficients (layout in the module
    docstring). Before ``start[k]`` the stroke is ``before[k]``; after ``start + count·period`` it is
    ``after[k]`` (velocity and acceleration zero in both).
    """

    start: np.ndarray
    period: np.ndarray
    count: np.ndarray
    before: np.ndarray
    after: np.ndarray
    seg_start: np.ndarray
    seg_coef: np.ndarray
    n_seg: np.ndarray

    @property
    def n_channels(self) -> int:
        return int(self.start.size)

    def as_tuple(self) -> tuple:
        """The arrays in the order the kernel expects."""
        return (self.start, self.period, self.count, self.before, self.after, self.seg_start,
                self.seg_coef, self.n_seg)

    def evaluate(self, t: float) -> np.ndarray:
        """(3, n_channels) array of s (m), ṡ (m/s), s̈ (m/s²) at time ``t`` (right-continuous); one compiled
        call for every channel (a Python loop over 64 channels cost ~0.2 ms per streamed window)."""
        out = np.empty((3, 1, self.n_channels))
        sample_into(self.as_tuple(), np.array([float(t)]), out)
        return out[:, 0, :]

    def end_time(self) -> float:
        """Time after which every channel holds its final value."""
        return float(np.max(self.start + self.count * self.period))


def stack_tables(tables: Sequence[StrokeTable]) -> StrokeTable:
    """One table whose channels are those of ``tables`` in order (segments padded to a common size)."""
    n_max = max(int(t.seg_coef.shape[1]) for t in tables)
    seg_start, seg_coef = [], []
    for t in tables:
        pad = n_max - t.seg_coef.shape[1]
        seg_start.append(np.pad(t.seg_start, ((0, 0), (0, pad)), mode='edge'))
        seg_coef.append(np.pad(t.seg_coef, ((0, 0), (0, pad), (0, 0))))
    cat = np.concatenate
    return StrokeTable(cat([t.start for t in tables]), cat([t.period for t in tables]),
                       cat([t.count for t in tables]), cat([t.before for t in tables]),
                       cat([t.after for t in tables]), cat(seg_start), cat(seg_coef),
                       cat([t.n_seg for t in tables]))


# ----------------------------------------------------------------------------------------------------
# Kernel-side evaluation (compiled)

@jit
def locate_segment(src: tuple, k: int, t: float) -> tuple[int, int]:
    """(period index j, segment index i) active at time ``t`` on channel ``k`` (right-continuous).

    j = -1: before the pattern starts; j = -2: after it ends. A time exactly on a boundary belongs to
    the segment that starts there, so a step that ended on a breakpoint continues on the next segment.
    """
    start, period, count, _, _, seg_start, _, n_seg = src
    if t < start[k]:
        return -1, 0
    if t >= start[k] + count[k] * period[k]:
        return -2, 0
    j = min(max(int((t - start[k]) // period[k]), 0), int(count[k]) - 1)
    tau = t - (start[k] + j * period[k])
    n = n_seg[k]
    i = min(max(int(np.searchsorted(seg_start[k, :n + 1], tau, side='right')) - 1, 0), n - 1)
    while segment_end(src, k, j, i) <= t:     # rounding: the boundary computed as the integrator does
        i += 1
        if i == n:
            i = 0
            j += 1
            if j >= count[k]:
                return -2, 0
    return j, i


@jit_inline
def segment_end(src: tuple, k: int, j: int, i: int) -> float:
    """Time (s) at which segment (j, i) of channel ``k`` ends: the next hard breakpoint."""
    start, period, _, _, _, seg_start, _, _ = src
    if j == -1:
        return start[k]
    if j == -2:
        return math.inf
    return start[k] + j * period[k] + seg_start[k, i + 1]


@jit_inline
def segment_time(src: tuple, k: int, j: int, i: int, t: float) -> float:
    """τ (s): time ``t`` measured from the start of channel ``k``'s segment (j, i), repetition j ≥ 0."""
    start, period, _, _, _, seg_start, _, _ = src
    return t - (start[k] + j * period[k] + seg_start[k, i])


@jit_inline
def channel_value(src: tuple, k: int, j: int, i: int, t: float) -> tuple[float, float, float, float]:
    """(s, ṡ, s̈, s⃛) of channel ``k`` at ``t`` evaluated on segment (j, i), which may be extrapolated a
    little past its end (a step ending on a breakpoint evaluates its last stage from the left side).
    (Callers that drop s⃛ pay nothing for it: the compiler removes what an inlined caller does not use.)"""
    _, _, _, before, after, _, seg_coef, _ = src
    if j == -1:
        return before[k], 0.0, 0.0, 0.0
    if j == -2:
        return after[k], 0.0, 0.0, 0.0
    tau = segment_time(src, k, j, i, t)
    c = seg_coef[k, i]
    s = c[0] + tau * (c[1] + tau * (c[2] + tau * (c[3] + tau * (c[4] + tau * c[5]))))
    sd = c[1] + tau * (2.0 * c[2] + tau * (3.0 * c[3] + tau * (4.0 * c[4] + tau * 5.0 * c[5])))
    sdd = 2.0 * c[2] + tau * (6.0 * c[3] + tau * (12.0 * c[4] + tau * 20.0 * c[5]))
    sddd = 6.0 * c[3] + tau * (24.0 * c[4] + tau * 60.0 * c[5])
    for h in range(N_TRIG):
        base = N_POLY + 3 * h
        w = c[base + 2]
        if w == 0.0:                    # the terms in use come first: the rest of the slots are empty
            break
        if c[base] != 0.0 or c[base + 1] != 0.0:
            cw = math.cos(w * tau)
            sw = math.sin(w * tau)
            trig = c[base] * cw + c[base + 1] * sw
            trig_rate = c[base + 1] * cw - c[base] * sw
            s += trig
            sd += w * trig_rate
            sdd -= w * w * trig
            sddd -= w * w * w * trig_rate
    return s, sd, sdd, sddd


@jit_inline
def channel_bounds(src: tuple, k: int, j: int, i: int, t0: float, t1: float) -> tuple[float, float, float]:
    """Upper bounds of |s| (m), |ṡ| (m/s) and |s̈| (m/s²) of channel ``k`` on segment (j, i) (as
    :func:`channel_value` evaluates it) for every t in [t0, t1]: each polynomial coefficient's term at the
    largest |τ| of the range, plus each trigonometric term's amplitude times ω⁰, ω¹, ω²."""
    if j < 0:                                          # held before or after the schedule
        return abs(channel_value(src, k, j, i, t0)[0]), 0.0, 0.0
    tau = max(abs(segment_time(src, k, j, i, t0)), abs(segment_time(src, k, j, i, t1)))
    c = src[6][k, i]                                   # the segment's coefficients
    s_max = sd_max = sdd_max = 0.0
    power = 1.0                                        # tau^n, from n = 0
    for n in range(6):
        s_max += abs(c[n]) * power
        if n + 1 < 6:
            sd_max += (n + 1) * abs(c[n + 1]) * power
        if n + 2 < 6:
            sdd_max += (n + 2) * (n + 1) * abs(c[n + 2]) * power
        power *= tau
    for h in range(N_TRIG):
        amplitude = math.hypot(c[N_POLY + 3 * h], c[N_POLY + 3 * h + 1])
        w = abs(c[N_POLY + 3 * h + 2])
        s_max += amplitude
        sd_max += amplitude * w
        sdd_max += amplitude * w * w
    return s_max, sd_max, sdd_max


@jit_inline
def channel_ranges(src: tuple, k: int, j: int, i: int, t0: float, t1: float) -> tuple[float, float, float, float]:
    """Bounds (s_lo, s_hi, s̈_lo, s̈_hi) of s (m) and s̈ (m/s²) of channel ``k`` on segment (j, i) (as
    :func:`channel_value` evaluates it) for every t in [t0, t1]: each polynomial term's range (τⁿ is monotone
    on either side of 0) plus each trigonometric term's exact range, its values at the ends or ±R where
    its rate changes sign in between (R its amplitude; s̈'s term is −ω² times s's), or ±R over a window of
    half its period or more."""
    _, _, _, before, after, _, seg_coef, _ = src
    if j < 0:
        held = before[k] if j == -1 else after[k]
        return held, held, 0.0, 0.0
    tau0 = segment_time(src, k, j, i, t0)
    tau1 = segment_time(src, k, j, i, t1)
    c = seg_coef[k, i]
    straddles = tau0 < 0.0 < tau1
    s_lo = s_hi = c[0]
    sdd_lo = sdd_hi = 2.0 * c[2]
    p0 = p1 = 1.0                                     # tau0^n, tau1^n from n = 1
    for n in range(1, 6):
        p0 *= tau0
        p1 *= tau1
        for order in (0, 2):
            if n + order > 5 or c[n + order] == 0.0:
                continue
            a = c[n] if order == 0 else (n + 2) * (n + 1) * c[n + 2]
            v0, v1 = a * p0, a * p1
            lo, hi = min(v0, v1), max(v0, v1)
            if straddles:
                lo, hi = min(lo, 0.0), max(hi, 0.0)
            if order == 0:
                s_lo, s_hi = s_lo + lo, s_hi + hi
            else:
                sdd_lo, sdd_hi = sdd_lo + lo, sdd_hi + hi
    for h in range(N_TRIG):
        base = N_POLY + 3 * h
        cc, ss, w = c[base], c[base + 1], c[base + 2]
        if cc == 0.0 and ss == 0.0:
            continue
        if abs(w) * (tau1 - tau0) >= math.pi:
            lo = -math.hypot(cc, ss)
            hi = -lo
        else:
            cos0, sin0, cos1, sin1 = math.cos(w * tau0), math.sin(w * tau0), math.cos(w * tau1), math.sin(w * tau1)
            v0, v1 = cc * cos0 + ss * sin0, cc * cos1 + ss * sin1
            lo, hi = min(v0, v1), max(v0, v1)
            rate0, rate1 = w * (ss * cos0 - cc * sin0), w * (ss * cos1 - cc * sin1)
            if rate0 > 0.0 >= rate1:                  # a maximum in between
                hi = math.hypot(cc, ss)
            elif rate0 < 0.0 <= rate1:                # a minimum
                lo = -math.hypot(cc, ss)
        s_lo, s_hi = s_lo + lo, s_hi + hi
        sdd_lo, sdd_hi = sdd_lo - w * w * hi, sdd_hi - w * w * lo
    return s_lo, s_hi, sdd_lo, sdd_hi


@jit
def sample_into(src: tuple, times: np.ndarray, out: np.ndarray) -> None:
    """``out`` (3, times, channels): s (m), ṡ (m/s), s̈ (m/s²) of every channel of ``src`` at ``times`` (s),
    right-continuous, evaluated exactly as the kernel does (:func:`locate_segment`, :func:`channel_value`)."""
    for k in range(out.shape[2]):
        for n in range(times.size):
            j, i = locate_segment(src, k, times[n])
            out[0, n, k], out[1, n, k], out[2, n, k], _ = channel_value(src, k, j, i, times[n])


@jit
def sixth_derivative_bound(src: tuple, times: np.ndarray, out: np.ndarray) -> None:
    """``out`` (times,): R(t) = max over channels of Σ_h √(C_h² + S_h²)·ω_h⁶ of the segment active at each of
    ``times`` (m/s⁶; 0 where no channel runs a trigonometric term): the polynomial part of a segment has no
    sixth derivative, so R bounds |s⁽⁶⁾|."""
    seg_coef = src[6]
    for n in range(times.size):
        worst = 0.0
        for k in range(seg_coef.shape[0]):
            j, i = locate_segment(src, k, times[n])
            if j >= 0:
                c = seg_coef[k, i]
                bound = 0.0
                for h in range(N_TRIG):
                    bound += math.hypot(c[N_POLY + 3 * h], c[N_POLY + 3 * h + 1]) * c[N_POLY + 3 * h + 2] ** 6
                worst = max(worst, bound)
        out[n] = worst


# ----------------------------------------------------------------------------------------------------
# Building tables

def _segment(poly: Sequence[float] = (), cos: float = 0.0, sin: float = 0.0, omega: float = 0.0,
             more: Sequence[tuple[float, float, float]] = ()) -> np.ndarray:
    """One coefficient row: the polynomial, the trigonometric term (cos, sin, omega), then ``more`` terms.

    The terms in use fill the first slots and each runs at a frequency above 0: :func:`channel_value` stops at
    the first slot whose omega is 0."""
    terms = [(cos, sin, omega), *more]
    if any(term[2] == 0.0 and any(later[2] != 0.0 for later in terms[h + 1:]) for h, term in enumerate(terms)):
        raise ValueError(f'a trigonometric term at frequency 0 before one in use: {terms}')
    row = np.zeros(N_COEF)
    row[:len(poly)] = poly
    for h, term in enumerate(terms):
        row[N_POLY + 3 * h:N_POLY + 3 * h + 3] = term
    return row


def _scurve_ramp() -> list[tuple[float, np.ndarray]]:
    """A 0 -> 1 ramp over unit time with a triangular acceleration (constant-jerk pieces, jerk-limited).

    Jerk +J on [0, 1/4], −J on [1/4, 3/4], +J on [3/4, 1]; J makes the ramp end at exactly 1.
    Returns (piece start, cubic coefficients in local time) for each of the three pieces.
    """
    bounds = (0.0, 0.25, 0.75, 1.0)
    signs = (1.0, -1.0, 1.0)

    def pieces(jerk: float) -> tuple[list[tuple[float, np.ndarray]], float]:
        p = v = a = 0.0
        out = []
        for (t0, t1), sign in zip(itertools.pairwise(bounds), signs, strict=True):
            j = sign * jerk
            out.append((t0, np.array([p, v, a / 2.0, j / 6.0])))
            d = t1 - t0
            p, v, a = p + v * d + a * d * d / 2 + j * d ** 3 / 6, v + a * d + j * d * d / 2, a + j * d
        return out, p

    _, reach = pieces(1.0)
    return pieces(1.0 / reach)[0]


def _unit_pattern(params: StrokeParams) -> list[tuple[float, np.ndarray]]:
    """One stroke of unit amplitude over unit phase: (segment start in phase, coefficients in phase)."""
    two_pi = 2.0 * math.pi
    shape, duty = params.waveform, params.duty
    if shape == 'raised_cosine':
        return [(0.0, _segment([0.5], cos=-0.5, omega=two_pi))]
    if shape == 'sine':
        return [(0.0, _segment(sin=1.0, omega=two_pi))]
    if shape == 'half_sine':
        return [(0.0, _segment(sin=1.0, omega=math.pi))]
    if shape == 'asymmetric':
        return [(0.0, _segment([0.5], cos=-0.5, omega=math.pi / duty)),
                (duty, _segment([0.5], cos=0.5, omega=math.pi / (1.0 - duty)))]
    if shape == 'harmonics':      # Σ a_h [sin(2π n_h u + φ_h) − sin φ_h]: 0 at the start and end of a stroke
        terms = [(a * math.sin(phi), a * math.cos(phi), two_pi * n) for n, a, phi
                 in zip(params.harmonics, params.harmonic_amplitudes, params.harmonic_phases, strict=True)]
        offset = -sum(a * math.sin(phi) for a, phi in zip(params.harmonic_amplitudes, params.harmonic_phases,
                                                          strict=True))
        return [(0.0, _segment([offset], *terms[0], more=terms[1:]))]
    if shape == 'trapezoid':
        ramp = (1.0 - duty) / 2.0
        out = []
        for start, cubic in _scurve_ramp():      # rise, then hold at 1, then the mirrored fall
            out.append((start * ramp, _segment(cubic / ramp ** np.arange(4))))
        out.append((ramp, _segment([1.0])))
        for start, cubic in _scurve_ramp():
            fall = -cubic / ramp ** np.arange(4)
            fall[0] += 1.0
            out.append((ramp + duty + start * ramp, _segment(fall)))
        return out
    values = np.asarray(params.samples, dtype=float)
    phase = np.linspace(0.0, 1.0, values.size + 1)
    spline = CubicSpline(phase, np.append(values, values[0]), bc_type='periodic')
    return [(phase[i], _segment(spline.c[::-1, i])) for i in range(values.size)]


def waveform_table(params: StrokeParams, n_actuators: int) -> StrokeTable:
    """The analytic stroke burst of ``params`` on ``n_actuators`` actuators (phases per actuator)."""
    if len(params.phases) != n_actuators:
        raise ParameterError('stroke.phases', list(params.phases),
                             f'one phase per actuator ({n_actuators} surface.centers)')
    f, amplitude = params.frequency, params.amplitude
    pattern = _unit_pattern(params)
    starts = [p / f for p, _ in pattern]
    rows = []
    for _, coef in pattern:                       # phase -> time: c_i f^i, ω f; scale by A
        row = coef.copy()
        row[:N_POLY] *= amplitude * f ** np.arange(N_POLY)
        for h in range(N_TRIG):
            row[N_POLY + 3 * h:N_POLY + 3 * h + 2] *= amplitude
            row[N_POLY + 3 * h + 2] *= f
        rows.append(row)
    if params.pause > 0:
        starts.append(1.0 / f)
        rows.append(_segment())
    starts.append(params.period_s)
    n = len(rows)
    return StrokeTable(
        start=params.delay + np.asarray(params.phases, dtype=float) / f,
        period=np.full(n_actuators, params.period_s),
        count=np.full(n_actuators, params.count, dtype=np.int64),
        before=np.zeros(n_actuators), after=np.zeros(n_actuators),
        seg_start=np.tile(np.asarray(starts), (n_actuators, 1)),
        seg_coef=np.tile(np.asarray(rows), (n_actuators, 1, 1)),
        n_seg=np.full(n_actuators, n, dtype=np.int64))


@jit
def hermite_coefficients(times: np.ndarray, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray, order: int,
                         coef: np.ndarray) -> None:
    """Fill ``coef`` (actuators, knots − 1, ≥ 6) with the polynomial coefficients c_0..c_5 (local time from
    each knot) of the piecewise Hermite interpolation joint_trajectory_controller runs: ``order`` 5 quintic
    (``acc`` used), 3 cubic (``vel`` only), 1 linear (positions only; ``vel``/``acc`` unread). ``times``
    (n,) s; ``pos``/``vel``/``acc`` (n, actuators); the other entries of ``coef`` are left as they are.

    Compiled: the numpy form (30 array operations over every segment) cost ~0.6 ms for a 5 ms window of
    64 actuators, a quarter of the simulator's time under a continuous stream."""
    for i in range(times.size - 1):
        d = times[i + 1] - times[i]
        for k in range(pos.shape[1]):
            p0, p1 = pos[i, k], pos[i + 1, k]
            c = coef[k, i]
            c[0] = p0
            if order == 1:
                c[1] = (p1 - p0) / d
                continue
            v0, v1 = vel[i, k], vel[i + 1, k]
            c[1] = v0
            if order == 3:
                c[2] = (3.0 * (p1 - p0) - (2.0 * v0 + v1) * d) / (d * d)
                c[3] = (2.0 * (p0 - p1) + (v0 + v1) * d) / (d * d * d)
                continue
            a0, a1 = acc[i, k], acc[i + 1, k]
            c[2] = a0 / 2.0
            dp = p1 - p0 - v0 * d - a0 * d * d / 2.0
            dv = v1 - v0 - a0 * d
            da = a1 - a0
            c[3] = (10.0 * dp - 4.0 * dv * d + da * d * d / 2.0) / d ** 3
            c[4] = (-15.0 * dp + 7.0 * dv * d - da * d * d) / d ** 4
            c[5] = (6.0 * dp - 3.0 * dv * d + da * d * d / 2.0) / d ** 5


def trajectory_table(times: Sequence[float], positions: np.ndarray, velocities: np.ndarray | None = None,
                     accelerations: np.ndarray | None = None) -> StrokeTable:
    """Piecewise Hermite interpolation through knots (docs/dynamics.md §2), holding the last position after.

    ``times`` (n,) absolute sim times (s), strictly increasing; ``positions``, ``velocities``,
    ``accelerations`` (n, n_actuators) in m, m/s, m/s². Quintic Hermite when accelerations are given
    (s̈ continuous), cubic when only velocities are, linear when only positions are
    (joint_trajectory_controller's rules). A single knot holds that position from its time on.
    """
    times = np.asarray(times, dtype=float)
    pos = np.atleast_2d(np.asarray(positions, dtype=float))
    if pos.shape[0] != times.size:
        pos = pos.T
    n_knots, n_act = pos.shape
    if n_knots < 1 or times.size != n_knots or np.any(np.diff(times) <= 0) or not np.all(np.isfinite(pos)):
        raise ValueError('trajectory needs strictly increasing knot times and finite positions, '
                         'one row per knot')
    vel = None if velocities is None else np.asarray(velocities, dtype=float).reshape(n_knots, n_act)
    acc = None if accelerations is None or vel is None else \
        np.asarray(accelerations, dtype=float).reshape(n_knots, n_act)
    n_seg = max(n_knots - 1, 1)
    coef = np.zeros((n_act, n_seg, N_COEF))
    if n_knots > 1:
        order = 1 if vel is None else (3 if acc is None else 5)
        unused = np.zeros((0, 0))
        hermite_coefficients(times, pos, unused if vel is None else vel, unused if acc is None else acc, order,
                             coef)
    if n_knots == 1:                             # a constant segment, then the same value held
        coef[:, 0, 0] = pos[0]
        span = np.array([0.0, 1.0])
    else:
        span = times - times[0]
    if n_knots > 1 and vel is not None:
        seg_start, coef = _jumps_at_short_gaps(times, pos, vel, acc, coef)
        n_seg = seg_start.shape[1] - 1
    else:
        seg_start = np.tile(span, (n_act, 1))
    return StrokeTable(
        start=np.full(n_act, times[0]), period=np.full(n_act, span[-1]),
        count=np.ones(n_act, dtype=np.int64), before=pos[0].copy(), after=pos[-1].copy(),
        seg_start=seg_start, seg_coef=coef, n_seg=np.full(n_act, n_seg, dtype=np.int64))


JUMP_GAP = 2.0e-9     # s: knots at most this far apart mark a breakpoint the stroke jumps across


def is_jump_gap(gap: np.ndarray | float) -> np.ndarray | bool:
    """Whether knots ``gap`` s apart bracket a breakpoint (at most :data:`JUMP_GAP`; knot times are whole
    nanoseconds, so half a nanosecond of margin absorbs their float rounding)."""
    return gap < JUMP_GAP + 0.5e-9


def _jumps_at_short_gaps(times: np.ndarray, pos: np.ndarray, vel: np.ndarray, acc: np.ndarray | None,
                         coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Knots at most :data:`JUMP_GAP` apart are a breakpoint, not a path to interpolate (docs/dynamics.md §2):
    each actuator follows the earlier knot's side (its Taylor polynomial from s, ṡ, s̈) up to a switch time b
    and the later knot's side from b on, so a jump in ṡ or s̈ (the analytic waveform's, which the actuator
    brackets by knots ≤ 2 ns apart) is a hard breakpoint here as it is offline, not a ~1e9 m/s² quintic.

    b is where the two sides meet (:func:`_switch_times`), anywhere in the gap: a gap is short for every
    actuator when one of them has a breakpoint there, so another's breakpoint may lie a hair from a knot
    (the start of a stroke at a trajectory's or a window's first knot, or next to another actuator's knot),
    and an error in b changes the velocity the part carries on with by s̈·δb (a take-off at the corner of an
    ``asymmetric`` stroke: 1e-6 m/s for 0.1 ns). Returns the segment starts from the first knot (actuators,
    segments + 1) and the coefficients (actuators, segments, 9); a side that the switch leaves no time is a
    segment of length 0."""
    span = times - times[0]
    starts = np.tile(span, (pos.shape[1], 1))
    gaps = np.diff(times)
    short = np.flatnonzero(is_jump_gap(gaps))
    if short.size == 0:
        return starts, coef
    acc = np.zeros_like(pos) if acc is None else acc
    d = gaps[short][:, None]                                      # (gaps, actuators) below
    p0, v0, a0 = pos[short], vel[short], acc[short]
    p1, v1, a1 = pos[short + 1], vel[short + 1], acc[short + 1]
    tau = _switch_times(d, p0, v0, a0, p1, v1, a1)
    e = d - tau                                                    # from b to the later knot
    left = np.zeros((short.size, pos.shape[1], coef.shape[2]))
    left[..., 0], left[..., 1], left[..., 2] = p0, v0, a0 / 2.0
    right = np.zeros_like(left)
    right[..., 0], right[..., 1], right[..., 2] = p1 - v1 * e + a1 * e * e / 2.0, v1 - a1 * e, a1 / 2.0
    coef = coef.copy()
    coef[:, short] = left.transpose(1, 0, 2)
    switch = np.minimum(span[short][:, None] + tau, span[short + 1][:, None])     # never past the later knot
    new_starts = np.insert(starts, short + 1, switch.T, axis=1)
    new_coef = np.insert(coef, short + 1, right.transpose(1, 0, 2), axis=1)
    return new_starts, new_coef


def _switch_times(d: np.ndarray, p0: np.ndarray, v0: np.ndarray, a0: np.ndarray, p1: np.ndarray, v1: np.ndarray,
                  a1: np.ndarray) -> np.ndarray:
    """τ in [0, d]: where the earlier knot's side (p0, v0, a0 at τ = 0) meets the later one's (p1, v1, a1 at
    τ = d), elementwise. The stroke's position is continuous at a breakpoint, so b is a root of the
    difference of the two sides' Taylor parabolas, Q(τ) = Aτ² + Bτ + C:

    * a jump in ṡ (Δv) is a simple root, the other lying 2Δv/Δs̈ away (~1/ω, far outside a 2-ns gap):
      the root nearest the gap;
    * a jump in s̈ alone is a double root (the sides touch: ṡ is continuous too), which rounding splits
      or lifts off the axis by up to ~1 ps: the vertex, where the two sides' velocities meet;
    * the two cases apart: roots more than 2d apart are a jump in ṡ, nearer ones (or none) a double root.

    Exact but for the sides' next order (the jerk: b off by j·d²/Δs̈, ~1e-19 s for a piezo's strokes).
    Where nothing jumps (a smooth actuator in a gap that another one's breakpoint made short) both sides
    are the same stroke and any τ in the gap does."""
    half_da = (a0 - a1) / 2.0
    b = v0 - v1 + a1 * d
    c = p0 - p1 + v1 * d - a1 * d * d / 2.0
    disc = b * b - 4.0 * half_da * c
    with np.errstate(divide='ignore', invalid='ignore'):
        vertex = np.where(half_da != 0.0, -b / (2.0 * half_da), d / 2.0)
        q = -(b + np.copysign(np.sqrt(np.maximum(disc, 0.0)), b)) / 2.0
        roots = np.stack([q / half_da, c / q])                  # stable: no cancellation in either
    outside = np.maximum(-roots, roots - d)                       # distance from the gap (≤ 0: inside)
    nearest = np.where(outside[0] <= outside[1], roots[0], roots[1])
    tau = np.where(disc > 4.0 * (half_da * d) ** 2, nearest, vertex)
    return np.where(np.isfinite(tau), np.clip(tau, 0.0, d), d / 2.0)


class StrokeSchedule:
    """Stroke sources in force from given sim times on: what the simulator node feeds the model.

    Starts with one table (e.g. the analytic waveform, or a constant hold). A commanded trajectory
    replaces the rest of the current source from its start time on (joint_trajectory_controller
    semantics); the model's ``advance`` splits its work at every switch time.
    """

    def __init__(self, initial: StrokeTable, t_from: float = -math.inf):
        self._pieces: list[tuple[float, StrokeTable]] = [(t_from, initial)]

    @property
    def pieces(self) -> list[tuple[float, StrokeTable]]:
        """(time from which it applies, table), in increasing time (after :meth:`drop_ended`, only from the
        piece in force at that time on)."""
        return list(self._pieces)

    def table_at(self, t: float) -> StrokeTable:
        """The table in force at time ``t`` (the first piece's for a time before it, e.g. before a time given
        to :meth:`drop_ended`)."""
        return self._pieces[self._index_at(t)][1]

    def _index_at(self, t: float) -> int:
        """Index of the piece in force at ``t``: the last one starting at or before it (0 if none does)."""
        return max(bisect.bisect_right(self._pieces, t, key=lambda piece: piece[0]) - 1, 0)

    def spans(self, t0: float, t1: float) -> list[tuple[float, float, StrokeTable]]:
        """(from, until, table) of each piece in force during (t0, t1], in time order: a piece applies on
        [from, until), ``until`` being the next piece's start (inf for the last). Found by bisection: the
        simulator asks every 1 ms tick."""
        pieces = self._pieces
        out = []
        for i in range(self._index_at(t0), len(pieces)):
            t_from, table = pieces[i]
            if t_from >= t1:
                break
            t_until = pieces[i + 1][0] if i + 1 < len(pieces) else math.inf
            if t_until > t0:
                out.append((t_from, t_until, table))
        return out

    def evaluate(self, t: float) -> np.ndarray:
        """(3, n_channels) s, ṡ, s̈ at ``t`` from the table in force."""
        return self.table_at(t).evaluate(t)

    @classmethod
    def of_pieces(cls, pieces: Sequence[tuple[float, StrokeTable]]) -> StrokeSchedule:
        """A schedule made of ``pieces`` ((time from which it applies, table), in increasing time)."""
        schedule = cls(pieces[0][1], pieces[0][0])
        schedule._pieces = list(pieces)
        return schedule

    def drop_ended(self, t: float) -> None:
        """Forget the pieces that ended at or before ``t``: they no longer affect anything from ``t`` on (a
        streamed burst adds one a window, and every lookup walks them)."""
        del self._pieces[:self._index_at(t)]

    def replace_from(self, t_start: float, table: StrokeTable) -> None:
        """Use ``table`` from ``t_start`` on, dropping whatever was scheduled at or after that time."""
        self._pieces = [(t, tab) for t, tab in self._pieces if t < t_start] + [(t_start, table)]

    def command_trajectory(self, t_start: float, knot_times: Sequence[float], positions: np.ndarray,
                           velocities: np.ndarray | None = None,
                           accelerations: np.ndarray | None = None, own_table: StrokeTable | None = None
                           ) -> StrokeTable:
        """Replace the schedule from ``t_start`` with a trajectory through the given knots.

        ``knot_times`` are absolute sim times (header stamp + time_from_start); knots before ``t_start`` are
        dropped. A knot exactly at ``t_start`` is the stroke from then on (joint_trajectory_controller
        samples a point at time 0 as it is): a stream's window starts where the previous one ends, at a knot
        both share, and a burst that starts with a jump (a ``sine``, a ``samples`` shape not starting at 0)
        jumps at its start, as offline. Otherwise the current stroke (s, ṡ, s̈ at ``t_start``) becomes the
        first knot, so the stroke stays continuous. (The current stroke at a piece's very end is its held
        value with ṡ = s̈ = 0: taking it instead of the shared knot put a velocity kink at every window
        joint, which threw the part of the soak's travelling wave 123 mm.) An empty trajectory holds the
        current position. Returns the table now in force from ``t_start``.

        ``own_table``: :func:`trajectory_table` of exactly these knots, made beforehand; it is the table when
        the knots start at ``t_start`` and none is dropped (then the current stroke plays no part).
        """
        times = np.asarray(knot_times, dtype=float)
        if own_table is not None and times.size and times[0] == t_start and bool((times[1:] > t_start).all()):
            self.replace_from(t_start, own_table)
            return own_table
        keep = times > t_start
        current = self.evaluate(t_start)
        n_act = current.shape[1]
        at_start = np.flatnonzero(times == t_start)
        first_index = int(at_start[0]) if at_start.size else None

        def rows(values: np.ndarray | None, first: np.ndarray) -> np.ndarray | None:
            if values is None:
                return None
            values = np.asarray(values, dtype=float).reshape(times.size, n_act)
            return np.vstack([first if first_index is None else values[first_index], values[keep]])

        table = trajectory_table(np.concatenate([[t_start], times[keep]]),
                                 rows(positions, current[0]), rows(velocities, current[1]),
                                 rows(accelerations, current[2]))
        self.replace_from(t_start, table)
        return table

    def hold_from(self, t_start: float) -> StrokeTable:
        """Stop: hold the stroke at its position at ``t_start`` (an empty trajectory message)."""
        return self.command_trajectory(t_start, [], np.zeros((0, self.evaluate(t_start).shape[1])))
