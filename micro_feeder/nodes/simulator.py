"""The ``simulator`` node: the real-time loop of DESIGN.md §4 around the physics stepper.

A loop thread owned by the node ticks at ``publish_rate`` on the wall clock and advances sim time by
elapsed wall time × ``real_time_factor`` (0: as fast as possible, ``step_period`` per step), never more
than two periods' worth per tick (a late tick slows sim time instead of building up a debt), then
publishes the state on the topics of docs/interface.md. Why a thread and not an rclpy timer: rclpy's
timer dispatch alone costs 12-15 % of a core at 1 kHz and adds jitter (bench/bench_nodes.py); a thread
sleeping to its next deadline costs a fraction of that. The executor (on whatever thread spins the node)
still runs the subscriptions, services, parameter callbacks and the 1 Hz diagnostics; one lock
serialises everything that touches the stepper or publishes state, so a command or a service call
happens between two ticks, never inside one. The thread sleeps while paused and is stopped and joined
by :meth:`Simulator.destroy_node` (which ``rclpy.shutdown`` also calls for a node left alive).

Commands on ``actuator/trajectory`` / ``actuator/command`` are checked (:mod:`.commands`) and applied
by their stamps in sim time, so a paused run advanced with ``simulator/step`` is repeatable bit for bit.
With ``lockstep`` the wall clock never advances sim time (there is no loop thread): each
``simulator/step`` call and each command message received grants one ``step_period`` (the command is
applied first), so a controller under test sees the same physics however slow it is. Model parameters
can be set at any time and are applied on ``simulator/reset``; ``real_time_factor`` and ``step_period``
apply at once.

For ``resim`` (:mod:`.resim`) a log must say what the simulator did with each command: the parameters in
force go out on the latched ``simulator/parameters`` (at start, on reset, on a change that applies at
once) and every command received, applied or refused, is acknowledged on ``simulator/command_receipts``
with the sim time it was received at.
"""

from __future__ import annotations

import collections
import functools
import math
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from typing import Any, TypeVar

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TwistStamped, WrenchStamped
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterEvent, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray, Header, String
from std_srvs.srv import SetBool, Trigger
from trajectory_msgs.msg import JointTrajectory
from visualization_msgs.msg import MarkerArray

from ..physics.dynamics import Event, SimulationError
from ..physics.parameters import ParameterError, ParamSpec
from . import messages
from ._ros import topic_qos
from .commands import CommandRejected, joint_names, parse_setpoints, parse_trajectory
from .parameters import check_changes, declare, model_specs, values
from .spin import spin_node
from .stepper import Stepper, build_model

NODE_SPECS: dict[str, tuple[ParamSpec, Any]] = {
    'publish_rate': (ParamSpec('rate of the loop timer and of the state topics', 'Hz', gt=0, le=10000,
                               read_only=True), 1000.0),
    'real_time_factor': (ParamSpec('sim seconds per wall second; 0 = as fast as possible', '', ge=0, le=1000),
                         1.0),
    'start_paused': (ParamSpec('start paused: advance with simulator/step, run with simulator/pause false',
                               kind='bool', read_only=True), False),
    'publish_clock': (ParamSpec('publish sim time on /clock', kind='bool', read_only=True), True),
    'step_period': (ParamSpec('sim time advanced by one simulator/step call, and per step when '
                              'real_time_factor is 0', 's', gt=0, le=1.0), 1e-3),
    'markers_rate': (ParamSpec('rate of surface/markers (wall clock)', 'Hz', gt=0, le=1000, read_only=True),
                     30.0),
    'lockstep': (ParamSpec('sim time never advances on the wall clock: one step_period per simulator/step '
                           'call and per command message received', kind='bool', read_only=True), False),
}

F = TypeVar('F', bound=Callable[..., Any])


