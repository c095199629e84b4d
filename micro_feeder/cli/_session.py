"""Several nodes in one process for a CLI command: a private rclpy context, Ctrl-C/SIGTERM handling, an
optional recorder, one EventsExecutor spun on the main thread, and a clean shutdown whatever happens."""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from collections.abc import Callable, Iterator
from typing import Any, TypeVar

from ..physics.parameters import ParameterError
from . import CommandError

N = TypeVar('N')


def add_namespace_option(parser: argparse.ArgumentParser) -> None:
    """``--namespace NS``: run the nodes under ``/NS`` so that several feeders share one ROS graph."""
    parser.add_argument('--namespace', metavar='NS', default='/',
                        help='ROS namespace of every node, topic and service of this feeder (e.g. feeder1 -> '
                             '/feeder1/particle/pose, /feeder1/simulator/step); in a namespace the simulator '
                             'does not publish /clock, so several feeders can share a graph (docs/interface.md)')


def namespace(text: str) -> str:
    """``feeder1`` or ``/feeder1`` -> ``/feeder1``, checked by ROS's rules; raises :class:`CommandError`."""
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace
    ns = '/' + text.strip('/')
    try:
        validate_namespace(ns)
    except InvalidNamespaceException as err:
        raise CommandError(f'--namespace {text!r} is not a valid ROS namespace: {err}') from err
    return ns


def validate(flat: dict[str, Any], controller: bool = False) -> None:
    """Check the settings the nodes will refuse (the model groups, and the feed controller's goal with
    ``controller``) before a session starts, so that a refused value leaves no log directory behind.
    Raises :class:`CommandError`. Cheap: no contact tables are built."""
    from ..settings import build_group, validate_model
    try:
        validate_model(flat)
        if controller:
            from ..control.feed_planner import FeedGoal
            build_group(FeedGoal, flat)
    except (ParameterError, ValueError) as err:
        raise CommandError(str(err)) from err


READY_TIMEOUT = 10.0  # s (wall clock) a command waits at t = 0 for its nodes and recorder to hear each other


class RosSession:
    """What a command builds its nodes with; see :func:`ros_session`."""

    def __init__(self, context: Any, stop: Any, record: str | None, namespace: str = '/', viewer: Any = None):
        self.context = context
        self.stop = stop
        self.namespace = namespace
        self.viewer = viewer    # a micro_feeder.viz Viewer (--foxglove): forwards what the nodes publish
        self.nodes: list[Any] = []
        self.recorder = None
        self.log: str | None = None
        self._executor: Any = None
        if record:
            from rclpy.parameter import Parameter

            from ..nodes.recorder import Recorder
            self.recorder = self.add(lambda: Recorder(context=context, namespace=namespace,
                                                      parameter_overrides=[Parameter('output', value=record)]))

    def add(self, build: Callable[[], N]) -> N:
        """Build a node (a refused parameter becomes a :class:`CommandError`) and include it in the spin.
        Build it with ``namespace=session.namespace`` (``--namespace``)."""
        from ..nodes.spin import NodeRefused
        from ..physics.dynamics import SimulationError
        if self.stop:       # Ctrl-C during start-up: build nothing more (the command ends "interrupted")
            raise KeyboardInterrupt
        try:
            node = build()
        except (ParameterError, ValueError, FileExistsError, SimulationError, NodeRefused) as err:
            raise CommandError(str(err)) from err
        self.nodes.append(node)
        if self.recorder is not None:      # the simulator's state topics, recorded as they are published
            self.recorder.record_in_process(node)
        if self.viewer is not None:
            self.viewer.tap(node)
        return node

    def recorder_hears(self, sim: Any) -> bool:
        """True without a recorder, else once it hears every state topic of the simulator ``sim``: through a
        matched subscription, or where the topic is published (:meth:`Recorder.record_in_process`)."""
        return self.recorder is None or sim.outputs_matched(self.recorder.in_process)

    def spin(self, done: Callable[[], bool], future: Any = None) -> None:
        """Spin every node in the session's EventsExecutor until ``done()`` or Ctrl-C/SIGTERM; ``future`` (an
        rclpy Future) completing ends the spin too, without waiting for the next check of ``done()``. One
        executor for the whole session: a message that arrived but was not yet taken when an executor was
        shut down never reached its callback in the next one (the receipt of ``run``'s burst, published as
        its wait for the burst ended, was missing from the log in 4 of 6 runs)."""
        from rclpy.experimental import EventsExecutor

        from ..nodes._ros import spin_until
        from ._foxglove import announce
        if self._executor is None:
            self._executor = EventsExecutor(context=self.context)
        for node in self.nodes:
            if node not in self._executor.get_nodes():
                self._executor.add_node(node)
        announce(self.viewer)
        spin_until(self._executor, lambda: bool(self.stop) or done() or (future is not None and future.done()),
                   future)

    def shutdown(self) -> None:
        """Shut the session's executor down (before its nodes are destroyed)."""
        if self._executor is not None:
            self._executor.shutdown()
            self._executor = None

    def close_log(self) -> str | None:
        """Finish the recording (summary, metadata.yaml); returns its path."""
        if self.recorder is not None and self.log is None:
            self.log = str(self.recorder.close())
        return self.log

    def recording_fate(self) -> str:
        """'' when the recording ran to its end, else where and why it stopped (``recording stopped at
        9.4 s: No space left on device (log readable up to 8.9 s)``)."""
        return self.recorder.fate() if self.recorder is not None else ''


@contextlib.contextmanager
def ros_session(record: str | None = None, namespace: str = '/', viewer: Any = None) -> Iterator[RosSession]:
    """A :class:`RosSession` whose nodes go in ``namespace``; ROS traffic stays on this host unless
    ROS_AUTOMATIC_DISCOVERY_RANGE is set. The process gets the simulator loop's GIL switch interval.
    ``viewer`` (``cli._foxglove.live_view``) is given every node built. Fast DDS shared-memory files of dead
    processes are removed first (:mod:`micro_feeder.nodes.fastdds_shm`). Run as the console script, the
    command leaves without the interpreter's finalisation once the session is shut down
    (:func:`micro_feeder.cli.leave`)."""
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    from ..realtime.loop import GIL_SWITCH_INTERVAL
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    import rclpy  # after the environment is set: rcl reads it at init
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from ..nodes._ros import StopFlag
    from ..nodes.fastdds_shm import remove_stale_files
    from . import ros_done

    remove_stale_files()
    context = Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    session = None
    try:
        session = RosSession(context, StopFlag().install(), record, namespace, viewer)
        yield session
    finally:
        if session is not None:
            session.close_log()
            session.shutdown()
            for node in session.nodes:
                node.destroy_node()
        rclpy.shutdown(context=context)
        ros_done()
