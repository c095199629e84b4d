"""The ROS standards on the real ``simulator`` executable, as a lab stack's client sees them: simulation_interfaces
2.0.0 services and the SimulateSteps action, control_msgs' FollowJointTrajectory, and the answer to a refused
topic command on ``simulator/command_status``. One simulator process (started paused) serves every test of the
module, in order; each test leaves it paused."""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import Any

import pytest
import rclpy
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from node_helpers import Probe, start_process, stop_process
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile
from ros_helpers import wait_until
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import EntityCategory, Result, SimulationState, SimulatorFeatures
from simulation_interfaces.srv import (
    DeleteEntity,
    GetEntities,
    GetEntitiesStates,
    GetEntityState,
    GetSimulationState,
    GetSimulatorFeatures,
    ResetSimulation,
    SetSimulationState,
    SpawnEntity,
    StepSimulation,
)
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from micro_feeder.nodes._ros import RefusalWatch

TICK_NS = 1_000_000      # step_period 1 ms (the default)
DEEP = QoSProfile(depth=1000)


class Session:
    """The simulator process and an outside client (the Probe listens to every topic of the contract)."""

    def __init__(self, context: Context):
        self.probe = Probe(context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.probe)

    def call(self, srv_type: type, name: str, request: Any = None, timeout: float = 10.0) -> Any:
        return self.probe.call(self.executor, srv_type, f'simulator/{name}', request, timeout)

    def state(self) -> int:
        return self.call(GetSimulationState, 'get_simulation_state').state.state

    def set_state(self, state: int) -> Result:
        return self.call(SetSimulationState, 'set_simulation_state',
                         SetSimulationState.Request(state=SimulationState(state=state))).result

    def entity(self) -> Any:
        response = self.call(GetEntityState, 'get_entity_state', GetEntityState.Request(entity='part_0'))
        assert response.result.result == Result.RESULT_OK, response.result.error_message
        return response.state

    def send_goal(self, action_type: type, name: str, goal: Any) -> tuple[Any, list]:
        """(goal handle, the feedback list that fills while it runs)."""
        client = ActionClient(self.probe, action_type, f'simulator/{name}', feedback_sub_qos_profile=DEEP)
        wait_until(client.server_is_ready, 10, executor=self.executor, what=f'action server {name}')
        # server_is_ready looks at the action's services only: feedback published before this client's
        # feedback subscription is discovered is lost (volatile), so wait for the server's feedback publisher
        wait_until(lambda: self.probe.count_publishers(f'/simulator/{name}/_action/feedback') > 0, 10,
                   executor=self.executor, what=f'{name} feedback publisher discovered')
        feedback: list = []
        future = client.send_goal_async(goal, feedback_callback=lambda msg: feedback.append(msg.feedback))
        wait_until(future.done, 10, executor=self.executor, what=f'{name} goal response')
        handle = future.result()
        assert handle.accepted
        return handle, feedback

    def result(self, handle: Any, timeout: float = 20.0) -> Any:
        future = handle.get_result_async()
        wait_until(future.done, timeout, executor=self.executor, what='action result')
        return future.result()

    def publish(self, topic: str, msg: Any) -> Any:
        """Publish a command and return its receipt from ``simulator/command_receipts``."""
        receipts = self.probe.msgs['simulator/command_receipts']
        count = len(receipts)
        self.probe.publish(topic, msg, self.executor)
        wait_until(lambda: len(receipts) > count, 10, executor=self.executor, what=f'receipt of {topic}')
        return receipts[count]


@pytest.fixture(scope='module')
def session() -> Iterator[Session]:
    context = Context()
    rclpy.init(context=context)
    sim = start_process('simulator', '-p', 'start_paused:=true', '-p', 'markers_rate:=1.0')
    s = Session(context)
    try:
        # up to 120 s: a fresh process compiles the physics kernel when numba's cache is stale
        s.call(GetSimulatorFeatures, 'get_simulator_features', timeout=120)
        yield s
    finally:
        s.executor.shutdown()
        s.probe.destroy_node()
        code, out = stop_process(sim)
        rclpy.shutdown(context=context)
    assert code == 0 and 'Traceback' not in out, out


