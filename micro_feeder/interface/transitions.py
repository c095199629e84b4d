"""The stamped transition stream ``particle/transitions``: one ``diagnostic_msgs/DiagnosticArray`` per mode
change, so that an outside client gets each event's exact sim time and kind with standard types.

Why DiagnosticArray: it is the standard message with a ``Header`` (the event's sim time as the stamp)
that carries named key/values, readable by every ROS tool and by the log readers without a custom
type; a ``std_msgs/String`` carries no time, and a bare ``Header`` would have to abuse ``frame_id``.

The messages are written as CDR bytes (``Publisher.publish(bytes)``): a part that slips and sticks every
1 kHz stroke makes ~3 transitions a tick, and building each as rclpy objects (a status, five key/values)
and letting ``publish`` serialize it cost ~60 µs, the largest share of the simulator's tick.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

from diagnostic_msgs.msg import DiagnosticStatus

from ..physics.dynamics import Event
from .cdr import ENCAPSULATION, STAMP, get_string, plain_end, put_string, put_uint32
from .names import FEEDER_FRAME
from .stamps import stamp_parts


class TransitionEncoder:
    """Serialized transition messages of one simulator (``source``: its node, ``feeder1/simulator``).

    Each event is one status named ``{source}: transition``: level OK, ``message`` = the kind, hardware id
    ``micro_feeder``, key/values ``kind``, ``from``, ``to``, ``t_s`` (exact sim time, repr of the float) and
    ``x_m`` (position, m), and with several parts ``part`` (its index, in order along the feeder);
    ``header.stamp`` = the sim time rounded to the nanosecond, frame ``feeder``. A status from its level to
    the key ``t_s`` depends only on (kind, from, to, whether a part is named, its alignment): it is kept per
    such key.
    """

    def __init__(self, source: str):
        self._source = source
        self._statuses: dict[tuple[str, str, str, bool, int], bytes] = {}

    def encode(self, event: Event, part: int | None = None) -> bytes:
        """``event`` (of part ``part``, when given) as the CDR bytes of its DiagnosticArray."""
        return self._encode([(event, part)])

    def encode_parts(self, transitions: list[tuple[Event, int]]) -> bytes:
        """Several parts' transitions (event, part index; in time order) as the CDR bytes of one DiagnosticArray,
        one status each as :meth:`encode` writes it with the part, ``header.stamp`` the first one's sim time: what
        ``particles/transitions`` carries once a tick (a publish cost ~16 µs, and 16 hopping parts change mode
        ~6 times a ms)."""
        return self._encode(transitions)

    def _encode(self, transitions: Sequence[tuple[Event, int | None]]) -> bytes:
        payload = bytearray(STAMP.pack(*stamp_parts(transitions[0][0].t)))
        put_string(payload, FEEDER_FRAME)
        put_uint32(payload, len(transitions))
        statuses = self._statuses
        for event, part in transitions:
            key = (event.kind, event.from_mode, event.to_mode, part is not None, len(payload) % 4)
            status = statuses.get(key)
            if status is None:
                status = statuses[key] = self._status(*key)
            payload += status
            put_string(payload, repr(event.t))
            put_string(payload, 'x_m')
            put_string(payload, repr(event.x))
            if part is not None:
                put_string(payload, 'part')
                put_string(payload, str(part))
        return ENCAPSULATION + payload

    def _status(self, kind: str, from_mode: str, to_mode: str, with_part: bool, phase: int) -> bytes:
        """A status from its level up to the key ``t_s``, starting ``phase`` bytes past a multiple of 4 of the
        payload (strings align on the payload's start)."""
        payload = bytearray(phase)
        payload += DiagnosticStatus.OK                              # level: one byte
        for text in (f'{self._source}: transition', kind, 'micro_feeder'):   # name, message, hardware id
            put_string(payload, text)
        put_uint32(payload, 6 if with_part else 5)                  # key/values
        for key, value in (('kind', kind), ('from', from_mode), ('to', to_mode)):
            put_string(payload, key)
            put_string(payload, value)
        put_string(payload, 't_s')
        return bytes(payload[phase:])


def status_messages(data: bytes) -> list[str] | None:
    """The ``message`` of each status of a serialized ``diagnostic_msgs/DiagnosticArray`` (little-endian CDR):
    a transition's kind, read from the bytes (a log holds two a stroke); None when they do not have the
    plain layout."""
    if len(data) < 16 or data[:2] != ENCAPSULATION[:2]:
        return None
    body = memoryview(data)[4:]
    unpack = struct.unpack_from
    out = []
    try:
        _, p = get_string(body, STAMP.size)                 # header: stamp, frame_id
        p += -p % 4
        (count,) = unpack('<I', body, p)
        p += 4
        if count > len(body):
            return None
        for _ in range(count):
            p += 1                                          # level: one byte
            p += -p % 4                                     # name
            p += 4 + unpack('<I', body, p)[0]
            message, p = get_string(body, p)
            p += -p % 4                                     # hardware_id
            p += 4 + unpack('<I', body, p)[0]
            p += -p % 4
            (values,) = unpack('<I', body, p)
            p += 4
            if values > len(body):
                return None
            for _ in range(2 * values):                     # key, value
                p += -p % 4
                p += 4 + unpack('<I', body, p)[0]
            out.append(message)
    except (ValueError, struct.error):
        return None
    return out if plain_end(body, p) else None
