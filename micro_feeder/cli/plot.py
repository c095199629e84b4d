"""``micro-feeder plot LOG -o FILE.png [--start S] [--end S]``: strokes, displacement, velocity, friction
against ±Q_max, normal load, height in flight and mode vs sim time, zoomed to where something happens."""

from __future__ import annotations

import argparse

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
    report_loss(log)
    return 0
