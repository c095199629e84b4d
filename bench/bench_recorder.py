"""Recorder and replay benchmarks, each printed with its target.

1. Zero loss at 5 topics × 1 kHz for --duration s (target: 0 lost, 60 s).
2. Maximum sustained rate: 5 topics at increasing total rates for --burst s each; the highest with zero
   loss (target ≥ 20k msg/s).
3. Replay timing error p50/p99 of the log from (1).

Run: .venv/bin/python bench/bench_recorder.py [--duration 60] [--json PATH | --no-json]. Sets LOCALHOST
discovery, a random domain and a temporary ROS_LOG_DIR itself. Results: bench/results/bench_recorder.json.
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(random.SystemRandom().randint(101, 200)))
os.environ.setdefault('ROS_LOG_DIR', tempfile.mkdtemp(prefix='bench-roslog-'))

import numpy as np
import rclpy
import results_json
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from results_json import figure

from micro_feeder.logs.reader import LogReader
from micro_feeder.nodes.replay import Replay

TOPICS = ['particle/pose', 'bench/a', 'bench/b', 'bench/c', 'bench/d']


def record(out: Path, rate_per_topic: float, seconds: float, node) -> tuple[int, int]:
    """Run the recorder executable while publishing; returns (published, recorded)."""
    exe = Path(sys.executable).parent / 'recorder'
    topics = '[' + ','.join(f'"{t}"' for t in TOPICS) + ']'
    proc = subprocess.Popen([str(exe), '--ros-args', '-p', f'output:={out}', '-p', f'topics:={topics}'],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    pubs = [node.create_publisher(PoseStamped, t, 1000) for t in TOPICS]
    try:
        deadline = time.monotonic() + 30
        while min(p.get_subscription_count() for p in pubs) < 1:
            if time.monotonic() > deadline:
                raise RuntimeError('recorder did not subscribe (bench topics discovered at 1 Hz)')
            time.sleep(0.05)
        msg, sent, start = PoseStamped(), 0, time.monotonic()
        while (now := time.monotonic() - start) < seconds:
            due = int(now * rate_per_topic)
            while sent < due:
                for p in pubs:
                    p.publish(msg)
                sent += 1
            time.sleep(0.0002)
        time.sleep(0.5)
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(60)
        for p in pubs:
            node.destroy_publisher(p)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        log = LogReader(out)
    recorded = sum(t.count for name, t in log.topics.items() if not name.startswith('/diagnostics'))
    return sent * len(TOPICS), recorded


def replay_timing(log: Path) -> np.ndarray:
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Replay(context=context, parameter_overrides=[Parameter('log', value=str(log))])
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        node.start()
        while not node.finished.done():
            executor.spin_once(timeout_sec=0.05)
        node.close()
        executor.shutdown()
        node.destroy_node()
        return np.asarray(node.timing_errors) * 1e3
    finally:
        rclpy.shutdown(context=context)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--duration', type=float, default=60.0, help='zero-loss run length [s]')
    parser.add_argument('--burst', type=float, default=5.0, help='length of each max-rate step [s]')
    results_json.add_arguments(parser, 'bench_recorder')
    args = parser.parse_args()
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    work = Path(tempfile.mkdtemp(prefix='bench-recorder-'))
    rclpy.init()
    node = rclpy.create_node('bench_publisher')
    sent, got = record(work / 'steady', 1000.0, args.duration, node)
    print(f'zero loss, 5 topics × 1 kHz for {args.duration:.0f} s: published {sent}, recorded {got}, '
          f'lost {sent - got}   (target: 0 lost over 60 s)')
    best = 0.0
    for total in (10_000, 15_000, 20_000, 25_000, 30_000):
        sent_n, got_n = record(work / f'rate{total}', total / len(TOPICS), args.burst, node)
        achieved = sent_n / args.burst
        print(f'  offered {total} msg/s (achieved {achieved:.0f}): lost {sent_n - got_n} of {sent_n}')
        if sent_n != got_n:
            break
        best = achieved
    print(f'max sustained rate with zero loss: {best:.0f} msg/s   (target: >= 20000 msg/s)')
    node.destroy_node()
    rclpy.shutdown()
    e = replay_timing(work / 'steady')
    print(f'replay timing error over {len(e)} messages: p50 {np.percentile(e, 50):.3f} ms, '
          f'p99 {np.percentile(e, 99):.3f} ms, max {e.max():.3f} ms   (no target set; measured)')
    figures = [
        figure('lost', f'recorder, 5 topics x 1 kHz for {args.duration:g} s: messages lost', sent - got, '', op='==',
               target=0, note=f'{got} of {sent} recorded'),
        figure('max_rate', 'recorder, highest rate of the ladder with zero loss', round(best), 'msg/s', op='>=',
               target=20_000, note='the ladder stops at 30,000 msg/s offered'),
        figure('replay_p50_ms', 'replay timing error, p50', round(float(np.percentile(e, 50)), 3), 'ms'),
        figure('replay_p99_ms', 'replay timing error, p99', round(float(np.percentile(e, 99)), 3), 'ms',
               note=f'over {len(e)} messages; max {e.max():.3f} ms'),
    ]
    results_json.save(args, 'bench_recorder', 'Recorder and replay', figures, load_before=load,
                      seconds=time.perf_counter() - started,
                      purpose='The recorder executable against a publisher in this process: loss at 5 kHz '
                              'in all, the highest rate without loss, and replay timing.')
    return 0


if __name__ == '__main__':
    sys.exit(main())
