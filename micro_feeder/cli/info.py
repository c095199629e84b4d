"""``micro-feeder info LOG``: topics, types, counts, rates, duration, final part state, loss."""

from __future__ import annotations

import argparse

from ..logs.coverage import coverage
from ..logs.summary import format_summary, summarize
from ._logs import open_log, report_loss


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser('info', help='summarise a log',
                                   description='Summarise a log (rosbag2 directory or .mcap): topics, types, '
                                               'counts, rates, duration, final part state, recorder loss; '
                                               'where and why the log ends, the sim time each topic '
                                               'starts at, commands missing against the simulator\'s '
                                               'receipts.')
    parser.add_argument('log', metavar='LOG', help='log directory or .mcap file')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    log = open_log(args.log)
    summary = summarize(log)
    print(format_summary(summary, coverage(log, summary.recorder, summary.part.stamp)))
    report_loss(log)
    return 0
