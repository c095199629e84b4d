"""The right-hand side of the particle dynamics in each mode, and the two margins of that mode
(docs/dynamics.md §1); compiled by numba (``NUMBA_DISABLE_JIT=1`` runs the same code as Python)."""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit, jit_inline
from ..piezo import piezo_acceleration
from ..surface import surface_at, surface_jet
from ..waveforms import N_POLY, N_TRIG, channel_value, locate_segment, segment_end
from .layout import (
    AUX_ARC,
    AUX_FELT_HI,
    AUX_FELT_LO,
    AUX_GAP,
    AUX_H,
    AUX_HT,
    AUX_HX,
    AUX_JET,
    AUX_L,
    AUX_LOAD_INDEX,
    AUX_MAT_AX,
    AUX_MAT_VX,
    AUX_MAT_VZ,
    AUX_MAT_X,
    AUX_N,
    AUX_QMAX,
    AUX_SLIP,
    AUX_STRETCH,
    AUX_T_RATE,
    AUX_T_REQ,
    AUX_XS,
    FLYING,
    STUCK,
    KernelModel,
)


@jit_inline
def interp(xs: np.ndarray, ys: np.ndarray, x: float) -> float:
    """Linear interpolation in a table with increasing ``xs``, extrapolated linearly at both ends."""
    n = xs.size
    i = min(max(int(np.searchsorted(xs, x)) - 1, 0), n - 2)
    return ys[i] + (x - xs[i]) * (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i])


@jit_inline
def table_interval(xs: np.ndarray, x: float, start: float) -> int:
    """The interval i of a table with increasing ``xs`` that holds ``x`` (xs[i] ≤ x < xs[i + 1], the first or
    last one beyond the ends), walked to from interval ``start``."""
    last = xs.size - 2
    i = min(max(int(start), 0), last)
    while i > 0 and x < xs[i]:
        i -= 1
    while i < last and x >= xs[i + 1]:
        i += 1
    return i


@jit_inline
def interp_near(xs: np.ndarray, ys: np.ndarray, x: float, aux: np.ndarray, slot: int) -> float:
    """:func:`interp`, searching from the interval found last time (kept in ``aux[slot]``): the load
    changes little between evaluations, so this walks 0-2 intervals instead of bisecting the table."""
    i = table_interval(xs, x, aux[slot])
    aux[slot] = i
    return ys[i] + (x - xs[i]) * (ys[i + 1] - ys[i]) / (xs[i + 1] - xs[i])


@jit_inline
def attraction(gap_m: np.ndarray, attraction_n: np.ndarray, gap: float) -> float:
    """F_att(δ) ≥ 0 (N): table, then the (ε/d)² tail beyond its last gap; δ < 0 reads as 0."""
    last = gap_m.size - 1
    if gap >= gap_m[last]:
        return attraction_n[last] * (gap_m[last] / gap) ** 2
    return interp(gap_m, attraction_n, max(gap, 0.0))


# Rows of at most this many actuators are summed whole: bisecting them costs more than it skips.
SHORT_ROW = 8

# In flight the closest surface point x_s is not at the part's x: strokes are evaluated one width farther
# than the cutoff radius (then every actuator surface_at includes at x_s is evaluated while |x_s - x| is
# within the narrowest width; beyond, evaluate() takes them all).
FLIGHT_REACH = 1.0

# The flight margin is the gap plus this many units of the heights' rounding (|z| + |h|, relative): a landing
# needs the gap below what the heights resolve (~1e-19 m), not rounded to 0. Just after a take-off the gap
# grows as t³ and stays below that for a nanosecond or two; a step ending there read it as 0 and landed.
GAP_RESOLUTION = 8.0 * 2.220446049250313e-16


@jit_inline
def felt_range(model: KernelModel, x: float, reach: float) -> tuple[int, int]:
    """The range of actuators centred within ``reach`` (m) of ``x``: two bisections of the (increasing)
    centres, so that actuators far from the part cost nothing; all of them for inf or a short row."""
    if not reach < math.inf or model.n_actuators <= SHORT_ROW:
        return 0, model.n_actuators
    return (int(np.searchsorted(model.centers, x - reach)),
            int(np.searchsorted(model.centers, x + reach, side='right')))


