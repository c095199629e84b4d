"""``micro-feeder export LOG --csv DIR``: one CSV per topic."""

from __future__ import annotations

import argparse

from ..logs.export import export_csv
from ..progress import Progress
from . import CommandError
from ._logs import open_log, report_loss


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser('export', help='export a log to CSV',
                                   description='Export a log to CSV: one file per topic, one row per message, '
                                               'one column per field (log_time_ns, stamp_ns = header stamp first).')
    parser.add_argument('log', metavar='LOG', help='log directory or .mcap file')
    parser.add_argument('--csv', metavar='DIR', required=True, help='directory for the CSV files')
    parser.add_argument('--topic', action='append', dest='topics', metavar='TOPIC',
                        help='export only this topic (repeatable; relative names match any namespace)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    log = open_log(args.log, 'export')
    progress = Progress('export', 0, 'messages')
    try:
        paths = export_csv(log, args.csv, args.topics, progress=progress)
    except OSError as err:
        raise CommandError(f'cannot write {args.csv}: {err}') from None
    finally:
        progress.close()
    for path in paths:
        print(path)
    report_loss(log)
    return 0
