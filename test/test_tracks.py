"""A rigid vibratory track with Coulomb contact, against the closed forms of conveying theory (issue 27;
docs/tracks.md), each through the paths users take: ``micro-feeder simulate`` and ``micro-feeder sweep``.

* Boothroyd's slip thresholds, forward Aω²/g = (μ cos α + sin α)/(cos β + μ sin β) and backward
  (μ cos α − sin α)/(cos β − μ sin β), and the flight threshold Γ = 1: no slip (no take-off) at
  1 − 1e-4 of the threshold amplitude, a slip (a take-off) in the predicted direction at 1 + 1e-4.
* Hopping with plastic, sticking landings on a horizontal track: the mean velocity over whole periods
  against the exact closed form (take-off at sin θ_t = 1/Γ, landing at the first root φ_l of
  sin θ_t + cos θ_t (φ − θ_t) − (φ − θ_t)²/(2Γ) − sin φ = 0, v̄/(Aω cos β) = [cos θ_t (φ_l − θ_t) − sin φ_l
  + sin θ_t]/(2π)), the root found here by bracketing and bisection (scipy), independent of the simulator.
"""

from __future__ import annotations

import contextlib
import io
import json
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from micro_feeder.cli import main

G = 9.81
FREQUENCY = 100.0                         # Hz
OMEGA = 2.0 * math.pi * FREQUENCY
THRESHOLD_MARGIN = 1e-4                   # relative: the thresholds are found to this


def _track(alpha: float, beta: float, mu: float, amplitude: float, count: int, landing: str = 'keep') -> list[str]:
    settings = {'surface.kind': 'track', 'track.inclination': alpha, 'track.vibration_angle': beta,
                'contact.model': 'coulomb', 'contact.mu': mu, 'landing.law': landing, 'stroke.waveform': 'sine',
                'stroke.frequency': FREQUENCY, 'stroke.amplitude': amplitude, 'stroke.count': count}
    return [arg for name, value in settings.items() for arg in ('--set', f'{name}={value!r}')]


def _cli_json(*args: str) -> dict:
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(list(args)) == 0
    return json.loads(out.getvalue())


def _simulate(settings: list[str], duration: float) -> dict:
    return _cli_json('simulate', *settings, '--duration', repr(duration), '--json', '--out', '/tmp')


def _sweep(settings: list[str], name: str, values: list[float], duration: float) -> list[dict]:
    result = _cli_json('sweep', *settings, '--vary', f'{name}=' + ','.join(map(repr, values)), '--duration',
                       repr(duration), '--json', '--processes', '1', '--out', '/tmp/test_tracks_sweep')
    return sorted(result['rows'], key=lambda row: row[name])


# (α, β, μ, which threshold comes first): forward on a level or downhill track, backward on steeper ones
SLIP_CASES = [(0.0, math.pi / 6, 0.5, 'forward'), (-0.1, 0.4, 0.3, 'forward'), (0.1, 0.4, 0.3, 'backward'),
              (0.3, math.pi / 6, 0.5, 'backward')]


def _slip_threshold(alpha: float, beta: float, mu: float, which: str) -> float:
    """Aω² at which the part first slips (Boothroyd)."""
    sign = 1.0 if which == 'forward' else -1.0
    return G * (mu * math.cos(alpha) + sign * math.sin(alpha)) / (math.cos(beta) + sign * mu * math.sin(beta))


@pytest.mark.parametrize('alpha, beta, mu, which', SLIP_CASES)
def test_slip_thresholds_are_boothroyds(alpha: float, beta: float, mu: float, which: str) -> None:
    threshold = _slip_threshold(alpha, beta, mu, which) / OMEGA ** 2
    other = 'backward' if which == 'forward' else 'forward'
    assert _slip_threshold(alpha, beta, mu, other) > _slip_threshold(alpha, beta, mu, which)
    below, above = threshold * (1 - THRESHOLD_MARGIN), threshold * (1 + THRESHOLD_MARGIN)
    duration = 2.0 / FREQUENCY
    for summary in (_simulate(_track(alpha, beta, mu, below, 2), duration),):
        assert summary['transitions']['stick_to_slip'] == 0, summary
    moved = _simulate(_track(alpha, beta, mu, above, 2), duration)
    assert moved['transitions']['stick_to_slip'] > 0, moved
    assert moved['distance_m'] * (1 if which == 'forward' else -1) > 0, moved
    rows = _sweep(_track(alpha, beta, mu, threshold, 2), 'stroke.amplitude', [below, above], duration)
    assert [row['stick_to_slip'] > 0 for row in rows] == [False, True], rows


