"""The simulator's control services: ``simulation_interfaces`` (2.0.0), node-private services and the
SimulateSteps action, and the project's std_srvs ``~/reset``, ``~/pause``, ``~/step`` as aliases.

The standard simulator-control API that Gazebo, Isaac Sim and O3DE serve, with Gazebo's names relative to the
node (``/gzserver/step_simulation`` there, ``simulator/step_simulation`` here). Every answer comes from the
node's own paths (:meth:`Simulator.reset`, :meth:`~Simulator.set_paused`, :meth:`~Simulator.step`,
:meth:`~Simulator.observe`), the ones ``~/reset``, ``~/pause`` and ``~/step`` take, so the std_srvs aliases and
the standard give the same results. Nothing waits unboundedly: a busy simulator (a tick stuck in the physics)
answers RESULT_OPERATION_FAILED with ``busy: ...`` within 0.5 s, and what this simulator cannot do answers
RESULT_FEATURE_UNSUPPORTED with the reason. docs/interface.md, *Standards*, lists the mapping.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from typing import Any, Protocol

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.node import Node
from rclpy.qos import QoSProfile
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (
    Bounds,
    EntityFilters,
    EntityState,
    Result,
    SimulationState,
    SimulatorFeatures,
)
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
from std_msgs.msg import Header
from std_srvs.srv import SetBool, Trigger

from ..interface import stamps
from ..interface.messages import tilt_quaternion
from ..interface.names import FEEDER_FRAME, part_entity
from ..physics.dynamics import Observation
from ..sim.engine import Busy
from ._ros import SERVICE_QOS

# Feedback comes every step: a deep history, so a client with the same depth misses none (default depth 10)
FEEDBACK_QOS = QoSProfile(depth=1000)
ENTITY_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_]*')      # a spawned part's name
MAX_SERVICE_STEPS = 10_000      # StepSimulation steps per call: the service holds the executor while it steps

FEATURES = [
    SimulatorFeatures.SPAWNING,
    SimulatorFeatures.DELETING,
    SimulatorFeatures.ENTITY_STATE_GETTING,
    SimulatorFeatures.SIMULATION_RESET,
    SimulatorFeatures.SIMULATION_STATE_GETTING,
    SimulatorFeatures.SIMULATION_STATE_SETTING,
    SimulatorFeatures.SIMULATION_STATE_PAUSE,
    SimulatorFeatures.STEP_SIMULATION_SINGLE,
    SimulatorFeatures.STEP_SIMULATION_MULTIPLE,
    SimulatorFeatures.STEP_SIMULATION_ACTION,
]
# A reset restores sim time and state together: every command is keyed on sim time, so neither alone is a
# state this simulator can be in; it also restores the parts of particle.x0 (spawned ones go, deleted ones
# come back), so SCOPE_SPAWNED alone is not a reset this simulator does.
FULL_RESET_SCOPES = (ResetSimulation.Request.SCOPE_DEFAULT, ResetSimulation.Request.SCOPE_ALL,
                     ResetSimulation.Request.SCOPE_TIME | ResetSimulation.Request.SCOPE_STATE)
PART_RESOURCE = 'part'     # SpawnEntity's entity_resource.uri: the one part type particle.* describes
SPAWN_FORMATS = [PART_RESOURCE]
CUSTOM_INFO = ('micro_feeder simulator: entities part_0, part_1, ... (one per particle.x0 entry, in order along the '
               'feeder; point masses; pose and twist in frame feeder, '
               'acceleration not reported). SpawnEntity: entity_resource.uri "part" (the part of particle.*), placed '
               'at initial_pose.position.x at rest on the surface; DeleteEntity removes a part (not the last). '
               'ResetSimulation: SCOPE_DEFAULT, SCOPE_ALL or SCOPE_TIME|SCOPE_STATE '
               '(time and state together, the parts of particle.x0 restored). A step is the step_period parameter. '
               'Commands: '
               'control_msgs/action/FollowJointTrajectory ~/follow_joint_trajectory, actuator/trajectory. '
               'See docs/interface.md.')


class ControlledSimulator(Protocol):
    """What this module needs of the simulator node (:class:`micro_feeder.nodes.simulator.Simulator`)."""

    @property
    def paused(self) -> bool: ...

    def reset(self, *, pause: bool = False) -> tuple[bool, str]: ...

    def set_paused(self, paused: bool) -> tuple[bool, str]: ...

    def step(self) -> tuple[bool, str]: ...

    def observe_entities(self) -> tuple[list[str], list[Observation]]: ...

    def entity_names(self) -> list[str]: ...

    def spawn_part(self, name: str, x: float) -> tuple[bool, str]: ...

    def delete_part(self, name: str) -> tuple[bool, str]: ...


def result(code: int, message: str = '') -> Result:
    """A simulation_interfaces Result (``code`` one of ``Result.RESULT_*``)."""
    return Result(result=code, error_message=message)


def entity_state(obs: Observation) -> EntityState:
    """The part as an entity: the pose and twist ``particle/pose`` and ``particle/twist`` carry at ``obs.t``
    (m, m/s; orientation = the contact tilt), frame ``feeder``; acceleration not reported (0)."""
    state = EntityState(header=Header(stamp=stamps.to_time(obs.t), frame_id=FEEDER_FRAME))
    state.pose.position.x, state.pose.position.z = obs.x, obs.z
    q = state.pose.orientation
    q.x, q.y, q.z, q.w = tilt_quaternion(obs.theta)
    state.twist.linear.x, state.twist.linear.z = obs.xdot, obs.zdot
    return state


def match_entities(filters: EntityFilters, observe: Callable[[], tuple[list[str], list[Observation]]]
                   ) -> tuple[Result, list[str], list[Observation]]:
    """The entities ``filters`` select, with their states: a name regular expression (searched, Python's
    syntax, which reads POSIX extended expressions of names alike) and sphere bounds (the part's position
    inside). Categories, tags, box and convex-hull bounds are not supported."""
    if filters.categories:
        return result(Result.RESULT_FEATURE_UNSUPPORTED, 'entity categories are not supported (no '
                      'ENTITY_CATEGORIES feature)'), [], []
    if filters.tags.tags:
        return result(Result.RESULT_FEATURE_UNSUPPORTED, 'entity tags are not supported (no ENTITY_TAGS '
                      'feature)'), [], []
    bounds = filters.bounds
    if bounds.type not in (Bounds.TYPE_EMPTY, Bounds.TYPE_SPHERE):
        return result(Result.RESULT_FEATURE_UNSUPPORTED, f'bounds of type {bounds.type}: only TYPE_EMPTY and '
                      'TYPE_SPHERE are supported'), [], []
    if bounds.type == Bounds.TYPE_SPHERE and len(bounds.points) < 2:
        return result(Result.RESULT_OPERATION_FAILED, 'sphere bounds need 2 points: centre, (radius, 0, 0)'), [], []
    names, parts = observe()
    try:
        chosen = [k for k in range(len(parts)) if re.search(filters.filter, names[k])]
    except re.error as err:
        return result(Result.RESULT_OPERATION_FAILED, f'filter {filters.filter!r}: {err}'), [], []
    if bounds.type == Bounds.TYPE_SPHERE:
        c, radius = bounds.points[0], bounds.points[1].x
        chosen = [k for k in chosen if math.dist((parts[k].x, 0.0, parts[k].z), (c.x, c.y, c.z)) <= radius]
    return result(Result.RESULT_OK), [names[k] for k in chosen], [parts[k] for k in chosen]


class SimulationControl:
    """The services and action of simulation_interfaces on ``node`` (names relative to the node, ``~/``).

    ``simulator``: the node's control paths. STOPPED is paused at t = 0 after SetSimulationState STOPPED (a
    pause and a full reset) or at start-up when paused, until something plays, pauses or steps it.
    """

    def __init__(self, node: Node, simulator: ControlledSimulator, t: Callable[[], float]):
        self._sim = simulator
        self._t = t
        self._stopped = simulator.paused and t() == 0.0
        self._stepping = False          # a SimulateSteps goal is being executed
        services: list[tuple[Any, str, Callable[[Any, Any], Any]]] = [
            (GetSimulatorFeatures, 'get_simulator_features', self._on_features),
            (GetSimulationState, 'get_simulation_state', self._on_get_state),
            (SetSimulationState, 'set_simulation_state', self._on_set_state),
            (StepSimulation, 'step_simulation', self._on_step),
            (ResetSimulation, 'reset_simulation', self._on_reset),
            (GetEntities, 'get_entities', self._on_entities),
            (GetEntitiesStates, 'get_entities_states', self._on_entities_states),
            (GetEntityState, 'get_entity_state', self._on_entity_state),
            (SpawnEntity, 'spawn_entity', self._on_spawn),
            (DeleteEntity, 'delete_entity', self._on_delete),
        ]
        for srv_type, name, callback in services + self._aliases():
            node.create_service(srv_type, f'~/{name}', callback, qos_profile=SERVICE_QOS)
        self._action = ActionServer(node, SimulateSteps, '~/simulate_steps', execute_callback=self._execute_steps,
                                    goal_callback=lambda _goal: GoalResponse.ACCEPT,
                                    cancel_callback=lambda _goal: CancelResponse.ACCEPT,
                                    feedback_pub_qos_profile=FEEDBACK_QOS)

    def destroy(self) -> None:
        self._action.destroy()

    def state(self) -> int:
        """The SimulationState now: PLAYING while the wall clock advances sim time, else STOPPED or PAUSED."""
        if not self._sim.paused:
            return SimulationState.STATE_PLAYING
        if self._stopped and self._t() == 0.0:
            return SimulationState.STATE_STOPPED
        return SimulationState.STATE_PAUSED

    # -- services -----------------------------------------------------------------------------------

    def _aliases(self) -> list[tuple[Any, str, Callable[[Any, Any], Any]]]:
        """The project's own std_srvs services (docs/interface.md), kept as aliases on the same paths."""

        def answer(response: Any, outcome: tuple[bool, str]) -> Any:
            response.success, response.message = outcome
            return response

        return [(Trigger, 'reset', lambda _req, res: answer(res, self._sim.reset())),
                (SetBool, 'pause', lambda req, res: answer(res, self._sim.set_paused(req.data))),
                (Trigger, 'step', lambda _req, res: answer(res, self._sim.step()))]

    def _on_features(self, _request: Any, response: GetSimulatorFeatures.Response) -> GetSimulatorFeatures.Response:
        response.features = SimulatorFeatures(features=FEATURES, spawn_formats=SPAWN_FORMATS, custom_info=CUSTOM_INFO)
        return response

    def _on_get_state(self, _request: Any, response: GetSimulationState.Response) -> GetSimulationState.Response:
        response.state = SimulationState(state=self.state())
        response.result = result(Result.RESULT_OK)
        return response

    def _on_set_state(self, request: SetSimulationState.Request,
                      response: SetSimulationState.Response) -> SetSimulationState.Response:
        target, now = request.state.state, self.state()
        if target not in (SimulationState.STATE_STOPPED, SimulationState.STATE_PLAYING,
                          SimulationState.STATE_PAUSED):
            response.result = result(Result.RESULT_FEATURE_UNSUPPORTED, f'state {target}: only STOPPED, PLAYING and '
                                     'PAUSED (end the process with SIGINT/SIGTERM; there are no worlds to load)')
            return response
        if target == now:
            response.result = result(SetSimulationState.Response.ALREADY_IN_TARGET_STATE, f'already in state {now}')
            return response
        if target == SimulationState.STATE_STOPPED:
            ok, message = self._sim.reset(pause=True)
        else:
            ok, message = self._sim.set_paused(target == SimulationState.STATE_PAUSED)
            if ok and self.state() != target:       # e.g. at the end of a `micro-feeder run`
                ok = False
        if ok:
            self._stopped = target == SimulationState.STATE_STOPPED
            response.result = result(Result.RESULT_OK, message)
        else:
            response.result = result(SetSimulationState.Response.STATE_TRANSITION_ERROR, message)
        return response

    def _on_step(self, request: StepSimulation.Request, response: StepSimulation.Response) -> StepSimulation.Response:
        if request.steps > MAX_SERVICE_STEPS:
            response.result = result(Result.RESULT_OPERATION_FAILED, f'{request.steps} steps: at most '
                                     f'{MAX_SERVICE_STEPS} per call (use the SimulateSteps action for more)')
            return response
        for k in range(request.steps):
            ok, message = self._one_step()
            if not ok:
                response.result = result(Result.RESULT_OPERATION_FAILED,
                                         f'after {k} of {request.steps} steps: {message}')
                return response
        response.result = result(Result.RESULT_OK)
        return response

    def _one_step(self) -> tuple[bool, str]:
        """One step_period (only while paused: RESULT_OPERATION_FAILED otherwise, as Gazebo answers)."""
        if not self._sim.paused:
            return False, 'the simulation is playing: pause it first (SetSimulationState PAUSED)'
        ok, message = self._sim.step()
        if ok:
            self._stopped = False
        return ok, message

    def _on_reset(self, request: ResetSimulation.Request,
                  response: ResetSimulation.Response) -> ResetSimulation.Response:
        if request.scope not in FULL_RESET_SCOPES:
            response.result = result(Result.RESULT_FEATURE_UNSUPPORTED, f'scope {request.scope}: sim time and state '
                                     'reset together only (SCOPE_DEFAULT, SCOPE_ALL or SCOPE_TIME|SCOPE_STATE); '
                                     'spawned parts go and deleted ones come back with every reset)')
            return response
        ok, message = self._sim.reset()
        response.result = result(Result.RESULT_OK if ok else Result.RESULT_OPERATION_FAILED, message)
        return response

    def _observe(self) -> tuple[list[str], list[Observation]]:
        return self._sim.observe_entities()

    def _on_entities(self, request: GetEntities.Request, response: GetEntities.Response) -> GetEntities.Response:
        try:
            response.result, response.entities, _ = match_entities(request.filters, self._observe)
        except Busy as err:
            response.result = result(Result.RESULT_OPERATION_FAILED, str(err))
        return response

    def _on_entities_states(self, request: GetEntitiesStates.Request,
                            response: GetEntitiesStates.Response) -> GetEntitiesStates.Response:
        try:
            response.result, names, parts = match_entities(request.filters, self._observe)
            response.entities, response.states = names, [entity_state(obs) for obs in parts]
        except Busy as err:
            response.result = result(Result.RESULT_OPERATION_FAILED, str(err))
        return response

    def _on_entity_state(self, request: GetEntityState.Request,
                         response: GetEntityState.Response) -> GetEntityState.Response:
        try:
            names, parts = self._observe()
            if request.entity not in names:
                response.result = result(Result.RESULT_NOT_FOUND, f'no entity {request.entity!r} (entities: '
                                         f'{names[0]} ... {names[-1]})' if len(names) > 1 else
                                         f'no entity {request.entity!r} (entities: {names[0]})')
                return response
            response.state = entity_state(parts[names.index(request.entity)])
            response.result = result(Result.RESULT_OK)
        except Busy as err:
            response.result = result(Result.RESULT_OPERATION_FAILED, str(err))
        return response

    def _on_spawn(self, request: SpawnEntity.Request, response: SpawnEntity.Response) -> SpawnEntity.Response:
        code, message, name = self._spawn(request)
        if code == Result.RESULT_OK:
            try:
                ok, message = self._sim.spawn_part(name, request.initial_pose.pose.position.x)
                # refused by the simulator: where it goes, or (another spawn came first) its name
                code = Result.RESULT_OK if ok else SpawnEntity.Response.NAME_NOT_UNIQUE if name in \
                    self._sim.entity_names() else SpawnEntity.Response.INVALID_POSE
            except Busy as err:
                code, message = Result.RESULT_OPERATION_FAILED, str(err)
        response.result = result(code, message)
        response.entity_name = name if code == Result.RESULT_OK else ''
        return response

    def _spawn(self, request: SpawnEntity.Request) -> tuple[int, str, str]:
        """(result code, reason, entity name) of a spawn request before the simulator is asked: the resource,
        the namespace, the frame, the name (taken or made)."""
        uri, resource_string = request.entity_resource.uri, request.entity_resource.resource_string
        if not uri and not resource_string:
            return SpawnEntity.Response.NO_RESOURCE, f'entity_resource: give uri "{PART_RESOURCE}"', ''
        if uri != PART_RESOURCE:
            return SpawnEntity.Response.UNSUPPORTED_FORMAT, (f'entity_resource {uri or "resource_string"!r}: only '
                                                             f'uri "{PART_RESOURCE}" (the part of particle.*)'), ''
        if request.entity_namespace:
            return SpawnEntity.Response.NAMESPACE_INVALID, 'a part has no interfaces of its own: leave ' \
                                                           'entity_namespace empty', ''
        frame = request.initial_pose.header.frame_id
        if frame not in ('', FEEDER_FRAME, 'world'):
            return SpawnEntity.Response.INVALID_POSE, f'frame {frame!r}: positions are in {FEEDER_FRAME!r}', ''
        x = request.initial_pose.pose.position.x
        if not math.isfinite(x):
            return SpawnEntity.Response.INVALID_POSE, f'position.x = {x}: not a number', ''
        try:
            names = self._sim.entity_names()
        except Busy as err:
            return Result.RESULT_OPERATION_FAILED, str(err), ''
        name = request.name
        if name and not ENTITY_NAME.fullmatch(name):
            return SpawnEntity.Response.NAME_INVALID, (f'name {name!r}: letters, digits and _, not starting with a '
                                                       'digit'), ''
        if not name or name in names:
            if not request.allow_renaming:
                return ((SpawnEntity.Response.NAME_NOT_UNIQUE, f'an entity named {name!r} exists (set '
                         'allow_renaming to get another name)', '') if name else
                        (SpawnEntity.Response.NAME_INVALID, 'no name given (give one, or set allow_renaming)', ''))
            name = next(part_entity(k) for k in range(len(names) + 1) if part_entity(k) not in names)
        return Result.RESULT_OK, '', name

    def _on_delete(self, request: DeleteEntity.Request, response: DeleteEntity.Response) -> DeleteEntity.Response:
        try:
            if request.entity not in self._sim.entity_names():
                response.result = result(Result.RESULT_NOT_FOUND, f'no entity {request.entity!r}')
                return response
            ok, message = self._sim.delete_part(request.entity)
            response.result = result(Result.RESULT_OK if ok else Result.RESULT_OPERATION_FAILED, message)
        except Busy as err:
            response.result = result(Result.RESULT_OPERATION_FAILED, str(err))
        return response

    # -- SimulateSteps ------------------------------------------------------------------------------

    async def _execute_steps(self, goal: ServerGoalHandle) -> SimulateSteps.Result:
        """Step ``goal.request.steps`` times with feedback after each (completed + remaining = steps), yielding
        to the executor between steps so that a cancel request (and everything else) is served meanwhile."""
        steps = goal.request.steps
        outcome = SimulateSteps.Result(result=result(Result.RESULT_OK))
        if self._stepping:
            outcome.result = result(Result.RESULT_OPERATION_FAILED, 'another SimulateSteps goal is running')
            goal.abort()
            return outcome
        self._stepping = True
        try:
            for k in range(steps):
                if goal.is_cancel_requested:
                    outcome.result = result(Result.RESULT_OK, f'canceled after {k} of {steps} steps')
                    goal.canceled()
                    return outcome
                ok, message = self._one_step()
                if not ok:
                    outcome.result = result(Result.RESULT_OPERATION_FAILED, f'after {k} of {steps} steps: {message}')
                    goal.abort()
                    return outcome
                goal.publish_feedback(SimulateSteps.Feedback(completed_steps=k + 1, remaining_steps=steps - k - 1))
                await Yield()
        finally:
            self._stepping = False
        goal.succeed()
        return outcome


class Yield:
    """Awaiting it hands the executor back once: the task is resumed on its next turn, and whatever else is
    waiting (a cancel request, a command, a service) is served in between."""

    def __await__(self) -> Any:
        yield
