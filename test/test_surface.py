"""The Gaussian surface: closed-form derivatives against finite differences, parameter checks."""

import math

import numpy as np
import pytest

from micro_feeder.physics.parameters import ParameterError
from micro_feeder.physics.surface import SurfaceParams, surface_at, surface_profile

CENTERS = np.array([0.0, 2e-3])
WIDTHS = np.array([1e-3, 0.6e-3])


def strokes(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two smooth test strokes with analytic derivatives (m, m/s, m/s²)."""
    w = 2 * np.pi * 700.0
    s = np.array([50e-6 * np.sin(w * t), 30e-6 * np.cos(1.3 * w * t)])
    sd = np.array([50e-6 * w * np.cos(w * t), -30e-6 * 1.3 * w * np.sin(1.3 * w * t)])
    sdd = np.array([-50e-6 * w * w * np.sin(w * t), -30e-6 * (1.3 * w) ** 2 * np.cos(1.3 * w * t)])
    return s, sd, sdd


def height(x: float, t: float) -> float:
    s, sd, sdd = strokes(t)
    return surface_at(x, s, sd, sdd, CENTERS, WIDTHS, math.inf, 0, CENTERS.size)[0]


@pytest.mark.parametrize('x', [-1.3e-3, 0.4e-3, 1.1e-3, 2.5e-3])
def test_derivatives_match_finite_differences(x):
    t = 3.1e-4
    h, hx, hxx, ht, htt, hxt = surface_at(x, *strokes(t), CENTERS, WIDTHS, math.inf, 0, CENTERS.size)
    dx, dt = 1e-7, 1e-8
    assert h == pytest.approx(height(x, t), rel=1e-15)
    assert hx == pytest.approx((height(x + dx, t) - height(x - dx, t)) / (2 * dx), rel=1e-6)
    assert hxx == pytest.approx((height(x + dx, t) - 2 * h + height(x - dx, t)) / dx ** 2, rel=1e-4)
    assert ht == pytest.approx((height(x, t + dt) - height(x, t - dt)) / (2 * dt), rel=1e-6)
    assert htt == pytest.approx((height(x, t + dt) - 2 * h + height(x, t - dt)) / dt ** 2, rel=1e-4)
    mixed = (height(x + dx, t + dt) - height(x + dx, t - dt) - height(x - dx, t + dt)
             + height(x - dx, t - dt)) / (4 * dx * dt)
    assert hxt == pytest.approx(mixed, rel=1e-4)


def test_profile_is_the_sum_of_gaussians():
    x = np.linspace(-3e-3, 5e-3, 17)
    s = np.array([1e-4, -2e-5])
    expected = sum(s[k] * np.exp(-(x - CENTERS[k]) ** 2 / (2 * WIDTHS[k] ** 2)) for k in range(2))
    np.testing.assert_allclose(surface_profile(x, s, CENTERS, WIDTHS), expected, rtol=1e-14)
    assert surface_profile(np.array([0.0]), s[:1], CENTERS[:1], WIDTHS[:1])[0] == pytest.approx(1e-4)


def test_widths_must_match_centers():
    with pytest.raises(ParameterError, match='surface.widths'):
        SurfaceParams(centers=(0.0, 1e-3), widths=(1e-3,))
    with pytest.raises(ParameterError, match='surface.widths'):
        SurfaceParams(widths=(-1e-3,))


def test_centers_must_increase_along_the_feeder():
    """The kernel finds the actuators near the part by bisecting the centres; equal centres are allowed."""
    with pytest.raises(ParameterError, match='surface.centers .*increasing order'):
        SurfaceParams(centers=(1e-3, 0.0), widths=(1e-3, 1e-3))
    assert SurfaceParams(centers=(0.0, 0.0, 1e-3), widths=(1e-3,) * 3).n_actuators == 3
