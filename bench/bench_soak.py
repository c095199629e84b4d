"""Soak benchmark: continuous strokes (``stroke.count`` 0, streamed by the actuator) against the simulator
at 1 kHz publishing, as separate processes, for minutes; and the same recorded by ``micro-feeder run --record``
in one process, then re-simulated.

Per case (1 actuator 10 min, 16 actuators 10 min, 64 actuators 2 min, ``run`` 10 min by default;
``--minutes M`` runs every case M minutes, ``--cases 1,16`` picks cases) it reports, each with its target:

* median real-time factor achieved (the simulator's ``/diagnostics``, one value per second): >= 0.99;
* RSS growth of the simulator and of the actuator (MB/min, least-squares slope after the first
  minute's tenth): < 1 MB/min;
* CPU of the simulator process (% of one core): <= 25 / 35 / 50 % for 1 / 16 / 64 actuators; the
  actuator's CPU is reported beside it;
* stream underruns (actuator), rejected commands (simulator): 0; warnings in the nodes' logs (written to
  ``out/soak/``, or ``$SOAK_LOG_DIR``). A node that exits during a case stops the benchmark with its log's path.

The ``run`` case: ``micro-feeder run --set stroke.count=0 --record LOG --duration 60*M`` (simulator, actuator
and recorder in one process, 1 actuator), then ``micro-feeder resim LOG``:

* median real-time factor (``/diagnostics``, once a second while streaming): >= 0.99;
* RSS growth of the run process (MB/min, over the second half of the run: glibc's arenas grow 2-3 MB in
  the first minutes and stop, which is no leak; the slope from 6 s on is reported beside it): < 0.1 MB/min;
  its CPU is reported;
* the log: poses recorded, largest gap between two pose stamps, messages the recorder lost (0);
* ``resim`` of the log: peak RSS <= 500 MB, wall time <= 5 min, and its verdict.

The travelling wave uses phases (k mod 4)/4: 4 distinct stroke starts per period, whatever the count.
Prints the load average before and after: on a shared 2-core machine the figures move with it.

    .venv/bin/python bench/bench_soak.py [--minutes M] [--cases 1,16,64,run] [--json PATH | --no-json]

Results: bench/results/bench_soak.json.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import results_json
from results_json import figure

os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(90 + os.getpid() % 30))

import rclpy  # imported after the environment is set: rcl reads it at init
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor

from micro_feeder.nodes._ros import topic_qos

CLK_TCK = os.sysconf('SC_CLK_TCK')
CASES = {1: (10.0, 25.0), 16: (10.0, 35.0), 64: (2.0, 50.0)}     # actuators: (minutes, CPU target %)
RUN_MINUTES = 10.0                     # the run case: micro-feeder run --record, then resim of its log
RUN_RSS_TARGET = 0.1                   # MB/min, the run process
POSE_RATE_TARGET = 990.0               # Hz of sim time: the 1 kHz grid at the real-time target of 0.99
RESIM_RSS_TARGET, RESIM_WALL_TARGET = 500.0, 300.0    # MB, s: resim of the run's log
BIN = Path(sys.executable).parent
LOG_DIR = Path(os.environ.get('SOAK_LOG_DIR', 'out/soak'))     # the nodes' logs, one file per case and node
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))


def cpu_seconds(pid: int) -> float:
    """utime + stime (s) of a process."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def rss_mb(pid: int) -> float:
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024
    return float('nan')


def wave_settings(n: int) -> dict[str, list[float]]:
    """The settings of an n-actuator travelling wave (1 mm apart, phases (k mod 4)/4)."""
    return {'surface.centers': [round(k * 1e-3, 6) for k in range(n)], 'surface.widths': [1e-3] * n,
            'stroke.phases': [(k % 4) / 4 for k in range(n)]}


def feeder_args(n: int) -> list[str]:
    """--ros-args parameters of :func:`wave_settings`."""
    return [arg for name, value in wave_settings(n).items() for arg in ('-p', f'{name}:={value}')]


def slope_per_minute(t: list[float], y: list[float]) -> float:
    """Least-squares slope of y against t (s), per minute."""
    return float(np.polyfit(np.asarray(t), np.asarray(y), 1)[0] * 60.0) if len(t) > 2 else float('nan')


