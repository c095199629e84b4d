"""Each command applies once: the simulator's memory of applied identities answers exactly as a set of every
identity ever applied would, and a stream's windows cost one run of that memory however long it streams."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from micro_feeder.interface.names import joint_names, split_window_id, window_id
from micro_feeder.settings import load_settings
from micro_feeder.sim.applied import AppliedCommands
from micro_feeder.sim.commands import DUPLICATE, CommandRejected, parse_trajectory_cdr
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import StrokeStream, encode_window

# identities that stress the split into stem and number: leading zeros, digits in the stem, no digits at all
STEMS = st.sampled_from(['', 'a', '/actuator:b1:w', '/actuator:b2:w', 'x0', 'x00', 'run7:', 'b'])
IDENTITIES = st.one_of(
    st.builds(lambda stem, n: f'{stem}{n}', STEMS, st.integers(0, 40)),
    st.builds(lambda stem, n: f'{stem}{n:03d}', STEMS, st.integers(0, 40)),
    st.text(alphabet='ab:/w0123', max_size=6),
)


@settings(max_examples=300, deadline=None)
@given(applied=st.lists(IDENTITIES, max_size=80), probes=st.lists(IDENTITIES, max_size=40))
def test_membership_is_that_of_the_set_of_identities_applied(applied: list[str], probes: list[str]) -> None:
    memory, reference = AppliedCommands(), set()
    for k, command_id in enumerate(applied):
        memory.add(command_id, k * 1e-3)
        reference.add(command_id)
    for command_id in [*applied, *probes]:
        assert (command_id in memory) == (command_id in reference), command_id
    assert len(memory) == len(reference)
    for command_id in applied[-10:]:
        assert memory.applied_at(command_id) == applied.index(command_id) * 1e-3


def test_a_long_stream_is_one_run() -> None:
    """A day of windows (35 a second), applied in order: one run, every window a duplicate afterwards."""
    memory = AppliedCommands()
    n = 35 * 86_400
    for k in range(1, n + 1):
        memory.add(window_id('/actuator:b1', k), k / 35)
    assert memory.runs() == 1 and len(memory) == n
    assert window_id('/actuator:b1', 1) in memory and window_id('/actuator:b1', n + 1) not in memory
    assert memory.applied_at(window_id('/actuator:b1', 1)) is None     # too old to say when
    assert memory.applied_at(window_id('/actuator:b1', n)) == pytest.approx(n / 35)


@given(stream=st.text(min_size=1, max_size=12), number=st.integers(0, 10**9))
def test_window_identities_split_back(stream: str, number: int) -> None:
    assert split_window_id(window_id(stream, number)) == (stream, number)


def test_a_window_resent_is_refused_as_a_duplicate_and_changes_nothing() -> None:
    stepper = Stepper(build_model(load_settings()))
    params = stepper.model.stroke
    stream = StrokeStream(params, 0, len(params.phases), 0, window=0.03, max_points=100, knots_per_stroke=0)
    windows, _ = stream.follow(0.0, 0.1)
    messages = [encode_window(w, window_id('s', k)) for k, w in enumerate(windows, start=1)]
    joints = joint_names(len(params.phases))
    for message in messages:
        stepper.command_trajectory(parse_trajectory_cdr(message, joints, stepper.limits))
    before = stepper.schedule.evaluate(0.05)
    first_applied = windows[1][0] * 1e-9       # a window stamped ahead applies from its stamp
    with pytest.raises(CommandRejected, match=f'{DUPLICATE} at t = {first_applied:.9f} s'):
        stepper.command_trajectory(parse_trajectory_cdr(messages[1], joints, stepper.limits))
    assert np.array_equal(stepper.schedule.evaluate(0.05), before)
    assert stepper.applied.runs() == 1 and len(stepper.applied) == len(messages)