def test_flight_threshold_is_a_throw_number_of_one() -> None:
    beta, mu = 0.5, 0.4
    threshold = G / (OMEGA ** 2 * math.sin(beta))
    below, above = threshold * (1 - THRESHOLD_MARGIN), threshold * (1 + THRESHOLD_MARGIN)
    duration = 2.0 / FREQUENCY
    calm, thrown = (_simulate(_track(0.0, beta, mu, a, 2), duration) for a in (below, above))
    assert calm['transitions']['take_off'] == 0 and thrown['transitions']['take_off'] > 0
    assert thrown['throw_number'] == pytest.approx(1 + THRESHOLD_MARGIN, rel=1e-12)
    rows = _sweep(_track(0.0, beta, mu, threshold, 2), 'stroke.amplitude', [below, above], duration)
    assert [row['take_off'] > 0 for row in rows] == [False, True], rows
    assert [row['regime'] for row in rows] == ['slides', 'flies']


def hopping_velocity_ratio(gamma: float) -> float:
    """v̄/(Aω cos β) of hopping with plastic, sticking landings on a horizontal track (exact)."""
    theta = math.asin(1.0 / gamma)

    def gap(phi: float) -> float:     # the part's height above the track, over A sin β, after take-off at θ
        return math.sin(theta) + math.cos(theta) * (phi - theta) - (phi - theta) ** 2 / (2 * gamma) - math.sin(phi)

    # the first root after θ: gap > 0 just after take-off; step out until it turns negative, then bisect
    step, phi = 1e-3, theta + 1e-3
    while gap(phi + step) > 0.0:
        phi += step
    landing = brentq(gap, phi, phi + step, xtol=1e-15, rtol=1e-15)
    return (math.cos(theta) * (landing - theta) - math.sin(landing) + math.sin(theta)) / (2 * math.pi)


def test_the_closed_form_itself_at_the_period_doubling_threshold() -> None:
    gamma = math.sqrt(1 + math.pi ** 2)
    assert hopping_velocity_ratio(gamma * (1 - 1e-12)) == pytest.approx(math.pi / gamma, rel=1e-6)


@pytest.mark.parametrize('gamma', [1.2, 1.5, 2.0, 3.0])
def test_hopping_with_sticking_landings_conveys_at_the_closed_form(gamma: float) -> None:
    beta, mu, count = math.pi / 6, 1e4, 12
    amplitude = gamma * G / (OMEGA ** 2 * math.sin(beta))
    expected = hopping_velocity_ratio(gamma) * amplitude * OMEGA * math.cos(beta)
    summary = _simulate(_track(0.0, beta, mu, amplitude, count, landing='stick'), count / FREQUENCY)
    assert summary['throw_number'] == pytest.approx(gamma, rel=1e-12)
    assert summary['mean_velocity_mps'] == pytest.approx(expected, rel=1e-3), (summary, expected)
    rows = _sweep(_track(0.0, beta, mu, amplitude, count, landing='stick'), 'stroke.amplitude', [amplitude],
                  count / FREQUENCY)
    assert rows[0]['mean_velocity_mps'] == pytest.approx(expected, rel=1e-3)


def test_at_the_period_doubling_threshold_the_part_conveys_at_pi_over_its_gamma() -> None:
    """Γ = √(1+π²): the hop lasts one whole period and v̄/(Aω cos β) = π/√(1+π²)."""
    beta, gamma, count = math.pi / 6, math.sqrt(1 + math.pi ** 2) * (1 - 1e-9), 12
    amplitude = gamma * G / (OMEGA ** 2 * math.sin(beta))
    summary = _simulate(_track(0.0, beta, 1e4, amplitude, count, landing='stick'), count / FREQUENCY)
    ratio = summary['mean_velocity_mps'] / (amplitude * OMEGA * math.cos(beta))
    assert ratio == pytest.approx(math.pi / math.sqrt(1 + math.pi ** 2), rel=1e-6)


