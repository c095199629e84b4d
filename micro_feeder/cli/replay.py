"""``micro-feeder replay LOG``: run the replay node on a log."""

from __future__ import annotations

import argparse
import math
import os
import re
import signal

from . import CommandError, ros_done
from ._foxglove import add_foxglove_option, announce, live_view

DEFAULT_WAIT_TIMEOUT = 30.0  # s (the replay node's wait_for_subscribers_timeout default)
_NAME = re.compile(r'[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*')


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
    parser.add_argument('--clock', action='store_true',
                        help='publish the log\'s sim time (its header stamps, or its recorded /clock) on /clock, '
                             'best effort, as rosbag2 does; the recorded /clock is then not replayed')
    parser.add_argument('--delay', type=float, default=0.0, metavar='S', help='wait S seconds before the first message')
    parser.add_argument('--wait-for-subscribers', action='store_true',
                        help='before the first message, wait for a subscriber on every --topic given (without '
                             '--topic: on any topic of the log), so that a subscriber in another process misses '
                             'nothing; at most --wait-timeout')
    parser.add_argument('--wait-timeout', type=float, default=DEFAULT_WAIT_TIMEOUT, metavar='S',
                        help='--wait-for-subscribers gives up after S seconds, names the topics without a '
                             f'subscriber and exits with status 1 (default {DEFAULT_WAIT_TIMEOUT:g})')
    parser.add_argument('--start-paused', action='store_true',
                        help='start paused; the replay/pause service (std_srvs/SetBool, false) resumes')
    parser.add_argument('--playback-duration', type=float, default=0.0, metavar='S',
                        help='replay only S seconds of the log (from --start-offset); 0 = to the end')
    parser.add_argument('--qos-profile-overrides-path', metavar='FILE.yaml',
                        help='rosbag2 QoS overrides: a YAML map of topic -> policies (reliability, durability, '
                             'history, depth) replacing the recorded ones')
    parser.add_argument('--namespace', metavar='NS',
                        help='publish under this namespace (/NS/particle/pose ...; /clock and /diagnostics stay '
                             'global)')
    add_foxglove_option(parser)
    parser.set_defaults(func=run)


def _check(args: argparse.Namespace) -> None:
    """Refuse what the replay node would refuse, with the option's name."""
    if not 0.01 <= args.rate <= 100.0:
        raise CommandError(f'--rate {args.rate}: must be within [0.01, 100]')
    for option, value, high in (('--start-offset', args.start_offset, 1e9), ('--delay', args.delay, 3600.0),
                                ('--playback-duration', args.playback_duration, 1e9),
                                ('--wait-timeout', args.wait_timeout, 86400.0)):
        if not (math.isfinite(value) and 0.0 <= value <= high):
            raise CommandError(f'{option} {value}: must be within [0, {high:g}] s')
    if args.namespace is not None and not _NAME.fullmatch(args.namespace.strip('/')):
        raise CommandError(f'--namespace {args.namespace!r}: not a ROS namespace (letters, digits, _ and /)')
    for rule in args.remap:
        source, sep, target = rule.partition(':=')
        if not (sep and source and target):
            raise CommandError(f'--remap {rule}: must be FROM:=TO')


def run(args: argparse.Namespace) -> int:
    _check(args)
    # ROS traffic stays on this host unless the user sets the range (rcl reads it at init).
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    from ..nodes.replay import main as replay_main  # rclpy only when replaying, after the environment

    def strings(values: list[str]) -> str:
        return '[' + ','.join(f'"{v}"' for v in values) + ']' if values else '[""]'

    def flag(value: bool) -> str:
        return str(value).lower()

    ros_args = ['-p', f'log:={args.log}', '-p', f'rate:={args.rate}', '-p', f'loop:={flag(args.loop)}',
                '-p', f'start_offset:={args.start_offset}', '-p', f'topics:={strings(args.topics)}',
                '-p', f'remap:={strings(args.remap)}', '-p', f'publish_clock:={flag(args.clock)}',
                '-p', f'delay:={args.delay}', '-p', f'wait_for_subscribers:={flag(args.wait_for_subscribers)}',
                '-p', f'wait_for_subscribers_timeout:={args.wait_timeout}',
                '-p', f'start_paused:={flag(args.start_paused)}', '-p', f'playback_duration:={args.playback_duration}']
    if args.qos_profile_overrides_path:
        ros_args += ['-p', f'qos_profile_overrides_path:={args.qos_profile_overrides_path}']
    if args.namespace:
        ros_args += ['-r', f'__ns:=/{args.namespace.strip("/")}']
    argv = ['replay', '--ros-args', *ros_args]
    try:
        with live_view(args.foxglove) as viewer:
            if viewer is None:
                return _status(replay_main(argv))

            def tap(node: object) -> None:
                viewer.tap(node)
                announce(viewer)
            return _status(replay_main(argv, tap=tap))
    finally:
        ros_done()      # the player shut its rclpy context down: the console script leaves at once


def _status(status: int) -> int:
    """The replay node's exit status, Ctrl-C (its 130) reported as every command reports it (``micro-feeder
    replay: interrupted``, status 130: cli.main)."""
    if status == 128 + signal.SIGINT:
        raise KeyboardInterrupt
    return status
