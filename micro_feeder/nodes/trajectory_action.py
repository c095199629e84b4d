"""The simulator's ``control_msgs/action/FollowJointTrajectory`` server, with joint_trajectory_controller's
semantics and error codes.

A goal's ``trajectory`` is checked and applied exactly as a JointTrajectory on ``actuator/trajectory``
(:mod:`micro_feeder.sim.commands`, :meth:`Simulator.follow`): same rules, same reasons. What differs from
the topic is that the sender learns the outcome:

* refused: the goal is accepted and at once aborted with ``error_code`` INVALID_JOINTS (unknown, missing or
  repeated joints), OLD_HEADER_TIMESTAMP (stamped so late that it ended before it arrived) or INVALID_GOAL
  (anything else, e.g. a stroke outside the piezo travel; a ``multi_dof_trajectory``), the reason in
  ``error_string``. joint_trajectory_controller rejects such goals, and its client never learns why;
* running: feedback (``header.stamp`` = sim time, ``desired`` = the commanded s, ṡ, s̈, ``actual`` = the
  strokes as they are, ``error`` = desired − actual, ``index`` = the knot last passed), at most every
  :data:`FEEDBACK_PERIOD` of wall time while sim time moves, at the start and once more at the end;
* ``path_tolerance`` (position m, velocity m/s per joint; > 0 checks, 0 and −1 none, as
  joint_trajectory_controller without default tolerances): checked at every feedback while the goal runs
  (sampled, not between feedbacks); a miss aborts with PATH_TOLERANCE_VIOLATED and the strokes hold where
  they are. The ideal actuator follows the command exactly; with ``piezo.enabled`` the stack lags it;
* done: SUCCEEDED with SUCCESSFUL once sim time has passed the last knot and every ``goal_tolerance``
  (position, velocity) is met, checked from the last knot on for up to ``goal_time_tolerance`` of sim time
  (0: at the last knot only); ABORTED with GOAL_TOLERANCE_VIOLATED, naming the joints, when it is still not
  met then;
* replaced by a newer goal, a topic command or a reset: ABORTED with INVALID_GOAL and
  joint_trajectory_controller's "Current goal cancelled due to new incoming action." (it sets such a goal
  canceled, a transition rclpy's goal handle does not offer from executing);
* canceled: the strokes hold where they are (an empty trajectory, as the topic's stop), CANCELED with
  SUCCESSFUL.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Protocol

import numpy as np
from control_msgs.action import FollowJointTrajectory
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.node import Node
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from ..interface import stamps
from ..physics.dynamics import Observation
from ..sim.commands import TrajectoryCommand
from .sim_control import FEEDBACK_QOS, Busy, Yield

Result = FollowJointTrajectory.Result
FEEDBACK_PERIOD = 0.01   # s of wall time between two feedback messages of a goal, at least
TURN_WAIT = 0.002        # s a running goal hands the executor thread back for (GIL released) between checks
PREEMPTED = 'Current goal cancelled due to new incoming action.'    # joint_trajectory_controller's words


class FollowingSimulator(Protocol):
    """What the action server needs of :class:`micro_feeder.nodes.simulator.Simulator`."""

    command_serial: int
    error: str

    @property
    def joints(self) -> list[str]: ...

    def follow(self, message: JointTrajectory | None = None) -> tuple[int, float, TrajectoryCommand]: ...

    def strokes(self, t: float | None = None) -> tuple[np.ndarray, Observation]: ...

    def sim_time(self) -> float: ...


def check_joints(names: list[str], joints: list[str]) -> str:
    """'' when ``names`` are the simulator's ``joints`` exactly once each (any order), else the reason."""
    unknown = sorted(set(names) - set(joints))
    repeated = sorted({n for n in names if names.count(n) > 1})
    missing = [j for j in joints if j not in names]
    if not (unknown or repeated or missing):
        return ''
    parts = [f'{what} {", ".join(which)}' for what, which in (('unknown joints', unknown),
                                                              ('repeated joints', repeated),
                                                              ('missing joints', missing)) if which]
    return f'{"; ".join(parts)} (the simulator has {", ".join(joints)}, every one named once)'


def point(values: np.ndarray, t_from_start: float) -> JointTrajectoryPoint:
    """A JointTrajectoryPoint of (k, joints) rows: positions (m), velocities (m/s)[, accelerations (m/s²)]."""
    p = JointTrajectoryPoint(positions=values[0].tolist(), velocities=values[1].tolist(),
                             time_from_start=stamps.to_duration(max(t_from_start, 0.0)))
    if len(values) > 2:
        p.accelerations = values[2].tolist()
    return p


