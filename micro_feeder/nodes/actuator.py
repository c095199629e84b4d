"""The ``actuator`` node: publishes the stroke waveform of the ``stroke.*`` parameters as JointTrajectory.

``~/start`` sends the configured burst on ``actuator/trajectory``: knots with positions, velocities and
accelerations of the analytic waveform, placed so that the quintic interpolation the simulator (and
joint_trajectory_controller) runs through them reproduces the schedule within 5e-13 m at every instant
(:mod:`micro_feeder.physics.trajectory`). ``~/stop`` stops: the stream ends and an empty trajectory
holds the strokes where they are. With ``auto_start`` the burst is sent once a simulator is reached. A
whole burst is sent again, the same bytes and identity, until the simulator's receipt names it
(:mod:`.until_receipt`: discovery can lose it). ``stroke.*`` may be changed at any time and apply to the
next start.

A burst that fits in one message (``stream.max_points`` knots, at most :data:`MESSAGE_BYTES`) goes out
whole, stamped 0 ("start on receipt"; ``stroke.delay`` is in the knot times): it needs nothing from the
simulator, so it works in lockstep too. A longer burst, or ``stroke.count`` 0 (strokes until ``~/stop``),
is **streamed**: the node follows sim time on ``actuator/joint_states`` and keeps ``stream.lead`` seconds
of the waveform scheduled ahead of it, in windows of at most ``stream.window`` s and one message's knots, each
stamped at its start in sim time (replace-from-start semantics: a window takes over exactly where the
previous one is, at a knot both share). Message size, memory and work per window are bounded whatever the
burst's length.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import SetParametersResult
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from ..interface import messages, stamps, trajectory_cdr
from ..interface.names import joint_names, split_window_id, window_id
from ..physics.parameters import ParamSpec
from ..physics.waveforms import StrokeParams
from ..settings import model_specs
from ..sim.commands import DUPLICATE
from ..sim.stream import StrokeStream, encode_stop, encode_window, points_per_message, sample_waveform
from ._ros import RefusalWatch, topic_qos
from .goal_sender import COMMAND_INTERFACES, GoalSender
from .parameters import check_changes, declare, values
from .refused import RefusedPublishes
from .spin import spin_node
from .until_receipt import UntilReceipt

REFUSED = 'the middleware refused it (a subscriber stalled, or no CPU)'


class NotSent(RuntimeError):
    """A burst or stop the middleware refused to take: nothing of it went out; sending it again may succeed."""


NODE_SPECS: dict[str, tuple[ParamSpec, Any]] = {
    'auto_start': (ParamSpec('send the burst once a simulator is reached (a whole burst again until its receipt)',
                             kind='bool', read_only=True),
                   True),
    'knots_per_stroke': (ParamSpec('minimum trajectory knots per stroke period (0: none); the waveform gets '
                                   'more where it needs them to be followed within 5e-13 m', kind='int', ge=0,
                                   le=10000), 0),
    'stream.max_points': (ParamSpec('knots per trajectory message at most; a longer burst is streamed in '
                                    'windows', kind='int', ge=16, le=100000), 2000),
    'stream.window': (ParamSpec('sim time one streamed message covers at most', 's', gt=0, le=10.0), 0.02),
    'stream.lead': (ParamSpec('a streamed burst is kept scheduled this far ahead of sim time', 's', gt=0, le=10.0),
                    0.2),
    'command_interface': (ParamSpec('how bursts are sent: "topic" (actuator/trajectory, whole or streamed) or '
                                    '"action" (each burst one FollowJointTrajectory goal: whole bursts only)',
                                    kind='str', choices=COMMAND_INTERFACES, read_only=True), 'topic'),
}
ACK_TIMEOUT_S = 1.0    # s an actuator that stops waits for its subscribers to acknowledge what it sent
GRAPH_SETTLE_S = 0.5   # s the trajectory topic's subscriptions must stay the same before an auto start
GRAPH_POLL_S = 0.05    # s between looks at which simulators the trajectory publisher reaches, while streaming
COUNT_SPEC = ParamSpec('number of strokes in the burst; 0 = strokes until ~/stop (streamed)', kind='int', ge=0)


class Actuator(Node):
    """Stroke waveform publisher: see the module docstring and docs/interface.md."""

    def __init__(self, overrides: Mapping[str, Any] | None = None, **kwargs: Any):
        super().__init__('actuator', **kwargs)
        self._stroke_specs = model_specs([StrokeParams])
        self._stroke_specs['stroke.count'] = (COUNT_SPEC, self._stroke_specs['stroke.count'][1])
        self._specs = {**self._stroke_specs, **NODE_SPECS}
        declare(self, self._specs, overrides)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self._pub = self.create_publisher(JointTrajectory, 'actuator/trajectory', topic_qos('actuator/trajectory'))
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', topic_qos('/diagnostics'))
        self.create_subscription(JointState, 'actuator/joint_states', self._on_sim_time,
                                 QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT), raw=True)
        self.create_service(Trigger, '~/start', self._on_start)
        self.create_service(Trigger, '~/stop', self._on_stop)
        self.bursts = 0
        self.stops = 0
        self.windows = 0
        self.underruns = 0
        self.rephases = 0                            # streams re-phased after a reset, restart or stall
        self.last_rephase = ''                       # why the stream last re-phased, in words
        self.sim_time: float | None = None           # latest sim time seen on actuator/joint_states (s)
        self._stream: StrokeStream | None = None
        self._pending_stream = False                 # streamed start waiting for the first sim time
        # the stream's messages the middleware refused, in order (window or not, message): sent again first
        self._outbox: deque[tuple[bool, bytes]] = deque()
        self._instance = f'{self.get_fully_qualified_name()}@{time.time_ns():x}'   # names this run's commands
        self.refusals = RefusalWatch(self, self._instance + ':', self._on_refused)   # the simulator's answers
        self.publishes = RefusedPublishes(self.get_logger())   # what the middleware refused to take, counted
        self.goals = GoalSender(self) if self.get_parameter('command_interface').value == 'action' else None
        # a whole burst is sent again until the simulator's receipt names it (lost in discovery otherwise)
        send_copy = (self.goals.send_copy if self.goals is not None
                     else lambda data: self.publishes.publish(self._pub, data))
        self.delivery = UntilReceipt(self, send_copy, lambda: self.goals.ready() if self.goals is not None
                                     else bool(self._simulator_subscriptions()))
        self._graph_seen: frozenset[bytes] | None = None   # the trajectory subscriptions seen ready, and since when
        self._graph_since = 0.0
        self._simulators: frozenset[bytes] = frozenset()   # trajectory subscriptions of the simulators reached
        self._matched = -1                           # trajectory subscriptions matched at the last look
        self._graph_looked = 0.0                     # monotonic time of that look (s)
        self._traj_topic = self._pub.topic_name
        self._joint_states_topic = self.resolve_topic_name('actuator/joint_states')
        self._auto = self.create_timer(0.05, self._auto_start) if self.get_parameter('auto_start').value else None
        self.create_timer(1.0, self._publish_diagnostics)
        self._warm_up()

    def _warm_up(self) -> None:
        """Build and encode one window of the configured strokes, unsent: the first call loads the compiled
        waveform code (0.2-0.7 s), which inside the first streamed window let sim time pass the strokes
        scheduled (an underrun at every start)."""
        encode_window(self._new_stream(0.0).next_window())

    # -- the burst ------------------------------------------------------------------------------------

    def _stroke_params(self) -> tuple[StrokeParams, int]:
        """(the stroke parameters with a count of at least 1, the configured count: 0 = endless)."""
        flat = values(self, self._stroke_specs)
        count = flat['stroke.count']
        return StrokeParams.from_flat({**flat, 'stroke.count': max(count, 1)}), count

    def start(self, held_at: float | None = None) -> str:
        """Send the burst: whole when it is finite and fits in ``stream.max_points`` knots, else start
        streaming it; with ``command_interface`` action, as one FollowJointTrajectory goal. Returns a one-line
        description; raises ValueError (nothing sent) for a streamed burst with the action, and
        :class:`NotSent` when the middleware refused the burst (start again). A stream starts
        ``stream.lead`` after the sim time it sees first, or at ``held_at`` (s) when the caller holds the
        simulator there until the first window has reached it (``micro-feeder run``)."""
        knots = self._whole_burst_knots()
        if self.goals is not None:
            return self._send_goal(knots)
        self._stream = None
        self._outbox.clear()
        self.delivery.settle()
        self.bursts += 1
        if knots is not None:
            times, pos, vel, acc = knots
            n = pos.shape[1]
            command_id = self._command_id()
            burst = trajectory_cdr.encode(joint_names(n), np.round(times * 1e9), pos, vel, acc, Time(), command_id)
            self.delivery.expect(command_id, burst)
            if not self.publishes.publish(self._pub, burst):
                self.delivery.settle()
                self.bursts -= 1                     # nothing of it went out: the next burst takes its number
                raise NotSent(f'burst not sent: {REFUSED}; start again')
            sent = f'burst sent: {times.size} knots on {n} joints, {times[-1]:.6g} s'
            if self._simulator_subscriptions():
                return sent
            return (f'{sent}; but no simulator is reached on actuator/trajectory yet (discovery), so only other '
                    f'subscribers get it: wait for simulator_reached on /diagnostics and start again')
        if held_at is not None:
            self._start_stream(held_at, lead=0.0)
        elif self.sim_time is None:
            self._pending_stream = True
            return 'burst streamed from the first sim time seen on actuator/joint_states'
        else:
            self._start_stream(self.sim_time)
        return f'burst streamed from t = {self._stream.origin_ns * 1e-9:.9f} s (sim time)'

    def _send_goal(self, knots: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None) -> str:
        """The burst as one FollowJointTrajectory goal, stamped 0 (start when the simulator handles it)."""
        if knots is None:
            raise ValueError('command_interface action sends whole bursts only, and this one is streamed '
                             '(stroke.count 0, or more knots than stream.max_points): send it on the topic '
                             '(command_interface topic) or raise stream.max_points')
        if not self.goals.ready():
            raise ValueError("the simulator's follow_joint_trajectory action server is not reached: nothing sent")
        self.bursts += 1
        times, pos, vel, acc = knots
        n = pos.shape[1]
        goal = messages.trajectory(joint_names(n), times, pos, vel, acc, Time())
        goal.header.frame_id = self._command_id()
        self.delivery.expect(goal.header.frame_id, serialize_message(goal))
        self.goals.send(goal)
        return f'burst sent as a FollowJointTrajectory goal: {times.size} knots on {n} joints, {times[-1]:.6g} s'

    def _whole_burst_knots(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """The configured burst's knots (:func:`sample_waveform`) when it is finite and fits in one message;
        None when :meth:`start` streams it."""
        params, count = self._stroke_params()
        if not count:
            return None
        n = len(params.phases)
        knots = sample_waveform(params, n, self.get_parameter('knots_per_stroke').value)
        return knots if knots[0].size <= points_per_message(self.get_parameter('stream.max_points').value, n) else None

    def _command_id(self, window: int | None = None) -> str:
        """The identity of a command this node sends (its trajectory's header.frame_id): node, process start,
        burst and window, so that the simulator applies each once and the log and the receipts name it."""
        burst = f'{self._instance}:b{self.bursts}'
        return burst if window is None else window_id(burst, window)

    def _simulator_subscriptions(self) -> frozenset[bytes] | None:
        """Endpoint ids of the ``actuator/trajectory`` subscriptions of simulators (nodes that also publish
        ``actuator/joint_states``), when every discovered subscription is matched with this node's publisher
        (what is sent now reaches them); None while some are discovered but not yet matched."""
        subscriptions = self.get_subscriptions_info_by_topic(self._traj_topic)
        if self._pub.get_subscription_count() < len(subscriptions):
            return None
        publishers = self.get_publishers_info_by_topic(self._joint_states_topic)
        simulators = {(i.node_namespace, i.node_name) for i in publishers}
        return frozenset(bytes(i.endpoint_gid) for i in subscriptions if (i.node_namespace, i.node_name) in simulators)

    def simulator_ready(self) -> bool:
        """True when a simulator (a node that subscribes to ``actuator/trajectory`` and publishes
        ``actuator/joint_states``) is on the graph, every discovered subscription of the trajectory topic is
        matched with this node's publisher, and the set of subscriptions has not changed for
        :data:`GRAPH_SETTLE_S`: a burst sent now reaches the simulator, and a recorder discovered a moment
        after it (which would miss the burst) has had time to appear. Another subscriber alone (a recorder, a
        viewer) is not enough."""
        ready = bool(self._simulator_subscriptions())
        seen = frozenset(bytes(i.endpoint_gid) for i in self.get_subscriptions_info_by_topic(self._traj_topic)) \
            if ready else None
        now = time.monotonic()
        if seen != self._graph_seen:
            self._graph_seen, self._graph_since = seen, now
        return ready and now - self._graph_since >= GRAPH_SETTLE_S

    def _look_for_simulators(self) -> tuple[bool, bool]:
        """(a simulator is reached, a new one appeared since the last look): looked up when the trajectory
        publisher's matches change, and every :data:`GRAPH_POLL_S` while streaming. A new simulator (restarted,
        or a second one) holds none of the strokes sent before it matched: the stream re-phases to it."""
        matched, now = self._pub.get_subscription_count(), time.monotonic()
        if matched == self._matched and now - self._graph_looked < GRAPH_POLL_S:
            return bool(self._simulators), False
        self._matched, self._graph_looked = matched, now
        simulators = self._simulator_subscriptions()
        if simulators is None:                       # one is discovered but not matched yet: wait for it
            return False, False
        new = bool(simulators - self._simulators)
        self._simulators = simulators
        return bool(simulators), new

    def trajectory_subscribers(self) -> int:
        """Subscriptions matched on ``actuator/trajectory``."""
        return self._pub.get_subscription_count()

    def stop(self) -> str:
        """End any stream and publish an empty trajectory (stop: hold the strokes where they are); with the
        action, cancel the running goal (the simulator holds the strokes where they are). Raises
        :class:`NotSent` when the middleware refused the stop (stop again)."""
        if self.goals is not None:
            self.delivery.settle()
            if not self.goals.cancel():
                return f'no goal running: nothing to stop (the last one {self.goals.state})'
            self.stops += 1
            return 'cancel sent'
        self._stream = None
        self._pending_stream = False
        self._outbox.clear()
        self.delivery.settle()
        n = len(self.get_parameter('stroke.phases').value)
        if not self.publishes.publish(self._pub, JointTrajectory(joint_names=joint_names(n))):
            raise NotSent(f'stop not sent: {REFUSED}; stop again')
        self.stops += 1
        return 'stop sent'

    def _new_stream(self, origin: float) -> StrokeStream:
        """A stream of the configured strokes whose time 0 falls at sim time ``origin`` (s)."""
        params, count = self._stroke_params()
        return StrokeStream(params, count, len(params.phases), round(origin * 1e9),
                            window=self.get_parameter('stream.window').value,
                            max_points=self.get_parameter('stream.max_points').value,
                            knots_per_stroke=self.get_parameter('knots_per_stroke').value)

    def _start_stream(self, now: float, lead: float | None = None) -> None:
        """Stream the burst from sim time ``now`` + ``lead`` (s; default ``stream.lead``)."""
        self._pending_stream = False
        self._simulators = self._simulator_subscriptions() or frozenset()
        self._stream = self._new_stream(now + (self.get_parameter('stream.lead').value if lead is None else lead))
        self._feed(now)

    def _feed(self, now: float) -> None:
        """Send what keeps ``stream.lead`` of strokes scheduled ahead of sim time ``now``, re-phasing first when
        sim time went back or passed the strokes (:meth:`StrokeStream.follow`); at a finite stream's end, a
        stop stamped there, so the simulator knows the stream ended rather than fell silent."""
        stream = self._stream
        reached, new_simulator = self._look_for_simulators()
        if not reached:                              # sent now, it would be lost: wait, re-phase when one is back
            return
        windows, why = stream.follow(now, self.get_parameter('stream.lead').value, new_simulator=new_simulator)
        if why is not None:
            self._outbox.clear()                     # they continued the strokes before the re-phase
            self.rephases += 1
            self.last_rephase = why
            self.underruns += 'passed the strokes' in why
            self.get_logger().warning(f'stream re-phased: {why}', throttle_duration_sec=5.0)
        for number, window in enumerate(windows, start=stream.windows_made - len(windows) + 1):
            self._outbox.append((True, encode_window(window, self._command_id(number))))
        if stream.done:
            self._stream = None
            self._outbox.append((False, encode_stop(stream.n_actuators, stream.scheduled_until,
                                                    self._command_id(stream.windows_made + 1))))
        self._send_outbox()

    def _send_outbox(self) -> None:
        """Send the stream's messages in order, up to the first the middleware refuses (counted:
        ``publishes_refused``, WARN); that one and those after it go again at the next sim time, so no strokes
        go missing. If a window has become late by then, the simulator refuses it (and the windows continuing
        it) and the stream re-phases (:meth:`_on_refused`)."""
        while self._outbox:
            is_window, message = self._outbox[0]
            if not self.publishes.publish(self._pub, message):
                return
            self._outbox.popleft()
            self.windows += is_window

    def _on_refused(self, command_id: str, reason: str) -> None:
        """The simulator refused one of this node's commands. When it is a window of the stream running that
        was not applied (late, or continuing one that was; a duplicate's first copy was applied), re-phase the
        stream, so that what follows is applied (:meth:`StrokeStream.refused`); the
        windows already sent after it are refused as well."""
        self.delivery.settle(command_id)
        window = split_window_id(command_id)
        if (window is None or window[0] != self._command_id() or self._stream is None or self.sim_time is None
                or DUPLICATE in reason):
            return
        why = self._stream.refused(window[1], self.sim_time, self.get_parameter('stream.lead').value)
        if why is not None:
            self._outbox.clear()                     # they continue the refused window: refused as well
            self.rephases += 1
            self.last_rephase = why
            self.get_logger().warning(f'stream re-phased: {why}', throttle_duration_sec=5.0)

    def _on_sim_time(self, data: bytes) -> None:
        self.sim_time = stamps.header_stamp(data)
        if self._pending_stream:
            origin_ns = round((self.sim_time + self.get_parameter('stream.lead').value) * 1e9)  # _start_stream's
            self._start_stream(self.sim_time)
            self.get_logger().info(f'burst streamed from t = {origin_ns * 1e-9:.9f} s (sim time)')
        elif self._stream is not None:
            self._feed(self.sim_time)
        elif self._outbox:                           # a finished stream's last window or stop, refused
            self._send_outbox()

    # -- ROS callbacks --------------------------------------------------------------------------------

    def _auto_start(self) -> None:
        """Send the burst once, when the simulator is there (:meth:`simulator_ready`); a burst the middleware
        refused is sent again on the next tick. The timer is gone after the start: a tick the executor had
        already queued finds ``_auto`` None and does nothing."""
        ready = self.goals.ready() if self.goals is not None else self.simulator_ready()
        if self._auto is None or not ready:
            return
        try:
            self.get_logger().info(self.start())
        except NotSent as err:
            self.get_logger().warning(f'auto_start: {err}: sending it again')
            return
        except ValueError as err:
            self.get_logger().error(f'auto_start: nothing sent: {err}')
        self.destroy_timer(self._auto)
        self._auto = None

    def destroy_node(self) -> None:
        """Wait (up to :data:`ACK_TIMEOUT_S`) until every subscriber acknowledged what was sent, then destroy:
        a reliable message not yet delivered to a slower subscriber (a recorder) dies with its publisher."""
        self._pub.wait_for_all_acked(Duration(nanoseconds=round(ACK_TIMEOUT_S * 1e9)))
        if self.goals is not None:
            self.goals.destroy()
        super().destroy_node()

    def state(self, reached: bool | None = None) -> str:
        """What the node is doing, in words: for /diagnostics and people (``reached``: whether a simulator is
        reached on actuator/trajectory, when the caller has just asked the graph)."""
        if self._auto is not None:
            return 'waiting for the simulator (auto_start)'
        if self.goals is not None:
            return f'goal {self.goals.state}' if self.goals.sent else 'idle'
        if self._pending_stream:
            return 'streaming: waiting for sim time on actuator/joint_states'
        if self._stream is None:
            return 'idle'
        if not (bool(self._simulator_subscriptions()) if reached is None else reached):
            return 'streaming: no simulator reached on actuator/trajectory, waiting for one'
        return f'streaming, {self.rephases} re-phase(s)' if self.rephases else 'streaming'

    def _on_start(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            response.success, response.message = True, self.start()
        except (ValueError, NotSent) as err:
            response.success, response.message = False, str(err)
        return response

    def _on_stop(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        try:
            response.success, response.message = True, self.stop()
        except NotSent as err:
            response.success, response.message = False, str(err)
        return response

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        # stroke.count 0 (endless) is the actuator's own: the stroke group is checked with one stroke
        checked = [Parameter('stroke.count', value=1) if p.name == 'stroke.count' and p.value == 0 else p
                   for p in params]
        current = values(self, self._stroke_specs)
        current['stroke.count'] = max(current['stroke.count'], 1)
        reason = check_changes(self._specs, current, checked, [StrokeParams])
        return SetParametersResult(successful=reason is None, reason=reason or '')

    def _publish_diagnostics(self) -> None:
        reached = bool(self._simulator_subscriptions())
        items = {'state': self.state(reached), 'bursts_sent': self.bursts, 'bursts_resent': self.delivery.resent,
                 'stops_sent': self.stops,
                 'windows_sent': self.windows, 'stream_underruns': self.underruns, 'stream_rephases': self.rephases,
                 'simulator_reached': reached,
                 'last_rephase': self.last_rephase,
                 'last_rephase_at': _seconds_text(getattr(self._stream, 'rephased_at', None)),
                 'streaming': self._stream is not None, 'subscribers': self._pub.get_subscription_count(),
                 'commands_refused': self.refusals.refused, 'last_refusal': self.refusals.last,
                 'publishes_refused': self.publishes.total()}
        if self.goals is not None:       # the goals' answers: refusals and failures come back in their results
            items.update({'goals_sent': self.goals.sent, 'goals_succeeded': self.goals.succeeded,
                          'goals_canceled': self.goals.canceled, 'commands_refused': self.goals.refused,
                          'last_refusal': self.goals.last})
        troubled = self.rephases or items['commands_refused'] or items['publishes_refused']
        status = DiagnosticStatus(name=f'{self.get_name()}: stroke', hardware_id='micro_feeder',
                                  level=DiagnosticStatus.WARN if troubled else DiagnosticStatus.OK,
                                  message=items['state'],
                                  values=[KeyValue(key=k, value=str(v)) for k, v in items.items()])
        self.publishes.publish(self._pub_diag, DiagnosticArray(header=Header(stamp=self.get_clock().now().to_msg()),
                                                               status=[status]))


def _seconds_text(t: float | None) -> str:
    """A sim time for /diagnostics: seconds to the µs, or empty when there is none."""
    return '' if t is None else f'{t:.6f}'


def main(args: list[str] | None = None) -> int:
    """Console script ``actuator``: ``actuator --ros-args -p stroke.count:=5 -p auto_start:=false``."""
    return spin_node('actuator', Actuator, args)
