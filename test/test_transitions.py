"""The hand-serialized messages of the simulator's event stream: ``particle/transitions`` (DiagnosticArray)
and ``particle/contact_state`` (String) bytes read back by rclpy as the message docs/interface.md describes,
built here field by field with rclpy's classes (the reference), and as long as rclpy's own serialization."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header, String

from micro_feeder.interface.messages import contact_state_bytes
from micro_feeder.interface.names import TRANSITION_KINDS
from micro_feeder.interface.transitions import TransitionEncoder
from micro_feeder.physics.dynamics import Event

MODES = ('stuck', 'sliding', 'flying')


def _reference(event: Event, source: str) -> DiagnosticArray:
    """The message of docs/interface.md for ``event``, built with rclpy's classes."""
    ns = round(event.t * 1e9)
    status = DiagnosticStatus(level=DiagnosticStatus.OK, name=f'{source}: transition', message=event.kind,
                              hardware_id='micro_feeder',
                              values=[KeyValue(key='kind', value=event.kind),
                                      KeyValue(key='from', value=event.from_mode),
                                      KeyValue(key='to', value=event.to_mode),
                                      KeyValue(key='t_s', value=repr(event.t)),
                                      KeyValue(key='x_m', value=repr(event.x))])
    return DiagnosticArray(header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id='feeder'),
                           status=[status])


@pytest.mark.parametrize('source', ['simulator', 'feeder1/simulator', 'a/b/sim_a'])
def test_transition_bytes_read_back_as_the_documented_message(source: str) -> None:
    """Every kind and mode pair, with times and positions whose reprs have every length mod 4 (each
    shifts the alignment of what follows), and a stamp that rounds up to the next second."""
    rng = np.random.default_rng(7)
    encoder = TransitionEncoder(source)
    times = [0.0, 1e-3, 0.5, 2.9999999996, 12345.678901234, *(10.0 ** rng.uniform(-6, 4, 40))]
    positions = [0.0, -1e-5, 2.5e-4, *(rng.uniform(-1, 1, 40) * 10.0 ** rng.integers(-9, 0, 40))]
    lengths = set()
    for (kind, from_mode, to_mode), t, x in zip(itertools.cycle(itertools.product(TRANSITION_KINDS, MODES, MODES)),
                                                times, positions, strict=False):
        event = Event(t=float(t), kind=kind, from_mode=from_mode, to_mode=to_mode, x=float(x))
        data = encoder.encode(event)
        expected = _reference(event, source)
        assert deserialize_message(data, DiagnosticArray) == expected, event
        assert len(data) == len(serialize_message(expected)), event
        lengths.add(len(repr(event.t)) % 4)
    assert lengths == {0, 1, 2, 3}
    assert deserialize_message(encoder.encode(Event(2.9999999996, 'landing', 'flying', 'stuck', 0.0)),
                               DiagnosticArray).header.stamp == Time(sec=3, nanosec=0)


def test_a_ticks_transitions_of_several_parts_read_back_as_one_status_each() -> None:
    """``particles/transitions``: one message a tick holding every part's transitions in time order, each the
    status ``particle/transitions`` gives it plus ``part``, at every alignment a status can start on; the stamp
    is the first one's."""
    rng = np.random.default_rng(11)
    encoder = TransitionEncoder('feeder1/simulator')
    kinds = itertools.cycle(itertools.product(TRANSITION_KINDS, MODES, MODES))
    times = np.sort(10.0 ** rng.uniform(-6, 2, 200))
    transitions = [(Event(t=float(t), kind=kind, from_mode=a, to_mode=b, x=float(rng.uniform(-1, 1) * 1e-4)), part)
                   for (kind, a, b), t, part in zip(kinds, times, itertools.cycle((3, 42, 517, 1024, 8)), strict=False)]
    for count in (1, 2, 7, 200):
        items = transitions[:count]
        message = deserialize_message(encoder.encode_parts(items), DiagnosticArray)
        assert message.header == _reference(items[0][0], 'feeder1/simulator').header
        expected = [_reference(event, 'feeder1/simulator').status[0] for event, _ in items]
        for status, (_, part) in zip(expected, items, strict=True):
            status.values.append(KeyValue(key='part', value=str(part)))
        assert message.status == expected
    assert {phase for *_, phase in encoder._statuses} == {0, 1, 2, 3}     # statuses began at every alignment


@pytest.mark.parametrize('mode', MODES)
def test_contact_state_bytes_are_the_string(mode: str) -> None:
    assert deserialize_message(contact_state_bytes(mode), String) == String(data=mode)
