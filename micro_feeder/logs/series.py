"""Time series of the part's motion from a log, on the simulation time axis.

Stamped topics (pose, twist, wrench) are placed at their ``header.stamp`` (sim time); the contact mode
at the exact sim times of ``particle/transitions`` when the log has them, else (``std_msgs/String``, no
stamp) at its receive time mapped onto sim time through the pose messages' (receive time, stamp) pairs.
When the stamps are all zero the receive time is used throughout. Used by
``plot`` and by ``resim`` to compare a re-simulated trajectory with the recorded one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..interface.names import MODES
from .reader import LogReader


@dataclass
class Series:
    """Samples of one topic: ``t`` [s], ``log_t`` receive time [s since log start], named value arrays."""

    t: np.ndarray
    log_t: np.ndarray
    values: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)


def topic_series(log: LogReader, topic: str, fields: dict[str, Callable[[Any], float]]) -> Series:
    """``fields`` extracted from every message of ``topic``; ``t`` = header stamp [s] (0 for an unstamped
    type: the caller maps those onto sim time)."""
    t, log_t, cols = [], [], {name: [] for name in fields}
    for m in log.messages([topic], decoded=True):
        msg = m.message
        t.append((m.stamp_ns or 0) * 1e-9)
        log_t.append((m.log_time_ns - log.start_ns) * 1e-9)
        for name, get in fields.items():
            cols[name].append(get(msg))
    return Series(np.asarray(t, float), np.asarray(log_t, float),
                  {name: np.asarray(v, float) for name, v in cols.items()})


@dataclass
class PartSeries:
    """The part's motion: pose (x, z [m]), twist (vx, vz [m/s]), contact wrench (friction T, normal
    load N [N]) and mode (index into ``MODES``, -1 unknown), all with ``t`` in sim time [s]."""

    pose: Series
    twist: Series
    wrench: Series
    mode: Series
    time_axis: str  # 'sim time' or 'receive time'


def transition_series(log: LogReader, start_mode: int, t0: float) -> Series | None:
    """The mode from ``particle/transitions``: ``start_mode`` (index into ``MODES``) from ``t0`` [s], then each
    change at its exact sim time (the key ``t_s``); None when the log has no transitions topic. Exact where
    the contact-state topic is only placed by its receive time (which drew a slide up to 3.5 ms late)."""
    if log.resolve('particle/transitions') is None:
        return None
    t, log_t, mode = [], [], []
    for m in log.messages(['particle/transitions'], decoded=True):
        for status in m.message.status:
            values = {kv.key: kv.value for kv in status.values}
            if values.get('to') in MODES and 't_s' in values:
                t.append(float(values['t_s']))
                log_t.append((m.log_time_ns - log.start_ns) * 1e-9)
                mode.append(MODES.index(values['to']))
    order = np.argsort(np.asarray(t, float), kind='stable')
    return Series(np.concatenate([[t0], np.asarray(t, float)[order]]),
                  np.concatenate([[0.0], np.asarray(log_t, float)[order]]),
                  {'mode': np.concatenate([[start_mode], np.asarray(mode, float)[order]])})


def part_series(log: LogReader) -> PartSeries:
    """Read the part's motion topics (relative names resolved, so a namespaced log works)."""
    pose = topic_series(log, 'particle/pose', {'x': lambda m: m.pose.position.x, 'z': lambda m: m.pose.position.z})
    twist = topic_series(log, 'particle/twist', {'vx': lambda m: m.twist.linear.x, 'vz': lambda m: m.twist.linear.z})
    wrench = topic_series(log, 'particle/contact_wrench',
                          {'friction': lambda m: m.wrench.force.x, 'normal': lambda m: m.wrench.force.z})
    mode = topic_series(log, 'particle/contact_state',
                        {'mode': lambda m: MODES.index(m.data) if m.data in MODES else -1})
    stamped = [s for s in (pose, twist, wrench) if len(s)]
    if stamped and any(np.any(s.t != 0) for s in stamped):
        first_mode = mode.values['mode'][0] if len(mode) and mode.values['mode'][0] >= 0 else MODES.index('stuck')
        changes = transition_series(log, int(first_mode), float(pose.t[0]) if len(pose) else 0.0)
        if changes is not None:
            mode = changes
        else:
            order = np.argsort(pose.log_t) if len(pose) else None
            if order is not None and len(pose) > 1:
                mode.t = np.interp(mode.log_t, pose.log_t[order], pose.t[order])
        axis = 'sim time'
    else:
        for s in (pose, twist, wrench, mode):
            s.t = s.log_t
        axis = 'receive time'
    return PartSeries(pose, twist, wrench, mode, axis)
