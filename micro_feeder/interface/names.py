"""The names a client sees on the interface: contact modes, transition kinds (the counters' names too),
coordinate frames (REP 103, docs/dynamics.md §1) and actuator joints. The physics owns the mode and event
names; this module is where the rest of the package takes them from."""

from __future__ import annotations

from ..physics.dynamics import MODES, TRANSITION_KINDS

FEEDER_FRAME = 'feeder'     # x along the feeder, z up, y to the left
CONTACT_FRAME = 'contact'   # at the part: x along the surface tangent, z along its normal

__all__ = ['CONTACT_FRAME', 'FEEDER_FRAME', 'MODES', 'TRANSITION_KINDS', 'joint_names', 'part_entity',
           'receipt_frame', 'split_receipt_frame', 'split_window_id', 'window_id']


def part_entity(number: int) -> str:
    """A part's entity name (simulation_interfaces): ``part_0``, ``part_1``, ... for the parts of
    ``particle.x0`` in order along the feeder; a spawned part without a name of its own takes the next unused
    number."""
    return f'part_{number}'


def joint_names(n_actuators: int) -> list[str]:
    """The actuator joint names ``piezo_0`` ... in actuator order."""
    return [f'piezo_{k}' for k in range(n_actuators)]


RECEIPT_ID_SEPARATOR = '#'


def receipt_frame(topic: str, command_id: str = '') -> str:
    """The ``frame_id`` of a command receipt: the command's topic, then ``#`` and the command's identity (its
    JointTrajectory's ``header.frame_id``) when it has one: ``actuator/trajectory#/actuator:b1:w3``."""
    return f'{topic}{RECEIPT_ID_SEPARATOR}{command_id}' if command_id else topic


def split_receipt_frame(frame_id: str) -> tuple[str, str]:
    """(topic, command identity or '') of a receipt's ``frame_id`` (:func:`receipt_frame`)."""
    topic, _, command_id = frame_id.partition(RECEIPT_ID_SEPARATOR)
    return topic, command_id


WINDOW_MARK = ':w'      # a stream window's identity: <stream>:w<k>, k = 1, 2, ... in the order sent


def window_id(stream: str, window: int) -> str:
    """The identity of window number ``window`` (1 = the first) of the stream named ``stream``."""
    return f'{stream}{WINDOW_MARK}{window}'


def split_window_id(command_id: str) -> tuple[str, int] | None:
    """(stream, window number) of a stream window's identity (:func:`window_id`), None for any other."""
    stream, mark, number = command_id.rpartition(WINDOW_MARK)
    if not mark or not stream or not number.isdigit():
        return None
    return stream, int(number)
