"""The recorder node: subscribes in serialized form and writes an MCAP log (rosbag2 layout).

Topics default to every micro_feeder topic (docs/interface.md) plus ``/clock`` and ``/diagnostics``,
resolved against the node's namespace. Known topics are subscribed at start with the QoS their
publishers offer (transient-local ones too, so latched state is captured) and a deeper history (so a
burst waits in the queue instead of being dropped); other configured topics are subscribed when they
appear in the graph. Each message is written with its receive time (wall clock, ns) as log time.

Loss accounting: the DDS sample-lost count and incompatible-QoS events, per topic, published on
``/diagnostics`` at 1 Hz (and so recorded too, which keeps them in a truncated log) and stored in the
log summary on a clean stop. rclpy's EventsExecutor cannot deliver message info (sequence numbers) to
a callback (``SystemError`` in rclpy 9.1.2), so gaps in a publisher's sequence are not counted.

The sample-lost count is read (:class:`LossCount`) once a second and at the stop, not taken as a QoS
event callback. A callback makes the middleware call the recorder from its receive thread while it holds
the reader's lock, and with rmw_fastrtps_shared_cpp 9.3.3 that can deadlock against the executor taking
the event (ros2/rmw_fastrtps#890, fixed upstream after that release): the recorder then hangs for good and
ignores SIGINT. Without a callback the middleware only counts, and reading the count takes the two locks
in one order.

Faults never reach the executor. The log is written on a thread of its own (``logs.background``): a
failed write (disk full, file too large, I/O error), a removed log directory, a write that does not return
within ``write_timeout`` s or a disk that cannot keep up stop the recording: the log is kept up to its last
whole chunk, finished there with where and why it ends (``logs.writer``), and the fault is reported once,
as one ERROR line on the node's logger and on ``/diagnostics`` (level ERROR from then on). The node stays
up (in ``micro-feeder run`` the simulation goes on); the ``recorder`` program ends with status 1 after
printing the summary of what is readable. A recorder that did not run for more than ``STALL_REPORT`` s
(its process stopped by SIGSTOP or a suspended machine, its executor busy elsewhere, starved of CPU) says so
when it runs again: what was published meanwhile may be missing, and it is counted in the ``stalls`` keys of
its counters.

In one process with the simulator (``micro-feeder run --record``), the simulator's state topics
(:data:`IN_PROCESS_TOPICS`, ~11,000 messages a second for one part under 1 kHz strokes) are recorded where
they are published (:meth:`Recorder.record_in_process`) instead of through a subscription: the process has
one GIL, and taking each message back from the middleware on the executor cost the simulator's loop its
real-time factor. Their log time is then the publish time, and nothing can be lost between publisher and
log. Only the one publisher of each such topic (the twin guard refuses a second simulator of the same name;
``/clock`` is the root namespace simulator's) is recorded that way; every other topic, and every other
process's messages, still come through subscriptions.

Use as a program (``recorder --ros-args -p output:=out/run1``: stops cleanly on SIGINT, SIGTERM or the
``~/stop`` service, ``/recorder/stop`` by default) or in-process: ``r = Recorder(context=ctx)``, add it to
an executor that runs on the main thread, spin, then ``r.close()``.
"""

from __future__ import annotations

import datetime
import sys
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.context import Context
from rclpy.event_handler import QoSSubscriptionEventType, SubscriptionEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.experimental import EventsExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rclpy.subscription import Subscription
from rclpy.task import Future
from std_srvs.srv import Trigger

from ..interface.topics import TOPICS, TOPICS_BY_NAME
from ..logs.background import WRITE_TIMEOUT, BackgroundWriter
from ..logs.coverage import coverage
from ..logs.metadata import dump_qos
from ..logs.reader import LogReader
from ..logs.summary import format_summary, summarize
from ..logs.writer import LogWriter, WriteFault
from ._ros import SERVICE_QOS, message_class, qos_to_dict, spin_until, topic_qos
from .spin import init_ros

SUBSCRIPTION_DEPTH = 1000  # messages queued per topic while the writer is busy
DIAGNOSTICS_PERIOD = 1.0  # s
DISCOVERY_PERIOD = 1.0  # s
WATCH_PERIOD = 0.25  # s between two looks at the writer thread (faults, stalls)
STALL_REPORT = 2.0  # s: a longer gap between two looks means the recorder process itself was stopped
# The simulator's state topics (every tick, or at every mode change), which it alone publishes: recorded
# in-process when the recorder shares a process with the simulator (Recorder.record_in_process).
IN_PROCESS_TOPICS = ('particle/pose', 'particle/twist', 'particle/contact_wrench', 'actuator/joint_states',
                     'particles/poses', 'particles/states', 'particle/contact_state', 'particle/transitions',
                     'particles/transitions', '/clock')


