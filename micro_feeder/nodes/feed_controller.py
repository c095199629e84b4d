"""The ``feed_controller`` example node: feeds the part to ``feed.target_x`` by firing stroke bursts.

It is a controller under test, as a lab would write one: it sees only the simulator's topics
(``particle/pose``, ``particle/twist``) and commands ``actuator/trajectory``, using sim time. Whenever the
part rests (ẋ = ż = 0 on a still surface, at least ``settle_time`` after the last burst ended) it asks the
:class:`~micro_feeder.control.feed_planner.FeedPlanner` for the next burst, until the part rests within
``feed.tolerance`` of the target. The outcome goes on the latched ``~/status`` and on
``/diagnostics``.

Decisions use only a pose and a twist with the same stamp, so they depend on the sim state alone and not
on which topic arrived first. With ``lockstep`` the node is also the simulator's clock master: after
deciding on the state at t it grants the next ``step_period`` (a trajectory it sends counts as the grant,
otherwise it calls ``simulator/step``), and never waits for sim time it has not granted. It grants the first
step itself as soon as ``simulator/step`` is available, and ignores the t = 0 state the simulator publishes
when it starts (that one answers no grant), so every run takes the same steps whatever the start-up timing.

A burst lost on its way (discovery matches the two ends one after the other; a message sent in between is
lost without an error; with the action, a goal request can be lost the same way) is not taken for a burst
that did not move the part: the simulator acknowledges each command, goals included, on
``simulator/command_receipts``. In lockstep, where sim time waits for the burst, the same bytes go
again (with the action, as a new goal under the same identity) until the receipt comes
(:class:`~.until_receipt.UntilReceipt`); in real time, where a copy sent later
would start mid-stroke, the burst is fired again, under the same identity, at the next decision on a part
at rest. Either way the simulator applies an identity once and refuses a copy of an applied burst as a
duplicate.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TwistStamped
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from std_msgs.msg import Header, String
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from ..control.feed_planner import Burst, FeedGoal, FeedPlanner
from ..interface import messages, stamps
from ..interface.names import joint_names
from ..physics.parameters import ParamSpec
from ..physics.waveforms import StrokeParams
from ..settings import model_specs
from ..sim.stream import sample_waveform
from ._ros import RefusalWatch, status_name, topic_qos
from .goal_sender import COMMAND_INTERFACES, GoalSender
from .parameters import declare, values
from .refused import RefusedPublishes
from .spin import spin_node
from .until_receipt import UntilReceipt

NODE_SPECS: dict[str, tuple[ParamSpec, Any]] = {
    'settle_time': (ParamSpec('sim time to wait after a burst ends before judging where the part rests', 's',
                              gt=0, le=1.0, read_only=True), 3e-3),
    'lockstep': (ParamSpec('drive the simulator in lockstep: grant one step after each decision',
                           kind='bool', read_only=True), False),
    'knots_per_stroke': (ParamSpec('trajectory knots per stroke period', kind='int', ge=2, le=10000,
                                   read_only=True), 40),
    'command_lead': (ParamSpec('real-time mode: a burst is stamped to start this long after the state it was '
                               'decided on; it must exceed the command latency, which includes working off a '
                               'backlog of state messages and sampling a long burst (up to ~20 ms measured '
                               'with the simulator in the same process); a late burst starts mid-stroke',
                               's', ge=0, le=1.0, read_only=True), 0.05),
    'command_interface': (ParamSpec('how bursts are sent: "topic" (actuator/trajectory) or "action" (each burst '
                                    'one FollowJointTrajectory goal; in lockstep the controller grants the next '
                                    'step once the simulator has handled the goal)', kind='str',
                                    choices=COMMAND_INTERFACES, read_only=True), 'topic'),
}
START_POLL_PERIOD = 0.05   # s (wall clock): how often a lockstep controller looks for the step service
STATUS_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)


class FeedController(Node):
    """Feed-to-target controller: see the module docstring and docs/hil.md."""

    def __init__(self, overrides: Mapping[str, Any] | None = None, **kwargs: Any):
        kwargs.setdefault('parameter_overrides', [Parameter('use_sim_time', value=True)])
        super().__init__('feed_controller', **kwargs)
        self._goal_specs = model_specs([FeedGoal])
        self._stroke_specs = model_specs([StrokeParams])
        declare(self, {**self._goal_specs, **self._stroke_specs, **NODE_SPECS}, overrides)
        self.goal = FeedGoal.from_flat(values(self, self._goal_specs))
        self.stroke = StrokeParams.from_flat(values(self, self._stroke_specs))
        self._settle = self.get_parameter('settle_time').value
        self._lockstep = self.get_parameter('lockstep').value
        self._knots = self.get_parameter('knots_per_stroke').value
        self._lead = self.get_parameter('command_lead').value
        self.planner = FeedPlanner(self.goal, travelling_wave=len(self.stroke.phases) > 1)
        # The first sampling of a waveform compiles (or loads) the JIT kernels: seconds or ~0.3 s that would
        # delay the first burst past its stamp, so pay it now, before any state arrives.
        sample_waveform(self.stroke, len(self.stroke.phases), self._knots)

        self._pub_trajectory = self.create_publisher(JointTrajectory, 'actuator/trajectory',
                                                     topic_qos('actuator/trajectory'))
        self._pub_status = self.create_publisher(String, '~/status', STATUS_QOS)
        self._pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', topic_qos('/diagnostics'))
        self._instance = f'{self.get_fully_qualified_name()}@{time.time_ns():x}'   # names this run's bursts
        self.refusals = RefusalWatch(self, self._instance + ':', self._on_refused)   # the simulator's answers
        self.publishes = RefusedPublishes(self.get_logger())   # what the middleware refused to take, counted
        self.goals = (GoalSender(self, on_handled=self._grant_step)   # a goal is not a grant
                      if self.get_parameter('command_interface').value == 'action' else None)
        # a burst with no receipt yet: sent again while sim time waits for it (lockstep) and only then
        send_copy = (self.goals.send_copy if self.goals is not None
                     else lambda data: self.publishes.publish(self._pub_trajectory, data))
        self.delivery = UntilReceipt(self, send_copy, lambda: self._lockstep and self._simulator_matched())
        self.bursts_refired = 0          # real time: bursts fired again, having had no receipt by the next decision
        self.create_subscription(PoseStamped, 'particle/pose', self._on_pose, topic_qos('particle/pose'))
        self.create_subscription(TwistStamped, 'particle/twist', self._on_twist, topic_qos('particle/twist'))
        self._step_client = self.create_client(Trigger, 'simulator/step') if self._lockstep else None
        steady = Clock(clock_type=ClockType.STEADY_TIME)     # sim time does not move until the first grant
        self._first_grant = (self.create_timer(START_POLL_PERIOD, self._grant_first_step, clock=steady)
                             if self._lockstep else None)
        self.create_timer(1.0, self._publish_diagnostics, clock=steady)

        self._poses: dict[int, PoseStamped] = {}
        self._twists: dict[int, TwistStamped] = {}
        self._burst: Burst | None = None
        self._burst_id = ''              # the identity (header.frame_id) the burst was sent under
        self._unsent: Burst | None = None    # the burst the middleware refused: fired again at the next decision
        self._burst_from_x = 0.0
        self._quiet_after = 0.0          # sim time (s) before which the part is not judged at rest
        self.start_time: float | None = None
        self.finish_time: float | None = None
        self.last_x = float('nan')
        self.last_t = 0.0
        self.commands_sent = 0
        self._told_waiting = False

    # -- state in ------------------------------------------------------------------------------------

    def _on_pose(self, msg: PoseStamped) -> None:
        self._poses[self._key(msg.header.stamp)] = msg
        self._try_decide(self._key(msg.header.stamp))

    def _on_twist(self, msg: TwistStamped) -> None:
        self._twists[self._key(msg.header.stamp)] = msg
        self._try_decide(self._key(msg.header.stamp))

    @staticmethod
    def _key(stamp: Time) -> int:
        return stamp.sec * 1_000_000_000 + stamp.nanosec

    def _try_decide(self, key: int) -> None:
        """Decide once the pose and twist of one sim time are both in (older unmatched ones are dropped)."""
        if key not in self._poses or key not in self._twists or (self._lockstep and key == 0):
            return
        pose, twist = self._poses.pop(key), self._twists.pop(key)
        for old in [k for k in self._poses if k < key]:
            del self._poses[old]
        for old in [k for k in self._twists if k < key]:
            del self._twists[old]
        self._decide(stamps.seconds(pose.header.stamp), pose.pose.position.x, twist)

    # -- control -------------------------------------------------------------------------------------

    @property
    def done(self) -> bool:
        return self.planner.status != 'running'

    def _decide(self, t: float, x: float, twist: TwistStamped) -> None:
        self.last_t, self.last_x = t, x
        if self.done:
            return
        if self.start_time is None:
            self.start_time = t
        at_rest = twist.twist.linear.x == 0.0 and twist.twist.linear.z == 0.0 and t >= self._quiet_after
        if not at_rest:
            self._grant_step()
            return
        if not self._lockstep and not self._simulator_listens():
            return
        if self._burst is not None:
            if self._unreceived():
                self.bursts_refired += 1
                self.get_logger().info(f'no receipt for {self._burst_id} by sim time {t:.6f} s (lost in '
                                       'discovery): fired again')
                self._fire(self._burst, t, x, self._burst_id)
                return
            self.planner.observe(self._burst, self._burst_from_x, x)
            self._burst = None
        burst = self._unsent if self._unsent is not None else self.planner.next_burst(x)
        self._unsent = None
        if burst is None:
            self._finish(t, x)
            return
        self._fire(burst, t, x)

    def _unreceived(self) -> bool:
        """Real time: has the last burst had no receipt (nor a refusal) yet? Its receipt left the
        simulator when the burst arrived, well before the burst's end, so none by now means the burst was
        lost; or, rarely, that the receipt was: then the burst fired again is refused as a duplicate, moves
        nothing, and the part is judged once its settle time has passed again."""
        return not self._lockstep and self.delivery.awaited == self._burst_id

    def _on_refused(self, command_id: str, reason: str) -> None:
        """The simulator refused a burst (or a copy of one it applied): it is not awaited any more."""
        self.delivery.settle(command_id)

    def _simulator_listens(self) -> bool:
        """Real-time mode: has ``actuator/trajectory`` a subscriber yet? A burst sent before it has one is
        lost (or, on a half-made match, delivered late and joined mid-stroke); the state keeps coming, so
        the controller decides again on the next one. Said once in the log while waiting."""
        if self._simulator_matched():
            return True
        if not self._told_waiting:
            self._told_waiting = True
            self.get_logger().info('waiting for the simulator (a subscriber on actuator/trajectory, or its '
                                   'follow_joint_trajectory action) before the first burst')
        return False

    def _simulator_matched(self) -> bool:
        """Is the simulator's end of the command interface matched: a subscriber on ``actuator/trajectory``,
        or its ``follow_joint_trajectory`` action server with the action?"""
        if self.goals is not None:
            return self.goals.ready()
        return self._pub_trajectory.get_subscription_count() > 0

    def _fire(self, burst: Burst, t: float, x: float, command_id: str = '') -> None:
        """Send ``burst`` stamped to start at t + ``command_lead`` + the wall time spent building it (sim
        time, real-time mode; a 20-stroke burst takes tens of ms to sample), or at t in lockstep, where the
        simulator waits. Judge the part again ``settle_time`` after the burst's end. ``command_id``: the
        identity of a burst fired again (its start position stays the one it was first fired from)."""
        building = time.perf_counter()
        phases = tuple(reversed(self.stroke.phases)) if burst.reversed_wave else self.stroke.phases
        stroke = dataclasses.replace(self.stroke, amplitude=burst.amplitude_m, count=burst.count, delay=0.0,
                                     pause=self.goal.stroke_pause, phases=phases)
        n = len(stroke.phases)
        msg = messages.trajectory(joint_names(n), *sample_waveform(stroke, n, self._knots), Time())
        start = t if self._lockstep else t + self._lead + (time.perf_counter() - building)
        msg.header.stamp = stamps.to_time(start)
        msg.header.frame_id = command_id or f'{self._instance}:b{self.commands_sent + 1}'
        self.delivery.expect(msg.header.frame_id, serialize_message(msg))
        if not self.send(msg):          # refused: fired again (the same burst) when the next state comes
            if command_id:              # still awaited: the next decision fires it again
                return
            self.delivery.settle()
            self._unsent = burst
            self._grant_step()          # lockstep: the command was to be the grant
            return
        if not command_id:
            self._burst_from_x = x
        self._burst, self._burst_id = burst, msg.header.frame_id
        self._quiet_after = start + stroke.burst_end_s() + self._settle

    def send(self, msg: JointTrajectory) -> bool:
        """Publish a command (in lockstep it also grants the simulator its next step), or send it as a goal
        (the grant follows once the simulator has handled it); False when the middleware refused it (counted
        in ``publishes_refused``, nothing sent)."""
        if self.goals is not None:
            self.goals.send(msg)
        elif not self.publishes.publish(self._pub_trajectory, msg):
            return False
        self.commands_sent += 1
        return True

    def _grant_step(self) -> None:
        if self._step_client is not None:
            self._step_client.call_async(Trigger.Request())

    def _grant_first_step(self) -> None:
        """Lockstep start: one grant as soon as the simulator's step service is there (and its action server,
        with the action: a goal sent before it is matched would be lost, and with it the grant)."""
        if self._step_client.service_is_ready() and (self.goals is None or self.goals.ready()):
            self.destroy_timer(self._first_grant)
            self._grant_step()

    def _finish(self, t: float, x: float) -> None:
        self.finish_time = t
        self.publishes.publish(self._pub_status, String(data=self.status_text()))
        self.get_logger().info(self.status_text())
        self._publish_diagnostics()

    # -- reporting -----------------------------------------------------------------------------------

    def result(self) -> dict[str, Any]:
        """The run's outcome: ``reached``, ``time_to_target_s`` (sim), ``strokes``, ``final_error_m``."""
        elapsed = None
        if self.finish_time is not None and self.start_time is not None and self.planner.status == 'reached':
            elapsed = self.finish_time - self.start_time
        return {'reached': self.planner.status == 'reached', 'status': self.planner.status,
                'reason': self.planner.reason, 'time_to_target_s': elapsed, 'strokes': self.planner.strokes,
                'bursts': self.planner.bursts, 'final_x_m': self.last_x,
                'final_error_m': self.goal.target_x - self.last_x}

    def status_text(self) -> str:
        """One line: the outcome, then the simulator's refusals of this controller's bursts, if any."""
        text = self._outcome_text()
        refused, last = self._refused()
        if refused:
            text += f' ({refused} burst(s) refused by the simulator, the last {last})'
        return text

    def _refused(self) -> tuple[int, str]:
        """(bursts the simulator refused, the last one and why): from simulator/command_status on the topic,
        from the goals' results with the action."""
        if self.goals is not None:
            return self.goals.refused, self.goals.last
        return self.refusals.refused, self.refusals.last

    def _outcome_text(self) -> str:
        r = self.result()
        if r['reached']:
            return (f"reached: x = {r['final_x_m'] * 1e3:.6f} mm, error {r['final_error_m'] * 1e6:+.3f} um, "
                    f"{r['strokes']} strokes in {r['bursts']} bursts, {r['time_to_target_s']:.6f} s sim time")
        if self.planner.status == 'unreachable':
            return f"unreachable: {r['reason']} (x = {r['final_x_m'] * 1e3:.6f} mm after {r['strokes']} strokes)"
        return f"running: x = {r['final_x_m'] * 1e3:.6f} mm, {r['strokes']} strokes so far"

    def _publish_diagnostics(self) -> None:
        level = {'reached': DiagnosticStatus.OK, 'running': DiagnosticStatus.OK}.get(self.planner.status,
                                                                                    DiagnosticStatus.ERROR)
        refused, last = self._refused()
        status = DiagnosticStatus(name=status_name(self, 'feed'), hardware_id='micro_feeder', level=level,
                                  message=self.status_text(),
                                  values=[KeyValue(key=k, value=str(v)) for k, v in
                                          {**self.result(), 'commands_refused': refused,
                                           'last_refusal': last,
                                           'bursts_resent': self.delivery.resent + self.bursts_refired,
                                           'publishes_refused': self.publishes.total()}.items()])
        self.publishes.publish(self._pub_diag, DiagnosticArray(header=Header(stamp=stamps.to_time(self.last_t)),
                                                               status=[status]))


def main(args: list[str] | None = None) -> int:
    """Console script ``feed_controller``: ``feed_controller --ros-args -p feed.target_x:=0.45e-3``."""
    return spin_node('feed_controller', FeedController, args)
