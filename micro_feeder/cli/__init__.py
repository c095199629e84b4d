"""The ``micro-feeder`` command.

Each subcommand lives in its own module of this package and exposes ``register(subparsers)``, which adds
its parser and sets ``func`` (called with the parsed arguments, returns the exit status). Modules are
discovered, so adding a command means adding a module.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import importlib
import os
import pkgutil
import sys
import warnings
from typing import TextIO

from ..compile_notice import announce_kernel_compiles
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


def _show_warning(message: Warning | str, category: type[Warning], filename: str, lineno: int,
                  file: TextIO | None = None, line: str | None = None) -> None:
    """Our own warnings (a damaged or truncated log ...) as one ``warning: ...`` line; others as Python shows them."""
    if category.__module__.startswith('micro_feeder'):
        print(f'warning: {message}', file=sys.stderr)
    else:
        _default_show_warning(message, category, filename, lineno, file, line)


_default_show_warning = warnings.showwarning


def main(argv: list[str] | None = None) -> int:
    """Run one command. A user mistake (bad option, parameter, path or file) is one line on stderr and exit
    status 2; Ctrl-C is ``interrupted`` and status 130, never a traceback. Called as the program (no
    ``argv``), Ctrl-C ends the process at once (:func:`exit_interrupted`)."""
    command = 'micro-feeder'
    try:
        warnings.showwarning = _show_warning
        announce_kernel_compiles(lambda line: print(f'micro-feeder: {line}', file=sys.stderr, flush=True))
        parser = build_parser()
        args = parser.parse_args(argv)
        command = f'micro-feeder {args.command}'
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f'{command}: interrupted', file=sys.stderr)
        if argv is None:
            exit_interrupted(130)
        return 130
    except Exception as err:  # user mistakes are classified here, once, for every command
        reason = user_error(err)
        if reason is None:
            raise
        print(f'{command}: error: {reason}', file=sys.stderr)
        return 2


def exit_interrupted(status: int) -> None:
    """End the program now, after Ctrl-C: the exit handlers run (child processes are stopped, logging is
    flushed) and the output is flushed, but the interpreter's teardown of every module is skipped: 0.25 s
    with numba loaded on an idle machine, up to 0.6 s on a loaded one, which made Ctrl-C late. Whatever the
    command holds open was closed when the interrupt unwound it."""
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(status)


def user_error(err: Exception) -> str | None:
    """The one-line reason when ``err`` is a user's mistake (refused value, path, file, parameters that
    make the simulation fail), else None (a bug: the traceback is shown)."""
    if isinstance(err, (CommandError, SettingsError, ParameterError)):
        return str(err)
    if isinstance(err, OSError):
        where = f' {err.filename}' if err.filename else ''
        return f'cannot use{where}: {err.strerror or err}'
    if isinstance(err, MemoryError) or 'Maximum allowed size exceeded' in str(err):
        return ('the request needs more memory than this machine has: lower the size that drives it '
                '(stroke.count, --duration, the sweep size); see "micro-feeder COMMAND --help"')
    dynamics = sys.modules.get('micro_feeder.physics.dynamics.model')
    if dynamics is not None and isinstance(err, dynamics.SimulationError):
        from ._common import changed_parameters
        changed = changed_parameters()
        hint = (f'parameters you set: {", ".join(changed)}; check them against docs/parameters.md'
                if changed else 'with the default parameters')
        return f'the simulation failed: {err} ({hint})'
    return None


if __name__ == '__main__':
    sys.exit(main())
