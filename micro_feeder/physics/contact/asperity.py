"""Single-asperity laws of the Kogut–Etsion model, as functions of the dimensionless interference.

``w = omega / omega_c`` is the interference over the critical (yield-inception) interference.
The laws are stated in docs/contact.md §2.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

# KE02 piece boundaries in w: elastic | elastic-plastic I | elastic-plastic II | fully plastic.
W_ELASTIC_PLASTIC = 1.0
W_PLASTIC_ZONE_AT_SURFACE = 6.0
W_FULLY_PLASTIC = 110.0

# The 'ke' friction law's elastic-plastic cubic, q = w^1.425 * (c3 w^3 + c2 w^2 + c1 w + c0) (§7).
_KE_CUBIC = (-0.01, 0.09, -0.40, 0.85)


def hardness_coefficient(poisson: float) -> float:
    """K = 0.454 + 0.41 nu, the maximum contact pressure at yield inception over the hardness (CEB87)."""
    return 0.454 + 0.41 * poisson


def contact_load_ratio(w: np.ndarray, hardness_coeff: float) -> np.ndarray:
    """P / P_c of one asperity at interference ratio w >= 0 (KE02, eq. 1)."""
    w = np.maximum(np.asarray(w, dtype=float), 0.0)
    return np.select(
        [w <= W_ELASTIC_PLASTIC, w <= W_PLASTIC_ZONE_AT_SURFACE, w <= W_FULLY_PLASTIC],
        [w ** 1.5, 1.03 * w ** 1.425, 1.40 * w ** 1.263],
        default=(3.0 / hardness_coeff) * w)


@lru_cache(maxsize=1)
def ke_limiting_interference() -> float:
    """w_lim: the preload above which the 'ke' law's asperity carries no tangential load (= 4.295)."""
    c3, c2, c1, c0 = _KE_CUBIC
    return brentq(lambda w: ((c3 * w + c2) * w + c1) * w + c0, 1.0, W_PLASTIC_ZONE_AT_SURFACE, xtol=1e-15)


def friction_breakpoints(law: str) -> tuple[float, ...]:
    """Interference ratios where the friction law ``law`` has a kink (integration break points)."""
    if law == 'ke':
        return (W_ELASTIC_PLASTIC, ke_limiting_interference())
    if law == 'elastic_only':
        return (W_ELASTIC_PLASTIC,)
    if law == 'linear_to_6':
        return (W_ELASTIC_PLASTIC, W_PLASTIC_ZONE_AT_SURFACE)
    raise ValueError(f'unknown friction law {law!r}')


def sliding_inception_ratio(w: np.ndarray, law: str) -> np.ndarray:
    """q = Q_max / L_c of one asperity at interference ratio w (KE03S; docs/contact.md §2).

    ``ke``: 0.52 w^0.982 (elastic), then the cubic guess down to zero at w_lim = 4.295.
    ``elastic_only``: zero beyond w = 1 (CEB88b). ``linear_to_6``: linear from 0.52 at w = 1 to 0 at w = 6.
    """
    w = np.maximum(np.asarray(w, dtype=float), 0.0)
    elastic = 0.52 * w ** 0.982
    if law == 'ke':
        c3, c2, c1, c0 = _KE_CUBIC
        plastic = w ** 1.425 * (((c3 * w + c2) * w + c1) * w + c0)
        plastic = np.where(w <= ke_limiting_interference(), plastic, 0.0)
    elif law == 'elastic_only':
        plastic = np.zeros_like(w)
    elif law == 'linear_to_6':
        plastic = np.clip(0.52 * (W_PLASTIC_ZONE_AT_SURFACE - w) / (W_PLASTIC_ZONE_AT_SURFACE - 1.0), 0.0, None)
    else:
        raise ValueError(f'unknown friction law {law!r}')
    return np.where(w <= 0.0, 0.0, np.where(w <= W_ELASTIC_PLASTIC, elastic, plastic))


def _hertz_gap_shape(t: np.ndarray) -> np.ndarray:
    """g of eq. 10 in the variable t = sqrt(rho^2 - 1): t - (1 - t^2) atan(t); ~ (4/3) t^3 for small t."""
    series = (4.0 / 3.0) * t ** 3 - (8.0 / 15.0) * t ** 5
    return np.where(t < 1e-3, series, t - (1.0 - t * t) * np.arctan(t))


def hertz_dmt_adhesion_direct(s: np.ndarray) -> np.ndarray:
    """f(s) = F_c / (2 pi dgamma R) of an elastic (Hertz) asperity with the LJ pressure outside
    the contact circle (docs/contact.md §2), s = omega / epsilon.

    Evaluated by the trapezoid rule in u = ln t, which converges exponentially for this smooth integrand
    decaying at both ends; the node range follows the integrand's scale t_c(s).
    """
    s = np.atleast_1d(np.asarray(s, dtype=float))
    out = np.ones_like(s)
    positive = s > 0
    sp = s[positive][:, None]
    t_scale = np.minimum(np.sqrt(2.0 / sp), np.cbrt(3.0 * np.pi / (4.0 * sp)))
    u = np.linspace(-16.0, 12.0, 561)[None, :]
    du = u[0, 1] - u[0, 0]
    t = t_scale * np.exp(u)
    x = 1.0 + (sp / np.pi) * _hertz_gap_shape(t)
    integrand = (x ** -3 - x ** -9) * t * t  # (...) * t dt with dt = t du
    out[positive] = (8.0 / 3.0) * s[positive] * integrand.sum(axis=1) * du
    return out


@lru_cache(maxsize=1)
def _hertz_dmt_spline() -> tuple[CubicSpline, float, float]:
    log_s = np.linspace(np.log(1e-9), np.log(1e9), 361)
    return CubicSpline(log_s, hertz_dmt_adhesion_direct(np.exp(log_s))), log_s[0], log_s[-1]


def hertz_dmt_adhesion(s: np.ndarray) -> np.ndarray:
    """f(s) of eq. 10 from a cached spline in ln s (relative error < 1e-8 for 1e-9 <= s <= 1e9)."""
    s = np.asarray(s, dtype=float)
    spline, lo, hi = _hertz_dmt_spline()
    log_s = np.log(np.clip(s, np.exp(lo), np.exp(hi)))
    return np.where(s <= np.exp(lo), 1.0, spline(log_s))


def contacting_adhesion_ratio(w: np.ndarray, omega_c_over_eps: float, scale: float) -> np.ndarray:
    """F_c / (2 pi dgamma R) of a contacting asperity: ``scale`` x eq. 10 for w <= 110, ``scale`` x 1
    (the flattened, fully plastic sphere) beyond (docs/contact.md §2, 'hertz_dmt')."""
    w = np.asarray(w, dtype=float)
    elastic = hertz_dmt_adhesion(np.maximum(w, 0.0) * omega_c_over_eps)
    return scale * np.where(w <= W_FULLY_PLASTIC, elastic, 1.0)


def noncontacting_adhesion_ratio(gap_over_eps: np.ndarray) -> np.ndarray:
    """F_nc / (2 pi dgamma R) of a rigid sphere at summit gap g = d - z from the flat (eq. 8, 9):
    (4/3) [(eps/xi)^2 - (1/4)(eps/xi)^8] with xi = g + eps (the Bradley force 1 at g = 0)."""
    r = 1.0 / (1.0 + np.asarray(gap_over_eps, dtype=float))
    r2 = r * r
    return (4.0 / 3.0) * (r2 - 0.25 * r2 ** 4)
