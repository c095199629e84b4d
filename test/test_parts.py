"""Many parts on one feeder (issue 28; docs/parts.md), against closed forms and invariants.

* Parameters: ``particle.x0`` / ``particle.v0`` as a number (one part, the model of before, bit for bit) or
  a list, refused with the reason when parts overlap, are out of order or the lists disagree.
* Parts too far apart to meet take the very steps each takes alone (bit for bit).
* A part sliding at v0 into a part at rest on a still, level track with Coulomb friction μ: impact speed
  u = √(v0² − 2μg·gap), Newton's restitution, then each part slides v²/(2μg) further (to 1e-9 m).
* A row at e = 1 passes the velocity down the row (Newton's cradle), touching or with gaps.
* Drawn scenarios on a vibrating track: no overlap, no reordering, momentum conserved in every impact.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from micro_feeder.cli import main
from micro_feeder.physics.dynamics import FeederModel, Observation
from micro_feeder.physics.dynamics.layout import FS_MAX_SPEED
from micro_feeder.physics.dynamics.model import _WORK
from micro_feeder.physics.parameters import ParameterError
from micro_feeder.physics.particle import ParticleParams
from micro_feeder.physics.parts import PartsModel
from micro_feeder.physics.parts.figures import gate_crossings, gate_figures, spacing_figures
from micro_feeder.physics.parts.model import PartsState
from micro_feeder.physics.waveforms import StrokeSchedule
from micro_feeder.settings import load_settings

G = 9.81
SIZE = 100e-6


def test_one_number_is_one_part_as_before():
    """``particle.x0`` a number: one part, the default v0 = 0 leaves it stuck at rest (the state of before)."""
    params = ParticleParams(x0=0.5e-3)
    assert params.n_parts == 1 and params.start_positions == (0.5e-3,) and params.start_velocities == (0.0,)
    model = FeederModel.from_settings(load_settings(['config/feeder.yaml']))
    state = model.initial_state()
    assert state.mode == 'stuck' and state.x == 0.5e-3 and state.xdot == 0.0 and state.max_speed == 0.0


def test_lists_place_one_part_per_entry():
    params = ParticleParams(x0=[0.0, 1e-4, 3e-4], v0=0.01, size=1e-4)
    assert params.start_positions == (0.0, 1e-4, 3e-4) and params.start_velocities == (0.01,) * 3
    assert ParticleParams(x0=[0.0, 2e-4], v0=[0.0, -0.02]).start_velocities == (0.0, -0.02)


@pytest.mark.parametrize('values, name, reason', [
    ({'x0': [0.0, 5e-5]}, 'particle.x0', 'at least particle.size = 0.0001 m apart (0 and 5e-05 are not)'),
    ({'x0': [3e-4, 0.0]}, 'particle.x0', 'increasing order'),
    ({'x0': []}, 'particle.x0', 'non-empty list'),
    ({'x0': [0.0, 1e-3], 'v0': [0.0, 0.0, 0.0]}, 'particle.v0', 'one entry per particle.x0 entry (2)'),
    ({'restitution': 1.5}, 'particle.restitution', '<= 1'),
    ({'size': 0.0}, 'particle.size', '> 0'),
])
def test_refused_with_the_reason(values, name, reason):
    with pytest.raises(ParameterError) as err:
        ParticleParams(**values)
    assert err.value.name == name and reason in str(err.value)


def test_a_starting_velocity_starts_a_slide_uncounted():
    model = FeederModel.from_settings({'particle.v0': -0.01})
    state = model.initial_state()
    assert state.mode == 'sliding' and state.xdot == -0.01 and sum(state.transitions.values()) == 0


# --- the parts model -----------------------------------------------------------------------------------

def _still_track(mu: float, x0: list[float], v0: list[float], restitution: float) -> PartsModel:
    """Parts on a level track that does not move (stroke amplitude 0), Coulomb friction μ."""
    return PartsModel.from_settings({
        'surface.kind': 'track', 'contact.model': 'coulomb', 'contact.mu': mu, 'stroke.amplitude': 0.0,
        'particle.x0': x0, 'particle.v0': v0, 'particle.restitution': restitution})


def _assert_apart_in_order_and_momentum(parts: PartsModel, result) -> None:
    gaps = np.diff(result.x, axis=1) - parts.size
    assert gaps.min() >= -1e-12, f'parts overlap by {-gaps.min():.3g} m'
    for impact in result.state.impacts:
        scale = sum(abs(v) for v in impact.before) + 1e-300
        assert abs(sum(impact.before) - sum(impact.after)) <= 1e-14 * scale, impact


def test_parts_too_far_apart_to_meet_move_exactly_as_alone():
    """Three parts on the travelling wave, 0.4 mm apart: each takes the very steps it takes alone."""
    flat = load_settings(['config/feeder.yaml', 'config/travelling_wave.yaml'], ['stroke.count=20'])
    starts = [0.6e-3, 1.0e-3, 1.4e-3]
    parts = PartsModel.from_settings({**flat, 'particle.x0': starts})
    state = parts.initial_state()
    parts.advance(state, 0.03)
    assert state.collisions == 0
    alone = FeederModel.from_settings(flat)
    for x0, together in zip(starts, state.parts, strict=True):
        single = alone.initial_state(x0)
        alone.advance(single, 0.03)
        assert single.distance != 0.0
        assert np.array_equal(single.y, together.y) and single.transitions == together.transitions
        assert single.max_speed == together.max_speed


@pytest.mark.parametrize('restitution', [0.0, 0.5, 1.0])
def test_sliding_part_into_part_at_rest_closed_form(restitution):
    """Impact at u = √(v0² − 2μg·gap); after it v = (1 ∓ e) u / 2, and each part slides v²/(2μg) on."""
    mu, v0, gap = 0.3, 0.05, 200e-6
    parts = _still_track(mu, [0.0, SIZE + gap], [v0, 0.0], restitution)
    result = parts.run(duration=0.05, output_step=1e-3)
    u = math.sqrt(v0 ** 2 - 2 * mu * G * gap)
    rear, front = (1 - restitution) * u / 2, (1 + restitution) * u / 2
    expected = [gap + rear ** 2 / (2 * mu * G), SIZE + gap + front ** 2 / (2 * mu * G)]
    assert np.abs(result.state.positions - expected).max() < 1e-9
    (impact,) = result.state.impacts
    # located to the event tolerance (1e-9 s), over which friction changes the speed by μg·1e-9 s
    assert impact.approach == pytest.approx(u, abs=2 * mu * G * 1e-9)
    u = impact.approach
    assert impact.after == pytest.approx(((1 - restitution) * u / 2, (1 + restitution) * u / 2), rel=1e-12)
    assert [p.mode for p in result.state.parts] == ['stuck', 'stuck']
    _assert_apart_in_order_and_momentum(parts, result)


@pytest.mark.parametrize('gaps', [[50e-6, 0.0, 0.0, 0.0], [50e-6, 30e-6, 20e-6, 10e-6]])
def test_newtons_cradle_passes_the_velocity_down_the_row(gaps):
    """e = 1: each part stops where it hits the next, which carries the velocity on (less μg over each gap);
    the last slides v²/(2μg)."""
    mu, v0 = 0.2, 0.05
    starts = np.cumsum([0.0] + [SIZE + g for g in gaps]).tolist()
    parts = _still_track(mu, starts, [v0] + [0.0] * len(gaps), 1.0)
    result = parts.run(duration=0.1, output_step=1e-3)
    speed, expected = v0, []
    for k, gap in enumerate(gaps):
        speed = math.sqrt(speed ** 2 - 2 * mu * G * gap)
        expected.append(starts[k + 1] - SIZE)
    expected.append(starts[-1] + speed ** 2 / (2 * mu * G))
    assert np.abs(result.state.positions - expected).max() < 1e-9
    assert result.state.collisions == len(gaps)
    _assert_apart_in_order_and_momentum(parts, result)


def test_a_struck_part_takes_the_mode_its_velocity_gives():
    model = FeederModel.from_settings({'surface.kind': 'track', 'contact.model': 'coulomb', 'contact.mu': 0.1,
                                       'stroke.amplitude': 0.0, 'track.inclination': 0.3})
    state = model.initial_state()
    assert [e.kind for e in model.set_velocity(state, 0.01)] == ['stick_to_slip'] and state.mode == 'sliding'
    # at rest on a slope steeper than μ allows: it cannot stick, and slides downhill (x runs uphill)
    assert len(model.set_velocity(state, 0.0)) == 0 and state.mode == 'sliding' and state.xdot == 0.0
    model.advance(state, 0.01)
    assert state.xdot < 0.0
    held = model.replace(contact=model.contact.replace(mu=1.0))
    state = held.initial_state()
    held.set_velocity(state, 0.01)
    assert [e.kind for e in held.set_velocity(state, 0.0)] == ['slip_to_stick'] and state.mode == 'stuck'
    flying = held.flying_state(0.0, 1e-3, 0.0, 0.0)
    assert len(held.set_velocity(flying, -0.02)) == 0 and flying.mode == 'flying' and flying.xdot == -0.02


def test_a_crowded_travelling_wave_keeps_parts_apart_in_order():
    """Ten parts 30 µm apart on the travelling wave, plastic and bouncing: they meet, press into trains, and
    never overlap or pass each other; momentum is conserved in every impact."""
    flat = load_settings(['config/feeder.yaml', 'config/travelling_wave.yaml'], ['stroke.count=20'])
    for restitution in (0.0, 0.5):
        starts = (0.4e-3 + 0.13e-3 * np.arange(10)).tolist()
        parts = PartsModel.from_settings({**flat, 'particle.x0': starts, 'particle.restitution': restitution})
        result = parts.run(duration=0.03, output_step=1e-4)
        assert result.state.collisions > 10
        _assert_apart_in_order_and_momentum(parts, result)


EXAMPLES = int(os.environ.get('MF_PARTS_EXAMPLES', '25'))


@settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(starts=st.lists(st.tuples(st.floats(0.2e-3, 2.0e-3), st.floats(-0.05, 0.05), st.booleans()),
                       min_size=1, max_size=6),
       ends=st.lists(st.floats(1e-4, 4e-3), min_size=1, max_size=3), hold_at=st.floats(0.0, 6e-3),
       small_buffer=st.booleans())
def test_advancing_copies_together_is_advancing_each_alone(starts, ends, hold_at, small_buffer):
    """FeederModel.advance_copies (one compiled call for all parts) gives every part the very state, events and
    peak speed a part advanced alone gets, over stroke segments (a hold commanded mid-run), in flight, sliding
    or stuck, also when the shared event buffer overflows and a part goes on alone; the originals stay."""
    flat = load_settings(['config/feeder.yaml', 'config/travelling_wave.yaml'], ['stroke.count=20'])
    model = FeederModel.from_settings(flat)
    schedule = StrokeSchedule(model.waveform())
    schedule.hold_from(hold_at)
    states = [model.flying_state(x0, 2e-6, v0, 0.01) if flying else model.initial_state(x0, v0)
              for x0, v0, flying in starts]
    work = _WORK.arrays(states[0].y.size, model.n_actuators)
    if small_buffer:
        work.batch_ev_i, work.batch_ev_f = np.zeros((3, 3), dtype=np.int64), np.zeros((3, 2))
    try:
        for t_end in np.cumsum(ends):
            before = [s.copy() for s in states]
            advanced = model.advance_copies(states, float(t_end), schedule)
            for state, old in zip(states, before, strict=True):
                assert np.array_equal(state.y, old.y) and np.array_equal(state.fs, old.fs, equal_nan=True)
            for k, state in enumerate(states):
                alone = state.copy()
                run_max = alone.max_speed
                alone.fs[FS_MAX_SPEED] = abs(alone.xdot)
                events = model.advance(alone, float(t_end), schedule)
                peak = alone.max_speed
                alone.fs[FS_MAX_SPEED] = max(run_max, peak)
                together = advanced.states[k]
                assert np.array_equal(alone.y, together.y) and np.array_equal(alone.iv, together.iv)
                assert np.array_equal(alone.fs, together.fs, equal_nan=True)
                assert list(advanced.events[k]) == list(events) and advanced.peak_speed[k] == peak
                path = np.abs(np.diff([state.x, *events.x, alone.x])).sum()
                assert advanced.path[k] == pytest.approx(path, rel=1e-12, abs=1e-18)
            states = advanced.states
    finally:
        work.batch_ev_i, work.batch_ev_f = np.zeros((4096, 3), dtype=np.int64), np.zeros((4096, 2))


@st.composite
def track_scenarios(draw) -> dict:
    n = draw(st.integers(2, 5))
    gaps = draw(st.lists(st.floats(0.0, 300e-6), min_size=n - 1, max_size=n - 1))
    return {'surface.kind': 'track', 'contact.model': 'coulomb', 'stroke.waveform': 'sine',
            'stroke.frequency': 100.0, 'stroke.count': 5, 'contact.mu': draw(st.floats(0.2, 0.8)),
            'stroke.amplitude': draw(st.floats(0.0, 100e-6)),
            'landing.law': draw(st.sampled_from(['keep', 'coulomb', 'stick'])),
            'particle.x0': np.cumsum([0.0] + [SIZE + g for g in gaps]).tolist(),
            'particle.v0': draw(st.lists(st.floats(-0.05, 0.05), min_size=n, max_size=n)),
            'particle.restitution': draw(st.floats(0.0, 1.0))}


@settings(max_examples=EXAMPLES, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(scenario=track_scenarios())
def test_drawn_scenarios_never_overlap_or_reorder(scenario):
    parts = PartsModel.from_settings(scenario)
    result = parts.run(duration=0.05, output_step=1e-3)
    _assert_apart_in_order_and_momentum(parts, result)


def test_gate_counts_forward_crossings_at_their_interpolated_times():
    t = np.array([0.0, 1.0, 2.0, 3.0])
    x = np.array([[0.0, 5.0], [2.0, 5.0], [0.0, 7.0], [4.0, 3.0]])     # part 0 passes x = 1 twice, part 1 never
    assert gate_crossings(t, x, 1.0).tolist() == [0.5, 2.25]
    figures = gate_figures(t, x, 1.0)
    assert figures['crossings'] == 2 and figures['feed_rate_hz'] == 2 / 3 and figures['headway_s'] == 1.75
    assert spacing_figures([3e-4, 1e-4, 6e-4]) == pytest.approx({'spacing_mean_m': 2.5e-4, 'spacing_min_m': 2e-4})


def test_simulate_reports_every_part_the_impacts_and_the_gate(tmp_path):
    """``micro-feeder simulate --json`` with two parts: the slide into a part at rest at e = 1 hands the
    velocity on, so the front part alone passes a gate ahead of it; one impact."""
    out = io.StringIO()
    settings = {'surface.kind': 'track', 'contact.model': 'coulomb', 'contact.mu': 0.3, 'stroke.amplitude': 0.0,
                'particle.x0': [0.0, 3e-4], 'particle.v0': [0.05, 0.0], 'particle.restitution': 1.0}
    args = [arg for name, value in settings.items() for arg in ('--set', f'{name}={value!r}')]
    with contextlib.redirect_stdout(out):
        assert main(['simulate', *args, '--duration', '0.05', '--gate', '4e-4', '--json', '--out', str(tmp_path),
                     '--plot']) == 0
    summary = json.loads(out.getvalue())
    assert summary['collisions'] == 1 and summary['crossings'] == 1 and summary['feed_rate_hz'] == 1 / 0.05
    assert [part['final_mode'] for part in summary['parts']] == ['stuck', 'stuck']
    assert summary['parts'][0]['distance_m'] == pytest.approx(2e-4, abs=1e-9)
    assert summary['parts'][0]['transitions']['slip_to_stick'] == 1
    assert (tmp_path / 'simulate.png').stat().st_size > 0 and (tmp_path / 'simulate.csv').read_text().startswith(
        't,x_0,mode_0,x_1,mode_1')


def _chunks_taken(parts: PartsModel, state, ends) -> int:
    """How many chunks (every part alone over one) ``parts`` tries to advance ``state`` through ``ends`` (s)."""
    before = parts.trials
    for t_end in ends:
        parts.advance(state, float(t_end))
    return parts.trials - before


def test_one_ms_calls_take_about_the_chunks_of_one_call():
    """A real-time loop advances the parts 1 ms a call: the chunks must not shrink to what each call's end left
    of the last one (2.9 chunks a ms when they did, 2.1 now and 1.9 in one call, for 16 parts 0.3 mm apart on a
    vibrating track), and the parts end where one call takes them (far apart: each moves as alone)."""
    flat = {**load_settings(), 'surface.kind': 'track', 'contact.model': 'coulomb', 'contact.mu': 0.5,
            'stroke.waveform': 'sine', 'stroke.frequency': 100.0, 'stroke.amplitude': 60e-6, 'stroke.count': 40,
            'particle.x0': [round(k * 0.3e-3, 6) for k in range(16)]}
    parts = PartsModel.from_settings(flat)
    once, ticked = parts.initial_state(), parts.initial_state()
    one_call = _chunks_taken(parts, once, [0.2])
    per_ms = _chunks_taken(parts, ticked, np.arange(1, 201) * 1e-3)
    assert once.collisions == ticked.collisions == 0
    assert np.array_equal(once.positions, ticked.positions) and np.array_equal(once.velocities, ticked.velocities)
    assert per_ms <= 1.2 * one_call, (per_ms, one_call)     # 427 against 385 (571 when they shrank)


def test_a_change_made_through_a_part_is_a_change_of_the_parts():
    """The parts are views of the rows one compiled call advances: a velocity set at an impact or a part moved
    through ``state.parts[k]`` is what the next chunk starts from; a part inserted or removed is taken too."""
    flat = {**load_settings(), 'particle.x0': [0.0, 1e-3, 2e-3]}
    parts = PartsModel.from_settings(flat)
    state = parts.initial_state()
    parts.advance(state, 1e-3)
    parts.model.move_to(state.parts[1], 1.2e-3)
    assert state.positions[1] == 1.2e-3 and state.rows.y[1, 0] == 1.2e-3
    state.insert(3, parts.model.initial_state(3e-3, 0.0))
    state.parts[3].fs[:] = state.parts[0].fs
    state.remove(0)
    assert len(state) == 3 and state.positions.tolist() == [1.2e-3, 2e-3, 3e-3]
    copy = state.copy()
    parts.advance(state, 2e-3)
    assert copy.t == 1e-3 and state.t == 2e-3 and state.positions.tolist()[1:] == [2e-3, 3e-3]


def test_observing_every_part_at_once_is_observing_each_alone():
    """One compiled call observes every part (the simulator publishes all of them each tick): each part's
    outputs are the numbers observing it alone gives, whatever the others' modes (nothing carried from one part
    to the next)."""
    flat = load_settings(['config/feeder.yaml', 'config/travelling_wave.yaml'], ['stroke.count=20'])
    model = FeederModel.from_settings(flat)
    states = [model.flying_state(0.5e-3, 2e-6, 0.01, 0.02), model.initial_state(1.0e-3, 0.0),
              model.initial_state(1.5e-3, -0.02), model.initial_state(2.0e-3, 0.0)]
    parts = PartsModel(model)
    state = PartsState(states)
    numbers = [name for name in Observation.__dataclass_fields__ if name != 'mode']
    for t in (0.0, 2.5e-3):
        parts.advance(state, t)
        together = model.observe_many(state.rows)
        for part, observed in zip(state.parts, together, strict=True):
            alone = model.observe(part)
            assert alone.mode == observed.mode
            for name in numbers:
                assert np.array_equal(getattr(alone, name), getattr(observed, name), equal_nan=True), name
        assert t > 0.0 or {o.mode for o in together} == {'flying', 'stuck', 'sliding'}


def _python_trials(parts: PartsModel) -> list[int]:
    """A counter of the chunks ``parts`` tries in Python (:meth:`PartsModel._trial`)."""
    calls: list[int] = []
    original = parts._trial
    parts._trial = lambda *args: calls.append(1) or original(*args)
    return calls


def _same_parts(a: PartsState, b: PartsState) -> None:
    ra, rb = a.rows, b.rows
    assert np.array_equal(ra.y, rb.y) and np.array_equal(ra.iv, rb.iv) and np.array_equal(ra.ahead, rb.ahead)
    assert np.array_equal(ra.fs, rb.fs, equal_nan=True)
    assert [on and on[2] for on in ra.ons] == [on and on[2] for on in rb.ons]    # on a table until the same time
    assert a.impacts == b.impacts and a.chunk_hint == b.chunk_hint


@pytest.mark.parametrize('case', ['track, 16 parts apart', 'crowded wave, plastic', 'crowded wave, e = 0.5',
                                  'track, a hold mid-run'])
def test_the_compiled_chunks_are_the_python_chunks_bit_for_bit(case):
    """The chunks in which no parts meet are taken in one compiled call (parts.apart); they are the very chunks
    the Python loop takes: every part's state, events, the impacts and the next chunk equal bit for bit, in 1-ms
    calls as a real-time loop makes them, with parts far apart (where the compiled call takes nearly every
    chunk), crowded (handing the chunks with impacts and trains back) and over stroke segments."""
    if case.startswith('track'):
        flat = {**load_settings(), 'surface.kind': 'track', 'contact.model': 'coulomb', 'contact.mu': 0.5,
                'stroke.waveform': 'sine', 'stroke.frequency': 100.0, 'stroke.amplitude': 60e-6, 'stroke.count': 20,
                'particle.x0': [round(k * 0.3e-3, 6) for k in range(16 if 'apart' in case else 4)]}
    else:
        flat = {**load_settings(['config/feeder.yaml', 'config/travelling_wave.yaml'], ['stroke.count=20']),
                'particle.x0': (0.4e-3 + 0.13e-3 * np.arange(10)).tolist(),
                'particle.restitution': 0.5 if '0.5' in case else 0.0}
    compiled, python = PartsModel.from_settings(flat), PartsModel.from_settings(flat)
    python.compiled_chunks = False
    source = None
    if 'hold' in case:
        source = StrokeSchedule(compiled.model.waveform())
        source.hold_from(0.0305)
    in_python = _python_trials(compiled)
    a, b = compiled.initial_state(), python.initial_state()
    for t_end in np.arange(1, 121) * 1e-3:
        events_a = compiled.advance(a, float(t_end), source)
        events_b = python.advance(b, float(t_end), source)
        assert [list(e) for e in events_a] == [list(e) for e in events_b], t_end
    _same_parts(a, b)
    assert [list(e) for e in compiled.advance(a, 0.2, source)] == [list(e) for e in python.advance(b, 0.2, source)]
    _same_parts(a, b)
    if 'apart' in case or 'hold' in case:      # the call over the hold's start: one compiled call a table
        assert len(in_python) < 0.02 * python.trials, (len(in_python), python.trials)
    else:
        assert a.collisions > 0 and len(in_python) < python.trials, (len(in_python), python.trials)