@jit_inline
def felt(model: KernelModel, aux: np.ndarray) -> tuple[int, int]:
    """The range of actuators whose strokes the last :func:`strokes_at` filled."""
    return int(aux[AUX_FELT_LO]), int(aux[AUX_FELT_HI])


@jit_inline
def surface_here(x: float, st: np.ndarray, model: KernelModel,
                 aux: np.ndarray) -> tuple[float, float, float, float, float, float]:
    """:func:`surface_at` at ``x`` (m) from the strokes the last :func:`strokes_at` filled in ``st``."""
    if model.track:                          # flat, at the track's normal displacement s sin β
        n = model.lift_channel
        return model.lift * st[0, n], 0.0, 0.0, model.lift * st[1, n], model.lift * st[2, n], 0.0
    first, stop = felt(model, aux)
    return surface_at(x, st[0], st[1], st[2], model.centers, model.widths, model.cutoff_radius, first, stop)


@jit_inline
def strokes_at(t: float, y: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
               st: np.ndarray, aux: np.ndarray, reach: float) -> float:
    """Fill ``st`` (4, channels) with s, ṡ, s̈, s⃛ at ``t`` on the segments ``cur``; return the base
    acceleration (m/s², 0 without the test-only base channel). With the piezo model the actuators'
    s, ṡ come from the state and s̈ from the stack dynamics driven by the commanded stroke (s⃛ unused).

    Only the actuators within ``model.cutoff_radius + reach`` of their widths from x = y[0] read their
    strokes (``reach`` 0: those ``surface_at`` keeps at x; ``inf``: every stroke, as with the piezo model,
    whose every stack is integrated). The range of columns filled (:func:`felt_range`, kept in ``aux``)
    is read back with :func:`felt`; the columns outside it are left as they were."""
    n_act = model.n_actuators
    radius = math.inf if model.piezo else model.cutoff_radius + reach
    lo, hi = felt_range(model, y[0], radius * model.max_width)
    aux[AUX_FELT_LO] = lo
    aux[AUX_FELT_HI] = hi
    for k in range(lo, hi):
        if not model.track and abs((y[0] - model.centers[k]) / model.widths[k]) > radius:
            st[0, k] = st[1, k] = st[2, k] = st[3, k] = 0.0
            continue
        stroke_into(st, k, src, cur, t)
    if model.has_base:
        stroke_into(st, n_act, src, cur, t)
    if model.piezo:
        for k in range(n_act):
            s = y[4 + 2 * k]
            sd = y[5 + 2 * k]
            st[2, k] = piezo_acceleration(st[0, k], s, sd, model.piezo_omega, model.piezo_zeta,
                                          model.piezo_min, model.piezo_max)
            st[0, k] = s
            st[1, k] = sd
    if model.track:
        return model.shake * st[2, 0] + model.slope_acc
    return st[2, n_act] if model.has_base else 0.0


@jit_inline
def stroke_into(st: np.ndarray, k: int, src: tuple, cur: np.ndarray, t: float) -> None:
    """Column ``k`` of ``st``: channel k's s, ṡ, s̈, s⃛ at ``t`` on its segment ``cur[k]``."""
    s, sd, sdd, sddd = channel_value(src, k, cur[k, 0], cur[k, 1], t)
    st[0, k] = s
    st[1, k] = sd
    st[2, k] = sdd
    st[3, k] = sddd


