"""Checks of the particle dynamics of docs/dynamics.md §1 (each can fail: closed forms, symmetry,
convergence, energy, independent numerics; nothing compares the code with its own stored output)."""

from dataclasses import dataclass

import numpy as np
import pytest

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.surface import surface_profile
from micro_feeder.physics.waveforms import trajectory_table


@dataclass(frozen=True)
class Tables:
    load_n: np.ndarray
    q_max_n: np.ndarray
    separation_m: np.ndarray
    gap_m: np.ndarray
    attraction_n: np.ndarray


@dataclass(frozen=True)
class FrictionlessContact:
    """Test variant of the contact model: no friction, no adhesion, no attraction in flight."""

    tables: Tables = Tables(np.array([-1.0, 1.0]), np.zeros(2), np.full(2, 75e-9), np.array([0.0, 1e-3]),
                            np.zeros(2))
    pull_off_n: float = 0.0


@pytest.fixture(scope='module')
def model() -> FeederModel:
    return FeederModel()


def table_mu(m: FeederModel) -> float:
    """Q_max(W)/m by linear interpolation in the contact tables (what the dynamics use; the tables
    match the contact model to ~1e-4)."""
    tables = m.contact_model.tables
    return float(np.interp(m.particle.weight_n, tables.load_n, tables.q_max_n)) / m.particle.mass


def flat(model: FeederModel, base=None, **integration) -> FeederModel:
    """Flat, horizontal surface (zero stroke), optionally shaken along x by ``base`` (test-only)."""
    return model.replace(stroke=model.stroke.replace(amplitude=0.0), base_acceleration=base,
                         integration=model.integration.replace(**integration))


def constant_base_acceleration(a0: float, duration: float):
    """Base channel with s̈ = a0 on [0, duration], 0 after (quintic Hermite of a parabola is exact)."""
    return trajectory_table([0.0, duration], [[0.0], [a0 * duration ** 2 / 2]], [[0.0], [a0 * duration]],
                            [[a0], [a0]])


def test_sliding_starts_when_m_a_reaches_q_max(model):
    """base acceleration ramp a = J t; sliding starts exactly at m a = Q_max(W) = 40 m/s² · m."""
    jerk, t_end = 4e4, 2e-3
    ramp = trajectory_table([0.0, t_end], [[0.0], [jerk * t_end ** 3 / 6]], [[0.0], [jerk * t_end ** 2 / 2]],
                            [[0.0], [jerk * t_end]])
    m = flat(model, ramp)
    state = m.initial_state()
    events = m.advance(state, 1.5e-3)
    assert [e.kind for e in events] == ['stick_to_slip']
    a_at_slip = jerk * events[0].t
    q_max = float(m.contact_model.q_max_at_load(m.particle.weight_n))
    assert a_at_slip == pytest.approx(table_mu(m), rel=1e-9)
    assert a_at_slip == pytest.approx(q_max / m.particle.mass, rel=1e-4)
    assert a_at_slip == pytest.approx(40.0, abs=0.01)
    assert events[0].x == model.particle.x0


def test_coulomb_displacement_matches_closed_form(model):
    """constant a0 for τ, then 0: x = −(a0−μ)τ²/2 − ((a0−μ)τ)²/(2μ), μ = Q_max(W)/m."""
    a0, tau = 100.0, 1e-3
    m = flat(model, constant_base_acceleration(a0, tau))
    mu = table_mu(m)
    state = m.initial_state()
    events = m.advance(state, 5e-3)
    expected = -(a0 - mu) * tau ** 2 / 2 - ((a0 - mu) * tau) ** 2 / (2 * mu)
    assert state.distance == pytest.approx(expected, rel=1e-9)
    assert [e.kind for e in events] == ['stick_to_slip', 'slip_to_stick']
    assert events[1].t == pytest.approx(tau + (a0 - mu) * tau / mu, abs=2e-9)
    assert state.max_speed == pytest.approx((a0 - mu) * tau, rel=1e-9)


def test_no_tangential_motion_at_the_bump_centre(model):
    """h_x = 0 under the part: it never slides (strokes up to just below take-off)."""
    for amplitude in (100e-6, 200e-6):
        m = model.replace(stroke=model.stroke.replace(amplitude=amplitude),
                          particle=model.particle.replace(x0=0.0), contact_model=model.contact_model)
        result = m.run()
        assert result.state.distance == 0.0
        assert result.state.transitions['stick_to_slip'] == 0


