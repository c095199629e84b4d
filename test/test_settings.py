"""Parameters files and --set overrides: formats, YAML 1.2 numbers, unknown names, validation."""

import pytest

from micro_feeder.physics.contact import ContactParams
from micro_feeder.settings import SettingsError, build_group, load_settings, parse_override


def test_overrides_read_as_yaml_with_exponent_floats():
    assert parse_override('contact.sigma=30e-9') == ('contact.sigma', 30e-9)
    assert parse_override('contact.hardness=1E9') == ('contact.hardness', 1e9)
    assert parse_override('contact.friction_law=ke') == ('contact.friction_law', 'ke')
    assert parse_override(' particle.x0 = -1.5e-3') == ('particle.x0', -1.5e-3)


def test_files_then_overrides_win_in_order(tmp_path):
    first = tmp_path / 'a.yaml'
    first.write_text('contact:\n  beta: 0.05\n  sigma: 25e-9\n')
    second = tmp_path / 'b.yaml'
    second.write_text('contact.beta: 0.06\n')
    flat = load_settings([first, second], ['contact.psi=3'])
    assert flat == {'contact.beta': 0.06, 'contact.sigma': 25e-9, 'contact.psi': 3}


def test_ros_parameters_file_sections(tmp_path):
    """/** then simulator sections are merged; node-only parameters are left to the nodes."""
    f = tmp_path / 'ros.yaml'
    f.write_text('/**:\n  ros__parameters:\n    contact: {beta: 0.05}\n    publish_rate: 500.0\n'
                 'simulator:\n  ros__parameters:\n    contact: {psi: 2.0}\n'
                 'recorder:\n  ros__parameters:\n    flush_period: 0.5\n')
    assert load_settings([f]) == {'contact.beta': 0.05, 'contact.psi': 2.0}


@pytest.mark.parametrize(('content', 'message'), [
    ('contact: [1, 2', 'not valid YAML'),
    ('- 1\n- 2\n', 'must hold a mapping'),
])
def test_unreadable_files_say_what_is_wrong(tmp_path, content, message):
    f = tmp_path / 'bad.yaml'
    f.write_text(content)
    with pytest.raises(SettingsError, match=message):
        load_settings([f])


def test_missing_file_and_unknown_name():
    with pytest.raises(SettingsError, match='cannot read parameters file'):
        load_settings(['/nonexistent/params.yaml'])
    with pytest.raises(SettingsError, match="unknown parameter 'contact.hardnes'; did you mean contact.hardness"):
        load_settings([], ['contact.hardnes=1e9'])


def test_build_group_turns_validation_into_settings_error():
    with pytest.raises(SettingsError, match=r"contact.epsilon = -4e-10 is not allowed: a finite number > 0"):
        build_group(ContactParams, {'contact.epsilon': -4e-10})


def test_every_parameter_is_documented():
    """docs/parameters.md names every parameter the settings accept (and no unknown one)."""
    import re
    from pathlib import Path

    from micro_feeder.settings import known_parameters

    doc = (Path(__file__).parents[1] / 'docs' / 'parameters.md').read_text()
    first_cells = re.findall(r'^\| `([^`]+)` \|', doc, flags=re.MULTILINE)
    documented = {name for name in first_cells if '.' in name or name == 'gravity'}   # not the preset rows
    assert documented == set(known_parameters())
