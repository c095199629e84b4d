"""Benchmark results as JSON: each bench/bench_*.py writes bench/results/<name>.json with its figures, their
targets and the machine it ran on; bench/report.py builds docs/performance.md and README's table from them.

One file per benchmark, replaced by its next run (``--json PATH`` writes elsewhere, ``--no-json`` nowhere).
A figure is a dict made by :func:`figure`: a key, what it measures, its value (a number, or a text for a
range), the unit, the target (comparison and value, or none for a figure that is only reported) and
whether the target is met.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RESULTS = BENCH / 'results'
SCHEMA = 1
OPS = {'<=': lambda v, t: v <= t, '>=': lambda v, t: v >= t, '<': lambda v, t: v < t, '>': lambda v, t: v > t,
       '==': lambda v, t: v == t}


def figure(key: str, what: str, value: float | int | str | None, unit: str = '', *, op: str | None = None,
           target: float | int | None = None, met: bool | None = None, shown: str | None = None,
           note: str = '') -> dict[str, Any]:
    """One figure. With ``op`` and ``target`` (e.g. '<=', 100) ``met`` is worked out from a numeric value
    unless given; ``shown`` is how to print the value (default: the value and the unit)."""
    if op is not None and op not in OPS:
        raise ValueError(f'unknown comparison {op!r}')
    if met is None and op is not None and isinstance(value, int | float):
        met = bool(OPS[op](value, target))
    return {'key': key, 'what': what, 'value': _plain(value), 'unit': unit,
            'target': None if op is None else {'op': op, 'value': target},
            'met': met, 'shown': shown, 'note': note}


def add_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    """``--json PATH`` / ``--no-json`` on a benchmark's command line."""
    parser.add_argument('--json', type=Path, default=RESULTS / f'{name}.json', metavar='PATH',
                        help=f'write the results here (default: bench/results/{name}.json)')
    parser.add_argument('--no-json', action='store_true', help='write no results file')


def machine() -> dict[str, Any]:
    """What the figures depend on: cores (nproc), CPU model, Python, the OS, the load averages now."""
    model = ''
    try:
        for line in Path('/proc/cpuinfo').read_text().splitlines():
            if line.startswith('model name'):
                model = line.split(':', 1)[1].strip()
                break
    except OSError:
        pass
    return {'cores': os.cpu_count(), 'cpu': model or platform.processor(), 'python': platform.python_version(),
            'system': f'{platform.system()} {platform.release()} {platform.machine()}',
            'load_average': [round(x, 2) for x in os.getloadavg()]}


def commit() -> str | None:
    """The commit the tree is at, with '+changes' when the package has uncommitted changes."""
    try:
        head = subprocess.run(['git', 'rev-parse', '--short', 'HEAD'], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(['git', 'status', '--porcelain', '--', 'micro_feeder'], cwd=ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return head + ('+changes' if dirty else '')


def save(args: argparse.Namespace, name: str, title: str, figures: list[dict[str, Any]], *,
         purpose: str = '', notes: list[str] | tuple[str, ...] = (), load_before: list[float] | None = None,
         seconds: float | None = None, command: str | None = None) -> Path | None:
    """Write the results file (unless ``--no-json``) and say where. ``command``: how to reproduce the
    figures, when not this script with its arguments (a benchmark run by another one)."""
    if args.no_json:
        return None
    command = command or ' '.join(['.venv/bin/python', f'bench/{name}.py', *_user_arguments()])
    data = {
        'schema': SCHEMA, 'benchmark': name, 'title': title, 'purpose': purpose, 'command': command,
        'source': f'measured by bench/{name}.py',
        'date': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC'),
        'commit': commit(), 'machine': {**machine(), 'load_average_before': load_before},
        'wall_seconds': None if seconds is None else round(seconds, 1),
        'figures': figures, 'notes': list(notes),
    }
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(data, indent=1, ensure_ascii=False) + '\n')
    print(f'results written to {_shown_path(args.json)}')
    return args.json


def _user_arguments() -> list[str]:
    """The command-line arguments that change what is measured (not where the JSON goes)."""
    out, skip = [], False
    for arg in sys.argv[1:]:
        if skip:
            skip = False
        elif arg == '--json':
            skip = True
        elif not arg.startswith('--json=') and arg != '--no-json':
            out.append(arg)
    return out


def _shown_path(path: Path) -> str:
    try:
        return str(path.resolve().relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def _plain(value: Any) -> Any:
    """numpy scalars and NaN made JSON-friendly (NaN -> None)."""
    if hasattr(value, 'item'):
        value = value.item()
    if isinstance(value, float) and value != value:
        return None
    return value
