"""Running nodes as a program: init, build, spin on the main thread until SIGINT/SIGTERM, clean up.

Uses the EventsExecutor on the thread that spins it (half the CPU of the SingleThreadedExecutor at
1 kHz, measured in bench/bench_nodes.py) with the recorder's stop flag and sliced spin loop
(:mod:`._ros`), because the EventsExecutor never returns to Python to run signal handlers by itself.
"""

from __future__ import annotations

import sys
from collections.abc import Callable

import rclpy
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

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


def spin_node(name: str, factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Console-script main: ``rclpy.init(args)`` (``--ros-args`` parsed by rcl), build the node, spin it
    until SIGINT/SIGTERM. A refused parameter value exits with status 2 and the reason on stderr."""
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = StopFlag().install()
    try:
        node = factory()
    except ParameterError as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        spin_nodes([node], lambda: bool(stop))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0