def test_the_landing_law_sets_the_conveying_speed_of_a_hopping_part() -> None:
    """Γ = 1.5, μ = 0.5 (FEEDER_THEORY's example): a landing that sticks, one with a Coulomb impulse and one
    that keeps the tangential velocity convey at 0.32, 0.60 and 0.81 of Aω cos β."""
    beta, gamma, count = math.pi / 6, 1.5, 120
    amplitude = gamma * G / (OMEGA ** 2 * math.sin(beta))
    scale = amplitude * OMEGA * math.cos(beta)
    ratios = {law: _simulate(_track(0.0, beta, 0.5, amplitude, count, law), count / FREQUENCY)['mean_velocity_mps']
              / scale for law in ('stick', 'coulomb', 'keep')}
    swept = _sweep(_track(0.0, beta, 0.5, amplitude, count, 'coulomb'), 'contact.mu', [0.5], count / FREQUENCY)
    assert swept[0]['mean_velocity_mps'] / scale == ratios['coulomb']
    assert ratios == pytest.approx({'stick': 0.32, 'coulomb': 0.60, 'keep': 0.81}, abs=0.005), ratios


@pytest.mark.parametrize('regime, gamma, mu', [('slides', 0.45, 0.3), ('flies', 1.5, 0.5)])
def test_the_mean_velocity_converges_with_the_tolerance(regime: str, gamma: float, mu: float) -> None:
    """Dividing integration.tolerance by 100 changes the mean velocity by less than 1e-4 relative."""
    beta, count = math.pi / 6, 20
    amplitude = gamma * G / (OMEGA ** 2 * math.sin(beta))
    settings = _track(0.0, beta, mu, amplitude, count)
    coarse, fine = (_simulate([*settings, '--set', f'integration.tolerance={tol!r}'], count / FREQUENCY)
                    for tol in (1e-10, 1e-12))
    assert coarse['mean_velocity_mps'] != 0.0
    assert fine['mean_velocity_mps'] == pytest.approx(coarse['mean_velocity_mps'], rel=1e-4)
    assert coarse['transitions']['take_off'] > 0 if regime == 'flies' else coarse['transitions']['take_off'] == 0


def test_a_bouncing_part_lands_at_the_free_fall_times_and_its_chatter_ends() -> None:
    """landing.restitution e: dropped from h0 on a still track, the part lands at t_1 = sqrt(2 h0 / g) and
    then after flights of 2 e^k v_1 / g (each impact within the event tolerance of its time, accumulating);
    a bounce whose flight would last less than 1000 event tolerances is plastic, so the chatter ends, in
    contact, before t_1 + 2 e v_1 / (g (1 − e))."""
    from micro_feeder.physics.dynamics import FeederModel

    e, h0 = 0.6, 1e-4
    model = FeederModel.from_settings({'surface.kind': 'track', 'contact.model': 'coulomb', 'stroke.amplitude': 0.0,
                                       'landing.restitution': e, 'particle.x0': 0.0})
    state = model.flying_state(0.0, h0, 0.0, 0.0)
    events = model.advance(state, 0.05)
    landings = [ev.t for ev in events if ev.kind == 'landing']
    g = G * math.cos(0.0)
    t1 = math.sqrt(2 * h0 / g)
    v1 = g * t1
    expected = [t1]
    while 2 * e ** len(expected) * v1 / g >= 1000 * model.integration.event_tolerance:
        expected.append(expected[-1] + 2 * e ** len(expected) * v1 / g)
    assert len(landings) == len(expected), (len(landings), len(expected))
    # each impact is located within the event tolerance (1e-9 s) and the next flight starts from there
    errors = [abs(got - want) for got, want in zip(landings, expected, strict=True)]
    assert all(err <= 2e-9 * (k + 1) for k, err in enumerate(errors)), errors
    assert state.mode == 'stuck' and landings[-1] < t1 + 2 * e * v1 / (g * (1 - e))
    counts = state.transitions
    assert counts['landing'] == len(expected) and counts['take_off'] == len(expected) - 1   # the bounces


