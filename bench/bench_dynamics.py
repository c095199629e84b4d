"""Benchmark: offline speed of the particle dynamics and of a frequency sweep (issue 3).

Usage: .venv/bin/python bench/bench_dynamics.py [--skip-compile] [--json PATH | --no-json]

1. Speed (x real time) on the default scenario (config/feeder.yaml) with strokes back to back for 1 s
   of sim time (1000 strokes at 1 kHz; the part slides in every one of them), on one core; best of 3
   (CPU time of the thread that integrates, so other load on the machine, and the OpenBLAS threads
   that spin for ~0.1 s after the contact tables are built, count less).
   Target >= 215x (the speed before the event-location guarantee), goal 1000x.
2. A 200-frequency x 5-stroke sweep (100..5000 Hz) on 2 worker processes, wall time. Target <= 5 s.
3. Accuracy of the default step: distance per stroke with the default integration settings against
   the dt -> 0 limit (tight tolerance, 1 us largest step) on the benchmark cases. Target <= 0.1 %.
4. Far actuators (issue 10): bench/bench_cutoff.py's travelling wave on 1, 16 and 64 actuators (target:
   64 within 2x of 1 actuator).
5. First-call compile time of the kernel in a fresh process with an empty numba cache (what a new
   installation pays once; later processes load the cache).

Results: bench/results/bench_dynamics.json (1-3, 5) and bench/results/bench_cutoff.json (4).
"""

import argparse
import os
import subprocess
import sys
import tempfile
import time

import bench_cutoff
import results_json
from results_json import figure

from micro_feeder.explore.sweep import sweep
from micro_feeder.physics.dynamics import FeederModel

# speed: no slower than before the event-location guarantee (215-240x then)
SPEED_TARGET, SPEED_GOAL, SWEEP_TARGET_S, ACCURACY_TARGET = 215.0, 1000.0, 5.0, 1e-3
CASES = [('default: 1 kHz, 100 um (stick-slide-stick)', {}),
         ('1 kHz, 200 um', {'amplitude': 200e-6}),
         ('2 kHz, 100 um (take-off)', {'frequency': 2000.0}),
         ('3 kHz, 100 um (take-off)', {'frequency': 3000.0})]


def speed(model: FeederModel) -> list[dict]:
    """Best of 3 (x real time), with the default event search and, for its cost, with tests at step ends
    only (integration.event_search step_ends), interleaved so that both see the same load."""
    busy = model.replace(stroke=model.stroke.replace(count=1000))
    ends_only = busy.replace(integration=busy.integration.replace(event_search='step_ends'))
    best = {'dips': 0.0, 'step_ends': 0.0}
    for _ in range(3):
        for name, variant in (('dips', busy), ('step_ends', ends_only)):
            state = variant.initial_state()
            variant.advance(state, 1e-3)
            start = time.thread_time()
            variant.advance(state, 1.0)
            best[name] = max(best[name], (1.0 - 1e-3) / (time.thread_time() - start))
            if name == 'dips':
                slips = state.transitions['stick_to_slip']
    print(f'offline speed, default scenario, 1000 strokes back to back ({slips} slides): {best["dips"]:.0f}x real '
          f'time on one core (target >= {SPEED_TARGET:.0f}x, goal {SPEED_GOAL:.0f}x)')
    print(f'  cost of finding dips inside steps: {best["step_ends"]:.0f}x with tests at step ends only, '
          f'{best["step_ends"] / best["dips"]:.2f}x slower with the guarantee')
    return [figure('speed_x', 'offline dynamics, default scenario, 1000 strokes back to back, one core',
                   round(best['dips']), 'x real time', op='>=', target=SPEED_TARGET,
                   note=f'goal {SPEED_GOAL:.0f}x; the target is the speed before the event-location guarantee'),
            figure('speed_step_ends_x', 'same, testing margins at step ends only (integration.event_search '
                   'step_ends)', round(best['step_ends']), 'x real time'),
            figure('guarantee_cost', 'cost of the event-location guarantee: times slower',
                   round(best['step_ends'] / best['dips'], 2), 'x')]


