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
from long_log import measure, write_long_log  # noqa: E402  (test/long_log.py: the log and the measuring)


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=10.0, help='sim time of the synthesized log (default 10)')
    parser.add_argument('--log', help='log to use (written there first when it does not exist)')
    parser.add_argument('--commands', default='info,export,resim', help='which commands to run')
    parser.add_argument('--rss-cap', type=float, default=6000.0, help='MB: kill a command above this (default 6000)')
    parser.add_argument('--timeout', type=float, default=1800.0, help='s: kill a command after this (default 1800)')
    parser.add_argument('--sigint-after', type=float, default=10.0,
                        help='s into a second run of each command to send SIGINT (0: no Ctrl-C runs)')
    args = parser.parse_args()
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
            if 0 < args.sigint_after < r['wall_s'] - 2:        # long enough to be interrupted
                r = measure([command, str(log), *extra], rss_cap_mb=args.rss_cap, timeout=args.timeout,
                            sigint_after=args.sigint_after)
                print(report(f'{command} + Ctrl-C at {args.sigint_after:g} s', r), flush=True)
                shutil.rmtree(scratch / 'csv', ignore_errors=True)
        print(f'load average after: {os.getloadavg()}')
    finally:
        shutil.rmtree(scratch / 'csv', ignore_errors=True)
        if not args.log:
            shutil.rmtree(scratch, ignore_errors=True)


if __name__ == '__main__':
    main()
