"""The simulator's ``/diagnostics`` status as a side-effect-free function of a snapshot of its state."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

OK, WARN, ERROR = 0, 1, 2       # diagnostic_msgs/DiagnosticStatus levels
LAGGING = 0.95                  # achieved / target real-time factor below which the loop is behind
WEDGED_S = 1.0                  # s: a tick working longer than this is reported as stuck
SILENT_STREAM_S = 0.1           # s of sim time a stream's strokes may have run out before it is reported


@dataclass(frozen=True)
class LoopSnapshot:
    """What the status is computed from. Times in s; ``periods_ms``/``busy_ms`` since the last report."""

    sim_time: float
    mode: str
    paused: bool
    lockstep: bool
    error: str
    rtf_target: float
    achieved_rtf: float
    publish_rate: float
    periods_ms: np.ndarray
    busy_ms: np.ndarray
    overruns: int
    tick_age: float
    steps_granted: int
    states_published: int
    pending_reset: bool
    transitions: Mapping[str, int]
    intake: Mapping[str, str]
    other_simulators: int = 0     # other live simulators of this one's name seen since start
    command_age: float = math.nan  # wall s since the last command arrived (nan: none yet)
    stream_silent: float = 0.0    # sim s since a stream's strokes ran out with no command after them
    refused: Mapping[str, int] = field(default_factory=dict)   # messages the middleware refused, per topic
    refused_new: Mapping[str, int] = field(default_factory=dict)   # of them, per topic, since the last report


@dataclass(frozen=True)
class LoopStatus:
    level: int
    message: str
    values: dict[str, str]


def achieved_rtf(wall: tuple[float, float], sim: tuple[float, float]) -> float:
    """Sim seconds (or any count) per wall second between two readings; 0 over no wall time."""
    return (sim[1] - sim[0]) / (wall[1] - wall[0]) if wall[1] > wall[0] else 0.0


def _pct(a: np.ndarray, q: float) -> str:
    return f'{np.percentile(a, q):.3f}' if a.size else 'nan'


def loop_status(s: LoopSnapshot) -> LoopStatus:
    """Level, message and key/values of the ``simulator: loop`` status (docs/interface.md)."""
    lagging = not s.paused and s.rtf_target > 0 and s.achieved_rtf < LAGGING * s.rtf_target
    wedged = s.tick_age > WEDGED_S
    if s.error:
        level, message = ERROR, s.error
    elif s.other_simulators:
        level, message = ERROR, (f'{s.other_simulators} other simulator(s) of this name run: two feeders in one '
                                 'namespace mix their states and commands; give each its own namespace '
                                 '(-r __ns:=/feeder2)')
    elif wedged:
        level, message = ERROR, (f'one tick has been working for {s.tick_age:.1f} s: the physics cannot advance '
                                 'in bounded time with these parameters (see integration.*)')
    elif s.stream_silent > SILENT_STREAM_S:
        level, message = WARN, (f'command source silent: the streamed strokes ran out {s.stream_silent:.3f} s of '
                                f'sim time ago (last command {s.command_age:.1f} s ago, wall); strokes held')
    elif s.refused_new:
        level, message = WARN, (f'the middleware refused {sum(s.refused_new.values())} message(s) since the last '
                                f'report, on {", ".join(sorted(s.refused_new))}: no subscriber got them (a '
                                'subscriber that stopped and resumed, or a machine out of CPU); the simulation goes on')
    elif lagging:
        level, message = WARN, (f'behind real time ({s.achieved_rtf:.3f} x): the ticks\' work (physics and '
                                f'publishing, tick_compute_p99_ms {_pct(s.busy_ms, 99)}) or a busy CPU')
    else:
        level = OK
        message = 'lockstep' if s.lockstep else 'paused' if s.paused else 'running'
    values = {'sim_time_s': f'{s.sim_time:.9f}', 'mode': s.mode, 'paused': str(s.paused),
              'real_time_factor_target': f'{s.rtf_target:g}', 'real_time_factor_achieved': f'{s.achieved_rtf:.4f}',
              'publish_rate_achieved': f'{s.publish_rate:.1f}',
              'tick_period_p50_ms': _pct(s.periods_ms, 50), 'tick_period_p99_ms': _pct(s.periods_ms, 99),
              'tick_compute_p99_ms': _pct(s.busy_ms, 99), 'overruns': str(s.overruns),
              'tick_in_progress_s': f'{s.tick_age:.3f}',
              'other_simulators': str(s.other_simulators), 'command_age_s': f'{s.command_age:.3f}',
              'stream_silent_s': f'{s.stream_silent:.3f}',
              'lockstep': str(s.lockstep), 'steps_granted': str(s.steps_granted),
              'states_published': str(s.states_published),
              **s.intake, 'model_parameters_pending_reset': str(s.pending_reset),
              'publishes_refused': str(sum(s.refused.values())),
              **{f'publishes_refused.{topic}': str(n) for topic, n in sorted(s.refused.items())}}
    values.update({k: str(v) for k, v in s.transitions.items()})
    return LoopStatus(level, message, values)
