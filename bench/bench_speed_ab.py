"""Benchmark: offline speed of this tree against an earlier commit, interleaved on the same machine.

Usage: .venv/bin/python bench/bench_speed_ab.py [--against REV] [--rounds N] [--json PATH | --no-json]

On a shared machine the speed of one process moves by 10-20 % from minute to minute, more than most kernel
changes: a change is judged by running it next to the code before it. This checks out ``REV`` (default
5fa1492, the code before the event-location guarantee of issue 9) into a temporary git worktree with its own
numba cache, compiles both once (a few minutes for ``REV`` on first use), then runs rounds that each time the
default scenario, 1000 strokes back to back (1 s of sim time), in a fresh process of each tree: best of 3 runs,
CPU time of the integrating thread. It prints every round's figures (x real time) and ratio, then the ranges,
the medians and the ratio of the medians. Target (issue 9): this tree at or above 215x; no slower than
``REV``. Results: bench/results/bench_speed_ab.json.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import results_json
from results_json import figure

ROOT = Path(__file__).resolve().parent.parent
SPEED_TARGET = 215.0
# Runs in each tree's own process: the FeederModel API it uses exists since before issue 9.
MEASURE = """
import sys, time
from micro_feeder.physics.dynamics import FeederModel
model = FeederModel()
busy = model.replace(stroke=model.stroke.replace(count=1000))
best = 0.0
for _ in range(int(sys.argv[1])):
    state = busy.initial_state()
    busy.advance(state, 1e-3)
    start = time.thread_time()
    busy.advance(state, 1.0)
    best = max(best, (1.0 - 1e-3) / (time.thread_time() - start))
print(best)
"""


def speed(tree: Path, env: dict[str, str], runs: int) -> float:
    """Best of ``runs`` (x real time) in a fresh process importing the package from ``tree``."""
    done = subprocess.run([sys.executable, '-c', MEASURE, str(runs)], cwd=tree, env=env, check=True,
                          capture_output=True, text=True)
    return float(done.stdout.split()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--against', default='5fa1492', help='the commit to compare with (default 5fa1492)')
    parser.add_argument('--rounds', type=int, default=6, help='interleaved rounds (default 6)')
    parser.add_argument('--runs', type=int, default=3, help='runs per process, the best kept (default 3)')
    results_json.add_arguments(parser, 'bench_speed_ab')
    args = parser.parse_args()
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix='speed_ab_') as scratch:
        other = Path(scratch) / 'tree'
        added = subprocess.run(['git', 'worktree', 'add', '--detach', str(other), args.against], cwd=ROOT,
                               capture_output=True, text=True)
        if added.returncode != 0:
            sys.exit(f'cannot check out {args.against} beside {ROOT} (this needs a git clone that has it): '
                     f'{added.stderr.strip()}')
        try:
            trees = {'this tree': (ROOT, dict(os.environ)),
                     args.against: (other, dict(os.environ, PYTHONPATH=str(other),
                                                NUMBA_CACHE_DIR=str(Path(scratch) / 'numba_cache')))}
            print(f'compiling {args.against} in {other} (a few minutes, once)...', flush=True)
            for tree, env in trees.values():
                speed(tree, env, 1)
            figures: dict[str, list[float]] = {name: [] for name in trees}
            for index in range(args.rounds):
                for name, (tree, env) in reversed(trees.items()):
                    figures[name].append(speed(tree, env, args.runs))
                new, old = figures['this tree'][-1], figures[args.against][-1]
                print(f'round {index + 1}: this tree {new:6.1f}x, {args.against} {old:6.1f}x, ratio {new / old:.3f}',
                      flush=True)
        finally:
            subprocess.run(['git', 'worktree', 'remove', '--force', str(other)], cwd=ROOT, check=False)
    medians = {name: statistics.median(values) for name, values in figures.items()}
    for name, values in figures.items():
        print(f'{name}: {min(values):.1f}-{max(values):.1f}x, median {medians[name]:.1f}x')
    ratio = medians['this tree'] / medians[args.against]
    print(f'ratio of the medians {ratio:.3f} (target: this tree >= {SPEED_TARGET:.0f}x: '
          f'{"met" if medians["this tree"] >= SPEED_TARGET else "NOT met"} on the median; no slower than '
          f'{args.against}: {"met" if ratio >= 1.0 else "NOT met"})')
    new, old = figures['this tree'], figures[args.against]
    results_json.save(args, 'bench_speed_ab', f'Offline speed against {args.against}', [
        figure('median_x', f'this tree, median of {args.rounds} rounds', round(medians['this tree'], 1), 'x real time',
               op='>=', target=SPEED_TARGET, note=f'rounds {min(new):.1f}-{max(new):.1f}x'),
        figure('against_median_x', f'{args.against}, median of {args.rounds} rounds', round(medians[args.against], 1),
               'x real time', note=f'rounds {min(old):.1f}-{max(old):.1f}x'),
        figure('ratio_of_medians', f'this tree against {args.against}, ratio of the medians', round(ratio, 3), '',
               op='>=', target=1.0,
               note='per round: ' + ', '.join(f'{a / b:.3f}' for a, b in zip(new, old, strict=True))),
    ], load_before=load, seconds=time.perf_counter() - started,
        purpose='The default scenario\'s offline speed, this tree and an earlier commit interleaved in fresh '
                'processes on the same machine (issue 9).')


if __name__ == '__main__':
    main()
