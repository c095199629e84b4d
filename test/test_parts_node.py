"""Several parts on the ROS interface (issue 28): the simulator node in-process with real rclpy, an outside
probe subscribed to every topic of the contract with its documented QoS, bounded waits."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from node_helpers import stamp_s
from rclpy.context import Context
from test_simulator_node import STEP, Rig, burst_message

from micro_feeder.interface.parts_messages import MODE_CODES, PART_STATE_FIELDS
from micro_feeder.settings import load_settings
from micro_feeder.sim.commands import parse_trajectory
from micro_feeder.sim.stepper import Stepper, build_model

X0 = [0.2e-3, 0.3e-3 + 1e-7, 0.6e-3]       # m: the bump at 0 pulls the parts in at different speeds: they meet
PARTS = {'particle.x0': X0, 'particle.size': 100e-6, 'particle.restitution': 0.5}


@pytest.fixture
def parts_rig(ros_context: Context) -> Iterator[Rig]:
    rig = Rig(ros_context, start_paused=True, step_period=STEP, **PARTS)
    yield rig
    rig.close()


def test_every_part_is_published_in_order_as_the_stepper_computes_it(parts_rig: Rig) -> None:
    """``particles/poses`` holds every part in order, ``particles/states`` their modes and velocities, part 0
    is also ``particle/pose``, and each part's transitions come on ``particles/transitions`` with its index:
    all as the Stepper computes them fed the same command at the same tick."""
    rig = parts_rig
    msg = burst_message(stamp=0.002)
    rig.wait(lambda: rig.probe.msgs['particle/contact_state'], 'latched initial contact state')
    rig.step(1)
    rig.send_trajectory(msg)
    n_steps = 12
    rig.step(n_steps - 1)
    assert rig.sim.rejected == 0

    stepper = Stepper(build_model({**load_settings(), **PARTS}))
    events: list[list] = [[] for _ in X0]
    for i in range(n_steps):
        if i == 1:
            stepper.command_trajectory(parse_trajectory(msg, ['piezo_0'], stepper.limits))
        for part, part_events in enumerate(stepper.advance_parts(stepper.t + STEP)):
            events[part] += [e for e in part_events if e.kind != 'reversal']
    assert stepper.parts_state.collisions >= 1, 'the scenario must have the parts meet'

    poses = rig.probe.msgs['particles/poses'][-1]
    assert poses.header.frame_id == 'feeder' and len(poses.poses) == len(X0)
    np.testing.assert_array_equal([p.position.x for p in poses.poses], stepper.parts_state.positions)
    assert rig.probe.msgs['particle/pose'][-1].pose.position.x == poses.poses[0].position.x
    states = rig.probe.msgs['particles/states'][-1]
    assert [d.label for d in states.layout.dim] == ['part', ','.join(PART_STATE_FIELDS)]
    table = np.asarray(states.data).reshape(len(X0), len(PART_STATE_FIELDS))
    np.testing.assert_array_equal(table[:, PART_STATE_FIELDS.index('xdot')], stepper.parts_state.velocities)
    assert table[:, 1].tolist() == [MODE_CODES[p.mode] for p in stepper.parts_state.parts]
    assert np.all(table[:, 0] == stepper.t)

    published = [(int(kv['part']), kv['kind'], float(kv['t_s'])) for kv in
                 ({v.key: v.value for v in status.values}
                  for m in rig.probe.msgs['particles/transitions'] for status in m.status)]
    for m in rig.probe.msgs['particles/transitions']:     # one message a tick, in time order, stamped at its first
        times = [float(next(v.value for v in status.values if v.key == 't_s')) for status in m.status]
        assert times == sorted(times) and stamp_s(m) == pytest.approx(times[0], abs=1e-9)
    expected = [(part, e.kind, e.t) for part, part_events in enumerate(events) for e in part_events]
    assert sorted(published) == sorted(expected) and len({p for p, _, _ in expected}) >= 2


def test_a_recorded_run_of_several_parts_resimulates_every_part_bit_for_bit(ros_context: Context, tmp_path) -> None:
    """The recorder keeps ``particles/poses``; ``resim`` of the log compares every part at every pose and finds
    them identical; with the last part started 10 µm further (part 0 unchanged) it says DIFFERENT, by that much
    (so every part is compared, not only part 0)."""
    from rclpy.parameter import Parameter

    from micro_feeder.logs.reader import LogReader
    from micro_feeder.nodes.recorder import Recorder
    from micro_feeder.sim.resim import resimulate

    rig = Rig(ros_context, start_paused=True, step_period=STEP, **PARTS)
    recorder = Recorder(context=ros_context, parameter_overrides=[Parameter('output', value=str(tmp_path / 'log')),
                                                                  Parameter('flush_period', value=0.2)])
    rig.executor.add_node(recorder)
    try:
        rig.wait(lambda: rig.probe.publishers_['actuator/trajectory'].get_subscription_count() == 3
                 and rig.sim.count_subscribers('particles/poses') == 2
                 and recorder.received['/simulator/parameters'] == 1, 'recorder matched')
        rig.send_trajectory(burst_message(0.0))
        rig.wait(lambda: recorder.received['/simulator/command_receipts'] == 1, 'receipt recorded')
        poses = recorder.received['/particles/poses']
        rig.step(12)
        rig.wait(lambda: recorder.received['/particles/poses'] == poses + 12, 'every pose recorded')
        collisions = rig.sim.stepper.parts_state.collisions
        final_modes = [p.mode for p in rig.sim.stepper.parts_state.parts]
        final_positions = rig.sim.stepper.parts_state.positions.tolist()
    finally:
        recorder.close()
        recorder.destroy_node()
        rig.close()
    assert collisions >= 1
    report = resimulate(LogReader(tmp_path / 'log'))
    assert report.parts == len(X0) and report.poses >= 12
    assert report.identical, report.verdict()
    assert f'of {len(X0)} parts' in report.verdict()
    moved = resimulate(LogReader(tmp_path / 'log'), {'particle.x0': [*X0[:-1], X0[-1] + 10e-6]})
    assert not moved.identical and 9e-6 < moved.max_error < 11e-6, moved.verdict()
    # info: every part's last recorded pose and mode; plot: the space-time picture beside the usual one
    from micro_feeder.cli import main
    from micro_feeder.logs.summary import summarize

    summary = summarize(LogReader(tmp_path / 'log'))
    assert [p.x for p in summary.parts] == final_positions
    assert [p.mode for p in summary.parts] == final_modes
    assert main(['plot', str(tmp_path / 'log'), '-o', str(tmp_path / 'run.png')]) == 0
    assert (tmp_path / 'run_parts.png').stat().st_size > 10_000



def test_every_part_is_an_entity_of_simulation_interfaces(parts_rig: Rig) -> None:
    """GetEntities lists part_0 … part_2; GetEntitiesStates gives each its pose (as particles/poses); a name
    filter and GetEntityState pick one; an unknown part is RESULT_NOT_FOUND."""
    from simulation_interfaces.msg import Result
    from simulation_interfaces.srv import GetEntities, GetEntitiesStates, GetEntityState

    rig = parts_rig
    rig.wait(lambda: rig.probe.msgs['particle/contact_state'], 'latched initial contact state')
    rig.send_trajectory(burst_message(stamp=0.0))
    rig.step(5)
    entities = rig.probe.call(rig.executor, GetEntities, 'simulator/get_entities')
    assert entities.result.result == Result.RESULT_OK and entities.entities == ['part_0', 'part_1', 'part_2']
    states = rig.probe.call(rig.executor, GetEntitiesStates, 'simulator/get_entities_states')
    poses = rig.probe.msgs['particles/poses'][-1]
    assert [s.pose.position.x for s in states.states] == [p.position.x for p in poses.poses]
    request = GetEntitiesStates.Request()
    request.filters.filter = '^part_[12]$'
    assert rig.probe.call(rig.executor, GetEntitiesStates, 'simulator/get_entities_states',
                          request).entities == ['part_1', 'part_2']
    one = rig.probe.call(rig.executor, GetEntityState, 'simulator/get_entity_state',
                         GetEntityState.Request(entity='part_2'))
    assert one.result.result == Result.RESULT_OK and one.state.pose.position.x == poses.poses[2].position.x
    missing = rig.probe.call(rig.executor, GetEntityState, 'simulator/get_entity_state',
                             GetEntityState.Request(entity='part_3'))
    assert missing.result.result == Result.RESULT_NOT_FOUND
