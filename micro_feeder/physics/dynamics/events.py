"""Event location and mode changes: a margin's sign change over a step, its dips inside a step
(docs/events.md), and the transition applied at an event (docs/dynamics.md §1)."""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from ..waveforms import channel_bounds, channel_ranges
from .layout import (
    AUX_L,
    AUX_LOAD_INDEX,
    AUX_MAT_VX,
    AUX_MAT_VZ,
    AUX_N,
    AUX_QMAX,
    AUX_ROOT_SLOPE,
    AUX_T_REQ,
    FLYING,
    FS_T_ENTRY,
    IV_DIR,
    IV_ENTRY_COUNTER,
    IV_FRESH,
    IV_LANDING,
    IV_MODE,
    IV_PREV_MODE,
    IV_SLIP_TO_STICK,
    IV_STICK_TO_SLIP,
    IV_TAKE_OFF,
    LANDING,
    LANDING_COULOMB,
    LANDING_STICK,
    REVERSAL,
    SLIDING,
    SLIP_TO_STICK,
    STICK_TO_SLIP,
    STUCK,
    TAKE_OFF,
    KernelModel,
)
from .rhs import contact_load, evaluate, felt_range, sign, strokes_at, surface_graph, surface_load, table_interval
from .steppers import dopri5_dense, hermite, interpolant_reach

