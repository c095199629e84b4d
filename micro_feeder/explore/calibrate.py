"""Fitting model parameters to recorded runs: least squares on the re-simulated part trajectory.

A log's recorded commands are re-applied to a fresh simulation by the replay loop ``resim`` uses (its stop
times, command receipts and the simulator's own command checks: :mod:`micro_feeder.sim.replay`);
the residuals are the differences between the re-simulated and the recorded part position (x, z) at
every recorded pose, over every log. scipy.optimize.least_squares ('trf', bounds) works on the
parameters divided by their starting values, so that a mass of 1e-9 kg and a friction factor of 0.01
are searched on the same footing; the Jacobian is by forward differences, its columns evaluated in
parallel on the runner (local processes or a Dask cluster; the logs must be readable at the same path
on every worker).

Uncertainty: the covariance s² (JᵀJ)⁻¹ with s² = Σr²/(m − n) at the solution (the residuals taken as
independent with equal variance: a lower bound when they are correlated in time, as trajectories are).
A parameter whose Jacobian column is zero has no effect on the logs: it is reported as not
identifiable and left at its start; two or more whose columns are (nearly) dependent are reported as
not separately identifiable.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from ..logs.reader import LogReader
from ..physics.dynamics import Observation
from ..settings import model_specs
from ..sim.replay import Recording, ReplayError, Stop, read_recording, replay
from ..sim.stepper import Stepper, build_model
from .runners import Runner

DIFF_STEP = 1e-4           # forward-difference step, relative to each parameter's start
NO_EFFECT = 1e-9           # a Jacobian column below this × the largest one: the parameter has no effect
MAX_CONDITION = 1e10       # condition number of the scaled JᵀJ above which parameters are not separable
FAILED_RESIDUAL = 1.0      # m: residual of a pose after the re-simulation failed (far larger than any real one)


class CalibrationError(ValueError):
    """The fit cannot start (no pose in a log, unknown parameter, a start of zero ...); says why."""


@lru_cache(maxsize=16)
def load_recording(path: str) -> Recording:
    """Read a log once per process (the workers cache it too)."""
    try:
        rec = read_recording(LogReader(path))
    except ReplayError as err:
        raise CalibrationError(f'{path}: {err} to fit') from err
    notes = [f'{path}: {note}' for note in rec.notes]
    if not rec.snapshots:
        notes.append(f'{path}: no simulator/parameters recorded, defaults assumed')
    return dataclasses.replace(rec, notes=notes)


def resimulate_poses(path: str, changes: Mapping[str, float]) -> np.ndarray:
    """Re-simulated (x, z) at each recorded pose of the log at ``path`` with ``changes`` applied; poses
    after a failure of the integration are NaN."""
    rec = load_recording(path)
    out = np.full((len(rec.posed_stops), 2), np.nan)
    filled = 0

    def keep(_stop: Stop, obs: Observation) -> None:
        nonlocal filled
        out[filled] = obs.x, obs.z
        filled += 1

    replay(Stepper(build_model({**rec.flat, **changes})), rec, keep)
    return out


def residuals(path: str, changes: Mapping[str, float]) -> np.ndarray:
    """Re-simulated minus recorded (x, z) at every pose, flattened (m); a failed stretch counts
    ``FAILED_RESIDUAL`` per coordinate."""
    diff = (resimulate_poses(path, changes) - load_recording(path).poses).ravel()
    return np.where(np.isfinite(diff), diff, FAILED_RESIDUAL)


def _residual_task(task: tuple[str, dict[str, float]]) -> np.ndarray:
    return residuals(*task)


@dataclass
class Fitted:
    """One fitted parameter: value, 1-sigma uncertainty (NaN when not identifiable), start, and
    whether the logs determine it."""

    name: str
    value: float
    sigma: float
    start: float
    identifiable: bool


@dataclass
class CalibrationResult:
    parameters: list[Fitted]
    converged: bool
    message: str
    evaluations: int
    rms_start: float            # m, over every pose coordinate
    rms: float                  # m
    max_abs: float              # m
    residual_count: int
    logs: list[str]
    problems: list[str] = field(default_factory=list)   # identifiability / convergence, for people

    def as_dict(self) -> dict[str, Any]:
        def clean(v: Any) -> Any:
            return None if isinstance(v, float) and not math.isfinite(v) else v
        return {'parameters': {p.name: {k: clean(v) for k, v in vars(p).items() if k != 'name'}
                               for p in self.parameters},
                'converged': self.converged, 'message': self.message, 'evaluations': self.evaluations,
                'rms_start_m': self.rms_start, 'rms_m': self.rms, 'max_abs_m': self.max_abs,
                'residuals': self.residual_count, 'logs': self.logs, 'problems': self.problems}


def calibrate(paths: Sequence[str], start: Mapping[str, float], runner: Runner,
              bounds: Mapping[str, tuple[float, float]] | None = None, max_evaluations: int = 60,
              progress: Callable[[int, float], None] | None = None) -> CalibrationResult:
    """Fit the parameters ``start`` (name -> starting value, each ≠ 0) to the logs ``paths``."""
    specs = model_specs()
    for name, value in start.items():
        if name not in specs or specs[name][0].kind not in ('float', 'int', 'float_or_list'):
            raise CalibrationError(f'{name}: not a numeric model parameter (see docs/parameters.md)')
        if not value or not math.isfinite(value):
            raise CalibrationError(f'{name}: the start must be a finite non-zero value (the fit is relative to it); '
                                   'give one with --set NAME=START')
    recordings = [load_recording(str(p)) for p in paths]
    names = list(start)
    scale = np.array([float(start[n]) for n in names])
    low, high = _bounds(names, scale, specs, bounds or {})
    evaluations = 0

    def fun_many(points: list[np.ndarray]) -> list[np.ndarray]:
        nonlocal evaluations
        tasks = [(r.path, dict(zip(names, (u * scale).tolist(), strict=True))) for u in points for r in recordings]
        flat = runner.map(_residual_task, tasks)
        evaluations += len(points)
        n = len(recordings)
        return [np.concatenate(flat[i * n:(i + 1) * n]) for i in range(len(points))]

    u0 = np.ones(len(names))
    r0 = fun_many([u0])[0]
    j0 = _jacobian(fun_many, u0, r0, high)
    column = np.linalg.norm(j0, axis=0)
    no_effect = column <= NO_EFFECT * max(column.max(), 1e-300)
    problems = [f'{n} has no effect on the recorded trajectory (its Jacobian column is zero): not identifiable '
                'from these logs; left at its start' for n, dead in zip(names, no_effect, strict=True) if dead]
    free = [i for i in range(len(names)) if not no_effect[i]]
    result_u, converged, message, jac = u0.copy(), False, 'nothing to fit', j0
    if free:
        from scipy.optimize import least_squares
        cache: dict[bytes, np.ndarray] = {u0.tobytes(): r0}

        def full(v: np.ndarray) -> np.ndarray:
            u = u0.copy()
            u[free] = v
            return u

        def residual_fn(v: np.ndarray) -> np.ndarray:
            u = full(v)
            if u.tobytes() not in cache:
                cache[u.tobytes()] = fun_many([u])[0]
            if progress is not None:
                progress(evaluations, _rms(cache[u.tobytes()]))
            return cache[u.tobytes()]

        def jac_fn(v: np.ndarray) -> np.ndarray:
            return _jacobian(fun_many, full(v), residual_fn(v), high)[:, free]

        fit = least_squares(residual_fn, u0[free], jac=jac_fn, bounds=(low[free], high[free]), method='trf',
                            x_scale=1.0, max_nfev=max_evaluations, xtol=1e-10, ftol=1e-12, gtol=1e-12)
        result_u = full(fit.x)
        converged, message = fit.status > 0, fit.message
        jac = np.zeros_like(j0)
        jac[:, free] = fit.jac
        if not converged:
            problems.append(f'did not converge within {max_evaluations} evaluations ({fit.message}); '
                            'the values shown are the last iterate')
    r = fun_many([result_u])[0]
    sigma, coupled = _uncertainty(jac, r, free)
    if coupled:
        problems.append(f'{", ".join(names[i] for i in coupled)} are not separately identifiable from these logs '
                        '(their effects on the trajectory are nearly proportional): the uncertainties are huge')
    fitted = [Fitted(n, float(result_u[i] * scale[i]), float(sigma[i] * abs(scale[i])), float(scale[i]),
                     not no_effect[i] and i not in coupled) for i, n in enumerate(names)]
    notes = [note for rec in recordings for note in rec.notes]
    return CalibrationResult(fitted, converged, message, evaluations, _rms(r0), _rms(r), float(np.max(np.abs(r))),
                             int(r.size), [rec.path for rec in recordings], problems + notes)


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(r ** 2)))


def _bounds(names: list[str], scale: np.ndarray, specs: Mapping[str, Any],
            given: Mapping[str, tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
    """Bounds in units of the start: the given ones, else the parameter's own limits within a factor 10
    of the start (keeping the sign)."""
    low, high = np.empty(len(names)), np.empty(len(names))
    for i, name in enumerate(names):
        lo, hi = given.get(name, (min(scale[i] / 10, scale[i] * 10), max(scale[i] / 10, scale[i] * 10)))
        spec = specs[name][0]
        lo = max([lo, *(b for b in (spec.ge, spec.gt) if b is not None)])
        hi = min([hi, *(b for b in (spec.le, spec.lt) if b is not None)])
        a, b = sorted((lo / scale[i], hi / scale[i]))
        if not a < 1.0 < b:
            raise CalibrationError(f'{name}: the start {scale[i]:g} is not strictly inside its bounds [{lo:g}, {hi:g}]')
        low[i], high[i] = a, b
    return low, high


def _jacobian(fun_many: Callable[[list[np.ndarray]], list[np.ndarray]], u: np.ndarray, r: np.ndarray,
              high: np.ndarray) -> np.ndarray:
    """Forward differences, all columns in one parallel batch (backward at an upper bound)."""
    steps = np.where(u + DIFF_STEP * np.maximum(np.abs(u), 1.0) <= high, 1.0, -1.0) * DIFF_STEP * np.maximum(
        np.abs(u), 1.0)
    points = [u + steps[j] * np.eye(len(u))[j] for j in range(len(u))]
    return np.column_stack([(rj - r) / steps[j] for j, rj in enumerate(fun_many(points))])


def _uncertainty(jac: np.ndarray, r: np.ndarray, free: list[int]) -> tuple[np.ndarray, list[int]]:
    """1-sigma per parameter (relative to the start; NaN where not identifiable) and the indices of
    parameters that are not separately identifiable."""
    sigma = np.full(jac.shape[1], np.nan)
    if not free:
        return sigma, []
    j = jac[:, free]
    dof = max(r.size - len(free), 1)
    s2 = float(r @ r) / dof
    norms = np.linalg.norm(j, axis=0)
    jn = j / norms
    condition = np.linalg.cond(jn.T @ jn)
    if not math.isfinite(condition) or condition > MAX_CONDITION:
        return sigma, free if len(free) > 1 else []
    cov = s2 * np.linalg.inv(jn.T @ jn) / np.outer(norms, norms)
    sigma[free] = np.sqrt(np.diag(cov))
    return sigma, []