def _descriptor(description: str, type_: int, *, float_range: tuple[float, float] | None = None,
                int_range: tuple[int, int] | None = None) -> ParameterDescriptor:
    d = ParameterDescriptor(description=description, type=type_, read_only=True)
    if float_range:
        d.floating_point_range = [FloatingPointRange(from_value=float_range[0], to_value=float_range[1])]
    if int_range:
        d.integer_range = [IntegerRange(from_value=int_range[0], to_value=int_range[1])]
    return d


def default_topics(namespace: str) -> list[str]:
    """Every micro_feeder topic; without ``/clock`` in a namespace (a namespaced simulator does not
    publish it, so the ``/clock`` there would be another feeder's)."""
    return [spec.name for spec in TOPICS if namespace == '/' or spec.name != '/clock']


class LossCount:
    """The middleware's count of a subscription's lost messages (DDS sample lost), read on demand.

    Reading takes the count since the last read. No callback is registered for the event, so the
    middleware never calls into ROS from its receive thread for it (see the module docstring)."""

    def __init__(self, subscription: Subscription) -> None:
        with subscription.handle:
            self._event = _rclpy.EventHandle(subscription.handle,
                                             QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST)

    def take(self) -> int:
        """Messages lost since the last call."""
        with self._event:
            info = self._event.take_event()
        return int(info.total_count_change) if info is not None else 0

    def destroy(self) -> None:
        self._event.destroy_when_not_in_use()


