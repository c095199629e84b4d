"""The ``simulator`` node: the real-time loop of docs/interface.md around the simulation core's
:class:`~micro_feeder.sim.stepper.Stepper`.

A thin rclpy shell over rclpy-free parts: the wall-clock loop thread (:mod:`micro_feeder.realtime.loop`)
ticks at ``publish_rate`` and advances sim time by elapsed wall time × ``real_time_factor`` (0: as fast as
possible, ``step_period`` per step), never more than two periods' worth per tick, then publishes the
state; the command intake (:mod:`micro_feeder.realtime.intake`) parses commands on a worker thread,
coalesces superseded ones and throttles refusal logs; the ``/diagnostics`` arithmetic is
:func:`micro_feeder.realtime.diagnostics.loop_status`. One lock serialises everything that touches the
stepper or publishes state, so a command, a step or a reset happens between two ticks, never inside one.

Commands on ``actuator/trajectory`` / ``actuator/command`` are checked (:mod:`micro_feeder.sim.commands`) and applied
by their stamps in sim time, so a paused run advanced with ``~/step`` is repeatable bit for bit. With
``lockstep`` the wall clock never advances sim time (there is no loop thread): each ``~/step`` call and
each command message received grants one ``step_period`` (the command is applied first). Model
parameters can be set at any time and are applied on ``~/reset``; ``real_time_factor`` and
``step_period`` apply at once (the on-set callback only validates; the post-set callback applies).

For ``resim`` (:mod:`micro_feeder.sim.resim`) a log must say what the simulator did with each command: the parameters in
force go out on the latched ``~/parameters`` and every command received, applied or refused, is
acknowledged on ``~/command_receipts`` with the sim time it was received at; a refused one is answered on
``~/command_status`` with the reason. The control services (std_srvs and simulation_interfaces) live in
:mod:`.sim_control`, the FollowJointTrajectory action in :mod:`.trajectory_action`; both call this node's
:meth:`~Simulator.reset`, :meth:`~Simulator.set_paused`, :meth:`~Simulator.step` and :meth:`~Simulator.follow`.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from copy import deepcopy
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseArray, PoseStamped, TwistStamped, WrenchStamped
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterEvent, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, String
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from ..interface import messages, stamps, wire
from ..interface.cdr import read_float64_array
from ..interface.entity_changes import DELETED, SPAWNED, EntityChange
from ..interface.names import joint_names, receipt_frame
from ..interface.parts_messages import PartsMessages
from ..interface.topics import ENTITY_CHANGES, RECEIVED_COPIES
from ..interface.transitions import TransitionEncoder
from ..physics.dynamics import Event, Observation, SimulationError
from ..physics.parameters import ParameterError, ParamSpec
from ..realtime.diagnostics import LoopSnapshot, achieved_rtf, loop_status
from ..realtime.intake import CommandIntake, IntakeCounters, Outcome, Received, ThrottledLog, plan
from ..realtime.loop import GIL_SWITCH_INTERVAL, TickLoop
from ..settings import model_specs
from ..sim.commands import (
    TrajectoryCommand,
    parse_setpoints,
    parse_trajectory,
    parse_trajectory_cdr,
    start_time,
)
from ..sim.stepper import Stepper, build_model
from ._ros import status_name, topic_qos
from .parameters import check_changes, declare, values
from .sim_control import Busy, SimulationControl
from .spin import NodeRefused, spin_node
from .trajectory_action import TrajectoryAction

NODE_SPECS: dict[str, tuple[ParamSpec, Any]] = {
    'publish_rate': (ParamSpec('rate of the loop timer and of the state topics', 'Hz', gt=0, le=10000,
                               read_only=True), 1000.0),
    'real_time_factor': (ParamSpec('sim seconds per wall second; 0 = as fast as possible', '', ge=0, le=1000),
                         1.0),
    'start_paused': (ParamSpec('start paused: advance with ~/step, run with ~/pause false',
                               kind='bool', read_only=True), False),
    'publish_clock': (ParamSpec('publish sim time on /clock (default: true in the root namespace, false in '
                                'any other, so that namespaced feeders do not fight over one /clock)',
                                kind='bool', read_only=True), True),
    'step_period': (ParamSpec('sim time advanced by one ~/step call, and per step when '
                              'real_time_factor is 0', 's', gt=0, le=1.0), 1e-3),
    'markers_rate': (ParamSpec('rate of surface/markers (wall clock)', 'Hz', gt=0, le=1000, read_only=True),
                     30.0),
    'lockstep': (ParamSpec('sim time never advances on the wall clock: one step_period per ~/step '
                           'call and per command message received', kind='bool', read_only=True), False),
    'max_command_bytes': (ParamSpec('largest command message accepted (serialized size); a larger one is '
                                    'refused unparsed: send long strokes in windows', 'B', ge=1024, le=2 ** 30,
                                    kind='int', read_only=True), 2 ** 20),
}

PART_SIZE = 100e-6     # marker diameter of the part (m)
MARKER_POINTS = 200    # points of the surface line strip
BUSY_TIMEOUT = 0.5     # s a service waits for a tick in progress before answering "busy"
STOP_TIMEOUT = 0.3     # s destroy_node waits for each of the loop and intake threads (Ctrl-C answered < 1 s)
COMMAND_QUEUE = 1000   # commands the subscription holds while the executor is busy (a flood waits, not lost)
COMMAND_TYPES = {'actuator/trajectory': JointTrajectory, 'actuator/command': Float64MultiArray}
TWIN_WATCH_DEPTH = 10    # events of ~/parameters kept for the twin check (own ones included)


class DuplicateSimulator(NodeRefused):
    """Another simulator already publishes this one's state topics (same name and namespace): refused."""