class TrajectoryAction:
    """``~/follow_joint_trajectory`` on ``node`` for ``simulator`` (see the module docstring)."""

    def __init__(self, node: Node, simulator: FollowingSimulator):
        self._sim = simulator
        self._wake = threading.Event()      # never set: a bounded, GIL-free wait between two checks of a goal
        self._server = ActionServer(node, FollowJointTrajectory, '~/follow_joint_trajectory',
                                    execute_callback=self._execute,
                                    goal_callback=lambda _goal: GoalResponse.ACCEPT,
                                    cancel_callback=lambda _goal: CancelResponse.ACCEPT,
                                    feedback_pub_qos_profile=FEEDBACK_QOS)

    def destroy(self) -> None:
        self._server.destroy()

    def _refuse(self, goal: ServerGoalHandle, code: int, reason: str) -> Any:
        goal.abort()
        return Result(error_code=code, error_string=reason)

    async def _execute(self, goal: ServerGoalHandle) -> Any:
        request = goal.request
        joints = self._sim.joints
        if request.multi_dof_trajectory.points or request.multi_dof_trajectory.joint_names:
            return self._refuse(goal, Result.INVALID_GOAL, 'multi_dof_trajectory: the actuators are single joints')
        trajectory: JointTrajectory = request.trajectory
        try:
            serial, start, command = self._sim.follow(trajectory)
        except Busy as err:
            return self._refuse(goal, Result.INVALID_GOAL, str(err))
        except ValueError as err:
            reason = check_joints(list(trajectory.joint_names), joints)
            if reason:
                return self._refuse(goal, Result.INVALID_JOINTS, reason)
            code = Result.OLD_HEADER_TIMESTAMP if 'ended before it arrived' in str(err) else Result.INVALID_GOAL
            return self._refuse(goal, code, str(err))
        base = start if command.stamp == 0.0 else command.stamp
        knots = base + command.offsets
        end = float(knots[-1]) if knots.size else start
        path_tolerances = tolerance_table(request.path_tolerance)
        goal_tolerances = tolerance_table(request.goal_tolerance)
        give_up = end + max(stamps.seconds(request.goal_time_tolerance), 0.0)   # sim time the goal must be met by
        last_feedback, fed_at = -np.inf, None      # wall time (s) and sim time (s) of the last feedback
        while True:
            if goal.is_cancel_requested:
                not_held = self._hold()
                goal.canceled()
                return Result(error_code=Result.SUCCESSFUL, error_string=f'canceled; the strokes not held: {not_held}'
                              if not_held else 'canceled: the strokes hold where they are')
            if self._sim.command_serial != serial:
                goal.abort()
                return Result(error_code=Result.INVALID_GOAL, error_string=PREEMPTED)
            if self._sim.error:
                goal.abort()
                return Result(error_code=Result.INVALID_GOAL, error_string=f'simulation stopped: {self._sim.error}')
            t = self._sim.sim_time()
            done = t >= end
            if done or (t != fed_at and time.monotonic() - last_feedback >= FEEDBACK_PERIOD):
                last_feedback, fed_at = time.monotonic(), t
                try:
                    error = self._feedback(goal, knots, base, min(t, end) if done else None)
                except Busy:
                    error = None
                if error is not None and not done:
                    miss = tolerance_misses(self._sim.joints, path_tolerances, error)
                    if miss:
                        not_held = self._hold()
                        miss += f' (the strokes not held: {not_held})' if not_held else ''
                        goal.abort()
                        return Result(error_code=Result.PATH_TOLERANCE_VIOLATED,
                                      error_string=f'at t = {error[2]:.9f} s: {miss}')
                if done and error is not None:
                    miss = tolerance_misses(self._sim.joints, goal_tolerances, error)
                    if not miss:
                        goal.succeed()
                        return Result(error_code=Result.SUCCESSFUL)
                    if t >= give_up:
                        goal.abort()
                        return Result(error_code=Result.GOAL_TOLERANCE_VIOLATED,
                                      error_string=f'at t = {error[2]:.9f} s: {miss}')
            self._wake.wait(TURN_WAIT)
            await Yield()

    def _hold(self) -> str:
        """Hold the strokes where they are (an empty trajectory: the topic's stop); '' when the simulator took
        it, else why not."""
        try:
            self._sim.follow()
        except (Busy, ValueError) as err:
            return str(err)
        return ''

    def _feedback(self, goal: ServerGoalHandle, knots: np.ndarray, base: float,
                  t: float | None) -> tuple[np.ndarray, np.ndarray, float]:
        """Publish the goal's feedback now; returns its error: position (m) and velocity (m/s) per joint,
        desired − actual, and the sim time (s) of the state."""
        desired, obs = self._sim.strokes(t)
        actual = np.vstack([obs.strokes, obs.stroke_velocities])
        joints = self._sim.joints
        feedback = FollowJointTrajectory.Feedback(
            header=Header(stamp=stamps.to_time(obs.t)), joint_names=joints,
            desired=point(desired, obs.t - base), actual=point(actual, obs.t - base),
            error=point(desired[:2] - actual, obs.t - base),
            index=max(int(np.searchsorted(knots, obs.t, side='right')) - 1, 0))
        goal.publish_feedback(feedback)
        return desired[0] - actual[0], desired[1] - actual[1], obs.t


def tolerance_table(tolerances: Any) -> dict[str, tuple[float, float]]:
    """{joint: (position m, velocity m/s)} of a sequence of control_msgs/JointTolerance: a value > 0 is a
    tolerance, 0 (the controller's default: none here) and −1 (none) are not."""
    return {tol.name: (tol.position, tol.velocity) for tol in tolerances if tol.position > 0.0 or tol.velocity > 0.0}


def tolerance_misses(joints: list[str], tolerances: dict[str, tuple[float, float]],
                     error: tuple[np.ndarray, np.ndarray, float]) -> str:
    """'' when every joint's error (position m, velocity m/s per joint, in ``joints`` order) is within its
    tolerance, else which joints miss, by how much."""
    misses = []
    for k, name in enumerate(joints):
        position, velocity = tolerances.get(name, (0.0, 0.0))
        if position > 0.0 and abs(error[0][k]) > position:
            misses.append(f'{name} {abs(error[0][k]):.3g} m from the trajectory, tolerance {position:g} m')
        if velocity > 0.0 and abs(error[1][k]) > velocity:
            misses.append(f'{name} {abs(error[1][k]):.3g} m/s from the trajectory, tolerance {velocity:g} m/s')
    return '; '.join(misses)
