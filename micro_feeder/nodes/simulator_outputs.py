"""What the ``simulator`` node publishes, and how: the state topics of docs/interface.md and the records a log
needs (``~/parameters``, ``~/command_receipts``, ``~/command_status``, ``~/entity_changes``, the copies of the
commands received).

:class:`SimulatorOutputs` owns the publishers and the per-model message buffers (state messages with one
joint per actuator, per-part messages, surface markers) that :meth:`~SimulatorOutputs.configure` rebuilds
for each model. It is the engine's :class:`~micro_feeder.sim.engine.Outputs`, called with the engine's lock
held, between two ticks (a batch's receipts just after it); the node publishes ``~/parameters`` and
``/diagnostics`` on :attr:`~SimulatorOutputs.parameters` and :attr:`~SimulatorOutputs.diagnostics`. A message
the middleware refuses is counted in :attr:`~SimulatorOutputs.refused` (:mod:`.refused`), and publishing goes on.
"""

from __future__ import annotations

import math
import time
from collections.abc import Collection, Sequence
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, TwistStamped, WrenchStamped
from rcl_interfaces.msg import ParameterEvent
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, String
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from ..interface import messages
from ..interface.entity_changes import EntityChange
from ..interface.names import joint_names, receipt_frame
from ..interface.parts_messages import PartsMessages
from ..interface.topics import ENTITY_CHANGES, RECEIVED_COPIES
from ..interface.transitions import TransitionEncoder
from ..physics.dynamics import Event
from ..physics.dynamics.model import ObservedParts
from ..realtime.intake import Received
from ..sim.stepper import Stepper
from ._ros import status_name, topic_qos
from .refused import RefusedPublishes

PART_SIZE = 100e-6     # marker diameter of the part (m)
MARKER_POINTS = 200    # points of the surface line strip
COMMAND_TYPES = {'actuator/trajectory': JointTrajectory, 'actuator/command': Float64MultiArray}


