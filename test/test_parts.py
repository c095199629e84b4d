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

import math

import numpy as np
import pytest

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.parameters import ParameterError
from micro_feeder.physics.particle import ParticleParams
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
