"""One integration step of the current mode: classical RK4, Dormand-Prince 5(4) with its error estimate
and dense output, and the cubic Hermite interpolant of a step (docs/dynamics.md §3)."""

from __future__ import annotations

import numpy as np

from .._jit import jit, jit_inline
from .layout import KernelModel
from .rhs import evaluate

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
        r2, r3, r4, r5 = dense_coefficients(i, h, y0, f0, y1, f1, work)
        out[i] = y0[i] + theta * (r2 + (1.0 - theta) * (r3 + theta * (r4 + (1.0 - theta) * r5)))


@jit_inline
def dense_coefficients(i: int, h: float, y0: np.ndarray, f0: np.ndarray, y1: np.ndarray, f1: np.ndarray,
                       work: np.ndarray) -> tuple[float, float, float, float]:
    """r2..r5 of entry ``i`` in :func:`dopri5_dense`'s interpolant."""
    r2 = y1[i] - y0[i]
    r3 = h * f0[i] - r2
    r4 = r2 - h * f1[i] - r3
    r5 = h * (DP_D[0] * f0[i] + DP_D[1] * work[1, i] + DP_D[2] * work[2, i] + DP_D[3] * work[3, i]
              + DP_D[4] * work[4, i] + DP_D[5] * f1[i])
    return r2, r3, r4, r5


@jit_inline
def hermite(theta: float, h: float, y0: np.ndarray, f0: np.ndarray, y1: np.ndarray, f1: np.ndarray,
            out: np.ndarray) -> None:
    """Cubic Hermite interpolant of a step at fraction ``theta`` (dense output, 4th-order accurate)."""
    t2 = theta * theta
    t3 = t2 * theta
    a0, b0, a1, b1 = 2 * t3 - 3 * t2 + 1, (t3 - 2 * t2 + theta) * h, -2 * t3 + 3 * t2, (t3 - t2) * h
    for i in range(y0.size):
        out[i] = a0 * y0[i] + b0 * f0[i] + a1 * y1[i] + b1 * f1[i]


@jit_inline
def interpolant_reach(i: int, h: float, y0: np.ndarray, f0: np.ndarray, y1: np.ndarray, f1: np.ndarray,
                      work: np.ndarray, dense: bool) -> float:
    """Upper bound of |y_i(θ) − y0_i| over the step's interpolant, θ in [0, 1]: :func:`dopri5_dense`'s
    (``dense``; its form θ(r2 + (1−θ)(r3 + θ(r4 + (1−θ) r5))) has every factor within [0, 1]) or
    :func:`hermite`'s (y0 + a1 (y1 − y0) + b0 f0 + b1 f1 with 0 ≤ a1 ≤ 1 and |b0|, |b1| ≤ 4h/27)."""
    if not dense:
        return abs(y1[i] - y0[i]) + 4.0 / 27.0 * h * (abs(f0[i]) + abs(f1[i]))
    r2, r3, r4, r5 = dense_coefficients(i, h, y0, f0, y1, f1, work)
    return abs(r2) + abs(r3) + abs(r4) + abs(r5)
