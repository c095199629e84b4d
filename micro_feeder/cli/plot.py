"""``micro-feeder plot LOG -o FILE.png``: position, velocity, mode, friction and normal load vs time."""

from __future__ import annotations

import argparse

from . import CommandError
from ._logs import open_log, report_loss


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser('plot', help='plot the part motion of a log',
                                   description='Plot position, velocity, contact mode, friction and normal '
                                               'load vs time from a log (PNG).')
    parser.add_argument('log', metavar='LOG', help='log directory or .mcap file')
    parser.add_argument('-o', '--output', metavar='FILE.png', required=True, help='image to write')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..logs.plot import plot_log  # matplotlib only when plotting

    log = open_log(args.log)
    try:
        path = plot_log(log, args.output)
    except OSError as err:
        raise CommandError(f'cannot write {args.output}: {err}') from None
    print(f'wrote {path}')
    report_loss(log)
    return 0
