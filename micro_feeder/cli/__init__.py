"""The ``micro-feeder`` command.

Each subcommand lives in its own module of this package and exposes ``register(subparsers)``, which adds
its parser and sets ``func`` (called with the parsed arguments, returns the exit status). Modules are
discovered, so adding a command means adding a module.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from ..physics.parameters import ParameterError
from ..settings import SettingsError

COMMAND_ORDER = ('run', 'simulate', 'sweep', 'optimize', 'calibrate', 'contact', 'hil', 'info', 'plot', 'export',
                 'recover', 'replay', 'resim')


class CommandError(Exception):
    """A user-facing failure: printed as ``micro-feeder: error: ...`` with exit status 2."""


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='micro-feeder',
        description='Simulate a piezo-actuated micro-part feeder: rough-surface adhesion and friction, '
                    'stick/slide/flight dynamics, ROS 2 nodes, MCAP logs.',
        epilog='Run "micro-feeder COMMAND --help" for the options of a command. '
               'Parameters: docs/parameters.md.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', required=True)
    modules = [name for _, name, _ in pkgutil.iter_modules(__path__) if not name.startswith('_')]
    rank = {name: i for i, name in enumerate(COMMAND_ORDER)}
    for name in sorted(modules, key=lambda n: (rank.get(n, len(rank)), n)):
        importlib.import_module(f'{__name__}.{name}').register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (CommandError, SettingsError, ParameterError) as err:
        print(f'micro-feeder {args.command}: error: {err}', file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print('interrupted', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
