"""Long logs: peak memory, wall time, progress and Ctrl-C of ``micro-feeder resim``, ``export`` and ``info``.

Writes (or reuses) a log of continuous 1 kHz strokes like ``micro-feeder run --set stroke.count=0 --record``
makes (``test/long_log.py``: the simulator's own stepper and serializers, the actuator's streamed windows,
re-simulated bit for bit), then runs each command on it as a separate process and reports, per command:

* peak RSS (``VmHWM``, sampled every 0.1 s and read by the process itself at exit): target <= 500 MB for
  a 1-hour log;
* wall time, and when the first progress line came (``resim`` and ``export``, on stderr after 2 s);
* Ctrl-C (a second run of each command that took longer than that): SIGINT sent ``--sigint-after`` s
  into the run, time to exit (target < 1 s), exit status (130) and whether a traceback was printed.

A command whose RSS passes ``--rss-cap`` MB or that runs longer than ``--timeout`` s is killed and reported
as such (the figures up to then are kept).

    .venv/bin/python bench/bench_long_logs.py [--minutes 10] [--log DIR] [--commands resim,export,info]
                                              [--json PATH | --no-json]

Results: bench/results/bench_long_logs.json.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT / 'bench'))
import results_json  # noqa: E402
from long_log import measure, write_long_log  # noqa: E402  (test/long_log.py: the log and the measuring)
from results_json import figure  # noqa: E402

RSS_TARGET_MB = 500.0      # peak RSS of any log command, whatever the log's length
SIGINT_TARGET_S = 1.0      # s from Ctrl-C to exit


def report(name: str, r: dict) -> str:
    out = [f'{name}: peak RSS {r["peak_mb"]:.0f} MB, wall {r["wall_s"]:.1f} s, exit {r["status"]}'
           + (f' ({r["killed"]})' if r['killed'] else '')
           + (f', first progress line at {r["first_progress_s"]:.1f} s' if r['first_progress_s'] is not None
              else ', no progress line')]
    if r['sigint_to_exit_s'] is not None:
        traceback = any('Traceback' in line for line in r['stderr'])
        out.append(f'  Ctrl-C: exited {r["sigint_to_exit_s"]:.2f} s after SIGINT, status {r["status"]}, '
                   f'traceback: {"YES" if traceback else "no"}')
    out += [f'  | {line}' for line in r['stderr'][-3:] + r['stdout'].splitlines()[:1]]
    return '\n'.join(out)


def command_figures(command: str, minutes: float, r: dict, interrupted: dict | None) -> list[dict]:
    """The figures of one command on the log, for bench/results/bench_long_logs.json."""
    what = f'{command} of a {minutes:g}-minute log'
    figures = [figure(f'{command}_peak_mb', f'{what}: peak RSS', round(r['peak_mb']), 'MB', op='<=',
                      target=RSS_TARGET_MB, met=None if not r['killed'] else False,
                      note=r['killed'] or f'exit {r["status"]}'),
               figure(f'{command}_wall_s', f'{what}: wall time', round(r['wall_s'], 1), 's',
                      note='first progress line at '
                           + (f'{r["first_progress_s"]:.1f} s' if r['first_progress_s'] is not None else '(none)'))]
    if interrupted is not None and interrupted['sigint_to_exit_s'] is not None:
        traceback = any('Traceback' in line for line in interrupted['stderr'])
        figures.append(figure(f'{command}_sigint_s', f'{what}: Ctrl-C to exit',
                              round(interrupted['sigint_to_exit_s'], 2), 's', op='<=', target=SIGINT_TARGET_S,
                              met=interrupted['sigint_to_exit_s'] <= SIGINT_TARGET_S and interrupted['status'] == 130
                              and not traceback,
                              note=f'exit {interrupted["status"]}, traceback {"YES" if traceback else "no"}'))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0, help='sim time of the synthesized log (default 10)')
    parser.add_argument('--log', help='log to use (written there first when it does not exist)')
    parser.add_argument('--commands', default='info,export,resim', help='which commands to run')
    parser.add_argument('--rss-cap', type=float, default=6000.0, help='MB: kill a command above this (default 6000)')
    parser.add_argument('--timeout', type=float, default=1800.0, help='s: kill a command after this (default 1800)')
    parser.add_argument('--sigint-after', type=float, default=10.0,
                        help='s into a second run of each command to send SIGINT (0: no Ctrl-C runs)')
    results_json.add_arguments(parser, 'bench_long_logs')
    args = parser.parse_args()
    load, started, figures = [round(x, 2) for x in os.getloadavg()], time.perf_counter(), []
    scratch = Path(tempfile.mkdtemp(prefix='bench_long_logs_'))
    log = Path(args.log) if args.log else scratch / 'log'
    try:
        if not log.exists():
            started = time.monotonic()
            counts = write_long_log(log, args.minutes * 60.0, progress=True)
            print(f'wrote {log}: {counts} in {time.monotonic() - started:.0f} s')
        size = sum(f.stat().st_size for f in ([log] if log.is_file() else log.glob('*.mcap')))
        print(f'log {log}: {size / 2**20:.0f} MiB; load average {os.getloadavg()}', flush=True)
        for command in args.commands.split(','):
            extra = {'export': ['--csv', str(scratch / 'csv')]}.get(command, [])
            r = measure([command, str(log), *extra], rss_cap_mb=args.rss_cap, timeout=args.timeout)
            print(report(command, r), flush=True)
            shutil.rmtree(scratch / 'csv', ignore_errors=True)
            interrupted = None
            if 0 < args.sigint_after < r['wall_s'] - 2:        # long enough to be interrupted
                interrupted = measure([command, str(log), *extra], rss_cap_mb=args.rss_cap, timeout=args.timeout,
                                      sigint_after=args.sigint_after)
                print(report(f'{command} + Ctrl-C at {args.sigint_after:g} s', interrupted), flush=True)
                shutil.rmtree(scratch / 'csv', ignore_errors=True)
            figures += command_figures(command, args.minutes, r, interrupted)
        print(f'load average after: {os.getloadavg()}')
        results_json.save(args, 'bench_long_logs', 'Long logs: resim, info, export', figures, load_before=load,
                          seconds=time.perf_counter() - started,
                          purpose=f'log commands on {size / 2**20:.0f} MiB of continuous 1 kHz strokes (what run '
                                  '--record writes, synthesized by test/long_log.py): memory that does not grow '
                                  'with the log, progress, Ctrl-C')
    finally:
        shutil.rmtree(scratch / 'csv', ignore_errors=True)
        if not args.log:
            shutil.rmtree(scratch, ignore_errors=True)


if __name__ == '__main__':
    main()
