"""Parts spawned and deleted in a running simulation (simulation_interfaces SpawnEntity / DeleteEntity, through
the simulator's Stepper): a part spawned is the part the parameters would have placed, a deleted one is gone as
if never there, and what cannot be placed is refused with nothing changed."""

from __future__ import annotations

import numpy as np
import pytest

from micro_feeder.interface import trajectory_cdr
from micro_feeder.interface.entity_changes import DELETED, SPAWNED, EntityChange, read_entity_changes
from micro_feeder.interface.names import joint_names
from micro_feeder.interface.stamps import to_time
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.settings import load_settings
from micro_feeder.sim.commands import parse_trajectory_cdr
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import sample_waveform

TICK = 1e-3
WAVE = {'stroke.waveform': 'raised_cosine', 'stroke.count': 6, 'stroke.amplitude': 150e-6,
        'stroke.phases': [0.0, 0.25, 0.5, 0.75], 'surface.centers': [-1.5e-3, -0.5e-3, 0.5e-3, 1.5e-3],
        'surface.widths': [1e-3] * 4}


def _stepper(x0: float | list[float], **settings: object) -> Stepper:
    flat = {**load_settings(), **WAVE, **settings, 'particle.x0': x0}
    stepper = Stepper(build_model(flat))
    params = StrokeParams.from_flat(flat)
    n = stepper.model.n_actuators
    times, pos, vel, acc = sample_waveform(params, n)
    data = trajectory_cdr.encode(joint_names(n), np.round(times * 1e9), pos, vel, acc, to_time(0.0))
    stepper.command_trajectory(parse_trajectory_cdr(data, joint_names(n), stepper.limits))
    return stepper


def _run(stepper: Stepper, ticks: int) -> list[tuple[float, float, str]]:
    for _ in range(ticks):
        stepper.advance_parts(stepper.t + TICK)
    return [(p.x, p.xdot, p.mode) for p in stepper.parts_state.parts]


@pytest.mark.parametrize('piezo', [False, True])
def test_a_part_spawned_at_the_start_is_the_part_the_parameters_place(piezo: bool) -> None:
    placed = _stepper([-0.6e-3, 0.55e-3, 1.3e-3], **{'piezo.enabled': piezo})
    spawned = _stepper(0.55e-3, **{'piezo.enabled': piezo})
    assert spawned.spawn_part('part_2', 1.3e-3) == 1
    assert spawned.spawn_part('part_1', -0.6e-3) == 0
    assert spawned.entity_names == ['part_1', 'part_0', 'part_2']
    assert _run(spawned, 40) == _run(placed, 40)          # bit for bit, impacts included
    assert placed.parts_state.collisions == spawned.parts_state.collisions


def test_a_part_spawned_mid_run_rests_where_it_is_put_and_a_deleted_one_leaves_the_rest_as_alone() -> None:
    alone, stepper = _stepper(0.55e-3), _stepper(0.55e-3)
    _run(alone, 5)
    _run(stepper, 5)
    stepper.spawn_part('late', -1.4e-3)
    part = stepper.parts_state.parts[0]
    assert (part.x, part.xdot, part.mode, part.t) == (-1.4e-3, 0.0, 'stuck', stepper.t)
    assert part.y[4:].tolist() == stepper.parts_state.parts[1].y[4:].tolist()
    _run(stepper, 3)
    stepper.delete_part('late')
    assert stepper.parts is None and stepper.entity_names == ['part_0']
    _run(alone, 3)
    # the part far from the spawned one took the steps it takes alone
    assert _run(stepper, 30) == _run(alone, 30)


def test_what_cannot_be_placed_or_removed_is_refused_with_nothing_changed() -> None:
    stepper = _stepper([0.0, 0.5e-3])
    before = _run(stepper, 2)
    left, right = (p[0] for p in before)
    for name, x, reason in (('part_0', 1e-3, 'exists already'), ('a', right - 0.05e-3, f'the part at {right:.6g}'),
                            ('a', left + 0.05e-3, f'the part at {left:.6g}'), ('a', 2.0, 'within -1 m ... 1 m'),
                            ('a', float('nan'), 'within -1 m ... 1 m')):
        with pytest.raises(ValueError, match=reason):
            stepper.spawn_part(name, x)
    with pytest.raises(ValueError, match="no entity named 'b'"):
        stepper.delete_part('b')
    stepper.delete_part('part_0')
    with pytest.raises(ValueError, match='last part'):
        stepper.delete_part('part_1')
    assert stepper.entity_names == ['part_1'] and [p[0] for p in before][1] == stepper.parts_state.parts[0].x
    plate = _stepper(0.5e-3, **{'surface.thickness': 1e-4, 'piezo.enabled': False})
    with pytest.raises(ValueError, match='thickness'):
        plate.spawn_part('b', -0.5e-3)
    stepper.reset()
    assert stepper.entity_names == ['part_0', 'part_1'] and stepper.n_parts == 2


def test_an_entity_change_reads_back_as_written() -> None:
    changes = [EntityChange(SPAWNED, 'guest', 0, 0.0123456789012, -4.5e-4),
               EntityChange(DELETED, 'part_0', 1, 0.5, 1e-3)]
    for change in changes:
        assert read_entity_changes(change.message('feeder/simulator: entity')) == [change]
    bad = changes[0].message('simulator: entity')
    bad.status[0].values = bad.status[0].values[1:]
    with pytest.raises(ValueError, match='entity'):
        read_entity_changes(bad)


def test_the_plot_of_a_log_follows_each_part_by_its_name_through_spawns_and_deletes() -> None:
    from micro_feeder.cli.plot import _follow_parts
    # rows (x, mode) at t = 0, 1, 2, 3: part_0 at 5; 'b' spawned at 1 in front (x 9); 'a' spawned at 2 behind
    # (x 1); part_0 deleted at 3 (the changes show from the next row: the pose at t was published first)
    rows = [np.array([[5.0, 0]]), np.array([[5.0, 0], [9.0, 0]]), np.array([[1.0, 0], [5.0, 0], [9.0, 0]]),
            np.array([[1.0, 0], [9.0, 0]])]
    changes = [EntityChange(SPAWNED, 'b', 1, 0.5, 9.0), EntityChange(SPAWNED, 'a', 0, 1.5, 1.0),
               EntityChange(DELETED, 'part_0', 1, 2.5, 5.0)]
    names, table = _follow_parts([0.0, 1.0, 2.0, 3.0], rows, changes)
    assert names == ['part_0', 'b', 'a']
    x = table[:, :, 0]
    assert np.array_equal(x, np.array([[5, np.nan, np.nan], [5, 9, np.nan], [5, 9, 1], [np.nan, 9, 1]]),
                          equal_nan=True)