@jit_inline
def contact_load(x: float, xd: float, st: np.ndarray, base_acc: float, model: KernelModel,
                 aux: np.ndarray) -> None:
    """Normal load N, required friction T_req and Q_max(N) for a part on the surface at (x, ẋ); the surface's
    derivatives there go to ``aux`` for :func:`margin_slopes` (one pass over the bumps serves both).

    N = m (h_tt + 2 h_xt ẋ + h_xx ẋ² + g − h_x a_b) / L, T_req = N h_x + m L a_b (a_b: base
    acceleration, 0 except in the flat-surface check), and ẍ = (T − T_req) / (m L).
    """
    m = model.mass
    if model.track:
        n = model.lift_channel
        h, ht, htt, httt = model.lift * st[0, n], model.lift * st[1, n], model.lift * st[2, n], model.lift * st[3, n]
        hx = hxx = hxt = httx = hxxt = hxxx = 0.0
    else:
        first, stop = felt(model, aux)
        h, hx, hxx, ht, htt, hxt, httt, httx, hxxt, hxxx = surface_jet(
            x, st[0], st[1], st[2], st[3], model.centers, model.widths, model.cutoff_radius, first, stop)
    aux[AUX_JET], aux[AUX_JET + 1], aux[AUX_JET + 2], aux[AUX_JET + 3] = hxx, htt, hxt, httt
    aux[AUX_JET + 4], aux[AUX_JET + 5], aux[AUX_JET + 6] = httx, hxxt, hxxx
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
    if model.half_thickness > 0.0:
        closest_material_point(x, z, st, model, aux)
        return
    xs = x
    for _ in range(20):
        h, hx, hxx, _ht, _htt, _hxt = surface_here(xs, st, model, aux)
        step = ((xs - x) + (h - z) * hx) / (1.0 + hx * hx + (h - z) * hxx)
        xs -= step
        if abs(step) <= 1e-15 + 1e-13 * abs(xs):
            break
    h, hx, _hxx, _ht, _htt, _hxt = surface_here(xs, st, model, aux)
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
    base_acc = strokes_at(t, y, model, src, cur, st, aux, FLIGHT_REACH if mode == FLYING else 0.0)
    for i in range(dy.size):
        dy[i] = 0.0
    if model.piezo:
        for k in range(model.n_actuators):
            dy[4 + 2 * k] = st[1, k]
            dy[5 + 2 * k] = st[2, k]
    if mode == FLYING:
        closest_point(y[0], y[2], st, model, aux)
        if abs(aux[AUX_XS] - y[0]) > FLIGHT_REACH * model.min_width:     # beyond the strokes evaluated:
            strokes_at(t, y, model, src, cur, st, aux, math.inf)         # take them all and look again
            closest_point(y[0], y[2], st, model, aux)
        f_att = attraction(model.gap_m, model.attraction_n, aux[AUX_GAP])
        aux[AUX_N] = -f_att
        dy[0] = y[1]
        dy[1] = -base_acc + f_att * aux[AUX_HX] / (aux[AUX_L] * m)
        dy[2] = y[3]
        dy[3] = -model.gravity - f_att / (aux[AUX_L] * m)
        return aux[AUX_GAP] + GAP_RESOLUTION * (abs(y[2]) + abs(aux[AUX_H])), math.inf
    if model.half_thickness > 0.0:
        return material_evaluate(mode, direction, y, model, st, base_acc, aux, dy)
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


