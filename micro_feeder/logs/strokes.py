"""The actuator strokes a log commanded, rebuilt from its recorded commands (no rclpy).

A 1 kHz ``actuator/joint_states`` samples a 1 kHz stroke once per period: plotted, it is an alias. The
commands say exactly what the simulator was told: each ``actuator/trajectory`` (its knots, interpolated as
the simulator does, quintic/cubic/linear Hermite, :func:`~micro_feeder.physics.waveforms.trajectory_table`)
and each ``actuator/command`` set-point, applied from the sim time the simulator received it
(``simulator/command_receipts``; the i-th receipt naming a topic belongs to the i-th message on it) or
from its stamp when that is later (joint_trajectory_controller semantics, as ``sim.stepper``). Without
receipts the receive time is mapped onto sim time through the poses. These are commanded strokes: a
command the simulator refused would still be drawn, and with ``piezo.*`` dynamics on the actual stroke
lags the command.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..interface.names import split_receipt_frame
from ..interface.stamps import stamp_ns
from ..interface.topics import COMMAND_TOPICS
from ..physics.waveforms import StrokeSchedule, trajectory_table
from .reader import LogReader


@dataclass
class CommandedStrokes:
    """The schedule of commanded strokes, and the sim-time span [s] over which each command moved them."""

    schedule: StrokeSchedule
    n_actuators: int
    active: list[tuple[float, float]] = field(default_factory=list)

    def at(self, t: np.ndarray) -> np.ndarray:
        """Strokes (len(t), n_actuators) in m at sim times ``t`` (s)."""
        return np.array([self.schedule.evaluate(float(ti))[0] for ti in np.atleast_1d(t)]).reshape(-1, self.n_actuators)


def commanded_strokes(log: LogReader, n_actuators: int, pose_log_t: np.ndarray, pose_t: np.ndarray
                      ) -> CommandedStrokes | None:
    """The strokes the log's commands describe, or None when it recorded no command. ``pose_log_t`` /
    ``pose_t``: receive times [s since log start] and stamps [s] of the poses, for logs without receipts."""
    topics = [t for t in COMMAND_TOPICS if log.command_source(t) is not None]
    if not topics:
        return None
    receipts: dict[str, list[float]] = defaultdict(list)
    if log.resolve('simulator/command_receipts') is not None:
        for m in log.messages(['simulator/command_receipts']):
            receipts[split_receipt_frame(m.message.frame_id)[0]].append(stamp_ns(m.message.stamp) * 1e-9)
    commands = []
    for topic in topics:
        for i, m in enumerate(log.messages([log.command_source(topic)])):
            if i < len(receipts[topic]):
                received = receipts[topic][i]
            elif len(pose_t):
                received = float(np.interp((m.log_time_ns - log.start_ns) * 1e-9, pose_log_t, pose_t))
            else:
                continue
            commands.append((received, topic, m.message))
    if not commands:
        return None
    strokes = CommandedStrokes(StrokeSchedule(trajectory_table([0.0], np.zeros((1, n_actuators))), -np.inf),
                               n_actuators)
    for received, topic, msg in sorted(commands, key=lambda c: c[0]):
        _apply(strokes, received, topic, msg)
    return strokes


def _apply(strokes: CommandedStrokes, received: float, topic: str, msg: Any) -> None:
    n = strokes.n_actuators
    if topic == 'actuator/command':
        values = np.asarray(msg.data, dtype=float)
        if values.size == n:
            strokes.schedule.replace_from(received, trajectory_table([received], values[None, :]))
            strokes.active.append((received, received))
        return
    stamp = stamp_ns(msg.header.stamp) * 1e-9
    start = stamp if stamp > received else received
    if not msg.points:
        strokes.schedule.hold_from(start)
        return
    order = [int(name.rsplit('_', 1)[-1]) for name in msg.joint_names]
    if sorted(order) != list(range(n)):
        return                      # not this simulator's joints: the simulator refused it
    points = msg.points

    def columns(field_name: str) -> np.ndarray | None:
        rows = [list(getattr(p, field_name)) for p in points]
        if any(len(r) != n for r in rows):
            return None
        values = np.zeros((len(rows), n))
        values[:, order] = np.asarray(rows, dtype=float)
        return values

    base = start if stamp == 0.0 else stamp
    knots = base + np.array([stamp_ns(p.time_from_start) * 1e-9 for p in points])
    strokes.schedule.command_trajectory(start, knots, columns('positions'), columns('velocities'),
                                        columns('accelerations'))
    strokes.active.append((start, float(knots[-1])))
