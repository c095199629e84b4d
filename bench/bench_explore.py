"""Benchmark: maps, Dask scale-out and calibration (issue 13).

Usage: .venv/bin/python bench/bench_explore.py [--size N] [--json PATH | --no-json]

1. A frequency × amplitude map (N × N points, 100–3000 Hz × 20–200 µm, default N = 100) of 5-stroke
   runs on 2 local worker processes, wall time. Target: 100 × 100 in ≤ 60 s on the 2-core machine.
   (The README's map is the same sweep through ``micro-feeder sweep ... --plot``.)
2. The same map on 1 local process (speed-up 1 → 2 workers) and on a Dask cluster of 2 single-threaded
   workers started here on 127.0.0.1 (local processes → Dask); the tables must be identical.
3. A calibration's wall time: a 20-stroke run recorded by ``micro-feeder run --duration 0.5`` (real time),
   two parameters (contact.friction_scale, particle.x0) fitted from starts 10 % off, 2 local processes.

Results: bench/results/bench_explore.json.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import results_json
from results_json import figure

from micro_feeder.explore.calibrate import calibrate
from micro_feeder.explore.cluster import local_cluster
from micro_feeder.explore.designs import Axis, Grid, RunPlan
from micro_feeder.explore.evaluate import Job, evaluate
from micro_feeder.explore.runners import DaskCluster, InProcess, LocalProcesses, Runner
from micro_feeder.explore.sweep import run_plan

MAP_TARGET_S = 60.0
BIN = Path(sys.executable).parent


def time_map(plan: RunPlan, job: Job, runner: Runner) -> tuple[float, float, list[dict]]:
    """Wall time and this process's CPU time of the plan (after a warm-up that starts every worker), and
    its rows."""
    warm_up = RunPlan(Grid([Axis('stroke.frequency', 500.0, 1500.0, 16 * runner.workers)]))
    with runner:
        list(run_plan(job, warm_up, runner))
        started, cpu = time.perf_counter(), time.process_time()
        rows = list(run_plan(job, plan, runner))
        return time.perf_counter() - started, time.process_time() - cpu, rows


def calibration_time(folder: Path) -> list[dict]:
    log = folder / 'run'
    env = {**os.environ, 'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST', 'ROS_LOG_DIR': str(folder / 'ros')}
    subprocess.run([str(BIN / 'micro-feeder'), 'run', '--duration', '0.5',
                    '--set', 'stroke.count=20', '--set', 'stroke.amplitude=90e-6', '--record', str(log)],
                   check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    start = {'contact.friction_scale': 0.010814 * 1.1, 'particle.x0': 0.5e-3 * 0.9}
    started = time.perf_counter()
    with LocalProcesses(2) as runner:
        result = calibrate([str(log)], start, runner)
    wall = time.perf_counter() - started
    values = ', '.join(f'{p.name} {p.value:.6g} (true {v:.6g})' for p, v in
                       zip(result.parameters, (0.010814, 0.5e-3), strict=True))
    print(f'calibration, 2 parameters, {result.residual_count} residuals ({result.residual_count // 2} poses): '
          f'{wall:.1f} s wall, {result.evaluations} evaluations, rms {result.rms:.2e} m, converged '
          f'{result.converged}; {values}')
    errors = [abs(p.value / v - 1) for p, v in zip(result.parameters, (0.010814, 0.5e-3), strict=True)]
    return [figure('calibration_s', f'calibration, 2 parameters, {result.residual_count // 2}-pose log, 2 processes, '
                   'wall time', round(wall, 1), 's',
                   note=f'{result.evaluations} evaluations, converged {result.converged}, largest relative error of '
                        f'the fitted parameters {max(errors):.1e}; {values}')]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--size', type=int, default=100, help='points per axis of the map (default 100)')
    results_json.add_arguments(parser, 'bench_explore')
    args = parser.parse_args()
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    n = args.size
    plan = RunPlan(Grid([Axis('stroke.frequency', 100.0, 3000.0, n), Axis('stroke.amplitude', 20e-6, 200e-6, n)]))
    job = Job({'stroke.count': 5})
    print(f'load: {os.getloadavg()[0]:.2f} (1-min average, 2 cores)')
    evaluate(job, {})          # kernel and base model loaded here, inherited by the forked workers
    wall2, _, rows = time_map(plan, job, LocalProcesses(2))
    flights = sum(r['regime'] == 'flies' for r in rows)
    print(f'map {n} x {n} (frequency x amplitude, 5 strokes), 2 local processes: {wall2:.2f} s wall '
          f'({len(rows) / wall2:.0f} runs/s; {flights} runs with a take-off; target for 100 x 100: '
          f'<= {MAP_TARGET_S:.0f} s)')
    figures = [figure('map_s', f'frequency x amplitude map, {n} x {n} x 5 strokes, 2 processes, wall time',
                      round(wall2, 1), 's', op='<=', target=MAP_TARGET_S if n == 100 else None)]
    wall1, cpu1, rows1 = time_map(plan, job, InProcess())
    print(f'same map, 1 process: {wall1:.2f} s wall ({cpu1:.2f} s CPU: the share of a core it got); '
          f'speed-up 1 -> 2 local workers: {wall1 / wall2:.2f}x')
    figures.append(figure('map_1_process_s', 'same map, 1 process, wall time', round(wall1, 1), 's',
                          note=f'{cpu1:.1f} s CPU; speed-up 1 -> 2 local workers {wall1 / wall2:.2f}x'))
    assert repr(rows1) == repr(rows), 'the 1-process table differs'     # repr: NaN equals NaN
    with tempfile.TemporaryDirectory() as folder:
        with local_cluster(Path(folder), workers=2) as cluster:
            wall_dask, _, rows_dask = time_map(plan, job, DaskCluster(cluster.address))
        assert repr(rows_dask) == repr(rows), 'the Dask table differs from the local one'
        print(f'same map, Dask cluster of 2 workers on this machine: {wall_dask:.2f} s wall; local 2 processes '
              f'-> Dask 2 workers: {wall2 / wall_dask:.2f}x (identical table)')
        figures.append(figure('map_dask_s', 'same map, Dask cluster of 2 workers on this machine, wall time',
                              round(wall_dask, 1), 's', note='the table is identical to the local one'))
        figures += calibration_time(Path(folder))
    results_json.save(args, 'bench_explore', 'Maps, Dask, calibration', figures, load_before=load,
                      seconds=time.perf_counter() - started,
                      purpose='A frequency x amplitude map on local processes and on a Dask cluster, and a '
                              'calibration\'s wall time (issue 13).')

if __name__ == '__main__':
    main()
