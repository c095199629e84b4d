"""The compiled inner loop: the particle on the actuated surface integrated from one target time to the
next, with event location (docs/dynamics.md, docs/events.md).

Plain functions over numpy arrays so that numba compiles them (``NUMBA_DISABLE_JIT=1`` runs the very
same code as Python). The public, documented API is :mod:`micro_feeder.physics.dynamics.model`; this
module is its engine; the data it works on is laid out in :mod:`.layout`.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .events import (
    adhesion_floor,
    first_dip,
    locate_root,
    material_jump,
    required_friction_keeps_sign,
    threshold_decision,
    transition,
)
from .layout import (
    AUX_GAP,
    AUX_H,
    AUX_HT,
    AUX_HX,
    AUX_MAT_VX,
    AUX_N,
    AUX_QMAX,
    AUX_ROOT_SLOPE,
    AUX_T_RATE,
    AUX_T_REQ,
    C_FRICTION,
    C_GAP,
    C_H,
    C_HT,
    C_MODE,
    C_N,
    C_QMAX,
    C_SEPARATION,
    C_T,
    C_THETA,
    C_X,
    C_XD,
    C_Z,
    C_ZD,
    CHATTER,
    DONE,
    EVENT_NOT_LOCATED,
    EVENTS_FULL,
    FLYING,
    FS_AHEAD_T0,
    FS_AHEAD_T1,
    FS_H,
    FS_MAX_SPEED,
    FS_START_SLOPE0,
    FS_START_SLOPE1,
    FS_T,
    FS_T_ENTRY,
    IV_AHEAD_GRAZING,
    IV_AHEAD_WHICH,
    IV_DIR,
    IV_FRESH,
    IV_MODE,
    IV_START_KNOWN,
    N_FIXED_COLUMNS,
    NON_FINITE,
    RECORDS_FULL,
    SLIDING,
    STUCK,
    KernelModel,
)
from .rhs import (
    copy_into,
    evaluate,
    finite,
    interp,
    locate_all,
    margin_slopes,
    polynomial_step,
    strokes_at,
    surface_graph,
    wave_step,
)
from .steppers import dopri5_dense, dopri5_error, dopri5_step, rk4_step


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
    strokes_at(t, y, model, src, cur, st, aux, math.inf)   # every stroke column exact, felt or not
    for k in range(model.n_actuators):
        row[N_FIXED_COLUMNS + k] = st[0, k]
    if mode == FLYING:
        h, _hx, ht = surface_graph(y[0], st, model, aux)
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


@jit
def keep_ahead(t0: float, t1: float, y0: np.ndarray, y1: np.ndarray, which: int, grazing: bool, slope0: float,
               slope1: float, start_known: bool, ahead: np.ndarray, iv: np.ndarray, fs: np.ndarray) -> None:
    """Keep the step (t0, y0) -> (t1, y1), taken past the target, for the next call: with the event it
    ends on (``which`` >= 0) or else what the dip search knows where the following step starts."""
    copy_into(ahead[0], y0)
    copy_into(ahead[1], y1)
    fs[FS_AHEAD_T0], fs[FS_AHEAD_T1] = t0, t1
    iv[IV_AHEAD_WHICH], iv[IV_AHEAD_GRAZING] = which, grazing
    iv[IV_START_KNOWN], fs[FS_START_SLOPE0], fs[FS_START_SLOPE1] = start_known, slope0, slope1


@jit
def report_at(t_target: float, t0: float, y: np.ndarray, iv: np.ndarray, model: KernelModel, src: tuple,
              cur: np.ndarray, st: np.ndarray, aux: np.ndarray, scratch: np.ndarray, rec: np.ndarray,
              n_rec: int) -> int:
    """Replace ``y``, the state at ``t0``, by the state at ``t_target`` (within the kept step): one step
    of the run's own method (no error control: it is shorter than the step the control accepted). With
    ``model.record`` its output row goes to ``rec[n_rec]``; returns the rows used."""
    mode, direction = iv[IV_MODE], iv[IV_DIR]
    # stuck, nothing moves relative to the surface; with surface.thickness the part moves with its material
    if mode != STUCK or model.piezo or model.half_thickness > 0.0:
        f0, out = scratch[6], scratch[8]
        evaluate(mode, direction, t0, y, model, src, cur, st, aux, f0)
        if model.adaptive and not model.threshold:
            dopri5_step(mode, direction, t0, y, f0, t_target - t0, model, src, cur, st, aux, scratch, out)
        else:
            rk4_step(mode, direction, t0, y, f0, t_target - t0, model, src, cur, st, aux, scratch, out)
        copy_into(y, out)
        if model.half_thickness > 0.0 and mode == STUCK:     # its material point's velocity, exactly
            evaluate(mode, direction, t_target, y, model, src, cur, st, aux, scratch[9])
            y[1] = aux[AUX_MAT_VX]
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
    allocates): ``scratch`` (N_SCRATCH, y.size), ``st`` (4, channels), ``aux`` (N_AUX,), ``cur`` (channels, 2)
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
        if resume_which < 0:                        # accepted as the loop accepts a step: a mode entered
            iv[IV_FRESH] = 0                        # before it is no longer fresh (a velocity jump where
            if record:                              # the step ends was missed: a reversal of the slip)
                observe(t, y, iv, model, src, cur, st, aux, work[10], rec[n_rec])
                n_rec += 1
    fs[FS_AHEAD_T1] = math.nan
    need_eval = True
    t_next = t
    g0 = g1 = 0.0
    same_instant = 0
    t_last_event = math.nan
    h_cap = 0.0
    h_wave = h_poly = math.inf
    dip_retries = 0
    start_known, start_slope0, start_slope1 = iv[IV_START_KNOWN] != 0, fs[FS_START_SLOPE0], fs[FS_START_SLOPE1]
    t_req0 = t_rate0 = t_req1 = t_rate1 = math.nan      # T_req and dT_req/dt where the step starts and ends
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
                h_poly = polynomial_step(src, cur) if model.half_thickness > 0.0 else math.inf
            if threshold and mode != FLYING:
                kind = threshold_decision(t, y, model, src, cur, st, aux, iv, fs)
                if kind >= 0:
                    ev_i[n_ev, 0], ev_i[n_ev, 1], ev_i[n_ev, 2] = kind, mode, iv[IV_MODE]
                    ev_f[n_ev, 0], ev_f[n_ev, 1] = t, y[0]
                    n_ev += 1
                    mode = iv[IV_MODE]
            g0, g1 = evaluate(mode, iv[IV_DIR], t, y, model, src, cur, st, aux, f0)
            kind = material_jump(mode, g0, t, y, aux, iv, fs) if model.half_thickness > 0.0 else -1
            if kind >= 0:                       # the material's velocity jumped under the part
                ev_i[n_ev, 0], ev_i[n_ev, 1], ev_i[n_ev, 2] = kind, mode, iv[IV_MODE]
                ev_f[n_ev, 0], ev_f[n_ev, 1] = t, y[0]
                n_ev += 1
                mode = iv[IV_MODE]
                g0, g1 = evaluate(mode, iv[IV_DIR], t, y, model, src, cur, st, aux, f0)
            t_req0 = aux[AUX_T_REQ]
            need_eval = False
            if dip_search:                      # the margins' slopes where this step starts
                start_slope0, start_slope1 = margin_slopes(mode, iv[IV_DIR], y, f0, model, st, aux)
                t_rate0 = aux[AUX_T_RATE]
                start_known = not math.isnan(start_slope0)
            if g1 <= 0.0:                       # a condition that already holds switches at once
                which = 1
            elif iv[IV_FRESH] == 0 and (g0 < 0.0 if mode == STUCK else g0 <= 0.0):
                which = 0
        if which < 0:
            direction = iv[IV_DIR]
            moving = mode != STUCK or model.piezo or model.half_thickness > 0.0
            error_control = adaptive and moving     # Dormand-Prince; else RK4, or stuck checks
            if error_control:
                h = min(fs[FS_H], dt, t_next - t, t_limit - t)
            else:
                h = min(dt if moving or threshold else model.check_step, t_next - t, t_limit - t)
            if dip_search and (error_control or not moving):     # fixed-step RK4 keeps its dt
                h = min(h, h_wave)
                if mode == STUCK:
                    h = min(h, h_poly)
            if h_cap > 0.0:
                h = min(h, h_cap)
                h_cap = 0.0
            # a step cut short by a breakpoint, the target, a dip or the wave's limit says nothing about
            # the step size the error allows: the size proposed before is kept unless the error rejects it
            h_proposed = fs[FS_H] if error_control and h < fs[FS_H] else 0.0
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
                    fs[FS_H] = max(h_proposed, h * min(5.0, max(0.2, 0.9 * max(err, 1e-10) ** -0.2)))
                    break
                h *= max(0.2, 0.9 * err ** -0.2)
                h_proposed = 0.0
            if model.half_thickness > 0.0 and mode == STUCK:
                y1[1] = aux[AUX_MAT_VX]         # stuck: the part's velocity is its material point's, exactly
            t_req1 = aux[AUX_T_REQ]
            end_slope0 = end_slope1 = math.nan
            if dip_search:                      # in closed form where it has one (else NaN)
                end_slope0, end_slope1 = margin_slopes(mode, direction, y1, f1, model, st, aux)
                t_rate1 = aux[AUX_T_RATE]
            if not finite(y1) or math.isnan(e0) or math.isnan(e1):
                status = NON_FINITE
                break
            fresh = iv[IV_FRESH] != 0
            # stuck stays stuck while |T_req| <= Q_max; a fresh mode's margin starts at 0 by construction
            hit0 = (e0 < 0.0 and g0 >= 0.0) if mode == STUCK else (e0 <= 0.0 and (g0 > 0.0 or fresh))
            hit1 = e1 <= 0.0 and g1 > 0.0
            if not (hit0 or hit1) and dip_search and dip_retries < 4:
                theta, end_slope0, end_slope1, t_rate1 = first_dip(
                    mode, direction, t, h, y, f0, y1, f1, g0, g1, e0, e1, fresh, start_known, start_slope0,
                    start_slope1, end_slope0, end_slope1, t_req0, t_rate0, t_req1, t_rate1, model, src, cur, st,
                    aux, work, error_control)
                if theta > 0.0:                 # a margin dips past its event inside the step: end the
                    h_cap = theta * h           # step there (the retried step then locates the root)
                    dip_retries += 1
                    continue
            if not (hit0 or hit1):              # accept the step
                t_new = t_next if h == t_next - t else (t_limit if h == t_limit - t else t + h)
                if t_new > t_target:            # past the target: keep it and report at the target
                    keep_ahead(t, t_new, y, y1, -1, False, end_slope0, end_slope1,
                               t_new < t_next and not math.isnan(end_slope0), ahead, iv, fs)
                    n_rec = report_at(t_target, t, y, iv, model, src, cur, st, aux, scratch, rec, n_rec)
                    t = t_target
                    break
                t = t_new
                copy_into(y, y1)
                copy_into(f0, f1)
                g0, g1 = e0, e1
                t_req0, t_rate0 = t_req1, t_rate1
                iv[IV_FRESH] = 0
                dip_retries = 0
                # each margin's slope where the next step starts (at this step's end)
                start_slope0, start_slope1 = end_slope0, end_slope1
                fs[FS_MAX_SPEED] = max(fs[FS_MAX_SPEED], abs(y[1]))
                if record:
                    observe(t, y, iv, model, src, cur, st, aux, work[10], rec[n_rec])
                    n_rec += 1
                need_eval = t >= t_next or (threshold and mode != FLYING)
                start_known = not need_eval and not math.isnan(end_slope0)
                iv[IV_START_KNOWN], fs[FS_START_SLOPE0], fs[FS_START_SLOPE1] = start_known, start_slope0, start_slope1
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
            if (dip_search and mode == STUCK and dip_retries < 4 and theta * h > 4.0 * tol
                    and not (which == 0 and not hit1 and t_req0 * t_req1 >= 0.0
                             and required_friction_keeps_sign(t, h, y, model, src, cur)
                             and adhesion_floor(mode, t, h, y, f0, y1, f1, work, error_control, model, src,
                                                cur) > 0.0)):
                # a root search brackets any of the roots in the step, and a margin can dip past its event
                # and recover before the root it found: the step is retaken to just short of that root,
                # where the dip search looks (docs/events.md); not needed for the stick margin's root where
                # T_req keeps its sign (no kink: its one root) and the adhesion margin provably stays above 0
                h_cap = theta * h - 2.0 * tol
                dip_retries += 1
                continue
            if not moving:
                copy_into(y1, y)
            elif adaptive and mode == SLIDING and which == 0:
                dopri5_dense(theta, h, y, f0, y1, f1, work, work[9])   # a slide's end: the state on the
                copy_into(y1, work[9])                                 # interpolant of the root
            elif adaptive:                      # take-off, landing: a full step to the root, as the
                # flight is sensitive to them; error-controlled, in pieces if need be: its last stage lies at
                # the root, where the predicted state can overshoot the margin (past pull-off, the Q_max(N)
                # table's steep first segment read a 1e-9 N overshoot as a negative friction limit, and one
                # 250-ns step to a take-off came out 6.6e-7 m/s off)
                t_root = t + theta * h
                t_sub = t
                y_sub, f_sub = work[9], work[10]
                copy_into(y_sub, y)
                copy_into(f_sub, f0)
                while True:
                    h_sub = t_root - t_sub
                    while True:
                        dopri5_step(mode, direction, t_sub, y_sub, f_sub, h_sub, model, src, cur, st, aux, work, y1)
                        evaluate(mode, direction, t_sub + h_sub, y1, model, src, cur, st, aux, f1)
                        err = dopri5_error(h_sub, f_sub, work, f1, model.tolerance, dt)
                        if err <= 1.0 or not math.isfinite(err) or h_sub < 1e-14:
                            break
                        h_sub *= max(0.2, 0.9 * err ** -0.2)
                    if h_sub == t_root - t_sub:
                        break
                    t_sub += h_sub
                    copy_into(y_sub, y1)
                    copy_into(f_sub, f1)
                # a landing in a take-off's first step: the gap, 0 at the take-off, is there smaller than the
                # interpolant's error, which can cross 0 at once (75 ps into a step whose end had landed 0.8 µs
                # after the true landing); the gap the step to the root reaches decides: if it is still open,
                # the step is retaken shorter
                if mode == FLYING and fresh and dip_retries < 8 and \
                        evaluate(mode, direction, t_root, y1, model, src, cur, st, aux, f1)[0] > 0.0:
                    h_cap = 0.5 * h
                    dip_retries += 1
                    continue
            else:                               # flight is sensitive to them; RK4: step to the root, once
                slope = aux[AUX_ROOT_SLOPE]     # more if the true margin disagrees with Hermite's root
                for attempt in range(2):
                    rk4_step(mode, direction, t, y, f0, theta * h, model, src, cur, st, aux, work, y1)
                    if attempt == 1 or slope >= 0.0:
                        break
                    if mode == SLIDING and which == 0 and model.half_thickness == 0.0:
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
                keep_ahead(t, t_new, y, y1, which, grazing, math.nan, math.nan, False, ahead, iv, fs)
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


@jit
def advance_parts(ys: np.ndarray, ivs: np.ndarray, fss: np.ndarray, aheads: np.ndarray, running: np.ndarray,
                  status: np.ndarray, t_target: float, t_limit: float, model: KernelModel, src: tuple,
                  ev_i: np.ndarray, ev_f: np.ndarray, ev_count: np.ndarray, path: np.ndarray, rec: np.ndarray,
                  record: int, scratch: np.ndarray, st: np.ndarray, aux: np.ndarray, cur: np.ndarray) -> int:
    """:func:`advance` for several parts' states at once, the rows of ``ys``, ``ivs``, ``fss`` (parts, ...) and
    ``aheads`` (parts, 2, y.size): one compiled call where a Python loop over the parts cost ~15 µs a part.

    Each part whose ``running`` flag is set is integrated to ``t_target`` by the very calls to :func:`advance` it
    would get alone, so its answer is the same bit for bit. Its events go to ``ev_i`` / ``ev_f`` one part after
    the other (``ev_count[p]`` of them for part p, added to what was there), and ``path[p]`` grows by the
    distance along x between its start, its events and its end (m). A part whose events no longer fit, or
    whose integration fails, stops with its ``running`` flag cleared and its ``status`` set (EVENTS_FULL: the
    caller goes on with it alone; an error as :func:`advance` gives it). Returns the events written.

    ``record`` is :func:`advance`'s flag, passed in (0) rather than written here: a literal 0 would be typed
    ``Literal[int](0)`` and make numba compile a second copy of the whole kernel (minutes, GBs) for it."""
    n_ev = 0
    for p in range(ys.shape[0]):
        if not running[p]:
            continue
        y, iv, fs, ahead = ys[p], ivs[p], fss[p], aheads[p]
        x_last = y[0]
        while fs[FS_T] < t_target:
            code, n, _ = advance(y, iv, fs, ahead, t_target, t_limit, model, src, ev_i[n_ev:], ev_f[n_ev:], rec,
                                 record, scratch, st, aux, cur)
            for k in range(n_ev, n_ev + n):
                path[p] += abs(ev_f[k, 1] - x_last)
                x_last = ev_f[k, 1]
            n_ev += n
            ev_count[p] += n
            if code != DONE:
                running[p] = False
                status[p] = code
                break
        path[p] += abs(y[0] - x_last)
    return n_ev
