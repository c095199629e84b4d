"""The simulator's physics side without ROS: model, state, stroke schedule and the commands applied to it.

:class:`Stepper` owns a :class:`FeederModel`, its :class:`FeederState` and the :class:`StrokeSchedule` that
commands edit. The simulator node calls :meth:`Stepper.advance` every tick and applies commands as they
arrive; an offline script can drive the very same object to predict what the node publishes.
Everything is a pure function of the parameters and of the (time, command) sequence, which makes a
stepped run repeatable bit for bit.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..physics.contact import ContactModel, ContactParams
from ..physics.dynamics import EventList, FeederModel, Observation
from ..physics.particle import ParticleParams
from ..physics.trajectory import CommandLimits, check_table
from ..physics.waveforms import StrokeSchedule, trajectory_table
from .commands import CommandRejected, TrajectoryCommand, start_time


@functools.lru_cache(maxsize=4)
def _contact_model(contact: ContactParams, particle: ParticleParams) -> ContactModel:
    """Contact tables are the slow part of a model (~1 s): share them between models in one process."""
    return ContactModel(contact, particle)


def build_model(flat: Mapping[str, Any]) -> FeederModel:
    """A model from flat ``{dotted name: value}`` settings, reusing contact tables already built.

    Raises :class:`~micro_feeder.physics.parameters.ParameterError` for a refused parameter.
    """
    contact = _contact_model(ContactParams.from_flat(flat), ParticleParams.from_flat(flat))
    return FeederModel.from_settings(flat, contact_model=contact)


class Stepper:
    """Model + state + stroke schedule, driven to successive sim times.

    Starts (and :meth:`reset` restarts) at t = 0 with the part stuck at ``particle.x0`` and every stroke
    held at 0: the strokes only move when a command arrives.
    """

    def __init__(self, model: FeederModel):
        self.model = model
        self.reset()
        self._warm_up()

    def _warm_up(self) -> None:
        """Run every compiled function a tick or a command uses once, on copies, so that a first-call load
        or compile (seconds with a cold numba cache, 10-40 ms warm) happens here and not under the simulator's
        lock inside the first tick or the first command: the kernel, and a quintic trajectory command
        (Hermite coefficients, its check against the piezo limits, its evaluation)."""
        state = self.state.copy()
        self.model.advance(state, 1e-6, self.schedule)
        self.model.observe(state, self.schedule)
        n = self.model.n_actuators
        schedule = StrokeSchedule.of_pieces(self.schedule.pieces)
        knots = np.zeros((3, n))
        table = schedule.command_trajectory(1e-6, [2e-6, 3e-6, 4e-6], knots, knots, knots)
        check_table(table, CommandLimits(*self.limits))
        self.model.advance(state, 5e-6, schedule)

    def reset(self, model: FeederModel | None = None) -> None:
        """Back to t = 0 (with ``model`` instead of the current one when given)."""
        if model is not None:
            self.model = model
        self.state = self.model.initial_state()
        self.schedule = StrokeSchedule(trajectory_table([0.0], np.zeros((1, self.model.n_actuators))))

    @property
    def t(self) -> float:
        """Sim time (s)."""
        return self.state.t

    @property
    def limits(self) -> tuple[float, float]:
        """Stroke travel (m) accepted in commands: the piezo limits."""
        return self.model.piezo.stroke_min, self.model.piezo.stroke_max

    def advance(self, t_target: float) -> EventList:
        """Integrate to ``t_target`` (s); returns the mode changes. Raises ``SimulationError``."""
        return self.model.advance(self.state, t_target, self.schedule)

    def observe(self) -> Observation:
        return self.model.observe(self.state, self.schedule)

    def command_trajectory(self, cmd: TrajectoryCommand) -> float:
        """Apply a checked trajectory: it replaces the schedule from its start time on (the stamp, or now
        when the stamp is 0 or past); knots are at stamp + time_from_start (receipt time + time_from_start
        for stamp 0); an empty one holds the stroke from then on. Returns the start time (s).

        Raises :class:`CommandRejected` (the schedule unchanged) when the interpolated stroke, joined to
        the stroke in force at the start, leaves the piezo limits anywhere between knots."""
        t0 = start_time(cmd.stamp, self.state.t)
        if cmd.is_stop:
            self.schedule.hold_from(t0)
        else:
            base = t0 if cmd.stamp == 0.0 else cmd.stamp
            before = self.schedule.pieces
            table = self.schedule.command_trajectory(t0, base + cmd.offsets, cmd.positions, cmd.velocities,
                                                     cmd.accelerations)
            reason = check_table(table, CommandLimits(*self.limits))
            if reason is not None:
                self.schedule = StrokeSchedule.of_pieces(before)
                raise CommandRejected(f'trajectory: {reason}')
        self._prune()
        return t0

    def command_setpoints(self, values: np.ndarray) -> None:
        """Hold the strokes at ``values`` (m) from now on (the piezo model, when on, smooths the step)."""
        t = self.state.t
        self.schedule.replace_from(t, trajectory_table([t], np.asarray(values, dtype=float)[None, :]))
        self._prune()

    def _prune(self) -> None:
        """Drop the schedule pieces that ended at or before now (they no longer affect anything)."""
        self.schedule.drop_ended(self.state.t)
