"""The stroke stream: a burst's knots for a trajectory message, whole or in windows that follow sim time.

What the actuator node sends, without ROS: :func:`sample_waveform` gives a whole burst's knots,
:class:`StrokeStream` the successive windows of a streamed one (each stamped at its start in sim time,
taking over at a knot the previous window ends on), :func:`encoded_window` one window as the serialized
JointTrajectory. Knots are placed so that the quintic interpolation the simulator (and
joint_trajectory_controller) runs through them reproduces the schedule within 5e-13 m
(:mod:`micro_feeder.physics.trajectory`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..interface import stamps, trajectory_cdr
from ..interface.names import joint_names
from ..physics.trajectory import burst_end_ns, max_spacing, table_knots, waveform_knots
from ..physics.waveforms import StrokeParams, waveform_table

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

    @property
    def done(self) -> bool:
        return self.end_ns is not None and self.sent_ns >= self.end_ns

    @property
    def scheduled_until(self) -> float:
        """Sim time (s) up to which the strokes are scheduled."""
        return (self.origin_ns + self.sent_ns) * 1e-9

    def next_window(self) -> tuple[int, np.ndarray, np.ndarray]:
        """(stamp in ns of sim time, knot offsets from the stamp in ns, (3, n, actuators) s, ṡ, s̈)."""
        start = self.sent_ns
        stop = start + self._window_ns if self.end_ns is None else min(start + self._window_ns, self.end_ns)
        table = waveform_table(self._strokes_through(stop), self.n_actuators)
        ns, values = table_knots(table, start * 1e-9, stop * 1e-9, max_spacing=self._max_spacing)
        if ns.size > self._max_points:       # cut at a message's knots; later windows are made that long
            ns, values = ns[:self._max_points], values[:, :self._max_points]
            self._window_ns = max(int(ns[-1]) - start, 1)
        self.sent_ns = int(ns[-1])
        return self.origin_ns + start, ns - start, values

    def _strokes_through(self, stop_ns: int) -> StrokeParams:
        """The burst's parameters with enough strokes to cover burst time ``stop_ns`` (endless: a count
        that grows with time, so a table stays a few strokes long relative to the window)."""
        if self.count:
            return dataclasses.replace(self.params, count=self.count)
        p = self.params
        needed = math.floor((stop_ns * 1e-9 - p.delay) / p.period_s) + 2 + math.ceil(max(p.phases))
        return dataclasses.replace(p, count=max(needed, 1))


def encoded_window(stream: StrokeStream) -> bytes:
    """The stream's next window as a serialized JointTrajectory stamped at its start."""
    stamp_ns, offsets_ns, knots = stream.next_window()
    return trajectory_cdr.encode(joint_names(stream.n_actuators), offsets_ns, knots[0], knots[1], knots[2],
                                 stamps.to_time(stamp_ns * 1e-9))
