"""Benchmark of the closed loop (issue 6): pose published -> command received by the simulator, real time.

Three processes, as in hardware in the loop: this script (the driver, no ROS), the simulator (1 kHz, real
time) and a controller. Phase 1, the round trip: a *responder* answers every ``particle/pose`` it
receives with an empty ``actuator/trajectory`` (stop = hold the strokes; harmless, they stay at 0) whose
``header.stamp`` is the pose's stamp, so the simulator can tell which pose each command answers (a past
stamp starts on receipt: docs/interface.md). Phase 2, optional: the real ``feed_controller`` executable
feeding the part to a target: for each burst, its stamp minus the sim time at which the simulator received
it, which must stay positive (the burst then starts exactly at its stamp; a late one starts mid-stroke).

Both ends are timed in the simulator's process: the driver runs the product's ``Simulator`` node there
through a bench-only subclass (``--role simulator``) that notes the wall time (``perf_counter``) just
before each pose is published and, with the sim time, at the entry of the ``actuator/trajectory``
callback, then writes the
samples to a JSON file when SIGINT ends it. It spins like the ``simulator`` executable (``spin_node``:
EventsExecutor on the main thread). Children get ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, a random
ROS_DOMAIN_ID and a temporary ROS_LOG_DIR. Issue 6 sets no target: the figures are a report.

    .venv/bin/python bench/bench_hil.py [--seconds 10] [--warmup 1] [--responder-executor events|single]
                                        [--feed-seconds 10 | --no-feed] [--json PATH | --no-json]

Results (driver only): bench/results/bench_hil.json.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import results_json
from results_json import figure

BENCH = Path(__file__).resolve().parent
FEED_LEAD = 0.05        # s: command_lead given to the feed controller (its burst stamp = pose stamp + lead)


# -- child: the simulator, timed -------------------------------------------------------------------

def run_simulator(out: Path, ros_args: list[str]) -> int:
    """``--role simulator``: the product's Simulator with both ends of the round trip timed."""
    from rclpy.serialization import deserialize_message
    from trajectory_msgs.msg import JointTrajectory

    from micro_feeder.nodes.simulator import Simulator
    from micro_feeder.nodes.spin import spin_node

    class _TimedPublisher:
        """Wraps the pose publisher: notes perf_counter just before each publish, by stamp (ns)."""

        def __init__(self, publisher: Any, sent: dict[int, float]):
            self._publisher, self._sent = publisher, sent

        def publish(self, msg: Any) -> None:
            if isinstance(msg, bytes | bytearray | memoryview):     # the simulator publishes CDR bytes
                sec, nanosec = struct.unpack_from('<iI' if msg[1] == 1 else '>iI', msg, 4)
            else:
                sec, nanosec = msg.header.stamp.sec, msg.header.stamp.nanosec
            self._sent[sec * 1_000_000_000 + nanosec] = time.perf_counter()
            self._publisher.publish(msg)

        def __getattr__(self, name: str) -> Any:
            return getattr(self._publisher, name)

    class TimedSimulator(Simulator):
        def __init__(self, *args: Any, **kwargs: Any):
            self.sent: dict[int, float] = {}
            self.received: list[tuple[int, float]] = []
            super().__init__(*args, **kwargs)
            self._pub_pose = _TimedPublisher(self._pub_pose, self.sent)

        def _on_command(self, topic: str, data: bytes) -> None:     # on delivery, before the intake
            if topic == 'actuator/trajectory':
                received = time.perf_counter()
                msg = deserialize_message(data, JointTrajectory)
                stamp = msg.header.stamp
                self.received.append((stamp.sec * 1_000_000_000 + stamp.nanosec, received, len(msg.points),
                                      round(self.stepper.t * 1e9)))
            super()._on_command(topic, data)

    nodes: list[TimedSimulator] = []

    def factory() -> TimedSimulator:
        nodes.append(TimedSimulator())
        return nodes[-1]

    status = spin_node('simulator', factory, ['simulator', '--ros-args', *ros_args])
    if nodes:
        sim = nodes[0]
        out.write_text(json.dumps({'sent': list(sim.sent.items()), 'received': sim.received,
                                   'rejected': sim.rejected, 'overruns': sim.overruns}))
    return status


