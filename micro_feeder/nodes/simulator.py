"""The ``simulator`` node: the real-time simulator of docs/interface.md, a thin rclpy shell over the
simulation core's :class:`~micro_feeder.sim.engine.Engine` (no ROS: the wall-clock loop at ``publish_rate``,
step grants, the command intake, one lock that keeps commands, steps and resets between two ticks) and its
:class:`~micro_feeder.sim.session.Session` (the Stepper and the commands applied to it). This node declares
the parameters, publishes (:mod:`.simulator_outputs`), subscribes to the commands and reports on
``/diagnostics`` (:func:`micro_feeder.realtime.diagnostics.loop_status`).

Commands on ``actuator/trajectory`` / ``actuator/command`` are checked (:mod:`micro_feeder.sim.commands`) and
applied by their stamps in sim time, so a paused run advanced with ``~/step`` is repeatable bit for bit. With
``lockstep`` the wall clock never advances sim time (there is no loop thread): each ``~/step`` call and each
command message received grants one ``step_period`` (the command is applied first). Model parameters can be set
at any time and are applied on ``~/reset``; ``real_time_factor`` and ``step_period`` apply at once (the on-set
callback only validates; the post-set callback applies).

For ``resim`` (:mod:`micro_feeder.sim.resim`) a log must say what the simulator did with each command: the
parameters in force go out on the latched ``~/parameters`` and every command received, applied or refused, is
acknowledged on ``~/command_receipts`` with the sim time it was received at; a refused one is answered on
``~/command_status`` with the reason. A second simulator of this name is refused (:mod:`.twin_guard`). The
control services (std_srvs and simulation_interfaces) live in :mod:`.sim_control`, the FollowJointTrajectory
action in :mod:`.trajectory_action`; both call this node's :meth:`~Simulator.reset`,
:meth:`~Simulator.set_paused`, :meth:`~Simulator.step` and :meth:`~Simulator.follow`.
"""

from __future__ import annotations

import dataclasses
import sys
import threading
import time
from collections.abc import Collection, Mapping, Sequence
from copy import deepcopy
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import Parameter as ParameterMsg
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray, Header
from trajectory_msgs.msg import JointTrajectory

from ..interface import stamps, wire
from ..interface.names import joint_names
from ..physics.dynamics import Observation
from ..realtime.diagnostics import loop_status
from ..realtime.loop import GIL_SWITCH_INTERVAL
from ..sim.commands import TrajectoryCommand
from ..sim.engine import BUSY_TIMEOUT, Engine
from ..sim.session import Session
from ..sim.stepper import Stepper, build_model
from ._ros import status_name, topic_qos
from .parameters import values
from .sim_control import SimulationControl
from .simulator_outputs import COMMAND_TYPES, SimulatorOutputs
from .simulator_parameters import NODE_SPECS, SimulatorParameters
from .spin import spin_node
from .trajectory_action import TrajectoryAction
from .twin_guard import DuplicateSimulator, TwinGuard

__all__ = ['BUSY_TIMEOUT', 'NODE_SPECS', 'STOP_TIMEOUT', 'DuplicateSimulator', 'Simulator', 'main', 'topic_qos']

STOP_TIMEOUT = 0.3     # s destroy_node waits for each of the loop and intake threads (Ctrl-C answered < 1 s)
COMMAND_QUEUE = 1000   # commands the subscription holds while the executor is busy (a flood waits, not lost)