def locked(method: F) -> F:
    """Run a :class:`Simulator` method holding the node's lock (an entry point from another thread)."""
    @functools.wraps(method)
    def wrapper(self: Simulator, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return method(self, *args, **kwargs)
    return wrapper  # type: ignore[return-value]


PART_SIZE = 100e-6     # marker diameter of the part (m)
MARKER_POINTS = 200    # points of the surface line strip


class Simulator(Node):
    """Feeder simulator: see the module docstring and docs/interface.md.

    ``overrides``: parameter values that win over ``--ros-args`` and the defaults (used by
    ``micro-feeder run --params/--set``). Raises :class:`ParameterError` for a refused value.
    """

    def __init__(self, overrides: Mapping[str, Any] | None = None, **kwargs: Any):
        super().__init__('simulator', **kwargs)
        # First, what destroy_node() needs: rclpy destroys a node whose construction failed below (a refused
        # parameter) at shutdown, and that must not end in an AttributeError hiding the reason.
        self._running = threading.Event()   # set while the loop thread may tick (not paused, not stopping)
        self._stopping = False
        self._loop_thread: threading.Thread | None = None
        self._lock = threading.RLock()      # the stepper and the state publishers: tick thread vs executor
        self._t_end = math.inf              # stop_at(): sim time never advances past this
        self._stopped_at: Future | None = None
        self._model_specs = model_specs()
        self._specs = {**self._model_specs, **NODE_SPECS}
        declare(self, self._specs, overrides)
        self._stepper = Stepper(build_model(values(self, self._model_specs)))
        self._model_parameters = self._parameter_msgs(self._model_specs)
        self._model_pending = False
        p = values(self, NODE_SPECS)
        self._rtf: float = p['real_time_factor']
        self._step_period: float = p['step_period']
        self._period = 1.0 / p['publish_rate']
        self._publish_clock: bool = p['publish_clock']
        self._lockstep: bool = p['lockstep']
        self._paused: bool = p['start_paused'] or self._lockstep
        self._markers_period = 1.0 / p['markers_rate']
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)

        self._pub_pose = self._publisher(PoseStamped, 'particle/pose')
        self._pub_twist = self._publisher(TwistStamped, 'particle/twist')
        self._pub_wrench = self._publisher(WrenchStamped, 'particle/contact_wrench')
        self._pub_joints = self._publisher(JointState, 'actuator/joint_states')
        self._pub_mode = self._publisher(String, 'particle/contact_state')
        self._pub_markers = self._publisher(MarkerArray, 'surface/markers')
        self._pub_clock = self._publisher(ClockMsg, '/clock') if self._publish_clock else None
        self._pub_diag = self._publisher(DiagnosticArray, '/diagnostics')
        self._pub_parameters = self._publisher(ParameterEvent, 'simulator/parameters')
        self._pub_receipts = self._publisher(Header, 'simulator/command_receipts')
        self.create_subscription(JointTrajectory, 'actuator/trajectory', self._on_trajectory,
                                 topic_qos('actuator/trajectory'))
        self.create_subscription(Float64MultiArray, 'actuator/command', self._on_command,
                                 topic_qos('actuator/command'))
        self.create_service(Trigger, 'simulator/reset', self._on_reset)
        self.create_service(SetBool, 'simulator/pause', self._on_pause)
        self.create_service(Trigger, 'simulator/step', self._on_step)

        self.rejected = 0
        self.last_rejection = ''
        self.steps_granted = 0
        self.overruns = 0
        self.error = ''
        self._mode = ''
        self._tick_periods: collections.deque[float] = collections.deque(maxlen=4000)
        self._tick_busy: collections.deque[float] = collections.deque(maxlen=4000)
        self._last_tick = time.perf_counter()
        self._last_markers = -float('inf')
        self._window = (time.perf_counter(), self._stepper.t)
        self.achieved_rtf = 0.0
        self._configure_outputs()
        self._publish_parameters()
        self._publish_state([])
        self.create_timer(1.0, self._publish_diagnostics, clock=Clock(clock_type=ClockType.STEADY_TIME))
        if not self._lockstep:
            self._set_paused(self._paused)
            self._loop_thread = threading.Thread(target=self._loop, name='simulator-loop', daemon=True)
            self._loop_thread.start()

    def _publisher(self, msg_type: type, topic: str) -> Any:
        return self.create_publisher(msg_type, topic, topic_qos(topic))

    # -- public, for micro-feeder run and tests -----------------------------------------------------

    @property
    def stepper(self) -> Stepper:
        return self._stepper

    @property
    def paused(self) -> bool:
        """True when the wall clock does not advance sim time (paused, failed, or lockstep)."""
        return self._paused

    @property
    def lockstep(self) -> bool:
        return self._lockstep

    @property
    def joints(self) -> list[str]:
        return joint_names(self._stepper.model.n_actuators)

    @locked
    def grant_step(self) -> tuple[bool, str]:
        """Advance one ``step_period`` and publish: what ``simulator/step`` does. Only while paused (always,
        in lockstep), not after a simulation failure and not past :meth:`stop_at`'s end.
        Returns (success, message)."""
        if not self._paused or self.error:
            return False, self.error or 'step needs the simulation paused (call simulator/pause true)'
        if self._stepper.t >= self._t_end:
            return False, f'stopped at t = {self._stepper.t:.9f} s (end of the run)'
        self.steps_granted += 1
        self._step(self._stepper.t + self._step_period)
        return not self.error, self.error or f't = {self._stepper.t:.9f} s'

    @locked
    def stop_at(self, t_end: float) -> Future:
        """Never advance sim time past ``t_end`` (s): the loop (or a lockstep grant) stops exactly there and
        pauses; the returned future completes when sim time reaches it (at once if it already has)."""
        self._t_end = t_end
        self._stopped_at = Future()
        self._check_end()
        return self._stopped_at

    @locked
    def pause(self) -> None:
        """Stop the wall-clock loop advancing sim time (after the tick in progress, if any): the state is
        final until something resumes it. Lockstep is always paused."""
        if not self._lockstep:
            self._set_paused(True)

    def destroy_node(self) -> None:
        """Stop and join the loop thread, then destroy the node (publishers last)."""
        self._stopping = True
        self._running.set()
        if self._loop_thread is not None:
            self._loop_thread.join()
            self._loop_thread = None
        super().destroy_node()

    # -- loop ---------------------------------------------------------------------------------------

    def _set_paused(self, paused: bool) -> None:
        """Pause or run the wall-clock loop (the thread sleeps on ``_running`` while paused)."""
        self._paused = paused
        if paused:
            self._running.clear()
        else:
            self._last_tick = time.perf_counter()
            self._running.set()

    def _loop(self) -> None:
        """The loop thread: tick every ``_period`` s of wall time on a fixed grid (a late tick skips the
        grid points it missed rather than catching up), sleeping while paused, until :meth:`destroy_node`."""
        next_tick = time.perf_counter() + self._period
        while not self._stopping:
            if not self._running.is_set():
                self._running.wait()
                next_tick = time.perf_counter() + self._period
                continue
            delay = next_tick - time.perf_counter()
            if delay > 0.0:
                time.sleep(delay)
            if self._stopping:
                return
            try:
                self._tick()
            except Exception as err:  # a loop that dies silently would look like a frozen simulation
                self._fail(f'loop thread stopped: {type(err).__name__}: {err}')
                raise
            now = time.perf_counter()
            next_tick += self._period
            if next_tick <= now:
                next_tick += math.ceil((now - next_tick) / self._period) * self._period

    @locked
    def _tick(self) -> None:
        start = time.perf_counter()
        if self._paused:
            return
        self._tick_periods.append(start - self._last_tick)
        elapsed, self._last_tick = start - self._last_tick, start
        if self._rtf > 0.0:
            self._step(self._stepper.t + min(elapsed, 2.0 * self._period) * self._rtf)
        else:
            deadline = start + 0.8 * self._period
            while not self._paused and time.perf_counter() < deadline:
                self._step(self._stepper.t + self._step_period)
        busy = time.perf_counter() - start
        self._tick_busy.append(busy)
        if busy > self._period:
            self.overruns += 1

    def _step(self, t_target: float) -> None:
        """Advance to ``t_target`` (never past :meth:`stop_at`'s end) and publish; on a simulation failure
        pause and report it."""
        try:
            events = self._stepper.advance(min(t_target, self._t_end))
        except SimulationError as err:
            self._fail(str(err))
            return
        self._publish_state(events)
        self._check_end()

    def _check_end(self) -> None:
        """At :meth:`stop_at`'s end: pause and complete its future."""
        if self._stepper.t >= self._t_end and self._stopped_at is not None:
            if not self._lockstep:
                self._set_paused(True)
            if not self._stopped_at.done():
                self._stopped_at.set_result(self._stepper.t)

    @locked
    def _fail(self, error: str) -> None:
        """Stop on an error: pause, log it, report it on /diagnostics (cleared by simulator/reset)."""
        self.error = error
        self._set_paused(True)
        self.get_logger().error(f'simulation stopped (paused; call simulator/reset): {error}')
        self._publish_diagnostics()

    def _publish_state(self, events: list[Event]) -> None:
        obs = self._stepper.observe()
        state = self._state_messages
        stamp = state.update(obs, obs.stroke_velocities)
        self._pub_pose.publish(state.pose)
        self._pub_twist.publish(state.twist)
        self._pub_wrench.publish(state.wrench)
        self._pub_joints.publish(state.joints)
        for event in events:
            if event.kind != 'reversal':
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
            self._pub_mode.publish(String(data=mode))

    def _configure_outputs(self) -> None:
        """Per-model output buffers: the state messages (one joint per actuator) and the surface markers."""
        self._state_messages = messages.StateMessages(self.joints)
        surface = self._stepper.model.surface
        c, w = np.asarray(surface.centers), np.asarray(surface.widths)
        xs = np.linspace(float(np.min(c - 4 * w)), float(np.max(c + 4 * w)), MARKER_POINTS)
        self._markers = messages.SurfaceMarkers(xs, surface.centers, surface.widths, PART_SIZE)

    # -- commands -----------------------------------------------------------------------------------

    def _acknowledge(self, topic: str) -> None:
        """``simulator/command_receipts``: a command arrived on ``topic`` at the current sim time."""
        self._pub_receipts.publish(Header(stamp=messages.to_time(self._stepper.t), frame_id=topic))

    @locked
    def _on_trajectory(self, msg: JointTrajectory) -> None:
        self._acknowledge('actuator/trajectory')
        try:
            cmd = parse_trajectory(msg, self.joints, self._stepper.limits)
            self._stepper.command_trajectory(cmd)
        except (CommandRejected, ValueError) as err:
            self._reject(str(err))
        self._lockstep_grant()

    @locked
    def _on_command(self, msg: Float64MultiArray) -> None:
        self._acknowledge('actuator/command')
        try:
            self._stepper.command_setpoints(parse_setpoints(msg.data, self._stepper.model.n_actuators,
                                                            self._stepper.limits))
        except CommandRejected as err:
            self._reject(str(err))
        self._lockstep_grant()

    def _lockstep_grant(self) -> None:
        """In lockstep a command message, applied or refused, grants the step its sender waits for."""
        if self._lockstep:
            self.grant_step()

    def _reject(self, reason: str) -> None:
        self.rejected += 1
        self.last_rejection = reason
        self.get_logger().warning(f'command rejected: {reason}')

    # -- services -----------------------------------------------------------------------------------

    def _on_reset(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        # The model is built without the lock (new contact tables take ~1 s; the loop keeps ticking
        # meanwhile) and swapped in under it.
        parameters = self._parameter_msgs(self._model_specs)
        try:
            model = build_model(values(self, self._model_specs))
        except (ParameterError, ValueError) as err:
            response.success, response.message = False, f'model parameters refused, not reset: {err}'
            return response
        with self._lock:
            self._stepper.reset(model)
            self._model_parameters = parameters
            self._model_pending = False
            self.error = ''
            self._mode = ''
            self._configure_outputs()
            self._window = (time.perf_counter(), 0.0)
            self._publish_parameters()
            self._publish_state([])
        response.success, response.message = True, 't = 0, model parameters applied'
        return response

    @locked
    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        if not request.data and self.error:
            response.success, response.message = False, f'cannot resume after a failure: {self.error}'
            return response
        if not request.data and self._lockstep:
            response.success = False
            response.message = ('lockstep: sim time advances only per simulator/step call or command message, '
                                'never on the wall clock')
            return response
        if not self._lockstep:
            self._set_paused(request.data)
        response.success = True
        response.message = f'{"paused" if self._paused else "running"} at t = {self._stepper.t:.9f} s'
        return response

    def _on_step(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        response.success, response.message = self.grant_step()
        return response

    # -- parameters and diagnostics -----------------------------------------------------------------

    @locked
    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        reason = check_changes(self._specs, values(self, self._model_specs), params)
        if reason is not None:
            return SetParametersResult(successful=False, reason=reason)
        for param in params:
            if param.name == 'real_time_factor':
                self._rtf = param.value
            elif param.name == 'step_period':
                self._step_period = param.value
            elif param.name in self._model_specs:
                self._model_pending = True
        if self._model_pending:
            self.get_logger().info('model parameters changed: applied on simulator/reset')
        return SetParametersResult(successful=True)

    @locked
    def _after_set_parameters(self, params: list[Parameter]) -> None:
        if any(p.name in NODE_SPECS for p in params):
            self._publish_parameters()

    def _parameter_msgs(self, names: Iterable[str]) -> list[ParameterMsg]:
        return [self.get_parameter(name).to_parameter_msg() for name in names]

    def _publish_parameters(self) -> None:
        """The parameters in force on the latched ``simulator/parameters``, stamped with the sim time: the
        model's as last applied (not a change waiting for reset) and the node's current ones."""
        self._pub_parameters.publish(ParameterEvent(
            stamp=messages.to_time(self._stepper.t), node=self.get_fully_qualified_name(),
            new_parameters=self._model_parameters + self._parameter_msgs(NODE_SPECS)))

    @locked
    def diagnostics(self) -> DiagnosticStatus:
        """The simulator's status: achieved real-time factor over the last second, tick timing, counters."""
        now, t = time.perf_counter(), self._stepper.t
        wall0, sim0 = self._window
        self.achieved_rtf = (t - sim0) / (now - wall0) if now > wall0 else 0.0
        self._window = (now, t)
        periods = np.asarray(self._tick_periods) * 1e3
        busy = np.asarray(self._tick_busy) * 1e3
        self._tick_periods.clear()
        self._tick_busy.clear()

        def pct(a: np.ndarray, q: float) -> str:
            return f'{np.percentile(a, q):.3f}' if a.size else 'nan'

        status = DiagnosticStatus(name=f'{self.get_name()}: loop', hardware_id='micro_feeder')
        lagging = not self._paused and self._rtf > 0 and self.achieved_rtf < 0.95 * self._rtf
        status.level = DiagnosticStatus.ERROR if self.error else (
            DiagnosticStatus.WARN if lagging else DiagnosticStatus.OK)
        status.message = self.error or ('lockstep' if self._lockstep else 'paused' if self._paused else (
            'behind real time: the physics cannot keep up' if lagging else 'running'))
        items = {'sim_time_s': f'{t:.9f}', 'mode': self._stepper.state.mode, 'paused': str(self._paused),
                 'real_time_factor_target': f'{self._rtf:g}', 'real_time_factor_achieved': f'{self.achieved_rtf:.4f}',
                 'tick_period_p50_ms': pct(periods, 50), 'tick_period_p99_ms': pct(periods, 99),
                 'tick_compute_p99_ms': pct(busy, 99), 'overruns': str(self.overruns),
                 'lockstep': str(self._lockstep), 'steps_granted': str(self.steps_granted),
                 'rejected_commands': str(self.rejected), 'last_rejection': self.last_rejection,
                 'model_parameters_pending_reset': str(self._model_pending)}
        items.update({k: str(v) for k, v in self._stepper.state.transitions.items()})
        status.values = [KeyValue(key=k, value=v) for k, v in items.items()]
        if lagging:
            self.get_logger().warning(f'behind real time: achieved real-time factor {self.achieved_rtf:.3f}',
                                      throttle_duration_sec=10.0)
        return status

    @locked
    def _publish_diagnostics(self) -> None:
        self._pub_diag.publish(DiagnosticArray(header=Header(stamp=messages.to_time(self._stepper.t)),
                                               status=[self.diagnostics()]))


def main(args: list[str] | None = None) -> int:
    """Console script ``simulator``: ``simulator --ros-args --params-file config/feeder.yaml -p ...``."""
    return spin_node('simulator', Simulator, args)