@pytest.mark.parametrize('frequency', [1000.0, 1500.0])
def test_mirror_symmetry(model, frequency):
    """parts at c + Δ and c − Δ move mirror-symmetrically (bump centred at c = 1 mm)."""
    base = model.replace(surface=model.surface.replace(centers=(1e-3,)),
                         stroke=model.stroke.replace(frequency=frequency, amplitude=150e-6))
    right = base.run(state=base.initial_state(1e-3 + 0.4e-3)).state
    left = base.run(state=base.initial_state(1e-3 - 0.4e-3)).state
    assert abs(right.distance) > 1e-7
    assert left.distance == pytest.approx(-right.distance, rel=1e-6)
    assert left.transitions == right.transitions


def distance(m: FeederModel) -> float:
    state = m.initial_state()
    m.advance(state, m.default_duration())
    return state.distance


def test_rk4_converges_with_fourth_order(model):
    """distance per stroke vs dt for fixed-step RK4 (events located to 1e-9 s): order 4 until the
    kinks of the piecewise-linear Q_max(N) table take over (below dt ~ 5e-5 s, docs/dynamics.md)."""
    reference = distance(model.replace(integration=model.integration.replace(method='rk4', dt=1e-6)))
    errors = [abs(distance(model.replace(integration=model.integration.replace(method='rk4', dt=dt)))
                  - reference) for dt in (2e-4, 1e-4, 5e-5)]
    orders = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all((orders > 3.5) & (orders < 4.6)), orders


@pytest.mark.parametrize('frequency', [1000.0, 3000.0])   # stick-slide-stick; and a take-off
def test_default_step_meets_the_accuracy_target(model, frequency):
    """the default (adaptive) integration keeps distance per stroke within 0.1 % of dt -> 0."""
    m = model.replace(stroke=model.stroke.replace(frequency=frequency))
    fine = m.replace(integration=m.integration.replace(dt=1e-6, tolerance=1e-14))
    assert distance(m) == pytest.approx(distance(fine), rel=1e-3)


def test_threshold_logic_converges_to_event_location(model):
    """the seed's threshold-velocity logic approaches the event-located result as dt -> 0."""
    exact = distance(model.replace(integration=model.integration.replace(tolerance=1e-14, dt=1e-5)))
    gaps = [abs(distance(model.replace(integration=model.integration.replace(
        friction_logic='threshold', dt=dt))) / exact - 1) for dt in (1e-5, 2.5e-7)]
    assert gaps[1] < 1e-5
    assert gaps[1] < gaps[0]


def test_energy_balance_frictionless(model):
    """frictionless, adhesion-free: ΔE = ∫ N h_t / L dt, the work of the moving surface."""
    m = model.replace(stroke=model.stroke.replace(frequency=50.0), contact_model=FrictionlessContact(),
                      integration=model.integration.replace(method='rk4', dt=2e-6))
    result = m.run(duration=0.03)
    assert result.state.transitions['take_off'] == 0 and abs(result.state.distance) > 1e-5
    mass, g = m.particle.mass, m.particle.gravity
    energy = 0.5 * mass * (result['xdot'] ** 2 + result['zdot'] ** 2) + mass * g * result['z']
    power = result['normal_load'] * result['surface_velocity'] * np.cos(result['theta'])
    t = result['t']
    work = np.sum(0.5 * (power[1:] + power[:-1]) * np.diff(t))
    assert energy[-1] - energy[0] == pytest.approx(work, rel=1e-6)
    assert abs(work) > 1e-3 * np.max(np.abs(energy - energy[0]))


def test_free_flight_is_a_parabola(model):
    """no attraction, flat surface: x = x0 + vx t, z = z0 + vz t − g t²/2 to 1e-9 m."""
    m = flat(model).replace(contact_model=FrictionlessContact())
    state = m.flying_state(x=1e-3, z=1e-3, vx=0.01, vz=0.1)
    assert m.advance(state, 0.02) == []
    g = m.particle.gravity
    assert state.x == pytest.approx(1e-3 + 0.01 * 0.02, abs=1e-9)
    assert state.z == pytest.approx(1e-3 + 0.1 * 0.02 - g * 0.02 ** 2 / 2, abs=1e-9)
    assert state.mode == 'flying'


