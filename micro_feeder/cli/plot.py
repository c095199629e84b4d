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
    times, tables = zip(*[(table[0, fields.index('t')], table) for labels, table in rows if labels == fields],
                        strict=True)
    names, tables = _follow_parts(list(times), list(tables), _entity_changes(log))
    t = np.asarray(times)
    keep = ((args.start is None) | (t >= (args.start or 0.0))) & ((args.end is None) | (t <= (args.end or np.inf)))
    output = Path(args.output)
    path = output.with_name(f'{output.stem}_parts{output.suffix or ".png"}')
    try:
        return plot_positions(t[keep], tables[keep, :, fields.index('x')], tables[keep, :, fields.index('mode')],
                              path, f'{tables.shape[1]} parts of {log.path.name}: position against time '
                              '(impacts are not recorded)', names=names)
    except OSError as err:
        raise CommandError(f'cannot write {path}: {err}') from None


def _entity_changes(log) -> list:
    """The parts spawned and deleted during the run (``simulator/entity_changes``), in time order."""
    from ..interface.entity_changes import read_entity_changes
    from ..interface.topics import ENTITY_CHANGES

    if log.resolve(ENTITY_CHANGES) is None:
        return []
    return sorted((change for m in log.messages([ENTITY_CHANGES], decoded=True)
                   for change in read_entity_changes(m.message)), key=lambda change: change.t)


def _follow_parts(times: list, tables: list, changes: list):
    """(entity names, (rows, parts, fields) array): each part in its own column through spawns and deletes,
    NaN where it is not there. Row k holds the parts in order along the feeder at ``times[k]``; a change made
    at sim time t shows from the first row after t (the simulator publishes before it changes the parts)."""
    import numpy as np

    from ..interface.names import part_entity

    present = [part_entity(k) for k in range(tables[0].shape[0])]
    names = list(present)
    rows, pending = [], list(changes)
    for t, table in zip(times, tables, strict=True):
        while pending and pending[0].t < t:
            change = pending.pop(0)
            if change.kind == 'spawned':
                present.insert(min(change.part, len(present)), change.entity)
                if change.entity not in names:
                    names.append(change.entity)
            elif change.entity in present:
                present.remove(change.entity)
        row = np.full((len(names), table.shape[1]), np.nan)
        if len(present) == table.shape[0]:             # else the record and the poses disagree: the row is left out
            row[[names.index(name) for name in present]] = table
        rows.append(row)
    width = len(names)
    return names, np.stack([np.vstack([row, np.full((width - row.shape[0], row.shape[1]), np.nan)]) for row in rows])
