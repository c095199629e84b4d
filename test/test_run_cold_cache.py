"""``micro-feeder run --record`` on a fresh numba cache (the first run after installing): every compiled
function is compiled while sim time is held at 0, none on the first tick or the first command, so the log
starts at t = 0 and the poses arrive without a stall. One run with an empty ``NUMBA_CACHE_DIR``: ~10 min of
compiling on an idle core (that is the point: a warm cache loads in ~1.5 s and hides a late compile)."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from micro_feeder.logs.reader import LogReader
from micro_feeder.logs.sim_parameters import recorded_parameters
from micro_feeder.logs.summary import format_summary, summarize, tick_length

MAX_GAP = 0.050     # s: largest wall gap allowed between two consecutive poses as the recorder logged them


@pytest.mark.fresh_cache
@pytest.mark.timeout(1200)
def test_run_on_a_fresh_numba_cache_starts_at_zero_without_a_stall(tmp_path: Path) -> None:
    env = {**os.environ, 'NUMBA_CACHE_DIR': str(tmp_path / 'numba-cache')}
    started = time.monotonic()
    proc = subprocess.run([str(Path(sys.executable).parent / 'micro-feeder'), 'run', '--duration', '1',
                           '--set', 'stroke.count=5', '--record', str(tmp_path / 'log')],
                          env=env, capture_output=True, text=True, timeout=1100)
    wall = time.monotonic() - started
    assert proc.returncode == 0, proc.stderr
    assert 'started after' not in proc.stderr, proc.stderr      # the hold ended because all was there
    assert any((tmp_path / 'numba-cache').rglob('*.nbi')), 'the run did not use the fresh cache'
    log = LogReader(tmp_path / 'log')
    poses = list(log.messages(['particle/pose']))
    stamps = np.array([m.stamp_ns for m in poses]) * 1e-9
    # from the burst's receipt (the simulator applies it at t = 0, just before the hold ends) to each pose of
    # the running simulation: the held pose at t = 0 is recorded as the simulator is built, long before
    receipt = next(log.messages(['simulator/command_receipts'])).log_time_ns * 1e-9
    running = stamps > 0
    received = np.concatenate([[receipt], np.array([m.log_time_ns for m in poses])[running] * 1e-9])
    stamps = np.concatenate([[0.0], stamps[running]])
    gaps = np.diff(received)
    tick = tick_length(recorded_parameters(log)[0])
    worst = int(np.argmax(gaps))
    first = poses[0].stamp_ns * 1e-9
    print(f'run {wall:.1f} s wall (compile included); {len(poses)} poses, first at sim time {first:.6f} s '
          f'(one tick {tick * 1e3:g} ms), last {stamps[-1]:.6f} s; largest gap between two poses received '
          f'{gaps[worst] * 1e3:.1f} ms, after sim time {stamps[worst]:.6f} s; '
          f'p99 {np.percentile(gaps, 99) * 1e3:.2f} ms')
    assert first <= tick + 1e-9, f'the log starts at sim time {first:.6f} s, not 0'
    assert gaps[worst] <= MAX_GAP, (f'{gaps[worst] * 1e3:.1f} ms without a pose after sim time '
                                    f'{stamps[worst]:.6f} s')
    assert 'start missing' not in format_summary(summarize(log))