@jit_inline
def margin_slopes(mode: int, direction: int, y: np.ndarray, dy: np.ndarray, model: KernelModel, st: np.ndarray,
                  aux: np.ndarray) -> tuple[float, float]:
    """Time derivatives (per second) of the two margins :func:`evaluate` just returned at (t, y) along the
    motion ``dy`` it computed (``st`` and ``aux`` as it left them): stick (or slide) margin, adhesion margin.

    In closed form from the strokes' s⃛ and the bump's derivatives (:func:`surface_jet`, which the evaluation
    left in ``aux``): with a = ẍ,
    v = ẋ (0 when stuck), dN/dt = m (dA/dt · L − A · dL/dt) / L² for A = h_tt + 2 h_xt v + h_xx v² + g − h_x a_b,
    dL/dt = h_x (h_xt + h_xx v) / L; dT_req/dt = dN/dt h_x + N (h_xt + h_xx v) + m (dL/dt a_b + L da_b/dt);
    dQ_max/dt = the slope of the Q_max(N) table segment at N times dN/dt; the slide margin's is dir·a. NaN in
    flight, with the piezo model (the stack's s⃛ is not tracked), with the threshold friction logic and with
    surface.thickness.
    Stuck, dT_req/dt goes to ``aux[AUX_T_RATE]`` (NaN where there is no closed form): the dip search follows
    the stick margin's two smooth branches Q_max ∓ T_req where T_req changes sign (``events.first_dip``).
    """
    aux[AUX_T_RATE] = math.nan
    if mode == FLYING or model.piezo or model.threshold or model.half_thickness > 0.0:
        return math.nan, math.nan
    m = model.mass
    v = y[1] if mode != STUCK else 0.0
    a = dy[1] if mode != STUCK else 0.0
    hx, hxx, htt, hxt = aux[AUX_HX], aux[AUX_JET], aux[AUX_JET + 1], aux[AUX_JET + 2]
    httt, httx, hxxt, hxxx = aux[AUX_JET + 3], aux[AUX_JET + 4], aux[AUX_JET + 5], aux[AUX_JET + 6]
    n_act = model.n_actuators
    if model.track:
        base, base_rate = model.shake * st[2, 0] + model.slope_acc, model.shake * st[3, 0]
    else:
        base, base_rate = (st[2, n_act], st[3, n_act]) if model.has_base else (0.0, 0.0)
    hx_rate = hxt + hxx * v
    normal_acc = htt + model.gravity - hx * base
    normal_acc_rate = httt + httx * v - hx_rate * base - hx * base_rate
    if model.convective:
        normal_acc += 2.0 * hxt * v + hxx * v * v
        normal_acc_rate += (2.0 * (httx + hxxt * v) * v + 2.0 * hxt * a + (hxxt + hxxx * v) * v * v
                            + 2.0 * hxx * v * a)
    length = math.sqrt(1.0 + hx * hx)
    length_rate = hx * hx_rate / length
    n = m * normal_acc / length
    n_rate = m * (normal_acc_rate - normal_acc * length_rate / length) / length
    adhesion_rate = n_rate
    if not model.include_weight:
        adhesion_rate += m * model.gravity * length_rate / (length * length)
    if mode != STUCK:
        return direction * a, adhesion_rate
    i = min(max(int(aux[AUX_LOAD_INDEX]), 0), model.load_n.size - 2)
    q_rate = n_rate * (model.q_max_n[i + 1] - model.q_max_n[i]) / (model.load_n[i + 1] - model.load_n[i])
    t_req = n * hx + m * length * base
    t_req_rate = n_rate * hx + n * hx_rate + m * (length_rate * base + length * base_rate)
    aux[AUX_T_RATE] = t_req_rate
    return q_rate - (t_req_rate if t_req > 0.0 else -t_req_rate if t_req < 0.0 else abs(t_req_rate)), adhesion_rate


# -- surface.thickness: the top surface's material points move along x too (docs/dynamics.md §1) ---------

@jit_inline
def material_point(x: float, st: np.ndarray, model: KernelModel, aux: np.ndarray) -> float:
    """The abscissa X (m) of the top surface's material point now at ``x``: x = X + u(X), u = −(t/2) h_X(X)
    (Kirchhoff plate, t = surface.thickness), by Newton from X = x. One root while (t/2) h_XX < 1 (else the
    surface would fold over: :func:`material_load` gives NaN)."""
    c = model.half_thickness
    first, stop = felt(model, aux)
    xm = x
    for _ in range(30):
        _h, hx, hxx, _ht, _htt, _hxt = surface_at(xm, st[0], st[1], st[2], model.centers, model.widths,
                                                  model.cutoff_radius, first, stop)
        step = (xm - c * hx - x) / (1.0 - c * hxx)
        xm -= step
        if abs(step) <= 2e-16 * (abs(x) + model.min_width):
            break
    return xm


