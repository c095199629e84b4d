"""Console-script entry points of the nodes, quiet on Ctrl-C/SIGTERM from the very first instant.

Importing a node module takes ~0.8 s (rclpy, numpy, numba); a Ctrl-C then raised KeyboardInterrupt inside
an import and printed a traceback. These entry points set plain exit handlers first, then import the
node module and run its ``main`` (which installs its own stop handling).
"""

from __future__ import annotations

import importlib
import signal
from typing import Any


def _exit(signum: int, _frame: Any) -> None:
    raise SystemExit(128 + signum)


def _run(module: str) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _exit)
    return importlib.import_module(f'micro_feeder.nodes.{module}').main()


def simulator() -> int:
    return _run('simulator')


def actuator() -> int:
    return _run('actuator')


def recorder() -> int:
    return _run('recorder')


def replay() -> int:
    return _run('replay')


def feed_controller() -> int:
    return _run('feed_controller')