JUMP_TOLERANCE = 1e-9    # relative (1 + |ẋ| in m/s): a stuck part's velocity and its material point's differ
                         # by more only after the material's velocity jumped (both are set from one evaluation;
                         # across a commanded knot the two pieces' polynomials agree to ~1e-11 relative, which
                         # 1e-12 read as a jump: a zero-length slide; friction absorbs 1e-9 m/s in ~1e-11 s)


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
        if mode == SLIDING and which == 0 and model.half_thickness == 0.0:   # the slide margin dir·ẋ needs
            g = direction * yi[1]                                               # no force evaluation
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
              start_slope0: float, start_slope1: float, end_slope0: float, end_slope1: float, t_req0: float,
              t_rate0: float, t_req1: float, t_rate1: float, model: KernelModel, src: tuple, cur: np.ndarray,
              st: np.ndarray, aux: np.ndarray, work: np.ndarray, dense: bool) -> tuple[float, float, float, float]:
    """Step fraction of a point where a margin, positive at both ends of the step, dips past its event
    inside it (-1 if there is none), both margins' slopes (per second) at the step's end, and dT_req/dt there.

    A margin with an interior minimum decreases where the step starts and increases where it ends. The
    slopes come in closed form (:func:`margin_slopes`: ``start_slope0/1`` when ``start_known``,
    ``end_slope0/1`` when not NaN), else from differences over δ = min(1e-3, event_tolerance / h) of the
    step inside each end (in flight, with the piezo model). The minimum is then searched
    (:func:`brent_dip`, from the minimum of the margin's cubic model on those values and slopes) to the
    event tolerance, stopping at the first point past the event. Guarantee, under the assumption that a
    margin has at most one local extremum within one step (docs/events.md): a dip longer than the event
    tolerance is found, whatever the step size.

    The stick margin Q_max − |T_req| has kinks (local maxima) where T_req changes sign, and T_req can change
    sign twice in one step with the margin dipping in between: a stuck step is searched on the margin's two
    smooth branches Q_max ∓ T_req (``t_req0``, ``t_req1``: T_req at the step's ends, ``t_rate0/1`` its rates,
    NaN where :func:`margin_slopes` has no closed form), each with its own values and slopes at both ends
    (the margin is the lower of them, below 0 where either is). The other branch's search is skipped where
    T_req provably keeps its sign over the step (:func:`required_friction_keeps_sign`, asked only when that
    branch's slopes call for a search): the margin is then one smooth branch. Nor is a branch searched whose
    lower bound over the step is above 0 (:func:`stick_branch_floor`): no dip of it reaches its event.
    """
    tol = model.event_tolerance / h
    if tol >= 0.25:
        return -1.0, math.nan, math.nan, t_rate1
    delta = min(1e-3, tol)
    b0 = b1 = math.nan
    t_near_start = t_near_end = math.nan
    if math.isnan(end_slope0):
        b0, b1 = margins_at(1.0 - delta, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work,
                            dense)
        t_near_end = aux[AUX_T_REQ]
        end_slope0, end_slope1 = (e0 - b0) / (delta * h), (e1 - b1) / (delta * h)
    if not start_known:
        a0, a1 = margins_at(delta, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work, dense)
        t_near_start = aux[AUX_T_REQ]
        start_slope0, start_slope1 = (a0 - g0) / (delta * h), (a1 - g1) / (delta * h)
    if mode == STUCK and math.isnan(t_rate1):
        if math.isnan(t_near_end):
            margins_at(1.0 - delta, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work, dense)
            t_near_end = aux[AUX_T_REQ]
        t_rate1 = (t_req1 - t_near_end) / (delta * h)
    if mode == STUCK and math.isnan(t_rate0):
        if math.isnan(t_near_start):
            margins_at(delta, mode, direction, t, h, y0, f0, y1, f1, model, src, cur, st, aux, work, dense)
            t_near_start = aux[AUX_T_REQ]
        t_rate0 = (t_near_start - t_req0) / (delta * h)
    s0 = 1.0 if t_req0 > 0.0 else -1.0       # the sign of T_req where the step starts, and where it ends
    s1 = 1.0 if t_req1 > 0.0 else -1.0
    best = 2.0
    ranged = derived = False                # the stuck step's ranges (stuck_ranges), found when first needed
    hx_lo = hx_hi = acc_lo = acc_hi = 0.0
    for which in range(2):
        start, end = (g0, e0) if which == 0 else (g1, e1)
        near_end, start_slope, end_slope = (b0, start_slope0, end_slope0) if which == 0 else \
            (b1, start_slope1, end_slope1)
        if not (math.isfinite(start) and math.isfinite(end)) or (which == 0 and fresh):
            continue
        strict = mode == STUCK and which == 0
        if crossed(near_end, strict):           # (NaN, not evaluated, is not crossed)
            best = min(best, 1.0 - delta)
            continue
        branches = 2 if strict else 1
        for k in range(branches):
            branch = 0.0                        # the margin itself, else the branch Q_max - branch T_req
            v_start, v_end, d_start, d_end = start, end, start_slope, end_slope
            if branches == 2:                   # the branch the margin starts on, then the other
                branch = s0 if k == 0 else -s0
                v_start = start + abs(t_req0) - branch * t_req0
                v_end = end + abs(t_req1) - branch * t_req1
                d_start = start_slope + (s0 - branch) * t_rate0
                d_end = end_slope + (s1 - branch) * t_rate1
            if not (d_start < 0.0 and d_end > 0.0):
                continue
            if strict:
                if not ranged:
                    derived, hx_lo, hx_hi, acc_lo, acc_hi = stuck_ranges(t, h, y0, model, src, cur)
                    ranged = True
                if derived and k == 1 and t_req0 * t_req1 >= 0.0 and one_sided(hx_lo, hx_hi) \
                        and one_sided(acc_lo, acc_hi):
                    continue                    # no kink: the margin is the branch searched first
                if derived and stick_branch_floor(branch, hx_lo, hx_hi, acc_lo, acc_hi, model, aux) > 0.0:
                    continue                    # this branch stays above its event over the step
            if which == 1 and adhesion_floor(mode, t, h, y0, f0, y1, f1, work, dense, model, src, cur) > 0.0:
                continue                        # the adhesion margin cannot reach 0 in this step
            seed = dip_seed(v_start, v_end, d_start * h, d_end * h, tol)
            theta = brent_dip(which, strict, branch, seed, v_start, v_end, mode, direction, t, h, y0, f0, y1, f1,
                              model, src, cur, st, aux, work, dense, tol)
            if 0.0 < theta < best:
                best = theta
    return (best if best <= 1.0 else -1.0), end_slope0, end_slope1, t_rate1


