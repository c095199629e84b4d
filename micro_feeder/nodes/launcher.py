"""Console-script entry points of the nodes: quiet on Ctrl-C/SIGTERM from their first line on, and quick
to exit. (Before that line the interpreter itself is starting, ~50 ms, more under load, and answers Ctrl-C
with its own traceback, whatever the program.)

Importing a node module takes ~0.8 s (rclpy, numpy, numba); a Ctrl-C then raised KeyboardInterrupt inside
an import and printed a traceback. These entry points set plain exit handlers first, then import the
node module and run its ``main`` (which installs its own stop handling and shuts ROS down). Then they
leave without the interpreter's finalisation, which took 0.4 s at load 3.4 (more under heavier load, and
1.4 s with a loop thread stuck in the physics) and has nothing left to do: ROS is shut down (Fast DDS
removes its shared memory then), files are closed, and the output is flushed here.
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
from typing import Any


def _exit(signum: int, _frame: Any) -> None:
    # Not SystemExit: raised inside an import it comes out as a chained ImportError traceback (rclpy's C
    # library loader). Nothing needs cleaning up before the node's main has started.
    os._exit(128 + signum)


def _run(module: str) -> int:
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _exit)
    status = importlib.import_module(f'micro_feeder.nodes.{module}').main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(status or 0))


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

