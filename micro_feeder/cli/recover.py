"""``micro-feeder recover BROKEN OUT``: rewrite a crashed recording as a complete log."""

from __future__ import annotations

import argparse

from ..logs.metadata import LogFormatError
from ..logs.recover import recover
from . import CommandError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser('recover', help='rewrite a truncated log as a complete one',
                                   description='Read a log whose recorder was killed up to its last whole '
                                               'chunk and write those messages as a complete log.')
    parser.add_argument('broken', metavar='BROKEN', help='log directory or .mcap file')
    parser.add_argument('output', metavar='OUT', help='new log directory, or a file name ending in .mcap')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        result = recover(args.broken, args.output)
    except (OSError, LogFormatError) as err:
        raise CommandError(str(err)) from None
    state = (f'{len(result.truncated)} truncated file(s) read to their last whole chunk'
             if result.truncated else 'the source was complete')
    print(f'recovered {result.messages:,} messages into {result.output} ({state})')
    return 0
