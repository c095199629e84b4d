"""The recorder node: subscribes in serialized form and writes an MCAP log (rosbag2 layout).

Topics default to every micro_feeder topic (docs/interface.md) plus ``/clock`` and ``/diagnostics``,
resolved against the node's namespace. Known topics are subscribed at start with the QoS their
publishers offer (transient-local ones too, so latched state is captured) and a deeper history (so a
burst waits in the queue instead of being dropped); other configured topics are subscribed when they
appear in the graph. Each message is written with its receive time (wall clock, ns) as log time.

Loss accounting: QoS message-lost and incompatible-QoS events, per topic, published on
``/diagnostics`` at 1 Hz (and so recorded too, which keeps them in a truncated log) and stored in the
log summary on a clean stop. rclpy's EventsExecutor cannot deliver message info (sequence numbers) to
a callback (``SystemError`` in rclpy 9.1.2), so gaps in a publisher's sequence are not counted.

Use as a program (``recorder --ros-args -p output:=out/run1``: stops cleanly on SIGINT, SIGTERM or the
``~/stop`` service, ``/recorder/stop`` by default) or in-process: ``r = Recorder(context=ctx)``, add it to
an executor that runs on the main thread, spin, then ``r.close()``.
"""

from __future__ import annotations

import datetime
import sys
import time
from collections import Counter
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.context import Context
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.exceptions import ParameterException
from rclpy.experimental import EventsExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from std_srvs.srv import Trigger

from ..interface.topics import TOPICS, TOPICS_BY_NAME
from ..logs.metadata import dump_qos
from ..logs.reader import LogReader
from ..logs.summary import format_summary, summarize
from ..logs.writer import LogWriter
from ._ros import SERVICE_QOS, message_class, qos_to_dict, spin_until, topic_qos
from .spin import init_ros

SUBSCRIPTION_DEPTH = 1000  # messages queued per topic while the writer is busy
DIAGNOSTICS_PERIOD = 1.0  # s
DISCOVERY_PERIOD = 1.0  # s


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


class Recorder(Node):
    """Records topics to an MCAP log; see the module docstring."""

    def __init__(self, *, context: Context | None = None, cli_args: list[str] | None = None,
                 parameter_overrides: list | None = None, node_name: str = 'recorder',
                 namespace: str | None = None) -> None:
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
        p = {name: self.get_parameter(name).value for name in
             ('output', 'topics', 'flush_period', 'split_size', 'split_duration')}
        output = p['output'] or datetime.datetime.now().strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
        self.writer = LogWriter(output, flush_period=p['flush_period'], split_size=p['split_size'],
                                split_duration=p['split_duration'])
        self.done = Future()
        self.received: Counter[str] = Counter()
        self.lost: Counter[str] = Counter()
        self.incompatible: Counter[str] = Counter()
        self._closed = False
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
        self.create_timer(min(p['flush_period'] / 2, 0.25), self._flush_if_due)
        if self._pending:
            self.create_timer(DISCOVERY_PERIOD, self._discover)
        self.create_service(Trigger, '~/stop', self._on_stop, qos_profile=SERVICE_QOS)
        self.get_logger().info(f'recording {len(p["topics"])} topics to {self.writer.path}')

    # -- subscriptions --------------------------------------------------------------------------------
    def _subscribe(self, topic: str, type_name: str, qos: QoSProfile) -> None:
        events = SubscriptionEventCallbacks(
            message_lost=lambda info, t=topic: self.lost.update({t: info.total_count_change}),
            incompatible_qos=lambda info, t=topic: self.incompatible.update({t: info.total_count_change}))
        self.create_subscription(message_class(type_name), topic,
                                 lambda data, t=topic, n=type_name: self._on_message(t, n, data),
                                 qos, raw=True, event_callbacks=events)

    def _on_message(self, topic: str, type_name: str, data: bytes) -> None:
        now = time.time_ns()
        if self._closed:
            return
        if topic not in self.received:
            offered = [qos_to_dict(info.qos_profile) for info in self.get_publishers_info_by_topic(topic)]
            self.writer.add_topic(topic, type_name, dump_qos(offered))
        self.received[topic] += 1
        self.writer.write(topic, data, now)

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
    def counters(self) -> dict[str, str]:
        """The loss counters as string key/values (``/diagnostics`` and the log summary use the same)."""
        c = {'received_total': str(sum(self.received.values())), 'lost_total': str(sum(self.lost.values())),
             'incompatible_qos_total': str(sum(self.incompatible.values())),
             'flush_period': str(self.writer.flush_period), 'output': str(self.writer.path)}
        for topic in sorted(set(self.received) | set(self.lost)):
            c[f'received.{topic}'] = str(self.received[topic])
            c[f'lost.{topic}'] = str(self.lost[topic])
        for topic, n in sorted(self.incompatible.items()):
            c[f'incompatible_qos.{topic}'] = str(n)
        return c

    def _publish_diagnostics(self) -> None:
        c = self.counters()
        bad = c['lost_total'] != '0' or c['incompatible_qos_total'] != '0'
        status = DiagnosticStatus(
            level=DiagnosticStatus.WARN if bad else DiagnosticStatus.OK,
            name=f'recorder: {self.get_fully_qualified_name()}', hardware_id='micro_feeder',
            message=(f'{c["lost_total"]} lost, {c["incompatible_qos_total"]} incompatible-QoS events'
                     if bad else f'recording to {self.writer.path}'),
            values=[KeyValue(key=k, value=v) for k, v in c.items()])
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self._diagnostics.publish(msg)

    def _flush_if_due(self) -> None:
        if not self._closed:
            self.writer.flush_if_due()

    def _on_stop(self, _request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.close()
        response.success = True
        response.message = f'stopped: {self.writer.message_count} messages in {self.writer.path}'
        return response

    def close(self) -> Path:
        """Stop recording: write the summary with the counters and ``metadata.yaml``. Idempotent."""
        if not self._closed:
            self._closed = True
            self.writer.custom_data.update(self.counters())
            self.writer.close()
            self.get_logger().info(f'closed {self.writer.path}: {self.writer.message_count} messages')
        if not self.done.done():
            self.done.set_result(True)
        return self.writer.path


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
    print(format_summary(summarize(LogReader(path))))
    return 0


if __name__ == '__main__':
    sys.exit(main())