class Diagnostics:
    """A node of this process listening to ``/diagnostics``: the simulator's achieved real-time factor once a
    second while the actuator streams, and the latest status of each node."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('bench_soak', context=self.context)
        self.latest: dict[str, dict[str, str]] = {}
        self.rtf: list[float] = []
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, topic_qos('/diagnostics'))
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            self.latest[status.name.split(':')[0].strip('/')] = values
            if status.name.endswith('simulator: loop') and self.streaming():
                self.rtf.append(float(values['real_time_factor_achieved']))

    def streaming(self) -> bool:
        return self.latest.get('actuator', {}).get('streaming') == 'True'

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


def run_case(n: int, minutes: float, cpu_target: float, args: list[str] | None = None, name: str = '') -> dict:
    """The simulator and the actuator as separate processes for ``minutes`` of continuous strokes, with ``n``
    actuators (``args``: the ``-p`` arguments of both instead; ``name``: of the logs, default ``soak_{n}``)."""
    common = args or feeder_args(n)
    stem = name or f'soak_{n}'
    # logs go to files: a pipe nobody reads blocks a process once ~64 KiB of warnings are waiting in it
    logs = {name: (LOG_DIR / f'{stem}_{name}.log').open('w') for name in ('simulator', 'actuator')}
    sim = subprocess.Popen([str(BIN / 'simulator'), '--ros-args', *common], stdout=logs['simulator'],
                           stderr=subprocess.STDOUT)
    act = subprocess.Popen([str(BIN / 'actuator'), '--ros-args', *common, '-p', 'stroke.count:=0'],
                           stdout=logs['actuator'], stderr=subprocess.STDOUT)
    diagnostics = Diagnostics()
    latest, rtf, streaming, executor = diagnostics.latest, diagnostics.rtf, diagnostics.streaming, diagnostics.executor
    samples: list[tuple[float, float, float, float, float]] = []   # t, sim cpu, act cpu, sim rss, act rss
    try:
        deadline = time.monotonic() + 60.0
        while not streaming():
            executor.spin_once(timeout_sec=0.1)
            if time.monotonic() > deadline or sim.poll() is not None or act.poll() is not None:
                raise RuntimeError('the actuator did not start streaming within 60 s')
        start = time.monotonic()
        end = start + minutes * 60.0
        next_sample = start
        while (now := time.monotonic()) < end:
            for name, proc in (('simulator', sim), ('actuator', act)):
                if proc.poll() is not None:
                    raise RuntimeError(f'the {name} exited ({proc.returncode}) {now - start:.0f} s into the run; '
                                       f'its log: {LOG_DIR / f"{stem}_{name}.log"}')
            if now >= next_sample:
                samples.append((now - start, cpu_seconds(sim.pid), cpu_seconds(act.pid), rss_mb(sim.pid),
                                rss_mb(act.pid)))
                next_sample += 5.0
                done = (now - start) / (end - start)
                print(f'\r  {n} actuators: {done:5.1%}, RTF {rtf[-1] if rtf else float("nan"):.4f}', end='',
                      file=sys.stderr, flush=True)
            executor.spin_once(timeout_sec=0.1)
        samples.append((time.monotonic() - start, cpu_seconds(sim.pid), cpu_seconds(act.pid), rss_mb(sim.pid),
                        rss_mb(act.pid)))
        print(file=sys.stderr)
    finally:
        diagnostics.close()
        for proc in (act, sim):
            proc.send_signal(signal.SIGINT)
        for proc in (act, sim):
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                proc.kill()
        for log in logs.values():
            log.close()
    s = np.asarray(samples)
    wall = s[-1, 0] - s[0, 0]
    warm = s[:, 0] >= min(6.0, wall / 10)          # RSS settles once the first windows are out
    return {
        'actuators': n, 'minutes': wall / 60.0,
        'rtf_median': statistics.median(rtf) if rtf else float('nan'), 'rtf_min': min(rtf, default=float('nan')),
        'sim_cpu_pct': 100.0 * (s[-1, 1] - s[0, 1]) / wall, 'act_cpu_pct': 100.0 * (s[-1, 2] - s[0, 2]) / wall,
        'sim_rss_mb_per_min': slope_per_minute(list(s[warm, 0]), list(s[warm, 3])),
        'act_rss_mb_per_min': slope_per_minute(list(s[warm, 0]), list(s[warm, 4])),
        'sim_rss_mb': s[-1, 3], 'act_rss_mb': s[-1, 4], 'cpu_target': cpu_target,
        'underruns': latest.get('actuator', {}).get('stream_underruns', '?'),
        'windows': latest.get('actuator', {}).get('windows_sent', '?'),
        'rejected': latest.get('simulator', {}).get('rejected_commands', '?'),
        'warnings': {name: warnings_in(LOG_DIR / f'{stem}_{name}.log') for name in ('simulator', 'actuator')},
    }


def run_record_case(minutes: float, settings: dict[str, object] | None = None, name: str = 'soak_run') -> dict:
    """``micro-feeder run --record`` for ``minutes`` (one process: simulator, actuator, recorder; ``settings``
    on top of the defaults), then ``micro-feeder resim`` of its log (``LOG_DIR/<name>_log``)."""
    from long_log import measure

    from micro_feeder.logs.reader import LogReader
    log = LOG_DIR / f'{name}_log'
    shutil.rmtree(log, ignore_errors=True)
    output = (LOG_DIR / f'{name}.log').open('w')
    extra = [arg for key, value in (settings or {}).items() for arg in ('--set', f'{key}={value}')]
    proc = subprocess.Popen([str(BIN / 'micro-feeder'), 'run', '--set', 'stroke.count=0', *extra, '--record', str(log),
                             '--duration', f'{minutes * 60.0:g}'], stdout=output, stderr=subprocess.STDOUT)
    diagnostics = Diagnostics()
    samples: list[tuple[float, float, float]] = []   # t, cpu, rss
    try:
        deadline = time.monotonic() + 60.0
        while not diagnostics.streaming():
            diagnostics.executor.spin_once(timeout_sec=0.1)
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError(f'the run did not start streaming within 60 s; its output: {output.name}')
        start = next_sample = time.monotonic()
        while proc.poll() is None:
            now = time.monotonic()
            if now >= next_sample:
                samples.append((now - start, cpu_seconds(proc.pid), rss_mb(proc.pid)))
                next_sample += 5.0
                rtf = diagnostics.rtf[-1] if diagnostics.rtf else float('nan')
                print(f'\r  run --record: {(now - start) / (minutes * 60.0):5.1%}, RTF {rtf:.4f}', end='',
                      file=sys.stderr, flush=True)
            diagnostics.executor.spin_once(timeout_sec=0.1)
        print(file=sys.stderr)
    finally:
        diagnostics.close()
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
        output.close()
    s = np.asarray([row for row in samples if not np.isnan(row[2])])
    wall = s[-1, 0] - s[0, 0]
    warm = s[:, 0] >= min(6.0, wall / 10)
    steady = s[:, 0] >= s[0, 0] + wall / 2       # the allocator's arenas grow 2-3 MB in the first minutes, then stop
    reader = LogReader(log)
    stamps = np.fromiter((m.stamp_ns for m in reader.messages(['particle/pose'])), dtype=np.int64)
    summary = Path(output.name).read_text()
    resim = measure(['resim', str(log)], rss_cap_mb=4 * RESIM_RSS_TARGET, timeout=4 * RESIM_WALL_TARGET)
    return {
        'minutes': wall / 60.0, 'status': proc.returncode,
        'rtf_median': statistics.median(diagnostics.rtf) if diagnostics.rtf else float('nan'),
        'rtf_min': min(diagnostics.rtf, default=float('nan')),
        'run_rtf': next((line.split('real-time factor ')[1].rstrip(')') for line in summary.splitlines()
                         if line.startswith('sim time')), '?'),
        'cpu_pct': 100.0 * (s[-1, 1] - s[0, 1]) / wall,
        'rss_mb_per_min': slope_per_minute(list(s[steady, 0]), list(s[steady, 2])),
        'rss_mb_per_min_whole': slope_per_minute(list(s[warm, 0]), list(s[warm, 2])),
        'rss_mb': s[-1, 2], 'poses': stamps.size, 'max_gap_ms': float(np.max(np.diff(stamps))) * 1e-6,
        'pose_rate_hz': (stamps.size - 1) / ((stamps[-1] - stamps[0]) * 1e-9),
        'lost': reader.recorder_info.get('lost_total', '?'),
        'received': reader.recorder_info.get('received_total', '?'),
        'underruns': diagnostics.latest.get('actuator', {}).get('stream_underruns', '?'),
        'warnings': warnings_in(Path(output.name)), 'log': log, 'output': output.name,
        'resim': resim,
    }


def run_report(r: dict) -> str:
    resim = r['resim']
    verdict = resim['stdout'].splitlines()[0] if resim['stdout'] else f'(no verdict: {resim["stderr"][-1:]})'
    return '\n'.join([
        f"micro-feeder run --record, 1 actuator, {r['minutes']:.2f} min of continuous strokes (exit {r['status']}; "
        f"{r['underruns']} underruns; warnings logged {r['warnings']}, in {r['output']})",
        f"  real-time factor median {r['rtf_median']:.4f} (min {r['rtf_min']:.4f}; the run's own summary "
        f"{r['run_rtf']})   target >= 0.99  {ok(r['rtf_median'] >= 0.99)}",
        f"  RSS growth over the second half {r['rss_mb_per_min']:+.3f} MB/min (from 6 s on "
        f"{r['rss_mb_per_min_whole']:+.3f}; {r['rss_mb']:.0f} MB at the end)   target < "
        f"{RUN_RSS_TARGET:g} MB/min  {ok(r['rss_mb_per_min'] < RUN_RSS_TARGET)}   (CPU {r['cpu_pct']:.1f} % of a core)",
        f"  log {r['log']}: {r['poses']:,} poses ({r['pose_rate_hz']:.0f} per sim second, target >= "
        f"{POSE_RATE_TARGET:.0f}), "
        f"largest stamp gap {r['max_gap_ms']:.3f} ms, lost {r['lost']} of "
        f"{r['received']} received",
        f"  resim of the log: peak RSS {resim['peak_mb']:.0f} MB   target <= {RESIM_RSS_TARGET:g} MB  "
        f"{ok(resim['peak_mb'] <= RESIM_RSS_TARGET and not resim['killed'])}; wall {resim['wall_s']:.0f} s   target <= "
        f"{RESIM_WALL_TARGET:g} s  {ok(resim['wall_s'] <= RESIM_WALL_TARGET and not resim['killed'])}"
        + (f" ({resim['killed']})" if resim['killed'] else ''),
        f"  {verdict}",
    ])


def warnings_in(log: Path) -> int:
    """Lines at WARN level or above in a node's log."""
    return sum(line.startswith(('[WARN]', '[ERROR]', '[FATAL]')) for line in log.read_text().splitlines())


