"""The particle-dynamics API: an immutable model, a mutable state, a stepper and a batch run.

Typical use (the simulator node calls ``advance`` every tick)::

    model = FeederModel.from_settings(flat)              # immutable; builds the contact tables once
    state = model.initial_state()                        # mutable (t = 0, stuck at particle.x0)
    source = StrokeSchedule(model.waveform())            # or a hold, then commanded trajectories
    events = model.advance(state, t_target, source)      # -> EventList of Event, state now at t_target
    obs = model.observe(state, source)                   # pose, twist, wrench, mode at state.t
    source.command_trajectory(t_cmd, knot_times, positions, velocities, accelerations)

    result = model.run()                                 # a whole scenario as a time series

Like MuJoCo's model/data split, a :class:`FeederModel` never changes after construction (parameters,
contact tables, packed kernel inputs); a :class:`FeederState` holds everything that evolves, so several
states can share one model and a state can be copied to branch a run. SI units throughout; frames of
docs/dynamics.md §1 (``feeder``: x along the feeder, z up; ``contact``: tilted by θ = atan(h_x) about y).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ..contact import ContactParams, contact_law
from ..parameters import ParameterError
from ..particle import ParticleParams
from ..piezo import PiezoParams
from ..surface import SurfaceParams, TrackParams
from ..waveforms import StrokeParams, StrokeSchedule, StrokeTable, stack_tables, waveform_table
from . import kernel as k
from . import layout
from .conveying import ConveyingWindow, throw_number
from .event_list import MODES, NO_EVENTS, TRANSITION_KINDS, EventList
from .kernel_observe import observe_parts
from .params import LANDING_LAWS, DetachParams, IntegrationParams, LandingParams


class SimulationError(RuntimeError):
    """The integration cannot continue (non-finite state, an event that cannot be located, chatter).

    The message names the time, the mode and the state; ``state`` is left at the last good point.
    """


@dataclass(frozen=True)
class Observation:
    """What the node publishes at one instant (docs/dynamics.md §4), SI units, frame ``feeder``.

    ``theta`` is the contact-frame tilt atan(h_x) (rad) about the feeder's y axis: a pose orientation
    rotates by −θ about y, so that +x of the contact frame points up the slope when h_x > 0.
    ``normal_load`` is N (> 0 presses the part on the surface; in flight −F_att, the attraction);
    ``friction`` is T along the contact frame's x; ``separation`` is d(N) (NaN in flight); ``gap`` the
    distance to the surface in flight (NaN in contact). ``strokes`` and ``stroke_velocities`` are s and ṡ per
    actuator (m, m/s): the piezo stack's state with the piezo model on, else the commanded stroke's.
    """

    t: float
    mode: str
    x: float
    z: float
    xdot: float
    zdot: float
    theta: float
    normal_load: float
    friction: float
    q_max: float
    separation: float
    gap: float
    surface_height: float
    surface_velocity: float
    strokes: np.ndarray
    stroke_velocities: np.ndarray


class ObservedParts(Sequence[Observation]):
    """Every part's outputs at one sim time as rows (parts × the output columns of docs/dynamics.md §4, then s
    per actuator) and stroke rates ṡ (parts × actuators, m/s): what one compiled call gives. Indexing builds one
    part's :class:`Observation`; a consumer of every part (the simulator's per-tick messages) reads
    :attr:`rows` instead of building 16 of them a tick."""

    __slots__ = ('rows', 'stroke_velocities')

    def __init__(self, rows: np.ndarray, stroke_velocities: np.ndarray):
        self.rows, self.stroke_velocities = rows, stroke_velocities

    def __len__(self) -> int:
        return self.rows.shape[0]

    def __getitem__(self, index: int) -> Observation:      # type: ignore[override]  (no slices)
        row = self.rows[index]
        values = row[:layout.N_FIXED_COLUMNS].tolist()
        values[layout.C_MODE] = MODES[int(values[layout.C_MODE])]        # Observation's fields are in column order
        return Observation(*values, strokes=row[layout.N_FIXED_COLUMNS:],
                           stroke_velocities=self.stroke_velocities[index])


class FeederState:
    """Everything that evolves: time, mode, kinematic state, piezo state, transition counters.

    Create it with :meth:`FeederModel.initial_state` or :meth:`FeederModel.flying_state`. Fields are
    numpy arrays shared with the kernel; read them through the properties.
    """

    def __init__(self, n_stacks: int, x0: float):
        self.y = np.zeros(4 + 2 * n_stacks)           # [x, ẋ, z, ż], then (s_k, ṡ_k) per piezo stack
        self.y[0] = x0
        self.iv = np.zeros(layout.N_IV, dtype=np.int64)
        self.iv[layout.IV_ENTRY_COUNTER] = -1
        self.fs = np.zeros(layout.N_FS)
        self.fs[layout.FS_T_ENTRY] = -math.inf
        self.fs[layout.FS_AHEAD_T1] = math.nan
        self.ahead = np.zeros((2, self.y.size))     # the step taken past the last target (kernel.advance)
        self.ahead_on: tuple = ()                   # (model, stroke table, its end time) it was taken on
        self.x0 = x0

    def copy(self) -> FeederState:
        """An independent copy (to branch a run)."""
        other = FeederState.__new__(FeederState)
        other.y, other.iv, other.fs, other.ahead = self.y.copy(), self.iv.copy(), self.fs.copy(), self.ahead.copy()
        other.ahead_on, other.x0 = self.ahead_on, self.x0
        return other

    @property
    def t(self) -> float:
        """Sim time (s)."""
        return float(self.fs[layout.FS_T])

    @property
    def mode(self) -> str:
        """``stuck``, ``sliding`` or ``flying``."""
        return MODES[int(self.iv[layout.IV_MODE])]

    @property
    def x(self) -> float:
        """Position along the feeder (m)."""
        return float(self.y[0])

    @property
    def xdot(self) -> float:
        """Velocity along x (m/s): ẋ in contact, v_x in flight."""
        return float(self.y[1])

    @property
    def z(self) -> float:
        """Height of the part in flight (m); 0 while on the surface."""
        return float(self.y[2])

    @property
    def zdot(self) -> float:
        """Vertical velocity in flight (m/s); 0 on the surface."""
        return float(self.y[3])

    @property
    def piezo_stroke(self) -> np.ndarray:
        """Each piezo stack's extension (m), a view into the state (empty unless ``piezo.enabled``: only then
        are the stacks integrated, so only then do they take room in the state every step works on)."""
        return self.y[4::2]

    @property
    def piezo_velocity(self) -> np.ndarray:
        """Each piezo stack's extension rate (m/s), a view into the state."""
        return self.y[5::2]

    @property
    def distance(self) -> float:
        """Net displacement x − x0 (m)."""
        return float(self.y[0] - self.x0)

    @property
    def max_speed(self) -> float:
        """Largest |ẋ| (|v_x| in flight) seen so far (m/s)."""
        return float(self.fs[layout.FS_MAX_SPEED])

    @property
    def transitions(self) -> dict[str, int]:
        """Counters ``stick_to_slip``, ``slip_to_stick``, ``take_off``, ``landing`` (docs/dynamics.md §1)."""
        return {name: int(self.iv[idx]) for name, idx in zip(TRANSITION_KINDS, layout.COUNTERS, strict=True)}


