"""Rough-surface integrals of the KE model over the Gaussian summit heights (docs/contact.md §3).

All lengths here are in units of sigma (``d`` means d*). Forces are divided by A_n H. Each integral is a
composite Gauss–Legendre sum on a fixed node set, so one matrix of Gaussian densities serves a whole
vector of separations:

* contacting asperities, in the interference ratio w = (z - d)/omega_c*: panels graded geometrically
  toward w = 0 and broken at every kink of the piecewise laws (1, 6, 110, the friction law's zeros);
* non-contacting asperities, in the gap g = d - z: panels graded from the Lennard-Jones scale eps*,
  or, for separations far above the summits, uniform panels in z.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from . import asperity

GAUSS_ORDER = 8
Z_CUTOFF = 37.5        # phi*(37.5) ~ 1e-306: no summit density beyond +-Z_CUTOFF sigma
DENSITY_LOG_FLOOR = -600.0
FAR_SEPARATION = Z_CUTOFF + 10.0   # beyond this d*, the LJ kernel is smooth over every summit
_GL_X, _GL_W = np.polynomial.legendre.leggauss(GAUSS_ORDER)
_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)


@dataclass(frozen=True)
class DimensionlessInputs:
    """The groups the dimensionless model depends on (docs/contact.md §1)."""

    beta: float            # eta R sigma
    omega_c: float         # omega_c / sigma = 1 / psi^2
    epsilon: float         # epsilon / sigma
    hardness_coeff: float  # K = 0.454 + 0.41 nu
    adhesion: float        # delta_gamma / (H sigma)
    adhesion_contact_scale: float
    friction_scale: float
    friction_law: str


@dataclass(frozen=True)
class SurfaceForces:
    """Dimensionless totals (÷ A_n H) at each separation: contact load P*, adhesion of the contacting
    and of the non-contacting asperities, and the maximum static friction Q_max*."""

    contact_load: np.ndarray
    adhesion_contact: np.ndarray
    adhesion_noncontact: np.ndarray
    q_max: np.ndarray

    @property
    def adhesion(self) -> np.ndarray:
        """Total adhesion F_s* (eq. 11)."""
        return self.adhesion_contact + self.adhesion_noncontact

    @property
    def applied_load(self) -> np.ndarray:
        """Applied load F* = P* - F_s* (eq. 12); positive presses the surfaces together."""
        return self.contact_load - self.adhesion


def summit_density(z: np.ndarray) -> np.ndarray:
    """phi*(z) = exp(-z^2/2)/sqrt(2 pi), the standard Gaussian density of summit heights.

    The exponent is floored at DENSITY_LOG_FLOOR (|z| > 34.6, phi < 1e-261): below it exp() returns
    subnormal numbers, and subnormal arithmetic made the table build five times slower.
    """
    return _INV_SQRT_2PI * np.exp(np.maximum(-0.5 * z * z, DENSITY_LOG_FLOOR))


def graded_breaks(start: float, stop: float, first_width: float, max_width: float,
                  growth: float = 1.6) -> np.ndarray:
    """Panel edges from ``start`` to ``stop``: widths grow geometrically from ``first_width`` up to
    ``max_width`` (the last panel is shortened to end at ``stop``)."""
    length = stop - start
    growing = first_width * growth ** np.arange(max(int(np.ceil(np.log(max_width / first_width) / np.log(growth))), 0))
    growing = growing[np.cumsum(growing) < length]
    remaining = length - growing.sum()
    uniform = np.full(int(np.ceil(remaining / max_width)), max_width)
    offsets = np.cumsum(np.concatenate([growing, uniform]))
    return np.concatenate([[start], np.minimum(start + offsets, stop)])


def gauss_nodes(edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nodes and weights of the composite Gauss–Legendre rule on the panels between ``edges``."""
    left, right = edges[:-1, None], edges[1:, None]
    half = 0.5 * (right - left)
    nodes = (left + half * (1.0 + _GL_X[None, :])).ravel()
    weights = (half * _GL_W[None, :]).ravel()
    return nodes, weights