class SimulatorOutputs:
    """The simulator node's publishers. ``publish_clock``: sim time goes out on ``/clock`` too;
    ``markers_period``: wall seconds between two ``surface/markers`` (the state topics go out every tick)."""

    def __init__(self, node: Node, stepper: Stepper, *, publish_clock: bool, markers_period: float):
        def publisher(msg_type: type, topic: str, name: str | None = None) -> Any:
            return node.create_publisher(msg_type, name or topic, topic_qos(topic))

        self._pub_pose = publisher(PoseStamped, 'particle/pose')
        self._pub_twist = publisher(TwistStamped, 'particle/twist')
        self._pub_wrench = publisher(WrenchStamped, 'particle/contact_wrench')
        self._pub_joints = publisher(JointState, 'actuator/joint_states')
        self._pub_mode = publisher(String, 'particle/contact_state')
        self._pub_transitions = publisher(DiagnosticArray, 'particle/transitions')
        self._pub_markers = publisher(MarkerArray, 'surface/markers')
        self._pub_part_poses = publisher(PoseArray, 'particles/poses')
        self._pub_part_states = publisher(Float64MultiArray, 'particles/states')
        self._pub_part_transitions = publisher(DiagnosticArray, 'particles/transitions')
        self._pub_clock = publisher(ClockMsg, '/clock') if publish_clock else None
        self.diagnostics = publisher(DiagnosticArray, '/diagnostics')
        self.parameters = publisher(ParameterEvent, 'simulator/parameters', '~/parameters')
        self._pub_receipts = publisher(Header, 'simulator/command_receipts', '~/command_receipts')
        self._pub_status = publisher(DiagnosticArray, 'simulator/command_status', '~/command_status')
        self._pub_entity_changes = publisher(DiagnosticArray, ENTITY_CHANGES, '~/entity_changes')
        self._pub_received = {topic: publisher(COMMAND_TYPES[topic], copy, '~/' + copy.split('/')[-1])
                              for topic, copy in RECEIVED_COPIES.items()}
        self.refused = RefusedPublishes(node.get_logger())
        self._send = self.refused.publish
        self._markers_period = markers_period
        self._last_markers = -float('inf')
        self._transitions = TransitionEncoder(status_name(node, 'transition').removesuffix(': transition'))
        self._command_status_name = status_name(node, 'command')
        self._entity_status_name = status_name(node, 'entity')
        self.configure(stepper)

    def configure(self, stepper: Stepper) -> None:
        """Per-model output buffers: the state messages (one joint per actuator), the parts' messages and the
        surface markers; the next contact state goes out whatever it is."""
        self._mode = ''
        self._state_messages = messages.StateMessages(joint_names(stepper.model.n_actuators))
        self._parts_messages = PartsMessages(stepper.n_parts)
        surface = stepper.model.surface
        c, w = np.asarray(surface.centers), np.asarray(surface.widths)
        xs = np.linspace(float(np.min(c - 4 * w)), float(np.max(c + 4 * w)), MARKER_POINTS)
        track = stepper.model.track
        self._markers = messages.SurfaceMarkers(
            xs, surface.centers, surface.widths, PART_SIZE,
            math.sin(track.vibration_angle) if surface.kind == 'track' else None)

    def publish_state(self, observed: ObservedParts, events: Sequence[Sequence[Event]]) -> None:
        """Publish the state now (every part's outputs, in part order), with ``events`` (each part's mode
        changes since the last time)."""
        obs = observed[0]
        parts = self._parts_messages
        parts.update(observed)
        self._send(self._pub_part_poses, parts.poses)
        self._send(self._pub_part_states, parts.states)
        transitions = [(event, part) for part, part_events in enumerate(events) if len(part_events)
                       for event in part_events if event.kind != 'reversal']
        if transitions:
            transitions.sort(key=lambda item: item[0].t)
            self._send(self._pub_part_transitions, self._transitions.encode_parts(transitions))
        events = events[0] if events else []
        state = self._state_messages
        stamp = state.update(obs, obs.stroke_velocities)
        self._send(self._pub_pose, state.pose)
        self._send(self._pub_twist, state.twist)
        self._send(self._pub_wrench, state.wrench)
        self._send(self._pub_joints, state.joints)
        for event in events:
            if event.kind != 'reversal':
                self._send(self._pub_transitions, self._transitions.encode(event))
                self._publish_mode(event.to_mode)
        self._publish_mode(obs.mode)
        if self._pub_clock is not None:
            self._send(self._pub_clock, state.clock)
        now = time.perf_counter()
        if now - self._last_markers >= self._markers_period:
            self._last_markers = now
            self._send(self._pub_markers, self._markers.update(obs, stamp))

    def _publish_mode(self, mode: str) -> None:
        if mode != self._mode:
            self._mode = mode
            self._send(self._pub_mode, messages.contact_state_bytes(mode))

    def parts_changed(self, n_parts: int, change: EntityChange) -> None:
        """A part spawned or deleted: buffers for ``n_parts`` parts, and the change on ``~/entity_changes``."""
        self._parts_messages = PartsMessages(n_parts)
        self._send(self._pub_entity_changes, change.message(self._entity_status_name))

    def copy_received(self, topic: str, message: Any) -> None:
        """A command received on ``topic`` (serialized, or a goal's trajectory) on its copy
        (``simulator/trajectories_received``): what a recorder holds whichever senders it discovered."""
        if topic in self._pub_received:
            self._send(self._pub_received[topic], message)

    def acknowledge(self, received: Received, t: float) -> None:
        """``~/command_receipts``: a command arrived on its topic (with its identity, if it has one) and was
        handled at sim time ``t`` (s)."""
        self._send(self._pub_receipts, messages.header_bytes(t, receipt_frame(received.topic, received.command_id)))

    def answer(self, received: Received, t: float, refusal: str) -> None:
        """``~/command_status``: why the command received at sim time ``t`` (s) was not applied (refusals only)."""
        if refusal:     # published as bytes: a flood of refusals is answered one by one
            self._send(self._pub_status, messages.command_status(
                t, receipt_frame(received.topic, received.command_id), self._command_status_name,
                received.topic, received.command_id, refusal))

    def matched(self, recorded_in_process: Collection[str] = ()) -> bool:
        """True when every state topic has at least one subscription matched (a recorder that has not yet
        matched a topic would miss its first messages), not counting the topics ``recorded_in_process``
        (absolute names)."""
        return all(pub.get_subscription_count() > 0 or pub.topic_name in recorded_in_process for pub in
                   (self._pub_pose, self._pub_twist, self._pub_wrench, self._pub_joints, self._pub_mode,
                    self._pub_transitions, self._pub_markers, self.parameters, self._pub_receipts,
                    self._pub_part_poses, self._pub_part_states, self._pub_part_transitions,
                    *self._pub_received.values()))
