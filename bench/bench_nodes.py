"""Benchmark of the simulator node at 1 kHz publishing, as a separate process seen by an outside client.

Measures: achieved real-time factor (target: holds 1.0), CPU share of the simulator process (target
<= 25 % of one core) and its split between the loop thread, the main (executor) thread and the rest
(Fast DDS), tick period p50/p99 (target p99 <= 1.5 ms; from the node's /diagnostics), and the latency from
a trajectory command to the first pose that reflects it (p50/p99; the pose's tilt changes as soon as the
stroke does, since the part sits on the bump's flank). Prints the load average before and after: the
figures are only comparable at a similar load (2 cores).

Then the live view (``--foxglove``): CPU share of a ``micro-feeder run`` process (simulator and actuator
nodes in one process, the actuator idle after its burst) without ``--foxglove``, with it and no viewer
(target <= 25 % of one core: the hook costs nothing measurable), and with one viewer subscribed to every
topic the server advertises (the test client test/foxglove_client, installed by ``make test``; target
<= 35 %).

    .venv/bin/python bench/bench_nodes.py [--seconds 10] [--commands 60] [--viewer-seconds 10]
                                          [--json PATH | --no-json]

Results: bench/results/bench_nodes.json.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import results_json
from results_json import figure

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(60 + os.getpid() % 30))

import rclpy  # imported after the environment is set: rcl reads it at init
from builtin_interfaces.msg import Duration
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.executors import SingleThreadedExecutor
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from micro_feeder.nodes._ros import topic_qos

CLK_TCK = os.sysconf('SC_CLK_TCK')


def cpu_seconds(pid: int) -> float:
    return _stat_cpu(Path(f'/proc/{pid}/stat'))


def _stat_cpu(stat: Path) -> float:
    """utime + stime (s) from a /proc stat file."""
    fields = stat.read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def thread_cpu(pid: int) -> dict[int, float]:
    """CPU seconds per thread id of process ``pid``."""
    out = {}
    for task in Path(f'/proc/{pid}/task').iterdir():
        try:
            out[int(task.name)] = _stat_cpu(task / 'stat')
        except OSError:
            continue
    return out


def thread_split(pid: int, before: dict[int, float], after: dict[int, float], wall: float) -> str:
    """'loop 15.1 %, main 0.8 %, other 2.0 %': the busiest thread other than the main one is the loop
    thread (the node's only busy Python thread); 'other' is Fast DDS's threads."""
    used = {tid: (cpu - before.get(tid, 0.0)) / wall * 100 for tid, cpu in after.items()}
    main = used.pop(pid, 0.0)
    loop = max(used.values(), default=0.0)
    return f'loop {loop:.1f} %, main {main:.1f} %, other {sum(used.values()) - loop:.1f} %'


def spin_until(executor: SingleThreadedExecutor, predicate, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            return False
        executor.spin_once(timeout_sec=0.005)
    return True


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=10.0, help='steady-state measurement window (s)')
    parser.add_argument('--commands', type=int, default=60, help='trajectory commands for the latency')
    parser.add_argument('--viewer-seconds', type=float, default=10.0,
                        help='window of each live-view CPU measurement (s); 0 skips them')
    results_json.add_arguments(parser, 'bench_nodes')
    args = parser.parse_args()
    load_before = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    exe = shutil.which('simulator', path=str(Path(sys.executable).parent))
    proc = subprocess.Popen([exe, '--ros-args', '-p', 'publish_rate:=1000.0'], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL)
    rclpy.init()
    node = rclpy.create_node('bench_nodes')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    poses: list[tuple[float, float, float]] = []       # (wall receive time, sim stamp, orientation.y)
    diags: list[dict[str, str]] = []
    qos = topic_qos('particle/pose')
    qos.depth = 1000
    node.create_subscription(PoseStamped, 'particle/pose', lambda m: poses.append(
        (time.perf_counter(), m.header.stamp.sec + m.header.stamp.nanosec * 1e-9, m.pose.orientation.y)), qos)
    node.create_subscription(DiagnosticArray, '/diagnostics', lambda m: diags.extend(
        {kv.key: kv.value for kv in s.values} for s in m.status if s.name == 'simulator: loop'), 10)
    pub = node.create_publisher(JointTrajectory, 'actuator/trajectory', topic_qos('actuator/trajectory'))
    try:
        if not spin_until(executor, lambda: len(poses) > 1000 and pub.get_subscription_count() > 0, 120):
            print('simulator did not start', file=sys.stderr)
            return 1
        # steady state: real-time factor, CPU, tick timing
        load0 = os.getloadavg()[0]
        wall0, cpu0, n0, d0 = time.perf_counter(), cpu_seconds(proc.pid), len(poses), len(diags)
        threads0 = thread_cpu(proc.pid)
        spin_until(executor, lambda: False, args.seconds)
        wall1, cpu1 = time.perf_counter(), cpu_seconds(proc.pid)
        split = thread_split(proc.pid, threads0, thread_cpu(proc.pid), wall1 - wall0)
        load1 = os.getloadavg()[0]
        window = poses[n0:]
        rtf = (window[-1][1] - window[0][1]) / (window[-1][0] - window[0][0])
        cpu = (cpu1 - cpu0) / (wall1 - wall0)
        windows = diags[d0 + 1:] or diags[-1:]
        p50 = float(np.median([float(d['tick_period_p50_ms']) for d in windows]))
        p99 = [float(d['tick_period_p99_ms']) for d in windows]
        rate = len(window) / (window[-1][0] - window[0][0])
        # latency: alternate strokes of +-50 um reached 0.1 ms after receipt; first pose with the new tilt sign
        latencies = []
        for i in range(args.commands):
            target = 50e-6 if i % 2 == 0 else -50e-6
            msg = JointTrajectory(joint_names=['piezo_0'], points=[JointTrajectoryPoint(
                positions=[target], time_from_start=Duration(nanosec=100_000))])
            start = len(poses)
            sent = time.perf_counter()
            pub.publish(msg)
            # tilt of the contact frame: orientation.y = sin(-theta/2), theta = atan(h_x); h_x < 0 for s > 0
            # at x0 > c (the surface falls toward the part), so s > 0 -> theta < 0 -> orientation.y > 0
            if spin_until(executor, lambda s=start, g=target: any(np.sign(p[2]) == np.sign(g) for p in poses[s:]),
                          2.0):
                first = next(p for p in poses[start:] if np.sign(p[2]) == np.sign(target))
                latencies.append(first[0] - sent)
            spin_until(executor, lambda: False, 0.03)
        lat = np.asarray(latencies) * 1e3
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
    print(f'simulator process at publish_rate 1000 Hz, {args.seconds:g} s steady state ({os.cpu_count()} cores, '
          f'load average {load0:.2f} -> {load1:.2f})')
    print(f'  poses received          {rate:8.1f} /s')
    print(f'  real-time factor        {rtf:8.4f}    target: holds 1.0')
    print(f'  CPU share               {cpu * 100:7.1f} %    target: <= 25 % of one core ({split})')
    print(f'  tick period p50         {p50:8.3f} ms')
    print(f'  tick period p99         {np.median(p99):8.3f} ms (median of 1 s windows; worst {max(p99):.3f} ms)'
          f'    target: <= 1.5 ms')
    print(f'  command -> pose latency p50 {np.percentile(lat, 50):6.2f} ms, p99 {np.percentile(lat, 99):6.2f} ms '
          f'({lat.size}/{args.commands} commands seen)')
    figures = [
        figure('rtf', 'simulator at 1 kHz: achieved real-time factor', round(rtf, 4), '', op='>=', target=0.99,
               note='target: holds 1.0'),
        figure('cpu_pct', 'simulator at 1 kHz: CPU of its process, % of one core', round(cpu * 100, 1), '%', op='<=',
               target=25, note=split),
        figure('tick_p50_ms', 'simulator at 1 kHz: tick period p50', round(p50, 3), 'ms'),
        figure('tick_p99_ms', 'simulator at 1 kHz: tick period p99 (median of 1 s windows)',
               round(float(np.median(p99)), 3), 'ms', op='<=', target=1.5,
               note=f'worst 1 s window {max(p99):.3f} ms'),
        figure('command_latency_p50_ms', 'trajectory command -> first pose reflecting it, p50',
               round(float(np.percentile(lat, 50)), 2), 'ms', note=f'{lat.size}/{args.commands} commands seen'),
        figure('command_latency_p99_ms', 'trajectory command -> first pose reflecting it, p99',
               round(float(np.percentile(lat, 99)), 2), 'ms'),
    ]
    status = 0
    if args.viewer_seconds > 0:
        status, live = live_view_cpu(args.viewer_seconds)
        figures += live
    results_json.save(args, 'bench_nodes', 'The simulator node at 1 kHz', figures, load_before=load_before,
                      seconds=time.perf_counter() - started,
                      purpose='The simulator as a separate process at 1 kHz publishing, seen by an outside client; '
                              'then the CPU of a micro-feeder run process with and without the live view.')
    return status


CLIENT = Path(__file__).parents[1] / 'test' / 'foxglove_client'


def live_view_cpu(seconds: float) -> tuple[int, list[dict]]:
    """CPU share of ``micro-feeder run`` without --foxglove, with it and no viewer, and with one viewer."""
    if not (CLIENT / 'node_modules').is_dir():
        print(f'live view: skipped, no test client (run: cd {CLIENT} && npm ci)', file=sys.stderr)
        return 1, []
    load0 = os.getloadavg()[0]
    results = [('run, no --foxglove', _run_cpu(seconds, None, False), 25),
               ('run --foxglove, no viewer', _run_cpu(seconds, 18900 + os.getpid() % 500, False), 25),
               ('run --foxglove, 1 viewer (all topics)', _run_cpu(seconds, 19400 + os.getpid() % 500, True), 35)]
    print(f'live view: CPU share of the micro-feeder run process, {seconds:g} s each '
          f'(load average {load0:.2f} -> {os.getloadavg()[0]:.2f})')
    for what, cpu, target in results:
        print(f'  {what:38s} {cpu * 100:6.1f} %    target: <= {target} % of one core')
    keys = ('live_view_off_pct', 'live_view_no_viewer_pct', 'live_view_viewer_pct')
    return 0, [figure(key, f'live view, micro-feeder {what}: CPU of the process, % of one core', round(cpu * 100, 1),
                      '%', op='<=', target=target)
               for key, (what, cpu, target) in zip(keys, results, strict=True)]


def _run_cpu(seconds: float, port: int | None, viewer: bool) -> float:
    """CPU share (cores) of a ``micro-feeder run`` over ``seconds`` once it runs (and the viewer subscribed)."""
    exe = shutil.which('micro-feeder', path=str(Path(sys.executable).parent))
    cmd = [exe, 'run', '--duration', str(seconds + 30)] + (['--foxglove', f'127.0.0.1:{port}'] if port else [])
    with open(os.devnull, 'w') as devnull:
        proc = subprocess.Popen(cmd, stdout=devnull, stderr=devnull)
        client = None
        try:
            time.sleep(4.0)             # started, kernel loaded, the actuator's burst over
            if viewer:
                client = subprocess.Popen(['node', str(CLIENT / 'client.js'), f'ws://127.0.0.1:{port}', '*',
                                           str(seconds + 4)], stdout=devnull, stderr=devnull)
                time.sleep(2.0)         # connected and subscribed
            wall0, cpu0 = time.perf_counter(), cpu_seconds(proc.pid)
            time.sleep(seconds)
            return (cpu_seconds(proc.pid) - cpu0) / (time.perf_counter() - wall0)
        finally:
            if client is not None:
                client.kill()
                client.wait()
            proc.send_signal(signal.SIGINT)
            proc.wait(timeout=30)


if __name__ == '__main__':
    sys.exit(main())
