"""One simulator per name: a second ``simulator`` in the same namespace would mix its states, commands and
logs with the first one's, so the newer of two stops.

Every simulator publishes its wall-clock start (``started_at_ns``) on its latched ``~/parameters``. A new one
reads that topic before it publishes anything (:meth:`TwinGuard.refuse_twin`: it refuses to start when an
older one answers) and keeps watching it, for an older twin that discovery showed too late.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rcl_interfaces.msg import ParameterEvent
from rclpy.node import Node

from ._ros import topic_qos
from .spin import NodeRefused

TWIN_WATCH_DEPTH = 10           # events of ~/parameters kept for the twin check (own ones included)
DUPLICATE_DISCOVERY_S = 0.5     # s after the node is created that the graph is watched for an older simulator


class DuplicateSimulator(NodeRefused):
    """Another simulator already publishes this one's state topics (same name and namespace): refused."""


class TwinGuard:
    """Watches ``~/parameters`` of ``node`` (a simulator started at ``started_at_ns``, wall clock) for a twin;
    ``on_twin(reason)`` stops the node when an older one shows up after its start. ``twins``: the start times
    of the older live twins seen; ``refusal``: why the node must not run on this graph ('' when it may)."""

    def __init__(self, node: Node, started_at_ns: int, on_twin: Callable[[str], None]):
        self.started_at_ns = started_at_ns
        self.twins: set[int] = set()
        self.refusal = ''
        self._on_twin = on_twin
        # 10 deep: this node's own events arrive here too, and a history of 1 let one of them overwrite a
        # twin's latched event before the executor took it (under load: the twin never seen, both ran)
        self._watch = node.create_subscription(ParameterEvent, '~/parameters', self._on_parameters,
                                               topic_qos('simulator/parameters', TWIN_WATCH_DEPTH))

    def refuse_twin(self, created: float) -> None:
        """Raise :class:`DuplicateSimulator` when a live simulator of this name (same node name and namespace)
        is on the graph: its latched ``~/parameters`` arrives within :data:`DUPLICATE_DISCOVERY_S` of the
        node's creation (``created``, :func:`time.monotonic`; read by hand: no executor spins the node yet, and
        it has published nothing). A dead one's leftover graph entries send nothing, so a restart is not
        refused. Slower discovery is caught later by :meth:`_on_parameters`."""
        while True:
            taken = self._watch.handle.take_message(ParameterEvent, False)
            if taken is not None:
                raise DuplicateSimulator(twin_message(taken[0].node))
            if time.monotonic() - created >= DUPLICATE_DISCOVERY_S:
                return
            time.sleep(0.02)

    def _on_parameters(self, msg: ParameterEvent) -> None:
        """``~/parameters`` of a simulator of this name: the node's own (same ``started_at_ns``), a newer twin
        (it stops itself on this node's event), or an older one that discovery showed too late for
        :meth:`refuse_twin`: the node then stops as on a failure, with the reason."""
        started = next((p.value.integer_value for p in msg.new_parameters if p.name == 'started_at_ns'), 0)
        if started == self.started_at_ns or started > self.started_at_ns or started in self.twins:
            return
        self.twins.add(started)
        self.refusal = twin_message(msg.node)
        self._on_twin(self.refusal)


def twin_message(node: str) -> str:
    """Why a simulator does not run beside another one named ``node`` (its fully qualified name)."""
    return (f'another simulator named {node} is running: two simulators in one namespace would mix their '
            'states, commands and logs. Start this one in its own namespace (--ros-args -r __ns:=/feeder2, '
            'or micro-feeder run --namespace feeder2), or stop the other')
