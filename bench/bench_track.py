"""Benchmark: offline speed of a vibratory-track run against the bump surface, interleaved in one process.

Usage: .venv/bin/python bench/bench_track.py [--rounds N] [--json PATH | --no-json]

Two scenarios, each 1 s of sim time from rest, timed in alternation (CPU time of this thread, best of each
round's runs), so that the machine's drift hits both alike:

* **bumps**: the default model (one actuator, raised-cosine strokes of 100 µm at 1 kHz, the rough-surface
  contact), 1000 strokes back to back: one slip and one stick per stroke;
* **track**: a horizontal track vibrating at β = 30° with a 100 Hz sine of Γ = 1.5, Coulomb friction
  μ = 0.5, Coulomb landings: 100 hops, each a take-off, a landing and slips: the part is never at rest, so
  every step is integrated, at most ``integration.dt`` (default 0.1 ms) long;
* **track, dt 1 ms**: the same with ``integration.dt`` 1 ms, which a 100 Hz drive allows (the mean velocity
  agrees with the default's to ~1e-7 relative).

Reports each one's speed (x real time) and the ratios to the bump surface. The bump part is stuck for most of
each stroke (it costs next to nothing then), the track part never: the default-step ratio is reported, the
target is on the 1 ms one (>= 1: a track, with no surface to sum, no slower than the bumps once its step
suits its drive). Results: bench/results/bench_track.json.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

import results_json
from results_json import figure

from micro_feeder.physics.dynamics import FeederModel

SIM_SECONDS = 1.0
G, FREQUENCY, BETA, GAMMA = 9.81, 100.0, math.pi / 6, 1.5


def scenarios() -> dict[str, FeederModel]:
    bumps = FeederModel.from_settings({'stroke.count': 1000})
    amplitude = GAMMA * G / ((2 * math.pi * FREQUENCY) ** 2 * math.sin(BETA))
    track = FeederModel.from_settings({
        'surface.kind': 'track', 'track.vibration_angle': BETA, 'contact.model': 'coulomb', 'contact.mu': 0.5,
        'landing.law': 'coulomb', 'stroke.waveform': 'sine', 'stroke.frequency': FREQUENCY,
        'stroke.amplitude': amplitude, 'stroke.count': round(SIM_SECONDS * FREQUENCY)})
    return {'bumps': bumps, 'track': track, 'track_dt1ms': track.replace(
        integration=track.integration.replace(dt=1e-3))}


def speed(model: FeederModel, runs: int) -> tuple[float, dict[str, int]]:
    """Best of ``runs`` (x real time) over 1 s of sim time from rest, and the run's transition counts."""
    best, counts = 0.0, {}
    for _ in range(runs):
        state = model.initial_state()
        model.advance(state, 1e-3)                 # compiled and warm
        start = time.thread_time()
        model.advance(state, SIM_SECONDS)
        best = max(best, (SIM_SECONDS - 1e-3) / (time.thread_time() - start))
        counts = state.transitions
    return best, counts


def _range(values: list[float]) -> str:
    return f'range {min(values):.0f}-{max(values):.0f}x over the rounds'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--rounds', type=int, default=6, help='interleaved rounds (default 6)')
    parser.add_argument('--runs', type=int, default=3,
                        help='runs per scenario per round, the best kept (default 3)')
    results_json.add_arguments(parser, 'bench_track')
    args = parser.parse_args()
    load, started = [round(x, 2) for x in os.getloadavg()], time.perf_counter()
    models = scenarios()
    figures_of: dict[str, list[float]] = {name: [] for name in models}
    counts: dict[str, dict[str, int]] = {}
    for k in range(args.rounds):
        for name, model in (models.items() if k % 2 == 0 else reversed(models.items())):
            x, counts[name] = speed(model, args.runs)
            figures_of[name].append(x)
        print(f'round {k + 1}: ' + ', '.join(f'{name} {values[-1]:.0f}x' for name, values in figures_of.items()),
              flush=True)
    medians = {name: statistics.median(values) for name, values in figures_of.items()}
    ratio, ratio_1ms = medians['track'] / medians['bumps'], medians['track_dt1ms'] / medians['bumps']
    print(f'median: bumps {medians["bumps"]:.0f}x ({counts["bumps"]}), track {medians["track"]:.0f}x '
          f'({counts["track"]}), track at dt 1 ms {medians["track_dt1ms"]:.0f}x; track / bumps {ratio:.2f}, '
          f'at dt 1 ms {ratio_1ms:.2f} (target >= 1)')
    figures = [
        figure('bumps_speed_x', 'bump surface, 1000 raised-cosine strokes at 1 kHz: x real time',
               round(medians['bumps']), 'x', note=_range(figures_of['bumps'])),
        figure('track_speed_x', 'track, 100 hops at Γ = 1.5 (sine 100 Hz, Coulomb): x real time',
               round(medians['track']), 'x', note=_range(figures_of['track'])),
        figure('track_dt1ms_speed_x', 'the same track with integration.dt 1 ms: x real time',
               round(medians['track_dt1ms']), 'x', note=_range(figures_of['track_dt1ms'])),
        figure('track_vs_bumps', 'track / bump surface at the default step, ratio of the medians', round(ratio, 2),
               '', note='the bump part is stuck most of each stroke, the track part never'),
        figure('track_dt1ms_vs_bumps', 'track at dt 1 ms / bump surface, ratio of the medians (interleaved)',
               round(ratio_1ms, 2), '', op='>=', target=1.0),
    ]
    results_json.save(args, 'bench_track', 'Vibratory track against the bump surface (offline)', figures,
                      load_before=load, seconds=time.perf_counter() - started,
                      purpose='offline speed of a vibratory-track run against the bump surface, 1 s of sim time '
                              'each, interleaved in one process')


if __name__ == '__main__':
    main()