def stroke(joint: str = 'piezo_0', amplitude: float = 100e-6, duration: float = 1e-3, knots: int = 33,
           frame_id: str = '') -> JointTrajectory:
    """README's raised-cosine stroke s = A/2 (1 − cos 2π t/T) with exact s, ṡ, s̈ (stamp 0: on receipt)."""
    w = 2 * math.pi / duration
    msg = JointTrajectory(joint_names=[joint])
    msg.header.frame_id = frame_id
    for k in range(knots):
        t = k * duration / (knots - 1)
        msg.points.append(JointTrajectoryPoint(
            positions=[amplitude / 2 * (1 - math.cos(w * t))], velocities=[amplitude / 2 * w * math.sin(w * t)],
            accelerations=[amplitude / 2 * w ** 2 * math.cos(w * t)], time_from_start=Duration(nanosec=round(t * 1e9))))
    return msg


def pose_key(state: Any) -> tuple:
    """Everything an EntityState says, as exact values."""
    p, q, v = state.pose.position, state.pose.orientation, state.twist.linear
    return (state.header.stamp.sec, state.header.stamp.nanosec, state.header.frame_id,
            p.x, p.y, p.z, q.x, q.y, q.z, q.w, v.x, v.y, v.z)


def test_features_and_the_start_state(session: Session) -> None:
    features = session.call(GetSimulatorFeatures, 'get_simulator_features').features
    assert sorted(features.features) == sorted([
        SimulatorFeatures.SPAWNING, SimulatorFeatures.DELETING,
        SimulatorFeatures.ENTITY_STATE_GETTING, SimulatorFeatures.SIMULATION_RESET,
        SimulatorFeatures.SIMULATION_STATE_GETTING, SimulatorFeatures.SIMULATION_STATE_SETTING,
        SimulatorFeatures.SIMULATION_STATE_PAUSE, SimulatorFeatures.STEP_SIMULATION_SINGLE,
        SimulatorFeatures.STEP_SIMULATION_MULTIPLE, SimulatorFeatures.STEP_SIMULATION_ACTION])
    assert 'part_0' in features.custom_info and list(features.spawn_formats) == ['part']
    assert session.state() == SimulationState.STATE_STOPPED       # started paused at t = 0
    entities = session.call(GetEntities, 'get_entities')
    assert entities.result.result == Result.RESULT_OK and list(entities.entities) == ['part_0']


def test_unsupported_or_unknown_requests_answer_at_once(session: Session) -> None:
    unsupported = Result.RESULT_FEATURE_UNSUPPORTED
    for scope in (ResetSimulation.Request.SCOPE_TIME, ResetSimulation.Request.SCOPE_STATE,
                  ResetSimulation.Request.SCOPE_SPAWNED):
        answer = session.call(ResetSimulation, 'reset_simulation', ResetSimulation.Request(scope=scope)).result
        assert answer.result == unsupported and 'together' in answer.error_message, (scope, answer)
    assert session.set_state(SimulationState.STATE_QUITTING).result == unsupported
    request = GetEntities.Request()
    request.filters.categories = [EntityCategory(category=EntityCategory.CATEGORY_ROBOT)]
    assert session.call(GetEntities, 'get_entities', request).result.result == unsupported
    request = GetEntities.Request()
    request.filters.filter = '^robot'
    answer = session.call(GetEntities, 'get_entities', request)
    assert answer.result.result == Result.RESULT_OK and list(answer.entities) == []
    missing = session.call(GetEntityState, 'get_entity_state', GetEntityState.Request(entity='robot'))
    assert missing.result.result == Result.RESULT_NOT_FOUND
    assert session.state() == SimulationState.STATE_STOPPED       # nothing above changed anything