@jit_inline
def stuck_ranges(t: float, h: float, y0: np.ndarray, model: KernelModel, src: tuple,
                 cur: np.ndarray) -> tuple[bool, float, float, float, float]:
    """(derived, h_x's range, (h_tt + g)'s range) over the stuck step [t, t + h] of a part held at rest at
    x = ``y0[0]`` on the bump surface: h_x = Σ s_k g_k'(x) and h_tt + g = g + Σ s̈_k g_k(x), from each felt
    actuator's range of s_k and s̈_k (:func:`channel_ranges`) times its bump g_k and g_k' at x. Not derived
    (False) for the piezo model, a base, a track, a thick surface or a part not at rest: there N and T_req
    depend on more than these two."""
    if model.piezo or model.has_base or model.track or model.half_thickness > 0.0 or y0[1] != 0.0:
        return False, 0.0, 0.0, 0.0, 0.0
    x = y0[0]
    hx_lo = hx_hi = 0.0
    acc_lo = acc_hi = model.gravity
    lo, hi = felt_range(model, x, model.cutoff_radius * model.max_width)
    for k in range(lo, hi):
        w = model.widths[k]
        u = (x - model.centers[k]) / w
        if abs(u) > model.cutoff_radius:
            continue
        g = math.exp(-0.5 * u * u)
        slope = -u / w * g
        s_lo, s_hi, sdd_lo, sdd_hi = channel_ranges(src, k, cur[k, 0], cur[k, 1], t, t + h)
        hx_lo += min(slope * s_lo, slope * s_hi)
        hx_hi += max(slope * s_lo, slope * s_hi)
        acc_lo += g * sdd_lo
        acc_hi += g * sdd_hi
    return True, hx_lo, hx_hi, acc_lo, acc_hi


@jit_inline
def required_friction_keeps_sign(t: float, h: float, y0: np.ndarray, model: KernelModel, src: tuple,
                                 cur: np.ndarray) -> bool:
    """True where T_req = N h_x provably never changes sign over the stuck step [t, t + h] of a part held
    at rest at x = ``y0[0]`` on the bump surface (it may touch 0); False where that is not derived
    (:func:`stuck_ranges`). Then the stick margin Q_max − |T_req| is its smooth branch Q_max − s T_req over
    the whole step (no kink to hide a dip, and a root search's root is its only one) and the other branch,
    Q_max + |T_req| ≥ Q_max ≥ 0, needs no search.

    At rest, N = m (h_tt + g) / L: N and h_x each keep their sign where their ranges lie on one side of 0
    (:func:`one_sided`).
    """
    derived, hx_lo, hx_hi, acc_lo, acc_hi = stuck_ranges(t, h, y0, model, src, cur)
    return derived and one_sided(hx_lo, hx_hi) and one_sided(acc_lo, acc_hi)


@jit_inline
def stick_branch_floor(branch: float, hx_lo: float, hx_hi: float, acc_lo: float, acc_hi: float,
                       model: KernelModel, aux: np.ndarray) -> float:
    """A lower bound (N) of the stick margin's smooth branch Q_max(N) − ``branch``·T_req over a stuck step,
    from the ranges of h_x and h_tt + g over it (:func:`stuck_ranges`). At rest N = m a / L and
    T_req = N h_x = m a φ(h_x), with a = h_tt + g, L = √(1 + h_x²) and φ(u) = u / √(1 + u²) increasing:
    each is bilinear in a and a monotone function of h_x, so its extremes are at the ranges' corners;
    Q_max is the piecewise-linear table, whose minimum over N's range is at its ends or a knot inside
    (found from the table interval of the last load, ``aux[AUX_LOAD_INDEX]``, only read).
    Above 0, that branch cannot dip to its event in the step: its search is skipped."""
    m = model.mass
    root_lo, root_hi = math.sqrt(1.0 + hx_lo * hx_lo), math.sqrt(1.0 + hx_hi * hx_hi)
    phi_lo, phi_hi = hx_lo / root_lo, hx_hi / root_hi
    t_lo = m * min(acc_lo * phi_lo, acc_lo * phi_hi, acc_hi * phi_lo, acc_hi * phi_hi)
    t_hi = m * max(acc_lo * phi_lo, acc_lo * phi_hi, acc_hi * phi_lo, acc_hi * phi_hi)
    inv_lo = 1.0 / max(root_lo, root_hi)                           # 1/L over the step: L is largest at
    inv_hi = 1.0 if hx_lo <= 0.0 <= hx_hi else 1.0 / min(root_lo, root_hi)   # the steepest h_x
    n_lo = m * min(acc_lo * inv_lo, acc_lo * inv_hi, acc_hi * inv_lo, acc_hi * inv_hi)
    n_hi = m * max(acc_lo * inv_lo, acc_lo * inv_hi, acc_hi * inv_lo, acc_hi * inv_hi)
    loads, limits = model.load_n, model.q_max_n
    last = loads.size - 2
    i = table_interval(loads, n_lo, aux[AUX_LOAD_INDEX])
    q_lo = limits[i] + (n_lo - loads[i]) * (limits[i + 1] - limits[i]) / (loads[i + 1] - loads[i])
    while i < last and n_hi >= loads[i + 1]:
        i += 1
        q_lo = min(q_lo, limits[i])
    q_lo = min(q_lo, limits[i] + (n_hi - loads[i]) * (limits[i + 1] - limits[i]) / (loads[i + 1] - loads[i]))
    demand = t_hi if branch > 0.0 else -t_lo
    return q_lo - demand - 1e-9 * (abs(q_lo) + abs(demand))      # less a margin for the roundings


