"""The stroke stream: a burst's knots for a trajectory message, whole or in windows that follow sim time.

What the actuator node sends, without ROS: :func:`sample_waveform` gives a whole burst's knots,
:class:`StrokeStream` the successive windows of a streamed one (each stamped at its start in sim time,
taking over at a knot the previous window ends on; re-phased to sim time when it goes back or the sender
stalled: :meth:`StrokeStream.follow`), :func:`encode_window` one window as the serialized JointTrajectory.
Knots are placed so that the quintic interpolation the simulator (and joint_trajectory_controller) runs
through them reproduces the schedule within 5e-13 m (:mod:`micro_feeder.physics.trajectory`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..interface import stamps, trajectory_cdr
from ..interface.names import joint_names
from ..physics.trajectory import burst_end_ns, max_spacing, table_knots, waveform_knots
from ..physics.waveforms import StrokeParams, waveform_table

Window = tuple[int, np.ndarray, np.ndarray]   # stamp (ns of sim time), knot offsets (ns), (3, n, actuators) s, ṡ, s̈
TIME_BACK = 1e-3               # s: sim time going back more than this is a reset or a new simulator
RAMP_MIN_NS = 1_000_000        # a re-phased stream ramps to the waveform over at least this long (ns)
MESSAGE_BYTES = 256 * 1024     # a trajectory message's knots take at most this many bytes (whatever the joints)


def sample_waveform(params: StrokeParams, n_actuators: int, knots_per_stroke: int = 0
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Knots of the whole burst: times (s from its start, whole ns) and (n, actuators) s (m), ṡ (m/s),
    s̈ (m/s²), at least ``knots_per_stroke`` per stroke period (see :func:`waveform_knots`)."""
    return waveform_knots(params, n_actuators, min_knots_per_stroke=knots_per_stroke)