class StateRows:
    """Several parts' states (all at one sim time) as the rows of four arrays: what one compiled call advances
    (:meth:`FeederModel.advance_rows`). ``ons`` and ``x0`` hold each row's ``ahead_on`` and ``x0``.

    :meth:`views` gives one :class:`FeederState` per row whose arrays are that row: a change made through a
    view (a velocity set at an impact, a part moved) is a change of the rows."""

    __slots__ = ('ahead', 'fs', 'iv', 'ons', 'x0', 'y')

    def __init__(self, y: np.ndarray, iv: np.ndarray, fs: np.ndarray, ahead: np.ndarray, ons: list[tuple],
                 x0: list[float]):
        self.y, self.iv, self.fs, self.ahead, self.ons, self.x0 = y, iv, fs, ahead, ons, x0

    @classmethod
    def of(cls, states: Sequence[FeederState]) -> StateRows:
        """Rows holding copies of ``states``."""
        return cls(np.stack([s.y for s in states]), np.stack([s.iv for s in states]),
                   np.stack([s.fs for s in states]), np.stack([s.ahead for s in states]),
                   [s.ahead_on for s in states], [s.x0 for s in states])

    def __len__(self) -> int:
        return self.y.shape[0]

    @property
    def t(self) -> float:
        """Sim time (s)."""
        return float(self.fs[0, layout.FS_T])

    def copy(self) -> StateRows:
        """Independent rows (to branch a run)."""
        return StateRows(self.y.copy(), self.iv.copy(), self.fs.copy(), self.ahead.copy(), list(self.ons),
                         list(self.x0))

    def view(self, p: int) -> FeederState:
        """Row ``p`` as a :class:`FeederState` sharing its arrays."""
        state = FeederState.__new__(FeederState)
        state.y, state.iv, state.fs, state.ahead = self.y[p], self.iv[p], self.fs[p], self.ahead[p]
        state.ahead_on, state.x0 = self.ons[p], self.x0[p]
        return state

    def views(self) -> list[FeederState]:
        """Every row as a :class:`FeederState` sharing its arrays."""
        return [self.view(p) for p in range(len(self))]


@dataclass(frozen=True)
class RunResult:
    """A simulated time series: one row per accepted step and per event (docs/dynamics.md §4)."""

    columns: tuple[str, ...]
    data: np.ndarray
    events: EventList
    state: FeederState
    conveying: dict[str, float] = field(default_factory=dict)

    def __getitem__(self, name: str) -> np.ndarray:
        """One column by name (``t``, ``x``, ``friction``, ``stroke_0`` ...)."""
        return self.data[:, self.columns.index(name)]

    @property
    def modes(self) -> np.ndarray:
        """Mode per row as strings."""
        return np.asarray(MODES)[self['mode'].astype(int)]

    def summary(self) -> dict[str, Any]:
        """Net distance (m), whether the part settled (stuck at the end: a part still sliding or in
        flight has not arrived, and its position is not a distance travelled), final mode, transition
        counts, max speed (m/s), sim time (s), and the conveying figures (:meth:`FeederModel.conveying_figures`,
        None where there is none)."""
        return {'distance_m': self.state.distance, 'settled': self.state.mode == 'stuck',
                'final_mode': self.state.mode, 'transitions': self.state.transitions,
                'max_speed_mps': self.state.max_speed, 'sim_time_s': self.state.t,
                **{k: None if math.isnan(v) else v for k, v in self.conveying.items()}}


