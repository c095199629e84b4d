"""The stepper API the simulator node builds on: ticks, commanded trajectories, guards, options."""

import json
import os
import subprocess
import sys
from dataclasses import dataclass

import numpy as np
import pytest

from micro_feeder.physics.dynamics import FeederModel, SimulationError
from micro_feeder.physics.parameters import ParameterError
from micro_feeder.physics.waveforms import StrokeSchedule
from micro_feeder.settings import load_settings


@pytest.fixture(scope='module')
def model() -> FeederModel:
    return FeederModel()


def test_ticks_give_the_same_motion_as_one_advance(model):
    whole = model.initial_state()
    events_whole = model.advance(whole, 3e-3)
    ticked = model.initial_state()
    events_ticked = []
    for t in np.arange(1, 3001) * 1e-6:
        events_ticked += model.advance(ticked, t)
    assert ticked.t == pytest.approx(3e-3, abs=1e-15)
    assert ticked.distance == pytest.approx(whole.distance, rel=1e-5)   # within the accuracy target
    assert [e.kind for e in events_ticked] == [e.kind for e in events_whole]
    assert [e.t for e in events_ticked] == pytest.approx([e.t for e in events_whole], abs=2e-9)
    assert ticked.transitions == whole.transitions


def test_commanded_trajectory_reproduces_the_waveform(model):
    """The raised cosine sent as knots (exact s, ṡ, s̈) through a schedule, from a hold."""
    f = model.stroke.frequency
    start = 0.5e-3
    knots = start + np.linspace(0.0, 1.0 / f, 41)
    waveform = model.replace(stroke=model.stroke.replace(delay=start))
    exact = waveform.waveform()
    samples = np.array([exact.evaluate(t)[:, 0] for t in knots[:-1]] + [[0.0, 0.0, 0.0]])
    schedule = StrokeSchedule(model.waveform())
    schedule.hold_from(0.0)
    state = model.initial_state()
    model.advance(state, 0.2e-3, schedule)
    schedule.command_trajectory(0.2e-3, knots, samples[:, :1], samples[:, 1:2], samples[:, 2:3])
    model.advance(state, 4e-3, schedule)
    reference = waveform.initial_state()
    waveform.advance(reference, 4e-3)
    assert state.distance == pytest.approx(reference.distance, rel=1e-4)
    assert state.transitions == reference.transitions


def test_observation_in_contact(model):
    state = model.initial_state()
    model.advance(state, 0.6e-3)
    obs = model.observe(state)
    assert obs.mode == 'sliding' and obs.t == pytest.approx(0.6e-3)
    assert obs.z == pytest.approx(obs.surface_height)
    assert abs(obs.friction) == pytest.approx(obs.q_max)
    assert 50e-9 < obs.separation < 100e-9 and np.isnan(obs.gap)
    assert obs.strokes.shape == (1,)


def test_non_finite_state_stops_with_a_clear_error(model):
    @dataclass(frozen=True)
    class Tables:
        load_n = np.array([-1.0, 1.0])
        q_max_n = np.array([np.nan, np.nan])
        separation_m = np.zeros(2)
        gap_m = np.array([0.0, 1e-3])
        attraction_n = np.zeros(2)

    @dataclass(frozen=True)
    class BrokenContact:
        tables = Tables()
        pull_off_n = 1e-5

    broken = model.replace(contact_model=BrokenContact())
    state = broken.initial_state()
    with pytest.raises(SimulationError, match=r't = .* s in mode (stuck|sliding)'):
        broken.advance(state, 1e-3)
    assert np.all(np.isfinite(state.y))


def test_piezo_filters_and_limits_the_stroke(model):
    ideal = model.run().state.distance
    fast = model.replace(piezo=model.piezo.replace(enabled=True, natural_frequency=1e6, damping=0.7))
    assert fast.run().state.distance == pytest.approx(ideal, rel=1e-2)
    limited = model.replace(piezo=model.piezo.replace(enabled=True, stroke_max=60e-6, damping=1.0))
    strokes = limited.run()['stroke_0']
    assert np.max(strokes) == pytest.approx(60e-6, rel=1e-2)
    assert np.max(strokes) <= 60e-6 * 1.001


def test_state_of_another_model_refused(model):
    """The piezo stacks take room in the state only when integrated: a state made for a model without
    them is refused by a model with them (and the other way round), not read past its end."""
    with_stacks = model.replace(piezo=model.piezo.replace(enabled=True))
    assert model.initial_state().piezo_stroke.size == 0 and with_stacks.initial_state().piezo_stroke.size == 1
    for made_by, used_by in ((model, with_stacks), (with_stacks, model)):
        state = made_by.initial_state()
        with pytest.raises(ValueError, match='make the state with this model'):
            used_by.advance(state, 1e-4)
        with pytest.raises(ValueError, match='make the state with this model'):
            used_by.observe(state)


def test_from_settings_and_parameter_errors():
    m = FeederModel.from_settings(load_settings([], ['surface.centers=[0.0, 2.0e-3]',
                                                     'surface.widths=[1e-3, 1e-3]',
                                                     'stroke.phases=[0.0, 0.25]']))
    assert m.n_actuators == 2 and m.run(duration=1e-3).data.shape[1] == 14 + 2
    with pytest.raises(ParameterError, match='stroke.phases'):
        FeederModel.from_settings({'surface.centers': [0.0, 2e-3], 'surface.widths': [1e-3, 1e-3]})
    with pytest.raises(ParameterError, match='piezo.stroke_max'):
        FeederModel.from_settings({'piezo.stroke_min': 1e-4, 'piezo.stroke_max': 1e-5})
    with pytest.raises(ParameterError, match=r'integration.friction_logic .*one of'):
        FeederModel.from_settings({'integration.friction_logic': 'karnopp'})


def test_uncompiled_kernel_gives_the_same_result(model):
    """NUMBA_DISABLE_JIT=1 runs the same kernel as plain Python (the debugging path)."""
    code = ('import json; from micro_feeder.physics.dynamics import FeederModel; '
            'r = FeederModel().run(); print(json.dumps(r.summary()))')
    env = dict(os.environ, NUMBA_DISABLE_JIT='1')
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         check=True, timeout=120)
    plain = json.loads(out.stdout)
    compiled = model.run().summary()
    assert plain['distance_m'] == pytest.approx(compiled['distance_m'], rel=1e-12)
    assert plain['transitions'] == compiled['transitions']