# -- child: the responder ----------------------------------------------------------------------------

def run_responder(executor_kind: str) -> int:
    """``--role responder``: answer every pose with an empty trajectory stamped with the pose's stamp."""
    import rclpy
    from geometry_msgs.msg import PoseStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.experimental import EventsExecutor
    from rclpy.signals import SignalHandlerOptions
    from std_msgs.msg import Header
    from trajectory_msgs.msg import JointTrajectory

    from micro_feeder.nodes._ros import StopFlag, spin_until, topic_qos

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = StopFlag().install()
    node = rclpy.create_node('hil_responder')
    pub = node.create_publisher(JointTrajectory, 'actuator/trajectory', topic_qos('actuator/trajectory'))
    node.create_subscription(PoseStamped, 'particle/pose',
                             lambda msg: pub.publish(JointTrajectory(header=Header(stamp=msg.header.stamp))),
                             topic_qos('particle/pose'))
    executor = EventsExecutor() if executor_kind == 'events' else SingleThreadedExecutor()
    executor.add_node(node)
    try:
        spin_until(executor, lambda: bool(stop))
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


# -- driver --------------------------------------------------------------------------------------------

def child_env(log_dir: str) -> dict[str, str]:
    env = dict(os.environ)
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', ROS_DOMAIN_ID=str(random.SystemRandom().randint(1, 100)),
               ROS_LOG_DIR=log_dir)
    return env


def stop(proc: subprocess.Popen, what: str) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        print(f'  ({what} ignored SIGINT: killed)', file=sys.stderr)


