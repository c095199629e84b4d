"""The compiled inner loop: particle on the actuated surface, RK4 with event location.

Plain functions over numpy arrays so that numba compiles them (``NUMBA_DISABLE_JIT=1`` runs the very
same code as Python). The public, documented API is :mod:`micro_feeder.physics.dynamics.model`; this
module is its engine. Equations: docs/dynamics.md §1; event location: docs/events.md.

Data passed around (all SI):

* ``model``: a :class:`KernelModel`, the immutable inputs by name (MuJoCo's ``mjModel``);
* ``src``: a :class:`~micro_feeder.physics.waveforms.StrokeTable` as a tuple; channels 0..n_act-1 are
  the actuators, channel n_act (present when ``model.has_base``) the horizontal base acceleration of
  the test-only flat-surface check (its s̈ is the base acceleration);
* ``y``: state vector. In contact ``[x, ẋ, 0, 0]``, in flight ``[x, v_x, z, v_z]``; then, with the piezo
  model, ``[s_k, ṡ_k]`` per actuator;
* ``iv`` (int64) and ``fs`` (float64): discrete state and bookkeeping, indexed by ``IV_*`` / ``FS_*``.

Every mode has two *margins*, positive while the mode lasts; an event is a margin reaching 0:
stuck: Q_max − |T_req| and N_det + F_po; sliding: dir·ẋ and N_det + F_po; flying: the gap δ.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._jit import jit, jit_inline
from ..piezo import piezo_acceleration
from ..surface import surface_at
from ..waveforms import COEF_OMEGA, channel_value, locate_segment, segment_end

STUCK, SLIDING, FLYING = 0, 1, 2


class KernelModel(NamedTuple):
    """Everything the kernel reads and never changes, by name (SI units): built by
    :class:`~micro_feeder.physics.dynamics.model.FeederModel`. numba compiles it as a typed tuple."""

    mass: float                 # particle mass (kg)
    gravity: float              # g (m/s²)
    pull_off: float             # pull-off force F_po (N)
    dt: float                   # RK4 step / largest DOPRI5 step (s)
    tolerance: float            # DOPRI5 error allowed per step on positions (m)
    check_step: float           # largest step while stuck (s)
    event_tolerance: float      # time tolerance of event location (s)
    cutoff_radius: float        # surface.cutoff as a radius in widths (inf: exact sum; docs/dynamics.md)
    piezo_omega: float          # piezo stack natural angular frequency (rad/s)
    piezo_zeta: float           # piezo stack damping ratio
    piezo_min: float            # piezo travel limits (m)
    piezo_max: float
    adaptive: bool              # DOPRI5 (else fixed-step RK4)
    threshold: bool             # the seed's threshold-velocity friction logic (else exact events)
    dip_search: bool            # event_search 'dips': margins' minima inside steps are searched
    convective: bool            # 2 h_xt ẋ + h_xx ẋ² kept in the normal load
    include_weight: bool        # take-off test with the weight inside N
    landing_relative: bool      # landing keeps the velocity relative to the surface
    piezo: bool                 # piezo stack dynamics integrated (state y[4:])
    has_base: bool              # test-only base-acceleration channel after the actuators
    record: bool                # write one output row per step and event
    centers: np.ndarray         # actuator centres (m)
    widths: np.ndarray          # actuator widths (m)
    load_n: np.ndarray          # contact tables: normal load (N) ...
    q_max_n: np.ndarray         # ... and Q_max at that load (N), separation (m) at that load
    separation_m: np.ndarray
    gap_m: np.ndarray           # flight table: gap (m) ...
    attraction_n: np.ndarray    # ... and adhesive attraction (N)
    n_actuators: int


# iv: discrete state. IV_ENTRY_COUNTER: the counter incremented when the current mode was entered (-1
# none), IV_PREV_MODE: the mode before it; both serve "a mode that ends within the event tolerance of
# its start is treated as not entered".
# IV_AHEAD_*: the step taken past the last target (see ``advance``); IV_START_*: what the dip search
# knows about the margins' slopes where the next step starts.
(IV_MODE, IV_DIR, IV_FRESH, IV_STICK_TO_SLIP, IV_SLIP_TO_STICK, IV_TAKE_OFF, IV_LANDING,
 IV_ENTRY_COUNTER, IV_PREV_MODE, IV_AHEAD_WHICH, IV_AHEAD_GRAZING, IV_START_KNOWN, IV_START_DOWN0,
 IV_START_DOWN1) = range(14)
N_IV = 14
COUNTERS = (IV_STICK_TO_SLIP, IV_SLIP_TO_STICK, IV_TAKE_OFF, IV_LANDING)

# fs: continuous bookkeeping (FS_H: the adaptive step size to try next; FS_AHEAD_T0/T1: start and end of
# the step taken past the last target, T1 NaN when there is none)
FS_T, FS_T_ENTRY, FS_MAX_SPEED, FS_H, FS_AHEAD_T0, FS_AHEAD_T1 = range(6)
N_FS = 6
N_SCRATCH = 11

# Dormand-Prince 5(4): nodes, stage coefficients, 5th-order weights, error weights (b - b*).
DP_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0)
DP_A = ((1 / 5, 0.0, 0.0, 0.0, 0.0),
        (3 / 40, 9 / 40, 0.0, 0.0, 0.0),
        (44 / 45, -56 / 15, 32 / 9, 0.0, 0.0),
        (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0),
        (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656))
DP_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84)
DP_E = (71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40)
# Dense output (Hairer & Wanner's DOPRI5 continuous extension, 4th order): weights of k1, k3..k7.
DP_D = (-12715105075 / 11282082432, 87487479700 / 32700410799, -10690763975 / 1880347072,
        701980252875 / 199316789632, -1453857185 / 822651844, 69997945 / 29380423)

# aux: quantities of the last evaluation
(AUX_N, AUX_T_REQ, AUX_QMAX, AUX_L, AUX_H, AUX_HX, AUX_HT, AUX_GAP, AUX_XS, AUX_LOAD_INDEX,
 AUX_ROOT_SLOPE) = range(11)
N_AUX = 11

# Columns of a recorded row (then one stroke column per actuator).
(C_T, C_MODE, C_X, C_Z, C_XD, C_ZD, C_THETA, C_N, C_FRICTION, C_QMAX, C_SEPARATION, C_GAP, C_H,
 C_HT) = range(14)
N_FIXED_COLUMNS = 14
COLUMN_NAMES = ('t', 'mode', 'x', 'z', 'xdot', 'zdot', 'theta', 'normal_load', 'friction', 'q_max',
                'separation', 'gap', 'surface_height', 'surface_velocity')

# Kernel return codes.
DONE, EVENTS_FULL, RECORDS_FULL, NON_FINITE, EVENT_NOT_LOCATED, CHATTER = range(6)

# Event kinds (recorded with each mode change); REVERSAL: a slide changing direction (not counted).
STICK_TO_SLIP, SLIP_TO_STICK, TAKE_OFF, LANDING, REVERSAL = range(5)


@jit_inline
def interp(xs: np.ndarray, ys: np.ndarray, x: float) -> float:
    """Linear interpolation in a table with increasing ``xs``, extrapolated linearly at both ends."""
    n = xs.size
    i = min(max(int(np.searchsorted(xs, x)) - 1, 0), n - 2)
    return ys[i] + (x - xs[i]) * (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i])


@jit_inline
def interp_near(xs: np.ndarray, ys: np.ndarray, x: float, aux: np.ndarray, slot: int) -> float:
    """:func:`interp`, searching from the interval found last time (kept in ``aux[slot]``): the load
    changes little between evaluations, so this walks 0-2 intervals instead of bisecting the table."""
    last = xs.size - 2
    i = min(max(int(aux[slot]), 0), last)
    while i > 0 and x < xs[i]:
        i -= 1
    while i < last and x >= xs[i + 1]:
        i += 1
    aux[slot] = i
    return ys[i] + (x - xs[i]) * (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i])


@jit_inline
def attraction(gap_m: np.ndarray, attraction_n: np.ndarray, gap: float) -> float:
    """F_att(δ) ≥ 0 (N): table, then the (ε/d)² tail beyond its last gap; δ < 0 reads as 0."""
    last = gap_m.size - 1
    if gap >= gap_m[last]:
        return attraction_n[last] * (gap_m[last] / gap) ** 2
    return interp(gap_m, attraction_n, max(gap, 0.0))


@jit_inline
def strokes_at(t: float, y: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
               st: np.ndarray, every: bool) -> float:
    """Fill ``st`` (3, channels) with s, ṡ, s̈ at ``t`` on the segments ``cur``; return the base
    acceleration (m/s², 0 without the test-only base channel). With the piezo model the actuators'
    s, ṡ come from the state and s̈ from the stack dynamics driven by the commanded stroke.

    Unless ``every`` (or with the piezo model, whose every stack is integrated), an actuator that
    ``surface_at`` skips at x = y[0] (beyond ``model.cutoff_radius`` widths) reads 0 instead of its stroke."""
    n_act = model.n_actuators
    skip = not every and not model.piezo
    for k in range(st.shape[1]):
        if skip and k < n_act and abs((y[0] - model.centers[k]) / model.widths[k]) > model.cutoff_radius:
            st[0, k] = st[1, k] = st[2, k] = 0.0
            continue
        s, sd, sdd = channel_value(src, k, cur[k, 0], cur[k, 1], t)
        st[0, k] = s
        st[1, k] = sd
        st[2, k] = sdd
    if model.piezo:
        for k in range(n_act):
            s = y[4 + 2 * k]
            sd = y[5 + 2 * k]
            st[2, k] = piezo_acceleration(st[0, k], s, sd, model.piezo_omega, model.piezo_zeta,
                                          model.piezo_min, model.piezo_max)
            st[0, k] = s
            st[1, k] = sd
    return st[2, n_act] if model.has_base else 0.0


@jit_inline
def contact_load(x: float, xd: float, st: np.ndarray, base_acc: float, model: KernelModel,
                 aux: np.ndarray) -> None:
    """Normal load N, required friction T_req and Q_max(N) for a part on the surface at (x, ẋ).

    N = m (h_tt + 2 h_xt ẋ + h_xx ẋ² + g − h_x a_b) / L, T_req = N h_x + m L a_b (a_b: base
    acceleration, 0 except in the flat-surface check), and ẍ = (T − T_req) / (m L).
    """
    m = model.mass
    h, hx, hxx, ht, htt, hxt = surface_at(x, st[0], st[1], st[2], model.centers, model.widths, model.cutoff_radius)
    length = math.sqrt(1.0 + hx * hx)
    normal_acc = htt + model.gravity - hx * base_acc
    if model.convective:
        normal_acc += 2.0 * hxt * xd + hxx * xd * xd
    n = m * normal_acc / length
    aux[AUX_N] = n
    aux[AUX_T_REQ] = n * hx + m * length * base_acc
    aux[AUX_QMAX] = interp_near(model.load_n, model.q_max_n, n, aux, AUX_LOAD_INDEX)
    aux[AUX_L] = length
    aux[AUX_H] = h
    aux[AUX_HX] = hx
    aux[AUX_HT] = ht


@jit
def closest_point(x: float, z: float, st: np.ndarray, model: KernelModel, aux: np.ndarray) -> None:
    """Closest surface point to (x, z) by Newton on its abscissa x_s; sets AUX_XS, AUX_H, AUX_HX (at
    x_s), AUX_L and AUX_GAP = signed distance along the normal there (> 0 above the surface)."""
    centers, widths = model.centers, model.widths
    xs = x
    for _ in range(20):
        h, hx, hxx, _ht, _htt, _hxt = surface_at(xs, st[0], st[1], st[2], centers, widths, model.cutoff_radius)
        step = ((xs - x) + (h - z) * hx) / (1.0 + hx * hx + (h - z) * hxx)
        xs -= step
        if abs(step) <= 1e-15 + 1e-13 * abs(xs):
            break
    h, hx, _hxx, _ht, _htt, _hxt = surface_at(xs, st[0], st[1], st[2], centers, widths, model.cutoff_radius)
    length = math.sqrt(1.0 + hx * hx)
    aux[AUX_XS] = xs
    aux[AUX_H] = h
    aux[AUX_HX] = hx
    aux[AUX_L] = length
    aux[AUX_GAP] = ((z - h) - hx * (x - xs)) / length


@jit_inline
def evaluate(mode: int, direction: int, t: float, y: np.ndarray, model: KernelModel, src: tuple,
             cur: np.ndarray, st: np.ndarray, aux: np.ndarray, dy: np.ndarray) -> tuple[float, float]:
    """Right-hand side ``dy`` of mode ``mode`` at (t, y), and the mode's two margins."""
    m = model.mass
    base_acc = strokes_at(t, y, model, src, cur, st, mode == FLYING)
    for i in range(dy.size):
        dy[i] = 0.0
    if model.piezo:
        for k in range(model.n_actuators):
            dy[4 + 2 * k] = st[1, k]
            dy[5 + 2 * k] = st[2, k]
    if mode == FLYING:
        closest_point(y[0], y[2], st, model, aux)
        f_att = attraction(model.gap_m, model.attraction_n, aux[AUX_GAP])
        aux[AUX_N] = -f_att
        dy[0] = y[1]
        dy[1] = -base_acc + f_att * aux[AUX_HX] / (aux[AUX_L] * m)
        dy[2] = y[3]
        dy[3] = -model.gravity - f_att / (aux[AUX_L] * m)
        return aux[AUX_GAP], math.inf
    contact_load(y[0], y[1], st, base_acc, model, aux)
    n_detach = aux[AUX_N]
    if not model.include_weight:
        n_detach -= m * model.gravity / aux[AUX_L]
    adhesion_margin = n_detach + model.pull_off
    if mode == STUCK:
        stick_margin = math.inf if model.threshold else aux[AUX_QMAX] - abs(aux[AUX_T_REQ])
        return stick_margin, adhesion_margin
    friction = -direction * aux[AUX_QMAX]
    dy[0] = y[1]
    dy[1] = (friction - aux[AUX_T_REQ]) / (m * aux[AUX_L])
    slide_margin = math.inf if model.threshold else direction * y[1]
    return slide_margin, adhesion_margin


