"""The contact model at run time: forces vs separation, pull-off, and load-indexed tables.

:class:`ContactModel` evaluates the KE integrals once on dense separation grids and answers the
questions the dynamics asks (docs/contact.md §4): at applied normal load N, what is the equilibrium
separation d(N) on the stable branch and the maximum static friction Q_max(N); how hard does the
surface pull a part that has flown off to a gap delta; when is the part pulled off (N <= -F_po).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.optimize import minimize_scalar

from ..parameters import ParameterError
from ..particle import ParticleParams
from . import asperity
from .params import ContactParams
from .rough_surface import DimensionlessInputs, surface_forces

# Table extents and densities (separations in sigma).
MAX_TABLE_LOAD_N = 1.0          # the stable-branch table reaches at least this applied load
STABLE_BRANCH_POINTS = 1200
MAX_TABLE_GAP_M = 1e-3          # the flight table reaches this gap; beyond it the tail ~ 1/gap^2
GAP_POINTS = 400
POLISH_ITERATIONS = 30
POLISH_TOLERANCE = 1e-12        # relative to the pull-off force


class PulledOffError(ValueError):
    """The applied load is at or below -F_po: no equilibrium separation, the part has been pulled off."""


@dataclass(frozen=True)
class ContactTables:
    """Load- and gap-indexed tables for a compiled kernel (float64 arrays, linear interpolation).

    ``load_n`` rises strictly from -F_po (the pull-off point, first entry) to >= MAX_TABLE_LOAD_N, with
    ``q_max_n`` and ``separation_m`` at each load. ``gap_m`` rises from 0 (at the pull-off separation)
    to MAX_TABLE_GAP_M with the flight attraction ``attraction_n`` = -F(d_min + gap) >= 0; beyond the
    last gap the attraction decays as attraction_n[-1] * (gap_m[-1] / gap)^2.
    """

    load_n: np.ndarray
    q_max_n: np.ndarray
    separation_m: np.ndarray
    gap_m: np.ndarray
    attraction_n: np.ndarray
    pull_off_n: float
    d_pull_off_m: float


@dataclass(frozen=True)
class SeparationCurve:
    """Forces (N) at separations ``separation_m``: the model's curves of the seed's Figs. 4, 6, 9."""

    separation_m: np.ndarray
    contact_load_n: np.ndarray
    adhesion_contact_n: np.ndarray
    adhesion_noncontact_n: np.ndarray
    q_max_n: np.ndarray

    @property
    def adhesion_n(self) -> np.ndarray:
        return self.adhesion_contact_n + self.adhesion_noncontact_n

    @property
    def applied_load_n(self) -> np.ndarray:
        return self.contact_load_n - self.adhesion_n


class ContactModel:
    """KE rough-surface contact of the part on the feeder surface (immutable once built)."""

    def __init__(self, contact: ContactParams | None = None, particle: ParticleParams | None = None):
        self.contact = contact or ContactParams()
        self.particle = particle or ParticleParams()
        c = self.contact
        self.hardness_coeff = asperity.hardness_coefficient(c.poisson)
        self.inputs = DimensionlessInputs(
            beta=c.beta, omega_c=1.0 / c.psi ** 2, epsilon=c.epsilon / c.sigma,
            hardness_coeff=self.hardness_coeff, adhesion=c.delta_gamma / (c.hardness * c.sigma),
            adhesion_contact_scale=c.adhesion_contact_scale, friction_scale=c.friction_scale,
            friction_law=c.friction_law)
        self.force_unit_n = self.particle.area * c.hardness     # A_n H
        self._find_pull_off()
        self._build_stable_branch()
        self._build_flight_table()

    # ---- direct evaluation (quadrature) -------------------------------------------------------------

    def curve(self, separation_m: np.ndarray) -> SeparationCurve:
        """Every force at the given separations d (m) by direct quadrature (no table)."""
        d = np.atleast_1d(np.asarray(separation_m, dtype=float))
        forces = surface_forces(d / self.contact.sigma, self.inputs)
        unit = self.force_unit_n
        return SeparationCurve(d, unit * forces.contact_load, unit * forces.adhesion_contact,
                               unit * forces.adhesion_noncontact, unit * forces.q_max)

    def applied_load_at_separation(self, separation_m: np.ndarray) -> np.ndarray:
        """F(d) = P - F_s (N) by direct quadrature."""
        return self.curve(separation_m).applied_load_n

    def _applied_load_star(self, d_star: np.ndarray) -> np.ndarray:
        return surface_forces(d_star, self.inputs).applied_load

    # ---- construction -------------------------------------------------------------------------------

    def _find_pull_off(self) -> None:
        """F_po = -min F(d) and its separation d_min: coarse scan, then bounded Brent."""
        coarse = np.linspace(-4.0, 12.0, 321)
        loads = self._applied_load_star(coarse)
        i = int(np.argmin(loads))
        lo, hi = coarse[max(i - 1, 0)], coarse[min(i + 1, coarse.size - 1)]
        best = minimize_scalar(lambda d: float(self._applied_load_star(np.array([d]))[0]),
                               bounds=(lo, hi), method='bounded', options={'xatol': 1e-10})
        self._d_min_star = float(best.x)
        min_load = float(best.fun)
        if not min_load < 0.0:
            raise ParameterError('contact.delta_gamma', self.contact.delta_gamma,
                                 'large enough for the applied load to have a negative minimum (a pull-off force)')
        self.pull_off_n = -min_load * self.force_unit_n
        self.d_pull_off_m = self._d_min_star * self.contact.sigma

    def _build_stable_branch(self) -> None:
        """Forces on d from the pull-off point down to where F >= MAX_TABLE_LOAD_N, denser near d_min
        (where d(F) has a square-root singularity)."""
        target = MAX_TABLE_LOAD_N / self.force_unit_n
        depth = 1.0
        while self._applied_load_star(np.array([self._d_min_star - depth]))[0] < target:
            depth *= 1.5
            if depth > 60.0:
                raise ParameterError('contact.beta', self.contact.beta,
                                     f'large enough for the surface to carry {MAX_TABLE_LOAD_N:g} N (the load '
                                     'tables reach it); with these inputs it never does')
        u = np.linspace(0.0, 1.0, STABLE_BRANCH_POINTS)
        d_star = self._d_min_star - depth * u ** 1.5
        self.stable_branch = self.curve(d_star * self.contact.sigma)
        load = self.stable_branch.applied_load_n
        load[0] = -self.pull_off_n
        keep = np.concatenate([[True], np.diff(load) > 0.0])   # strictly increasing for the inverse
        self._load_n = load[keep]
        self._separation_m = self.stable_branch.separation_m[keep]
        self._q_max_n = self.stable_branch.q_max_n[keep]
        self._separation_of_load = PchipInterpolator(self._load_n, self._separation_m, extrapolate=False)
        self._q_max_of_load = PchipInterpolator(self._load_n, self._q_max_n, extrapolate=False)
        order = np.argsort(self._separation_m)
        self._slope_of_separation = PchipInterpolator(
            self._separation_m[order], self._load_n[order]).derivative()

    def _build_flight_table(self) -> None:
        """Attraction -F(d_min + gap) for gaps from 0 to MAX_TABLE_GAP_M, log-spaced beyond 1e-3 sigma."""
        sigma = self.contact.sigma
        gaps = np.concatenate([[0.0], np.geomspace(1e-3 * sigma, MAX_TABLE_GAP_M, GAP_POINTS - 1)])
        attraction = -self.applied_load_at_separation(self.d_pull_off_m + gaps)
        attraction[0] = self.pull_off_n
        self._gap_m = gaps
        self._attraction_n = attraction
        self._log_attraction_of_gap = PchipInterpolator(np.log(gaps[1:]), np.log(attraction[1:]))

    # ---- run-time look-ups --------------------------------------------------------------------------

    @cached_property
    def tables(self) -> ContactTables:
        """The load and gap tables, for the compiled dynamics kernel."""
        return ContactTables(load_n=self._load_n.copy(), q_max_n=self._q_max_n.copy(),
                             separation_m=self._separation_m.copy(), gap_m=self._gap_m.copy(),
                             attraction_n=self._attraction_n.copy(), pull_off_n=self.pull_off_n,
                             d_pull_off_m=self.d_pull_off_m)

    def _check_loads(self, load_n: np.ndarray) -> np.ndarray:
        load = np.asarray(load_n, dtype=float)
        if np.any(~np.isfinite(load)):
            raise ValueError(f'applied load must be finite, got {load}')
        if np.any(load <= -self.pull_off_n):
            raise PulledOffError(f'applied load {load.min():.6g} N is at or below the pull-off load '
                                 f'{-self.pull_off_n:.6g} N: no equilibrium, the part is pulled off')
        if np.any(load > self._load_n[-1]):
            raise ValueError(f'applied load {load.max():.6g} N is above the contact table '
                             f'({self._load_n[-1]:.6g} N)')
        return load

    def q_max_at_load(self, load_n: np.ndarray) -> np.ndarray:
        """Maximum static friction Q_max (N) at applied normal load N (> -F_po), monotone interpolant."""
        return self._q_max_of_load(self._check_loads(load_n))

    def separation_at_load(self, load_n: np.ndarray) -> np.ndarray:
        """Equilibrium separation d (m) at applied load N on the stable branch (d <= d_min).

        The monotone interpolant gives the start; Newton steps on the direct quadrature F(d) polish it,
        so that F(d(N)) = N to ~1e-12 of the pull-off force.
        """
        load = np.atleast_1d(self._check_loads(load_n))
        d = self._separation_of_load(load)
        scale = self.pull_off_n
        for _ in range(POLISH_ITERATIONS):
            residual = self.applied_load_at_separation(d) - load
            done = np.abs(residual) <= POLISH_TOLERANCE * scale + 1e-15 * np.abs(load)
            if done.all():
                break
            slope = self._slope_of_separation(d)
            step = np.where(done | (slope >= 0.0), 0.0, residual / np.where(slope < 0.0, slope, -1.0))
            d = np.minimum(d - step, self.d_pull_off_m)
        return d.reshape(np.shape(load_n))

    def attraction_at_gap(self, gap_m: np.ndarray) -> np.ndarray:
        """Attraction (N, >= 0) on a flying part at gap delta >= 0 from the pull-off separation:
        -F(d_min + delta), continuous with F_po at take-off (docs/contact.md §3)."""
        gap = np.asarray(gap_m, dtype=float)
        if np.any(gap < 0.0) or np.any(~np.isfinite(gap)):
            raise ValueError('gap must be finite and >= 0')
        small = np.maximum(gap, self._gap_m[1])
        inside = np.exp(self._log_attraction_of_gap(np.log(np.minimum(small, MAX_TABLE_GAP_M))))
        near = np.interp(gap, self._gap_m[:2], self._attraction_n[:2])
        tail = self._attraction_n[-1] * (MAX_TABLE_GAP_M / np.maximum(gap, MAX_TABLE_GAP_M)) ** 2
        return np.where(gap < self._gap_m[1], near, np.where(gap <= MAX_TABLE_GAP_M, inside, tail))

    # ---- derived quantities for reporting -----------------------------------------------------------

    @property
    def weight_n(self) -> float:
        return self.particle.weight_n

    @property
    def critical_interference_m(self) -> float:
        """omega_c = sigma / psi^2 (m)."""
        return self.contact.sigma / self.contact.psi ** 2

    @property
    def asperity_radius_m(self) -> float:
        """R = sigma [2E / (pi K H psi)]^2 (m), from the plasticity index and the reporting modulus E."""
        c = self.contact
        return c.sigma * (2.0 * c.elastic_modulus / (math.pi * self.hardness_coeff * c.hardness * c.psi)) ** 2

    @property
    def asperity_density_per_m2(self) -> float:
        """eta = beta / (R sigma) (1/m^2)."""
        return self.contact.beta / (self.asperity_radius_m * self.contact.sigma)

    @property
    def asperity_count(self) -> float:
        """eta A_n: summits within the nominal contact area."""
        return self.asperity_density_per_m2 * self.particle.area

    @property
    def tabor_parameter(self) -> float:
        """(R dgamma^2 / (E^2 eps^3))^(1/3); DMT-type adhesion needs it well below 1."""
        c = self.contact
        return (self.asperity_radius_m * c.delta_gamma ** 2 / (c.elastic_modulus ** 2 * c.epsilon ** 3)) ** (1 / 3)
