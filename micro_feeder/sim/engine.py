"""The ``simulator`` node's engine without ROS: a :class:`~.session.Session` advanced in real time or step by
step, its commands taken in between two ticks.

The wall-clock loop thread (:class:`~micro_feeder.realtime.loop.TickLoop`) ticks every ``period`` and advances
sim time by the elapsed wall time × ``rtf`` (0: as fast as possible, ``step_period`` per step), never more
than two periods' worth per tick, then publishes the state. A step grant advances one ``step_period`` while
paused; in ``lockstep`` there is no loop thread and the wall clock never advances sim time: each grant and
each command message (the command applied first) advances it. :meth:`Engine.stop_at` ends a run at an exact
sim time. The command intake (:class:`~micro_feeder.realtime.intake.CommandIntake`) parses commands on a
worker thread and applies them in arrival order between two ticks.

One lock serialises everything that touches the session or publishes state, so a command, a step or a reset
happens between two ticks, never inside one; a control call that cannot have it (or the intake's) within
:data:`BUSY_TIMEOUT` raises :class:`Busy`. The slow parts stay outside it: parsing, building a reset's model,
and a batch's receipts (a tick waits for them). What goes out goes through :class:`Outputs`; ``log`` is any
logger with ``info``/``warning``/``error`` (the node passes its rclpy logger).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np

from ..interface import stamps
from ..interface.entity_changes import EntityChange
from ..physics.dynamics import Event, FeederModel, Observation, SimulationError
from ..physics.parameters import ParameterError
from ..realtime.diagnostics import LoopSnapshot, achieved_rtf
from ..realtime.handoff import Handoff
from ..realtime.intake import CommandIntake, Received
from ..realtime.loop import TickLoop
from .commands import TrajectoryCommand
from .session import Session
from .stepper import Stepper

BUSY_TIMEOUT = 0.5     # s a control call waits for a tick in progress before answering "busy"


class Busy(Exception):
    """The simulator's lock could not be taken in time: a tick (or a large command) is still working."""


class Outputs(Protocol):
    """Where the engine's state, receipts and records go (the node's publishers); called with the lock held,
    except a batch's receipts (:meth:`acknowledge`, :meth:`answer`) and a goal's receipt, published after it."""

    def configure(self, stepper: Stepper) -> None: ...

    def publish_state(self, observations: list[Observation], events: Sequence[Sequence[Event]]) -> None: ...

    def copy_received(self, topic: str, message: Any) -> None: ...

    def acknowledge(self, received: Received, t: float) -> None: ...

    def answer(self, received: Received, t: float, refusal: str) -> None: ...

    def parts_changed(self, n_parts: int, change: EntityChange) -> None: ...


class Log(Protocol):
    """What the engine logs with: an rclpy node's logger, or Python's."""

    def info(self, message: str) -> Any: ...

    def error(self, message: str) -> Any: ...


