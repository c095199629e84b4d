"""EventList: the events of a call kept as arrays, read as Event tuples."""

import numpy as np

from micro_feeder.physics.dynamics import Event, EventList, FeederModel


def test_items_slices_columns_and_equality():
    codes = np.array([[0, 0, 1], [1, 1, 0], [2, 1, 2]])
    values = np.array([[1e-4, 2e-6], [5e-4, 3e-6], [9e-4, 4e-6]])
    events = EventList(codes, values)
    expected = [Event(1e-4, 'stick_to_slip', 'stuck', 'sliding', 2e-6),
                Event(5e-4, 'slip_to_stick', 'sliding', 'stuck', 3e-6),
                Event(9e-4, 'take_off', 'sliding', 'flying', 4e-6)]
    assert len(events) == 3
    assert list(events) == expected
    assert events == expected and expected == events
    assert events[1] == expected[1] and events[-1] == expected[-1]
    assert events[1:] == expected[1:] and isinstance(events[1:], EventList)
    assert events != expected[:2] and events != [*expected[:2], expected[0]]
    np.testing.assert_array_equal(events.t, values[:, 0])
    np.testing.assert_array_equal(events.x, values[:, 1])
    assert EventList.concatenate([events[:1], EventList(), events[1:]]) == expected
    assert EventList() == [] and EventList.concatenate([]) == []


def test_advance_returns_what_the_state_counts():
    model = FeederModel()
    state = model.initial_state()
    events = model.advance(state, model.default_duration())
    kinds = [e.kind for e in events]
    assert len(events) >= 2
    for kind, count in state.transitions.items():
        assert kinds.count(kind) == count
    assert np.all(np.diff(events.t) >= 0.0) and events.t[-1] <= state.t
    assert [e.t for e in events] == events.t.tolist()