class Simulator(Node):
    """Feeder simulator: see the module docstring and docs/interface.md.

    ``overrides``: parameter values that win over ``--ros-args`` and the defaults (used by
    ``micro-feeder run --params/--set``). Raises :class:`ParameterError` for a refused value,
    :class:`DuplicateSimulator` when a simulator of this name runs already and :class:`SimulationError`
    when the parameters cannot even start the simulation.
    """

    def __init__(self, overrides: Mapping[str, Any] | None = None, *, hold: bool = False, **kwargs: Any):
        """``hold``: the wall-clock loop waits at t = 0 until :meth:`resume` (``micro-feeder run`` holds it
        until its actuator and recorder are there), whatever ``start_paused`` says."""
        super().__init__('simulator', **kwargs)
        created = time.monotonic()
        self.started_at_ns = time.time_ns()     # tells this simulator from a twin of its name (older one wins)
        self._twin_guard = TwinGuard(self, self.started_at_ns, lambda reason: self._engine.fail(reason))
        self.twins = self._twin_guard.twins     # older live simulators of this name seen (their start times)
        # First, what destroy_node() needs: rclpy destroys a node whose construction failed below (a refused
        # parameter) at shutdown, and that must not end in an AttributeError hiding the reason.
        self._engine: Engine | None = None
        self._lock = threading.RLock()      # the engine's: the session and the state publishers, ticks vs the rest
        self._params = SimulatorParameters(self, overrides)
        p = values(self, NODE_SPECS)
        self._session = Session(Stepper(build_model(self._params.model())), lockstep=p['lockstep'],
                                warn=self.get_logger().warning, decode_setpoints=_decode_setpoints)
        self.commands = self._session.commands
        self.add_post_set_parameters_callback(self._apply_parameters)

        self._twin_guard.refuse_twin(created)
        self._outputs = SimulatorOutputs(self, self.stepper, publish_clock=p['publish_clock'],
                                         markers_period=1.0 / p['markers_rate'])
        self._refused_reported: dict[str, int] = {}   # publishes refused per topic, as of the last /diagnostics
        self._engine = Engine(self._session, self._outputs, self.get_logger(), lock=self._lock,
                              lockstep=p['lockstep'], rtf=p['real_time_factor'], step_period=p['step_period'],
                              period=1.0 / p['publish_rate'], start_paused=p['start_paused'],
                              max_command_bytes=p['max_command_bytes'], publish_thread=p['publish_thread'],
                              on_failure=self._publish_diagnostics)
        for topic, msg_type in COMMAND_TYPES.items():
            self.create_subscription(msg_type, topic, lambda data, t=topic: self._engine.submit(t, data),
                                     topic_qos(topic, COMMAND_QUEUE), raw=True)
        self._sim_control = SimulationControl(self, self, self.sim_time)   # simulation_interfaces, std_srvs
        self._trajectory_action = TrajectoryAction(self, self)             # FollowJointTrajectory
        self._instance = f'{self.get_fully_qualified_name()}@{time.time_ns():x}'   # names goals without a name
        self._goals_followed = 0
        self._publish_parameters()
        self.create_timer(1.0, self._publish_diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._engine.start(hold=hold)       # the state at t = 0, then the loop runs unless paused

    # -- public, for micro-feeder run, the services and tests (the engine's, see there) -----------

    @property
    def stepper(self) -> Stepper:
        return self._session.stepper

    @property
    def command_serial(self) -> int:
        """+1 for every command applied and every reset: what replaced a goal's strokes."""
        return self._session.command_serial

    @property
    def refusal(self) -> str:
        """Why this node must not run on this graph ('' when it may; :func:`spin_node` exits 2 on it)."""
        return self._twin_guard.refusal

    @property
    def paused(self) -> bool:
        """True when the wall clock does not advance sim time (paused, failed, ended, or lockstep)."""
        return self._engine.paused

    @property
    def lockstep(self) -> bool:
        return self._engine.lockstep

    @property
    def error(self) -> str:
        """Why the simulation stopped ('' while it runs; cleared by :meth:`reset`)."""
        return self._engine.error

    @property
    def steps_granted(self) -> int:
        return self._engine.steps_granted

    @property
    def states_published(self) -> int:
        return self._engine.states_published

    @property
    def achieved_rtf(self) -> float:
        """The real-time factor achieved between the last two :meth:`diagnostics`."""
        return self._engine.achieved_rtf

    @property
    def overruns(self) -> int:
        """Ticks whose work took longer than the loop period, since start."""
        return self._engine.overruns

    @property
    def joints(self) -> list[str]:
        return joint_names(self.stepper.model.n_actuators)

    @property
    def rejected(self) -> int:
        """Commands refused since start (invalid or too large)."""
        return self.commands.refused

    @property
    def last_rejection(self) -> str:
        return self.commands.last_refusal

    def sim_time(self) -> float:
        """Sim time now (s)."""
        return self.stepper.t

    def limits(self) -> tuple[float, float]:
        """The stroke travel (m) commands must stay in: the piezo limits."""
        return self.stepper.limits

    def grant_step(self) -> tuple[bool, str]:
        """Advance one ``step_period`` and publish, if paused (:meth:`Engine.grant_step`). (success, message)."""
        return self._engine.grant_step()

    def step(self) -> tuple[bool, str]:
        """What ``~/step`` does: :meth:`grant_step`, or (False, ``busy: ...``) (:meth:`Engine.step`)."""
        return self._engine.step()

    def stop_at(self, t_end: float) -> Future:
        """Never advance sim time past ``t_end`` (s): the loop (or a lockstep grant) stops exactly there and
        pauses; the returned future completes when sim time reaches it (at once if it already has)."""
        stopped_at = Future()

        def reached(t: float) -> None:
            if not stopped_at.done():
                stopped_at.set_result(t)

        self._engine.stop_at(t_end, reached)
        return stopped_at

    def pause(self) -> None:
        """Stop the wall-clock loop advancing sim time (:meth:`Engine.pause`)."""
        self._engine.pause()

    def resume(self) -> None:
        """Let the wall-clock loop advance sim time (what ``~/pause false`` does; :meth:`Engine.resume`)."""
        self._engine.resume()

    def set_paused(self, paused: bool) -> tuple[bool, str]:
        """What ``~/pause`` does: pause, or run (refused after a failure and in lockstep). (success, message)."""
        return self._engine.set_paused(paused)

    def reset(self, *, pause: bool = False) -> tuple[bool, str]:
        """What ``~/reset`` does (and ResetSimulation, SetSimulationState STOPPED with ``pause``): t = 0 with
        the model parameters set now (:meth:`Engine.reset`). (success, message)."""
        parameters = self._params.messages(self._params.model_specs)
        return self._engine.reset(lambda: build_model(self._params.model()),
                                  lambda: self._model_applied(parameters), pause=pause)

    def follow(self, message: JointTrajectory | None = None) -> tuple[int, float, TrajectoryCommand]:
        """A FollowJointTrajectory goal's trajectory (None: an empty one, which holds the strokes) applied as
        on ``actuator/trajectory`` (:meth:`Engine.follow`), named by its ``header.frame_id`` or, without one,
        ``<node>@<start>:fjt<k>``: a log of a goal-driven run replays. Returns (its :attr:`command_serial`,
        its start in sim time (s), the command); raises ValueError with the reason or :class:`Busy`."""
        copy = JointTrajectory(joint_names=self.joints) if message is None else deepcopy(message)
        if not copy.header.frame_id:
            self._goals_followed += 1
            copy.header.frame_id = f'{self._instance}:fjt{self._goals_followed}'
        return self._engine.follow(copy)

    def observe(self) -> Observation:
        """Part 0's state now, as published (taken under the lock, between two ticks); raises :class:`Busy`."""
        return self._engine.observe()

    def observe_parts(self) -> list[Observation]:
        """Every part's state now, in part order (as :meth:`observe`)."""
        return self._engine.observe_parts()

    def entity_names(self) -> list[str]:
        """Every part's entity name now, in part order."""
        return self._engine.entity_names()

    def observe_entities(self) -> tuple[list[str], list[Observation]]:
        """Every part's entity name and state now, in part order."""
        return self._engine.observe_entities()

    def spawn_part(self, name: str, x: float) -> tuple[bool, str]:
        """SpawnEntity: a part named ``name`` placed at ``x`` (m) now, at rest; recorded on
        ``simulator/entity_changes`` (:meth:`Engine.spawn_part`). (success, message: the reason of a refusal)."""
        return self._engine.spawn_part(name, x)

    def delete_part(self, name: str) -> tuple[bool, str]:
        """DeleteEntity: the part named ``name`` removed now, recorded as :meth:`spawn_part`'s."""
        return self._engine.delete_part(name)

    def strokes(self, t: float | None = None) -> tuple[np.ndarray, Observation]:
        """((3, joints) commanded s, ṡ, s̈ at ``t`` (s; default now), the state now); raises :class:`Busy`."""
        return self._engine.strokes(t)

    def hears(self, topic: str) -> bool:
        """True when this node's subscription to the command ``topic`` (``actuator/trajectory``) has matched a
        publisher: what is sent now arrives. A publisher that matched it on its side only can send before the
        subscription knows the publisher, and a volatile subscription never gets that message."""
        name = self.resolve_topic_name(topic)
        return any(sub.topic_name == name and sub.get_publisher_count() > 0 for sub in self.subscriptions)

    def outputs_matched(self, recorded_in_process: Collection[str] = ()) -> bool:
        """True when every state topic the simulator publishes has at least one subscription matched (a
        recorder that has not yet matched a topic would miss its first messages), not counting the topics
        ``recorded_in_process`` (absolute names) by a recorder in this process."""
        return self._outputs.matched(recorded_in_process)

    def destroy_node(self) -> None:
        """Stop the loop and intake threads (waiting up to :data:`STOP_TIMEOUT` each for work in
        progress: a tick stuck in the physics is left to die with the process), then destroy the action servers
        and the node. ``Node.destroy_node`` leaves action servers to the garbage collector, which destroyed one
        at an arbitrary moment of a later test and deadlocked inside Fast DDS (CI hung)."""
        if self._engine is not None:
            self._engine.stop(timeout=STOP_TIMEOUT)
        for name in ('_trajectory_action', '_sim_control'):
            server = getattr(self, name, None)
            if server is not None:
                setattr(self, name, None)
                server.destroy()
        super().destroy_node()

    # -- parameters and diagnostics -----------------------------------------------------------------

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """Post-set callback: the node's parameters apply at once, the model's on ~/reset. Says so once per
        reset, not once per set (a client setting 450 parameters one by one got 450 INFO lines)."""
        with self._lock:
            was_pending = self._params.pending
            for param in params:
                if param.name == 'real_time_factor':
                    self._engine.rtf = param.value
                elif param.name == 'step_period':
                    self._engine.step_period = param.value
                elif param.name in self._params.model_specs:
                    self._params.pending = True
            if any(p.name in NODE_SPECS for p in params):
                self._publish_parameters()
        if self._params.pending and not was_pending:
            self.get_logger().info('model parameters changed: applied on ~/reset (further changes before it are '
                                   'not logged; /diagnostics: model_parameters_pending_reset)')

    def _model_applied(self, parameters: list[ParameterMsg]) -> None:
        """A reset put the model of ``parameters`` in force (under the lock): published on ``~/parameters``."""
        self._params.applied = parameters
        self._params.pending = False
        self._publish_parameters()

    def _publish_parameters(self) -> None:
        """The parameters in force on the latched ``~/parameters`` (:meth:`SimulatorParameters.event`)."""
        self._outputs.refused.publish(self._outputs.parameters,
                                      self._params.event(self.stepper.t, self.started_at_ns))

    def diagnostics(self) -> DiagnosticStatus:
        """The simulator's status (:func:`loop_status` of :meth:`Engine.snapshot`): achieved real-time factor
        over the time since the last call, tick timing, counters. Takes no lock, so it reports even while a
        tick is stuck."""
        refused = self._outputs.refused.counts()
        new = {topic: n - self._refused_reported.get(topic, 0) for topic, n in refused.items()
               if n > self._refused_reported.get(topic, 0)}
        snapshot = self._engine.snapshot(pending_reset=self._params.pending, other_simulators=len(self.twins))
        status = loop_status(dataclasses.replace(snapshot, refused=refused, refused_new=new))
        self._refused_reported = refused
        if status.level != 0:
            self.get_logger().warning(status.message, throttle_duration_sec=10.0)
        return DiagnosticStatus(name=status_name(self, 'loop'), hardware_id='micro_feeder',
                                level=bytes([status.level]), message=status.message,
                                values=[KeyValue(key=k, value=v) for k, v in status.values.items()])

    def _publish_diagnostics(self) -> None:
        self._session.flush_logs()
        report = DiagnosticArray(header=Header(stamp=stamps.to_time(self.stepper.t)), status=[self.diagnostics()])
        self._outputs.refused.publish(self._outputs.diagnostics, report)


def _decode_setpoints(data: bytes) -> Sequence[float]:
    """An ``actuator/command`` in a layout the fast reader does not read, by rclpy's deserialization."""
    return wire.deserialize(data, Float64MultiArray).data


def main(args: list[str] | None = None) -> int:
    """Console script ``simulator``: ``simulator --ros-args --params-file config/feeder.yaml -p ...``."""
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    return spin_node('simulator', Simulator, args)
