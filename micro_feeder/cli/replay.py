"""``micro-feeder replay LOG``: run the replay node on a log."""

from __future__ import annotations

import argparse
import math
import os

from . import CommandError
from ._foxglove import add_foxglove_option, live_view


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser('replay', help='publish a log on its topics at recorded timing',
                                   description='Publish a log\'s messages on their topics at their recorded '
                                               'timing × RATE (the replay node; Ctrl-C stops).')
    parser.add_argument('log', metavar='LOG', help='log directory or .mcap file')
    parser.add_argument('--rate', type=float, default=1.0, help='playback speed factor (default 1)')
    parser.add_argument('--loop', action='store_true', help='start again after the end')
    parser.add_argument('--start-offset', type=float, default=0.0, metavar='S', help='skip S seconds')
    parser.add_argument('--topic', action='append', dest='topics', default=[], metavar='TOPIC',
                        help='replay only this topic (repeatable)')
    parser.add_argument('--remap', action='append', default=[], metavar='FROM:=TO', help='rename a topic')
    parser.add_argument('--clock', action='store_true', help='publish the playback time on /clock')
    add_foxglove_option(parser)
    parser.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    """Refuse what the replay node would refuse, with the option's name."""
    if not 0.01 <= args.rate <= 100.0:
        raise CommandError(f'--rate {args.rate}: must be within [0.01, 100]')
    if not (math.isfinite(args.start_offset) and 0.0 <= args.start_offset <= 1e9):
        raise CommandError(f'--start-offset {args.start_offset}: must be within [0, 1e9] s')
    for rule in args.remap:
        source, sep, target = rule.partition(':=')
        if not (sep and source and target):
            raise CommandError(f'--remap {rule}: must be FROM:=TO')


def run(args: argparse.Namespace) -> int:
    _check(args)
    # DESIGN §2: ROS traffic stays on this host unless the user sets the range (rcl reads it at init).
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    from ..nodes.replay import main as replay_main  # rclpy only when replaying, after the environment

    def strings(values: list[str]) -> str:
        return '[' + ','.join(f'"{v}"' for v in values) + ']' if values else '[""]'

    argv = ['replay', '--ros-args', '-p', f'log:={args.log}', '-p', f'rate:={args.rate}',
            '-p', f'loop:={str(args.loop).lower()}', '-p', f'start_offset:={args.start_offset}',
            '-p', f'topics:={strings(args.topics)}', '-p', f'remap:={strings(args.remap)}',
            '-p', f'publish_clock:={str(args.clock).lower()}']
    with live_view(args.foxglove) as viewer:
        return replay_main(argv) if viewer is None else replay_main(argv, tap=viewer.tap)