def interference_nodes(w_max: float, omega_c: float, law: str) -> tuple[np.ndarray, np.ndarray]:
    """Nodes in w on [0, w_max], graded toward w = 0 (where w^1.5 and w^0.982 are not smooth) and
    broken at the kinks of the load, adhesion and friction laws. Panels span at most 1 sigma in z."""
    kinks = {asperity.W_ELASTIC_PLASTIC, asperity.W_PLASTIC_ZONE_AT_SURFACE, asperity.W_FULLY_PLASTIC,
             *asperity.friction_breakpoints(law)}
    stops = [*sorted(k for k in kinks if k < w_max), w_max]
    sigma_in_w = 1.0 / omega_c
    edges = [graded_breaks(0.0, stops[0], 1e-12 * stops[0], min(0.25 * stops[0], sigma_in_w), growth=2.0)]
    for a, b in itertools.pairwise(stops):
        edges.append(graded_breaks(a, b, min(0.25 * a, sigma_in_w), min(0.5 * b, sigma_in_w))[1:])
    return gauss_nodes(np.concatenate(edges))


def surface_forces(d: np.ndarray, inputs: DimensionlessInputs) -> SurfaceForces:
    """P*, F_s* (contacting, non-contacting) and Q_max* at the separations ``d`` (in sigma)."""
    d = np.atleast_1d(np.asarray(d, dtype=float))
    contact = _contacting_integrals(d, inputs)
    noncontact = np.empty_like(d)
    near = d <= FAR_SEPARATION
    noncontact[near] = _noncontacting_near(d[near], inputs.epsilon)
    noncontact[~near] = _noncontacting_far(d[~near], inputs.epsilon)
    load_prefactor = (2.0 / 3.0) * math.pi * inputs.hardness_coeff * inputs.beta * inputs.omega_c
    adhesion_prefactor = 2.0 * math.pi * inputs.beta * inputs.adhesion
    return SurfaceForces(
        contact_load=load_prefactor * contact[0],
        adhesion_contact=adhesion_prefactor * contact[1],
        adhesion_noncontact=adhesion_prefactor * noncontact,
        q_max=inputs.friction_scale * load_prefactor * contact[2],
    )


def _contacting_integrals(d: np.ndarray, inputs: DimensionlessInputs) -> np.ndarray:
    """Rows: int p(w) phi dz*, int f_c(w) phi dz*, int q(w) phi dz* over the contacting summits."""
    out = np.zeros((3, d.size))
    reach = d < Z_CUTOFF
    if not reach.any():
        return out
    w_max = (Z_CUTOFF - d[reach].min()) / inputs.omega_c
    w, weights = interference_nodes(w_max, inputs.omega_c, inputs.friction_law)
    laws = np.stack([
        asperity.contact_load_ratio(w, inputs.hardness_coeff),
        asperity.contacting_adhesion_ratio(w, inputs.omega_c / inputs.epsilon, inputs.adhesion_contact_scale),
        asperity.sliding_inception_ratio(w, inputs.friction_law),
    ]) * (weights * inputs.omega_c)
    density = summit_density(d[reach, None] + inputs.omega_c * w[None, :])
    out[:, reach] = laws @ density.T
    return out


def _noncontacting_near(d: np.ndarray, epsilon: float) -> np.ndarray:
    """int_{-inf}^{d} J_nc dz* / (phi-weighted), by nodes in the gap g = d - z graded from eps*.
    Zero for d* <= -Z_CUTOFF: every summit is then in contact."""
    if d.size == 0 or d.max() <= -Z_CUTOFF:
        return np.zeros_like(d)
    g_max = d.max() + Z_CUTOFF
    gap, weights = gauss_nodes(graded_breaks(0.0, g_max, 0.25 * epsilon, 1.0))
    kernel = asperity.noncontacting_adhesion_ratio(gap / epsilon) * weights
    return summit_density(d[:, None] - gap[None, :]) @ kernel


def _noncontacting_far(d: np.ndarray, epsilon: float) -> np.ndarray:
    """The same integral for d* > FAR_SEPARATION, where the kernel is smooth: nodes in z."""
    if d.size == 0:
        return d.copy()
    z, weights = gauss_nodes(np.linspace(-Z_CUTOFF, Z_CUTOFF, 76))
    density = summit_density(z) * weights
    return asperity.noncontacting_adhesion_ratio((d[:, None] - z[None, :]) / epsilon) @ density
