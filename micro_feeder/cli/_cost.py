"""What a command will cost, estimated before it starts, and the refusal of an absurd one.

The estimates are deliberately simple upper-bound-ish figures from the parameters alone (no model is
built): integration steps (and the time series' memory) of an offline run, wall time of a node run. The
actuator streams a long burst in bounded windows, so ``stroke.count`` costs a node run nothing up front.
Beyond a limit the command is refused with the estimate
and the parameter to change; ``--force`` starts it anyway where a user could mean it (a long run), never
for what cannot work (an infinite duration).
"""

from __future__ import annotations

import argparse
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from . import CommandError

# simulate: one CSV row per integration step. Measured (load 3, 2 cores): 300 s of sim time at dt 1e-4 s,
# 3.16e6 rows, in 66 s (5 s integrating, 58 s writing the CSV): ~5e4 steps per wall second.
STEPS_PER_WALL_SECOND = 5e4
BYTES_PER_STEP = 15 * 8       # the time series in memory: 15 columns of float64 per row
MAX_OFFLINE_WALL_S = 600.0    # simulate: refuse an estimate beyond 10 minutes (--force)
MAX_OFFLINE_BYTES = 2e9       # ... or beyond 2 GB of time series (--force)
MAX_NODE_WALL_S = 24 * 3600.0  # run/hil: refuse beyond a day of wall time (--force)


def _value(flat: Mapping[str, Any], name: str) -> Any:
    from ..settings import known_parameters
    return flat.get(name, known_parameters()[name][1])


def _number(flat: Mapping[str, Any], name: str) -> float | None:
    value = _value(flat, name)
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def burst_seconds(flat: Mapping[str, Any]) -> float | None:
    """Sim time [s] the configured burst lasts (delay + strokes + pauses), None when a value is not a number."""
    count, freq = _number(flat, 'stroke.count'), _number(flat, 'stroke.frequency')
    pause, delay = _number(flat, 'stroke.pause'), _number(flat, 'stroke.delay')
    if None in (count, freq, pause, delay) or not freq > 0:
        return None
    return delay + count / freq + max(count - 1, 0) * pause


def _human(seconds: float) -> str:
    if seconds < 120:
        return f'{seconds:.0f} s'
    if seconds < 2 * 3600:
        return f'{seconds / 60:.0f} min'
    if seconds < 3 * 86400:
        return f'{seconds / 3600:.1f} h'
    return f'{seconds / 86400:.3g} days'


def _check_duration(option: str, value: float | None) -> None:
    if value is not None and not math.isfinite(value):
        raise CommandError(f'{option} {value}: an infinite or undefined duration never ends; give a number of '
                           f'seconds (or leave it out: run stops on Ctrl-C)')


def check_cost(args: argparse.Namespace, flat: Mapping[str, Any]) -> None:
    """Refuse a command whose estimated cost is absurd (see the module docstring). Raises CommandError."""
    command = getattr(args, 'command', None)
    force = getattr(args, 'force', False)
    if getattr(args, 'record', None):
        check_new_log_path(args.record)
    duration = getattr(args, 'duration', None)
    _check_duration('--duration', duration)
    _check_duration('--timeout', getattr(args, 'timeout', None))
    if command == 'run':
        wall = None
        if duration is not None:
            rtf = getattr(args, 'real_time_factor', 1.0)
            wall = duration / rtf if rtf and rtf > 0 else None
        if wall is not None and wall > MAX_NODE_WALL_S and not force:
            raise CommandError(f'--duration {duration:g} s at real-time factor {args.real_time_factor:g} would run '
                               f'for about {_human(wall)} of wall time: lower --duration or raise '
                               '--real-time-factor (or add --force if you mean it)')
    elif command == 'simulate':
        _check_offline(flat, duration, force)


def check_new_log_path(path: str) -> None:
    """Refuse, before any node starts, a ``--record`` path a new log cannot be written to."""
    target = Path(path)
    if target.exists() and (target.suffix == '.mcap' or not target.is_dir()):
        raise CommandError(f'--record {path}: {path} exists; give a new name (a log is never overwritten)')
    if target.is_dir() and any(target.iterdir()):
        raise CommandError(f'--record {path}: the directory exists and is not empty; give a new name')
    parent = target.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
        raise CommandError(f'--record {path}: cannot create it: {parent} is not a writable directory')


def _check_offline(flat: Mapping[str, Any], duration: float | None, force: bool) -> None:
    dt, check = _number(flat, 'integration.dt'), _number(flat, 'integration.check_step')
    settle = _number(flat, 'integration.settling_time')
    sim = duration if duration is not None else (
        None if burst_seconds(flat) is None or settle is None else burst_seconds(flat) + settle)
    if sim is None or dt is None or check is None or not min(dt, check) > 0:
        return
    if not math.isfinite(sim):
        raise CommandError(f'the run would last {sim} s of sim time: lower stroke.count, stroke.pause or '
                           'stroke.delay, or give --duration')
    steps = sim / min(dt, check)
    wall, size = steps / STEPS_PER_WALL_SECOND, steps * BYTES_PER_STEP
    if (wall > MAX_OFFLINE_WALL_S or size > MAX_OFFLINE_BYTES) and not force:
        which = '--duration' if duration is not None else 'stroke.count / stroke.pause / stroke.delay (or --duration)'
        raise CommandError(f'{sim:.3g} s of sim time at a step of {min(dt, check):g} s is about {steps:.3g} steps '
                           f'(time series of ~{size / 1e9:.3g} GB, ~{_human(wall)} of computing and writing): lower '
                           f'{which} or raise integration.dt / integration.check_step (or add --force if you mean it)')