@jit_inline
def one_sided(lo: float, hi: float) -> bool:
    """A range [lo, hi] on one side of 0 (touching it allowed, to 1e-9 of its size for rounding)."""
    slack = 1e-9 * (hi - lo)
    return lo >= -slack or hi <= slack


@jit_inline
def adhesion_floor(mode: int, t: float, h: float, y0: np.ndarray, f0: np.ndarray, y1: np.ndarray, f1: np.ndarray,
                   work: np.ndarray, dense: bool, model: KernelModel, src: tuple, cur: np.ndarray) -> float:
    """A lower bound (N) of the adhesion margin over the step's interpolant (as :func:`first_dip` sees it);
    -inf where none is derived (in flight, with the piezo model or the base channel).

    N = m A / L with L ≥ 1, so N ≥ m min(0, A) (and N − m g / L ≥ m min(0, A − g) for the weight outside
    N), and A = h_tt + 2 h_xt ẋ + h_xx ẋ² + g ≥ g − Σ S2_k − 2 V Σ S1_k e^(−1/2) / w_k − V² Σ S0_k / w_k²:
    S0..S2 bound each felt actuator's |s|, |ṡ|, |s̈| over the step (:func:`channel_bounds`), the bump's
    |g|, |g'| w, |g''| w² are at most 1, e^(−1/2), 1, and V bounds |ẋ| on the interpolant. Felt: within
    the cutoff of any x the interpolant reaches. A floor above 0 proves that the margin has no dip to find.
    """
    if mode == FLYING or model.piezo or model.has_base or model.track or model.half_thickness > 0.0:
        return -math.inf
    reach = interpolant_reach(0, h, y0, f0, y1, f1, work, dense)
    speed = abs(y0[1]) + interpolant_reach(1, h, y0, f0, y1, f1, work, dense) if model.convective else 0.0
    htt = hxt = hxx = 0.0
    lo, hi = felt_range(model, y0[0], model.cutoff_radius * model.max_width + reach)
    for k in range(lo, hi):
        w = model.widths[k]
        if abs(y0[0] - model.centers[k]) > model.cutoff_radius * w + reach:
            continue
        s_max, sd_max, sdd_max = channel_bounds(src, k, cur[k, 0], cur[k, 1], t, t + h)
        htt += sdd_max
        hxt += sd_max * 0.6065306597126334 / w          # e^(-1/2) / w
        hxx += s_max / (w * w)
    normal_acc = model.gravity - htt - 2.0 * hxt * speed - hxx * speed * speed
    if not model.include_weight:
        normal_acc -= model.gravity
    return model.mass * min(0.0, normal_acc) + model.pull_off