class Engine:
    """``session`` run under ``lock`` (the node's parameter callbacks take it too), publishing on ``outputs``.

    ``rtf`` (sim s per wall s) and ``step_period`` (s) may change at any time (under the lock); ``period``
    (s) is the loop's. ``start_paused``: the loop waits for :meth:`resume`. ``max_command_bytes``: a larger
    command is refused unparsed. ``publish_thread``: the loop's ticks publish on a thread of their own.
    ``on_failure()``: called after a failure is logged (the node reports it).
    """

    def __init__(self, session: Session, outputs: Outputs, log: Log, *, lock: threading.RLock, lockstep: bool,
                 rtf: float, step_period: float, period: float, start_paused: bool, max_command_bytes: int,
                 on_failure: Callable[[], None], publish_thread: bool = True):
        self.session = session
        self._lock = lock
        self.lockstep = lockstep
        self.rtf = rtf
        self.step_period = step_period
        self.paused = True          # the wall clock does not advance sim time (paused, failed, ended, lockstep)
        self.error = ''
        self.steps_granted = 0
        self.states_published = 0
        self.achieved_rtf = 0.0
        self._outputs = outputs
        self._log = log
        self._on_failure = on_failure
        self._period = period
        self._user_paused = start_paused
        self._t_end = math.inf              # stop_at(): sim time never advances past this
        self._on_end: Callable[[float], None] | None = None
        self._last_command_wall: float | None = None   # time.monotonic() of the last command received
        self._window = (time.perf_counter(), session.stepper.t, 0)     # achieved rates count from here
        self._intake = CommandIntake(self._process_commands, lambda: self.paused,
                                     max_message_bytes=max_command_bytes, max_queued_bytes=4 * max_command_bytes,
                                     batch_interval=0.5 * period)
        self._loop = None if lockstep else TickLoop(period, self._tick, self._loop_failed)
        # the loop's ticks publish on a thread of their own (overlapping the next tick's integration): 16 parts
        # hold real time alone in a process (0.96-0.98 -> 0.99), but in a process shared with a recorder the
        # extra thread's share of the GIL costs more than it overlaps (0.93 -> 0.87-0.89, one part)
        self._handoff = Handoff(self._publish_failed) if publish_thread and not lockstep else None

    @property
    def stepper(self) -> Stepper:
        return self.session.stepper

    @property
    def overruns(self) -> int:
        """Ticks whose work took longer than the loop period, since start."""
        return self._loop.timing.overruns if self._loop is not None else 0

    def start(self, *, hold: bool) -> None:
        """Publish the state at t = 0, then run the loop unless ``start_paused``, ``hold`` or lockstep."""
        self._publish_state([])
        if self._loop is not None:
            self._set_paused(self._user_paused or hold)

    def stop(self, timeout: float) -> None:
        """Stop the loop and intake threads, waiting up to ``timeout`` (s) each for work in progress (a tick
        stuck in the physics is left to die with the process)."""
        if self._loop is not None:
            self._loop.stop(timeout=timeout)
        if self._handoff is not None:
            self._handoff.stop(timeout=timeout)
        self._intake.stop(timeout=timeout)

    def _locked(self, lock: Any) -> Any:
        """``lock`` acquired within :data:`BUSY_TIMEOUT`, as a context manager; raises :class:`Busy`."""
        if not lock.acquire(timeout=BUSY_TIMEOUT):
            age = self._loop.timing.tick_age(time.perf_counter()) if self._loop is not None else 0.0
            raise Busy(f'busy: one tick has been working for {age:.1f} s (the physics cannot advance in '
                       'bounded time with these parameters); try again or stop the node')
        return _Release(lock)

    # -- when sim time advances ---------------------------------------------------------------------

    def grant_step(self) -> tuple[bool, str]:
        """Advance one ``step_period`` and publish, after the commands received so far. Only while paused
        (always, in lockstep), not after a simulation failure and not past :meth:`stop_at`'s end. Returns
        (success, message)."""
        self._intake.drain()
        with self._lock:
            return self._grant_step()

    def step(self) -> tuple[bool, str]:
        """:meth:`grant_step`, or (False, ``busy: ...``) when a tick holds the lock for longer than
        :data:`BUSY_TIMEOUT`."""
        try:
            with self._locked(self._intake.busy), self._locked(self._lock):
                return self.grant_step()
        except Busy as err:
            return False, str(err)

    def stop_at(self, t_end: float, on_end: Callable[[float], None]) -> None:
        """Never advance sim time past ``t_end`` (s): the loop (or a lockstep grant) stops exactly there and
        pauses, and ``on_end(t)`` is called when sim time reaches it (at once if it already has)."""
        with self._lock:
            self._t_end = t_end
            self._on_end = on_end
            self._check_end()

    def pause(self) -> None:
        """Stop the loop advancing sim time (after the tick in progress, if any): the state is final until
        something resumes it. Lockstep is always paused."""
        with self._lock:
            self._user_paused = True
            self._set_paused(True)

    def resume(self) -> None:
        """Let the loop advance sim time; no effect in lockstep, after a failure or at :meth:`stop_at`'s end."""
        with self._lock:
            self._user_paused = False
            self._set_paused(False)

    def set_paused(self, paused: bool) -> tuple[bool, str]:
        """Pause, or run (refused after a failure and in lockstep). (success, message)."""
        try:
            with self._locked(self._lock):
                if not paused and self.error:
                    return False, f'cannot resume after a failure: {self.error}'
                if not paused and self.lockstep:
                    return False, ('lockstep: sim time advances only per ~/step call or command message, '
                                   'never on the wall clock')
                self._user_paused = paused
                self._set_paused(paused)
                return True, f'{"paused" if self.paused else "running"} at t = {self.stepper.t:.9f} s'
        except Busy as err:
            return False, str(err)

    def fail(self, error: str) -> None:
        """Stop on an error: pause, log it, report it (``on_failure``; cleared by :meth:`reset`)."""
        with self._lock:
            self.error = error
            self._set_paused(True)
        self._log.error(f'simulation stopped (paused; call ~/reset): {error}')
        self._on_failure()

    def _set_paused(self, paused: bool) -> None:
        """Pause or run the loop; it stays paused after a failure, at the end and in lockstep."""
        was_paused = self.paused
        self.paused = paused or bool(self.error) or self.lockstep or self.stepper.t >= self._t_end
        if self.paused and not was_paused:
            self._flush_published()             # paused: the last state is out when this returns
        if was_paused and not self.paused:     # the achieved real-time factor counts from here
            self._window = (time.perf_counter(), self.stepper.t, self.states_published)
        if self._loop is not None:
            if self.paused:
                self._loop.pause()
            else:
                self._loop.resume()

    def _tick(self, elapsed: float) -> None:
        """One loop tick: advance by the elapsed wall time × rtf (at most two periods' worth) or, as fast as
        possible, steps of ``step_period`` for 80 % of the period."""
        with self._lock:
            if self.paused:
                return
            if self.rtf > 0.0:
                self._step(self.stepper.t + min(elapsed, 2.0 * self._period) * self.rtf, handed_off=True)
            else:
                deadline = time.perf_counter() + 0.8 * self._period
                while not self.paused and time.perf_counter() < deadline:
                    self._step(self.stepper.t + self.step_period, handed_off=True)

    def _loop_failed(self, err: BaseException) -> None:
        self.fail(f'loop thread stopped: {type(err).__name__}: {err}')

    def _publish_failed(self, err: BaseException) -> None:
        """On the publishing thread: fail on another one (the lock's holder may be waiting for this thread to
        finish what was handed over)."""
        threading.Thread(target=self.fail, args=(f'publishing the state failed: {type(err).__name__}: {err}',),
                         name='simulator-publish-failed', daemon=True).start()

    def _grant_step(self) -> tuple[bool, str]:
        if not self.paused or self.error:
            return False, self.error or 'step needs the simulation paused (call ~/pause true)'
        if self.stepper.t >= self._t_end:
            return False, f'stopped at t = {self.stepper.t:.9f} s (end of the run)'
        self.steps_granted += 1
        self._step(self.stepper.t + self.step_period)
        return not self.error, self.error or f't = {self.stepper.t:.9f} s'

    def _step(self, t_target: float, handed_off: bool = False) -> None:
        """Advance to ``t_target`` (never past :meth:`stop_at`'s end) and publish (``handed_off``: on the publishing
        thread); on a simulation failure pause and report it."""
        try:
            events = self.stepper.advance_parts(min(t_target, self._t_end))
        except SimulationError as err:
            self.fail(str(err))
            return
        self._publish_state(events, handed_off)
        self._check_end()

    def _check_end(self) -> None:
        """At :meth:`stop_at`'s end: pause and say so."""
        if self.stepper.t >= self._t_end and self._on_end is not None:
            self._set_paused(True)
            self._on_end(self.stepper.t)

    def _publish_state(self, events: Sequence[Sequence[Event]], handed_off: bool = False) -> None:
        """Publish the state now, with ``events`` (each part's mode changes since the last time); ``handed_off``:
        on the publishing thread, after the states handed to it before (the state is observed here)."""
        self.states_published += 1
        observed = self.stepper.observe_parts()
        if handed_off and self._handoff is not None:
            self._handoff.put(self._outputs.publish_state, observed, events)
            return
        self._flush_published()
        self._outputs.publish_state(observed, events)

    def _flush_published(self) -> None:
        """Wait until the states handed to the publishing thread are out (before publishing on this thread, or
        changing what publishing uses)."""
        if self._handoff is not None:
            self._handoff.flush()

    # -- commands -----------------------------------------------------------------------------------

    def submit(self, topic: str, data: bytes) -> None:
        """A serialized command message received on ``topic`` (executor thread): counted, copied on its
        ``simulator/..._received`` topic and queued; the intake does the rest."""
        self.session.commands.received += 1
        stamp = stamps.header_stamp(data) if topic == 'actuator/trajectory' else 0.0
        command_id = stamps.header_frame_id(data) if topic == 'actuator/trajectory' else ''
        self._last_command_wall = time.monotonic()
        self._outputs.copy_received(topic, data)    # the copy a recorder holds whichever senders it discovered
        self._intake.submit(Received(topic, data, stamp, command_id=command_id))

    def _process_commands(self, batch: list[Received]) -> None:
        """Plan ``batch`` (parsing outside the lock), then acknowledge and apply it in arrival order
        between two ticks; in lockstep each command grants its step (a duplicate of one applied does not: a
        command applies once). A refusal is answered."""
        session, outputs = self.session, self._outputs
        generation = session.generation
        outcomes = session.plan(batch)
        receipts: list[tuple[Received, float, str]] = []    # published after the lock: a tick waits for it
        with self._lock:
            if generation != session.generation:    # a reset changed the model while parsing
                outcomes = session.plan(batch)
            for outcome in outcomes:
                t = self.stepper.t
                if self.lockstep:
                    repeated = session.commands.repeated
                    outputs.acknowledge(outcome.received, t)
                    outputs.answer(outcome.received, t, session.apply(outcome))
                    if session.commands.repeated == repeated:   # a copy of a command applied grants nothing
                        self._grant_step()
                else:
                    receipts.append((outcome.received, t, session.apply(outcome)))
        for received, t, refusal in receipts:
            outputs.acknowledge(received, t)
            outputs.answer(received, t, refusal)
        session.commands.dropped = self._intake.dropped

    def follow(self, message: Any) -> tuple[int, float, TrajectoryCommand]:
        """Check and apply a FollowJointTrajectory goal's ``trajectory_msgs/JointTrajectory`` as the same
        message received on ``actuator/trajectory`` now would be, after the commands received before it; like
        a topic command it is copied (``simulator/trajectories_received``) and acknowledged
        (``simulator/command_receipts``, named by its ``header.frame_id``), applied or refused. Returns (its
        ``command_serial``, its start in sim time (s), the command). Raises ValueError with the reason
        (:class:`~.commands.CommandRejected` from the schedule: the interpolation leaves the travel, a
        duplicate, a late join that would jump) or :class:`Busy` (then nothing was received)."""
        session = self.session
        generation = session.generation
        parsed = session.parse_goal(message)                # outside the lock: a long goal takes a while
        received = Received('actuator/trajectory', b'', stamps.seconds(message.header.stamp),
                            command_id=message.header.frame_id)
        with self._locked(self._intake.busy), self._locked(self._lock):
            self._intake.drain()
            if generation != session.generation:            # a reset changed the model while parsing
                parsed = session.parse_goal(message)
            session.commands.received += 1
            self._outputs.copy_received('actuator/trajectory', message)
            t = self.stepper.t
            refusal: ValueError | None = None
            try:
                serial, start = session.follow(parsed)
            except ValueError as err:
                refusal = err
        self._outputs.acknowledge(received, t)
        if refusal is not None:
            raise refusal
        return serial, start, parsed

    # -- resets, entities, observations -------------------------------------------------------------

    def reset(self, build: Callable[[], FeederModel], installed: Callable[[], None], *,
              pause: bool = False) -> tuple[bool, str]:
        """t = 0 with the model ``build()`` returns, commands dropped; runs again unless paused (or ``pause``).
        ``installed()``: the new model is in force (called under the lock, just before the state at t = 0 is
        published: the node publishes the parameters applied). Returns (success, message); refused, with
        nothing changed, when ``build`` or the first state fails or within :data:`BUSY_TIMEOUT` the locks
        cannot be had."""
        # The model is built and checked without the lock (new contact tables take ~1 s; the loop keeps
        # ticking meanwhile) and swapped in under it.
        try:
            stepper = self.session.prepare(build())
        except (ParameterError, ValueError, SimulationError) as err:
            return False, f'model parameters refused, not reset: {err}'
        try:
            with self._locked(self._intake.busy), self._locked(self._lock):
                self._intake.drain()
                self.session.install(stepper)
                self.error = ''
                self._flush_published()
                self._outputs.configure(stepper)
                self._window = (time.perf_counter(), 0.0, self.states_published)
                installed()
                self._publish_state([])
                self._user_paused = self._user_paused or pause
                self._set_paused(self._user_paused)
        except Busy as err:
            return False, str(err)
        return True, f't = 0, model parameters applied, {"paused" if self.paused else "running"}'

    def spawn_part(self, name: str, x: float) -> tuple[bool, str]:
        """A part named ``name`` placed at ``x`` (m) now, at rest (:meth:`Session.spawn_part`), the change
        published and logged. (success, message: the reason of a refusal); raises :class:`Busy`."""
        return self._change_parts(lambda: self.session.spawn_part(name, x))

    def delete_part(self, name: str) -> tuple[bool, str]:
        """The part named ``name`` removed now (:meth:`Session.delete_part`), as :meth:`spawn_part`."""
        return self._change_parts(lambda: self.session.delete_part(name))

    def _change_parts(self, change: Callable[[], EntityChange]) -> tuple[bool, str]:
        with self._locked(self._lock):
            stepper = self.stepper
            try:
                record = change()
            except ValueError as err:
                return False, str(err)
            self._flush_published()
            self._outputs.parts_changed(stepper.n_parts, record)
        message = (f'{record.entity} {record.kind} at x = {record.x * 1e3:.6g} mm, t = {record.t:.9f} s: '
                   f'{stepper.n_parts} parts')
        self._log.info(message)
        return True, message

    def observe(self) -> Observation:
        """Part 0's state now, as published (taken under the lock, between two ticks); raises :class:`Busy`."""
        with self._locked(self._lock):
            return self.stepper.observe()

    def observe_parts(self) -> list[Observation]:
        """Every part's state now, in part order (as :meth:`observe`)."""
        with self._locked(self._lock):
            return list(self.stepper.observe_parts())

    def entity_names(self) -> list[str]:
        """Every part's entity name now, in part order."""
        with self._locked(self._lock):
            return list(self.stepper.entity_names)

    def observe_entities(self) -> tuple[list[str], list[Observation]]:
        """Every part's entity name and state now, in part order."""
        with self._locked(self._lock):
            return list(self.stepper.entity_names), list(self.stepper.observe_parts())

    def strokes(self, t: float | None = None) -> tuple[np.ndarray, Observation]:
        """((3, joints) commanded s, ṡ, s̈ at ``t`` (s; default now), the state now), under the lock; raises
        :class:`Busy`."""
        with self._locked(self._lock):
            return self.session.strokes(t)

    def snapshot(self, *, pending_reset: bool, other_simulators: int) -> LoopSnapshot:
        """What ``/diagnostics`` reports (:func:`~micro_feeder.realtime.diagnostics.loop_status`): the achieved
        real-time factor and publish rate over the time since the last call, tick timing, counters. Takes no
        lock, so it reports even while a tick is stuck."""
        now, t, published = time.perf_counter(), self.stepper.t, self.states_published
        wall0, sim0, published0 = self._window
        self.achieved_rtf = achieved_rtf((wall0, now), (sim0, t))
        publish_rate = achieved_rtf((wall0, now), (published0, published))
        self._window = (now, t, published)
        loop = self._loop
        periods, busy = loop.timing.drain() if loop is not None else (np.zeros(0), np.zeros(0))
        state = self.stepper.state
        return LoopSnapshot(
            sim_time=t, mode=state.mode, paused=self.paused, lockstep=self.lockstep, error=self.error,
            rtf_target=self.rtf, achieved_rtf=self.achieved_rtf,
            publish_rate=publish_rate, periods_ms=periods, busy_ms=busy,
            overruns=self.overruns, tick_age=loop.timing.tick_age(now) if loop is not None else 0.0,
            steps_granted=self.steps_granted, states_published=self.states_published,
            pending_reset=pending_reset, transitions=state.transitions,
            intake=self.session.commands.as_items(),
            other_simulators=other_simulators,
            command_age=(time.monotonic() - self._last_command_wall if self._last_command_wall is not None
                         else math.nan),
            stream_silent=self.session.stream_silent(t))


class _Release:
    """Context manager releasing a lock that was acquired already."""

    def __init__(self, lock: Any):
        self._lock = lock

    def __enter__(self) -> None:
        return None

    def __exit__(self, *_exc: object) -> None:
        self._lock.release()
