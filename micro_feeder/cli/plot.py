"""``micro-feeder plot LOG -o FILE.png [--start S] [--end S]``: strokes, displacement, velocity, friction
against ±Q_max, normal load, height in flight and mode vs sim time, zoomed to where something happens."""

from __future__ import annotations

import argparse
from pathlib import Path

from . import CommandError
from ._logs import open_log, report_loss


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser('plot', help='plot the part motion of a log',
                                   description='Plot the commanded strokes, the part\'s displacement and '
                                               'velocity, friction against ±Q_max, normal load, height in '
                                               'flight and contact mode vs sim time from a log (PNG). By '
                                               'default the time axis spans where something happens.')
    parser.add_argument('log', metavar='LOG', help='log directory or .mcap file')
    parser.add_argument('-o', '--output', metavar='FILE.png', required=True, help='image to write')
    parser.add_argument('--start', type=float, metavar='S', help='start of the time window (s, sim time)')
    parser.add_argument('--end', type=float, metavar='S', help='end of the time window (s, sim time)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..plots.log import plot_log  # matplotlib only when plotting

    log = open_log(args.log, 'plot')
    try:
        path = plot_log(log, args.output, start=args.start, end=args.end)
    except OSError as err:
        raise CommandError(f'cannot write {args.output}: {err}') from None
    except ValueError as err:
        raise CommandError(str(err)) from None
    print(f'wrote {path}')
    parts = _plot_parts(log, args)
    if parts is not None:
        print(f'wrote {parts} (every part against time)')
    report_loss(log)
    return 0


def _plot_parts(log, args: argparse.Namespace):
    """With several parts (``particles/states``), their space–time picture beside the output
    (``NAME_parts.png``); None with one part."""
    import numpy as np

    from ..plots.parts import plot_positions

    rows = []
    for m in log.messages(['particles/states'], decoded=True):
        dims = m.message.layout.dim
        if len(dims) == 2 and dims[0].size > 0:
            rows.append((dims[1].label.split(','), np.asarray(m.message.data).reshape(dims[0].size, dims[1].size)))
    if not rows or max(table.shape[0] for _, table in rows) < 2:
        return None
    fields = rows[0][0]
    same = [table for labels, table in rows if labels == fields]
    changed = len({table.shape for table in same}) > 1
    tables = _stack_parts(same)
    t = tables[:, 0, fields.index('t')]
    t = np.where(np.isnan(t), np.roll(t, -1), t)       # a row between two numbers of parts: the next row's time
    keep = ((args.start is None) | (t >= (args.start or 0.0))) & ((args.end is None) | (t <= (args.end or np.inf)))
    output = Path(args.output)
    path = output.with_name(f'{output.stem}_parts{output.suffix or ".png"}')
    try:
        return plot_positions(t[keep], tables[keep, :, fields.index('x')], tables[keep, :, fields.index('mode')],
                              path, f'{tables.shape[1]} parts of {log.path.name}: position against time '
                              '(impacts are not recorded)' + (' - parts spawned or deleted: a line ends where the '
                                                              'parts changed' if changed else ''))
    except OSError as err:
        raise CommandError(f'cannot write {path}: {err}') from None


def _stack_parts(tables: list):
    """(rows, parts, fields) of per-message (parts, fields) tables whose number of parts changes (parts spawned
    or deleted): padded with NaN to the most parts, and a NaN row where the number changes, so that no line joins
    a part before the change to another after it."""
    import numpy as np

    most = max(table.shape[0] for table in tables)
    out, last = [], tables[0].shape[0]
    for table in tables:
        if table.shape[0] != last:
            out.append(np.full((most, table.shape[1]), np.nan))
            last = table.shape[0]
        out.append(np.vstack([table, np.full((most - table.shape[0], table.shape[1]), np.nan)]))
    return np.stack(out)
