"""Sending strokes as ``control_msgs/action/FollowJointTrajectory`` goals, as a client of
joint_trajectory_controller does, and keeping what the simulator answered.

The actuator and the feed controller use it with ``command_interface: action``: each burst is one goal on
``simulator/follow_joint_trajectory``; the sender learns whether it was refused (and why), when it started
(its first feedback), and how it ended (succeeded, aborted with the error string, replaced, canceled).

A goal request can be lost in discovery as a topic message can (the server's side of the match not made
yet): nothing answers it. Its senders keep the burst until the simulator's receipt names it and send it again
as a new goal under the same identity (:class:`~.until_receipt.UntilReceipt`). The simulator applies an
identity once: a copy of a goal it applied is aborted as a duplicate, which is counted in ``repeated``, not
as a refusal, and does not call ``on_handled`` a second time for the same burst.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from trajectory_msgs.msg import JointTrajectory

from ..sim.commands import DUPLICATE

ACTION = 'simulator/follow_joint_trajectory'
COMMAND_INTERFACES = ('topic', 'action')    # the values of the senders' read-only command_interface parameter
STATUS_NAMES = {GoalStatus.STATUS_SUCCEEDED: 'succeeded', GoalStatus.STATUS_ABORTED: 'aborted',
                GoalStatus.STATUS_CANCELED: 'canceled'}


class GoalSender:
    """One node's FollowJointTrajectory goals: sent, running, and how each ended.

    ``on_handled()`` runs once per burst (a goal's ``header.frame_id``) when the simulator has handled it: at
    its first feedback (the trajectory is applied) or when it ended without one (refused, or a copy of it
    refused as a duplicate when the first copy's answers were lost). A lockstep sender grants its next step
    then, since a goal is not a grant. Counters: ``sent`` (goals, copies included), ``succeeded``,
    ``refused`` (ended other than succeeded or canceled: refused at once, aborted while running, replaced),
    ``repeated`` (copies of an applied burst, aborted as duplicates: not faults), ``canceled``; ``last`` = the
    last failure (identity: error string), as :class:`~._ros.RefusalWatch` keeps it."""

    def __init__(self, node: Node, on_handled: Callable[[], None] | None = None):
        self._node = node
        self._on_handled = on_handled
        self._client = ActionClient(node, FollowJointTrajectory, ACTION)
        self.sent = self.succeeded = self.refused = self.repeated = self.canceled = 0
        self.last = ''
        self._handled = ''                # the identity of the last burst on_handled ran for
        self.running: Any = None          # the running goal's handle (rclpy ClientGoalHandle), None when none
        self._running_name = ''           # and its burst's identity
        self.state = 'idle'               # idle, sent, running, succeeded, aborted, canceled, rejected

    def ready(self) -> bool:
        """True when the simulator's action server is on the graph and matched."""
        return self._client.server_is_ready()

    def send(self, trajectory: JointTrajectory) -> None:
        """Send ``trajectory`` (its ``header.frame_id`` names it) as a goal; the answers arrive on the executor."""
        self.sent += 1
        self.state = 'sent'
        handled = [False]
        name = trajectory.header.frame_id or f'goal {self.sent}'
        handle: list[Any] = [None]

        def handled_once() -> None:
            if not handled[0]:
                handled[0] = True
                if self._on_handled is not None and name != self._handled:
                    self._handled = name
                    self._on_handled()

        def on_feedback(_feedback: Any) -> None:
            if not handled[0]:
                self.state = 'running'
            handled_once()

        def on_result(future: Any) -> None:
            response = future.result()
            status, result = response.status, response.result
            if status == GoalStatus.STATUS_ABORTED and DUPLICATE in result.error_string:
                self.repeated += 1       # its first copy was applied and runs (or ran) on: not this goal's end
                self._node.get_logger().info(f'goal {name}: a copy of a burst the simulator applied, not '
                                             'applied again')
                if self.running is handle[0]:
                    self.running = None
                elif self.running is not None:
                    self.state = 'running'
                handled_once()
                return
            if self.running is handle[0]:
                self.running = None
            self.state = STATUS_NAMES.get(status, f'status {status}')
            if status == GoalStatus.STATUS_SUCCEEDED and result.error_code == result.SUCCESSFUL:
                self.succeeded += 1
                self._node.get_logger().info(f'goal {name} succeeded', throttle_duration_sec=1.0)
            elif status == GoalStatus.STATUS_CANCELED:
                self.canceled += 1
                self._node.get_logger().info(f'goal {name} canceled: {result.error_string}')
            else:
                self._failed(f'{name}: {self.state}: {result.error_string or f"error code {result.error_code}"}')
            handled_once()

        def on_goal(future: Any) -> None:
            handle[0] = future.result()
            if not handle[0].accepted:
                self.state = 'rejected'
                self._failed(f'{name}: rejected')
                handled_once()
                return
            if self.running is None or self._running_name != name:    # a copy leaves its first copy running
                self.running, self._running_name = handle[0], name
            handle[0].get_result_async().add_done_callback(on_result)

        self._client.send_goal_async(FollowJointTrajectory.Goal(trajectory=trajectory),
                                     feedback_callback=on_feedback).add_done_callback(on_goal)

    def send_copy(self, data: bytes) -> bool:
        """Send a serialized JointTrajectory (a burst awaiting its receipt, as first sent) again, as a new goal
        under the same identity: :class:`~.until_receipt.UntilReceipt`'s ``publish`` with the action."""
        self.send(deserialize_message(data, JointTrajectory))
        return True

    def _failed(self, what: str) -> None:
        """A goal refused, aborted or replaced: counted, kept as the last failure, logged (throttled)."""
        self.refused += 1
        self.last = what
        self._node.get_logger().warning(f'the simulator ended goal {what}', throttle_duration_sec=5.0)

    def cancel(self) -> bool:
        """Cancel the running goal (the simulator then holds the strokes where they are); False when none runs."""
        if self.running is None:
            return False
        self.running.cancel_goal_async()
        return True

    def destroy(self) -> None:
        self._client.destroy()