def test_seven_steps_equal_seven_single_steps_and_reset_restores_t0(session: Session) -> None:
    initial = session.call(GetEntitiesStates, 'get_entities_states')
    assert initial.result.result == Result.RESULT_OK and list(initial.entities) == ['part_0']
    assert len(initial.states) == 1 and pose_key(initial.states[0])[:2] == (0, 0)
    runs = []
    for single in (False, True):
        receipt = session.publish('actuator/trajectory', stroke())
        assert (receipt.stamp.sec, receipt.stamp.nanosec) == (0, 0)
        poses = session.probe.msgs['particle/pose']
        count = len(poses)
        for request in ([StepSimulation.Request(steps=1)] * 7 if single else [StepSimulation.Request(steps=7)]):
            answer = session.call(StepSimulation, 'step_simulation', request).result
            assert answer.result == Result.RESULT_OK, answer.error_message
        wait_until(lambda c=count, got=poses: len(got) >= c + 7, 10, executor=session.executor, what='7 poses')
        runs.append(([(p.header.stamp.nanosec, p.pose.position.x, p.pose.position.z) for p in poses[count:count + 7]],
                     pose_key(session.entity())))
        assert session.state() == SimulationState.STATE_PAUSED
        reset = session.call(ResetSimulation, 'reset_simulation',
                             ResetSimulation.Request(scope=ResetSimulation.Request.SCOPE_ALL)).result
        assert reset.result == Result.RESULT_OK, reset.error_message
        after = session.call(GetEntitiesStates, 'get_entities_states').states[0]
        assert pose_key(after) == pose_key(initial.states[0])        # t = 0 and the initial state, bit for bit
    assert runs[0][1][:2] == (0, 7 * TICK_NS)                         # exactly 7 ticks of sim time
    assert [p[0] for p in runs[0][0]] == [k * TICK_NS for k in range(1, 8)]
    assert runs[0] == runs[1]                                         # bit for bit
    assert runs[0][0][-1][1] != initial.states[0].pose.position.x, 'the stroke moved nothing'


def test_stepping_while_playing_is_refused_with_the_standards_code(session: Session) -> None:
    assert session.set_state(SimulationState.STATE_PLAYING).result == Result.RESULT_OK
    try:
        assert session.state() == SimulationState.STATE_PLAYING
        answer = session.call(StepSimulation, 'step_simulation').result
        assert answer.result == Result.RESULT_OPERATION_FAILED and 'playing' in answer.error_message
        handle, _ = session.send_goal(SimulateSteps, 'simulate_steps', SimulateSteps.Goal(steps=3))
        outcome = session.result(handle)
        assert outcome.status == GoalStatus.STATUS_ABORTED
        assert outcome.result.result.result == Result.RESULT_OPERATION_FAILED
    finally:
        assert session.set_state(SimulationState.STATE_PAUSED).result == Result.RESULT_OK
    assert session.set_state(SimulationState.STATE_PAUSED).result == SetSimulationState.Response.ALREADY_IN_TARGET_STATE
    assert session.state() == SimulationState.STATE_PAUSED


