"""Where a run is split into ``advance`` calls does not change it, as a property over drawn scenarios.

The kernel never cuts a step at a call's target: the step that passes it is kept and taken by the next call
(docs/events.md), so the node's 1 ms ticks, ``simulate``'s output steps and a resim's stop times all take the
steps one call takes. What a kept step carries over must be exactly what the loop itself keeps: a resumed
step that left its slide "fresh" hid the reversal a velocity jump makes where that step ends (a sine's end
on a plate: the part slid on the wrong way for 56 ns, 3e-9 m by the end; found by test_paths.py's random
draws). Every event, reversals included, must be the same in kind and time, and the part where it ends.
"""

from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_paths import _duration, _settings, scenarios

from micro_feeder.sim.stepper import build_model

SPLITS = st.lists(st.floats(0.0, 1.0, exclude_max=True), min_size=1, max_size=8)


def _advanced(flat: dict[str, object], targets: list[float]) -> tuple[list[tuple[str, float]], object]:
    model = build_model(flat)
    state = model.initial_state()
    events = []
    for t in targets:
        events += [(e.kind, e.t) for e in model.advance(state, t)]
    return events, state


@settings(max_examples=150, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(scenario=scenarios(), fractions=SPLITS)
def test_a_run_split_anywhere_takes_the_steps_of_one_call(scenario: dict[str, object], fractions: list[float]) -> None:
    scenario = {k: v for k, v in scenario.items() if not k.startswith('stream.')}
    flat = _settings(scenario)
    end = _duration(flat)
    whole_events, whole = _advanced(flat, [end])
    split_events, split = _advanced(flat, [*sorted(f * end for f in fractions), end])
    assert split_events == whole_events, scenario
    assert split.transitions == whole.transitions
    assert split.mode == whole.mode
    np.testing.assert_array_equal(split.y, whole.y, err_msg=str(scenario))


def test_a_velocity_jump_where_a_resumed_step_ends_reverses_the_slip() -> None:
    """The case found: a sine's end on a plate, 15.8 µs after a reversal, with a call ending in between."""
    flat = _settings({
        'stroke.waveform': 'sine', 'stroke.count': 4, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
        'stroke.duty': 0.5, 'stroke.amplitude': 1.932453478860765e-05, 'stroke.frequency': 852.0,
        'stroke.phases': [0.3984375, 0.0078125, 0.71875], 'surface.centers': [-0.0004, 0.0, 0.0004],
        'surface.widths': [0.0005140165167146125, 0.0005, 0.001306796362616968], 'particle.x0': 0.0,
        'piezo.enabled': False, 'surface.thickness': 0.0002356499179202825})
    jump = 0.0078125 / 852.0 + 4 / 852.0          # actuator 1's burst ends: ṡ jumps from 0.103 m/s to 0
    end = _duration(flat)
    whole_events, whole = _advanced(flat, [end])
    split_events, split = _advanced(flat, [jump - 1e-9, end])
    reversals = [t for kind, t in whole_events if kind == 'reversal' and abs(t - jump) < 1e-7]
    assert len(reversals) == 2 and abs(reversals[0] - jump) < 1e-12   # at the jump, and back 56 ns later
    assert split_events == whole_events
    assert split.distance == whole.distance
