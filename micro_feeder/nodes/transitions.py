"""The stamped transition stream ``particle/transitions``: one ``diagnostic_msgs/DiagnosticArray`` per mode
change, so that an outside client gets each event's exact sim time and kind with standard types.

Why DiagnosticArray: it is the standard message with a ``Header`` (the event's sim time as the stamp)
that carries named key/values, readable by every ROS tool and by the log readers without a custom
type; a ``std_msgs/String`` carries no time, and a bare ``Header`` would have to abuse ``frame_id``.
"""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

from ..physics.dynamics import Event
from .messages import FEEDER_FRAME, to_time

TRANSITION_KINDS = ('stick_to_slip', 'slip_to_stick', 'take_off', 'landing')


def transition_message(event: Event, source: str) -> DiagnosticArray:
    """``event`` as one status named ``{source}: transition`` (source: the node, ``feeder1/simulator``):
    ``message`` = the kind, key/values ``kind``, ``from``, ``to``, ``t_s`` (exact sim time, repr of the
    float) and ``x_m`` (position, m);
    ``header.stamp`` = the sim time rounded to the nanosecond, frame ``feeder``."""
    status = DiagnosticStatus(level=DiagnosticStatus.OK, name=f'{source}: transition', message=event.kind,
                              hardware_id='micro_feeder',
                              values=[KeyValue(key='kind', value=event.kind),
                                      KeyValue(key='from', value=event.from_mode),
                                      KeyValue(key='to', value=event.to_mode),
                                      KeyValue(key='t_s', value=repr(event.t)),
                                      KeyValue(key='x_m', value=repr(event.x))])
    return DiagnosticArray(header=Header(stamp=to_time(event.t), frame_id=FEEDER_FRAME), status=[status])