def test_simulate_steps_feedback_and_cancel(session: Session) -> None:
    t0 = session.entity().header.stamp
    handle, feedback = session.send_goal(SimulateSteps, 'simulate_steps', SimulateSteps.Goal(steps=40))
    outcome = session.result(handle)
    assert outcome.status == GoalStatus.STATUS_SUCCEEDED and outcome.result.result.result == Result.RESULT_OK
    wait_until(lambda: len(feedback) == 40, 5, executor=session.executor, what='40 feedback messages')
    assert [(f.completed_steps, f.remaining_steps) for f in feedback] == [(k, 40 - k) for k in range(1, 41)]
    t1 = session.entity().header.stamp
    assert (t1.sec * 10 ** 9 + t1.nanosec) - (t0.sec * 10 ** 9 + t0.nanosec) == 40 * TICK_NS

    steps = 10 ** 9
    handle, feedback = session.send_goal(SimulateSteps, 'simulate_steps', SimulateSteps.Goal(steps=steps))
    wait_until(lambda: len(feedback) >= 5, 10, executor=session.executor, what='SimulateSteps feedback')
    cancel = handle.cancel_goal_async()
    wait_until(cancel.done, 10, executor=session.executor, what='cancel response')
    outcome = session.result(handle)
    assert outcome.status == GoalStatus.STATUS_CANCELED
    assert all(f.completed_steps + f.remaining_steps == steps for f in feedback)
    assert feedback[-1].remaining_steps > 0
    assert session.state() == SimulationState.STATE_PAUSED


def test_follow_joint_trajectory(session: Session) -> None:
    bad = FollowJointTrajectory.Goal(trajectory=stroke(joint='piezo_7'))
    handle, _ = session.send_goal(FollowJointTrajectory, 'follow_joint_trajectory', bad)
    outcome = session.result(handle)
    assert outcome.status == GoalStatus.STATUS_ABORTED
    assert outcome.result.error_code == FollowJointTrajectory.Result.INVALID_JOINTS
    assert 'unknown joints piezo_7' in outcome.result.error_string and 'missing joints piezo_0' in \
        outcome.result.error_string

    out_of_travel = FollowJointTrajectory.Goal(trajectory=stroke(amplitude=1.0))
    handle, _ = session.send_goal(FollowJointTrajectory, 'follow_joint_trajectory', out_of_travel)
    outcome = session.result(handle)
    assert outcome.result.error_code == FollowJointTrajectory.Result.INVALID_GOAL
    assert 'piezo limits' in outcome.result.error_string

    # A long goal replaced by a newer one is aborted with joint_trajectory_controller's reason.
    first, _ = session.send_goal(FollowJointTrajectory, 'follow_joint_trajectory',
                                 FollowJointTrajectory.Goal(trajectory=stroke(duration=50e-3)))
    good, feedback = session.send_goal(FollowJointTrajectory, 'follow_joint_trajectory',
                                       FollowJointTrajectory.Goal(trajectory=stroke()))
    replaced = session.result(first)
    assert replaced.status == GoalStatus.STATUS_ABORTED
    assert replaced.result.error_code == FollowJointTrajectory.Result.INVALID_GOAL
    assert 'new incoming action' in replaced.result.error_string
    wait_until(lambda: feedback, 10, executor=session.executor, what='feedback at the goal start')
    answer = session.call(StepSimulation, 'step_simulation', StepSimulation.Request(steps=2)).result
    assert answer.result == Result.RESULT_OK, answer.error_message
    outcome = session.result(good)
    assert outcome.status == GoalStatus.STATUS_SUCCEEDED, outcome.result.error_string
    assert outcome.result.error_code == FollowJointTrajectory.Result.SUCCESSFUL
    assert len(feedback) >= 2 and list(feedback[-1].joint_names) == ['piezo_0']
    first_t, last_t = (f.header.stamp.sec * 10 ** 9 + f.header.stamp.nanosec for f in (feedback[0], feedback[-1]))
    assert last_t - first_t == 2 * TICK_NS
    assert feedback[-1].actual.positions[0] == pytest.approx(feedback[-1].desired.positions[0], abs=1e-12)


