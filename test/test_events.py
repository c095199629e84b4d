"""Runs end where the part rests, and mode changes are found wherever they happen (issue 9)."""

from __future__ import annotations

import dataclasses

import pytest

from micro_feeder.physics.dynamics import FeederModel


def test_a_run_with_no_duration_goes_on_until_the_part_rests() -> None:
    """3 kHz strokes throw the part: at the default length it is still in the air; the run goes on until it
    has landed and stuck, and says it settled. With no time left to settle it says it did not."""
    model = FeederModel.from_settings({'stroke.frequency': 3000.0, 'stroke.count': 2})
    plain = model.initial_state()
    model.advance(plain, model.default_duration())
    assert plain.mode != 'stuck'                          # the case the issue found: mid-flight
    result = model.run()
    assert result.summary()['settled'] and result.state.mode == 'stuck'
    assert result.state.t > model.default_duration()
    assert result.state.transitions['landing'] >= 1 and result['t'][-1] == result.state.t
    capped = model.replace(integration=dataclasses.replace(model.integration, settle_max=0.0)).run()
    assert not capped.summary()['settled'] and capped.state.t == pytest.approx(model.default_duration())


def test_settle_is_a_no_op_for_a_part_at_rest() -> None:
    model = FeederModel.from_settings({'stroke.count': 1})
    state = model.initial_state()
    model.advance(state, model.default_duration())
    assert state.mode == 'stuck'
    t = state.t
    assert model.settle(state) == [] and state.t == t
