"""The simulator's session without ROS: the :class:`~.stepper.Stepper` in force and what happens to each
command received for it.

:class:`Session` is the command-application policy of the ``simulator`` node (docs/interface.md,
*Commands*): a received message is parsed for the current model (:mod:`.commands`), a batch is planned by
:func:`micro_feeder.realtime.intake.plan` (superseded commands coalesced; in lockstep nothing is, every
message being a step grant) and each command applied, coalesced, dropped or refused, counted in
:class:`~micro_feeder.realtime.intake.IntakeCounters`. It also builds and checks the Stepper a reset
installs, records the parts spawned and deleted as :class:`~micro_feeder.interface.entity_changes.EntityChange`
and tells how long a stream has been silent.

Nothing here locks and nothing publishes: the engine (:mod:`.engine`) holds its lock around every call but
:meth:`~Session.parse`, :meth:`~Session.plan`, :meth:`~Session.parse_goal` and :meth:`~Session.prepare` (the
slow ones, done without it while the loop ticks) and :meth:`~Session.stream_silent` (for ``/diagnostics``,
which takes no lock), and publishes what these return. Refusals and late commands
are reported as throttled lines (:class:`~micro_feeder.realtime.intake.ThrottledLog`) passed to ``warn`` (the
node's logger).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ..interface.cdr import read_float64_array
from ..interface.entity_changes import DELETED, SPAWNED, EntityChange
from ..interface.names import joint_names
from ..physics.dynamics import FeederModel, Observation, SimulationError
from ..realtime.intake import IntakeCounters, Outcome, Received, ThrottledLog, plan
from .commands import (
    DuplicateCommand,
    TrajectoryCommand,
    parse_setpoints,
    parse_trajectory,
    parse_trajectory_cdr,
    start_time,
)
from .stepper import Stepper


class Session:
    """The Stepper in force (``stepper``) and the commands applied to it.

    ``lockstep``: every command message is a step grant, so none is coalesced. ``warn``: where the throttled
    lines about refused, dropped and late commands go. ``decode_setpoints``: the values of a serialized
    ``std_msgs/Float64MultiArray`` whose layout :func:`~micro_feeder.interface.cdr.read_float64_array` does
    not read (the node passes rclpy's deserialization; any exception it raises refuses the command).
    """

    def __init__(self, stepper: Stepper, *, lockstep: bool, warn: Callable[[str], None],
                 decode_setpoints: Callable[[bytes], Sequence[float]]):
        self.stepper = stepper
        self.lockstep = lockstep
        self.commands = IntakeCounters()
        self.command_serial = 0     # +1 for every command applied and every reset: what replaced a goal's strokes
        self.stream_open = False    # the last trajectory applied was a stream's window (stamped, not empty)
        self.generation = 0         # model generation: commands parsed for an older model re-parse
        self._warn = warn
        self._decode_setpoints = decode_setpoints
        self._refusal_log = ThrottledLog()
        self._late_log = ThrottledLog(label='late')

    # -- commands received on the topics ------------------------------------------------------------

    def parse(self, received: Received) -> tuple[str, Any]:
        """A checked command for the current model, or ValueError with the reason (no lock needed)."""
        stepper = self.stepper
        joints = joint_names(stepper.model.n_actuators)
        if received.topic == 'actuator/trajectory':     # read from its bytes (rclpy's for odd layouts)
            return received.topic, parse_trajectory_cdr(received.data, joints, stepper.limits)
        values = read_float64_array(received.data)
        if values is None:
            try:
                values = self._decode_setpoints(received.data)
            except Exception as err:  # rclpy raises several types for malformed bytes
                raise ValueError(f'{received.topic}: cannot deserialize: {err}') from err
        return received.topic, parse_setpoints(values, stepper.model.n_actuators, stepper.limits)

    def plan(self, batch: list[Received]) -> list[Outcome]:
        """What becomes of each message of ``batch`` at the sim time now (parsed without the lock)."""
        # in lockstep every command message is a grant: nothing is coalesced
        return plan(batch, self.stepper.t, start_time, self.parse, coalesce=not self.lockstep)

    def apply(self, outcome: Outcome) -> str:
        """Apply (or coalesce, drop, refuse) one command; returns why it was not applied ('' otherwise)."""
        if outcome.coalesced:
            self.commands.coalesced += 1
            return ''
        if outcome.dropped:
            reason = f'{outcome.received.topic}: dropped unparsed, the command queue was full'
            self._log(self._refusal_log.note(reason))
            return reason
        if outcome.refused:
            self.refuse(outcome.refused)
            return outcome.refused
        topic, command = outcome.command
        try:
            if topic == 'actuator/trajectory':
                self._log(self.note_late(command.stamp))
                self.stepper.command_trajectory(command)
                self.stream_open = command.stamp > 0.0 and not command.is_stop
            else:
                self.stepper.command_setpoints(command)
                self.stream_open = False
        except DuplicateCommand as err:
            self.commands.repeated += 1
            return str(err)
        except ValueError as err:
            self.refuse(str(err))
            return str(err)
        self.command_serial += 1
        return ''

    def note_late(self, stamp: float) -> str | None:
        """A trajectory stamped before now starts now (joint_trajectory_controller semantics): what it
        scheduled before is lost, and a stream joined mid-stroke can throw the part. Counted; returns the
        line to log (throttled like refusals), if one is due."""
        t = self.stepper.t
        # stamps are whole nanoseconds and sim time a sum of step periods: a stamp equal to the sim time
        # rounded to the nanosecond is on time (lockstep used to warn "late by 0.000 ms")
        if stamp > 0.0 and round(t * 1e9) > round(stamp * 1e9):
            self.commands.late += 1
            return self._late_log.note(
                f'actuator/trajectory arrived {(t - stamp) * 1e3:.3f} ms after its stamp: its knots before sim '
                f'time {t:.6f} s were dropped (the sender should schedule further ahead, e.g. the '
                "actuator's stream.lead)")
        return None

    def refuse(self, reason: str) -> None:
        """Count a refused command and log the reason (throttled)."""
        self.commands.refused += 1
        self.commands.last_refusal = reason
        self._log(self._refusal_log.note(reason))

    def flush_logs(self) -> None:
        """Log the summary lines due of refused and late commands (call it periodically)."""
        self._log(self._refusal_log.flush())
        self._log(self._late_log.flush())

    def _log(self, line: str | None) -> None:
        if line is not None:
            self._warn(line)

    def stream_silent(self, t: float) -> float:
        """Sim seconds since the strokes of a stream (the last trajectory applied was a window stamped ahead)
        ran out with nothing after them: its sender stalled, died or lost the simulator. 0 otherwise."""
        if not self.stream_open:
            return 0.0
        start, table = self.stepper.schedule.pieces[-1]
        return max(t - max(start, table.end_time()), 0.0)

    # -- FollowJointTrajectory goals ------------------------------------------------------------------

    def parse_goal(self, message: Any) -> TrajectoryCommand | ValueError:
        """A goal's ``trajectory_msgs/JointTrajectory`` checked for the current model, or the ValueError
        refusing it (no lock needed)."""
        try:
            return parse_trajectory(message, joint_names(self.stepper.model.n_actuators), self.stepper.limits)
        except ValueError as err:
            return err

    def follow(self, parsed: TrajectoryCommand | ValueError) -> tuple[int, float]:
        """Apply a goal's :meth:`parse_goal` now: returns (its :attr:`command_serial`, its start in sim time
        (s)). Raises the ValueError refusing it (counted and logged as a topic command's refusal)."""
        if isinstance(parsed, ValueError):
            self.refuse(str(parsed))
            raise parsed
        try:
            start = self.stepper.command_trajectory(parsed)
        except DuplicateCommand:
            self.commands.repeated += 1
            raise
        except ValueError as err:    # CommandRejected from the schedule: a late join that would jump, ...
            self.refuse(str(err))
            raise
        self.stream_open = False
        self.command_serial += 1
        return self.command_serial, start

    def strokes(self, t: float | None = None) -> tuple[np.ndarray, Observation]:
        """((3, joints) commanded s, ṡ, s̈ at ``t`` (s; default now), the state now)."""
        obs = self.stepper.observe()
        return self.stepper.schedule.evaluate(obs.t if t is None else t), obs

    # -- resets and entities ------------------------------------------------------------------------

    def prepare(self, model: FeederModel) -> Stepper:
        """The Stepper a reset to ``model`` installs (:meth:`install`), built without the lock (new contact
        tables take ~1 s): at t = 0, its first state checked (:func:`check_finite`), the command applied
        before the reset still applied. Raises what :class:`Stepper` and :func:`check_finite` raise."""
        stepper = Stepper(model)
        check_finite(stepper)
        stepper.applied = self.stepper.applied      # a command applied before the reset stays applied
        return stepper

    def install(self, stepper: Stepper) -> None:
        """Run ``stepper`` from now on (a reset): commands parsed for the previous model parse again, and
        what the previous one followed (goals, streams) is over."""
        self.stepper = stepper
        self.command_serial += 1
        self.stream_open = False
        self.generation += 1

    def spawn_part(self, name: str, x: float) -> EntityChange:
        """A part named ``name`` placed at ``x`` (m) now (:meth:`Stepper.spawn_part`): the record of it.
        Raises ValueError (nothing changed) with the reason of a refusal."""
        return self._change_parts(SPAWNED, name, lambda: self.stepper.spawn_part(name, x))

    def delete_part(self, name: str) -> EntityChange:
        """The part named ``name`` removed now (:meth:`Stepper.delete_part`), as :meth:`spawn_part`."""
        return self._change_parts(DELETED, name, lambda: self.stepper.delete_part(name))

    def _change_parts(self, kind: str, name: str, change: Callable[[], int]) -> EntityChange:
        stepper = self.stepper
        before = dict(zip(stepper.entity_names, stepper.parts_state.positions.tolist(), strict=True))
        index = change()
        x = before[name] if kind == DELETED else stepper.parts_state.parts[index].x
        return EntityChange(kind, name, index, stepper.t, x)


def check_finite(stepper: Stepper) -> None:
    """Raise :class:`SimulationError` when the state a stepper would publish first is not finite."""
    obs = stepper.observe()
    published = (obs.x, obs.z, obs.xdot, obs.zdot, obs.theta, obs.normal_load, obs.friction)
    if not all(math.isfinite(v) for v in published):
        raise SimulationError(f'the state at t = 0 is not finite (x, z, ẋ, ż, θ, N, T = {published})')