def sweep_time() -> list[dict]:
    values = [100.0 + i * (5000.0 - 100.0) / 199 for i in range(200)]
    start = time.perf_counter()
    rows = sweep({'stroke.count': 5}, 'stroke.frequency', values, processes=2)
    wall = time.perf_counter() - start
    flights = sum(r['take_off'] > 0 for r in rows)
    print(f'sweep, 200 frequencies x 5 strokes on 2 processes: {wall:.2f} s wall ({flights} runs with a '
          f'take-off; target <= {SWEEP_TARGET_S:.0f} s)')
    return [figure('sweep_s', 'sweep, 200 frequencies x 5 strokes, 2 processes, wall time', round(wall, 2), 's',
                   op='<=', target=SWEEP_TARGET_S)]


def accuracy(model: FeederModel) -> list[dict]:
    print(f'default step (method {model.integration.method}, dt {model.integration.dt:g} s, tolerance '
          f'{model.integration.tolerance:g} m, check_step {model.integration.check_step:g} s) against dt -> 0:')
    errors = []
    for label, stroke in CASES:
        m = model.replace(stroke=model.stroke.replace(**stroke))
        limit = m.replace(integration=m.integration.replace(dt=1e-6, tolerance=1e-14, check_step=1e-6))
        got, ref = (run.run().state.distance for run in (m, limit))
        errors.append(abs(got / ref - 1))
        print(f'  {label:<45} {got * 1e6:>10.5f} um vs {ref * 1e6:>10.5f} um: '
              f'{abs(got / ref - 1):.1e} (target <= {ACCURACY_TARGET:.0e})')
    return [figure('accuracy_max', f'distance per stroke, default step against dt -> 0, worst of {len(CASES)} '
                   'cases (relative)', float(f'{max(errors):.2g}'), '', op='<=', target=ACCURACY_TARGET,
                   shown=f'{max(errors):.1e}',
                   note='cases: ' + '; '.join(f'{label} {e:.1e}' for (label, _), e in zip(CASES, errors, strict=True)))]


def compile_time() -> list[dict]:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        code = 'from micro_feeder.physics.dynamics import FeederModel; FeederModel().run()'
        start = time.perf_counter()
        subprocess.run([sys.executable, '-c', code], env=env, check=True)
        cold = time.perf_counter() - start
        start = time.perf_counter()
        subprocess.run([sys.executable, '-c', code], env=env, check=True)
        warm = time.perf_counter() - start
    print(f'first run in a fresh process: {cold:.1f} s with an empty numba cache (compile), '
          f'{warm:.1f} s with the cache (import + load + run)')
    return [figure('compile_s', 'first run in a fresh process, empty numba cache (the one-off compile)',
                   round(cold), 's'),
            figure('cached_start_s', 'first run in a fresh process with the cache (import, load, run)',
                   round(warm, 1), 's')]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--skip-compile', action='store_true',
                        help='skip the fresh-process compile measurement (about 4 minutes on 2 cores)')
    results_json.add_arguments(parser, 'bench_dynamics')
    args = parser.parse_args()
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    model = FeederModel()
    model.run()
    figures = speed(model) + sweep_time() + accuracy(model)
    seconds = time.perf_counter() - started
    cutoff_args = argparse.Namespace(json=args.json.parent / 'bench_cutoff.json', no_json=args.no_json)
    bench_cutoff.main(cutoff_args, command='.venv/bin/python bench/bench_cutoff.py',
                      notes=('Measured as part of bench/bench_dynamics.py.',))
    notes = []
    if args.skip_compile:
        notes.append('The compile time was not measured in this run (--skip-compile).')
    else:
        started = time.perf_counter()
        figures += compile_time()
        seconds += time.perf_counter() - started
    results_json.save(args, 'bench_dynamics', 'Offline dynamics: speed, sweep, accuracy', figures, notes=notes,
                      load_before=load, seconds=seconds,
                      purpose='Offline speed of the particle dynamics (CPU time of the integrating thread, best '
                              'of 3), a frequency sweep on 2 processes (wall time), and the default step\'s '
                              'accuracy (issue 3).')


if __name__ == '__main__':
    main()
