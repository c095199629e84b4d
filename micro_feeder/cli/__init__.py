"""The ``micro-feeder`` command.

Each subcommand lives in its own module of this package and exposes ``register(subparsers)``, which adds
its parser and sets ``func`` (called with the parsed arguments, returns the exit status). Modules are
discovered, so adding a command means adding a module.
"""

from __future__ import annotations

# Only the standard library at import time: the console script imports this module before main() runs, and
# a Ctrl-C during the ~1 s of numpy/numba/rclpy imports must come out as "interrupted" (status 130), not as
# a KeyboardInterrupt traceback. The commands and what they need are imported inside main().
import argparse
import contextlib
import importlib
import os
import pkgutil
import signal
import sys
import warnings
from typing import TextIO

INTERRUPTED = 130   # exit status after Ctrl-C (128 + SIGINT, as a shell reports it)
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
    status 2; Ctrl-C is ``interrupted`` and status 130, never a traceback.

    Called as the console script (``argv`` None: the process is this command's), Ctrl-C while the commands
    are imported (~1 s of numpy, numba, rclpy; several under load) ends the process at once, as the node
    executables do (nodes/launcher.py): nothing has been done that needs undoing, and the interpreter's
    finalisation of half-imported modules took 1-3 s at load 10. And a command that ran ROS nodes, or
    that was interrupted, leaves with ``os._exit`` once its output is flushed (:func:`leave`)."""
    console = argv is None
    # A process started with Ctrl-C ignored (a background job of a script) keeps ignoring it.
    quick_exit = console and signal.getsignal(signal.SIGINT) is signal.default_int_handler
    if quick_exit:
        signal.signal(signal.SIGINT, _interrupted_while_starting)
    status = _run(argv, quick_exit)
    if console and (_ros_used or status == INTERRUPTED):
        leave(status)
    return status


def _interrupted_while_starting(_signum: int, _frame: object) -> None:
    os.write(2, b'micro-feeder: interrupted\n')
    os._exit(INTERRUPTED)


_sigint_seen = False


def _interrupt(signum: int, frame: object) -> None:
    """Python's own Ctrl-C (KeyboardInterrupt), remembered: raised while a C extension initialises (rclpy's,
    imported by the command under load), it comes out as that module's ImportError ('initialization failed'),
    which is then an interruption too, not a traceback."""
    global _sigint_seen
    _sigint_seen = True
    signal.default_int_handler(signum, frame)


def _run(argv: list[str] | None, quick_exit: bool = False) -> int:
    command = 'micro-feeder'
    try:
        from ..compile_notice import announce_kernel_compiles
        warnings.showwarning = _show_warning
        announce_kernel_compiles(lambda line: print(f'micro-feeder: {line}', file=sys.stderr, flush=True))
        parser = build_parser()
        args = parser.parse_args(argv)
        command = f'micro-feeder {args.command}'
        if quick_exit:  # from here on, Ctrl-C is the command's to handle (KeyboardInterrupt or its own)
            signal.signal(signal.SIGINT, _interrupt)
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f'{command}: interrupted', file=sys.stderr)
        return INTERRUPTED
    except Exception as err:  # user mistakes are classified here, once, for every command
        if _sigint_seen:    # Ctrl-C inside an extension module's import surfaces as its ImportError
            print(f'{command}: interrupted', file=sys.stderr)
            return INTERRUPTED
        reason = user_error(err)
        if reason is None:
            raise
        print(f'{command}: error: {reason}', file=sys.stderr)
        return 2


_ros_used = False   # set by cli._session.ros_session once its rclpy context is shut down


def ros_done() -> None:
    """Called when a command's ROS session has been shut down: see :func:`leave`."""
    global _ros_used
    _ros_used = True


def leave(status: int) -> None:
    """End the process now, without the interpreter's finalisation: after a ROS session, or after Ctrl-C.
    Everything the command had to undo is undone by then, in its ``with`` and ``finally`` blocks (nodes
    destroyed, the rclpy context shut down, Fast DDS's participant and its shared memory released, logs and
    tables closed, worker processes killed and joined). What finalisation still did took 1-4 s at load
    5-12 on 2 cores, over 8 s at times (garbage collection of numba's, scipy's and rclpy's modules, OpenBLAS
    joining its threads at exit), all the while ignoring Ctrl-C: the "hang on shutdown" of issue 30, and
    most of a sweep's answer to Ctrl-C (1.5 s at load 10, where 0.1 s was the sweep's own). The node
    executables leave the same way (nodes/launcher.py)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):     # a closed pipe: nothing more can be said there
            stream.flush()
    os._exit(status)


def user_error(err: Exception) -> str | None:
    """The one-line reason when ``err`` is a user's mistake (refused value, path, file, parameters that
    make the simulation fail), else None (a bug: the traceback is shown)."""
    from ..physics.parameters import ParameterError
    from ..settings import SettingsError
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
