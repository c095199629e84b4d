"""The chunks in which no two parts come near each other, taken in one compiled call.

:meth:`.model.PartsModel.advance` takes its chunks one at a time in Python: every part alone over the chunk
(one compiled call), then the gaps and reaches, the cut of a chunk where parts come near, the next chunk's
length. 16 hopping parts take ~2 chunks a millisecond, and that Python cost the simulator node as much as
the integration. :func:`advance_apart` takes the same chunks, by the same rules and the same arithmetic (so
the same numbers, bit for bit), as long as no two parts touch at a chunk's start and none closes its gap
within it; it hands the chunk where that happens (an impact, a train) back to the Python loop untaken.

A module of its own so that the kernel's cached machine code stays as it was.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit_exact
from ..dynamics.kernel import advance_parts
from ..dynamics.layout import DONE, FS_MAX_SPEED, FS_T, KernelModel

REACH_SAFETY = 2.0          # how far a part may have gone in a chunk: this times its largest speed times the chunk
CONTACT_GAP = 1e-12         # m: two parts this close (or closer) touch
MAX_CHUNK = 1.0             # s: the longest chunk, when no two parts are near each other

REACHED, HANDED_BACK = 0, 1   # what advance_apart returns: t_target reached; the next chunk is the caller's


@jit_exact
def near_end(t0: float, near_chunk: float) -> float:
    """The end (s) of a near chunk starting at ``t0``: the next multiple of ``near_chunk``."""
    return (math.floor(t0 / near_chunk + 1e-9) + 1) * near_chunk


@jit_exact
def _copy_2d(target: np.ndarray, source: np.ndarray) -> None:
    for i in range(source.shape[0]):
        for j in range(source.shape[1]):
            target[i, j] = source[i, j]


@jit_exact
def _copy_3d(target: np.ndarray, source: np.ndarray) -> None:
    for i in range(source.shape[0]):
        _copy_2d(target[i], source[i])


@jit_exact
def next_chunk(gaps: np.ndarray, reach: np.ndarray, near: bool, chunk: float, grown_from: float,
               near_chunk: float) -> float:
    """The chunk to try after one of ``chunk`` (s): a near chunk while parts are ``near`` or touching (``gaps``
    between neighbours at its end, m), else as long as the gaps allow (the ``reach`` of each pair over the
    chunk, m, scaled) and at most twice ``grown_from`` (s)."""
    if near:
        return near_chunk
    moving = False
    ratio = math.inf
    for i in range(gaps.size):
        if gaps[i] <= CONTACT_GAP:
            return near_chunk
        if reach[i] > 0.0:
            moving = True
            ratio = min(ratio, gaps[i] / reach[i])
    allowed = 0.5 * ratio * chunk if moving else MAX_CHUNK
    return min(MAX_CHUNK, max(near_chunk, min(2.0 * grown_from, allowed)))


@jit_exact
def advance_apart(ys: np.ndarray, ivs: np.ndarray, fss: np.ndarray, aheads: np.ndarray, t_target: float,
                  t_limit: float, size: float, near_chunk: float, hint: np.ndarray, model: KernelModel, src: tuple,
                  trial_ys: np.ndarray, trial_ivs: np.ndarray, trial_fss: np.ndarray, trial_aheads: np.ndarray,
                  running: np.ndarray, status: np.ndarray, counts: np.ndarray, path: np.ndarray,
                  run_max: np.ndarray, part_reach: np.ndarray, reach: np.ndarray, gap0: np.ndarray,
                  gap1: np.ndarray, ev_i: np.ndarray, ev_f: np.ndarray, out_i: np.ndarray, out_f: np.ndarray,
                  out_count: np.ndarray, trials: np.ndarray, rec: np.ndarray, record: int, scratch: np.ndarray,
                  st: np.ndarray, aux: np.ndarray, cur: np.ndarray) -> int:
    """Advance the parts' rows (``ys``, ``ivs``, ``fss``, ``aheads``: parts × ..., changed in place) chunk by
    chunk towards ``t_target`` (s) on one stroke table (``src``, valid until ``t_limit``), as
    :meth:`.model.PartsModel._chunk` does, while no two parts touch or meet. ``hint[0]``: the chunk to try
    next (s; 0: a near chunk), updated. Each taken chunk's events of part p go to ``out_i[p]`` / ``out_f[p]``
    (``out_count[p]`` of them, chunk after chunk); ``trials[0]``: the trials made (kept or cut).
    The ``trial_*`` … ``gap1`` arrays are work space (one row or entry per part), ``ev_i`` … ``cur`` the
    kernel's (:func:`.kernel.advance_parts`).

    Returns REACHED, or HANDED_BACK when the next chunk (from the rows' time, with ``hint[0]``) is the Python
    loop's: two parts touch at its start, a gap closes within it, a part's integration stopped (too many
    events, or a failure the caller reports), or a part's events would not fit in its row of ``out_i``."""
    n = ys.shape[0]
    trials[0] = 0
    for p in range(n):
        out_count[p] = 0
    while True:
        t = fss[0, FS_T]
        if not t < t_target:
            return REACHED
        for i in range(n - 1):
            gap0[i] = ys[i + 1, 0] - ys[i, 0] - size
            if gap0[i] <= CONTACT_GAP:
                return HANDED_BACK
        chunk_hint = hint[0] if hint[0] != 0.0 else near_chunk
        t1_planned = near_end(t, near_chunk) if chunk_hint <= near_chunk else t + chunk_hint
        t1 = min(t1_planned, t_target)
        t1_given = t1
        while True:
            _copy_2d(trial_ys, ys)
            _copy_2d(trial_ivs, ivs)
            _copy_2d(trial_fss, fss)
            _copy_3d(trial_aheads, aheads)
            for p in range(n):
                run_max[p] = trial_fss[p, FS_MAX_SPEED]
                trial_fss[p, FS_MAX_SPEED] = abs(trial_ys[p, 1])
                running[p] = True
                status[p] = 0
                counts[p] = 0
                path[p] = 0.0
            trials[0] += 1
            advance_parts(trial_ys, trial_ivs, trial_fss, trial_aheads, running, status, t1, t_limit, model,
                          src, ev_i, ev_f, counts, path, rec, record, scratch, st, aux, cur)
            chunk = t1 - t
            for p in range(n):
                if status[p] != DONE:
                    return HANDED_BACK
                part_reach[p] = REACH_SAFETY * trial_fss[p, FS_MAX_SPEED] * chunk + path[p]
            near = False
            ratio = math.inf
            for i in range(n - 1):
                gap1[i] = trial_ys[i + 1, 0] - trial_ys[i, 0] - size
                if gap1[i] <= CONTACT_GAP:
                    return HANDED_BACK
                reach[i] = part_reach[i] + part_reach[i + 1]
                if reach[i] > 0.0 and gap0[i] <= reach[i]:
                    near = True
                    ratio = min(ratio, gap0[i] / reach[i])
            if near and t1 > near_end(t, near_chunk) * (1 + 1e-15):
                cut = 0.5 * ratio * chunk
                t1 = t + cut if cut > near_chunk else near_end(t, near_chunk)
                continue
            break
        for p in range(n):
            if out_count[p] + counts[p] > out_i.shape[1]:
                return HANDED_BACK
        k = 0
        for p in range(n):
            for _ in range(counts[p]):
                j = out_count[p]
                out_i[p, j, 0], out_i[p, j, 1], out_i[p, j, 2] = ev_i[k, 0], ev_i[k, 1], ev_i[k, 2]
                out_f[p, j, 0], out_f[p, j, 1] = ev_f[k, 0], ev_f[k, 1]
                out_count[p] += 1
                k += 1
        _copy_2d(ys, trial_ys)
        _copy_2d(ivs, trial_ivs)
        _copy_2d(fss, trial_fss)
        _copy_3d(aheads, trial_aheads)
        for p in range(n):
            fss[p, FS_MAX_SPEED] = max(run_max[p], trial_fss[p, FS_MAX_SPEED])
        grown_from = max(chunk, t1_planned - t) if t1 == t1_given else chunk
        hint[0] = next_chunk(gap1[:n - 1], reach[:n - 1], near, chunk, grown_from, near_chunk)