def test_take_off_and_landing(model):
    """A 3 kHz stroke beats adhesion (h_tt < −(F_po/m + g)): the part flies, lands, then sticks."""
    m = model.replace(stroke=model.stroke.replace(frequency=3000.0))
    result = m.run(duration=0.3)
    kinds = [e.kind for e in result.events]
    assert kinds.count('take_off') == 1 and kinds.count('landing') == 1
    assert kinds.index('landing') > kinds.index('take_off')
    assert result.state.mode == 'stuck'
    take_off = result.events[kinds.index('take_off')]
    row = np.searchsorted(result['t'], take_off.t)
    # continuity of the normal force at take-off: N = −F_po = −F_att(0)
    assert result['normal_load'][row] == pytest.approx(-m.contact_model.pull_off_n, rel=1e-3)
    assert result.state.transitions == {'stick_to_slip': kinds.count('stick_to_slip'),
                                        'slip_to_stick': kinds.count('slip_to_stick'),
                                        'take_off': 1, 'landing': 1}
    # without the weight in the detachment test (the seed's variant) the part leaves earlier
    seed_rule = m.replace(detach=m.detach.replace(include_weight=False))
    earlier = next(e for e in seed_rule.run(duration=2e-4).events if e.kind == 'take_off')
    assert earlier.t < take_off.t


def test_landing_keeps_the_tangential_velocity_then_coulomb_stop(model):
    """On a flat, still surface a landing keeps v_x, then friction Q_max(W) stops it: Δx = v²/(2μ)."""
    m = flat(model)
    vx = 0.01
    result = m.run(duration=5e-3, state=m.flying_state(x=0.0, z=2e-6, vx=vx, vz=-0.05))
    assert [e.kind for e in result.events] == ['landing', 'slip_to_stick']
    landing = result.events[0]
    row = np.flatnonzero(result['t'] == landing.t)[-1]
    assert result['xdot'][row] == pytest.approx(vx, rel=1e-12)
    mu = table_mu(m)
    assert result.state.x - landing.x == pytest.approx(vx ** 2 / (2 * mu), rel=1e-6)


def test_contact_frame_tilt_sign(model):
    """θ = atan(h_x): beside the bump (x > c) the surface falls away, h_x < 0, so θ < 0."""
    state = model.initial_state()
    model.advance(state, 0.2e-3)
    obs = model.observe(state)
    stroke = obs.strokes
    dx = 1e-8
    slope = (surface_profile(np.array([obs.x + dx]), stroke, model.surface.centers, model.surface.widths)
             - surface_profile(np.array([obs.x - dx]), stroke, model.surface.centers,
                               model.surface.widths))[0] / (2 * dx)
    assert slope < 0
    assert obs.theta == pytest.approx(np.arctan(slope), rel=1e-6)


def test_convective_terms_change_little_at_the_seed_operating_point(model):
    """The seed drops 2 h_xt ẋ + h_xx ẋ² from the normal load: at the default point that changes the
    distance per stroke by well under 1 % (but not by nothing)."""
    with_terms = distance(model)
    seed_form = distance(model.replace(integration=model.integration.replace(convective_terms=False)))
    assert seed_form != with_terms
    assert seed_form == pytest.approx(with_terms, rel=1e-2)


def test_breakpoints_an_ulp_apart_cost_no_step_size():
    """16 actuators in five phase groups: phases computed as 0.2 k put breakpoints of one group ~1e-19 s
    apart. A step cut short at a breakpoint keeps the step size the error allowed before it, so the run
    takes about as many steps (rows) as with exactly equal phases (2.1x as many when each such step shrank
    the next), and moves the part alike."""
    n = 16

    def wave(phases: list[float]) -> FeederModel:
        return FeederModel.from_settings({
            'particle.x0': 0.1e-3, 'surface.centers': [0.5e-3 * (k - n // 2) for k in range(n)],
            'surface.widths': [0.4e-3] * n, 'stroke.amplitude': 150e-6, 'stroke.frequency': 1000.0,
            'stroke.phases': phases, 'stroke.count': 20})

    exact = [0.2 * ((k - n // 2) % 5) for k in range(n)]
    nudged = [phase * (1.0 + 4e-16 * (k % 3)) for k, phase in enumerate(exact)]
    assert len(set(nudged)) > len(set(exact))
    steady, jittered = (wave(phases).run(duration=0.02) for phases in (exact, nudged))
    assert len(jittered.data) <= 1.2 * len(steady.data)
    assert jittered.state.distance == pytest.approx(steady.state.distance, rel=1e-9)
    assert jittered.state.transitions == steady.state.transitions