def ok(good: bool) -> str:
    return 'ok' if good else 'MISSED'


def report(r: dict) -> str:
    return '\n'.join([
        f"{r['actuators']} actuator(s), {r['minutes']:.2f} min of continuous strokes "
        f"({r['windows']} windows, {r['underruns']} underruns, {r['rejected']} rejected; warnings logged: "
        f"simulator {r['warnings']['simulator']}, actuator {r['warnings']['actuator']}, in {LOG_DIR})",
        f"  real-time factor median {r['rtf_median']:.4f} (min {r['rtf_min']:.4f})   target >= 0.99  "
        f"{ok(r['rtf_median'] >= 0.99)}",
        f"  simulator CPU {r['sim_cpu_pct']:.1f} % of a core   target <= {r['cpu_target']:g} %  "
        f"{ok(r['sim_cpu_pct'] <= r['cpu_target'])}   (actuator {r['act_cpu_pct']:.1f} %)",
        f"  RSS growth simulator {r['sim_rss_mb_per_min']:+.3f} MB/min ({r['sim_rss_mb']:.0f} MB), actuator "
        f"{r['act_rss_mb_per_min']:+.3f} MB/min ({r['act_rss_mb']:.0f} MB)   target < 1 MB/min  "
        f"{ok(max(r['sim_rss_mb_per_min'], r['act_rss_mb_per_min']) < 1.0)}",
    ])


