"""A message the middleware refuses to take (``RCLError: cannot publish data``) is counted and reported, and the
simulator (or the actuator) runs on. Before, a refusal ended the simulation for every subscriber.

Fast DDS refuses a write when it cannot make room in a full writer history within ``max_blocking_time``. In a
clean-clone CI run, a recorder that had been stopped (SIGSTOP) resumed and asked for repairs on a loaded machine,
and its publisher was refused. That state cannot be brought about on demand. So :class:`RefusingPublisher`
wraps a real publisher and refuses its first messages with the same error. Everything else here is the real
node, middleware and subscriber.
"""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from node_helpers import Probe
from rclpy._rclpy_pybind11 import RCLError
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from ros_helpers import wait_until
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from micro_feeder.interface.names import split_window_id
from micro_feeder.nodes._ros import topic_qos
from micro_feeder.nodes.actuator import Actuator
from micro_feeder.nodes.simulator import Simulator
from micro_feeder.realtime.diagnostics import WARN

pytestmark = pytest.mark.faults

REFUSED = 3


class RefusingPublisher:
    """A real publisher whose ``refusals`` messages after the first ``after`` the middleware 'refuses', as
    Fast DDS does."""

    def __init__(self, publisher: Any, refusals: int, after: int = 0) -> None:
        self._publisher = publisher
        self.refusals = refusals
        self.after = after              # messages let through before the refusals

    def publish(self, message: Any) -> None:
        if self.after:
            self.after -= 1
        elif self.refusals:
            self.refusals -= 1
            raise RCLError('Failed to publish: cannot publish data, at /project/src/rmw_publish.cpp:68')
        self._publisher.publish(message)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._publisher, name)


def _values(status: Any) -> dict[str, str]:
    return {kv.key: kv.value for kv in status.values}


def test_a_refused_state_message_is_counted_and_the_simulator_runs_on(ros_context: Context) -> None:
    sim = Simulator(context=ros_context, namespace='/refused', hold=True)
    listener = Node('pose_listener', namespace='/refused', context=ros_context)
    poses: list[float] = []
    listener.create_subscription(PoseStamped, 'particle/pose',
                                 lambda m: poses.append(m.header.stamp.sec + m.header.stamp.nanosec * 1e-9),
                                 topic_qos('particle/pose'))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    executor.add_node(listener)
    try:
        sim.diagnostics()                                   # the report window starts here
        wait_until(lambda: sim._outputs._pub_pose.get_subscription_count() > 0, 30, executor=executor,
                   what='the listener matched')
        refusing = RefusingPublisher(sim._outputs._pub_pose, REFUSED)
        sim._outputs._pub_pose = refusing
        sim.resume()
        wait_until(lambda: len(poses) >= 50, 30, executor=executor, what='poses after the refused ones')
        assert refusing.refusals == 0 and not sim.error
        first = sim.diagnostics()
        again = sim.diagnostics()
    finally:
        executor.shutdown()
        listener.destroy_node()
        sim.destroy_node()
    assert first.level == bytes([WARN]), first.message
    assert f'refused {REFUSED} message(s)' in first.message and '/refused/particle/pose' in first.message
    values = _values(first)
    assert values['publishes_refused'] == str(REFUSED)
    assert values['publishes_refused./refused/particle/pose'] == str(REFUSED)
    assert 'refused' not in again.message                 # nothing new since: the count stays, the warning goes
    assert _values(again)['publishes_refused'] == str(REFUSED)
    assert poses == sorted(poses)                         # what did go out went out in order


