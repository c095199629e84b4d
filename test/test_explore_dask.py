"""Runs on a real Dask cluster (a ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1, random
ports, started here as a user would) give the same results as the local run (sweep table, optimum,
calibration), also when a worker is killed mid-run; local worker processes stop with the command (Ctrl-C,
or the command killed)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_calibrate import recorded  # noqa: F401 - the recorded stepped log (a module fixture)

from micro_feeder.explore.calibrate import calibrate
from micro_feeder.explore.cluster import LocalCluster, local_cluster
from micro_feeder.explore.designs import Grid, RunPlan, parse_axis, parse_perturbation
from micro_feeder.explore.evaluate import Job
from micro_feeder.explore.optimize import Problem, optimize
from micro_feeder.explore.runners import DaskCluster, InProcess, LocalProcesses
from micro_feeder.explore.sweep import run_plan

BIN = Path(sys.executable).parent
START_TIMEOUT = 60.0     # s: scheduler and workers up (a loaded 2-core machine)


def _wait_for(predicate, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError(f'{what} not within {timeout} s')
        time.sleep(0.1)


@pytest.fixture(scope='module')
def cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LocalCluster]:
    """``dask scheduler`` + 2 single-threaded ``dask worker`` processes (no nanny: killing one is a real
    worker death), all on 127.0.0.1 with ports the OS picks."""
    with local_cluster(tmp_path_factory.mktemp('dask'), workers=2, timeout=START_TIMEOUT) as started:
        yield started


def test_cli_sweep_on_the_cluster_equals_the_local_run(cluster, tmp_path, capsys):
    from micro_feeder.cli import main
    args = ['sweep', '--vary', 'stroke.frequency=500:3000:12', '--vary', 'stroke.amplitude=40e-6:160e-6:4',
            '--set', 'stroke.count=2']
    assert main([*args, '--processes', '2', '--out', str(tmp_path / 'local')]) == 0
    assert main([*args, '--scheduler', cluster.address, '--out', str(tmp_path / 'dask')]) == 0
    out = capsys.readouterr().out
    assert 'Dask cluster' in out
    local, remote = ((tmp_path / d / 'sweep.csv').read_text() for d in ('local', 'dask'))
    assert local == remote and len(local.splitlines()) == 49


def test_a_worker_killed_mid_run_costs_only_its_tasks(cluster):
    plan = RunPlan(Grid([parse_axis('stroke.frequency=600:1500:6')]),
                   (parse_perturbation('contact.friction_scale=normal:10%'),), replicates=8, seed=2)
    job = Job({'stroke.count': 2})
    expected = list(run_plan(job, plan, InProcess()))
    victim = cluster.workers[0]
    rows = []
    with DaskCluster(cluster.address, window=8) as runner:
        def kill_after_first_rows() -> None:
            _wait_for(lambda: len(rows) >= 2, 60, 'first rows')
            victim.send_signal(signal.SIGKILL)
        killer = threading.Thread(target=kill_after_first_rows, daemon=True)
        killer.start()
        for row in run_plan(job, plan, runner):
            rows.append(row)
        killer.join(timeout=5)
    assert victim.wait(timeout=5) == -signal.SIGKILL
    assert rows == expected


def test_optimize_and_calibrate_on_the_cluster_equal_the_local_run(cluster, recorded):  # noqa: F811
    problem = Problem(Job({'stroke.count': 2, 'stroke.frequency': 1200.0}), ('particle.x0',), ((0.1e-3, 1.4e-3),))
    start = {'contact.friction_scale': 0.0115, 'particle.x0': 0.55e-3}
    results = []
    for runner in (LocalProcesses(2), DaskCluster(cluster.address)):
        with runner:
            results.append((optimize(problem, runner, seed=4, max_generations=15).as_dict(),
                            calibrate([str(recorded)], start, runner).as_dict()))
    assert results[0] == results[1]
    assert results[0][0]['evaluations'] > 20 and results[0][1]['converged']


def _sweep_process(*extra: str) -> subprocess.Popen:
    return subprocess.Popen([str(BIN / 'micro-feeder'), 'sweep', '--vary', 'stroke.frequency=100:5000:100000000',
                             '--force', '--processes', '2', *extra], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def _children(pid: int) -> list[int]:
    out = subprocess.run(['pgrep', '-P', str(pid)], capture_output=True, text=True).stdout
    return [int(p) for p in out.split()]


def _alive(pid: int) -> bool:
    try:
        with open(f'/proc/{pid}/stat') as handle:
            return handle.read().split()[2] != 'Z'
    except FileNotFoundError:
        return False


@pytest.mark.parametrize('how', ['ctrl-c', 'killed'])
def test_local_workers_never_outlive_the_command(how, tmp_path):
    proc = _sweep_process('--out', str(tmp_path))
    try:
        _wait_for(lambda: len(_children(proc.pid)) == 2, 60, 'two worker processes')
        workers = _children(proc.pid)
        time.sleep(1.0)                                  # the sweep is under way
        started = time.monotonic()
        proc.send_signal(signal.SIGINT if how == 'ctrl-c' else signal.SIGKILL)
        proc.wait(timeout=30)
        stopped = time.monotonic() - started
        _wait_for(lambda: not any(_alive(w) for w in workers), 5, 'the workers gone')
        if how == 'ctrl-c':
            err = proc.stderr.read()
            assert proc.returncode == 130 and 'Traceback' not in err and err.rstrip().endswith('interrupted')
            assert stopped < 1.0, f'Ctrl-C took {stopped:.2f} s'
    finally:
        proc.kill()
        proc.wait()
        proc.stdout.close()
        proc.stderr.close()