def case_figures(r: dict) -> list[dict]:
    """The JSON figures of one case."""
    n = r['actuators']
    rss = max(r['sim_rss_mb_per_min'], r['act_rss_mb_per_min'])
    counts = [_count(r['underruns']), _count(r['rejected'])]
    faults = None if None in counts else sum(counts)
    return [
        figure(f'rtf_median_{n}', f'{n} actuator(s), {r["minutes"]:.1f} min streamed: median real-time factor',
               round(r['rtf_median'], 4), '', op='>=', target=0.99, note=f'min {r["rtf_min"]:.4f}'),
        figure(f'sim_cpu_{n}_pct', f'{n} actuator(s): simulator CPU, % of one core', round(r['sim_cpu_pct'], 1), '%',
               op='<=', target=r['cpu_target'], note=f'actuator {r["act_cpu_pct"]:.1f} %'),
        figure(f'rss_growth_{n}', f'{n} actuator(s): RSS growth, the larger of simulator and actuator', round(rss, 3),
               'MB/min', op='<', target=1.0,
               note=f'simulator {r["sim_rss_mb_per_min"]:+.3f} ({r["sim_rss_mb"]:.0f} MB), actuator '
                    f'{r["act_rss_mb_per_min"]:+.3f} ({r["act_rss_mb"]:.0f} MB)'),
        figure(f'underruns_rejected_{n}', f'{n} actuator(s): stream underruns + rejected commands',
               faults, '', op='==', target=0,
               note=f'{r["underruns"]} underruns, {r["rejected"]} rejected, {r["windows"]} windows; warnings logged: '
                    f'simulator {r["warnings"]["simulator"]}, actuator {r["warnings"]["actuator"]}'),
    ]