def test_a_refused_topic_command_is_answered_on_command_status(session: Session) -> None:
    status = session.probe.msgs['simulator/command_status']
    count = len(status)
    watch = RefusalWatch(session.probe, 'client@1:')        # what the actuator and feed controller keep
    receipt = session.publish('actuator/trajectory', stroke(joint='bogus', frame_id='client@1:b1'))
    setpoints = session.publish('actuator/command', Float64MultiArray(data=[math.nan]))
    wait_until(lambda: len(status) >= count + 2, 10, executor=session.executor, what='two command_status answers')
    trajectory, command = status[count:count + 2]
    assert trajectory.header.frame_id == 'actuator/trajectory#client@1:b1' == receipt.frame_id
    assert trajectory.header.stamp == receipt.stamp
    assert 'bogus' in trajectory.status[0].message and trajectory.status[0].level == b'\x02'
    assert command.header.frame_id == 'actuator/command' == setpoints.frame_id
    assert command.header.stamp == setpoints.stamp and 'non-finite' in command.status[0].message
    wait_until(lambda: watch.refused == 1, 5, executor=session.executor, what='the sender-side watch')
    assert watch.last.startswith('client@1:b1: ') and 'bogus' in watch.last


def _set_model(session: Session, **values: float | bool) -> None:
    """Set model parameters on the simulator and reset, which applies them (docs/interface.md)."""
    params = [Parameter(name, value=value).to_parameter_msg() for name, value in values.items()]
    answer = session.call(SetParameters, 'set_parameters', SetParameters.Request(parameters=params))
    assert all(r.successful for r in answer.results), answer.results
    reset = session.call(ResetSimulation, 'reset_simulation',
                         ResetSimulation.Request(scope=ResetSimulation.Request.SCOPE_DEFAULT)).result
    assert reset.result == Result.RESULT_OK, reset.error_message


def test_follow_joint_trajectory_tolerances_with_a_lagging_piezo(session: Session) -> None:
    """A slow, lightly damped stack (200 Hz, ζ 0.05: it rings for ~0.1 s) lags the stroke by micrometres: a
    1 nm path tolerance aborts with PATH_TOLERANCE_VIOLATED; a 10 nm goal tolerance is missed at the last
    knot (GOAL_TOLERANCE_VIOLATED with goal_time_tolerance 0) and met once the ringing has died down within a
    goal_time_tolerance of 0.3 s (SUCCESSFUL)."""
    _set_model(session, **{'piezo.enabled': True, 'piezo.natural_frequency': 200.0, 'piezo.damping': 0.05})
    codes = FollowJointTrajectory.Result
    try:
        path = FollowJointTrajectory.Goal(trajectory=stroke(duration=20e-3),
                                          path_tolerance=[JointTolerance(name='piezo_0', position=1e-9)])
        handle, feedback = session.send_goal(FollowJointTrajectory, 'follow_joint_trajectory', path)
        wait_until(lambda: feedback, 10, executor=session.executor, what='feedback at the goal start')
        session.call(StepSimulation, 'step_simulation', StepSimulation.Request(steps=5))
        outcome = session.result(handle)
        assert outcome.result.error_code == codes.PATH_TOLERANCE_VIOLATED, outcome.result.error_string
        assert 'piezo_0' in outcome.result.error_string and 'tolerance 1e-09 m' in outcome.result.error_string

        for grace_s, code in ((0.0, codes.GOAL_TOLERANCE_VIOLATED), (0.3, codes.SUCCESSFUL)):
            goal = FollowJointTrajectory.Goal(trajectory=stroke(duration=5e-3),
                                              goal_tolerance=[JointTolerance(name='piezo_0', position=1e-8)],
                                              goal_time_tolerance=Duration(nanosec=round(grace_s * 1e9)))
            handle, feedback = session.send_goal(FollowJointTrajectory, 'follow_joint_trajectory', goal)
            wait_until(lambda f=feedback: f, 10, executor=session.executor, what='feedback at the goal start')
            for _ in range(40):                   # 10 ms of sim time at a time, until the goal has an answer
                session.call(StepSimulation, 'step_simulation', StepSimulation.Request(steps=10))
                future = handle.get_result_async()
                end = time.monotonic() + 0.5
                while not future.done() and time.monotonic() < end:
                    session.executor.spin_once(timeout_sec=0.01)
                if future.done():
                    break
            outcome = session.result(handle)
            assert outcome.result.error_code == code, (grace_s, outcome.result.error_string)
    finally:
        _set_model(session, **{'piezo.enabled': False, 'piezo.natural_frequency': 50e3, 'piezo.damping': 0.7})


