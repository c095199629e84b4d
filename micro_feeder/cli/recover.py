"""``micro-feeder recover BROKEN OUT``: rewrite a crashed recording as a complete log."""

from __future__ import annotations

import argparse

from ..logs.metadata import LogFormatError
from ..logs.recover import recover
from . import CommandError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser('recover', help='rewrite a truncated log as a complete one',
                                   description='Read a log whose recorder was killed (up to its last whole '
                                               'chunk) or whose files are damaged (every undamaged chunk) and '
                                               'write those messages as a new, complete log; lists what was '
                                               'dropped and where.')
    parser.add_argument('broken', metavar='BROKEN', help='log directory or .mcap file')
    parser.add_argument('output', metavar='OUT', help='new log directory, or a file name ending in .mcap')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        result = recover(args.broken, args.output)
    except (OSError, LogFormatError) as err:
        raise CommandError(str(err)) from None
    state = [f'{len(result.truncated)} truncated file(s) read to their last whole chunk'] if result.truncated else []
    if result.damage:
        dropped = 'an unknown number of' if result.dropped is None else f'{result.dropped:,}'
        state.append(f'{dropped} messages dropped; {len(result.damage)} damaged part(s), listed below')
    print(f'recovered {result.messages:,} messages into {result.output} '
          f'({"; ".join(state) or "the source was complete and undamaged"})')
    for damage in result.damage:
        print(f'  dropped: {damage}')
    return 0
