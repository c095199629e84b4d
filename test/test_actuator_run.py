"""The strokes the actuator sends are the strokes the model runs: ``micro-feeder run`` (actuator and
simulator nodes over ROS) moves the part as far as the offline ``micro-feeder simulate`` does.

Before the knots bracketed the waveform's breakpoints, a 3-stroke burst with 50 ms pauses moved the part
−133 mm in ``run`` (the quintic between a resting knot and the next stroke's first knot swung to 85 mm)
against −7.8 µm offline.
"""

from __future__ import annotations

import itertools
import json
import re
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

CLI = [str(Path(sys.executable).parent / 'micro-feeder')]


@pytest.mark.parametrize('stroke', [
    ['stroke.count=3', 'stroke.pause=0.05'],
    ['stroke.count=3', 'stroke.pause=0.01', 'stroke.amplitude=150e-6'],
    ['stroke.count=2', 'stroke.pause=0.02', 'stroke.waveform=asymmetric', 'stroke.duty=0.3'],
    # strokes whose velocity or acceleration jumps: the knots ≤ 2 ns apart are a breakpoint in the simulator
    # (before, run threw the sine's part 2.27 m at 14.9 m/s against -288 µm offline)
    ['stroke.count=3', 'stroke.waveform=sine'],
    ['stroke.count=3', 'stroke.waveform=half_sine'],
    ['stroke.count=4', 'stroke.waveform=asymmetric', 'stroke.duty=0.8', 'stroke.frequency=800'],
])
def test_run_moves_the_part_as_far_as_simulate(stroke: list[str], tmp_path: Path) -> None:
    sets = [arg for item in stroke for arg in ('--set', item)]
    offline = subprocess.run([*CLI, 'simulate', '--json', '--out', str(tmp_path), *sets], capture_output=True,
                             text=True, timeout=120, check=True)
    want = json.loads(offline.stdout)
    run = subprocess.run([*CLI, 'run', '--duration', '0.4', *sets], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    moved = re.search(r'moved ([-+0-9.]+) um', run.stdout)
    transitions = re.search(r'transitions\s+(.*)', run.stdout)
    assert moved and transitions, run.stdout
    assert 'bursts sent, 0 rejected' in run.stdout
    # the summary prints the distance to 1 nm; both paths integrate the same strokes
    assert float(moved.group(1)) * 1e-6 == pytest.approx(want['distance_m'], abs=1.5e-9)
    assert transitions.group(1) == ', '.join(f'{k} {v}' for k, v in want['transitions'].items())


def test_continuous_strokes_in_run_are_the_offline_strokes(tmp_path: Path) -> None:
    """stroke.count 0 in ``run``: the actuator streams strokes until stopped, from t = 0 (``run`` holds its
    simulator there until the first window is in; they started stream.lead = 0.2 s late); over 0.5 s the part
    moves as an offline burst cut at 0.5 s does."""
    run = subprocess.run([*CLI, 'run', '--duration', '0.5', '--set', 'stroke.count=0'], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    start = re.search(r'burst streamed from t = ([0-9.]+) s', run.stderr)
    moved = re.search(r'moved ([-+0-9.]+) um', run.stdout)
    transitions = re.search(r'transitions\s+(.*)', run.stdout)
    assert start and moved and transitions, run.stdout + run.stderr
    assert float(start.group(1)) == 0.0, run.stderr
    assert '0 rejected, 0 late' in run.stdout, run.stdout + run.stderr
    offline = subprocess.run([*CLI, 'simulate', '--json', '--out', str(tmp_path), '--set', 'stroke.count=1000',
                              '--set', f'stroke.delay={start.group(1)}', '--duration', '0.5'],
                             capture_output=True, text=True, timeout=120, check=True)
    want = json.loads(offline.stdout)
    assert want['transitions']['stick_to_slip'] > 50, run.stdout + run.stderr
    assert float(moved.group(1)) * 1e-6 == pytest.approx(want['distance_m'], abs=1.5e-9)
    assert transitions.group(1) == ', '.join(f'{k} {v}' for k, v in want['transitions'].items())


def test_a_recorded_run_starts_at_sim_time_zero_without_a_stall(tmp_path: Path) -> None:
    """``run --record`` holds sim time at 0 until its actuator and recorder are there: the log's poses start
    at t = 0, the burst is applied at t = 0 as offline, and no wall-clock gap over 50 ms separates two poses
    (the command path is compiled before the loop runs, not under its lock in the first tick)."""
    from micro_feeder.logs.reader import LogReader
    from micro_feeder.logs.series import part_series

    log = tmp_path / 'run'
    run = subprocess.run([*CLI, 'run', '--duration', '0.5', '--set', 'stroke.count=5', '--record', str(log)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert 'started after' not in run.stderr, run.stderr
    offline = subprocess.run([*CLI, 'simulate', '--json', '--out', str(tmp_path), '--set', 'stroke.count=5',
                              '--duration', '0.5'], capture_output=True, text=True, timeout=120, check=True)
    moved = re.search(r'moved ([-+0-9.]+) um', run.stdout)
    assert moved and float(moved.group(1)) * 1e-6 == pytest.approx(json.loads(offline.stdout)['distance_m'],
                                                                    abs=1.5e-9), run.stdout
    reader = LogReader(log)
    poses = [(m.stamp_ns, m.log_time_ns) for m in reader.messages(['particle/pose'], decoded=True)]
    receipts = [m.stamp_ns for m in reader.messages(['simulator/command_receipts'], decoded=True)]
    assert poses[0][0] <= 2_000_000, poses[:3]                     # the first tick's pose (or t = 0's)
    assert receipts == [0], receipts                                # the burst reached the simulator at t = 0
    # plot's mode panel steps at the exact transition times, not at contact_state receive times
    changes = [float(kv.value) for m in reader.messages(['particle/transitions'], decoded=True)
               for status in m.message.status for kv in status.values if kv.key == 't_s']
    mode = part_series(reader).mode
    assert len(changes) == 10 and mode.t[1:].tolist() == changes, (changes, mode.t)
    running = [p for p in poses if p[0] > 0]                        # the held pose at t = 0 waits, by design
    wall_gaps = [b[1] - a[1] for a, b in itertools.pairwise(running)]
    assert max(wall_gaps) < 50_000_000, max(wall_gaps)


def test_run_records_each_tick_of_the_simulators_state_once_as_published(tmp_path: Path) -> None:
    """``run --record`` records the simulator's per-tick state topics in its process as they are published (not
    taken back from the middleware): each holds every tick's message once, in order, on the ticks of
    ``particle/pose``; the recorder's counters and ``info`` name them."""
    from micro_feeder.logs.reader import LogReader
    from micro_feeder.nodes.recorder import IN_PROCESS_TOPICS

    log = tmp_path / 'run'
    run = subprocess.run([*CLI, 'run', '--duration', '1', '--set', 'stroke.count=0', '--record', str(log)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert 'started after' not in run.stderr, run.stderr
    reader = LogReader(log)
    ticks = [m.stamp_ns for m in reader.messages(['particle/pose'], decoded=True)]
    assert ticks[0] == 0 and len(ticks) > 500 and ticks[-1] >= 990_000_000, (len(ticks), ticks[:2], ticks[-2:])
    running = [t for t in ticks if t > 0]
    assert all(b > a for a, b in itertools.pairwise(running)), 'a tick recorded twice or out of order'
    for topic in ('particle/twist', 'particle/contact_wrench', 'actuator/joint_states', 'particles/poses'):
        assert [m.stamp_ns for m in reader.messages([topic], decoded=True)] == ticks, topic
    state_times = [round(m.message.data[0] * 1e9) for m in reader.messages(['particles/states'], decoded=True)]
    assert state_times == ticks
    # every transition the run counted is in the log, the last tick's too (taken at the stop, not left behind)
    kinds = Counter(status.message for m in reader.messages(['particle/transitions'], decoded=True)
                    for status in m.message.status)
    transitions = re.search(r'transitions\s+(.*)', run.stdout)
    assert transitions and kinds['stick_to_slip'] > 100, run.stdout
    assert transitions.group(1) == ', '.join(f'{k} {kinds[k]}' for k in ('stick_to_slip', 'slip_to_stick',
                                                                           'take_off', 'landing'))
    counters = reader.recorder_info
    assert set(counters['recorded_in_process'].split(',')) == {'/' + name.lstrip('/') for name in IN_PROCESS_TOPICS}
    clock = [round(m.message.clock.sec * 1e9) + m.message.clock.nanosec
             for m in reader.messages(['/clock'], decoded=True)]
    assert clock == ticks
    assert int(counters['received./particle/pose']) == len(ticks) and counters['lost_total'] == '0'
    info = subprocess.run([*CLI, 'info', str(log)], capture_output=True, text=True, timeout=60, check=True)
    assert "recorded as published, in the simulator's process" in info.stdout, info.stdout
