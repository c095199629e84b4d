"""config/feeder.yaml holds exactly the code defaults (the code is the truth)."""

from pathlib import Path

import pytest

from micro_feeder.control.feed_planner import FeedGoal
from micro_feeder.physics.dynamics.params import dynamics_parameter_groups
from micro_feeder.physics.particle import ParticleParams
from micro_feeder.settings import known_parameters, read_parameters_file

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'feeder.yaml'


def test_config_values_equal_code_defaults():
    values = read_parameters_file(CONFIG)
    known = known_parameters()
    assert values['contact.preset'] == 'seed_paper'
    # the file names the preset, not the values it controls (contact.model and contact.mu are not a preset's)
    assert not [name for name in values if name.startswith('contact.')
                and name not in ('contact.preset', 'contact.model', 'contact.mu')]
    for name, value in values.items():
        default = known[name][1]
        expected = list(default) if isinstance(default, tuple) else default
        if isinstance(value, (str, bool)):
            assert value == expected, name
        else:
            assert value == pytest.approx(expected, rel=1e-12), name


def test_config_sets_every_dynamics_particle_and_controller_parameter():
    values = read_parameters_file(CONFIG)
    for group in [ParticleParams, *dynamics_parameter_groups(), FeedGoal]:
        for _, name, _ in group.specs():
            assert name in values, name