def run_figures(r: dict) -> list[dict]:
    """The run case's figures for bench/results/bench_soak.json."""
    resim = r['resim']
    return [
        figure('run_rtf_median', f'micro-feeder run --record, {r["minutes"]:.1f} min streamed: median real-time factor',
               round(r['rtf_median'], 4), '', op='>=', target=0.99, note=f'min {r["rtf_min"]:.4f}'),
        figure('run_rss_mb_per_min', 'micro-feeder run --record: RSS growth over the second half of the run',
               round(r['rss_mb_per_min'], 3), 'MB/min', op='<', target=RUN_RSS_TARGET,
               note=f'from 6 s on {r["rss_mb_per_min_whole"]:+.3f} MB/min (the allocator warming up); '
                    f'CPU {r["cpu_pct"]:.1f} % of a core'),
        figure('run_lost', 'micro-feeder run --record: messages the recorder lost', _count(r['lost']), '', op='<=',
               target=0,
               note=f'{r["poses"]:,} poses, largest stamp gap {r["max_gap_ms"]:.3f} ms'),
        figure('run_pose_rate_hz', 'micro-feeder run --record: poses published per second of sim time',
               round(r['pose_rate_hz'], 1), 'Hz', op='>=', target=POSE_RATE_TARGET,
               note='a tick that comes late skips the 1 ms grid points it missed'),
        figure('run_resim_peak_mb', 'resim of that log: peak RSS', round(resim['peak_mb']), 'MB', op='<=',
               target=RESIM_RSS_TARGET, note=resim['killed'] or f'wall {resim["wall_s"]:.0f} s'),
    ]


def _count(value: str | int) -> int | None:
    """A count read from /diagnostics ('?' when it never came)."""
    try:
        return int(value)
    except (TypeError, ValueError):
        return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, help='minutes per case (default: 10 / 10 / 2 / 10)')
    parser.add_argument('--cases', default='1,16,64,run',
                        help='cases to run: actuator counts (of 1, 16, 64) and run (micro-feeder run --record)')
    results_json.add_arguments(parser, 'bench_soak')
    args = parser.parse_args()
    if args.cases == 'run' and args.json == results_json.RESULTS / 'bench_soak.json':
        args.json = results_json.RESULTS / 'bench_soak_run.json'    # its own page section, not the soak's
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    print(f'load average before: {os.getloadavg()}')
    figures = []
    for case in args.cases.split(','):
        if case == 'run':
            result = run_record_case(args.minutes or RUN_MINUTES)
            print(run_report(result), flush=True)
            figures += run_figures(result)
            continue
        minutes, cpu_target = CASES[int(case)]
        result = run_case(int(case), args.minutes or minutes, cpu_target)
        print(report(result), flush=True)
        figures += case_figures(result)
    print(f'load average after: {os.getloadavg()}')
    title = ('Continuous strokes recorded in one process (run --record soak)' if args.cases == 'run'
             else 'Continuous strokes (soak)')
    results_json.save(args, 'bench_soak', title, figures, load_before=load,
                      seconds=time.perf_counter() - started,
                      purpose='stroke.count 0, streamed by the actuator to the simulator at 1 kHz, ' +
                              ('in one process with the recorder (micro-feeder run --record), then resim of its log'
                               if args.cases == 'run' else 'separate processes') +
                              ', for minutes: real-time factor, CPU, memory growth, underruns.')


if __name__ == '__main__':
    main()
