"""Running nodes as a program: init, build, spin on the main thread until SIGINT/SIGTERM, clean up.

Uses the EventsExecutor on the thread that spins it (half the CPU of the SingleThreadedExecutor at
1 kHz, measured in bench/bench_nodes.py) with the recorder's stop flag and sliced spin loop
(:mod:`._ros`), because the EventsExecutor never returns to Python to run signal handlers by itself.
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable
from typing import Any

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.context import Context
from rclpy.experimental import EventsExecutor
from rclpy.logging import get_logger
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from ..compile_notice import announce_kernel_compiles
from ..physics.dynamics import SimulationError
from ..physics.parameters import ParameterError
from ._ros import SPIN_SLICE, StopFlag, spin_until
from .fastdds_shm import remove_stale_files


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
    """``rclpy.init(args)`` for a console script, with SIGINT/SIGTERM setting the returned stop flag, after
    removing the Fast DDS shared-memory files of dead processes (:mod:`.fastdds_shm`).
    ``--ros-args`` rcl cannot read (``-p surface.centers:=[0,0.002]``: an integer in a float list) print
    one line with the reason and give None (exit status 2), not an RCLError traceback."""
    stop = StopFlag().install()
    remove_stale_files()
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as err:
        reason = str(err).removeprefix('failed to initialize rcl: ').split(', at /')[0]
        if 'Sequence should be of same type' in reason:
            reason += ' (every value of a list must have one type: write [0.0, 0.002], not [0, 0.002])'
        print(f'{name}: error: cannot read the --ros-args: {reason}', file=sys.stderr)
        return None
    return stop


def build_interruptibly(factory: Callable[[], Node], stop: StopFlag) -> Node | None:
    """``factory()`` on a helper thread while this (main) thread watches ``stop``, so that SIGINT/SIGTERM
    are answered even while construction runs compiled code for long (the physics warm-up with extreme
    parameters); None when stopped first. Exceptions of ``factory`` are raised here."""
    result: dict[str, Any] = {}

    def build() -> None:
        try:
            result['node'] = factory()
        except BaseException as err:  # handed to the main thread
            result['error'] = err

    thread = threading.Thread(target=build, name='node-build', daemon=True)
    thread.start()
    while thread.is_alive():
        thread.join(SPIN_SLICE)
        if stop and thread.is_alive():
            return None
    if 'error' in result:
        raise result['error']
    return result['node']


class NodeRefused(RuntimeError):
    """A node that will not run on this graph (e.g. a second simulator in one namespace); says why."""


def spin_node(name: str, factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Console-script main: ``rclpy.init(args)`` (``--ros-args`` parsed by rcl), build the node, spin it
    until SIGINT/SIGTERM. A refused parameter value exits with status 2 and the reason on stderr, and so
    does a simulation that cannot start (e.g. a part placed where the physics fails at once)."""
    stop = init_ros(name, args)
    if stop is None:
        return 2
    announce_kernel_compiles(get_logger(name).info)
    try:
        node = build_interruptibly(factory, stop)
    except (ParameterError, SimulationError, NodeRefused) as err:
        print(f'{name}: error: {err}', file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    if node is None:
        print(f'{name}: stopped during start-up', file=sys.stderr)
        sys.stderr.flush()
        os._exit(0)     # the half-built node still runs compiled code on its thread: nothing to clean up
    try:
        spin_nodes([node], lambda: bool(stop) or bool(getattr(node, 'refusal', '')))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    refusal = getattr(node, 'refusal', '')
    if refusal:
        print(f'{name}: error: {refusal}', file=sys.stderr)
        return 2
    return 0