@jit_inline
def dip_seed(g0: float, g1: float, d0: float, d1: float, tol: float) -> float:
    """Where the cubic Hermite model of a margin has its minimum (values g0, g1 at the step's ends, slopes
    d0 < 0 < d1 per step fraction: its derivative, a quadratic, has one root in (0, 1) where it rises),
    kept within [2 tol, 1 - 2 tol]; the golden section point if that cannot be computed."""
    qa = 6.0 * (g0 - g1) + 3.0 * (d0 + d1)          # p'(θ) = qa θ² + qb θ + d0
    qb = 6.0 * (g1 - g0) - 4.0 * d0 - 2.0 * d1
    disc = qb * qb - 4.0 * qa * d0
    theta = 0.3819660112501051
    if disc >= 0.0:                                  # the rising root, without cancellation
        theta = (-qb + math.sqrt(disc)) / (2.0 * qa) if qb < 0.0 else 2.0 * d0 / (-qb - math.sqrt(disc))
    if not math.isfinite(theta):
        theta = 0.3819660112501051
    return min(max(theta, 2.0 * tol), 1.0 - 2.0 * tol)


@jit_inline
def brent_dip(which: int, strict: bool, branch: float, seed: float, g_start: float, g_end: float, mode: int,
              direction: int, t: float, h: float, y0: np.ndarray,
              f0: np.ndarray, y1: np.ndarray, f1: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
              st: np.ndarray, aux: np.ndarray, work: np.ndarray, dense: bool, tol: float) -> float:
    """Brent's minimisation (parabolic steps, golden-section fallback) of margin ``which`` over the step
    (fractions 0..1; ``branch`` ±1: the stick margin's branch Q_max − branch·T_req instead, 0: the margin
    itself) to ``tol``, returning the first fraction found past the event, or -1 when the
    minimum stays short of it. It starts at ``seed``, with the step's ends (margins ``g_start``,
    ``g_end``) as the other points of its first parabola. (One evaluation site, the first point
    included: it is inlined.)"""
    golden = 0.3819660112501051
    a, b = 0.0, 1.0
    x = w = v = u = seed
    fx = fw = fv = 0.0
    d = e = 0.0
    for it in range(100):
        if it > 0:
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
        if branch != 0.0:
            fu = aux[AUX_QMAX] - branch * aux[AUX_T_REQ]
        if crossed(fu, strict):
            return u
        if it == 0:                         # the ends are the other two points of the first parabola
            fx, w, fw, v, fv, d, e = fu, 1.0, g_end, 0.0, g_start, 1.0, 1.0
        elif fu <= fx:
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
def bounce_flight(rebound: float, x: float, xd: float, st: np.ndarray, base_acc: float, model: KernelModel,
                  aux: np.ndarray) -> float:
    """How long (s) a bounce leaving the surface at ``rebound`` (m/s, normal) would fly, from the normal
    acceleration A = N L / m that pushes the part onto the surface there: 2 rebound / A (inf where A ≤ 0:
    the surface falls away faster than the part). Successive bounces on a surface that moves little during
    them lose a factor e_n each, so their flights fall below ``bounce_min_flight`` after finitely many, and
    the last landing is plastic: chatter ends in finite time (at most the first flight / (1 − e_n) in all)."""
    surface_load(x, xd, False, st, base_acc, model, aux)
    pressing = aux[AUX_N] * aux[AUX_L] / model.mass
    return 2.0 * rebound / pressing if pressing > 0.0 else math.inf