BOUNCE_MIN_FLIGHT_EVENT_TOLERANCES = 1000   # a bounce shorter than this many event tolerances is plastic


@dataclass(frozen=True)
class FeederModel:
    """Immutable particle-on-surface model (parameters, contact tables, packed kernel inputs).

    Build with :meth:`from_settings` (flat ``{dotted name: value}``, as read from config/feeder.yaml
    and ``--set``) or with the parameter groups directly. ``contact_model`` may be given to reuse
    tables or to substitute test variants (any object with ``tables`` and ``pull_off_n``).
    ``base_acceleration``: an optional one-channel :class:`StrokeTable` whose s̈ (m/s²) shakes the
    whole feeder along x (used for the flat-surface threshold check of docs/dynamics.md §1).
    """

    particle: ParticleParams = field(default_factory=ParticleParams)
    contact: ContactParams = field(default_factory=ContactParams)
    surface: SurfaceParams = field(default_factory=SurfaceParams)
    track: TrackParams = field(default_factory=TrackParams)
    stroke: StrokeParams = field(default_factory=StrokeParams)
    piezo: PiezoParams = field(default_factory=PiezoParams)
    integration: IntegrationParams = field(default_factory=IntegrationParams)
    detach: DetachParams = field(default_factory=DetachParams)
    landing: LandingParams = field(default_factory=LandingParams)
    contact_model: Any = None
    base_acceleration: StrokeTable | None = None

    def __post_init__(self) -> None:
        if self.contact_model is None:
            object.__setattr__(self, 'contact_model', contact_law(self.contact, self.particle))
        object.__setattr__(self, '_waveform', waveform_table(self.stroke, self.surface.n_actuators))
        surface, integration, piezo = self.surface, self.integration, self.piezo
        track = surface.kind == 'track'
        if track and surface.n_actuators != (2 if self.track.drive == 'two_way' else 1):
            raise ParameterError('surface.centers', list(surface.centers),
                                 f"track.drive '{self.track.drive}' moves the track with "
                                 f"{2 if self.track.drive == 'two_way' else 1} actuator(s): give that many centres "
                                 '(and widths, and stroke.phases)')
        if surface.thickness > 0.0:
            self._check_thickness()
        alpha, beta = self.track.inclination, self.track.vibration_angle
        gravity = self.particle.gravity * (math.cos(alpha) if track else 1.0)     # its part normal to the surface
        scalars = dict(
            mass=self.particle.mass, gravity=gravity, pull_off=self.contact_model.pull_off_n,
            dt=integration.dt, tolerance=integration.tolerance, check_step=integration.check_step,
            event_tolerance=integration.event_tolerance, cutoff_radius=surface.cutoff_radius,
            min_width=min(surface.widths), max_width=max(surface.widths),
            piezo_omega=piezo.omega_n, piezo_zeta=piezo.damping, piezo_min=piezo.stroke_min,
            piezo_max=piezo.stroke_max, lift=math.sin(beta) if track else 0.0,
            shake=math.cos(beta) if track else 0.0,
            slope_acc=self.particle.gravity * math.sin(alpha) if track else 0.0, landing_mu=self.contact.mu,
            restitution=self.landing.restitution, half_thickness=0.5 * surface.thickness,
            bounce_min_flight=BOUNCE_MIN_FLIGHT_EVENT_TOLERANCES * integration.event_tolerance)
        flags = dict(
            adaptive=integration.method == 'dopri5', threshold=integration.friction_logic == 'threshold',
            dip_search=integration.event_search == 'dips', convective=integration.convective_terms,
            include_weight=self.detach.include_weight, landing_relative=self.landing.velocity == 'relative',
            piezo=piezo.enabled, has_base=self.base_acceleration is not None, track=track, record=False)
        tables = {name: np.ascontiguousarray(getattr(self.contact_model.tables, name), dtype=float)
                  for name in ('load_n', 'q_max_n', 'separation_m', 'gap_m', 'attraction_n')}
        # one numba type whatever the Python types the settings arrived in (no recompilation)
        packed = layout.KernelModel(
            **{name: float(value) for name, value in scalars.items()},
            **{name: bool(value) for name, value in flags.items()}, **tables,
            centers=np.asarray(surface.centers, dtype=float), widths=np.asarray(surface.widths, dtype=float),
            n_actuators=int(surface.n_actuators), landing_law=LANDING_LAWS.index(self.landing.law),
            lift_channel=1 if track and self.track.drive == 'two_way' else 0)
        object.__setattr__(self, '_kernel_model', packed)
        object.__setattr__(self, '_recording_model', packed._replace(record=True))

    def _check_thickness(self) -> None:
        """surface.thickness needs the exact-event dynamics it was built on (docs/dynamics.md §1)."""
        integration, particle = self.integration, self.particle
        checks = (('piezo.enabled', self.piezo.enabled, self.piezo.enabled, 'false with surface.thickness > 0 (the '
                   'stack model and a moving material are not combined)'),
                  ('integration.friction_logic', integration.friction_logic, integration.friction_logic != 'events',
                   "'events' with surface.thickness > 0"),
                  ('integration.convective_terms', integration.convective_terms, not integration.convective_terms,
                   'true with surface.thickness > 0'),
                  ('particle.x0', list(particle.start_positions), particle.n_parts > 1,
                   'one part with surface.thickness > 0 (parts meeting on a moving material are not modelled)'))
        for name, value, refused, allowed in checks:
            if refused:
                raise ParameterError(name, value, allowed)

    @classmethod
    def from_settings(cls, flat: Mapping[str, Any], **overrides: Any) -> FeederModel:
        """Build every group from a flat ``{dotted name: value}`` mapping (defaults for missing names).

        Raises :class:`~micro_feeder.physics.parameters.ParameterError` naming a refused parameter.
        """
        groups = {name: group.from_flat(flat) for name, group in (
            ('particle', ParticleParams), ('contact', ContactParams), ('surface', SurfaceParams),
            ('track', TrackParams), ('stroke', StrokeParams), ('piezo', PiezoParams),
            ('integration', IntegrationParams), ('detach', DetachParams), ('landing', LandingParams))}
        return cls(**groups, **overrides)

    def replace(self, **changes: Any) -> FeederModel:
        """A model with some groups replaced (the contact tables are reused unless contact or particle
        parameters change)."""
        keep_contact = 'contact' not in changes and 'particle' not in changes
        contact_model = changes.pop('contact_model', self.contact_model if keep_contact else None)
        current = {name: getattr(self, name) for name in (
            'particle', 'contact', 'surface', 'track', 'stroke', 'piezo', 'integration', 'detach', 'landing',
            'base_acceleration')}
        return FeederModel(**{**current, **changes}, contact_model=contact_model)

    @property
    def n_actuators(self) -> int:
        return self.surface.n_actuators

    def waveform(self) -> StrokeTable:
        """The analytic stroke burst of the ``stroke.*`` parameters (the default stroke source)."""
        return self._waveform

    def default_duration(self) -> float:
        """End of the last stroke plus ``integration.settling_time`` (s)."""
        return self.stroke.burst_end_s() + self.integration.settling_time

    def initial_state(self, x0: float | None = None, v0: float | None = None) -> FeederState:
        """t = 0, part at ``x0`` (m, default the first ``particle.x0``) with velocity ``v0`` (m/s, default the
        first ``particle.v0``): stuck at rest, or sliding in the direction of ``v0`` when it is not 0 (a start,
        not a counted transition)."""
        state = FeederState(self._n_stacks, self.particle.start_positions[0] if x0 is None else x0)
        v0 = self.particle.start_velocities[0] if v0 is None else v0
        if v0 != 0.0:
            state.y[1] = v0
            state.iv[layout.IV_MODE] = layout.SLIDING
            state.iv[layout.IV_DIR] = 1 if v0 > 0.0 else -1
            state.fs[layout.FS_MAX_SPEED] = abs(v0)
        return state

    def flying_state(self, x: float, z: float, vx: float, vz: float, t: float = 0.0) -> FeederState:
        """A part in flight at (x, z) (m) with velocity (vx, vz) (m/s) at time ``t``."""
        state = FeederState(self._n_stacks, x)
        state.y[:4] = x, vx, z, vz
        state.iv[layout.IV_MODE] = layout.FLYING
        state.fs[layout.FS_T] = t
        return state

    def set_velocity(self, state: FeederState, xdot: float,
                     source: StrokeTable | StrokeSchedule | None = None) -> EventList:
        """Give the part the velocity ``xdot`` (m/s, along x) at ``state.t``, as an impact does, and set its
        mode accordingly; returns the mode change (empty or one event, counted in ``state.transitions``).

        A flying part keeps flying (its v_x changes). A part on the surface slides in the direction of
        ``xdot`` when it is not 0; at ``xdot`` = 0 it is stuck when the stick criterion |T_req| <= Q_max
        holds there (docs/dynamics.md §1), else it starts sliding from rest in the direction friction
        opposes, as at a ``stick_to_slip``. The step the state kept past its last target is dropped.
        """
        self._check_state(state)
        old_mode = int(state.iv[layout.IV_MODE])
        state.y[1] = xdot
        state.fs[layout.FS_AHEAD_T1] = math.nan
        state.iv[layout.IV_START_KNOWN] = 0
        state.fs[layout.FS_MAX_SPEED] = max(state.fs[layout.FS_MAX_SPEED], abs(xdot))
        if old_mode == layout.FLYING:
            return EventList()
        if xdot != 0.0:
            new_mode, direction, fresh = layout.SLIDING, 1 if xdot > 0.0 else -1, 0
        else:
            required, limit = self.friction_at_rest(state, source)
            if abs(required) <= limit:
                new_mode, direction, fresh = layout.STUCK, 0, 0
            else:
                new_mode, direction, fresh = layout.SLIDING, -1 if required > 0.0 else 1, 1
        state.iv[layout.IV_DIR] = direction
        state.iv[layout.IV_FRESH] = fresh
        if new_mode == old_mode:
            return EventList()
        kind, counter = ((layout.STICK_TO_SLIP, layout.IV_STICK_TO_SLIP) if new_mode == layout.SLIDING
                         else (layout.SLIP_TO_STICK, layout.IV_SLIP_TO_STICK))
        state.iv[counter] += 1
        state.iv[layout.IV_PREV_MODE] = old_mode
        state.iv[layout.IV_MODE] = new_mode
        state.iv[layout.IV_ENTRY_COUNTER] = counter
        state.fs[layout.FS_T_ENTRY] = state.t
        return EventList(np.array([[kind, old_mode, new_mode]], dtype=np.int64), np.array([[state.t, state.x]]))

    def friction_at_rest(self, state: FeederState, source: StrokeTable | StrokeSchedule | None = None
                         ) -> tuple[float, float]:
        """(T_req, Q_max) (N) for the part at rest on the surface where ``state`` has it at ``state.t``: the
        friction that would keep it stuck and the most the contact can give (docs/dynamics.md §1)."""
        at_rest = state.copy()
        at_rest.y[1:4] = 0.0
        at_rest.iv[layout.IV_MODE] = layout.STUCK
        obs = self.observe(at_rest, source)                # friction is T_req while stuck
        return obs.friction, obs.q_max

    def move_to(self, state: FeederState, x: float) -> None:
        """Put the part at ``x`` (m) at ``state.t``, mode and velocity unchanged (how a train of parts
        pressed together keeps its parts apart, docs/parts.md); drops the step the state kept ahead."""
        self._check_state(state)
        state.y[0] = x
        state.fs[layout.FS_AHEAD_T1] = math.nan
        state.iv[layout.IV_START_KNOWN] = 0

    def advance(self, state: FeederState, t_target: float,
                source: StrokeTable | StrokeSchedule | None = None) -> EventList:
        """Integrate ``state`` in place to ``t_target`` (s) and return the mode changes on the way
        (a sequence of :class:`Event`, kept as arrays until read).

        ``source``: the stroke command (a table or a :class:`StrokeSchedule`; default the analytic
        waveform). Work is split at the schedule's switch times. Raises :class:`SimulationError`
        (time, mode, state) instead of producing a non-finite state.
        """
        events, _ = self._integrate(state, t_target, source, record=False)
        return events

    def advance_copies(self, states: Sequence[FeederState], t_target: float,
                       source: StrokeTable | StrokeSchedule | None = None) -> PartsAdvance:
        """Copies of ``states`` (all at one sim time) each integrated to ``t_target`` (s) as :meth:`advance`
        would (the same steps, bit for bit), in one compiled call per stroke segment instead of one Python call
        per state; ``states`` are left as they were. Also returns, per state, the largest |ẋ| (m/s; |v_x| in
        flight) at its start, its step ends and its events, and the distance along x between its start, its
        events and its end (m): how far it may have gone in between (docs/parts.md). Each copy's
        ``max_speed`` keeps its run's largest as before."""
        advanced = self.advance_rows(StateRows.of(states), t_target, source)
        return PartsAdvance(advanced.rows.views(), [advanced.events.get(p, NO_EVENTS) for p in range(len(states))],
                            advanced.peak_speed, advanced.path)

    def advance_rows(self, rows: StateRows, t_target: float,
                     source: StrokeTable | StrokeSchedule | None = None) -> RowsAdvance:
        """:meth:`advance_copies` on rows: new rows (``rows`` are left as they were), the events of the rows that
        had some (by row), each row's largest |ẋ| and distance along x (m)."""
        n = len(rows)
        ys, ivs, fss, aheads = rows.y.copy(), rows.iv.copy(), rows.fs.copy(), rows.ahead.copy()
        if ys.shape[1] != 4 + 2 * self._n_stacks:
            self._check_state(rows.view(0))
        run_max = fss[:, layout.FS_MAX_SPEED].copy()
        fss[:, layout.FS_MAX_SPEED] = np.abs(ys[:, 1])
        running = np.ones(n, dtype=np.bool_)
        status = np.zeros(n, dtype=np.int64)
        path = np.zeros(n)
        ons = list(rows.ons)
        collected: dict[int, list[EventList]] = {}
        for t_until, t_limit, table in self.segments(float(fss[0, layout.FS_T]), t_target, source):
            src, work, records = self._put_on(ys.shape[1], fss, ons, running, table, t_limit)
            counts = np.zeros(n, dtype=np.int64)
            n_ev = k.advance_parts(ys, ivs, fss, aheads, running, status, t_until, t_limit, self._kernel_model, src,
                                   work.batch_ev_i, work.batch_ev_f, counts, path, records, 0,
                                   work.scratch, work.st, work.aux, work.cur)
            if n_ev:
                ends = np.cumsum(counts)
                for p in np.flatnonzero(counts).tolist():
                    collected.setdefault(p, []).append(EventList(work.batch_ev_i[ends[p] - counts[p]:ends[p]].copy(),
                                                                 work.batch_ev_f[ends[p] - counts[p]:ends[p]].copy()))
        advanced = StateRows(ys, ivs, fss, aheads, ons, list(rows.x0))
        for p in np.flatnonzero(status != layout.DONE).tolist():
            copy = advanced.view(p)
            if status[p] != layout.EVENTS_FULL:
                raise SimulationError(self._failure(int(status[p]), copy))
            x_last = copy.x                                 # too many events to batch: on alone
            rest, _ = self._integrate(copy, t_target, source, record=False)
            advanced.ons[p] = copy.ahead_on
            path[p] += np.abs(np.diff([x_last, *rest.x, copy.x])).sum()
            collected.setdefault(p, []).append(rest)
        peak = fss[:, layout.FS_MAX_SPEED].copy()
        fss[:, layout.FS_MAX_SPEED] = np.maximum(run_max, peak)
        return RowsAdvance(advanced, {p: EventList.concatenate(e) for p, e in collected.items()}, peak, path)

    def _put_on(self, n_y: int, fss: np.ndarray, ons: list[tuple], running: np.ndarray, table: StrokeTable,
                t_limit: float) -> tuple[tuple, _KernelWork, np.ndarray]:
        """Rows about to be advanced on ``table`` (valid until ``t_limit``): a row taken on another model or
        table loses its look-ahead (``fss``), and each ``running`` row is marked as on this one (``ons``).
        Returns the kernel's stroke source, work arrays and (unused) output rows."""
        src = self._source_table(table).as_tuple()
        work = _WORK.arrays(n_y, src[0].size)
        on_now = (self, table, t_limit)
        for p, (on, go) in enumerate(zip(ons, running.tolist(), strict=True)):
            if not (on and on[0] is self and on[1] is table and on[2] == t_limit):
                fss[p, layout.FS_AHEAD_T1] = math.nan      # taken on another model or source: not valid
            if go:                                          # not a row left for the fallback below
                ons[p] = on_now
        return src, work, work.records(layout.N_FIXED_COLUMNS + self.n_actuators, False)

    def rows_on_one_table(self, rows: StateRows, t_target: float, source: StrokeTable | StrokeSchedule | None
                          ) -> tuple[layout.KernelModel, tuple, float, _KernelWork, np.ndarray] | None:
        """For a compiled caller advancing ``rows`` in place to at most ``t_target`` (s) by
        :func:`.kernel.advance_parts`: None unless one stroke table is in force over the whole span; else the
        rows marked as on it (as :meth:`advance_rows` marks them) and what the kernel takes: its model, the
        stroke source, the time the table stops being valid (s), the work arrays and the output rows."""
        segments = self.segments(rows.t, t_target, source)
        if len(segments) != 1:
            return None
        n_y = rows.y.shape[1]
        if n_y != 4 + 2 * self._n_stacks:
            self._check_state(rows.view(0))
        _, t_limit, table = segments[0]
        src, work, records = self._put_on(n_y, rows.fs, rows.ons, np.ones(len(rows), dtype=np.bool_), table, t_limit)
        return self._kernel_model, src, t_limit, work, records

    def settle(self, state: FeederState, source: StrokeTable | StrokeSchedule | None = None,
               max_time: float | None = None, step: float | None = None) -> EventList:
        """Integrate ``state`` on until the part is stuck again (at rest once the strokes have ended),
        for at most ``max_time`` (s, default ``integration.settle_max``) more, in pieces of ``step`` (s,
        default ``integration.settling_time`` or 1 ms); returns the events. Whether it settled:
        ``state.mode == 'stuck'`` afterwards."""
        return self._settle(state, source, max_time, step, record=False)[0]

    def run(self, duration: float | None = None, source: StrokeTable | StrokeSchedule | None = None,
            state: FeederState | None = None, output_step: float | None = None) -> RunResult:
        """Simulate from ``state`` (default: the initial state) for ``duration`` and return the time
        series: one row per integration step and per event, plus (with ``output_step``, s) rows at least
        every ``output_step`` for smooth plots. With no ``duration`` the run lasts
        :meth:`default_duration` and then goes on until the part is stuck again (:meth:`settle`, at most
        ``integration.settle_max`` more): the summary's ``settled`` says whether it came to rest."""
        state = self.initial_state() if state is None else state
        t_end = state.t + (self.default_duration() if duration is None else duration)
        rows = [self._observe_rows([state], source)[0]]
        events: list[EventList] = []
        stops = [t_end] if output_step is None else \
            [*np.arange(state.t + output_step, t_end, output_step).tolist(), t_end]
        window = ConveyingWindow.of(self.stroke) if source is None and state.t == 0.0 else None
        marks = window.marks if window is not None and window.t_end <= t_end else ()
        at_marks = []
        for t_stop in sorted({*stops, *marks}):
            chunk_events, recorded = self._integrate(state, t_stop, source, record=True)
            events.append(chunk_events)
            rows += recorded
            if t_stop in marks:
                at_marks.append(state.x)
        if duration is None:
            chunk_events, recorded = self._settle(state, source, None, output_step, record=True)
            events.append(chunk_events)
            rows += recorded
        return RunResult(self.columns(), np.vstack(rows), EventList.concatenate(events), state,
                         self.conveying_figures(window.velocity(*at_marks) if marks else math.nan))

    def throw_number(self) -> float:
        """Γ of a track (:func:`~.conveying.throw_number`); NaN for a bump surface."""
        return throw_number(self.surface, self.track, self.stroke, self.particle.gravity)

    def conveying_figures(self, mean_velocity: float) -> dict[str, float]:
        """``mean_velocity_mps`` over the burst's second half of whole periods (NaN for one stroke, a run that
        ends before it, or another source than the configured strokes) and ``throw_number`` (NaN for bumps)."""
        return {'mean_velocity_mps': mean_velocity, 'throw_number': self.throw_number()}

    def _settle(self, state: FeederState, source: StrokeTable | StrokeSchedule | None, max_time: float | None,
                step: float | None, record: bool) -> tuple[EventList, list[np.ndarray]]:
        max_time = self.integration.settle_max if max_time is None else max_time
        step = step or self.integration.settling_time or 1e-3
        t_cap = state.t + max_time
        events: list[EventList] = []
        rows: list[np.ndarray] = []
        while state.mode != 'stuck' and state.t < t_cap:
            chunk_events, recorded = self._integrate(state, min(state.t + step, t_cap), source, record)
            events.append(chunk_events)
            rows += recorded
        return EventList.concatenate(events), rows

    def columns(self) -> tuple[str, ...]:
        """Names of the recorded columns (then ``stroke_k`` per actuator)."""
        return layout.COLUMN_NAMES + tuple(f'stroke_{i}' for i in range(self.n_actuators))

    def observe(self, state: FeederState, source: StrokeTable | StrokeSchedule | None = None) -> Observation:
        """The outputs (docs/dynamics.md §4) at ``state.t`` (does not change the state)."""
        return self.observe_many([state], source)[0]

    def observe_many(self, states: Sequence[FeederState] | StateRows,
                     source: StrokeTable | StrokeSchedule | None = None) -> list[Observation]:
        """:meth:`observe` of several states at one sim time (the parts on a feeder, or their rows), in one
        compiled call."""
        return list(self.observe_rows(states, source))

    def observe_rows(self, states: Sequence[FeederState] | StateRows,
                     source: StrokeTable | StrokeSchedule | None = None) -> ObservedParts:
        """:meth:`observe_many` as rows (:class:`ObservedParts`: an Observation built only for the part asked)."""
        return ObservedParts(*self._observe_rows(states, source))

    # ------------------------------------------------------------------------------------------------

    def _source_table(self, source: StrokeTable | None) -> StrokeTable:
        table = self._waveform if source is None else source
        if table.n_channels != self.n_actuators:
            raise ValueError(f'stroke source has {table.n_channels} channels, the surface '
                             f'{self.n_actuators} actuators')
        if self.base_acceleration is not None:
            table = stack_tables([table, self.base_acceleration])
        return table

    def segments(self, t0: float, t1: float, source: StrokeTable | StrokeSchedule | None
                 ) -> list[tuple[float, float, StrokeTable]]:
        """(end time, time the table stops being valid, table) pieces covering (t0, t1] according to the
        schedule."""
        if not isinstance(source, StrokeSchedule):
            return [(t1, math.inf, self._waveform if source is None else source)]
        return [(min(t_until, t1), t_until, table) for _, t_until, table in source.spans(t0, t1)]

    def _observe_rows(self, states: Sequence[FeederState] | StateRows, source: StrokeTable | StrokeSchedule | None
                      ) -> tuple[np.ndarray, np.ndarray]:
        """The output rows (states, columns) at the states' time (one for all) and each one's stroke rates ṡ per
        channel (states, channels; m/s), in one compiled call."""
        n = len(states)
        if not n:
            return np.zeros((0, layout.N_FIXED_COLUMNS + self.n_actuators)), np.zeros((0, self.n_actuators))
        n_y = 4 + 2 * self._n_stacks
        if isinstance(states, StateRows):
            if states.y.shape[1] != n_y:
                self._check_state(states.view(0))
            ys, ivs, t = states.y, states.iv, states.t
        else:
            for state in states:
                if state.y.size != n_y:
                    self._check_state(state)
            ys, ivs, t = np.stack([s.y for s in states]), np.stack([s.iv for s in states]), states[0].t
        table = source.table_at(t) if isinstance(source, StrokeSchedule) else source
        src = self._source_table(table).as_tuple()
        work = _WORK.arrays(n_y, src[0].size)
        k.locate_all(src, t, work.cur)
        rows = np.zeros((n, layout.N_FIXED_COLUMNS + self.n_actuators))
        stroke_velocities = np.zeros((n, self.n_actuators))
        observe_parts(t, ys, ivs, self._kernel_model, src, work.cur, work.st, work.aux, work.dy, rows,
                      stroke_velocities)
        return rows, stroke_velocities

    def _integrate(self, state: FeederState, t_target: float,
                   source: StrokeTable | StrokeSchedule | None, record: bool
                   ) -> tuple[EventList, list[np.ndarray]]:
        self._check_state(state)
        packed = self._recording_model if record else self._kernel_model
        events: list[EventList] = []
        recorded: list[np.ndarray] = []
        for t_until, t_limit, table in self.segments(state.t, t_target, source):
            src = self._source_table(table).as_tuple()
            work = _WORK.arrays(state.y.size, src[0].size)
            ev_i, ev_f, scratch, st, aux, cur = work.ev_i, work.ev_f, work.scratch, work.st, work.aux, work.cur
            rec = work.records(layout.N_FIXED_COLUMNS + self.n_actuators, record)
            on = state.ahead_on
            if not (on and on[0] is self and on[1] is table and on[2] == t_limit):
                state.fs[layout.FS_AHEAD_T1] = math.nan      # taken on another model or source: not valid
            state.ahead_on = (self, table, t_limit)
            while state.t < t_until:
                status, n_ev, n_rec = k.advance(state.y, state.iv, state.fs, state.ahead, t_until, t_limit,
                                                packed, src, ev_i, ev_f, rec, 0, scratch, st, aux, cur)
                if n_ev:
                    events.append(EventList(ev_i[:n_ev].copy(), ev_f[:n_ev].copy()))
                if record and n_rec:
                    recorded.append(rec[:n_rec].copy())
                if status in (layout.NON_FINITE, layout.EVENT_NOT_LOCATED, layout.CHATTER):
                    raise SimulationError(self._failure(status, state))
        return EventList.concatenate(events), recorded

    @property
    def _n_stacks(self) -> int:
        """Piezo stacks in the state: one per actuator with ``piezo.enabled``, none otherwise."""
        return self.n_actuators if self.piezo.enabled else 0

    def _check_state(self, state: FeederState) -> None:
        if state.piezo_stroke.size != self._n_stacks:
            raise ValueError(f'the state holds {state.piezo_stroke.size} piezo stacks, this model integrates '
                             f'{self._n_stacks} (piezo.enabled {self.piezo.enabled}, {self.n_actuators} '
                             'actuators): make the state with this model (initial_state or flying_state)')

    def _failure(self, status: int, state: FeederState) -> str:
        what = {layout.NON_FINITE: 'the state or the contact load became non-finite',
                layout.EVENT_NOT_LOCATED: 'an event could not be located within integration.event_tolerance',
                layout.CHATTER: 'more than 8 mode changes at the same instant (chatter)'}[status]
        return (f'{what} at t = {state.t:.9g} s in mode {state.mode} '
                f'(x = {state.x:.9g} m, state vector {state.y.tolist()}); '
                f'try a smaller integration.dt')


