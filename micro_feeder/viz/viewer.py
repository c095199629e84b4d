"""A Foxglove WebSocket server (foxglove-sdk) inside a process that runs rclpy nodes.

:meth:`Viewer.tap` makes every publisher a node already has also hand its messages to the server: the
publisher's ``publish`` is wrapped (on that publisher object only), so the viewer sees exactly what the
node publishes, in the same order, on the thread that publishes it, with no extra subscription. Each
topic becomes a Foxglove channel with its ROS 2 schema (``ros2msg``, the text the logs store) and CDR
bytes, so Foxglove decodes them as it decodes a log. On top:

* ``/foxglove/scene`` (``foxglove.SceneUpdate``) and ``/foxglove/transforms`` (``feeder`` -> ``contact``),
  built (:mod:`.scene`) from the latest ``particle/pose``, ``actuator/joint_states``,
  ``particle/contact_state`` and ``simulator/parameters`` (for the geometry) at most ``SCENE_RATE``;
* ``/foxglove/friction_limit`` (JSON): friction T with ±Q_max(N), the static limit at the normal load of
  each forwarded ``particle/contact_wrench`` (N; Q_max null in flight), from the contact model of the
  latest ``simulator/parameters`` (built when a viewer first subscribes, off the simulation's thread);
* sim time (the stamp of ``/clock`` and ``particle/pose``) broadcast with the protocol's ``time``
  capability at most ``TIME_RATE``, and used as every forwarded message's log time.

Rates (wall clock; the viewer cannot follow more, and a slowed-down run, ``--real-time-factor 0.01``,
shows more sim detail per frame): the per-tick state topics (``particle/pose``, ``particle/twist``,
``particle/contact_wrench``, ``actuator/joint_states``, ``/clock``) at most ``STATE_RATE`` each, every
other topic whole (``particle/contact_state`` changes, commands, receipts, parameters, diagnostics,
markers). Latched topics (transient local) are sent again to a viewer that subscribes late.

Cost: with no viewer subscribed a publish costs one extra Python call and a flag test; the work (CDR
serialisation of live messages, the scene) happens only for channels a viewer is subscribed to.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import foxglove
import numpy as np
from foxglove.channels import FrameTransformsChannel, SceneUpdateChannel
from foxglove.websocket import Capability

from ..interface import stamps, wire
from ..interface.stamps import header_stamp_ns
from ..logs.schemas import schema_text
from ..logs.sim_parameters import parameter_value
from ..physics.dynamics import MODES
from ..physics.surface import TrackParams
from .endpoint import Endpoint
from .scene import PART_SIZE, FeederScene

STATE_RATE = 200.0      # Hz (wall): most messages per second forwarded on each per-tick state topic
SCENE_RATE = 30.0       # Hz (wall): scene updates
TIME_RATE = 50.0        # Hz (wall): sim time broadcasts
STATE_TOPICS = ('particle/pose', 'particle/twist', 'particle/contact_wrench', 'actuator/joint_states', '/clock',
                'particles/poses', 'particles/states')
SCENE_TOPIC = '/foxglove/scene'
TRANSFORMS_TOPIC = '/foxglove/transforms'
FRICTION_TOPIC = '/foxglove/friction_limit'
FRICTION_SCHEMA = {
    'title': 'micro_feeder friction limit', 'type': 'object',
    'properties': {'friction': {'type': 'number', 'description': 'friction T along the surface tangent (N)'},
                   'q_max': {'type': ['number', 'null'], 'description': 'static limit Q_max(N) (N); null in flight'},
                   'minus_q_max': {'type': ['number', 'null'], 'description': '-Q_max (N)'},
                   'normal_load': {'type': 'number', 'description': 'normal load N (N)'}}}
NOT_FORWARDED = ('/parameter_events',)     # rclpy's own, published by every node

# What the scene is built from: role -> topic (relative names match in any namespace).
ROLES = {'pose': 'particle/pose', 'joints': 'actuator/joint_states', 'mode': 'particle/contact_state',
         'parameters': 'simulator/parameters', 'wrench': 'particle/contact_wrench', 'parts': 'particles/states'}


class ViewerError(RuntimeError):
    """The server cannot start (port in use, address not available)."""


def type_name(msg_type: type) -> str:
    """``geometry_msgs/msg/PoseStamped`` for the rclpy class ``geometry_msgs.msg.PoseStamped``."""
    return f'{msg_type.__module__.split(".")[0]}/msg/{msg_type.__name__}'


def matches(topic: str, name: str) -> bool:
    """True when the resolved ``topic`` is ``name`` (absolute) or ends with it (relative, any namespace)."""
    return topic == name if name.startswith('/') else topic == '/' + name or topic.endswith('/' + name)


def message_stamp_ns(msg: Any) -> int:
    """Sim time (ns) of a ``/clock`` or header-stamped message, live object or CDR bytes."""
    if isinstance(msg, bytes):
        return header_stamp_ns(msg)        # a Clock's first field sits where a Header's stamp does
    stamp = msg.clock if hasattr(msg, 'clock') else msg.header.stamp
    return stamps.stamp_ns(stamp)


@dataclass
class ForwardedTopic:
    """One ROS topic forwarded on one Foxglove channel."""

    topic: str
    msg_type: type
    channel: foxglove.Channel
    period: float                      # s (wall) between forwarded messages; 0 = every message
    latched: bool
    role: str | None
    time_source: bool
    sent: int = 0
    last_sent: float = -math.inf
    latest: Any = None                 # the last message published (kept for a role or a latched topic)
    publishers: list[Any] = field(default_factory=list)


class _Subscriptions:
    """foxglove ServerListener: counts subscriptions (a publish does nothing more while there are none)
    and re-sends a latched topic's last message to a late subscriber."""

    def __init__(self, viewer: Viewer):
        self._viewer = viewer
        self._lock = threading.Lock()
        self.count = 0

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            self.count += 1
        self._viewer._on_subscribe(channel.topic)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            self.count = max(0, self.count - 1)