DUPLICATE_DISCOVERY_S = 0.5   # s after the node is created that the graph is watched for an older simulator


class Simulator(Node):
    """Feeder simulator: see the module docstring and docs/interface.md.

    ``overrides``: parameter values that win over ``--ros-args`` and the defaults (used by
    ``micro-feeder run --params/--set``). Raises :class:`ParameterError` for a refused value and
    :class:`SimulationError` when the parameters cannot even start the simulation.
    """

    def __init__(self, overrides: Mapping[str, Any] | None = None, *, hold: bool = False, **kwargs: Any):
        """``hold``: the wall-clock loop waits at t = 0 until :meth:`resume` (``micro-feeder run`` holds it
        until its actuator and recorder are there), whatever ``start_paused`` says."""
        super().__init__('simulator', **kwargs)
        created = time.monotonic()
        self.started_at_ns = time.time_ns()     # tells this simulator from a twin of its name (older one wins)
        self.twins: set[int] = set()            # older live simulators of this name seen (their start times)
        self.refusal = ''                       # why this node must not run on this graph (spin_node exits 2)
        # 10 deep: this node's own events arrive here too, and a history of 1 let one of them overwrite a
        # twin's latched event before the executor took it (under load: the twin never seen, both ran)
        self._twin_watch = self.create_subscription(ParameterEvent, '~/parameters', self._on_twin_parameters,
                                                    topic_qos('simulator/parameters', TWIN_WATCH_DEPTH))
        # First, what destroy_node() needs: rclpy destroys a node whose construction failed below (a refused
        # parameter) at shutdown, and that must not end in an AttributeError hiding the reason.
        self._loop: TickLoop | None = None
        self._intake: CommandIntake | None = None
        self._lock = threading.RLock()      # the stepper and the state publishers: tick thread vs the rest
        self._t_end = math.inf              # stop_at(): sim time never advances past this
        self._stopped_at: Future | None = None
        self._model_specs = model_specs()
        # One /clock per graph by default: only a simulator in the root namespace publishes it.
        clock_spec = (NODE_SPECS['publish_clock'][0], self.get_namespace() == '/')
        self._specs = {**self._model_specs, **NODE_SPECS, 'publish_clock': clock_spec}
        declare(self, self._specs, overrides)
        self._stepper = Stepper(build_model(values(self, self._model_specs)))
        self._model_parameters = self._parameter_msgs(self._model_specs)
        self._model_pending = False
        p = values(self, NODE_SPECS)
        self._rtf: float = p['real_time_factor']
        self._step_period: float = p['step_period']
        self._period = 1.0 / p['publish_rate']
        self._lockstep: bool = p['lockstep']
        self._user_paused: bool = p['start_paused']
        self._paused = True
        self._markers_period = 1.0 / p['markers_rate']
        self._max_command_bytes: int = p['max_command_bytes']
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        self._refuse_twin(created)
        self._pub_pose = self._publisher(PoseStamped, 'particle/pose')
        self._pub_twist = self._publisher(TwistStamped, 'particle/twist')
        self._pub_wrench = self._publisher(WrenchStamped, 'particle/contact_wrench')
        self._pub_joints = self._publisher(JointState, 'actuator/joint_states')
        self._pub_mode = self._publisher(String, 'particle/contact_state')
        self._pub_transitions = self._publisher(DiagnosticArray, 'particle/transitions')
        self._pub_markers = self._publisher(MarkerArray, 'surface/markers')
        self._pub_part_poses = self._publisher(PoseArray, 'particles/poses')
        self._pub_part_states = self._publisher(Float64MultiArray, 'particles/states')
        self._pub_part_transitions = self._publisher(DiagnosticArray, 'particles/transitions')
        self._pub_clock = self._publisher(ClockMsg, '/clock') if p['publish_clock'] else None
        self._pub_diag = self._publisher(DiagnosticArray, '/diagnostics')
        self._pub_parameters = self._publisher(ParameterEvent, 'simulator/parameters', '~/parameters')
        self._pub_receipts = self._publisher(Header, 'simulator/command_receipts', '~/command_receipts')
        self._pub_status = self._publisher(DiagnosticArray, 'simulator/command_status', '~/command_status')
        self._pub_entity_changes = self._publisher(DiagnosticArray, ENTITY_CHANGES, '~/entity_changes')
        self._pub_received = {topic: self._publisher(COMMAND_TYPES[topic], copy, '~/' + copy.split('/')[-1])
                              for topic, copy in RECEIVED_COPIES.items()}
        for topic, msg_type in COMMAND_TYPES.items():
            self.create_subscription(msg_type, topic, lambda data, t=topic: self._on_command(t, data),
                                     topic_qos(topic, COMMAND_QUEUE), raw=True)
        self._sim_control = SimulationControl(self, self, self.sim_time)   # simulation_interfaces, std_srvs
        self._trajectory_action = TrajectoryAction(self, self)             # FollowJointTrajectory

        self.commands = IntakeCounters()
        self.command_serial = 0     # +1 for every command applied and every reset: what replaced a goal's strokes
        self._instance = f'{self.get_fully_qualified_name()}@{time.time_ns():x}'   # names goals without a name
        self._goals_followed = 0
        self._last_command_wall: float | None = None   # time.monotonic() of the last command received
        self._stream_open = False       # the last trajectory applied was a stream's window (stamped, not empty)
        self._refusal_log = ThrottledLog()
        self._late_log = ThrottledLog(label='late')
        self.steps_granted = 0
        self.states_published = 0
        self.error = ''
        self._mode = ''
        self._generation = 0                # model generation: commands parsed for an older model re-parse
        self._window = (time.perf_counter(), self._stepper.t, 0)
        self.achieved_rtf = 0.0
        self._last_markers = -float('inf')
        self._transitions = TransitionEncoder(status_name(self, 'transition').removesuffix(': transition'))
        self._configure_outputs()
        self._publish_parameters()
        self._publish_state([])
        self.create_timer(1.0, self._publish_diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME))
        self._intake = CommandIntake(self._process_commands, lambda: self._paused,
                                     max_message_bytes=self._max_command_bytes,
                                     max_queued_bytes=4 * self._max_command_bytes,
                                     batch_interval=0.5 * self._period)
        if not self._lockstep:
            self._loop = TickLoop(self._period, self._tick, self._loop_failed)
            self._set_paused(self._user_paused or hold)

    def _refuse_twin(self, created: float) -> None:
        """Raise :class:`DuplicateSimulator` when a live simulator of this name (same node name and namespace)
        is on the graph: its latched ``~/parameters`` arrives within :data:`DUPLICATE_DISCOVERY_S` of this
        node's creation (read by hand: no executor spins the node yet, and this one has published nothing).
        A dead one's leftover graph entries send nothing, so a restart is not refused. Slower discovery is
        caught later by :meth:`_on_twin_parameters`."""
        while True:
            taken = self._twin_watch.handle.take_message(ParameterEvent, False)
            if taken is not None:
                raise DuplicateSimulator(self._twin_message(taken[0].node))
            if time.monotonic() - created >= DUPLICATE_DISCOVERY_S:
                return
            time.sleep(0.02)

    def _twin_message(self, node: str) -> str:
        return (f'another simulator named {node} is running: two simulators in one namespace would mix their '
                'states, commands and logs. Start this one in its own namespace (--ros-args -r __ns:=/feeder2, '
                'or micro-feeder run --namespace feeder2), or stop the other')

    def _on_twin_parameters(self, msg: ParameterEvent) -> None:
        """``~/parameters`` of a simulator of this name: this node's own (same ``started_at_ns``), a newer twin
        (it stops itself on this node's event), or an older one that discovery showed too late for
        :meth:`_refuse_twin`: this node then stops as on a failure, with the reason."""
        started = next((p.value.integer_value for p in msg.new_parameters if p.name == 'started_at_ns'), 0)
        if started == self.started_at_ns or started > self.started_at_ns or started in self.twins:
            return
        self.twins.add(started)
        self.refusal = self._twin_message(msg.node)
        self._fail(self.refusal)

    def _publisher(self, msg_type: type, topic: str, name: str | None = None) -> Any:
        return self.create_publisher(msg_type, name or topic, topic_qos(topic))

    # -- public, for micro-feeder run and tests -----------------------------------------------------

    @property
    def stepper(self) -> Stepper:
        return self._stepper

    @property
    def paused(self) -> bool:
        """True when the wall clock does not advance sim time (paused, failed, ended, or lockstep)."""
        return self._paused

    @property
    def lockstep(self) -> bool:
        return self._lockstep

    def sim_time(self) -> float:
        """Sim time now (s)."""
        return self._stepper.t

    def limits(self) -> tuple[float, float]:
        """The stroke travel (m) commands must stay in: the piezo limits."""
        return self._stepper.limits

    @property
    def joints(self) -> list[str]:
        return joint_names(self._stepper.model.n_actuators)

    @property
    def rejected(self) -> int:
        """Commands refused since start (invalid or too large)."""
        return self.commands.refused

    @property
    def last_rejection(self) -> str:
        return self.commands.last_refusal

    @property
    def overruns(self) -> int:
        """Ticks whose work took longer than the loop period, since start."""
        return self._loop.timing.overruns if self._loop is not None else 0

    def grant_step(self) -> tuple[bool, str]:
        """Advance one ``step_period`` and publish: what ``~/step`` does, after the commands received so
        far. Only while paused (always, in lockstep), not after a simulation failure and not past
        :meth:`stop_at`'s end. Returns (success, message)."""
        if self._intake is not None:
            self._intake.drain()
        with self._lock:
            return self._grant_step()

    def stop_at(self, t_end: float) -> Future:
        """Never advance sim time past ``t_end`` (s): the loop (or a lockstep grant) stops exactly there and
        pauses; the returned future completes when sim time reaches it (at once if it already has)."""
        with self._lock:
            self._t_end = t_end
            self._stopped_at = Future()
            self._check_end()
            return self._stopped_at

    def pause(self) -> None:
        """Stop the wall-clock loop advancing sim time (after the tick in progress, if any): the state is
        final until something resumes it. Lockstep is always paused."""
        with self._lock:
            self._user_paused = True
            self._set_paused(True)

    def resume(self) -> None:
        """Let the wall-clock loop advance sim time (what ``~/pause false`` does); no effect in lockstep, after a
        failure or at :meth:`stop_at`'s end."""
        with self._lock:
            self._user_paused = False
            self._set_paused(False)

    def outputs_matched(self) -> bool:
        """True when every state topic the simulator publishes has at least one subscription matched (a
        recorder that has not yet matched a topic would miss its first messages)."""
        return all(pub.get_subscription_count() > 0 for pub in
                   (self._pub_pose, self._pub_twist, self._pub_wrench, self._pub_joints, self._pub_mode,
                    self._pub_transitions, self._pub_markers, self._pub_parameters, self._pub_receipts,
                    self._pub_part_poses, self._pub_part_states, self._pub_part_transitions,
                    *self._pub_received.values()))

    def destroy_node(self) -> None:
        """Stop the loop and intake threads (waiting up to :data:`STOP_TIMEOUT` each for work in
        progress: a tick stuck in the physics is left to die with the process), then destroy the node."""
        if self._loop is not None:
            self._loop.stop(timeout=STOP_TIMEOUT)
        if self._intake is not None:
            self._intake.stop(timeout=STOP_TIMEOUT)
        super().destroy_node()

    # -- loop ---------------------------------------------------------------------------------------

    def _set_paused(self, paused: bool) -> None:
        """Pause or run the wall-clock loop; it stays paused after a failure, at the end and in lockstep."""
        was_paused = self._paused
        self._paused = paused or bool(self.error) or self._lockstep or self._stepper.t >= self._t_end
        if was_paused and not self._paused:     # the achieved real-time factor counts from here
            self._window = (time.perf_counter(), self._stepper.t, self.states_published)
        if self._loop is not None:
            if self._paused:
                self._loop.pause()
            else:
                self._loop.resume()

    def _tick(self, elapsed: float) -> None:
        """One loop tick: advance by the elapsed wall time × real_time_factor (at most two periods' worth)
        or, as fast as possible, steps of ``step_period`` for 80 % of the period."""
        with self._lock:
            if self._paused:
                return
            if self._rtf > 0.0:
                self._step(self._stepper.t + min(elapsed, 2.0 * self._period) * self._rtf)
            else:
                deadline = time.perf_counter() + 0.8 * self._period
                while not self._paused and time.perf_counter() < deadline:
                    self._step(self._stepper.t + self._step_period)

    def _loop_failed(self, err: BaseException) -> None:
        self._fail(f'loop thread stopped: {type(err).__name__}: {err}')

    def _grant_step(self) -> tuple[bool, str]:
        if not self._paused or self.error:
            return False, self.error or 'step needs the simulation paused (call ~/pause true)'
        if self._stepper.t >= self._t_end:
            return False, f'stopped at t = {self._stepper.t:.9f} s (end of the run)'
        self.steps_granted += 1
        self._step(self._stepper.t + self._step_period)
        return not self.error, self.error or f't = {self._stepper.t:.9f} s'

    def _step(self, t_target: float) -> None:
        """Advance to ``t_target`` (never past :meth:`stop_at`'s end) and publish; on a simulation failure
        pause and report it."""
        try:
            events = self._stepper.advance_parts(min(t_target, self._t_end))
        except SimulationError as err:
            self._fail(str(err))
            return
        self._publish_state(events)
        self._check_end()

    def _check_end(self) -> None:
        """At :meth:`stop_at`'s end: pause and complete its future."""
        if self._stepper.t >= self._t_end and self._stopped_at is not None:
            self._set_paused(True)
            if not self._stopped_at.done():
                self._stopped_at.set_result(self._stepper.t)

    def _fail(self, error: str) -> None:
        """Stop on an error: pause, log it, report it on /diagnostics (cleared by ~/reset)."""
        with self._lock:
            self.error = error
            self._set_paused(True)
        self.get_logger().error(f'simulation stopped (paused; call ~/reset): {error}')
        self._publish_diagnostics()

    def _publish_state(self, events: Sequence[Sequence[Event]]) -> None:
        """Publish the state now, with ``events`` (each part's mode changes since the last time)."""
        self.states_published += 1
        observations = self._stepper.observe_parts()
        obs = observations[0]
        parts = self._parts_messages
        parts.update(observations)
        self._pub_part_poses.publish(parts.poses)
        self._pub_part_states.publish(parts.states)
        for part, part_events in enumerate(events):
            for event in part_events:
                if event.kind != 'reversal':
                    self._pub_part_transitions.publish(self._transitions.encode(event, part))
        events = events[0] if events else []
        state = self._state_messages
        stamp = state.update(obs, obs.stroke_velocities)
        self._pub_pose.publish(state.pose)
        self._pub_twist.publish(state.twist)
        self._pub_wrench.publish(state.wrench)
        self._pub_joints.publish(state.joints)
        for event in events:
            if event.kind != 'reversal':
                self._pub_transitions.publish(self._transitions.encode(event))
                self._publish_mode(event.to_mode)
        self._publish_mode(obs.mode)
        if self._pub_clock is not None:
            self._pub_clock.publish(state.clock)
        now = time.perf_counter()
        if now - self._last_markers >= self._markers_period:
            self._last_markers = now
            self._pub_markers.publish(self._markers.update(obs, stamp))

    def _publish_mode(self, mode: str) -> None:
        if mode != self._mode:
            self._mode = mode
            self._pub_mode.publish(messages.contact_state_bytes(mode))

    def _configure_outputs(self) -> None:
        """Per-model output buffers: the state messages (one joint per actuator) and the surface markers."""
        self._state_messages = messages.StateMessages(self.joints)
        self._parts_messages = PartsMessages(self._stepper.n_parts)
        surface = self._stepper.model.surface
        c, w = np.asarray(surface.centers), np.asarray(surface.widths)
        xs = np.linspace(float(np.min(c - 4 * w)), float(np.max(c + 4 * w)), MARKER_POINTS)
        track = self._stepper.model.track
        self._markers = messages.SurfaceMarkers(
            xs, surface.centers, surface.widths, PART_SIZE,
            math.sin(track.vibration_angle) if surface.kind == 'track' else None)

    # -- commands -----------------------------------------------------------------------------------

    def _on_command(self, topic: str, data: bytes) -> None:
        """Subscription callback (executor thread): queue the serialized message; the intake does the rest."""
        self.commands.received += 1
        stamp = stamps.header_stamp(data) if topic == 'actuator/trajectory' else 0.0
        command_id = stamps.header_frame_id(data) if topic == 'actuator/trajectory' else ''
        self._last_command_wall = time.monotonic()
        if topic in self._pub_received:        # the copy a recorder holds whichever senders it discovered
            self._pub_received[topic].publish(data)
        self._intake.submit(Received(topic, data, stamp, command_id=command_id))

    def _parse(self, received: Received) -> tuple[str, Any]:
        """A checked command for the current model, or ValueError with the reason (no lock needed)."""
        stepper = self._stepper
        joints = joint_names(stepper.model.n_actuators)
        if received.topic == 'actuator/trajectory':     # read from its bytes (rclpy's for odd layouts)
            return received.topic, parse_trajectory_cdr(received.data, joints, stepper.limits)
        values = read_float64_array(received.data)
        if values is None:
            try:
                values = wire.deserialize(received.data, Float64MultiArray).data
            except Exception as err:  # rclpy raises several types for malformed bytes
                raise ValueError(f'{received.topic}: cannot deserialize: {err}') from err
        return received.topic, parse_setpoints(values, stepper.model.n_actuators, stepper.limits)

    def _plan(self, batch: list[Received]) -> list[Outcome]:
        # in lockstep every command message is a grant: nothing is coalesced
        return plan(batch, self._stepper.t, start_time, self._parse, coalesce=not self._lockstep)

    def _process_commands(self, batch: list[Received]) -> None:
        """Plan ``batch`` (parsing outside the lock), then acknowledge and apply it in arrival order
        between two ticks; in lockstep each command grants its step. A refusal is answered on
        ``~/command_status``."""
        generation = self._generation
        outcomes = self._plan(batch)
        receipts: list[tuple[Received, float, str]] = []    # published after the lock: a tick waits for it
        with self._lock:
            if generation != self._generation:      # a reset changed the model while parsing
                outcomes = self._plan(batch)
            for outcome in outcomes:
                t = self._stepper.t
                if self._lockstep:
                    self._acknowledge(outcome.received, t)
                    self._answer(outcome.received, t, self._apply(outcome))
                    self._grant_step()
                else:
                    receipts.append((outcome.received, t, self._apply(outcome)))
        for received, t, refusal in receipts:
            self._acknowledge(received, t)
            self._answer(received, t, refusal)
        self.commands.dropped = self._intake.dropped if self._intake is not None else 0

    def _apply(self, outcome: Outcome) -> str:
        """Apply (or coalesce, drop, refuse) one command; returns why it was not applied ('' otherwise)."""
        if outcome.coalesced:
            self.commands.coalesced += 1
            return ''
        if outcome.dropped:
            reason = f'{outcome.received.topic}: dropped unparsed, the command queue was full'
            self._log_refusals(self._refusal_log.note(reason))
            return reason
        if outcome.refused:
            self._refuse(outcome.refused)
            return outcome.refused
        topic, command = outcome.command
        try:
            if topic == 'actuator/trajectory':
                self._note_late(command.stamp)
                self._stepper.command_trajectory(command)
                self._stream_open = command.stamp > 0.0 and not command.is_stop
            else:
                self._stepper.command_setpoints(command)
                self._stream_open = False
        except ValueError as err:
            self._refuse(str(err))
            return str(err)
        self.command_serial += 1
        return ''

    def _note_late(self, stamp: float) -> None:
        """A trajectory stamped before now starts now (joint_trajectory_controller semantics): what it
        scheduled before is lost, and a stream joined mid-stroke can throw the part. Counted, and logged
        throttled like refusals."""
        late = self._stepper.t - stamp
        # stamps are whole nanoseconds and sim time a sum of step periods: a stamp equal to the sim time
        # rounded to the nanosecond is on time (lockstep used to warn "late by 0.000 ms")
        if stamp > 0.0 and round(self._stepper.t * 1e9) > round(stamp * 1e9):
            self.commands.late += 1
            self._log_refusals(self._late_log.note(
                f'actuator/trajectory arrived {late * 1e3:.3f} ms after its stamp: its knots before sim time '
                f'{self._stepper.t:.6f} s were dropped (the sender should schedule further ahead, e.g. the '
                "actuator's stream.lead)"))

    def _stream_silent(self, t: float) -> float:
        """Sim seconds since the strokes of a stream (the last trajectory applied was a window stamped ahead)
        ran out with nothing after them: its sender stalled, died or lost the simulator. 0 otherwise."""
        if not self._stream_open:
            return 0.0
        start, table = self._stepper.schedule.pieces[-1]
        return max(t - max(start, table.end_time()), 0.0)

    def _acknowledge(self, received: Received, t: float) -> None:
        """``~/command_receipts``: a command arrived on its topic (with its identity, if it has one) and was
        handled at sim time ``t`` (s)."""
        self._pub_receipts.publish(messages.header_bytes(t, receipt_frame(received.topic, received.command_id)))

    def _answer(self, received: Received, t: float, refusal: str) -> None:
        """``~/command_status``: why the command received at sim time ``t`` (s) was not applied (refusals only)."""
        if refusal:     # published as bytes: a flood of refusals is answered one by one
            self._pub_status.publish(messages.command_status(
                t, receipt_frame(received.topic, received.command_id), status_name(self, 'command'),
                received.topic, received.command_id, refusal))

    def _refuse(self, reason: str) -> None:
        self.commands.refused += 1
        self.commands.last_refusal = reason
        self._log_refusals(self._refusal_log.note(reason))

    def _log_refusals(self, line: str | None) -> None:
        if line is not None:
            self.get_logger().warning(line)

    # -- services -----------------------------------------------------------------------------------

    def _locked(self, lock: Any) -> Any:
        """``lock`` acquired within :data:`BUSY_TIMEOUT`, as a context manager; raises :class:`Busy`."""
        if not lock.acquire(timeout=BUSY_TIMEOUT):
            age = self._loop.timing.tick_age(time.perf_counter()) if self._loop is not None else 0.0
            raise Busy(f'busy: one tick has been working for {age:.1f} s (the physics cannot advance in '
                       'bounded time with these parameters); try again or stop the node')
        return _Release(lock)

    def reset(self, *, pause: bool = False) -> tuple[bool, str]:
        """What ``~/reset`` does (and ResetSimulation, SetSimulationState STOPPED with ``pause``): t = 0, the
        model parameters applied, commands dropped; runs again unless paused (or ``pause``). Returns (success,
        message); refused, with nothing changed, when the parameters cannot build a model or within
        :data:`BUSY_TIMEOUT` the lock cannot be had."""
        # The model is built and checked without the lock (new contact tables take ~1 s; the loop keeps
        # ticking meanwhile) and swapped in under it.
        parameters = self._parameter_msgs(self._model_specs)
        try:
            stepper = Stepper(build_model(values(self, self._model_specs)))
            _check_finite(stepper)
            stepper.applied = self._stepper.applied      # a command applied before the reset stays applied
        except (ParameterError, ValueError, SimulationError) as err:
            return False, f'model parameters refused, not reset: {err}'
        try:
            with self._locked(self._intake.busy), self._locked(self._lock):
                self._intake.drain()
                self._stepper = stepper
                self.command_serial += 1
                self._stream_open = False
                self._generation += 1
                self._model_parameters = parameters
                self._model_pending = False
                self.error = ''
                self._mode = ''
                self._configure_outputs()
                self._window = (time.perf_counter(), 0.0, self.states_published)
                self._publish_parameters()
                self._publish_state([])
                self._user_paused = self._user_paused or pause
                self._set_paused(self._user_paused)
        except Busy as err:
            return False, str(err)
        return True, f't = 0, model parameters applied, {"paused" if self._paused else "running"}'

    def set_paused(self, paused: bool) -> tuple[bool, str]:
        """What ``~/pause`` does: pause, or run (refused after a failure and in lockstep). (success, message)."""
        try:
            with self._locked(self._lock):
                if not paused and self.error:
                    return False, f'cannot resume after a failure: {self.error}'
                if not paused and self._lockstep:
                    return False, ('lockstep: sim time advances only per ~/step call or command message, '
                                   'never on the wall clock')
                self._user_paused = paused
                self._set_paused(paused)
                return True, f'{"paused" if self._paused else "running"} at t = {self._stepper.t:.9f} s'
        except Busy as err:
            return False, str(err)

    def step(self) -> tuple[bool, str]:
        """What ``~/step`` does: :meth:`grant_step`, or (False, ``busy: ...``) when a tick holds the lock for
        longer than :data:`BUSY_TIMEOUT`."""
        try:
            with self._locked(self._intake.busy), self._locked(self._lock):
                return self.grant_step()
        except Busy as err:
            return False, str(err)

    def observe(self) -> Observation:
        """Part 0's state now, as published (taken under the lock, between two ticks); raises :class:`Busy`."""
        with self._locked(self._lock):
            return self._stepper.observe()

    def observe_parts(self) -> list[Observation]:
        """Every part's state now, in part order (as :meth:`observe`)."""
        with self._locked(self._lock):
            return self._stepper.observe_parts()

    def entity_names(self) -> list[str]:
        """Every part's entity name now, in part order."""
        with self._locked(self._lock):
            return list(self._stepper.entity_names)

    def observe_entities(self) -> tuple[list[str], list[Observation]]:
        """Every part's entity name and state now, in part order."""
        with self._locked(self._lock):
            return list(self._stepper.entity_names), self._stepper.observe_parts()

    def spawn_part(self, name: str, x: float) -> tuple[bool, str]:
        """SpawnEntity: a part named ``name`` placed at ``x`` (m) now, at rest (:meth:`Stepper.spawn_part`);
        recorded on ``simulator/entity_changes``. (success, message: the reason of a refusal)."""
        return self._change_parts(SPAWNED, name, lambda: self._stepper.spawn_part(name, x))

    def delete_part(self, name: str) -> tuple[bool, str]:
        """DeleteEntity: the part named ``name`` removed now (:meth:`Stepper.delete_part`), recorded as
        :meth:`spawn_part`'s."""
        return self._change_parts(DELETED, name, lambda: self._stepper.delete_part(name))

    def _change_parts(self, kind: str, name: str, change: Callable[[], int]) -> tuple[bool, str]:
        with self._locked(self._lock):
            stepper = self._stepper
            before = dict(zip(stepper.entity_names, stepper.parts_state.positions.tolist(), strict=True))
            try:
                index = change()
            except ValueError as err:
                return False, str(err)
            x = before[name] if kind == DELETED else stepper.parts_state.parts[index].x
            change_record = EntityChange(kind, name, index, stepper.t, x)
            self._parts_messages = PartsMessages(stepper.n_parts)
            self._pub_entity_changes.publish(change_record.message(status_name(self, 'entity')))
        message = f'{name} {kind} at x = {x * 1e3:.6g} mm, t = {change_record.t:.9f} s: {stepper.n_parts} parts'
        self.get_logger().info(message)
        return True, message

    def follow(self, message: JointTrajectory | None = None) -> tuple[int, float, TrajectoryCommand]:
        """Check and apply a FollowJointTrajectory goal's trajectory (None: an empty one, which holds the
        strokes) as the same message received on ``actuator/trajectory`` now would be, after the commands
        received before it; returns (its :attr:`command_serial`, its start in sim time (s), the command).
        Like a topic command it is copied on ``simulator/trajectories_received`` and acknowledged on
        ``simulator/command_receipts``, applied or refused, named by its ``header.frame_id`` or, without one,
        ``<node>@<start>:fjt<k>``: a log of a goal-driven run replays. Raises ValueError with the reason
        (:class:`CommandRejected` from the schedule: the interpolation leaves the travel, a duplicate, a late
        join that would jump) or :class:`Busy` (then nothing was received)."""
        copy = JointTrajectory(joint_names=self.joints) if message is None else deepcopy(message)
        if not copy.header.frame_id:
            self._goals_followed += 1
            copy.header.frame_id = f'{self._instance}:fjt{self._goals_followed}'
        generation = self._generation
        parsed = self._parse_goal(copy)                     # outside the lock: a long goal takes a while
        received = Received('actuator/trajectory', b'', stamps.seconds(copy.header.stamp),
                            command_id=copy.header.frame_id)
        with self._locked(self._intake.busy), self._locked(self._lock):
            self._intake.drain()
            if generation != self._generation:              # a reset changed the model while parsing
                parsed = self._parse_goal(copy)
            self.commands.received += 1
            self._pub_received['actuator/trajectory'].publish(copy)
            t = self._stepper.t
            refusal = parsed if isinstance(parsed, ValueError) else None
            if refusal is None:
                try:
                    start = self._stepper.command_trajectory(parsed)
                except ValueError as err:
                    refusal = err
            if refusal is not None:
                self._refuse(str(refusal))
            else:
                self._stream_open = False
                self.command_serial += 1
                serial = self.command_serial
        self._acknowledge(received, t)
        if refusal is not None:
            raise refusal
        return serial, start, parsed

    def _parse_goal(self, message: JointTrajectory) -> TrajectoryCommand | ValueError:
        try:
            return parse_trajectory(message, self.joints, self._stepper.limits)
        except ValueError as err:
            return err

    def strokes(self, t: float | None = None) -> tuple[np.ndarray, Observation]:
        """((3, joints) commanded s, ṡ, s̈ at ``t`` (s; default now), the state now), under the lock; raises
        :class:`Busy`."""
        with self._locked(self._lock):
            obs = self._stepper.observe()
            return self._stepper.schedule.evaluate(obs.t if t is None else t), obs

    # -- parameters and diagnostics -----------------------------------------------------------------

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        """On-set callback: only checks (a refused set changes nothing); :meth:`_apply_parameters` applies."""
        reason = check_changes(self._specs, values(self, self._model_specs), params)
        return SetParametersResult(successful=reason is None, reason=reason or '')

    def _apply_parameters(self, params: list[Parameter]) -> None:
        """Post-set callback: the node's parameters apply at once, the model's on ~/reset. Says so once per
        reset, not once per set (a client setting 450 parameters one by one got 450 INFO lines)."""
        with self._lock:
            was_pending = self._model_pending
            for param in params:
                if param.name == 'real_time_factor':
                    self._rtf = param.value
                elif param.name == 'step_period':
                    self._step_period = param.value
                elif param.name in self._model_specs:
                    self._model_pending = True
            if any(p.name in NODE_SPECS for p in params):
                self._publish_parameters()
        if self._model_pending and not was_pending:
            self.get_logger().info('model parameters changed: applied on ~/reset (further changes before it are '
                                   'not logged; /diagnostics: model_parameters_pending_reset)')

    def _parameter_msgs(self, names: Iterable[str]) -> list[ParameterMsg]:
        return [self.get_parameter(name).to_parameter_msg() for name in names]

    def _publish_parameters(self) -> None:
        """The parameters in force on the latched ``~/parameters``, stamped with the sim time: the model's
        as last applied (not a change waiting for reset) and the node's current ones."""
        self._pub_parameters.publish(ParameterEvent(
            stamp=stamps.to_time(self._stepper.t), node=self.get_fully_qualified_name(),
            new_parameters=[*self._model_parameters, *self._parameter_msgs(NODE_SPECS),
                            Parameter('started_at_ns', value=self.started_at_ns).to_parameter_msg()]))

    def diagnostics(self) -> DiagnosticStatus:
        """The simulator's status (:func:`loop_status`): achieved real-time factor over the time since the
        last call, tick timing, counters. Takes no lock, so it reports even while a tick is stuck."""
        now, t, published = time.perf_counter(), self._stepper.t, self.states_published
        wall0, sim0, published0 = self._window
        self.achieved_rtf = achieved_rtf((wall0, now), (sim0, t))
        publish_rate = achieved_rtf((wall0, now), (published0, published))
        self._window = (now, t, published)
        loop = self._loop
        periods, busy = loop.timing.drain() if loop is not None else (np.zeros(0), np.zeros(0))
        state = self._stepper.state
        status = loop_status(LoopSnapshot(
            sim_time=t, mode=state.mode, paused=self._paused, lockstep=self._lockstep, error=self.error,
            rtf_target=self._rtf, achieved_rtf=self.achieved_rtf,
            publish_rate=publish_rate, periods_ms=periods, busy_ms=busy,
            overruns=self.overruns, tick_age=loop.timing.tick_age(now) if loop is not None else 0.0,
            steps_granted=self.steps_granted, states_published=self.states_published,
            pending_reset=self._model_pending, transitions=state.transitions,
            intake=self.commands.as_items(),
            other_simulators=len(self.twins),
            command_age=(time.monotonic() - self._last_command_wall if self._last_command_wall is not None
                         else math.nan),
            stream_silent=self._stream_silent(t)))
        if status.level != 0:
            self.get_logger().warning(status.message, throttle_duration_sec=10.0)
        return DiagnosticStatus(name=status_name(self, 'loop'), hardware_id='micro_feeder',
                                level=bytes([status.level]), message=status.message,
                                values=[KeyValue(key=k, value=v) for k, v in status.values.items()])

    def _publish_diagnostics(self) -> None:
        self._log_refusals(self._refusal_log.flush())
        self._log_refusals(self._late_log.flush())
        self._pub_diag.publish(DiagnosticArray(header=Header(stamp=stamps.to_time(self._stepper.t)),
                                               status=[self.diagnostics()]))


def _check_finite(stepper: Stepper) -> None:
    """Raise :class:`SimulationError` when the state a stepper would publish first is not finite."""
    obs = stepper.observe()
    published = (obs.x, obs.z, obs.xdot, obs.zdot, obs.theta, obs.normal_load, obs.friction)
    if not all(math.isfinite(v) for v in published):
        raise SimulationError(f'the state at t = 0 is not finite (x, z, ẋ, ż, θ, N, T = {published})')


class _Release:
    """Context manager releasing a lock that was acquired already."""

    def __init__(self, lock: Any):
        self._lock = lock

    def __enter__(self) -> None:
        return None

    def __exit__(self, *_exc: object) -> None:
        self._lock.release()


def main(args: list[str] | None = None) -> int:
    """Console script ``simulator``: ``simulator --ros-args --params-file config/feeder.yaml -p ...``."""
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    return spin_node('simulator', Simulator, args)