def points_per_message(max_points: int, n_actuators: int) -> int:
    """Knots in one trajectory message: ``max_points``, fewer when that many would exceed
    :data:`MESSAGE_BYTES` (64 actuators: 169 knots), so that a message stays far below the simulator's
    ``max_command_bytes`` (1 MiB) however many joints it carries."""
    return max(2, min(max_points, MESSAGE_BYTES // trajectory_cdr.point_bytes(n_actuators)))


class StrokeStream:
    """The windows of a streamed burst (pure: no ROS). Times in integer nanoseconds of sim time.

    ``origin_ns``: sim time at which the burst's time 0 falls; :meth:`next_window` returns the knots of the
    next window, starting where the previous one ended. ``count`` 0 = endless.
    """

    def __init__(self, params: StrokeParams, count: int, n_actuators: int, origin_ns: int, *,
                 window: float, max_points: int, knots_per_stroke: int):
        self.params, self.count, self.n_actuators = params, count, n_actuators
        self.origin_ns = origin_ns
        self.sent_ns = 0                                   # burst time up to which knots were sent
        self.end_ns = burst_end_ns(dataclasses.replace(params, count=count)) if count else None
        self._window_ns = max(round(window * 1e9), 1)
        self._max_points = points_per_message(max_points, n_actuators)
        self._max_spacing = max_spacing(params, knots_per_stroke)
        self._ramp_from: int | None = None                 # burst time (ns) a re-phased stream's next window starts
        self._last_now: float | None = None                # sim time of the last follow() (s)
        self.rephased_at: float | None = None              # sim time (s) of the last re-phase
        self.windows_made = 0                              # windows returned by next_window(): the k of w<k>
        self._rephased_after = 0                           # windows made before the last re-phase (in flight)

    @property
    def done(self) -> bool:
        return self.end_ns is not None and self.sent_ns >= self.end_ns

    @property
    def scheduled_until(self) -> float:
        """Sim time (s) up to which the strokes are scheduled (a pending ramp's start: nothing after it is sent)."""
        return (self.origin_ns + (self._ramp_from if self._ramp_from is not None else self.sent_ns)) * 1e-9

    def next_window(self) -> Window:
        """(stamp in ns of sim time, knot offsets from the stamp in ns, (3, n, actuators) s, ṡ, s̈). A window
        continues the previous one from the knot they share (offset 0). The first window after a re-phase has
        no knot at its stamp: the simulator starts it from the stroke in force there (s, ṡ, s̈), as
        joint_trajectory_controller does, and interpolates to its first knot one ramp later, so the stroke
        never jumps whatever the simulator holds."""
        start = self.sent_ns
        stop = start + self._window_ns if self.end_ns is None else min(start + self._window_ns, self.end_ns)
        table = waveform_table(self._strokes_through(stop), self.n_actuators)
        ns, values = table_knots(table, start * 1e-9, stop * 1e-9, max_spacing=self._max_spacing)
        room = self._max_points
        if ns.size > room:                   # cut at a message's knots; later windows are made that long
            ns, values = ns[:room], values[:, :room]
            self._window_ns = max(int(ns[-1]) - start, 1)
        self.sent_ns = int(ns[-1])
        self.windows_made += 1
        if self._ramp_from is not None:      # stamped where the ramp starts; its first knot one ramp later
            start, self._ramp_from = self._ramp_from, None
        return self.origin_ns + start, ns - start, values

    def follow(self, now: float, lead: float, *, new_simulator: bool = False) -> tuple[list[Window], str | None]:
        """The windows to send now that sim time is ``now`` (s), keeping ``lead`` (s) of strokes scheduled ahead,
        and why the stream re-phased first (None when it did not). It re-phases (:meth:`rejoin`, ``lead``
        ahead) when sim time went back or the sender saw ``new_simulator`` (a reset, a new simulator: the
        burst continuing) or passed the strokes scheduled (this sender stalled, or lost the simulator: in
        phase with sim time, the missed strokes skipped). Nothing stale is ever sent, and a re-phased stream
        ramps from wherever the simulator's strokes are, so they never jump."""
        why = None
        if new_simulator or (self._last_now is not None and now < self._last_now - TIME_BACK):
            cause = ('a new simulator' if new_simulator else
                     f'sim time went back from {self._last_now:.6f} s to {now:.6f} s (a reset, or a new simulator)')
            at_ns = self.rejoin(now, lead, keep_phase=False)
            why = f'{cause}: restarted at t = {at_ns * 1e-9:.6f} s'
        elif self.sent_ns > 0 and not self.done and self.scheduled_until < now:
            scheduled_until = self.scheduled_until
            at_ns = self.rejoin(now, lead, keep_phase=True)
            why = (f'sim time {now:.6f} s passed the strokes scheduled (until {scheduled_until:.6f} s: the '
                   f'sender stalled or lost the simulator, or stream.lead is short): rejoined at t = '
                   f'{at_ns * 1e-9:.6f} s')
        self._last_now = now
        windows = []
        while not self.done and self.scheduled_until < now + lead:
            windows.append(self.next_window())
        return windows, why

    def refused(self, window: int, now: float, lead: float) -> str | None:
        """The simulator refused this stream's window number ``window`` (1 = the first :meth:`next_window`)
        at sim time ``now`` (s): re-phase ``lead`` ahead, in phase with sim time, as after a stall. The
        windows sent after the refused one continue it and are refused too (docs/interface.md, *Commands*);
        a refusal of a window made before the last re-phase is one of those and changes nothing. Returns why
        it re-phased, or None."""
        if window <= self._rephased_after or self.done:
            return None
        at_ns = self.rejoin(now, lead, keep_phase=True)
        return f'window {window} refused by the simulator at {now:.6f} s: rejoined at t = {at_ns * 1e-9:.6f} s'

    def rejoin(self, now: float, lead: float, *, keep_phase: bool) -> int:
        """At sim time ``now`` (s), start the next window ``lead`` (s) ahead (returned, in ns), ramping
        over one stroke period from the stroke in force there (whatever the simulator holds: the window has no
        knot at its stamp) to the waveform's s, ṡ, s̈:
        after the simulator's strokes ran out or refused a window (``keep_phase``: the waveform stays where
        the schedule puts it in sim time; what was missed is skipped and what was refused is made again from
        there, never replayed late) or after sim time went back (a reset, a new simulator: the burst continues
        from where it was sent, with a new origin)."""
        at_ns = round((now + lead) * 1e9)
        self.rephased_at = now
        ramp_ns = max(round(self.params.period_s * 1e9), RAMP_MIN_NS)
        self._rephased_after = self.windows_made
        if keep_phase:
            self.sent_ns = max(at_ns + ramp_ns - self.origin_ns, 0)
        self.origin_ns = at_ns + ramp_ns - self.sent_ns
        self._ramp_from = self.sent_ns - ramp_ns
        return at_ns

    def _strokes_through(self, stop_ns: int) -> StrokeParams:
        """The burst's parameters with enough strokes to cover burst time ``stop_ns`` (endless: a count
        that grows with time, so a table stays a few strokes long relative to the window)."""
        if self.count:
            return dataclasses.replace(self.params, count=self.count)
        p = self.params
        needed = math.floor((stop_ns * 1e-9 - p.delay) / p.period_s) + 2 + math.ceil(max(p.phases))
        return dataclasses.replace(p, count=max(needed, 1))


def encode_window(window: Window, command_id: str = '') -> bytes:
    """A window (:meth:`StrokeStream.next_window`) as a serialized JointTrajectory stamped at its start,
    named ``command_id``."""
    stamp_ns, offsets_ns, knots = window
    return trajectory_cdr.encode(joint_names(knots.shape[2]), offsets_ns, knots[0], knots[1], knots[2],
                                 stamps.to_time(stamp_ns * 1e-9), command_id)


def encode_stop(n_actuators: int, at: float, command_id: str = '') -> bytes:
    """An empty JointTrajectory stamped at sim time ``at`` (s): hold the strokes from then on (a stream's end)."""
    empty = np.zeros((0, n_actuators))
    return trajectory_cdr.encode(joint_names(n_actuators), np.zeros(0), empty, empty, empty, stamps.to_time(at),
                                 command_id)
