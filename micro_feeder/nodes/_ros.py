"""Helpers shared by the nodes: message classes by name, QoS conversions, the main-thread spin loop that stops
on SIGINT/SIGTERM, and a command sender's watch of the simulator's refusals.

Why a custom spin loop: ``rclpy.experimental.EventsExecutor`` (needed to keep up with several kHz of
messages: ~10k msg/s received against ~3k for ``SingleThreadedExecutor.spin()``, which lost a third of a
burst at depth 1000) blocks in C++ inside ``spin()`` and never runs Python signal handlers; with
rclpy's own handlers installed a SIGTERM left it spinning at 100 % CPU. So ``main()`` installs plain Python
handlers and spins in slices of ``SPIN_SLICE`` seconds, checking a stop flag in between.
"""

from __future__ import annotations

import contextlib
import faulthandler
import importlib
import os
import signal
import sys
from collections.abc import Callable
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import Executor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future

from ..interface.names import split_receipt_frame
from ..interface.topics import TOPICS_BY_NAME
from ..logs.metadata import qos_profile
from ..sim.commands import DUPLICATE

SPIN_SLICE = 0.1  # s: longest delay between a signal and the spin loop noticing it


def message_class(type_name: str) -> type:
    """The Python class of ``pkg/msg/Type`` (``pkg/Type`` accepted)."""
    parts = type_name.split('/')
    return getattr(importlib.import_module(f'{parts[0]}.msg'), parts[-1])


def qos_to_dict(qos: QoSProfile) -> dict[str, Any]:
    """An rclpy profile as rosbag2's YAML mapping (history, depth, reliability, durability)."""
    profile = qos_profile(qos.reliability == ReliabilityPolicy.RELIABLE,
                          qos.durability == DurabilityPolicy.TRANSIENT_LOCAL, max(qos.depth, 1))
    if qos.history == HistoryPolicy.KEEP_ALL:
        profile['history'] = 'keep_all'
    return profile


def qos_from_dict(profile: dict[str, Any], default: QoSProfile) -> QoSProfile:
    """A profile read from a log (``parse_qos`` output) as rclpy QoS; unknown policies from ``default``."""
    qos = QoSProfile(depth=int(profile.get('depth') or default.depth))
    qos.history = HistoryPolicy.KEEP_ALL if profile.get('history') == 'keep_all' else HistoryPolicy.KEEP_LAST
    reliability = {'reliable': ReliabilityPolicy.RELIABLE, 'best_effort': ReliabilityPolicy.BEST_EFFORT}
    durability = {'volatile': DurabilityPolicy.VOLATILE, 'transient_local': DurabilityPolicy.TRANSIENT_LOCAL}
    qos.reliability = reliability.get(profile.get('reliability'), default.reliability)
    qos.durability = durability.get(profile.get('durability'), default.durability)
    return qos


class StopFlag:
    """Set by SIGINT/SIGTERM (after :meth:`install`) or by :meth:`set`. A second signal ends the process at
    once (status 128 + signal): whatever the clean stop is waiting for, Ctrl-C is never ignored."""

    def __init__(self) -> None:
        self.signal: int | None = None
        self.requested = False

    def install(self) -> StopFlag:
        """Take SIGINT and SIGTERM; SIGUSR1 then prints every thread's Python stack to stderr (from C, so
        also while the main thread is blocked in the middleware): a process that does not stop says where
        it is."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, self._handle)
        stderr = sys.__stderr__                 # the process's own: sys.stderr may be a capture with no file
        if stderr is not None:
            with contextlib.suppress(OSError, ValueError, AttributeError):      # no file descriptor
                faulthandler.register(signal.SIGUSR1, file=stderr, all_threads=True)
        return self

    def _handle(self, signum: int, _frame: Any) -> None:
        if self.signal is not None:
            os.write(2, f'{signal.Signals(signum).name} again: leaving at once\n'.encode())
            os._exit(128 + signum)
        self.signal = signum
        self.requested = True

    def set(self) -> None:
        self.requested = True

    def __bool__(self) -> bool:
        return self.requested


def spin_until(executor: Executor, done: Callable[[], bool], future: Future | None = None) -> None:
    """Spin ``executor`` on this thread until ``done()``; ``future`` completing wakes it early."""
    future = future or Future()
    while not done():
        executor.spin_until_future_complete(future, timeout_sec=SPIN_SLICE)


def status_name(node: Any, what: str) -> str:
    """A ``/diagnostics`` status name that stays unique with several feeders on one graph: the node's
    fully qualified name without the leading slash, then ``what`` (``simulator: loop``,
    ``feeder1/simulator: loop``)."""
    return f'{node.get_fully_qualified_name().lstrip("/")}: {what}'


def topic_qos(name: str, min_depth: int = 0) -> QoSProfile:
    """The QoS of a micro_feeder topic (docs/interface.md; relative name, e.g. ``particle/pose``) from the shared table
    (interface/topics.py), with a history at least ``min_depth`` deep."""
    spec = TOPICS_BY_NAME[name]
    reliability = ReliabilityPolicy.RELIABLE if spec.reliable else ReliabilityPolicy.BEST_EFFORT
    durability = DurabilityPolicy.TRANSIENT_LOCAL if spec.transient_local else DurabilityPolicy.VOLATILE
    return QoSProfile(depth=max(spec.depth, min_depth), reliability=reliability, durability=durability)


# Services: requests queued deep enough for bursts (200 asynchronous ~/step calls all answered; the
# rclpy default keeps 10 and silently drops the rest). Clients sending bursts need the same depth.
SERVICE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


class RefusalWatch:
    """A command sender's view of ``simulator/command_status``: the simulator's refusals of the commands whose
    identity (``header.frame_id``) starts with ``prefix``, counted, the last reason kept, logged on ``node``'s
    logger (throttled: one line per 5 s at most) and passed to ``on_refused`` (the refused identity, the reason).
    A duplicate (a copy of a command the simulator applied) is passed on but counted apart, unlogged."""

    def __init__(self, node: Any, prefix: str, on_refused: Callable[[str, str], None] | None = None):
        self._node, self._prefix, self._on_refused = node, prefix, on_refused
        self.refused = 0
        self.repeated = 0           # duplicates the simulator did not apply again (not counted in ``refused``)
        self.last = ''
        node.create_subscription(DiagnosticArray, 'simulator/command_status', self._on_status,
                                 topic_qos('simulator/command_status'))

    def _on_status(self, msg: Any) -> None:
        _topic, command_id = split_receipt_frame(msg.header.frame_id)
        if not command_id.startswith(self._prefix):
            return
        reason = msg.status[0].message if msg.status else ''
        if DUPLICATE in reason:      # a copy of a command applied (sent again until its receipt): no fault
            self.repeated += 1
        else:
            self.refused += 1
            self.last = f'{command_id}: {reason}'
            self._node.get_logger().warning(f'the simulator refused {self.last}', throttle_duration_sec=5.0)
        if self._on_refused is not None:
            self._on_refused(command_id, reason)