def _spawn(session: Session, name: str, x: float, uri: str = 'part', allow_renaming: bool = False) -> Any:
    request = SpawnEntity.Request(name=name, allow_renaming=allow_renaming)
    request.entity_resource.uri = uri
    request.initial_pose.header.frame_id = 'feeder'
    request.initial_pose.pose.position.x = x
    return session.call(SpawnEntity, 'spawn_entity', request)


def _delete(session: Session, name: str) -> Result:
    return session.call(DeleteEntity, 'delete_entity', DeleteEntity.Request(entity=name)).result


def test_spawn_and_delete_entities(session: Session) -> None:
    """Parts placed and removed while paused: the entities, their states and particles/poses follow; what cannot
    be placed is answered with the standard's codes and a reason; a reset restores the parts of particle.x0."""
    ok = Result.RESULT_OK
    assert session.call(ResetSimulation, 'reset_simulation', ResetSimulation.Request()).result.result == ok
    spawned = _spawn(session, 'guest', -0.5e-3)
    assert spawned.result.result == ok and spawned.entity_name == 'guest', spawned.result.error_message
    renamed = _spawn(session, 'guest', 1.5e-3, allow_renaming=True)
    assert renamed.result.result == ok and renamed.entity_name == 'part_1'
    for answer, code, reason in (
            (_spawn(session, 'guest', 2e-3), SpawnEntity.Response.NAME_NOT_UNIQUE, 'exists'),
            (_spawn(session, '', 2e-3), SpawnEntity.Response.NAME_INVALID, 'no name'),
            (_spawn(session, '9lives', 2e-3), SpawnEntity.Response.NAME_INVALID, 'letters'),
            (_spawn(session, 'x', 0.52e-3), SpawnEntity.Response.INVALID_POSE, 'overlaps'),
            (_spawn(session, 'x', 2e-3, uri='model://box'), SpawnEntity.Response.UNSUPPORTED_FORMAT, 'part'),
            (_spawn(session, 'x', 2e-3, uri=''), SpawnEntity.Response.NO_RESOURCE, 'uri')):
        assert answer.result.result == code and reason in answer.result.error_message, answer.result
    names = list(session.call(GetEntities, 'get_entities').entities)
    assert names == ['guest', 'part_0', 'part_1']                 # in order along the feeder
    session.probe.step(session.executor, 3)
    states = session.call(GetEntitiesStates, 'get_entities_states')
    assert [s.pose.position.x for s in states.states] == [-0.5e-3, 0.5e-3, 1.5e-3]
    poses = session.probe.msgs['particles/poses'][-1]
    assert [p.position.x for p in poses.poses] == [-0.5e-3, 0.5e-3, 1.5e-3]
    assert session.probe.msgs['particle/pose'][-1].pose.position.x == -0.5e-3      # part 0: the first in order
    assert _delete(session, 'guest').result == ok
    assert _delete(session, 'guest').result == Result.RESULT_NOT_FOUND
    assert _delete(session, 'part_0').result == ok
    last = _delete(session, 'part_1')
    assert last.result == Result.RESULT_OPERATION_FAILED and 'last part' in last.error_message
    changes = session.probe.msgs['simulator/entity_changes']
    assert [(c.status[0].message, c.status[0].values[0].value) for c in changes[-4:]] == [
        ('spawned', 'guest'), ('spawned', 'part_1'), ('deleted', 'guest'), ('deleted', 'part_0')]
    reset = session.call(ResetSimulation, 'reset_simulation', ResetSimulation.Request()).result
    assert reset.result == ok
    assert list(session.call(GetEntities, 'get_entities').entities) == ['part_0']
