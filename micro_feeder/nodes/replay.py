"""The replay node: publishes a log's messages on their topics at their recorded timing × ``rate``.

Messages are published as recorded CDR bytes (no decode), each with the QoS its publisher offered when
the log stored it (``offered_qos_profiles``; reliable, volatile, depth 100 otherwise), changed per topic by
a rosbag2 QoS overrides file (``qos_profile_overrides_path``). As ``ros2 bag play`` users expect: it can
wait for subscribers (``wait_for_subscribers``: one on every topic named in ``topics``, or, replaying every
topic, one on any of them; at most ``wait_for_subscribers_timeout`` seconds, then it ends with ``timed_out``
saying which topics had none) and/or ``delay`` seconds before the first message, ``start_paused``, stop
after ``playback_duration`` seconds of log, and, with ``publish_clock``, publish the log's *sim* time on
``/clock`` (the latest header stamp or recorded ``/clock`` replayed, falling back to the log time for a log
with neither) with rosbag2's clock QoS (best effort, keep last 1). In a node namespace (``-r __ns:=/NS``)
the recorded names are published under it, except
``/clock`` and ``/diagnostics``, which are global by convention. A player thread
sleeps until each message's due time (coarse sleep, then a short busy wait) and records its own timing
error: actual publish time minus due time [s] (the last ``TIMING_WINDOW`` of them, with the count and the
maximum over the whole run, so that ``loop`` runs in bounded memory). A pass that has nothing to publish
ends the replay with ``error`` set instead of looping on nothing. The executor, on the main thread, serves
``replay/pause`` (std_srvs/SetBool) and the optional ``/clock`` (playback log time) timer.
"""

from __future__ import annotations

import sys
import threading
import time
from collections import deque
from collections.abc import Callable

import numpy as np
import rclpy
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, ParameterType
from rclpy.context import Context
from rclpy.exceptions import ParameterException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from std_srvs.srv import SetBool

from ..interface.stamps import header_stamp_ns
from ..logs.metadata import parse_qos, read_qos_overrides
from ..logs.reader import LogMessage, LogReader
from ..progress import Progress
from ._ros import StopFlag, message_class, qos_from_dict, spin_until
from .fastdds_shm import remove_stale_files
from .refused import RefusedPublishes

DEFAULT_QOS = QoSProfile(depth=100)
# rosbag2's /clock publisher (rclcpp::ClockQoS): best effort, volatile, keep last 1.
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT, durability=DurabilityPolicy.VOLATILE)
CLOCK_TYPES = ('rosgraph_msgs/msg/Clock', 'rosgraph_msgs/Clock')
FIRST_STAMP_SEARCH = 10_000  # messages looked at for the first sim time before playing
GLOBAL_TOPICS = ('/clock', '/diagnostics', '/rosout', '/parameter_events', '/tf', '/tf_static')
BUSY_WAIT = 0.002  # s: last stretch before a due time spent polling the clock instead of sleeping
TIMING_WINDOW = 100_000  # timing errors kept for the percentiles (the latest ones)
DEFAULT_WAIT_TIMEOUT = 30.0  # s: how long wait_for_subscribers waits by default


def _descriptor(description: str, type_: int, float_range: tuple[float, float] | None = None
                ) -> ParameterDescriptor:
    d = ParameterDescriptor(description=description, type=type_, read_only=True)
    if float_range:
        d.floating_point_range = [FloatingPointRange(from_value=float_range[0], to_value=float_range[1])]
    return d