@jit
def locate_all(src: tuple, t: float, cur: np.ndarray) -> float:
    """Point ``cur`` at the segments active at ``t`` (right side); return the next breakpoint."""
    t_next = math.inf
    for k in range(cur.shape[0]):
        j, i = locate_segment(src, k, t)
        cur[k, 0] = j
        cur[k, 1] = i
        t_next = min(t_next, segment_end(src, k, j, i))
    return t_next


@jit
def wave_step(src: tuple, cur: np.ndarray) -> float:
    """Largest step (s) that keeps each margin to one local extremum per step: an eighth of the period of
    the fastest sinusoid in the active segments (a margin mixes strokes nonlinearly, doubling their
    frequency); inf when no segment has one."""
    seg_coef = src[6]
    fastest = 0.0
    for k in range(cur.shape[0]):
        if cur[k, 0] >= 0:
            fastest = max(fastest, abs(seg_coef[k, cur[k, 1], COEF_OMEGA]))
    return math.pi / (4.0 * fastest) if fastest > 0.0 else math.inf


@jit
def rk4_step(mode: int, direction: int, t: float, y: np.ndarray, f0: np.ndarray, h: float, model: KernelModel,
             src: tuple, cur: np.ndarray, st: np.ndarray, aux: np.ndarray, work: np.ndarray,
             out: np.ndarray) -> None:
    """One classical RK4 step of size ``h`` from (t, y) with slope ``f0`` at its start, into ``out``
    (stages k2..k4 in ``work[0:3]``; one evaluation site in a loop, compiled once)."""
    k2, k3, k4, ytmp = work[0], work[1], work[2], work[3]
    n = y.size
    for stage in range(3):
        previous = f0 if stage == 0 else work[stage - 1]
        weight = 1.0 if stage == 2 else 0.5
        for i in range(n):
            ytmp[i] = y[i] + weight * h * previous[i]
        evaluate(mode, direction, t + weight * h, ytmp, model, src, cur, st, aux, work[stage])
    for i in range(n):
        out[i] = y[i] + (h / 6.0) * (f0[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@jit
def dopri5_step(mode: int, direction: int, t: float, y: np.ndarray, f0: np.ndarray, h: float,
                model: KernelModel, src: tuple, cur: np.ndarray, st: np.ndarray, aux: np.ndarray,
                work: np.ndarray, out: np.ndarray) -> None:
    """The 5th-order Dormand-Prince solution of a step of size ``h`` from (t, y), slope ``f0``, into
    ``out``; stages k2..k6 are left in ``work[0:5]`` for :func:`dopri5_error` and :func:`dopri5_dense`.
    (One evaluation site in a loop: the inlined right-hand side is compiled once, not five times.)"""
    ytmp = work[5]
    n = y.size
    for stage in range(5):
        a = DP_A[stage]
        for i in range(n):
            acc = a[0] * f0[i]
            for j in range(stage):
                acc += a[j + 1] * work[j, i]
            ytmp[i] = y[i] + h * acc
        evaluate(mode, direction, t + DP_C[stage + 1] * h, ytmp, model, src, cur, st, aux, work[stage])
    for i in range(n):
        out[i] = y[i] + h * (DP_B[0] * f0[i] + DP_B[2] * work[1, i] + DP_B[3] * work[2, i]
                             + DP_B[4] * work[3, i] + DP_B[5] * work[4, i])


@jit_inline
def dopri5_error(h: float, f0: np.ndarray, work: np.ndarray, f1: np.ndarray, tolerance: float,
                 max_step: float) -> float:
    """Embedded error estimate of the last :func:`dopri5_step` (slope ``f1`` at its end), as a multiple
    of the allowed error: ``tolerance`` (m) on positions, ``tolerance / max_step`` (m/s) on velocities
    (even / odd state entries). ≤ 1 accepts the step."""
    worst = 0.0
    for i in range(f0.size):
        acc = (DP_E[0] * f0[i] + DP_E[2] * work[1, i] + DP_E[3] * work[2, i] + DP_E[4] * work[3, i]
               + DP_E[5] * work[4, i] + DP_E[6] * f1[i])
        scale = tolerance if i % 2 == 0 else tolerance / max_step
        worst = max(worst, abs(h * acc) / scale)
    return worst


@jit_inline
def dopri5_dense(theta: float, h: float, y0: np.ndarray, f0: np.ndarray, y1: np.ndarray, f1: np.ndarray,
                 work: np.ndarray, out: np.ndarray) -> None:
    """DOPRI5's own 4th-order interpolant of the last :func:`dopri5_step` (stages in ``work[1:5]``)."""
    for i in range(y0.size):
        r2 = y1[i] - y0[i]
        r3 = h * f0[i] - r2
        r4 = r2 - h * f1[i] - r3
        r5 = h * (DP_D[0] * f0[i] + DP_D[1] * work[1, i] + DP_D[2] * work[2, i] + DP_D[3] * work[3, i]
                  + DP_D[4] * work[4, i] + DP_D[5] * f1[i])
        out[i] = y0[i] + theta * (r2 + (1.0 - theta) * (r3 + theta * (r4 + (1.0 - theta) * r5)))


@jit_inline
def hermite(theta: float, h: float, y0: np.ndarray, f0: np.ndarray, y1: np.ndarray, f1: np.ndarray,
            out: np.ndarray) -> None:
    """Cubic Hermite interpolant of a step at fraction ``theta`` (dense output, 4th-order accurate)."""
    t2 = theta * theta
    t3 = t2 * theta
    a0, b0, a1, b1 = 2 * t3 - 3 * t2 + 1, (t3 - 2 * t2 + theta) * h, -2 * t3 + 3 * t2, (t3 - t2) * h
    for i in range(y0.size):
        out[i] = a0 * y0[i] + b0 * f0[i] + a1 * y1[i] + b1 * f1[i]


@jit
def locate_root(which: int, mode: int, direction: int, t: float, h: float, y0: np.ndarray,
                f0: np.ndarray, y1: np.ndarray, f1: np.ndarray, g_start: float, g_end: float,
                model: KernelModel, src: tuple, cur: np.ndarray, st: np.ndarray, aux: np.ndarray,
                work: np.ndarray, dense: bool) -> float:
    """Step fraction at which margin ``which`` (0 or 1) first reaches 0 on the step's interpolant
    (``dense``: the Dormand-Prince interpolant of the step just taken; else cubic Hermite).

    Illinois regula falsi, with bisection while the left end is not strictly positive (a margin that
    is 0 by construction at the start of a fresh mode). Returns the right end of the final bracket
    (where the margin is ≤ 0), narrower than the event tolerance; -1 if it could not be located.
    The margin's slope across the final bracket (per second) is left in ``aux[AUX_ROOT_SLOPE]``.
    """
    tol = model.event_tolerance / h
    a, b = 0.0, 1.0
    ga, gb = g_start, g_end
    side = 0
    true_a, true_b = g_start, g_end          # unhalved margins at the bracket ends
    yi, dy = work[9], work[10]
    for it in range(200):
        if b - a <= tol:
            aux[AUX_ROOT_SLOPE] = (true_b - true_a) / ((b - a) * h)
            return b
        if ga > 0.0 and it < 60:
            theta = b - gb * (b - a) / (gb - ga)
            theta = min(max(theta, a + 0.25 * tol), b - 0.25 * tol)
        else:
            theta = 0.5 * (a + b)
        if dense:
            dopri5_dense(theta, h, y0, f0, y1, f1, work, yi)
        else:
            hermite(theta, h, y0, f0, y1, f1, yi)
        if mode == SLIDING and which == 0:  # the slide margin dir·ẋ needs no force evaluation
            g = direction * yi[1]
        else:
            g = evaluate(mode, direction, t + theta * h, yi, model, src, cur, st, aux, dy)[which]
        if g > 0.0:
            a, ga, true_a = theta, g, g
            if side == 1:
                gb *= 0.5
            side = 1
        else:
            b, gb, true_b = theta, g, g
            if side == -1:
                ga *= 0.5
            side = -1
    return -1.0


@jit_inline
def margins_at(theta: float, mode: int, direction: int, t: float, h: float, y0: np.ndarray, f0: np.ndarray,
               y1: np.ndarray, f1: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray, st: np.ndarray,
               aux: np.ndarray, work: np.ndarray, dense: bool) -> tuple[float, float]:
    """Both margins at step fraction ``theta`` on the step's interpolant (as :func:`locate_root`)."""
    yi, dy = work[9], work[10]
    if dense:
        dopri5_dense(theta, h, y0, f0, y1, f1, work, yi)
    else:
        hermite(theta, h, y0, f0, y1, f1, yi)
    return evaluate(mode, direction, t + theta * h, yi, model, src, cur, st, aux, dy)


@jit_inline
def crossed(value: float, strict: bool) -> bool:
    """A margin past its event: < 0 for the stick margin (stuck holds at |T_req| = Q_max), else ≤ 0."""
    return value < 0.0 if strict else value <= 0.0


@jit_inline
def first_dip(mode: int, direction: int, t: float, h: float, y0: np.ndarray, f0: np.ndarray, y1: np.ndarray,
              f1: np.ndarray, g0: float, g1: float, e0: float, e1: float, fresh: bool, start_known: bool,
              start_down0: bool, start_down1: bool, model: KernelModel, src: tuple, cur: np.ndarray, st: np.ndarray,
              aux: np.ndarray, work: np.ndarray, dense: bool) -> tuple[float, float, float]:
    """Step fraction of a point where a margin, positive at both ends of the step, dips past its event
    inside it (-1 if there is none), and both margins just before the step's end.

    A margin with an interior minimum decreases just after the start and increases just before the end
    (compared at δ = min(1e-3, event_tolerance / h) inside each end; at the start, when ``start_known``,
    the previous step's end tells, ``start_down0/1``). Its minimum is then searched (:func:`brent_dip`)
    to the event tolerance, stopping at the first point past the event. Guarantee, under the assumption
    that a margin has at most one local minimum within one step (docs/events.md): a dip longer than the
    event tolerance is found, whatever the step size.
    """
    tol = model.event_tolerance / h
    if tol >= 0.25:
        return -1.0, math.nan, math.nan
    delta = min(1e-3, tol)
    b0, b1 = margins_at(1.0 - delta, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work,
                        dense)
    if not start_known:
        a0, a1 = margins_at(delta, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work, dense)
        start_down0, start_down1 = a0 < g0, a1 < g1
    best = 2.0
    for which in range(2):
        start, end = (g0, e0) if which == 0 else (g1, e1)
        near_end, down = (b0, start_down0) if which == 0 else (b1, start_down1)
        if not (math.isfinite(start) and math.isfinite(end)) or (which == 0 and fresh):
            continue
        strict = mode == STUCK and which == 0
        if crossed(near_end, strict):
            theta = 1.0 - delta
        elif down and near_end < end:
            theta = brent_dip(which, strict, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux,
                              work, dense, tol)
        else:
            continue
        if 0.0 < theta < best:
            best = theta
    return (best if best <= 1.0 else -1.0), b0, b1


@jit
def brent_dip(which: int, strict: bool, mode: int, direction: int, t: float, h: float, y0: np.ndarray,
              f0: np.ndarray, y1: np.ndarray, f1: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
              st: np.ndarray, aux: np.ndarray, work: np.ndarray, dense: bool, tol: float) -> float:
    """Brent's minimisation (parabolic steps, golden-section fallback) of margin ``which`` over the step
    (fractions 0..1) to ``tol``, returning the first fraction found past the event, or -1 when the
    minimum stays short of it."""
    golden = 0.3819660112501051
    a, b = 0.0, 1.0
    x = w = v = golden
    fx = margins_at(x, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work, dense)[which]
    if crossed(fx, strict):
        return x
    fw = fv = fx
    d = e = 0.0
    for _ in range(100):
        xm = 0.5 * (a + b)
        if abs(x - xm) <= 2.0 * tol - 0.5 * (b - a):
            break
        parabolic = False
        if abs(e) > tol:
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            p = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            if abs(p) < abs(0.5 * q * e) and q * (a - x) < p < q * (b - x):
                e = d
                d = p / q
                parabolic = True
                if (x + d) - a < 2.0 * tol or b - (x + d) < 2.0 * tol:
                    d = tol if xm >= x else -tol
        if not parabolic:
            e = (a - x) if x >= xm else (b - x)
            d = golden * e
        u = x + d if abs(d) >= tol else x + (tol if d > 0.0 else -tol)
        fu = margins_at(u, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work, dense)[which]
        if crossed(fu, strict):
            return u
        if fu <= fx:
            if u >= x:
                a = x
            else:
                b = x
            v, w, x = w, x, u
            fv, fw, fx = fw, fx, fu
        else:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, w = w, u
                fv, fw = fw, fu
            elif fu <= fv or v in (x, w):
                v, fv = u, fu
    return -1.0


@jit
def enter(iv: np.ndarray, fs: np.ndarray, t: float, new_mode: int, counter: int, grazing: bool) -> None:
    """Switch to ``new_mode`` at ``t`` and count the transition in ``iv[counter]`` (-1: not counted).

    ``grazing``: the mode being left ends (at a located event) within the event tolerance of its start,
    so it counts as never entered: this transition is not counted, and when the part returns to the
    mode it came from, the entry into the grazed mode is uncounted too (docs/dynamics.md §1).
    """
    if grazing:
        if new_mode == iv[IV_PREV_MODE] and iv[IV_ENTRY_COUNTER] >= 0:
            iv[iv[IV_ENTRY_COUNTER]] -= 1
        counter = -1
    elif counter >= 0:
        iv[counter] += 1
    iv[IV_PREV_MODE] = iv[IV_MODE]
    iv[IV_MODE] = new_mode
    iv[IV_ENTRY_COUNTER] = counter
    fs[FS_T_ENTRY] = t


@jit_inline
def copy_into(target: np.ndarray, values: np.ndarray) -> None:
    """target[:] = values, element by element (a slice assignment may allocate a temporary)."""
    for i in range(values.size):
        target[i] = values[i]


@jit_inline
def finite(values: np.ndarray) -> bool:
    """True when every entry is finite (an explicit loop: numba compiles no generator expressions)."""
    for v in values:  # noqa: SIM110
        if not math.isfinite(v):
            return False
    return True


@jit_inline
def sign(value: float) -> int:
    """+1, -1 or 0."""
    return 1 if value > 0.0 else (-1 if value < 0.0 else 0)


@jit
def transition(which: int, t: float, y: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
               st: np.ndarray, aux: np.ndarray, iv: np.ndarray, fs: np.ndarray, grazing: bool) -> int:
    """Apply the event of margin ``which`` in the current mode at (t, y) (docs/dynamics.md §1); returns
    the event kind. ``y`` is rewritten for the new mode."""
    mode = iv[IV_MODE]
    base_acc = strokes_at(t, y, model, src, cur, st, False)
    if mode == FLYING:                                     # landing: keep the tangential velocity
        _h, hx, _hxx, ht, _htt, _hxt = surface_at(y[0], st[0], st[1], st[2], model.centers, model.widths,
                                                  model.cutoff_radius)
        surface_vz = ht if model.landing_relative else 0.0
        xd = (y[1] + hx * (y[3] - surface_vz)) / (1.0 + hx * hx)
        y[1] = xd
        y[2] = 0.0
        y[3] = 0.0
        iv[IV_DIR] = sign(xd)
        iv[IV_FRESH] = 0
        enter(iv, fs, t, SLIDING if xd != 0.0 else STUCK, IV_LANDING, grazing)
        return LANDING
    if which == 1:                                         # take-off with the contact velocity
        h, hx, _hxx, ht, _htt, _hxt = surface_at(y[0], st[0], st[1], st[2], model.centers, model.widths,
                                                  model.cutoff_radius)
        y[2] = h
        y[3] = ht + hx * y[1]
        iv[IV_FRESH] = 1
        enter(iv, fs, t, FLYING, IV_TAKE_OFF, grazing)
        return TAKE_OFF
    y[1] = 0.0
    contact_load(y[0], 0.0, st, base_acc, model, aux)
    if mode == STUCK:                                      # friction opposes the impending motion
        iv[IV_DIR] = -sign(aux[AUX_T_REQ])
        iv[IV_FRESH] = 1
        enter(iv, fs, t, SLIDING, IV_STICK_TO_SLIP, grazing)
        return STICK_TO_SLIP
    if abs(aux[AUX_T_REQ]) <= aux[AUX_QMAX]:               # sliding came to rest and can stay
        enter(iv, fs, t, STUCK, IV_SLIP_TO_STICK, grazing)
        return SLIP_TO_STICK
    iv[IV_DIR] = -sign(aux[AUX_T_REQ])                     # slides back the other way (not counted)
    iv[IV_FRESH] = 1
    return REVERSAL


@jit
def threshold_decision(t: float, y: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
                       st: np.ndarray, aux: np.ndarray, iv: np.ndarray, fs: np.ndarray) -> int:
    """The seed's threshold-velocity friction logic at the start of a step (contact modes only).

    V_th = Q_max dt / m. Slip if |v_rel| ≥ V_th (friction opposes v_rel), or if |T_req| > Q_max
    (friction opposes the impending motion); stick (ẋ = 0) otherwise. Returns the event kind of a mode
    change, or -1.
    """
    base_acc = strokes_at(t, y, model, src, cur, st, False)
    contact_load(y[0], y[1], st, base_acc, model, aux)
    v_rel = y[1] * aux[AUX_L]
    v_threshold = aux[AUX_QMAX] * model.dt / model.mass
    if v_rel != 0.0 and abs(v_rel) >= v_threshold:
        new_mode, direction = SLIDING, sign(v_rel)
    elif abs(aux[AUX_T_REQ]) > aux[AUX_QMAX]:
        new_mode, direction = SLIDING, -sign(aux[AUX_T_REQ])
    else:
        new_mode, direction = STUCK, 0
        y[1] = 0.0
    iv[IV_DIR] = direction
    if new_mode == iv[IV_MODE]:
        return -1
    if new_mode == SLIDING:
        enter(iv, fs, t, SLIDING, IV_STICK_TO_SLIP, False)
        return STICK_TO_SLIP
    enter(iv, fs, t, STUCK, IV_SLIP_TO_STICK, False)
    return SLIP_TO_STICK


@jit
def observe(t: float, y: np.ndarray, iv: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
            st: np.ndarray, aux: np.ndarray, dy: np.ndarray, row: np.ndarray) -> None:
    """Fill ``row`` with the outputs of docs/dynamics.md §4 at (t, y) (columns ``COLUMN_NAMES``, then the
    actuator strokes). Normal load in flight: −F_att (the attraction, continuous with N at take-off)."""
    mode = iv[IV_MODE]
    evaluate(mode, iv[IV_DIR], t, y, model, src, cur, st, aux, dy)
    row[C_T] = t
    row[C_MODE] = mode
    row[C_X] = y[0]
    row[C_XD] = y[1]
    row[C_THETA] = math.atan(aux[AUX_HX])
    row[C_N] = aux[AUX_N]
    strokes_at(t, y, model, src, cur, st, True)            # every stroke column exact, felt or not
    for k in range(model.n_actuators):
        row[N_FIXED_COLUMNS + k] = st[0, k]
    if mode == FLYING:
        h, _hx, _hxx, ht, _htt, _hxt = surface_at(y[0], st[0], st[1], st[2], model.centers, model.widths,
                                                  model.cutoff_radius)
        row[C_Z] = y[2]
        row[C_ZD] = y[3]
        row[C_FRICTION] = 0.0
        row[C_QMAX] = math.nan
        row[C_SEPARATION] = math.nan
        row[C_GAP] = aux[AUX_GAP]
        row[C_H] = h
        row[C_HT] = ht
        return
    row[C_Z] = aux[AUX_H]
    row[C_ZD] = aux[AUX_HT] + aux[AUX_HX] * y[1]
    row[C_FRICTION] = aux[AUX_T_REQ] if mode == STUCK else -iv[IV_DIR] * aux[AUX_QMAX]
    row[C_QMAX] = aux[AUX_QMAX]
    row[C_SEPARATION] = interp(model.load_n, model.separation_m, aux[AUX_N])
    row[C_GAP] = math.nan
    row[C_H] = aux[AUX_H]
    row[C_HT] = aux[AUX_HT]


@jit_inline
def keep_ahead(t0: float, t1: float, y0: np.ndarray, y1: np.ndarray, which: int, grazing: bool, down0: bool,
               down1: bool, start_known: bool, ahead: np.ndarray, iv: np.ndarray, fs: np.ndarray) -> None:
    """Keep the step (t0, y0) -> (t1, y1), taken past the target, for the next call: with the event it
    ends on (``which`` >= 0) or else what the dip search knows where the following step starts."""
    copy_into(ahead[0], y0)
    copy_into(ahead[1], y1)
    fs[FS_AHEAD_T0], fs[FS_AHEAD_T1] = t0, t1
    iv[IV_AHEAD_WHICH], iv[IV_AHEAD_GRAZING] = which, grazing
    iv[IV_START_KNOWN], iv[IV_START_DOWN0], iv[IV_START_DOWN1] = start_known, down0, down1


@jit
def report_at(t_target: float, t0: float, y: np.ndarray, iv: np.ndarray, model: KernelModel, src: tuple,
              cur: np.ndarray, st: np.ndarray, aux: np.ndarray, scratch: np.ndarray, rec: np.ndarray,
              n_rec: int) -> int:
    """Replace ``y``, the state at ``t0``, by the state at ``t_target`` (within the kept step): one step
    of the run's own method (no error control: it is shorter than the step the control accepted). With
    ``model.record`` its output row goes to ``rec[n_rec]``; returns the rows used."""
    mode, direction = iv[IV_MODE], iv[IV_DIR]
    if mode != STUCK or model.piezo:            # stuck: nothing moves relative to the surface
        f0, out = scratch[6], scratch[8]
        evaluate(mode, direction, t0, y, model, src, cur, st, aux, f0)
        if model.adaptive and not model.threshold:
            dopri5_step(mode, direction, t0, y, f0, t_target - t0, model, src, cur, st, aux, scratch, out)
        else:
            rk4_step(mode, direction, t0, y, f0, t_target - t0, model, src, cur, st, aux, scratch, out)
        copy_into(y, out)
    if model.record:
        observe(t_target, y, iv, model, src, cur, st, aux, scratch[10], rec[n_rec])
        n_rec += 1
    return n_rec


@jit
def advance(y: np.ndarray, iv: np.ndarray, fs: np.ndarray, ahead: np.ndarray, t_target: float, t_limit: float,
            model: KernelModel, src: tuple, ev_i: np.ndarray, ev_f: np.ndarray, rec: np.ndarray, n_rec: int,
            scratch: np.ndarray, st: np.ndarray, aux: np.ndarray, cur: np.ndarray) -> tuple[int, int, int]:
    """Integrate the state (y, iv, fs) from fs[FS_T] to ``t_target`` on the stroke source ``src``.

    Steps are never cut at ``t_target``, so that where a run is split into calls does not change the
    steps it takes: the step that would pass ``t_target`` is taken whole (up to ``t_limit``, where ``src``
    stops being valid) and kept in ``ahead`` (2, y.size: its start and end states) with its event, if it
    ends on one; ``y`` becomes the state at ``t_target``, a step of the same method from the kept step's
    start. The next call on the same model and source goes on from the kept step; the caller clears it
    (``fs[FS_AHEAD_T1] = NaN``) whenever the model, the source or the state changes in between.

    Mode changes go to ``ev_i`` (kind, from, to) and ``ev_f`` (t, x); with ``model.record`` one row
    per accepted step and per event goes to ``rec`` from row ``n_rec`` on. Returns (status, number of
    events, rows used). A status other than DONE stops at a consistent state: EVENTS_FULL /
    RECORDS_FULL ask the caller to drain the buffers and call again; NON_FINITE, EVENT_NOT_LOCATED
    and CHATTER are errors (the state is left at the last good step). Work arrays (the kernel never
    allocates): ``scratch`` (N_SCRATCH, y.size), ``st`` (3, channels), ``aux`` (N_AUX,), ``cur`` (channels, 2)
    int64.
    """
    work = scratch
    f0 = scratch[6]
    f1 = scratch[7]
    y1 = scratch[8]
    dt = model.dt
    tol = model.event_tolerance
    threshold = model.threshold
    adaptive = model.adaptive and not threshold
    dip_search = model.dip_search and not threshold
    if fs[FS_H] <= 0.0:
        fs[FS_H] = dt
    record = model.record
    status = DONE
    n_ev = 0
    t = fs[FS_T]
    if t >= t_target:
        return status, n_ev, n_rec
    resume_which = -1
    if fs[FS_AHEAD_T0] <= t < fs[FS_AHEAD_T1]:      # a step taken past the last target
        locate_all(src, fs[FS_AHEAD_T0], cur)       # the segments the step was taken on
        if fs[FS_AHEAD_T1] > t_target:              # ... still ahead of this one: report on it
            copy_into(y, ahead[0])
            n_rec = report_at(t_target, fs[FS_AHEAD_T0], y, iv, model, src, cur, st, aux, scratch, rec, n_rec)
            fs[FS_T] = t_target
            return status, n_ev, n_rec
        t = fs[FS_AHEAD_T1]                         # ... ending before it: the step is taken
        copy_into(y, ahead[1])
        fs[FS_MAX_SPEED] = max(fs[FS_MAX_SPEED], abs(y[1]))
        resume_which = iv[IV_AHEAD_WHICH]
        if resume_which < 0 and record:
            observe(t, y, iv, model, src, cur, st, aux, work[10], rec[n_rec])
            n_rec += 1
    fs[FS_AHEAD_T1] = math.nan
    need_eval = True
    t_next = t
    g0 = g1 = 0.0
    same_instant = 0
    t_last_event = math.nan
    h_cap = 0.0
    h_wave = math.inf
    dip_retries = 0
    start_known, start_down0, start_down1 = iv[IV_START_KNOWN] != 0, iv[IV_START_DOWN0] != 0, iv[IV_START_DOWN1] != 0
    while t < t_target:
        if n_ev + 2 > ev_i.shape[0]:
            status = EVENTS_FULL
            break
        if record and n_rec + 2 > rec.shape[0]:
            status = RECORDS_FULL
            break
        mode = iv[IV_MODE]
        which = -1
        grazing = False
        if resume_which >= 0:                   # the kept step ended on an event: take it now
            which, grazing, need_eval = resume_which, iv[IV_AHEAD_GRAZING] != 0, False
            resume_which = -1
        if need_eval:
            if t >= t_next:                     # a new segment (or the first): point the cursor at it
                t_next = locate_all(src, t, cur)
                h_wave = wave_step(src, cur)
            if threshold and mode != FLYING:
                kind = threshold_decision(t, y, model, src, cur, st, aux, iv, fs)
                if kind >= 0:
                    ev_i[n_ev, 0], ev_i[n_ev, 1], ev_i[n_ev, 2] = kind, mode, iv[IV_MODE]
                    ev_f[n_ev, 0], ev_f[n_ev, 1] = t, y[0]
                    n_ev += 1
                    mode = iv[IV_MODE]
            g0, g1 = evaluate(mode, iv[IV_DIR], t, y, model, src, cur, st, aux, f0)
            need_eval = False
            if g1 <= 0.0:                       # a condition that already holds switches at once
                which = 1
            elif iv[IV_FRESH] == 0 and (g0 < 0.0 if mode == STUCK else g0 <= 0.0):
                which = 0
        if which < 0:
            direction = iv[IV_DIR]
            moving = mode != STUCK or model.piezo
            error_control = adaptive and moving     # Dormand-Prince; else RK4, or stuck checks
            if error_control:
                h = min(fs[FS_H], dt, t_next - t, t_limit - t)
            else:
                h = min(dt if moving or threshold else model.check_step, t_next - t, t_limit - t)
            if dip_search and (error_control or not moving):     # fixed-step RK4 keeps its dt
                h = min(h, h_wave)
            if h_cap > 0.0:
                h = min(h, h_cap)
                h_cap = 0.0
            while True:
                if error_control:
                    dopri5_step(mode, direction, t, y, f0, h, model, src, cur, st, aux, work, y1)
                elif moving:
                    rk4_step(mode, direction, t, y, f0, h, model, src, cur, st, aux, work, y1)
                else:                           # stuck: nothing to integrate, only the checks
                    copy_into(y1, y)
                e0, e1 = evaluate(mode, direction, t + h, y1, model, src, cur, st, aux, f1)
                if not error_control:
                    break
                err = dopri5_error(h, f0, work, f1, model.tolerance, dt)
                if err <= 1.0 or not math.isfinite(err) or h < 1e-14:
                    fs[FS_H] = h * min(5.0, max(0.2, 0.9 * max(err, 1e-10) ** -0.2))
                    break
                h *= max(0.2, 0.9 * err ** -0.2)
            if not finite(y1) or math.isnan(e0) or math.isnan(e1):
                status = NON_FINITE
                break
            fresh = iv[IV_FRESH] != 0
            # stuck stays stuck while |T_req| <= Q_max; a fresh mode's margin starts at 0 by construction
            hit0 = (e0 < 0.0 and g0 >= 0.0) if mode == STUCK else (e0 <= 0.0 and (g0 > 0.0 or fresh))
            hit1 = e1 <= 0.0 and g1 > 0.0
            near_end0 = near_end1 = math.nan
            if not (hit0 or hit1) and dip_search and dip_retries < 4:
                theta, near_end0, near_end1 = first_dip(
                    mode, direction, t, h, y, f0, y1, f1, g0, g1, e0, e1, fresh, start_known, start_down0,
                    start_down1, model, src, cur, st, aux, work, error_control)
                if theta > 0.0:                 # a margin dips past its event inside the step: end the
                    h_cap = theta * h           # step there (the retried step then locates the root)
                    dip_retries += 1
                    continue
            if not (hit0 or hit1):              # accept the step
                t_new = t_next if h == t_next - t else (t_limit if h == t_limit - t else t + h)
                if t_new > t_target:            # past the target: keep it and report at the target
                    keep_ahead(t, t_new, y, y1, -1, False, near_end0 > e0, near_end1 > e1,
                               t_new < t_next and not math.isnan(near_end0), ahead, iv, fs)
                    n_rec = report_at(t_target, t, y, iv, model, src, cur, st, aux, scratch, rec, n_rec)
                    t = t_target
                    break
                t = t_new
                copy_into(y, y1)
                copy_into(f0, f1)
                g0, g1 = e0, e1
                iv[IV_FRESH] = 0
                dip_retries = 0
                # is each margin decreasing where the next step starts? (its slope at this step's end)
                start_down0, start_down1 = near_end0 > e0, near_end1 > e1
                fs[FS_MAX_SPEED] = max(fs[FS_MAX_SPEED], abs(y[1]))
                if record:
                    observe(t, y, iv, model, src, cur, st, aux, work[10], rec[n_rec])
                    n_rec += 1
                need_eval = t >= t_next or (threshold and mode != FLYING)
                start_known = not need_eval and not math.isnan(near_end0)
                iv[IV_START_KNOWN], iv[IV_START_DOWN0], iv[IV_START_DOWN1] = start_known, start_down0, start_down1
                continue
            theta = 2.0
            if hit0:
                theta = locate_root(0, mode, direction, t, h, y, f0, y1, f1, g0, e0, model, src, cur,
                                    st, aux, work, adaptive and moving)
                which = 0
            if hit1:
                theta1 = locate_root(1, mode, direction, t, h, y, f0, y1, f1, g1, e1, model, src, cur,
                                     st, aux, work, adaptive and moving)
                if theta1 < 0.0 or (theta >= 0.0 and theta1 < theta):
                    theta, which = theta1, 1
            if theta < 0.0:
                status = EVENT_NOT_LOCATED
                break
            if not moving:
                copy_into(y1, y)
            elif adaptive and mode == SLIDING and which == 0:
                dopri5_dense(theta, h, y, f0, y1, f1, work, work[9])   # a slide's end: the state on the
                copy_into(y1, work[9])                                 # interpolant of the root
            elif adaptive:                      # take-off, landing: a full step to the root, as the
                dopri5_step(mode, direction, t, y, f0, theta * h, model, src, cur, st, aux, work, y1)
            else:                               # flight is sensitive to them; RK4: step to the root, once
                slope = aux[AUX_ROOT_SLOPE]     # more if the true margin disagrees with Hermite's root
                for attempt in range(2):
                    rk4_step(mode, direction, t, y, f0, theta * h, model, src, cur, st, aux, work, y1)
                    if attempt == 1 or slope >= 0.0:
                        break
                    if mode == SLIDING and which == 0:
                        g_true = direction * y1[1]
                    else:
                        g_true = evaluate(mode, direction, t + theta * h, y1, model, src, cur, st, aux,
                                          f1)[which]
                    if abs(g_true) <= -slope * tol:
                        break
                    theta = min(max(theta - g_true / (slope * h), tol / h), 1.0)
            t_new = t + theta * h
            grazing = t_new - fs[FS_T_ENTRY] < tol
            if t_new > t_target:                # the event lies past the target: keep it for later
                keep_ahead(t, t_new, y, y1, which, grazing, False, False, False, ahead, iv, fs)
                n_rec = report_at(t_target, t, y, iv, model, src, cur, st, aux, scratch, rec, n_rec)
                t = t_target
                break
            t = t_new
            copy_into(y, y1)
            fs[FS_MAX_SPEED] = max(fs[FS_MAX_SPEED], abs(y[1]))
        if t == t_last_event:
            same_instant += 1
            if same_instant > 8:
                status = CHATTER
                break
        else:
            same_instant = 0
            t_last_event = t
        kind = transition(which, t, y, model, src, cur, st, aux, iv, fs, grazing)
        ev_i[n_ev, 0], ev_i[n_ev, 1], ev_i[n_ev, 2] = kind, mode, iv[IV_MODE]
        ev_f[n_ev, 0], ev_f[n_ev, 1] = t, y[0]
        n_ev += 1
        if record:
            observe(t, y, iv, model, src, cur, st, aux, work[10], rec[n_rec])
            n_rec += 1
        need_eval = True
        dip_retries = 0
        start_known = False
        iv[IV_START_KNOWN] = 0
    fs[FS_T] = t
    return status, n_ev, n_rec