@jit
def material_load(x: float, xd: float, stuck: bool, st: np.ndarray, base_acc: float, model: KernelModel,
                  aux: np.ndarray) -> None:
    """:func:`contact_load` for a surface whose material points also move along x (surface.thickness t > 0).

    The top surface is the curve P(X) = (X + u, h) of the material abscissa X, u = −(t/2) h_X. A part on it
    at x (m), ẋ (m/s) sits on the point X (:func:`material_point`) and slips relative to it at
    Ẋ = (ẋ − u_t) / (1 + u_X) (0 when ``stuck``). With A = P_tt + 2 P_Xt Ẋ + P_XX Ẋ², J = |P_X|, n and τ the
    unit normal and tangent, the normal load is N = m n·(A + (a_b, g)), the friction that motion needs
    T_req = m τ·(A + (a_b, g)), and Ẍ = (T − T_req) / (m J), so ẍ = A_x + (1 + u_X) Ẍ.
    At t = 0 these are contact_load's. ``aux`` gets N, T_req, Q_max, the surface as a graph over x (height,
    slope dz/dx, its rate at fixed x, L) and the material quantities (AUX_MAT_*, AUX_SLIP, AUX_STRETCH =
    1 + u_X, AUX_ARC = J, AUX_MAT_AX = A_x). Compiled once and called, not inlined (as is
    :func:`material_evaluate`): off the seed's path, inlining it at every site only grows the compile."""
    c, m = model.half_thickness, model.mass
    xm = material_point(x, st, model, aux)
    first, stop = felt(model, aux)
    h, hx, hxx, ht, htt, hxt, _httt, hxtt, hxxt, hxxx = surface_jet(
        xm, st[0], st[1], st[2], st[3], model.centers, model.widths, model.cutoff_radius, first, stop)
    stretch = 1.0 - c * hxx
    if stretch <= 0.0:                       # the surface folds over: no material point under the part
        stretch = math.nan
    ut, utt, uxt, uxx = -c * hxt, -c * hxtt, -c * hxxt, -c * hxxx
    slip = 0.0 if stuck else (xd - ut) / stretch
    ax = utt + 2.0 * uxt * slip + uxx * slip * slip
    az = htt + 2.0 * hxt * slip + hxx * slip * slip
    arc = math.sqrt(stretch * stretch + hx * hx)
    n = m * (stretch * az - hx * ax + stretch * model.gravity - hx * base_acc) / arc
    slope = hx / stretch
    aux[AUX_N] = n
    aux[AUX_T_REQ] = m * (stretch * ax + hx * az + stretch * base_acc + hx * model.gravity) / arc
    aux[AUX_QMAX] = interp_near(model.load_n, model.q_max_n, n, aux, AUX_LOAD_INDEX)
    aux[AUX_L] = arc / stretch
    aux[AUX_H] = h
    aux[AUX_HX] = slope
    aux[AUX_HT] = ht - slope * ut
    aux[AUX_MAT_X], aux[AUX_MAT_VX], aux[AUX_MAT_VZ] = xm, ut, ht
    aux[AUX_SLIP], aux[AUX_STRETCH], aux[AUX_ARC], aux[AUX_MAT_AX] = slip, stretch, arc, ax


@jit
def material_evaluate(mode: int, direction: int, y: np.ndarray, model: KernelModel, st: np.ndarray,
                      base_acc: float, aux: np.ndarray, dy: np.ndarray) -> tuple[float, float]:
    """:func:`evaluate` in contact with surface.thickness: stuck, the part moves with its material point
    (ẋ = u_t, ẍ = u_tt); sliding, friction opposes the slip Ẋ, whose sign is the slide margin's."""
    m = model.mass
    material_load(y[0], y[1], mode == STUCK, st, base_acc, model, aux)
    n_detach = aux[AUX_N]
    if not model.include_weight:
        n_detach -= m * model.gravity * aux[AUX_STRETCH] / aux[AUX_ARC]
    adhesion_margin = n_detach + model.pull_off
    if mode == STUCK:
        dy[0] = aux[AUX_MAT_VX]
        dy[1] = aux[AUX_MAT_AX]
        return aux[AUX_QMAX] - abs(aux[AUX_T_REQ]), adhesion_margin
    slip_acc = (-direction * aux[AUX_QMAX] - aux[AUX_T_REQ]) / (m * aux[AUX_ARC])
    dy[0] = y[1]
    dy[1] = aux[AUX_MAT_AX] + aux[AUX_STRETCH] * slip_acc
    return direction * aux[AUX_SLIP], adhesion_margin


