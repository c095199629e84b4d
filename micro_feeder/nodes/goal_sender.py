"""Sending strokes as ``control_msgs/action/FollowJointTrajectory`` goals, as a client of
joint_trajectory_controller does, and keeping what the simulator answered.

The actuator and the feed controller use it with ``command_interface: action``: each burst is one goal on
``simulator/follow_joint_trajectory``; the sender learns whether it was refused (and why), when it started
(its first feedback), and how it ended (succeeded, aborted with the error string, replaced, canceled).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionClient
from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

ACTION = 'simulator/follow_joint_trajectory'
COMMAND_INTERFACES = ('topic', 'action')    # the values of the senders' read-only command_interface parameter
STATUS_NAMES = {GoalStatus.STATUS_SUCCEEDED: 'succeeded', GoalStatus.STATUS_ABORTED: 'aborted',
                GoalStatus.STATUS_CANCELED: 'canceled'}


class GoalSender:
    """One node's FollowJointTrajectory goals: sent, running, and how each ended.

    ``on_handled()`` runs once per goal when the simulator has handled it: at its first feedback (the
    trajectory is applied) or when it ended without one (refused). A lockstep sender grants its next step
    then, since a goal is not a grant. Counters: ``sent``, ``succeeded``, ``refused`` (ended other than
    succeeded or canceled: refused at once, aborted while running, replaced), ``canceled``; ``last`` = the
    last failure (identity: error string), as :class:`~._ros.RefusalWatch` keeps it."""

    def __init__(self, node: Node, on_handled: Callable[[], None] | None = None):
        self._node = node
        self._on_handled = on_handled
        self._client = ActionClient(node, FollowJointTrajectory, ACTION)
        self.sent = self.succeeded = self.refused = self.canceled = 0
        self.last = ''
        self.running: Any = None          # the running goal's handle (rclpy ClientGoalHandle), None when none
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

        def handled_once() -> None:
            if not handled[0]:
                handled[0] = True
                if self._on_handled is not None:
                    self._on_handled()

        def on_feedback(_feedback: Any) -> None:
            if not handled[0]:
                self.state = 'running'
            handled_once()

        def on_result(future: Any) -> None:
            response = future.result()
            status, result = response.status, response.result
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
            handle = future.result()
            if not handle.accepted:
                self.state = 'rejected'
                self._failed(f'{name}: rejected')
                handled_once()
                return
            self.running = handle
            handle.get_result_async().add_done_callback(on_result)

        self._client.send_goal_async(FollowJointTrajectory.Goal(trajectory=trajectory),
                                     feedback_callback=on_feedback).add_done_callback(on_goal)

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
