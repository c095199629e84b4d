"""The record of parts spawned and deleted while the simulator runs (simulation_interfaces SpawnEntity and
DeleteEntity): ``simulator/entity_changes``, one ``diagnostic_msgs/DiagnosticArray`` per change, so that a log
says when the parts' number changed and ``resim`` applies the change at the same sim time.

Each change is one status named ``simulator: entity`` (the node's name): level OK, ``message`` = ``spawned``
or ``deleted``, hardware id ``micro_feeder``, key/values ``entity`` (its name), ``part`` (its index in order
along the feeder, where it was placed or what it had), ``t_s`` (the exact sim time, repr of the float) and
``x_m`` (its position, m); ``header.stamp`` = the sim time rounded to the nanosecond, frame ``feeder``. Rare
messages: built as message objects, not hand-written bytes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

from .names import FEEDER_FRAME
from .stamps import to_time

SPAWNED, DELETED = 'spawned', 'deleted'


@dataclass(frozen=True)
class EntityChange:
    """A part ``spawned`` or ``deleted`` (``kind``) at sim time ``t`` (s): its ``entity`` name, its ``part``
    index in order along the feeder and its position ``x`` (m)."""

    kind: str
    entity: str
    part: int
    t: float
    x: float

    def message(self, status_name: str) -> DiagnosticArray:
        """As the DiagnosticArray the simulator publishes, its status named ``status_name``
        (``simulator: entity``, the node's name first)."""
        values = [KeyValue(key='entity', value=self.entity), KeyValue(key='part', value=str(self.part)),
                  KeyValue(key='t_s', value=repr(self.t)), KeyValue(key='x_m', value=repr(self.x))]
        status = DiagnosticStatus(level=DiagnosticStatus.OK, name=status_name, message=self.kind,
                                  hardware_id='micro_feeder', values=values)
        return DiagnosticArray(header=Header(stamp=to_time(self.t), frame_id=FEEDER_FRAME), status=[status])


def read_entity_changes(message: Any) -> list[EntityChange]:
    """The changes a decoded ``simulator/entity_changes`` message carries (statuses of another kind skipped).
    Raises :class:`ValueError` for a status of this kind that lacks a field or has one that does not parse."""
    changes = []
    for status in message.status:
        if status.message not in (SPAWNED, DELETED):
            continue
        values = {kv.key: kv.value for kv in status.values}
        try:
            changes.append(EntityChange(status.message, values['entity'], int(values['part']),
                                        float(values['t_s']), float(values['x_m'])))
        except (KeyError, ValueError) as err:
            raise ValueError(f'an entity change without a readable {err}: {values}') from err
    return changes