@jit_inline
def surface_load(x: float, xd: float, stuck: bool, st: np.ndarray, base_acc: float, model: KernelModel,
                 aux: np.ndarray) -> None:
    """:func:`contact_load` on whichever surface the model has: with surface.thickness its material points
    move along x too (:func:`material_load`; ``stuck``: the part rides its material point)."""
    if model.half_thickness > 0.0:
        material_load(x, xd, stuck, st, base_acc, model, aux)
    else:
        contact_load(x, xd, st, base_acc, model, aux)


@jit_inline
def surface_graph(x: float, st: np.ndarray, model: KernelModel, aux: np.ndarray) -> tuple[float, float, float]:
    """The surface under ``x`` (m) as a graph z = h(x, t): height (m), slope dz/dx and rate ∂h/∂t at fixed x
    (m/s), on whichever surface the model has; with surface.thickness ``aux`` also gets the material point
    under x and its velocity (AUX_MAT_*, :func:`material_load`)."""
    if model.half_thickness > 0.0:
        material_load(x, 0.0, True, st, 0.0, model, aux)
        return aux[AUX_H], aux[AUX_HX], aux[AUX_HT]
    h, hx, _hxx, ht, _htt, _hxt = surface_here(x, st, model, aux)
    return h, hx, ht


@jit
def closest_material_point(x: float, z: float, st: np.ndarray, model: KernelModel, aux: np.ndarray) -> None:
    """:func:`closest_point` on the curve P(X) = (X + u, h) of surface.thickness: Newton on (P − p)·P_X = 0
    over the material abscissa X; the same outputs (the graph's height, slope and L at the point found)."""
    c = model.half_thickness
    first, stop = felt(model, aux)
    xm = x
    for _ in range(20):
        h, hx, hxx, _ht, _htt, _hxt, _httt, _hxtt, _hxxt, hxxx = surface_jet(
            xm, st[0], st[1], st[2], st[3], model.centers, model.widths, model.cutoff_radius, first, stop)
        px, pz = xm - c * hx - x, h - z
        tx, tz = 1.0 - c * hxx, hx
        step = (px * tx + pz * tz) / (tx * tx + tz * tz + px * (-c * hxxx) + pz * hxx)
        xm -= step
        if abs(step) <= 1e-15 + 1e-13 * abs(xm):
            break
    h, hx, hxx, _ht, _htt, _hxt = surface_at(xm, st[0], st[1], st[2], model.centers, model.widths,
                                             model.cutoff_radius, first, stop)
    xs = xm - c * hx
    slope = hx / (1.0 - c * hxx)
    length = math.sqrt(1.0 + slope * slope)
    aux[AUX_XS] = xs
    aux[AUX_H] = h
    aux[AUX_HX] = slope
    aux[AUX_L] = length
    aux[AUX_GAP] = ((z - h) - slope * (x - xs)) / length


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
            for h in range(N_TRIG):
                fastest = max(fastest, abs(seg_coef[k, cur[k, 1], N_POLY + 3 * h + 2]))
    return math.pi / (4.0 * fastest) if fastest > 0.0 else math.inf


@jit
def polynomial_step(src: tuple, cur: np.ndarray) -> float:
    """Largest step (s) for a part stuck on a plate: a quarter of the shortest active polynomial segment whose
    stroke accelerates (inf when none). There the stick margin mixes the stroke's acceleration, which moves
    the material point along the feeder, with its position and velocity, which load the part: within one
    cubic piece of a jerk-limited ramp it dipped below 0 for 2.8 µs and rose again, two extrema in one
    step, which the dip search (one extremum per step) cannot see."""
    seg_start, seg_coef = src[5], src[6]
    shortest = math.inf
    for k in range(cur.shape[0]):
        j, i = cur[k, 0], cur[k, 1]
        if j < 0:
            continue
        trig = False
        for h in range(N_TRIG):
            trig = trig or seg_coef[k, i, N_POLY + 3 * h + 2] != 0.0
        accelerates = False
        for c in range(2, N_POLY):
            accelerates = accelerates or seg_coef[k, i, c] != 0.0
        if accelerates and not trig:
            shortest = min(shortest, seg_start[k, i + 1] - seg_start[k, i])
    return shortest / 4.0


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
