"""surface.cutoff: far actuators are skipped within the documented bound (docs/dynamics.md, "Far actuators")."""

import math

import numpy as np
import pytest

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.parameters import ParameterError
from micro_feeder.physics.surface import SurfaceParams, surface_at

N = 50


def full_sum(x, s, sd, sdd, centers, widths):
    """(h, h_x, h_xx, h_t, h_tt, h_xt) as the plain numpy sum over every actuator."""
    u = (x - centers) / widths
    g = np.exp(-0.5 * u * u)
    g1 = -u / widths * g
    g2 = (u * u - 1.0) / widths**2 * g
    return np.array([s @ g, s @ g1, s @ g2, sd @ g, sdd @ g, sd @ g1])


def bound(x, s, sd, sdd, centers, widths, cutoff):
    """The documented bound on each output's error, summed over the skipped actuators."""
    u_c = math.sqrt(2.0 * math.log(1.0 / cutoff))
    far = np.abs((x - centers) / widths) > u_c
    w = widths[far]
    one = u_c / w * cutoff
    two = (u_c * u_c - 1.0) / w**2 * cutoff
    return np.array([cutoff * np.abs(s[far]).sum(), one @ np.abs(s[far]), two @ np.abs(s[far]),
                     cutoff * np.abs(sd[far]).sum(), cutoff * np.abs(sdd[far]).sum(), one @ np.abs(sd[far])])


@pytest.mark.parametrize('cutoff', [1e-12, 1e-6, 1e-3])
def test_cutoff_within_bound(cutoff):
    rng = np.random.default_rng(10)
    centers = np.sort(rng.uniform(-5e-3, 5e-3, N))
    widths = rng.uniform(0.1e-3, 0.6e-3, N)
    u_c = SurfaceParams(centers=tuple(centers), widths=tuple(widths), cutoff=cutoff).cutoff_radius
    assert u_c == pytest.approx(math.sqrt(2.0 * math.log(1.0 / cutoff)))
    skipped = 0
    for _ in range(200):
        x = rng.uniform(-6e-3, 6e-3)
        s, sd, sdd = rng.normal(0, 1e-4, N), rng.normal(0, 1.0, N), rng.normal(0, 1e4, N)
        got = np.array(surface_at(x, s, sd, sdd, centers, widths, u_c))
        exact = full_sum(x, s, sd, sdd, centers, widths)
        scale = np.abs(full_sum(x, np.abs(s), np.abs(sd), np.abs(sdd), centers, widths))
        err = np.abs(got - exact)
        allowance = 1e-13 * scale                   # rounding of the sums themselves
        assert np.all(err <= bound(x, s, sd, sdd, centers, widths, cutoff) + allowance), (x, err)
        skipped += np.count_nonzero(np.abs((x - centers) / widths) > u_c)
    assert skipped > 0
    full = np.array(surface_at(0.1e-3, s, sd, sdd, centers, widths, math.inf))
    np.testing.assert_allclose(full, full_sum(0.1e-3, s, sd, sdd, centers, widths), rtol=1e-12, atol=0)


@pytest.mark.parametrize('cutoff', [-1e-12, 2e-3, math.nan])
def test_invalid_cutoff_refused(cutoff):
    with pytest.raises(ParameterError, match='surface.cutoff'):
        SurfaceParams(cutoff=cutoff)


def travelling_wave(n, cutoff, frequency=1000.0):
    """A travelling wave on n actuators 0.5 mm apart (config/travelling_wave.yaml, widened)."""
    return FeederModel.from_settings({
        'particle.x0': 1.0e-3, 'surface.centers': [0.5e-3 * k - 5e-3 for k in range(n)],
        'surface.widths': [0.4e-3] * n, 'stroke.amplitude': 150e-6, 'stroke.frequency': frequency,
        'stroke.phases': [(0.2 * k) % 1.0 for k in range(n)], 'stroke.count': 20, 'surface.cutoff': cutoff})


@pytest.mark.parametrize('frequency', [1000.0, 3000.0])
def test_travelling_wave_same_with_cutoff(frequency):
    """32 actuators, 20 strokes: the same distance and transitions with cutoff 1e-12 as exact, in contact
    (1 kHz) and with flights (3 kHz: in flight the strokes of actuators one width beyond the cutoff radius
    are evaluated too, because the closest surface point is not under the part)."""
    results = []
    for cutoff in (0.0, 1e-12):
        model = travelling_wave(32, cutoff, frequency)
        state = model.initial_state()
        model.run(state=state)
        results.append((state.distance, state.transitions))
    (exact, exact_counts), (cut, cut_counts) = results
    assert abs(exact - cut) <= 1e-9
    assert exact_counts == cut_counts
    assert sum(exact_counts.values()) > 0 and abs(exact) > 1e-7
    assert (exact_counts['take_off'] > 0) == (frequency > 2000.0)
