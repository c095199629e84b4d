"""The simulator's physics side without ROS: model, state, stroke schedule and the commands applied to it.

:class:`Stepper` owns a :class:`FeederModel`, the parts' states (one :class:`FeederState` each; several parts
meet through :class:`PartsModel`, docs/parts.md) and the :class:`StrokeSchedule` that commands edit. The
simulator node calls :meth:`Stepper.advance_parts` every tick and applies commands as they arrive; an offline
script can drive the very same object to predict what the node publishes. Everything is a pure function of
the parameters and of the (time, command) sequence, which makes a stepped run repeatable bit for bit.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..interface.names import part_entity, split_window_id, window_id
from ..physics.contact import ContactLaw, ContactParams, contact_law
from ..physics.dynamics import EventList, FeederModel, FeederState, Observation, layout
from ..physics.dynamics.model import ObservedParts
from ..physics.particle import ParticleParams
from ..physics.parts import PartsModel, PartsState
from ..physics.trajectory import CommandLimits, check_table
from ..physics.waveforms import StrokeSchedule, trajectory_table
from .applied import AppliedCommands
from .commands import DUPLICATE, CommandRejected, DuplicateCommand, TrajectoryCommand, start_time

JOIN_TOLERANCE = (1e-9, 1e-5)    # m, m/s: a late trajectory joins the stroke in force only this close to it
LEFT_LIMIT_S = 1e-12             # s: "just before" a window's start (knots are whole ns; stamp + offset and the
                                 # next stamp differ by rounding, ~1e-18 s)


def previous_window(command_id: str) -> str | None:
    """The identity of the window that ``command_id`` continues (``<stream>:w<k-1>`` for ``<stream>:w<k>``,
    k ≥ 2), or None when it names no stream window (docs/interface.md, *Commands*)."""
    window = split_window_id(command_id)
    if window is None or window[1] < 2:
        return None
    return window_id(window[0], window[1] - 1)


@functools.lru_cache(maxsize=4)
def _contact_model(contact: ContactParams, particle: ParticleParams) -> ContactLaw:
    """Contact tables are the slow part of a model (~1 s): share them between models in one process."""
    return contact_law(contact, particle)


def build_model(flat: Mapping[str, Any]) -> FeederModel:
    """A model from flat ``{dotted name: value}`` settings, reusing contact tables already built.

    Raises :class:`~micro_feeder.physics.parameters.ParameterError` for a refused parameter.
    """
    contact = _contact_model(ContactParams.from_flat(flat), ParticleParams.from_flat(flat))
    return FeederModel.from_settings(flat, contact_model=contact)


class Stepper:
    """Model + state + stroke schedule, driven to successive sim times.

    Starts (and :meth:`reset` restarts) at t = 0 with every part at its ``particle.x0`` (with its
    ``particle.v0``) and every stroke held at 0: the strokes only move when a command arrives. One part is
    integrated by the model alone; several by :class:`PartsModel`, which adds their impacts.
    """

    def __init__(self, model: FeederModel):
        self.model = model
        self.applied = AppliedCommands()
        self.reset()
        self._warm_up()

    def _warm_up(self) -> None:
        """Run every compiled function a tick, a spawn or a command uses once, on copies, so that a first-call load
        or compile (seconds with a cold numba cache, 10-40 ms warm) happens here and not under the simulator's
        lock inside the first tick or the first command: the kernel, and a quintic trajectory command
        (Hermite coefficients, its check against the piezo limits, its evaluation)."""
        parts = self.parts_state.copy()
        self._advance(parts, 1e-6, self.schedule)
        self.model.advance_copies(parts.parts, 2e-6, self.schedule)    # several parts' call (a spawn may need it)
        self.model.observe(parts.parts[0], self.schedule)
        n = self.model.n_actuators
        schedule = StrokeSchedule.of_pieces(self.schedule.pieces)
        knots = np.zeros((3, n))
        table = schedule.command_trajectory(1e-6, [2e-6, 3e-6, 4e-6], knots, knots, knots)
        check_table(table, CommandLimits(*self.limits))
        self._advance(parts, 5e-6, schedule)

    def reset(self, model: FeederModel | None = None) -> None:
        """Back to t = 0 (with ``model`` instead of the current one when given)."""
        if model is not None:
            self.model = model
        self.parts = PartsModel(self.model) if self.model.particle.n_parts > 1 else None
        self.parts_state = self.parts.initial_state() if self.parts is not None else \
            PartsState([self.model.initial_state()])
        self.schedule = StrokeSchedule(trajectory_table([0.0], np.zeros((1, self.model.n_actuators))))
        self.entity_names = [part_entity(k) for k in range(self.n_parts)]

    @property
    def state(self) -> FeederState:
        """Part 0's state (the one part's, with one): its time is every part's."""
        return self.parts_state.parts[0]

    @property
    def n_parts(self) -> int:
        return len(self.parts_state)

    @property
    def t(self) -> float:
        """Sim time (s)."""
        return self.parts_state.t

    @property
    def limits(self) -> tuple[float, float]:
        """Stroke travel (m) accepted in commands: the piezo limits."""
        return self.model.piezo.stroke_min, self.model.piezo.stroke_max

    def advance(self, t_target: float) -> EventList:
        """Integrate to ``t_target`` (s); returns part 0's mode changes (:meth:`advance_parts`: every part's).
        Raises ``SimulationError``."""
        return self.advance_parts(t_target)[0]

    def advance_parts(self, t_target: float) -> list[EventList]:
        """Integrate every part to ``t_target`` (s), impacts included; returns each part's mode changes."""
        return self._advance(self.parts_state, t_target, self.schedule)

    def _advance(self, parts: PartsState, t_target: float, schedule: StrokeSchedule) -> list[EventList]:
        if self.parts is None:
            return [self.model.advance(parts.parts[0], t_target, schedule)]
        return self.parts.advance(parts, t_target, schedule)

    def spawn_part(self, name: str, x: float) -> int:
        """Place a part named ``name`` at ``x`` (m) now, at rest on the surface (stuck, the stacks' state as the
        other parts have it); it takes its place in order along the feeder. Returns its index.

        Raises :class:`ValueError` (nothing changed) for a name already taken, an ``x`` outside
        ``particle.x0``'s range or within ``particle.size`` of a part's centre (parts never overlap), and on a
        plate with ``surface.thickness`` > 0 (one part only there)."""
        if name in self.entity_names:
            raise ValueError(f'an entity named {name!r} exists already')
        if not -1.0 <= x <= 1.0:
            raise ValueError(f'x = {x!r} m: a part goes within -1 m ... 1 m of the feeder\'s origin')
        if self.model.surface.thickness > 0.0:
            raise ValueError('one part only with surface.thickness > 0 (parts meeting on a moving material are '
                             'not modelled)')
        positions = self.parts_state.positions
        size = self.model.particle.size
        index = int(np.searchsorted(positions, x))
        near = [positions[i] for i in (index - 1, index) if 0 <= i < positions.size
                and abs(positions[i] - x) < size]
        if near:
            raise ValueError(f'x = {x:.6g} m overlaps the part at {near[0]:.6g} m (centres at least particle.size '
                             f'= {size:g} m apart)')
        like = self.state
        part = self.model.initial_state(x, 0.0)
        part.y[4:] = like.y[4:]                     # the piezo stacks' state: the surface's, shared by every part
        part.fs[layout.FS_T] = like.fs[layout.FS_T]
        self.parts_state.insert(index, part)
        self.entity_names.insert(index, name)
        self._parts_changed()
        return index

    def delete_part(self, name: str) -> int:
        """Remove the part named ``name``; returns the index it had. Raises :class:`ValueError` (nothing changed)
        for an unknown name and for the last part (a feeder simulates at least one)."""
        if name not in self.entity_names:
            raise ValueError(f'no entity named {name!r}')
        if self.n_parts == 1:
            raise ValueError(f'{name} is the last part: the simulator keeps at least one')
        index = self.entity_names.index(name)
        self.parts_state.remove(index)
        del self.entity_names[index]
        self._parts_changed()
        return index

    def _parts_changed(self) -> None:
        """After a spawn or a delete: several parts meet through :class:`PartsModel`, one alone is the model's."""
        self.parts = PartsModel(self.model) if self.n_parts > 1 else None
        self.parts_state.chunk_hint = 0.0

    def observe(self) -> Observation:
        """Part 0's outputs now (docs/dynamics.md §4)."""
        return self.model.observe(self.state, self.schedule)

    def observe_parts(self) -> ObservedParts:
        """Every part's outputs now, in part order (an :class:`Observation` per part when indexed)."""
        return self.model.observe_rows(self.parts_state.rows, self.schedule)

    def command_trajectory(self, cmd: TrajectoryCommand) -> float:
        """Apply a checked trajectory: it replaces the schedule from its start time on (the stamp, or now
        when the stamp is 0 or past); knots are at stamp + time_from_start (receipt time + time_from_start
        for stamp 0); an empty one holds the stroke from then on. Returns the start time (s).

        Raises :class:`CommandRejected` (the schedule unchanged) when the interpolated stroke, joined to
        the stroke in force at the start, leaves the piezo limits anywhere between knots; when its identity
        (``command_id``) was applied before (a duplicate: each command applies once, whoever resends it);
        when it is late (stamped before now) and joining it now would jump the stroke
        (:meth:`_check_late_join`); and when it continues a stream window but would jump the stroke at its start
        (:meth:`_check_continuation`)."""
        if cmd.command_id in self.applied:
            t_applied = self.applied.applied_at(cmd.command_id)
            when = 'before' if t_applied is None else f'at t = {t_applied:.9f} s'
            raise DuplicateCommand(f'trajectory {cmd.command_id}: {DUPLICATE} {when}, not applied again')
        t0 = start_time(cmd.stamp, self.t)
        if not cmd.is_stop and 0.0 < cmd.stamp < t0:
            self._check_late_join(cmd, t0)
        elif not cmd.is_stop and cmd.stamp > 0.0:
            self._check_continuation(cmd)
        if cmd.is_stop:
            self.schedule.hold_from(t0)
        else:
            base = t0 if cmd.stamp == 0.0 else cmd.stamp
            before = self.schedule.pieces
            table = self.schedule.command_trajectory(t0, base + cmd.offsets, cmd.positions, cmd.velocities,
                                                     cmd.accelerations, cmd.own_table)
            reason = check_table(table, CommandLimits(*self.limits))
            if reason is not None:
                self.schedule = StrokeSchedule.of_pieces(before)
                raise CommandRejected(f'trajectory: {reason}')
        self._prune()
        if cmd.command_id:
            self.applied.add(cmd.command_id, t0)
        return t0

    def _check_late_join(self, cmd: TrajectoryCommand, t0: float) -> None:
        """A trajectory stamped before ``t0`` (now) starts now, its earlier knots dropped: accepted only when
        the stroke in force now is where the trajectory itself is now (a stream window whose start the previous
        window covered), within :data:`JOIN_TOLERANCE`; otherwise joining it mid-way would jump the surface and
        throw the part, so it is refused (a streaming sender re-phases instead)."""
        times = cmd.stamp + cmd.offsets
        late_ms = (t0 - cmd.stamp) * 1e3
        if times[-1] <= t0:
            raise CommandRejected(f'trajectory late by {late_ms:.3f} ms: it ended before it arrived (at '
                                  f't = {times[-1]:.9f} s), not applied')
        own_table = cmd.own_table if cmd.own_table is not None else \
            trajectory_table(times, cmd.positions, cmd.velocities, cmd.accelerations)
        own = StrokeSchedule(own_table).evaluate(t0)
        now = self.schedule.evaluate(t0)
        jump = np.abs(own[:2] - now[:2])
        if jump[0].max() > JOIN_TOLERANCE[0] or jump[1].max() > JOIN_TOLERANCE[1]:
            k = int(np.argmax(np.maximum(jump[0] / JOIN_TOLERANCE[0], jump[1] / JOIN_TOLERANCE[1])))
            raise CommandRejected(f'trajectory late by {late_ms:.3f} ms: joining it at t = {t0:.9f} s would jump '
                                  f'joint {k} by {jump[0, k] * 1e6:.4g} µm and {jump[1, k] * 1e3:.4g} mm/s, which '
                                  'throws the part; not applied (stamp windows ahead of sim time, or re-phase)')

    def _check_continuation(self, cmd: TrajectoryCommand) -> None:
        """A stream window (identity ``<stream>:w<k>``, k ≥ 2) starts at a knot it shares with window k−1, so
        the stroke in force just before its start is where the window starts. When it is not (window k−1 was
        refused or lost, or another command replaced it), taking the knot as the stroke would jump the surface
        there and throw the part: refused (beyond :data:`JOIN_TOLERANCE`); the sender re-phases with a window
        that has no knot at its start, which the schedule starts from the stroke in force (no check needed)."""
        previous = previous_window(cmd.command_id)
        if previous is None or cmd.offsets.size == 0 or cmd.offsets[0] != 0.0:
            return
        at = cmd.stamp
        before = self.schedule.evaluate(at - LEFT_LIMIT_S)[:2]      # the stroke in force just before the start
        own = np.stack([cmd.positions[0], before[1] if cmd.velocities is None else cmd.velocities[0]])
        jump = np.abs(own - before)     # velocities: only where the window gives them
        if jump[0].max() > JOIN_TOLERANCE[0] or jump[1].max() > JOIN_TOLERANCE[1]:
            k = int(np.argmax(np.maximum(jump[0] / JOIN_TOLERANCE[0], jump[1] / JOIN_TOLERANCE[1])))
            applied = 'was applied but replaced' if previous in self.applied else 'was not applied'
            raise CommandRejected(f'trajectory {cmd.command_id} continues {previous}, which {applied}: starting it '
                                  f'at t = {at:.9f} s would jump joint {k} by {jump[0, k] * 1e6:.4g} µm and '
                                  f'{jump[1, k] * 1e3:.4g} mm/s, which throws the part; not applied (the sender '
                                  're-phases)')

    def command_setpoints(self, values: np.ndarray) -> None:
        """Hold the strokes at ``values`` (m) from now on (the piezo model, when on, smooths the step)."""
        t = self.t
        self.schedule.replace_from(t, trajectory_table([t], np.asarray(values, dtype=float)[None, :]))
        self._prune()

    def _prune(self) -> None:
        """Drop the schedule pieces that ended at or before now (they no longer affect anything)."""
        self.schedule.drop_ended(self.t)