def cpu_seconds(pid: int) -> float:
    """utime + stime (s) of a live process."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def run_phase(controller: list[str], seconds: float, tmp: Path, env: dict[str, str],
              sim_args: list[str]) -> tuple[dict[str, Any], dict[str, float]]:
    """Start the timed simulator, then ``controller``; after ``seconds`` stop both (controller first).
    Returns the simulator's samples and the CPU share of both processes over the run."""
    out = tmp / f'samples-{time.monotonic_ns()}.json'
    sim = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), '--role', 'simulator', '--out', str(out),
                            '--', *sim_args], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    ctl = None
    try:
        time.sleep(2.0)                       # the simulator up before the controller subscribes
        if sim.poll() is not None:
            raise RuntimeError(f'simulator exited: {sim.stderr.read()}')
        ctl = subprocess.Popen(controller, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(1.0)
        wall0, cpu0 = time.perf_counter(), (cpu_seconds(sim.pid), cpu_seconds(ctl.pid))
        time.sleep(seconds)
        wall = time.perf_counter() - wall0
        cpu = {'simulator': (cpu_seconds(sim.pid) - cpu0[0]) / wall,
               'controller': (cpu_seconds(ctl.pid) - cpu0[1]) / wall}
    finally:
        if ctl is not None:
            stop(ctl, 'controller')
        stop(sim, 'simulator')
    if not out.exists():
        raise RuntimeError(f'simulator wrote no samples: {sim.stderr.read()[-2000:]}')
    return json.loads(out.read_text()), cpu


def round_trips(samples: dict[str, Any], lead_ns: int, warmup: float) -> tuple[np.ndarray, int, list[int]]:
    """Round trips (ms) of the commands that name a published pose (stamp - ``lead_ns``, to within 2 ns of
    float rounding), dropping those answering poses of the first ``warmup`` s of answers. Returns them, the
    poses published over the same span and the knots of each kept command."""
    sent = {int(k): t for k, t in samples['sent']}
    keys = np.array(sorted(sent))
    trips = []
    for stamp, t_recv, knots, _ in samples['received']:
        i = np.searchsorted(keys, stamp - lead_ns)
        near = [keys[j] for j in (i - 1, i) if 0 <= j < keys.size and abs(keys[j] - (stamp - lead_ns)) <= 2]
        if near and near[0] > 0:
            trips.append((sent[int(near[0])], t_recv - sent[int(near[0])], knots))
    start = trips[0][0] + warmup if trips else 0.0
    kept = [row for row in trips if row[0] >= start]
    if not kept:
        return np.zeros(0), 0, []
    published = sum(1 for t in sent.values() if kept[0][0] <= t <= kept[-1][0])
    return np.array([dt for _, dt, _ in kept]) * 1e3, published, [knots for _, _, knots in kept]


def burst_margins(samples: dict[str, Any]) -> tuple[np.ndarray, list[int]]:
    """For each burst: its stamp minus the sim time when the simulator received it (ms; > 0 means it arrived
    in time and starts exactly at its stamp, < 0 means it started late, mid-trajectory), and its knots."""
    rows = [(stamp - sim_ns, knots) for stamp, _, knots, sim_ns in samples['received'] if knots]
    return np.array([margin for margin, _ in rows]) * 1e-6, [knots for _, knots in rows]


def publishing(samples: dict[str, Any], warmup: float) -> tuple[float, float, float]:
    """Poses published per wall second, the achieved real-time factor (sim s / wall s) and the span (s),
    from the end of the warm-up (counted from the first answered pose) to the last pose."""
    sent = sorted((t, k) for k, t in samples['sent'] if k > 0)
    answered = {row[0] for row in samples['received']}
    first = next((t for t, k in sent if k in answered), sent[0][0])
    window = [(t, k) for t, k in sent if t >= first + warmup]
    if len(window) < 2:
        return float('nan'), float('nan'), 0.0
    wall = window[-1][0] - window[0][0]
    return (len(window) - 1) / wall, (window[-1][1] - window[0][1]) * 1e-9 / wall, wall


def describe(ms: np.ndarray) -> str:
    if ms.size == 0:
        return 'no samples'
    return (f'p50 {np.percentile(ms, 50):6.3f} ms, p99 {np.percentile(ms, 99):6.3f} ms, '
            f'max {ms.max():6.3f} ms, n = {ms.size}')


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=10.0, help='round-trip measurement (s)')
    parser.add_argument('--warmup', type=float, default=1.0, help='answers dropped at the start (s)')
    parser.add_argument('--responder-executor', choices=('events', 'single'), default='events',
                        help='the responder spins an EventsExecutor (like the package nodes) or rclpy\'s '
                             'SingleThreadedExecutor (like rclpy.spin)')
    parser.add_argument('--feed-seconds', type=float, default=10.0, help='feed controller run (s)')
    parser.add_argument('--no-feed', action='store_true', help='skip the feed controller phase')
    parser.add_argument('--role', choices=('driver', 'simulator', 'responder'), default='driver',
                        help=argparse.SUPPRESS)
    parser.add_argument('--out', type=Path, help=argparse.SUPPRESS)
    parser.add_argument('ros_args', nargs='*', help=argparse.SUPPRESS)
    results_json.add_arguments(parser, 'bench_hil')
    args = parser.parse_args()
    if args.role == 'simulator':
        return run_simulator(args.out, args.ros_args)
    if args.role == 'responder':
        return run_responder(args.responder_executor)

    sim_args = ['-p', 'publish_rate:=1000.0', '-p', 'real_time_factor:=1.0']
    tmp = Path(tempfile.mkdtemp(prefix='bench-hil-'))
    env = child_env(str(tmp / 'roslog'))
    load0 = os.getloadavg()
    started = time.perf_counter()
    try:
        responder = [sys.executable, str(Path(__file__).resolve()), '--role', 'responder',
                     '--responder-executor', args.responder_executor]
        samples, cpu = run_phase(responder, args.seconds + args.warmup, tmp, env, sim_args)
        trip, published, _ = round_trips(samples, 0, args.warmup)
        received = len(samples['received'])
        rate, rtf, span = publishing(samples, args.warmup)
        load1 = os.getloadavg()
        feed = None
        if not args.no_feed:
            exe = shutil.which('feed_controller', path=str(Path(sys.executable).parent))
            controller = [exe, '--ros-args', '-p', 'feed.target_x:=0.2e-3', '-p', f'command_lead:={FEED_LEAD}']
            feed_samples, feed_cpu = run_phase(controller, args.feed_seconds, tmp, env, sim_args)
            feed = (burst_margins(feed_samples), feed_cpu)
        load2 = os.getloadavg()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)

    print(f'closed loop, simulator at 1000 Hz real time, separate processes ({os.cpu_count()} cores, load average '
          f'1/5 min {load0[0]:.2f}/{load0[1]:.2f} -> {load1[0]:.2f}/{load1[1]:.2f} -> {load2[0]:.2f}/{load2[1]:.2f})')
    print(f'  round trip pose published -> command received, responder ({args.responder_executor} executor) '
          f'answering every pose, {span:.1f} s of answers after {args.warmup:g} s warm-up:')
    print(f'    {describe(trip)}    target: none in issue 6 (report)')
    print(f'    poses published {published}, answered {trip.size} ({trip.size / max(published, 1) * 100:.1f} %); '
          f'commands received {received}, rejected {samples["rejected"]}; simulator overruns {samples["overruns"]}')
    print(f'    simulator while answered: {rate:.1f} poses/s, real-time factor {rtf:.4f}; CPU: simulator '
          f'{cpu["simulator"] * 100:.1f} %, responder {cpu["controller"] * 100:.1f} % of a core')
    if feed is not None:
        (ms, knots), feed_cpu = feed
        print(f'  feed controller bursts: stamp minus the sim time they reached the simulator (feed_controller '
              f'executable, target 0.2 mm, {args.feed_seconds:g} s; > 0 = in time, command_lead {FEED_LEAD * 1e3:g} '
              'ms + its build time):')
        print(f'    {describe(ms)}; late (< 0): {int(np.sum(ms < 0))} of {ms.size}')
        print(f'    in order, ms (knots): {" ".join(f"{v:.1f} ({k})" for v, k in zip(ms, knots, strict=True))}')
        print(f'    CPU: simulator {feed_cpu["simulator"] * 100:.1f} %, feed_controller '
              f'{feed_cpu["controller"] * 100:.1f} % of a core')
    figures = []
    if trip.size:
        figures += [figure(f'round_trip_{name}_ms', f'closed loop: pose published -> command received, {name}',
                           round(float(value), 3), 'ms',
                           note=f'responder ({args.responder_executor} executor) in another process answering every '
                                f'pose; {trip.size} answers' if name == 'p50' else '')
                    for name, value in (('p50', np.percentile(trip, 50)), ('p99', np.percentile(trip, 99)),
                                        ('max', trip.max()))]
    figures.append(figure('simulator_cpu_answered_pct', 'simulator CPU while every pose is answered, % of one core',
                          round(cpu['simulator'] * 100, 1), '%'))
    if feed is not None:
        (ms, _), _ = feed
        if ms.size:
            figures.append(figure('burst_margin_min_ms', 'feed controller bursts: smallest margin before their stamp '
                                  'on arrival', round(float(ms.min()), 1), 'ms', op='>', target=0,
                                  note=f'{ms.size} bursts, {int(np.sum(ms < 0))} late; largest margin '
                                       f'{ms.max():.1f} ms; command_lead {FEED_LEAD * 1e3:g} ms'))
    results_json.save(args, 'bench_hil', 'Closed loop (hardware in the loop)', figures,
                      load_before=[round(x, 2) for x in load0], seconds=time.perf_counter() - started,
                      purpose='The simulator at 1 kHz in real time with a controller in another process: the '
                              'round trip, and the feed controller\'s bursts arriving before their stamps (issue '
                              '6 sets no target: a report).')
    return 0


if __name__ == '__main__':
    sys.exit(main())