class Replay(Node):
    """Replays a log; ``finished`` completes after the last message (never with ``loop``)."""

    def __init__(self, *, context: Context | None = None, cli_args: list[str] | None = None,
                 parameter_overrides: list | None = None) -> None:
        super().__init__('replay', context=context, cli_args=cli_args,
                         parameter_overrides=parameter_overrides or [])
        s, d, b, a = (ParameterType.PARAMETER_STRING, ParameterType.PARAMETER_DOUBLE,
                      ParameterType.PARAMETER_BOOL, ParameterType.PARAMETER_STRING_ARRAY)
        self.declare_parameter('log', '', _descriptor('log directory or .mcap file to replay', s))
        self.declare_parameter('rate', 1.0, _descriptor('playback speed factor', d, (0.01, 100.0)))
        self.declare_parameter('loop', False, _descriptor('start again at start_offset after the end', b))
        self.declare_parameter('start_offset', 0.0, _descriptor('skip this long [s] from the log start', d,
                                                                (0.0, 1e9)))
        self.declare_parameter('topics', [''], _descriptor('topics to replay; empty = all', a))
        self.declare_parameter('remap', [''], _descriptor('topic renames, FROM:=TO (recorded names)', a))
        self.declare_parameter('publish_clock', False, _descriptor(
            'publish the playback log time on /clock (the recorded /clock is then not replayed)', b))
        self.declare_parameter('clock_frequency', 100.0, _descriptor('/clock rate [Hz]', d, (1.0, 1000.0)))
        self.declare_parameter('delay', 0.0, _descriptor('wait this long [s] before the first message', d,
                                                         (0.0, 3600.0)))
        self.declare_parameter('wait_for_subscribers', False, _descriptor(
            'before the first message, wait for a subscriber on every topic named in "topics" (all topics '
            'replayed: on any one of them)', b))
        self.declare_parameter('wait_for_subscribers_timeout', DEFAULT_WAIT_TIMEOUT, _descriptor(
            'wait_for_subscribers gives up after this long [s]: the replay ends, nothing published', d,
            (0.0, 86400.0)))
        self.declare_parameter('start_paused', False, _descriptor('start paused (replay/pause false resumes)', b))
        self.declare_parameter('playback_duration', 0.0, _descriptor(
            'replay only this long [s] of the log from start_offset; 0 = to the end', d, (0.0, 1e9)))
        self.declare_parameter('qos_profile_overrides_path', '', _descriptor(
            'rosbag2 QoS overrides file: topic -> QoS policies replacing the recorded ones', s))
        p = {n: self.get_parameter(n).value for n in
             ('log', 'rate', 'loop', 'start_offset', 'topics', 'remap', 'publish_clock', 'clock_frequency', 'delay',
              'wait_for_subscribers', 'wait_for_subscribers_timeout', 'start_paused', 'playback_duration',
              'qos_profile_overrides_path')}
        if not p['log']:
            raise ValueError('parameter "log" is required (the log to replay)')
        self.log = LogReader(p['log'])
        self.rate, self.loop = p['rate'], p['loop']
        self.start_ns = self.log.start_ns + int(p['start_offset'] * 1e9)
        self.end_ns = self.start_ns + int(p['playback_duration'] * 1e9) if p['playback_duration'] else None
        self.delay, self.wait_for_subscribers = p['delay'], p['wait_for_subscribers']
        self.wait_timeout = p['wait_for_subscribers_timeout']
        wanted = [t for t in p['topics'] if t]
        names = [self._recorded(t, 'topic') for t in wanted] if wanted else list(self.log.topics)
        # the topics the user named each need a subscriber; replaying a whole log (/diagnostics, markers,
        # parameters ... which nobody may listen to), one subscriber on any topic is enough
        self.wait_for_every_topic = bool(wanted)
        self._read = list(names)        # what the player reads: with publish_clock, the recorded /clock too
        if p['publish_clock']:
            names = [n for n in names if n != '/clock']
            if '/clock' in self.log.topics and '/clock' not in self._read:
                self._read.append('/clock')
        overrides = {}
        if p['qos_profile_overrides_path']:
            overrides = {self._recorded(t, 'QoS override for'): profile for t, profile
                         in read_qos_overrides(p['qos_profile_overrides_path']).items()}
        remap = {}
        for rule in (r for r in p['remap'] if r):
            source, sep, target = rule.partition(':=')
            if not (sep and source and target):
                raise ValueError(f'remap "{rule}" is not FROM:=TO')
            remap[self._recorded(source, 'remap')] = target
        self.topics = names
        self._outputs = {}
        for name in names:
            topic = self.log.topics[name]
            offered = parse_qos(topic.metadata.get('offered_qos_profiles', ''))
            profile = {**(offered[0] if offered else {}), **overrides.get(name, {})}
            qos = qos_from_dict(profile, DEFAULT_QOS)
            self._outputs[name] = self.create_publisher(message_class(topic.type), remap.get(name, self._output(name)),
                                                        qos)
        self.timing_errors: deque[float] = deque(maxlen=TIMING_WINDOW)  # the latest ones [s]
        self.timing_count = 0  # over the whole run
        self.timing_max = float('-inf')  # over the whole run [s]
        self.published = 0
        self.error: str | None = None  # why the replay stopped early (a pass had nothing to publish)
        self.timed_out: str | None = None  # wait_for_subscribers gave up (which topics had no subscriber)
        self.failure: str | None = None  # why the player thread died (a bug or an unreadable log)
        self._start_offset = p['start_offset']
        self.finished = Future()
        self.playback_ns = self.start_ns
        # The latest header stamp or recorded /clock replayed [ns]; before the first message, the first one due.
        self.sim_ns: int | None = self._first_stamp() if p['publish_clock'] else None
        self._paused_since: float | None = time.monotonic() if p['start_paused'] else None
        self._pause_shift = 0.0
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self.create_service(SetBool, 'replay/pause', self._on_pause)
        if p['publish_clock']:
            self._clock_pub = self.create_publisher(Clock, '/clock', CLOCK_QOS)
            self.create_timer(1.0 / p['clock_frequency'], self._publish_clock)
        self.refused = RefusedPublishes(self.get_logger())
        self._thread = threading.Thread(target=self._play, name='replay-player', daemon=True)

    def _recorded(self, name: str, what: str) -> str:
        """The recorded name of ``name`` (relative names resolved as the reader does); ValueError when
        the log has no such topic."""
        resolved = self.log.resolve(name)
        if resolved is None:
            raise ValueError(f'{what} "{name}": no such topic in {self.log.path} '
                             f'(it has {", ".join(sorted(self.log.topics)) or "no topic"})')
        return resolved

    @staticmethod
    def _stamp(m: LogMessage) -> int | None:
        """The sim time a message carries: its header stamp, or a recorded /clock's time; None for neither."""
        return m.stamp_ns if m.stamped else header_stamp_ns(m.data) if m.type in CLOCK_TYPES else None

    def _first_stamp(self) -> int | None:
        """The sim time of the first stamped message from ``start_offset`` (None: the log has none early on)."""
        for i, m in enumerate(self.log.messages(self._read, start_ns=self.start_ns, end_ns=self.end_ns)):
            if (stamp := self._stamp(m)) is not None or i >= FIRST_STAMP_SEARCH:
                return stamp
        return None

    def _output(self, name: str) -> str:
        """The name ``name`` is published under: relative to the node namespace, except the global topics."""
        return name if name in GLOBAL_TOPICS or self.get_namespace() == '/' else name.lstrip('/')

    @property
    def end_of_playback_ns(self) -> int:
        """Log time [ns] at which this playback ends (the log end, or start_offset + playback_duration)."""
        return self.log.end_ns if self.end_ns is None else min(self.end_ns, self.log.end_ns)

    def start(self) -> None:
        """Start playing (publishers should be matched first if nothing may be missed: wait_for_subscribers)."""
        self._thread.start()

    def _unmatched(self) -> list[str]:
        """The topics still waiting for a subscriber (published names); empty when the wait is over: every
        topic named in ``topics`` has one, or, replaying every topic, any one of them has."""
        waiting = sorted(pub.topic_name for pub in self._outputs.values() if not pub.get_subscription_count())
        if not self.wait_for_every_topic and len(waiting) < len(self._outputs):
            return []
        return waiting

    def _before_first_message(self) -> bool:
        """Wait for subscribers (at most ``wait_timeout``) and/or the delay; False when stopped meanwhile or
        when the wait timed out (``timed_out`` says why)."""
        if self.wait_for_subscribers and self._outputs:
            deadline = time.monotonic() + self.wait_timeout
            waiting = self._unmatched()
            if waiting:
                which = 'every one' if self.wait_for_every_topic else 'any'
                self.get_logger().info(f'waiting for a subscriber on {which} of {", ".join(waiting)} '
                                       f'(at most {self.wait_timeout:g} s)')
            while waiting := self._unmatched():
                if time.monotonic() > deadline:
                    self.timed_out = (f'no subscriber after {self.wait_timeout:g} s on '
                                      f'{"" if self.wait_for_every_topic else "any of "}{", ".join(waiting)}: '
                                      'nothing was replayed')
                    return False
                if self._stop.wait(0.01):
                    return False
        return not self._stop.wait(self.delay) if self.delay else True

    def _play(self) -> None:
        try:
            self._play_passes()
        except Exception as err:  # a dead player must not leave the process idling: report and end
            self.failure = f'the player stopped: {type(err).__name__}: {err}'
        if not self.finished.done():
            self.finished.set_result(self.failure is None)

    def _play_passes(self) -> None:
        if not self._before_first_message():
            return
        while not self._stop.is_set():
            origin = time.monotonic()
            with self._lock:
                self._pause_shift = 0.0
            published = 0
            for m in self.log.messages(self._read, start_ns=self.start_ns, end_ns=self.end_ns):
                due = origin + (m.log_time_ns - self.start_ns) * 1e-9 / self.rate
                if not self._wait_until(due):
                    return
                stamp = self._stamp(m)
                if stamp is not None:
                    self.sim_ns = stamp
                output = self._outputs.get(m.topic)
                if output is None:       # the recorded /clock, read for the sim time only
                    continue
                if not self.refused.publish(output, m.data):
                    continue
                error = time.monotonic() - due - self._pause_shift
                self.timing_errors.append(error)
                self.timing_count += 1
                self.timing_max = max(self.timing_max, error)
                self.playback_ns = m.log_time_ns
                self.published += 1
                published += 1
            if not published:
                self.error = (f'nothing to publish: no message of {", ".join(self.topics) or "any topic"} at or '
                              f'after start_offset {self._start_offset:g} s (the log spans '
                              f'{self.log.duration:.3f} s)')
                break
            if not self.loop:
                break

    def _wait_until(self, due: float) -> bool:
        """Sleep until ``due`` (+ time spent paused); False when stopped."""
        while True:
            if self._stop.is_set():
                return False
            with self._lock:
                paused = self._paused_since is not None
                target = due + self._pause_shift
            left = target - time.monotonic()
            if paused:
                self._stop.wait(0.01)
            elif left > BUSY_WAIT:
                self._stop.wait(left - BUSY_WAIT)
            elif left > 0:
                continue
            else:
                return True

    def _on_pause(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        with self._lock:
            now = time.monotonic()
            if request.data and self._paused_since is None:
                self._paused_since = now
            elif not request.data and self._paused_since is not None:
                self._pause_shift += now - self._paused_since
                self._paused_since = None
        response.success = True
        response.message = 'paused' if request.data else 'playing'
        return response

    def _publish_clock(self) -> None:
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(self.playback_ns if self.sim_ns is None else self.sim_ns,
                                                  1_000_000_000)
        self._clock_pub.publish(msg)

    def timing_report(self) -> str:
        """p50/p99/max of the publish timing error [ms]."""
        if not self.timing_count:
            return 'no message published'
        e = np.asarray(self.timing_errors) * 1e3
        window = '' if len(e) == self.timing_count else f' (p50/p99 of the last {len(e)})'
        return (f'{self.timing_count} messages, timing error p50 {np.percentile(e, 50):.3f} ms, '
                f'p99 {np.percentile(e, 99):.3f} ms, max {self.timing_max * 1e3:.3f} ms{window}')

    def close(self) -> None:
        """Stop the player thread."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()


def main(args: list[str] | None = None, tap: Callable[[Node], None] | None = None) -> int:
    """Console script ``replay``: ``replay --ros-args -p log:=out/run1 -p rate:=2.0``. ``tap`` is given the
    node before it plays (``micro-feeder replay --foxglove``). Exit status: 0 at the end of the replay, 128 +
    the signal number when SIGINT (130) or SIGTERM (143) stopped it, 1 when the wait for subscribers timed
    out or the player died, 2 for a refused parameter or nothing to publish."""
    remove_stale_files()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    stop = StopFlag().install()
    try:
        node = Replay()
    except (ValueError, OSError, ParameterException) as err:
        print(f'replay: error: {err}', file=sys.stderr)
        rclpy.shutdown()
        return 2
    if tap is not None:
        tap(node)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    node.start()
    span_ms = max((node.end_of_playback_ns - node.start_ns) // 1_000_000, 1)
    progress = Progress('replay', span_ms, 'ms of log')

    def done() -> bool:
        progress((node.playback_ns - node.start_ns) // 1_000_000)
        return bool(stop) or node.finished.done()

    try:
        spin_until(executor, done, node.finished)
    finally:
        progress.close()
        node.close()
        print(f'replay: {node.timing_report()}')
        refused = node.refused.counts()
        if refused:
            print(f'replay: the middleware refused {sum(refused.values())} messages (no subscriber got them): '
                  + ', '.join(f'{topic} {n}' for topic, n in sorted(refused.items())), file=sys.stderr)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown()
    if stop.signal is not None:
        return 128 + stop.signal
    if node.error:
        print(f'replay: error: {node.error}', file=sys.stderr)
        return 2
    for reason in (node.timed_out, node.failure):
        if reason:
            print(f'replay: error: {reason}', file=sys.stderr)
            return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