class PartsAdvance(NamedTuple):
    """What :meth:`FeederModel.advance_copies` returns, one entry per state: the advanced copies, their
    events, their largest |ẋ| (m/s) and the distance along x between their start, events and end (m)."""

    states: list[FeederState]
    events: list[EventList]
    peak_speed: np.ndarray
    path: np.ndarray


class RowsAdvance(NamedTuple):
    """What :meth:`FeederModel.advance_rows` returns: the advanced rows, the events of the rows that had some
    (by row index), each row's largest |ẋ| (m/s) and distance along x between its start, events and end (m)."""

    rows: StateRows
    events: dict[int, EventList]
    peak_speed: np.ndarray
    path: np.ndarray


class _KernelWork:
    """The kernel's work arrays for one state size and channel count (what ``kernel.advance`` and
    ``kernel.observe`` take as ``ev_i``, ``ev_f``, ``scratch``, ``st``, ``aux``, ``cur``, ``dy``, ``rec``).

    No kernel call depends on what an earlier one left in them: it writes every entry before reading it,
    except ``aux``'s load-table index (only where a search starts) and the ``st`` columns outside the felt
    range (left stale and never read). So they are kept between calls instead of allocated for each: the
    simulator node advances 1 ms a tick, and allocating them per call took a fifth of the tick's Python time.
    Callers copy what they keep (events, recorded rows)."""

    def __init__(self, n_y: int, n_channels: int):
        self.ev_i = np.zeros((1024, 3), dtype=np.int64)
        self.ev_f = np.zeros((1024, 2))
        self.scratch = np.zeros((layout.N_SCRATCH, n_y))
        self.st = np.zeros((4, n_channels))
        self.aux = np.zeros(layout.N_AUX)
        self.cur = np.zeros((n_channels, 2), dtype=np.int64)
        self.dy = np.zeros(n_y)
        self.batch_ev_i = np.zeros((4096, 3), dtype=np.int64)     # kernel.advance_parts: every part's events
        self.batch_ev_f = np.zeros((4096, 2))
        self._records: dict[tuple[int, bool], np.ndarray] = {}

    def records(self, n_columns: int, record: bool) -> np.ndarray:
        """The output-row buffer: 4096 rows when recording, else the 2 the kernel still needs."""
        key = (n_columns, record)
        if key not in self._records:
            self._records[key] = np.zeros((4096 if record else 2, n_columns))
        return self._records[key]


class _ThreadWork(threading.local):
    """:class:`_KernelWork` per thread and size: the compiled kernel releases the GIL, so two threads may
    integrate at once and must not share work arrays."""

    def __init__(self) -> None:
        self._by_size: dict[tuple[int, int], _KernelWork] = {}

    def arrays(self, n_y: int, n_channels: int) -> _KernelWork:
        """This thread's work arrays for a state of ``n_y`` entries and ``n_channels`` stroke channels."""
        work = self._by_size.get((n_y, n_channels))
        if work is None:
            work = self._by_size[(n_y, n_channels)] = _KernelWork(n_y, n_channels)
        return work


_WORK = _ThreadWork()