def test_a_refused_burst_is_reported_not_sent_and_the_actuator_runs_on(ros_context: Context) -> None:
    """The actuator's burst the middleware refuses: the start service says it was not sent (no burst counted,
    its number kept for the next), the actuator stays up, the next start sends it, and the actuator's
    ``/diagnostics`` counts the refusal and warns. Before, the refusal raised out of the service callback."""
    actuator = Actuator(context=ros_context, overrides={'auto_start': False, 'stroke.count': 2})
    probe = Probe(context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(actuator)
    executor.add_node(probe)
    actuator._pub = RefusingPublisher(actuator._pub, 1)
    try:
        refused = probe.call(executor, Trigger, 'actuator/start')
        assert not refused.success and refused.message.startswith('burst not sent: the middleware refused it')
        assert actuator.bursts == 0
        sent = probe.call(executor, Trigger, 'actuator/start')
        assert sent.message.startswith('burst sent'), sent.message
        trajectories = probe.msgs['actuator/trajectory']
        wait_until(lambda: trajectories, 10.0, executor=executor, what='the burst sent again')
        assert trajectories[-1].header.frame_id.endswith(':b1') and actuator.bursts == 1

        def stroke_status() -> Any:
            return next((s for array in probe.msgs['/diagnostics'] for s in array.status
                         if s.name.endswith(': stroke') and _values(s).get('publishes_refused') == '1'), None)
        wait_until(stroke_status, 10.0, executor=executor, what="the actuator's /diagnostics after the refusal")
        assert stroke_status().level == bytes([WARN])
    finally:
        executor.shutdown()


def test_a_refused_auto_start_burst_is_sent_again(ros_context: Context) -> None:
    """``auto_start``: the burst the middleware refused is sent again on the next tick and reaches the
    simulator as the first burst (before, the refusal was logged and the burst never sent)."""
    sim = Simulator(context=ros_context, namespace='/auto_refused', hold=True)
    actuator = Actuator(context=ros_context, namespace='/auto_refused', overrides={'stroke.count': 1})
    refusing = actuator._pub = RefusingPublisher(actuator._pub, 1)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    executor.add_node(actuator)
    try:
        wait_until(lambda: sim.commands.received >= 1, 30, executor=executor, what='the burst at the simulator')
        assert refusing.refusals == 0 and actuator.bursts == 1
        assert actuator.publishes.total() == 1
        assert actuator.state() == 'idle'          # the auto-start timer is gone once the burst went out
    finally:
        executor.shutdown()


def test_a_refused_controller_burst_is_fired_again_and_the_feed_ends_where_it_would_have(ros_context: Context) -> None:
    """The feed controller's first burst refused by the middleware (lockstep): counted, and the same burst
    fired at the next state; the feed takes the bursts it takes without the refusal and ends at the same x,
    one step later. Before, the refusal raised out of the pose callback."""
    from micro_feeder.nodes.feed_controller import FeedController
    from micro_feeder.nodes.spin import spin_nodes

    finals = {}
    for refusals in (0, 1):
        sim = Simulator(context=ros_context, overrides={'lockstep': True})
        controller = FeedController(context=ros_context, overrides={'feed.target_x': 0.46e-3, 'lockstep': True})
        refusing = controller._pub_trajectory = RefusingPublisher(controller._pub_trajectory, refusals)
        try:
            spin_nodes([sim, controller], lambda c=controller, s=sim: c.done or s.stepper.t > 1.0, ros_context)
            assert refusing.refusals == 0 and controller.publishes.total() == refusals
            finals[refusals] = (controller.planner.status, controller.planner.bursts, controller.commands_sent,
                                sim.commands.received, sim.stepper.state.x, sim.stepper.state.t)
        finally:
            controller.destroy_node()
            sim.destroy_node()
    status, bursts, sent, received, x, t = finals[1]
    assert status == 'reached' and finals[0][:4] == (status, bursts, sent, received) and bursts >= 2
    assert abs(x - finals[0][4]) <= 1e-9, (x, finals[0][4])
    assert t > finals[0][5]


class StreamedSimulator(Node):
    """What the actuator takes for a simulator (it subscribes to actuator/trajectory and publishes
    actuator/joint_states): publishes the sim times it is given and keeps the windows it receives."""

    def __init__(self, context: Context) -> None:
        super().__init__('simulator', context=context)
        self.windows: list[JointTrajectory] = []
        self.create_subscription(JointTrajectory, 'actuator/trajectory', self.windows.append,
                                 topic_qos('actuator/trajectory'))
        self._sim_time = self.create_publisher(JointState, 'actuator/joint_states', topic_qos('actuator/joint_states'))

    def tick(self, t_ns: int) -> None:
        self._sim_time.publish(JointState(header=Header(stamp=Time(sec=t_ns // 10**9, nanosec=t_ns % 10**9)),
                                          name=['piezo_0'], position=[0.0]))


def _ns(stamp: Any) -> int:
    return stamp.sec * 10**9 + stamp.nanosec


def test_a_refused_stream_window_is_sent_again_and_no_strokes_go_missing(ros_context: Context) -> None:
    """An endless stream whose third message the middleware refuses: the window is counted and sent again,
    in order, at the next sim time, so the windows the simulator gets still continue one another knot for knot
    (each starts where the one before ends). Before, the refused window was counted and dropped: a gap of its
    1.5 ms of strokes."""
    actuator = Actuator(context=ros_context, overrides={'auto_start': False, 'stroke.count': 0,
                                                         'stream.lead': 0.004, 'stream.window': 0.0015})
    simulator = StreamedSimulator(ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(actuator)
    executor.add_node(simulator)
    refusing = actuator._pub = RefusingPublisher(actuator._pub, 1, after=2)
    try:
        wait_until(actuator.simulator_ready, 10.0, executor=executor, what='the actuator reaches the simulator')
        simulator.tick(0)
        wait_until(lambda: actuator.sim_time == 0.0, 10.0, executor=executor, what='sim time at the actuator')
        assert actuator.start().startswith('burst streamed from t = 0.004')
        for ms in range(1, 21):
            simulator.tick(ms * 10**6)
            wait_until(lambda ms=ms: abs(actuator.sim_time - ms * 1e-3) < 1e-12, 10.0, executor=executor,
                       what='the actuator at sim time')
        wait_until(lambda: len(simulator.windows) == actuator.windows, 10.0, executor=executor,
                   what='every window sent received')
        assert refusing.refusals == 0 and actuator.publishes.total() == 1 and actuator.rephases == 0
        windows = simulator.windows
        assert len(windows) >= 14 and _ns(windows[0].header.stamp) == 4_000_000   # 20 ms of strokes, 1.5 ms each
        for before, after in itertools.pairwise(windows):
            end = _ns(before.header.stamp) + _ns(before.points[-1].time_from_start)
            assert _ns(after.header.stamp) == end, (before.header.frame_id, after.header.frame_id)
        assert [split_window_id(w.header.frame_id)[1] for w in windows] == list(range(1, len(windows) + 1))
    finally:
        executor.shutdown()
