"""surface.cutoff: far actuators are skipped within the documented bound (docs/dynamics.md, "Far actuators")."""

import math

import numpy as np
import pytest

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.dynamics import kernel as k
from micro_feeder.physics.dynamics.layout import AUX_FELT_HI, AUX_FELT_LO, N_AUX
from micro_feeder.physics.dynamics.rhs import FLIGHT_REACH, strokes_at, surface_here
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
        got = np.array(surface_at(x, s, sd, sdd, centers, widths, u_c, 0, N))
        exact = full_sum(x, s, sd, sdd, centers, widths)
        scale = np.abs(full_sum(x, np.abs(s), np.abs(sd), np.abs(sdd), centers, widths))
        err = np.abs(got - exact)
        allowance = 1e-13 * scale                   # rounding of the sums themselves
        assert np.all(err <= bound(x, s, sd, sdd, centers, widths, cutoff) + allowance), (x, err)
        skipped += np.count_nonzero(np.abs((x - centers) / widths) > u_c)
    assert skipped > 0
    full = np.array(surface_at(0.1e-3, s, sd, sdd, centers, widths, math.inf, 0, N))
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


@pytest.mark.parametrize('reach', [0.0, FLIGHT_REACH, math.inf])
def test_strokes_fill_every_actuator_felt_and_only_a_range_near_the_part(reach):
    """strokes_at bisects the sorted centres: 60 actuators of widths 0.1-1 mm spread over 8 cm. Every
    actuator within (u_c + reach) of its widths of x gets its stroke, the surface summed over that range
    equals the sum with every stroke filled (the columns left out hold NaN here), and the range leaves
    out most of the row."""
    rng = np.random.default_rng(7)
    n = 60
    centers, widths = np.sort(rng.uniform(-40e-3, 40e-3, n)), rng.uniform(1e-4, 1e-3, n)
    model = FeederModel.from_settings({
        'surface.centers': centers.tolist(), 'surface.widths': widths.tolist(), 'stroke.count': 5,
        'stroke.phases': rng.uniform(0.0, 1.0, n).tolist(), 'stroke.waveform': 'sine'})
    packed, src = model._kernel_model, model._source_table(None).as_tuple()
    u_c = model.surface.cutoff_radius
    cur = np.zeros((n, 2), dtype=np.int64)
    for x in rng.uniform(-45e-3, 45e-3, 40):
        t = rng.uniform(0.0, 4e-3)
        k.locate_all(src, t, cur)
        y = np.array([x, 0.0, 0.0, 0.0])
        everything, aux_all = np.zeros((4, n)), np.zeros(N_AUX)
        strokes_at(t, y, packed, src, cur, everything, aux_all, math.inf)
        st, aux = np.full((4, n), np.nan), np.zeros(N_AUX)
        strokes_at(t, y, packed, src, cur, st, aux, reach)
        lo, hi = int(aux[AUX_FELT_LO]), int(aux[AUX_FELT_HI])
        felt = np.flatnonzero(np.abs(x - centers) <= (u_c + reach) * widths)
        assert np.all((lo <= felt) & (felt < hi)), (x, lo, hi, felt)
        np.testing.assert_array_equal(st[:, felt], everything[:, felt])
        assert surface_here(x, st, packed, aux) == surface_here(x, everything, packed, aux_all)
        if reach < math.inf:
            assert hi - lo < n / 3
