"""Benchmark: offline cost of many parts on one feeder against each part alone (issue 28, docs/parts.md).

Usage: .venv/bin/python bench/bench_parts.py [--rounds N] [--strokes N] [--json PATH | --no-json]

A travelling wave as config/travelling_wave.yaml makes it (actuators 0.5 mm apart, 0.4 mm wide, phases 0,
0.2, ... 0.8 repeating, raised-cosine strokes of 150 µm at 1 kHz), long enough for 64 parts, which start
1 mm apart (dilute: over the strokes timed they move at most a few hundred µm, and never meet; the
benchmark reports the impacts it saw). Times (CPU time of this thread, best of each round's runs, rounds
interleaved) the parts model with 1, 16 and 64 parts, and the same parts each run alone with
``FeederModel.advance``; reports the cost per part-stroke, its ratios to one part, and the target: 64 dilute
parts within 1.5x of the 64 parts run alone. Results: bench/results/bench_parts.json.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import results_json
from results_json import figure

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.parts import PartsModel

SPACING = 1e-3                  # m between the parts' starts
PITCH, WIDTH = 0.5e-3, 0.4e-3   # m: actuator spacing and width (config/travelling_wave.yaml)
FIRST = 1.0e-3                  # m: the first part's start
COUNTS = (1, 16, 64)


def wave(n_parts: int, strokes: int) -> dict:
    """The travelling wave under ``n_parts`` parts, ``SPACING`` apart from ``FIRST``."""
    n_actuators = round((FIRST + (max(COUNTS) + 1) * SPACING) / PITCH) + 1
    return {'surface.centers': [k * PITCH for k in range(n_actuators)], 'surface.widths': [WIDTH] * n_actuators,
            'stroke.phases': [0.2 * (k % 5) for k in range(n_actuators)], 'stroke.amplitude': 150e-6,
            'stroke.frequency': 1000.0, 'stroke.count': strokes,
            'particle.x0': [FIRST + k * SPACING for k in range(n_parts)]}


def time_parts(parts: PartsModel, t_end: float) -> tuple[float, int]:
    """CPU seconds to advance the parts to ``t_end``, and the impacts seen."""
    state = parts.initial_state()
    parts.advance(state, 1e-6)                    # compiled and warm
    start = time.thread_time()
    parts.advance(state, t_end)
    return time.thread_time() - start, state.collisions


def time_alone(model: FeederModel, starts: list[float], t_end: float) -> float:
    """CPU seconds to advance each part alone to ``t_end``, summed."""
    total = 0.0
    for x0 in starts:
        state = model.initial_state(x0)
        model.advance(state, 1e-6)
        start = time.thread_time()
        model.advance(state, t_end)
        total += time.thread_time() - start
    return total


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--rounds', type=int, default=5, help='interleaved rounds (default 5)')
    parser.add_argument('--runs', type=int, default=3, help='runs per case per round, the best kept (default 3)')
    parser.add_argument('--strokes', type=int, default=20, help='strokes timed (default 20, 1 ms each)')
    results_json.add_arguments(parser, 'bench_parts')
    args = parser.parse_args()
    load, started = [round(x, 2) for x in os.getloadavg()], time.perf_counter()
    t_end = args.strokes / 1000.0
    models = {n: PartsModel.from_settings(wave(n, args.strokes)) for n in COUNTS}
    alone = models[max(COUNTS)].model
    starts = list(alone.particle.start_positions)
    per_part_stroke: dict[str, list[float]] = {**{f'parts_{n}': [] for n in COUNTS}, 'alone_64': []}
    impacts: dict[int, int] = {}
    for k in range(args.rounds):
        cases = [*COUNTS, 'alone']
        for case in (cases if k % 2 == 0 else reversed(cases)):
            if case == 'alone':
                best = min(time_alone(alone, starts, t_end) for _ in range(args.runs))
                per_part_stroke['alone_64'].append(best / (len(starts) * args.strokes))
                continue
            runs = [time_parts(models[case], t_end) for _ in range(args.runs)]
            impacts[case] = runs[0][1]
            per_part_stroke[f'parts_{case}'].append(min(r[0] for r in runs) / (case * args.strokes))
        print(f'round {k + 1}: ' + ', '.join(f'{name} {values[-1] * 1e6:.2f} us' for name, values in
                                             per_part_stroke.items()), flush=True)
    medians = {name: statistics.median(values) for name, values in per_part_stroke.items()}
    one = medians['parts_1']
    ratio_64_alone = medians['parts_64'] / medians['alone_64']
    print('median cost per part-stroke: ' + ', '.join(f'{n} {v * 1e6:.2f} us' for n, v in medians.items()))
    print(f'ratios to one part: 16 parts {medians["parts_16"] / one:.2f}, 64 parts {medians["parts_64"] / one:.2f}; '
          f'64 parts against the 64 run alone {ratio_64_alone:.2f} (target <= 1.5); impacts {impacts}')
    figures = [
        *(figure(f'parts_{n}_us', f'{n} part(s) on the travelling wave: CPU per part-stroke',
                 round(medians[f'parts_{n}'] * 1e6, 2), 'us', note=f'{impacts[n]} impacts') for n in COUNTS),
        figure('alone_64_us', 'the same 64 parts each run alone (FeederModel.advance): CPU per part-stroke',
               round(medians['alone_64'] * 1e6, 2), 'us'),
        figure('parts_16_vs_1', '16 parts against 1, per part-stroke', round(medians['parts_16'] / one, 2), ''),
        figure('parts_64_vs_1', '64 parts against 1, per part-stroke', round(medians['parts_64'] / one, 2), ''),
        figure('parts_64_vs_alone', '64 dilute parts against the 64 run alone (total time)', round(ratio_64_alone, 2),
               '', op='<=', target=1.5),
    ]
    results_json.save(args, 'bench_parts', 'Many parts on one feeder against each part alone (offline)', figures,
                      load_before=load, seconds=time.perf_counter() - started,
                      purpose='offline cost per part-stroke of 1, 16 and 64 dilute parts on a travelling wave, and '
                              'the overhead of the parts model over running each part alone',
                      notes=['parts start 1 mm apart; one part alone costs differently at different places on '
                             'the wave, so the 64-part figure is compared with the same 64 parts alone'])


if __name__ == '__main__':
    main()