@jit
def transition(which: int, t: float, y: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
               st: np.ndarray, aux: np.ndarray, iv: np.ndarray, fs: np.ndarray, grazing: bool) -> int:
    """Apply the event of margin ``which`` in the current mode at (t, y) (docs/dynamics.md §1); returns
    the event kind. ``y`` is rewritten for the new mode."""
    mode = iv[IV_MODE]
    base_acc = strokes_at(t, y, model, src, cur, st, aux, 0.0)
    if mode == FLYING:                                     # landing: landing.law, landing.restitution
        h, hx, ht = surface_graph(y[0], st, model, aux)
        # the velocity of the surface's material point there (it moves along x too with surface.thickness)
        material_vx, material_vz = (aux[AUX_MAT_VX], aux[AUX_MAT_VZ]) if model.half_thickness > 0.0 else (0.0, ht)
        vx, vz = (material_vx, material_vz) if model.landing_relative else (0.0, 0.0)
        length = math.sqrt(1.0 + hx * hx)
        approach = abs(y[3] - ht - hx * y[1]) / length     # normal velocity relative to the surface (m/s)
        xd = vx + ((y[1] - vx) + hx * (y[3] - vz)) / (1.0 + hx * hx)
        slip = xd - material_vx                            # relative to the material
        if model.landing_law == LANDING_STICK:
            slip = 0.0
        elif model.landing_law == LANDING_COULOMB:     # |Δv_t| ≤ μ |Δv_n|, Δv_n = (1 + e_n)·approach
            impulse = (1.0 + model.restitution) * approach
            slip = sign(slip) * max(abs(slip) - model.landing_mu * impulse / length, 0.0)
        xd = slip + material_vx
        rebound = model.restitution * approach
        if rebound > 0.0 and bounce_flight(rebound, y[0], xd, st, base_acc, model, aux) >= model.bounce_min_flight:
            y[1] = xd - hx * rebound / length              # tangential xd·L along the surface, rebound along n
            y[2] = h
            y[3] = ht + hx * xd + rebound / length
            iv[IV_FRESH] = 1
            enter(iv, fs, t, FLYING, IV_LANDING, grazing)
            if not grazing:
                iv[IV_TAKE_OFF] += 1                       # a bounce: a landing and a take-off at one instant
            return LANDING
        y[1] = xd
        y[2] = 0.0
        y[3] = 0.0
        iv[IV_DIR] = sign(slip)
        iv[IV_FRESH] = 0
        enter(iv, fs, t, SLIDING if slip != 0.0 else STUCK, IV_LANDING, grazing)
        return LANDING
    if which == 1:                                         # take-off with the contact velocity
        h, hx, ht = surface_graph(y[0], st, model, aux)
        y[2] = h
        y[3] = ht + hx * y[1]
        iv[IV_FRESH] = 1
        enter(iv, fs, t, FLYING, IV_TAKE_OFF, grazing)
        return TAKE_OFF
    surface_load(y[0], 0.0, True, st, base_acc, model, aux)   # at rest on the surface (its material point)
    y[1] = aux[AUX_MAT_VX] if model.half_thickness > 0.0 else 0.0
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
def material_jump(mode: int, slide_margin: float, t: float, y: np.ndarray, aux: np.ndarray, iv: np.ndarray,
                  fs: np.ndarray) -> int:
    """surface.thickness, where a step starts: whether the material under the part jumped in velocity (a stroke
    whose velocity jumps: a sine's start and end), per the evaluation just made at (t, y); the event kind, or
    -1. Friction, finite, gives the part no impulse: its velocity y[1] stays. A stuck part then slides
    relative to the material (``stick_to_slip``, counted); a sliding one whose slip the jump reversed (its
    ``slide_margin`` dir·Ẋ < 0 where a step starts: a continuous crossing is located inside the step before)
    slides back (a ``reversal``). Both paths see it: the exact jump of the analytic strokes here, the
    trajectory's nanosecond ramp as a friction demand no Q_max meets."""
    if mode == SLIDING:
        if iv[IV_FRESH] != 0 or slide_margin >= 0.0:
            return -1
        iv[IV_DIR] = -iv[IV_DIR]
        return REVERSAL
    jump = y[1] - aux[AUX_MAT_VX]
    if mode != STUCK or abs(jump) <= JUMP_TOLERANCE * (1.0 + abs(y[1])):
        return -1
    iv[IV_DIR] = sign(jump)
    iv[IV_FRESH] = 0
    enter(iv, fs, t, SLIDING, IV_STICK_TO_SLIP, False)
    return STICK_TO_SLIP


@jit
def threshold_decision(t: float, y: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
                       st: np.ndarray, aux: np.ndarray, iv: np.ndarray, fs: np.ndarray) -> int:
    """The seed's threshold-velocity friction logic at the start of a step (contact modes only).

    V_th = Q_max dt / m. Slip if |v_rel| ≥ V_th (friction opposes v_rel), or if |T_req| > Q_max
    (friction opposes the impending motion); stick (ẋ = 0) otherwise. Returns the event kind of a mode
    change, or -1.
    """
    base_acc = strokes_at(t, y, model, src, cur, st, aux, 0.0)
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