class Viewer:
    """The live view's server; see the module docstring. ``close()`` stops it."""

    def __init__(self, endpoint: Endpoint, name: str = 'micro_feeder'):
        self.endpoint = endpoint
        self.announced = False              # the CLI has told the user where to connect
        self.context = foxglove.Context()
        self._subscriptions = _Subscriptions(self)
        try:
            self.server = foxglove.start_server(
                name=name, host=endpoint.host, port=endpoint.port, capabilities=[Capability.Time],
                server_listener=self._subscriptions, context=self.context)
        except RuntimeError as err:
            raise ViewerError(f'cannot listen on {endpoint.host}:{endpoint.port}: {err}') from err
        self.topics: dict[str, ForwardedTopic] = {}
        self._by_role: dict[str, ForwardedTopic] = {}
        self.scene_channel = SceneUpdateChannel(SCENE_TOPIC, context=self.context)
        self.transforms_channel = FrameTransformsChannel(TRANSFORMS_TOPIC, context=self.context)
        self.friction_channel = foxglove.Channel(FRICTION_TOPIC, schema=FRICTION_SCHEMA, context=self.context)
        self._friction_limit: Any = None            # (parameters message it was built from, Q_max function)
        self._building = threading.Thread()         # builds the friction limit when the parameters change
        self.scenes_sent = 0
        self.friction_sent = 0
        self.sim_ns = 0
        self._scene: FeederScene | None = None
        self._scene_parameters: Any = None
        self._last_scene = -math.inf
        self._last_time = -math.inf

    @property
    def url(self) -> str:
        host = f'[{self.endpoint.host}]' if ':' in self.endpoint.host else self.endpoint.host
        return f'ws://{host}:{self.server.port}'

    # -- publishers -----------------------------------------------------------------------------------

    def tap(self, node: Any) -> None:
        """Forward what every publisher ``node`` has now publishes (call it after the node is built). A
        latched topic's message published before (in the node's constructor) reaches the viewer through a
        transient-local subscription on the node, which the node's executor serves."""
        for publisher in node.publishers:
            if publisher.topic_name in NOT_FORWARDED:
                continue
            forwarded = self._topic(publisher)
            if any(p is publisher for p in forwarded.publishers):
                continue
            forwarded.publishers.append(publisher)
            publisher.publish = self._wrap(publisher.publish, forwarded)
            if forwarded.latched:
                node.create_subscription(publisher.msg_type, publisher.topic_name,
                                         lambda data, f=forwarded: self._on_latched(f, data),
                                         publisher.qos_profile, raw=True)

    def _on_latched(self, forwarded: ForwardedTopic, data: bytes) -> None:
        if forwarded.latest is None:
            forwarded.latest = data

    def _topic(self, publisher: Any) -> ForwardedTopic:
        topic = publisher.topic_name
        if topic not in self.topics:
            name = type_name(publisher.msg_type)
            channel = foxglove.Channel(
                topic, message_encoding='cdr', context=self.context,
                schema=foxglove.Schema(name=name, encoding='ros2msg', data=schema_text(name).encode()))
            role = next((r for r, t in ROLES.items() if matches(topic, t)), None)
            state = any(matches(topic, t) for t in STATE_TOPICS)
            # rclpy's DurabilityPolicy.TRANSIENT_LOCAL is 1; compared by name to need no rclpy import here
            latched = getattr(publisher.qos_profile.durability, 'name', '') == 'TRANSIENT_LOCAL'
            self.topics[topic] = ForwardedTopic(
                topic, publisher.msg_type, channel, 1.0 / STATE_RATE if state else 0.0, latched, role,
                time_source=matches(topic, '/clock') or matches(topic, 'particle/pose'))
            if role is not None:
                self._by_role.setdefault(role, self.topics[topic])
        return self.topics[topic]

    def _wrap(self, publish: Any, forwarded: ForwardedTopic) -> Any:
        keep = forwarded.role is not None or forwarded.latched
        subscriptions = self._subscriptions

        def publish_and_forward(msg: Any) -> None:
            publish(msg)
            if keep:
                forwarded.latest = msg
            if subscriptions.count:
                self._forward(forwarded, msg)
        return publish_and_forward

    def _forward(self, forwarded: ForwardedTopic, msg: Any) -> None:
        now = time.monotonic()
        if forwarded.time_source:
            self.sim_ns = message_stamp_ns(msg)
        if now - forwarded.last_sent >= forwarded.period:
            forwarded.last_sent = now
            if forwarded.channel.has_sinks():
                self._send(forwarded, msg)
            if forwarded.role == 'wrench':
                self._send_friction_limit(msg)
        if forwarded.role == 'pose':
            self._on_pose(now)

    def _send(self, forwarded: ForwardedTopic, msg: Any) -> None:
        data = msg if isinstance(msg, bytes) else wire.serialize(msg)
        forwarded.channel.log(data, log_time=self.sim_ns)
        forwarded.sent += 1

    def _on_subscribe(self, topic: str) -> None:
        if topic == FRICTION_TOPIC:
            self._build_friction_limit()
        forwarded = self.topics.get(topic)
        if forwarded is not None and forwarded.latched and forwarded.latest is not None:
            self._send(forwarded, forwarded.latest)

    def _build_friction_limit(self) -> None:
        """The static limit of the latest recorded parameters (the contact tables take tens of ms: built on
        the server's thread when a viewer subscribes, not on the thread that publishes)."""
        forwarded = self._by_role.get('parameters')
        latest = forwarded.latest if forwarded is not None else None
        if latest is None or (self._friction_limit is not None and self._friction_limit[0] is latest):
            return
        event = self._latest('parameters')
        from ..logs.friction_limit import static_limit
        try:
            limit = static_limit({p.name: parameter_value(p.value) for p in event.new_parameters})
        except ValueError:
            return
        self._friction_limit = (latest, limit)

    def _send_friction_limit(self, wrench: Any) -> None:
        if not self.friction_channel.has_sinks():
            return
        parameters = self._by_role.get('parameters')
        current = parameters.latest if parameters is not None else None
        stale = self._friction_limit is None or self._friction_limit[0] is not current
        if stale and current is not None and not self._building.is_alive():
            self._building = threading.Thread(target=self._build_friction_limit, name='foxglove-friction-limit',
                                              daemon=True)
            self._building.start()
        if self._friction_limit is None:
            return
        if isinstance(wrench, bytes):
            wrench = wire.deserialize(wrench, self._by_role['wrench'].msg_type)
        force = wrench.wrench.force
        q = float(self._friction_limit[1](np.array([force.z]))[0])
        q_max = None if math.isnan(q) else q
        self.friction_sent += 1
        self.friction_channel.log({'friction': force.x, 'q_max': q_max, 'minus_q_max': None if q_max is None else -q,
                                   'normal_load': force.z}, log_time=self.sim_ns)

    # -- sim time and scene ---------------------------------------------------------------------------

    def _on_pose(self, now: float) -> None:
        if now - self._last_time >= 1.0 / TIME_RATE:
            self._last_time = now
            self.server.broadcast_time(self.sim_ns)
        if now - self._last_scene >= 1.0 / SCENE_RATE and (
                self.scene_channel.has_sinks() or self.transforms_channel.has_sinks()):
            self._last_scene = now
            self._send_scene()

    def _latest(self, role: str) -> Any:
        """The last message of a role's topic, decoded if it was published as CDR bytes (a replay)."""
        forwarded = self._by_role.get(role)
        if forwarded is None or forwarded.latest is None:
            return None
        msg = forwarded.latest
        if isinstance(msg, bytes):
            msg = wire.deserialize(msg, forwarded.msg_type)
        return msg

    def _send_scene(self) -> None:
        pose = self._latest('pose')
        scene = self._feeder_scene()
        if pose is None or scene is None:
            return
        joints = self._latest('joints')
        strokes = list(joints.position) if joints is not None else []
        if len(strokes) != scene.centers.size:
            strokes = [0.0] * scene.centers.size
        mode = self._latest('mode')
        p, q = pose.pose.position, pose.pose.orientation
        theta = -2.0 * math.atan2(q.y, q.w)      # the pose's orientation is a rotation by -θ about y
        t_ns = message_stamp_ns(pose)
        self.scene_channel.log(scene.update(t_ns, strokes, p.x, p.z, theta, mode.data if mode else '',
                                            self._other_parts()), log_time=t_ns)
        self.transforms_channel.log(scene.transforms(t_ns, p.x, p.z, theta), log_time=t_ns)
        self.scenes_sent += 1

    def _other_parts(self) -> list[tuple[float, float, str]]:
        """Parts 1, 2, … as (x, z, mode) from the latest ``particles/states`` (none with one part)."""
        states = self._latest('parts')
        if states is None or len(states.layout.dim) != 2:
            return []
        table = np.asarray(states.data).reshape(states.layout.dim[0].size, states.layout.dim[1].size)
        column = {name: k for k, name in enumerate(states.layout.dim[1].label.split(','))}
        return [(float(row[column['x']]), float(row[column['z']]), MODES[int(row[column['mode']])])
                for row in table[1:]]

    def _feeder_scene(self) -> FeederScene | None:
        """The scene of the geometry in the latest ``simulator/parameters`` (rebuilt when they change)."""
        forwarded = self._by_role.get('parameters')
        latest = forwarded.latest if forwarded is not None else None
        if latest is not self._scene_parameters:
            self._scene_parameters = latest
            event = self._latest('parameters')
            values = {p.name: parameter_value(p.value) for p in event.new_parameters} if event else {}
            try:
                track = values.get('surface.kind') == 'track'
                lift = math.sin(values.get('track.vibration_angle', TrackParams.vibration_angle)) if track else None
                self._scene = FeederScene(values.get('surface.centers', []), values.get('surface.widths', []),
                                          PART_SIZE, lift)
            except ValueError:
                self._scene = None
        return self._scene

    # -- end ------------------------------------------------------------------------------------------

    def summary(self) -> str:
        """``foxglove: ws://…: forwarded 1001 /particle/pose, …`` (messages sent to subscribed viewers)."""
        counts = [(f.sent, f.topic) for f in self.topics.values() if f.sent]
        counts.append((self.scenes_sent, SCENE_TOPIC))
        if self.friction_sent:
            counts.append((self.friction_sent, FRICTION_TOPIC))
        return f'foxglove: {self.url}: forwarded ' + ', '.join(f'{n} {t}' for n, t in counts)

    def close(self) -> None:
        """Stop the server (the wrapped publishers go on publishing; they forward to nobody)."""
        self._subscriptions.count = 0
        self.server.stop()
