"""Options shared by the exploring commands (sweep, optimize, calibrate): where the runs execute."""

from __future__ import annotations

import argparse
import os

from ..explore.runners import Runner, RunnerError, make_runner
from . import CommandError


def add_runner_options(parser: argparse.ArgumentParser) -> None:
    """``--processes N`` (local workers, default all cores) and ``--scheduler tcp://HOST:PORT`` (Dask)."""
    parser.add_argument('--processes', type=int, default=os.cpu_count() or 1, metavar='N',
                        help='local worker processes (default: all cores)')
    parser.add_argument('--scheduler', metavar='tcp://HOST:PORT',
                        help='run on the Dask cluster of this scheduler instead (docs/explore.md)')


def runner_from_args(args: argparse.Namespace) -> Runner:
    """The runner the options ask for; a scheduler that does not answer is a user-facing error."""
    try:
        return make_runner(max(1, args.processes), args.scheduler)
    except RunnerError as err:
        raise CommandError(str(err)) from err
