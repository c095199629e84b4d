"""Running nodes as a program: init, build, spin on the main thread until SIGINT/SIGTERM, clean up.

Uses the EventsExecutor on the thread that spins it (half the CPU of the SingleThreadedExecutor at
1 kHz, measured in bench/bench_nodes.py) with the recorder's stop flag and sliced spin loop
(:mod:`._ros`), because the EventsExecutor never returns to Python to run signal handlers by itself.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..physics.dynamics import SimulationError
from ..physics.parameters import ParameterError
from ._ros import StopFlag, spin_until


def spin_nodes(nodes: list[Node], done: Callable[[], bool], context: Context | None = None) -> None:
    """Spin ``nodes`` in one EventsExecutor on this thread until ``done()``; shuts the executor down."""
    executor = EventsExecutor(context=context)
    for node in nodes:
        executor.add_node(node)
    try:
        spin_until(executor, done)
    finally:
        executor.shutdown()


def init_ros(name: str, args: list[str] | None) -> StopFlag | None:
    """``rclpy.init(args)`` for a console script, with SIGINT/SIGTERM setting the returned stop flag.
    ``--ros-args`` rcl cannot read (``-p surface.centers:=[0,0.002]``: an integer in a float list) print
    one line with the reason and give None (exit status 2), not an RCLError traceback."""
    stop = StopFlag().install()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as err:
        reason = str(err).removeprefix('failed to initialize rcl: ').split(', at /')[0]
        if 'Sequence should be of same type' in reason:
            reason += ' (every value of a list must have one type: write [0.0, 0.002], not [0, 0.002])'
        print(f'{name}: error: cannot read the --ros-args: {reason}', file=sys.stderr)
        return None
    return stop


def spin_node(name: str, factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Console-script main: ``rclpy.init(args)`` (``--ros-args`` parsed by rcl), build the node, spin it
    until SIGINT/SIGTERM. A refused parameter value exits with status 2 and the reason on stderr, and so
    does a simulation that cannot start (e.g. a part placed where the physics fails at once)."""
    stop = init_ros(name, args)
    if stop is None:
        return 2
    try:
        node = factory()
    except (ParameterError, SimulationError) as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        spin_nodes([node], lambda: bool(stop))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