def _two_way(u: float, z: float, phi: float, mu: float, count: int) -> list[str]:
    """A two-way drive: the track moves along itself at velocity U cos ωt (x_p = (U/ω) sin ωt) and normal to
    itself as Z cos(ωt − φ), Coulomb friction μ."""
    along = u / OMEGA
    beta = math.atan2(z, along)
    amplitude = math.hypot(along, z)                    # x_p = A cos β sin ωt, z_p = A sin β sin(ωt − 2π p)
    phase = ((phi - math.pi / 2) / (2 * math.pi)) % 1.0  # sin(ωt − 2π p) = cos(ωt − φ)
    settings = {'surface.kind': 'track', 'track.drive': 'two_way', 'track.vibration_angle': beta,
                'surface.centers': [0.0, 0.0], 'surface.widths': [1e-3, 1e-3], 'stroke.phases': [0.0, phase],
                'contact.model': 'coulomb', 'contact.mu': mu, 'stroke.waveform': 'sine',
                'stroke.frequency': FREQUENCY, 'stroke.amplitude': amplitude, 'stroke.count': count}
    return [arg for name, value in settings.items() for arg in ('--set', f'{name}={value!r}')]


def coulomb_pump_velocity(u: float, z: float, phi: float) -> float:
    """Fast-vibration limit of the Coulomb pump: v̄ = −U sin δ with δ = ε cos δ, ε = (Zω²/g) cos φ."""
    eps = z * OMEGA ** 2 / G * math.cos(phi)
    delta = brentq(lambda d: d - eps * math.cos(d), -math.pi / 2, math.pi / 2, xtol=1e-15)
    return -u * math.sin(delta)


@pytest.mark.parametrize('phi', [0.0, math.pi / 3, 2.0])
def test_a_two_way_drive_pumps_as_coulomb_and_reverses_with_the_phase(phi: float) -> None:
    """Reznik & Canny's Coulomb pump: a part always sliding (track acceleration ≫ μg), never flying
    (Zω² < g), conveys at the fast-vibration limit within O(μg/(Uω)) of U, backward at φ = 0; shifting the
    normal motion by half a period mirrors the motion, so v̄(φ + π) = −v̄(φ)."""
    u, z, mu, count = 0.2, 0.5 * G / OMEGA ** 2, 0.2, 400     # relaxation πU/(2μg) = 0.16 s, 40 periods
    forward = _simulate(_two_way(u, z, phi, mu, count), count / FREQUENCY)
    reverse = _simulate(_two_way(u, z, phi + math.pi, mu, count), count / FREQUENCY)
    assert forward['transitions']['take_off'] == 0 and reverse['transitions']['take_off'] == 0
    v = forward['mean_velocity_mps']
    assert reverse['mean_velocity_mps'] == pytest.approx(-v, rel=1e-4)
    assert v == pytest.approx(coulomb_pump_velocity(u, z, phi), abs=3 * mu * G / OMEGA)


def _harmonic_drive(harmonics: list[int], amplitudes: list[float], phases: list[float], mu: float,
                    amplitude: float, count: int) -> list[str]:
    """A level track moved along itself only (β = 0: the normal load stays m g) by a sum of harmonics."""
    settings = {'surface.kind': 'track', 'track.vibration_angle': 0.0, 'contact.model': 'coulomb',
                'contact.mu': mu, 'stroke.waveform': 'harmonics', 'stroke.harmonics': harmonics,
                'stroke.harmonic_amplitudes': amplitudes, 'stroke.harmonic_phases': phases,
                'stroke.frequency': FREQUENCY, 'stroke.amplitude': amplitude, 'stroke.count': count}
    return [arg for name, value in settings.items() for arg in ('--set', f'{name}={value!r}')]