class Recorder(Node):
    """Records topics to an MCAP log; see the module docstring."""

    def __init__(self, *, context: Context | None = None, cli_args: list[str] | None = None,
                 parameter_overrides: list | None = None, node_name: str = 'recorder',
                 namespace: str | None = None) -> None:
        self._loss_counts: dict[str, LossCount] = {}   # first: destroy_node runs even when __init__ raises
        self._topic_subscriptions: dict[str, tuple[Subscription, str]] = {}   # absolute topic -> (subscription, type)
        self.in_process: set[str] = set()    # absolute names of the topics recorded where they are published
        super().__init__(node_name, context=context, cli_args=cli_args, namespace=namespace,
                         parameter_overrides=parameter_overrides or [])
        self.declare_parameter('output', '', _descriptor(
            'log directory to create (rosbag2 layout), or a file name ending in .mcap; '
            'empty = ./rosbag2_<date>-<time>', ParameterType.PARAMETER_STRING))
        self.declare_parameter('topics', default_topics(self.get_namespace()), _descriptor(
            'topics to record, relative names resolved in the node namespace (default: every micro_feeder topic; '
            'in a namespace other than /, not /clock, which belongs to the un-namespaced feeder)',
            ParameterType.PARAMETER_STRING_ARRAY))
        self.declare_parameter('flush_period', 1.0, _descriptor(
            'longest time [s] between two flushes to disk: what a crash can lose', ParameterType.PARAMETER_DOUBLE,
            float_range=(0.01, 60.0)))
        self.declare_parameter('split_size', 0, _descriptor(
            'start a new file when the current one reaches this size [bytes]; 0 = never',
            ParameterType.PARAMETER_INTEGER, int_range=(0, 2**62)))
        self.declare_parameter('split_duration', 0.0, _descriptor(
            'start a new file when the current one spans this long [s]; 0 = never',
            ParameterType.PARAMETER_DOUBLE, float_range=(0.0, 1e6)))
        self.declare_parameter('write_timeout', WRITE_TIMEOUT, _descriptor(
            'a write to the log that has not returned after this long [s] stops the recording '
            '(storage not responding)', ParameterType.PARAMETER_DOUBLE, float_range=(0.5, 3600.0)))
        p = {name: self.get_parameter(name).value for name in
             ('output', 'topics', 'flush_period', 'split_size', 'split_duration', 'write_timeout')}
        output = p['output'] or datetime.datetime.now().strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
        self.received: Counter[str] = Counter()
        self.lost: Counter[str] = Counter()
        self.incompatible: Counter[str] = Counter()
        self.stalls: list[tuple[int, float]] = []   # (wall-clock ns when it ended, seconds) per process stall
        self.writer = LogWriter(output, flush_period=p['flush_period'], split_size=p['split_size'],
                                split_duration=p['split_duration'], stop_on_error=True,
                                stamp_topic=self.resolve_topic_name('particle/pose'), metadata=self.counters)
        self._background = BackgroundWriter(self.writer, write_timeout=p['write_timeout'])
        self.done = Future()
        self._closed = False
        self._reported: set[str] = set()   # what was reported once: 'fault', 'error', skipped topics
        self._last_watch: float | None = None   # monotonic time of the last look (None before the first spin)
        self._pending: dict[str, str] = {}  # absolute name -> configured name, type not known yet
        for name in p['topics']:
            absolute = self.resolve_topic_name(name)
            spec = TOPICS_BY_NAME.get(name)
            if spec is None:
                self._pending[absolute] = name
            else:
                self._subscribe(absolute, spec.type, topic_qos(name, SUBSCRIPTION_DEPTH))
        self._diagnostics = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self.create_timer(DIAGNOSTICS_PERIOD, self._publish_diagnostics)
        self.create_timer(WATCH_PERIOD, self._watch)
        if self._pending:
            self.create_timer(DISCOVERY_PERIOD, self._discover)
        self.create_service(Trigger, '~/stop', self._on_stop, qos_profile=SERVICE_QOS)
        self.get_logger().info(f'recording {len(p["topics"])} topics to {self.writer.path}')

    # -- subscriptions --------------------------------------------------------------------------------
    def _subscribe(self, topic: str, type_name: str, qos: QoSProfile) -> None:
        events = SubscriptionEventCallbacks(
            incompatible_qos=lambda info, t=topic: self.incompatible.update({t: info.total_count_change}))
        subscription = self.create_subscription(message_class(type_name), topic,
                                                lambda data, t=topic, n=type_name: self._on_message(t, n, data),
                                                qos, raw=True, event_callbacks=events)
        self._loss_counts[topic] = LossCount(subscription)
        self._topic_subscriptions[topic] = (subscription, type_name)

    def record_in_process(self, node: Node) -> None:
        """Record ``node``'s publishers of :data:`IN_PROCESS_TOPICS` (a simulator in this process, built after
        the recorder and before it publishes them) where they publish, instead of through this recorder's
        subscriptions, which are destroyed."""
        wanted = {self.resolve_topic_name(name) for name in IN_PROCESS_TOPICS}
        for publisher in node.publishers:
            topic = publisher.topic_name
            if topic not in wanted or topic not in self._topic_subscriptions:
                continue
            subscription, type_name = self._topic_subscriptions.pop(topic)
            self._take_waiting(topic, type_name, subscription)
            self._loss_counts.pop(topic).destroy()
            self.destroy_subscription(subscription)
            self.in_process.add(topic)
            publisher.publish = self._recording(publisher.publish, topic, type_name,
                                                dump_qos([qos_to_dict(publisher.qos_profile)]))

    def _take_waiting(self, topic: str, type_name: str, subscription: Subscription) -> None:
        """Record what ``subscription`` received and the executor has not taken yet: before it is destroyed
        (the state at t = 0 a simulator publishes as it is built), and at the stop (what the last tick
        published before ``run`` ended: its transitions were missing from the log). At most one queue's
        depth: a sender that keeps publishing cannot hold the stop here."""
        with subscription.handle:
            for _ in range(max(subscription.qos_profile.depth, 1)):
                taken = subscription.handle.take_message(subscription.msg_type, True)
                if taken is None:
                    break
                self._on_message(topic, type_name, taken[0])

    def _recording(self, publish: Callable[[Any], None], topic: str, type_name: str,
                   offered_qos: str) -> Callable[[Any], None]:
        """``publish`` that also records what it publishes (CDR bytes, or a message serialized here)."""
        def publish_and_record(msg: Any) -> None:
            publish(msg)
            self._on_message(topic, type_name, msg if isinstance(msg, bytes) else serialize_message(msg),
                             offered_qos)
        return publish_and_record

    def _on_message(self, topic: str, type_name: str, data: bytes, offered_qos: str | None = None) -> None:
        """Record one message at its receive (or publish) time; ``offered_qos``: the publishers' QoS for a
        topic's first message (None: asked of the graph)."""
        now = time.time_ns()
        if self._closed:
            return
        if topic not in self.received:
            if offered_qos is None:
                offered_qos = dump_qos([qos_to_dict(info.qos_profile)
                                        for info in self.get_publishers_info_by_topic(topic)])
            self._background.add_topic(topic, type_name, offered_qos)
        self.received[topic] += 1
        self._background.write(topic, data, now)

    def _discover(self) -> None:
        for name, types in self.get_topic_names_and_types():
            if name in self._pending and types:
                publishers = self.get_publishers_info_by_topic(name)
                if not publishers:
                    continue
                reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in publishers)
                latched = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in publishers)
                self._subscribe(name, types[0], QoSProfile(
                    depth=SUBSCRIPTION_DEPTH,
                    reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
                    durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE))
                del self._pending[name]

    # -- counters, flushing, stopping ------------------------------------------------------------------
    def _count_lost(self) -> None:
        """Add what the middleware counted lost since the last look (executor or main thread only)."""
        for topic, count in self._loss_counts.items():
            n = count.take()
            if n:
                self.lost[topic] += n

    def counters(self) -> dict[str, str]:
        """The loss counters as string key/values (``/diagnostics`` and the log summary use the same).
        Also called by the writer thread when a fault finishes the log: the counters are copied first
        (one C-level copy each, atomic under the GIL) while the executor may be adding to them."""
        received, lost, incompatible, stalls = (dict(self.received), dict(self.lost), dict(self.incompatible),
                                                list(self.stalls))
        c = {'received_total': str(sum(received.values())), 'lost_total': str(sum(lost.values())),
             'incompatible_qos_total': str(sum(incompatible.values())),
             'flush_period': str(self.writer.flush_period), 'output': str(self.writer.path)}
        for topic in sorted(set(received) | set(lost)):
            c[f'received.{topic}'] = str(received.get(topic, 0))
            c[f'lost.{topic}'] = str(lost.get(topic, 0))
        for topic, n in sorted(incompatible.items()):
            c[f'incompatible_qos.{topic}'] = str(n)
        if stalls:
            longest_end, longest = max(stalls, key=lambda s: s[1])
            c.update({'stalls': str(len(stalls)), 'stalled_s': f'{sum(s for _, s in stalls):.3f}',
                      'longest_stall_s': f'{longest:.3f}', 'longest_stall_end_ns': str(longest_end)})
        if self.in_process:
            c['recorded_in_process'] = ','.join(sorted(self.in_process))
        if self._background.dropped:
            c['not_recorded'] = str(self._background.dropped)   # received after the recording stopped
        return c

    @property
    def fault(self) -> WriteFault | None:
        """Why the recording stopped early (None while it runs, and after a clean stop)."""
        return self._background.fault

    def fault_line(self) -> str:
        """The one line that reports :attr:`fault` ('' without one)."""
        fault = self.fault
        if fault is None:
            return ''
        start = self.writer.start_ns
        at = _when(fault.at_stamp_ns, fault.at_ns, start)
        until = _when(fault.readable_until_stamp_ns, fault.readable_until_ns, start)
        kept = (f'log readable up to {until} ({fault.kept:,} messages' +
                (f'; {fault.cut:,} received after its last whole chunk were cut' if fault.cut else '') + ')'
                if fault.readable_until_ns is not None or fault.kept else 'nothing readable was written')
        extra = f'; {fault.problems}' if fault.problems else ''
        return (f'recording stopped at {at}: {fault.reason} ({fault.detail}); {kept} in {self.writer.path}{extra}; '
                'nothing more is recorded')

    def fate(self) -> str:
        """For a run summary: ``recording stopped at 9.4 s: No space left on device (log readable up to
        8.9 s)``, or '' when the recording did not stop early."""
        fault = self.fault
        if fault is None:
            return ''
        start = self.writer.start_ns
        at = _when(fault.at_stamp_ns, fault.at_ns, start, short=True)
        if fault.readable_until_ns is None and not fault.kept:
            return f'recording stopped at {at}: {fault.reason} (nothing readable was written)'
        until = _when(fault.readable_until_stamp_ns, fault.readable_until_ns, start, short=True)
        return f'recording stopped at {at}: {fault.reason} (log readable up to {until})'

    def _status(self) -> DiagnosticStatus:
        c = self.counters()
        fault = self.fault
        bad = c['lost_total'] != '0' or c['incompatible_qos_total'] != '0'
        if fault is not None:
            level, message = DiagnosticStatus.ERROR, self.fault_line()
            c.update(fault.record())
        elif bad:
            level, message = DiagnosticStatus.WARN, (f'{c["lost_total"]} lost, {c["incompatible_qos_total"]} '
                                                     'incompatible-QoS events')
        else:
            level, message = DiagnosticStatus.OK, f'recording to {self.writer.path}'
        return DiagnosticStatus(level=level, name=f'recorder: {self.get_fully_qualified_name()}',
                                hardware_id='micro_feeder', message=message,
                                values=[KeyValue(key=k, value=v) for k, v in c.items()])

    def _publish_diagnostics(self) -> None:
        if not self._closed:
            self._count_lost()
        msg = DiagnosticArray(status=[self._status()])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(msg)

    def _watch(self) -> None:
        """Look at the writer thread: report a fault, a bug or a skipped topic once; notice a stall of
        this whole process (a gap between two looks)."""
        now = time.monotonic()
        gap, self._last_watch = now - (self._last_watch or now), now
        if gap > STALL_REPORT:
            self._background.excuse()   # the writer thread was stopped with the process, not stuck
            self.stalls.append((time.time_ns(), gap))
            self.get_logger().warning(
                f'the recorder did not run for {gap:.1f} s (its process stopped, or its executor busy or starved of '
                'CPU): messages published meanwhile may be missing from the log (counted lost where the middleware '
                'dropped them)')
        if self._closed:
            return
        self._background.poll()
        self._report()

    def _report(self) -> None:
        background = self._background
        for topic, reason in background.skipped.items():
            if topic not in self._reported:
                self._reported.add(topic)
                self.get_logger().error(f'{topic} is not recorded: {reason}')
        if background.error and 'error' not in self._reported:
            self._reported.add('error')
            self.get_logger().error(f'recorder error (a bug, please report it):\n{background.error}')
        if self.fault is not None and 'fault' not in self._reported:
            self._reported.add('fault')
            self.get_logger().error(self.fault_line())
            self._publish_diagnostics()
            if not self.done.done():
                self.done.set_result(True)

    def _on_stop(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.close()
        response.success = True
        response.message = f'stopped: {self.writer.message_count} messages in {self.writer.path}'
        return response

    def close(self) -> Path:
        """Stop recording: write the summary with the counters and ``metadata.yaml``. Idempotent. After a
        fault, reports it (once) instead: the log was finished when it happened."""
        if not self._closed:
            for topic, (subscription, type_name) in self._topic_subscriptions.items():
                self._take_waiting(topic, type_name, subscription)
            self._count_lost()
            self._closed = True
            self._background.close()    # a write stuck at the end is a fault too, reported here
            self._report()
            if self.fault is None:
                self.get_logger().info(f'closed {self.writer.path}: {self.writer.message_count} messages')
        if not self.done.done():
            self.done.set_result(True)
        return self.writer.path

    def destroy_node(self) -> None:
        """Destroys the loss counts' event handles first: left to the garbage collector, one would be
        destroyed at an arbitrary moment, possibly after its subscription."""
        for count in self._loss_counts.values():
            count.destroy()
        self._loss_counts.clear()
        super().destroy_node()


def _when(stamp_ns: int | None, log_ns: int | None, start_ns: int | None, short: bool = False) -> str:
    """Where in the run: ``sim time 9.412 s`` from a header stamp, else ``log time +9.41 s`` (from the
    log's first message); ``short``: ``9.4 s`` for sim time."""
    if stamp_ns is not None:
        return f'{stamp_ns * 1e-9:.1f} s' if short else f'sim time {stamp_ns * 1e-9:.3f} s'
    if log_ns is not None and start_ns is not None:
        return f'log time +{(log_ns - start_ns) * 1e-9:.2f} s'
    return 'the start'


def main(args: list[str] | None = None) -> int:
    """Console script ``recorder``: record until SIGINT, SIGTERM or ``~/stop``, then print the
    log summary."""
    stop = init_ros('recorder', args)
    if stop is None:
        return 2
    try:
        node = Recorder()
    except (ValueError, OSError, ParameterException) as err:
        print(f'recorder: error: {err}', file=sys.stderr)
        rclpy.shutdown()
        return 2
    executor = EventsExecutor()
    executor.add_node(node)
    try:
        spin_until(executor, lambda: bool(stop) or node.done.done(), node.done)
    finally:
        path = node.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
    try:
        log = LogReader(path)
        summary = summarize(log)
        print(format_summary(summary, coverage(log, summary.recorder, summary.part.stamp)))
    except (OSError, ValueError) as err:
        print(f'recorder: nothing readable in {path}: {err}', file=sys.stderr)
    return 1 if node.fault is not None else 0


if __name__ == '__main__':
    sys.exit(main())