def test_the_harmonics_stroke_is_its_closed_form() -> None:
    """s = A Σ a_h [sin(2π n_h f τ + φ_h) − sin φ_h] and its two derivatives, from the stroke table the
    kernel integrates, against the formula evaluated here (numpy), over a 3-stroke burst with a pause."""
    from micro_feeder.physics.trajectory import sample_table
    from micro_feeder.physics.waveforms import StrokeParams, waveform_table

    n, a, phi = (1, 2, 5), (1.0, 0.4, 0.15), (0.3, -1.2, 2.0)
    params = StrokeParams(waveform='harmonics', amplitude=50e-6, frequency=237.5, count=3, pause=1e-3,
                          delay=2e-4, harmonics=n, harmonic_amplitudes=a, harmonic_phases=phi)
    t = np.linspace(0.0, params.burst_end_s() + 1e-3, 4001)
    got = sample_table(waveform_table(params, 1), t)[:, :, 0]
    tau = (t - params.delay) % params.period_s
    running = (t >= params.delay) & (t < params.burst_end_s()) & (tau < 1.0 / params.frequency)
    w = 2.0 * np.pi * params.frequency * np.asarray(n, dtype=float)[:, None]
    arg = w * tau + np.asarray(phi)[:, None]
    amp = params.amplitude * np.asarray(a)[:, None]
    want = [np.sum(amp * (np.sin(arg) - np.sin(np.asarray(phi))[:, None]), axis=0),
            np.sum(amp * w * np.cos(arg), axis=0), np.sum(-amp * w ** 2 * np.sin(arg), axis=0)]
    for derivative, scale in enumerate((params.amplitude, params.amplitude * w.max(), params.amplitude * w.max() ** 2)):
        assert np.max(np.abs(got[derivative] - np.where(running, want[derivative], 0.0))) < 1e-12 * scale


@pytest.mark.parametrize('phi', [0.0, 1.0])
def test_a_reversed_phase_between_two_harmonics_reverses_the_conveying(phi: float) -> None:
    """Track motion s = A[sin ωt + a sin(2ωt + φ)] along itself, Coulomb friction, constant normal load:
    s_{φ+π}(t) = −s_φ(t + T/2) (+ a constant), the mirror image of the same motion half a period later, so
    the steady conveying velocity reverses: v̄(φ + π) = −v̄(φ) (to 1e-4; the transients differ)."""
    amplitude, mu, count = 0.4e-3, 0.3, 300          # Aω² = 16 g: the part slides, never sticks for long
    forward = _simulate(_harmonic_drive([1, 2], [1.0, 0.5], [0.0, phi], mu, amplitude, count), count / FREQUENCY)
    reverse = _simulate(_harmonic_drive([1, 2], [1.0, 0.5], [0.0, phi + math.pi], mu, amplitude, count),
                        count / FREQUENCY)
    v = forward['mean_velocity_mps']
    assert abs(v) > 1e-2 * amplitude * OMEGA               # it conveys
    # always sliding with μg ≪ Aω, the part's velocity barely varies and friction averages to 0 when the
    # track is faster than the part half of the time: v̄ → the median of the track's velocity
    theta = np.linspace(0.0, 2.0 * math.pi, 1_000_000, endpoint=False)
    median = amplitude * OMEGA * float(np.median(np.cos(theta) + np.cos(2.0 * theta + phi)))
    assert v == pytest.approx(median, abs=mu * G / OMEGA)   # approached as O(μg/ω): 0 and 0.18 μg/ω off
    assert reverse['mean_velocity_mps'] == pytest.approx(-v, rel=1e-4)


def test_a_one_to_three_harmonic_drive_with_constant_normal_load_conveys_nothing() -> None:
    """Odd harmonics only: s(t + T/2) = −s(t) (+ a constant), the motion is its own mirror image, so a part
    under a constant normal load conveys nothing once the start's transient has passed; through ``sweep``
    over the amplitude (sliding at each), against the 1:2 drive of the same amplitudes, which conveys."""
    mu, count = 0.3, 300
    amplitudes = [0.2e-3, 0.4e-3]
    odd = _sweep(_harmonic_drive([1, 3], [1.0, 0.5], [0.0, 0.7], mu, 1e-4, count), 'stroke.amplitude',
                 amplitudes, count / FREQUENCY)
    even = _sweep(_harmonic_drive([1, 2], [1.0, 0.5], [0.0, 0.7], mu, 1e-4, count), 'stroke.amplitude',
                  amplitudes, count / FREQUENCY)
    for row_odd, row_even in zip(odd, even, strict=True):
        scale = row_odd['stroke.amplitude'] * OMEGA
        assert row_odd['regime'] == 'slides'
        assert abs(row_odd['mean_velocity_mps']) < 1e-4 * scale
        assert abs(row_even['mean_velocity_mps']) > 1e-2 * scale
