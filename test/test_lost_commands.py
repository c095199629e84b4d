"""A whole burst lost on its way (discovery matches the two ends one after the other, and a message sent in
between is lost without an error) is sent again until the simulator's receipt names it; the simulator
applies it once, and the copies are neither faults on its side nor on the sender's.

The loss itself cannot be brought about on demand, so :class:`LosingSimulator` (what the actuator takes for
a simulator: it subscribes to ``actuator/trajectory`` and publishes ``actuator/joint_states``) ignores the
first trajectory it gets as if it never arrived, and acknowledges the others on
``simulator/command_receipts`` as the simulator does. The actuator and the middleware are real; the
simulator's side (a duplicate applied once, counted apart, no extra lockstep step) runs on a real Simulator.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.serialization import serialize_message
from ros_helpers import wait_until
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from trajectory_msgs.msg import JointTrajectory

from micro_feeder.interface import messages
from micro_feeder.interface.names import joint_names, receipt_frame
from micro_feeder.nodes._ros import topic_qos
from micro_feeder.nodes.actuator import Actuator
from micro_feeder.nodes.feed_controller import FeedController
from micro_feeder.nodes.goal_sender import GoalSender
from micro_feeder.nodes.simulator import Simulator
from micro_feeder.nodes.spin import spin_nodes
from micro_feeder.nodes.until_receipt import RECEIPT_WAIT_S

pytestmark = pytest.mark.faults


class LosingSimulator(Node):
    """Loses the first ``lost`` trajectories it gets; keeps and acknowledges the others."""

    def __init__(self, context: Context, lost: int) -> None:
        super().__init__('simulator', context=context)
        self.lost = lost
        self.received: list[JointTrajectory] = []
        self.create_subscription(JointTrajectory, 'actuator/trajectory', self._on_trajectory,
                                 topic_qos('actuator/trajectory'))
        self.create_publisher(JointState, 'actuator/joint_states', topic_qos('actuator/joint_states'))
        self._receipts = self.create_publisher(Header, 'simulator/command_receipts',
                                               topic_qos('simulator/command_receipts'))

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        if self.lost:
            self.lost -= 1
            return
        self.received.append(msg)
        self._receipts.publish(Header(frame_id=receipt_frame('actuator/trajectory', msg.header.frame_id)))


def _spin(executor: SingleThreadedExecutor, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)


@pytest.mark.parametrize('lost', [1, 2])
def test_a_burst_lost_in_discovery_is_sent_again_until_its_receipt(ros_context: Context, lost: int) -> None:
    """The burst's first ``lost`` copies vanish: the actuator sends it again (same identity, same knots)
    after 1 s, then 2 s, and stops once the receipt names it. Before, auto_start sent it once, and a burst
    lost that way was never applied (a clean-clone CI run timed out waiting for its receipt)."""
    actuator = Actuator(context=ros_context, overrides={'auto_start': True, 'stroke.count': 2})
    simulator = LosingSimulator(ros_context, lost)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(actuator)
    executor.add_node(simulator)
    try:
        wait_until(lambda: actuator.bursts == 1, 20.0, executor=executor, what='the auto start')
        sent_at = time.monotonic()
        wait_until(lambda: simulator.received, 20.0, executor=executor, what='a copy that arrives')
        waited = time.monotonic() - sent_at
        assert waited >= RECEIPT_WAIT_S * (2 ** lost - 1) - 0.05, waited      # 1 s, then 1 + 2 s
        wait_until(lambda: actuator.delivery.awaited is None, 10.0, executor=executor, what='the receipt taken')
        _spin(executor, 2.5 * RECEIPT_WAIT_S * 2 ** lost)        # past the next resend, were it still waiting
        assert len(simulator.received) == 1 and actuator.delivery.resent == lost
        assert actuator.bursts == 1 and actuator.refusals.refused == 0
        burst = simulator.received[0]
        assert burst.header.frame_id.endswith(':b1') and len(burst.points) > 10
    finally:
        executor.shutdown()
        actuator.destroy_node()
        simulator.destroy_node()


def test_a_stop_ends_the_wait_for_a_receipt(ros_context: Context) -> None:
    """A burst whose receipt never comes is not sent again after a stop (it would restart the strokes)."""
    actuator = Actuator(context=ros_context, overrides={'auto_start': True, 'stroke.count': 2})
    simulator = LosingSimulator(ros_context, lost=1)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(actuator)
    executor.add_node(simulator)
    try:
        wait_until(lambda: actuator.bursts == 1, 20.0, executor=executor, what='the auto start')
        assert actuator.stop() == 'stop sent' and actuator.delivery.awaited is None
        _spin(executor, 2.5 * RECEIPT_WAIT_S)
        assert actuator.delivery.resent == 0
        wait_until(lambda: len(simulator.received) == 1, 10.0, executor=executor, what='the stop')
        assert not simulator.received[0].points                              # the stop, not the burst
    finally:
        executor.shutdown()
        actuator.destroy_node()
        simulator.destroy_node()


@pytest.mark.parametrize('lockstep', [False, True])
def test_a_copy_of_an_applied_burst_is_refused_once_counted_apart_and_grants_nothing(
        ros_context: Context, lockstep: bool) -> None:
    """The same burst sent three times to a real Simulator: applied once; the two copies are answered as
    duplicates on simulator/command_status but counted in commands_repeated, not rejected_commands, the
    actuator does not count them as refusals, and in lockstep they grant no step (a command applies, and
    grants, once)."""
    simulator = Simulator(context=ros_context, overrides={'lockstep': lockstep, 'start_paused': True})
    actuator = Actuator(context=ros_context, overrides={'auto_start': False, 'stroke.count': 1})
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(simulator)
    executor.add_node(actuator)
    try:
        wait_until(actuator.simulator_ready, 20.0, executor=executor, what='the actuator reaches the simulator')
        before = simulator.steps_granted
        actuator.start()
        burst = actuator.delivery._awaited.message
        wait_until(lambda: actuator.delivery.awaited is None, 10.0, executor=executor, what='the receipt')
        assert simulator.steps_granted == before + lockstep          # the burst's own grant, in lockstep
        for _ in range(2):
            actuator._pub.publish(burst)
        wait_until(lambda: simulator.commands.repeated == 2, 10.0, executor=executor, what='both copies handled')
        wait_until(lambda: actuator.refusals.repeated == 2, 10.0, executor=executor, what='both answers')
        assert simulator.commands.refused == 0 and simulator.commands.received == 3
        items = {kv.key: kv.value for kv in simulator.diagnostics().values}
        assert items['commands_repeated'] == '2' and items['rejected_commands'] == '0'
        assert actuator.refusals.refused == 0 and actuator.refusals.last == ''
        assert simulator.steps_granted == before + lockstep          # and none for the copies
    finally:
        executor.shutdown()
        actuator.destroy_node()
        simulator.destroy_node()


def _losing_first_trajectory(simulator: Simulator) -> list[int]:
    """Make a real Simulator lose the first trajectory that reaches it, as if discovery had lost it on the way
    (its engine never sees it: no receipt, no count); returns a one-item list counting the trajectories lost."""
    lost = [0]
    submit = simulator._engine.submit

    def losing(topic: str, data: bytes) -> None:
        if topic == 'actuator/trajectory' and not lost[0]:
            lost[0] += 1
            return
        submit(topic, data)

    simulator._engine.submit = losing
    return lost


def _losing_first_goal(simulator: Simulator) -> list[int]:
    """Make a real Simulator's follow_joint_trajectory server lose the first goal request that reaches it, as
    if discovery had lost it on the way (no answer, no receipt, no count); returns a one-item list counting the
    requests lost. rclpy's ActionServer takes each request through ``_execute_goal_request``."""
    lost = [0]
    server = simulator._trajectory_action._server
    execute_request = server._execute_goal_request

    async def losing(request: object) -> None:
        if not lost[0]:
            lost[0] += 1
            return
        await execute_request(request)

    server._execute_goal_request = losing
    return lost


def _feed_run(ros_context: Context, lockstep: bool, lose_first: bool, interface: str = 'topic') -> tuple:
    """A FeedController feeding the part to 0.46 mm against a real Simulator, its bursts sent on ``interface``
    (topic, action); returns (the controller, the simulator's state at the end, the simulator's intake
    counters, bursts lost)."""
    simulator = Simulator(context=ros_context, overrides={'lockstep': lockstep})
    losing = _losing_first_goal if interface == 'action' else _losing_first_trajectory
    lost = losing(simulator) if lose_first else [0]
    controller = FeedController(context=ros_context, overrides={'feed.target_x': 0.46e-3, 'lockstep': lockstep,
                                                                'command_interface': interface})
    deadline = time.monotonic() + 60.0
    try:
        spin_nodes([simulator, controller], lambda: controller.done or time.monotonic() > deadline, ros_context)
        assert controller.done, f'the feed run timed out at sim time {simulator.stepper.t:.6f} s, lost {lost[0]}'
        return controller, simulator.stepper.state, dataclasses.replace(simulator.commands), lost[0]
    finally:
        controller.destroy_node()
        simulator.destroy_node()


@pytest.mark.parametrize('interface', ['topic', 'action'])
def test_a_lockstep_feed_run_with_its_first_burst_lost_ends_as_one_without(ros_context: Context,
                                                                           interface: str) -> None:
    """Lockstep: sim time waits for the controller's first burst (on the topic it is the grant of the next
    step; with the action the grant follows the goal's first answer), so losing it stalled the run. Sent
    again until its receipt (with the action, as a new goal under the same identity), the run reaches the
    target in the same final state, to the last bit, as a run that lost nothing."""
    finals = {}
    for lose_first in (False, True):
        controller, state, commands, lost = _feed_run(ros_context, True, lose_first, interface)
        assert controller.planner.status == 'reached' and lost == lose_first
        assert controller.delivery.resent == lost and commands.refused == 0
        if interface == 'action':
            goals = controller.goals
            assert goals.sent == controller.commands_sent + lost and goals.refused == goals.repeated == 0
        finals[lose_first] = (state.t, state.x, state.xdot, controller.planner.bursts, controller.planner.strokes)
    assert finals[True] == finals[False]


@pytest.mark.parametrize('interface', ['topic', 'action'])
def test_a_real_time_burst_lost_is_fired_again_not_taken_for_no_motion(ros_context: Context,
                                                                       interface: str) -> None:
    """Real time: the first burst is lost. With no receipt for it by the next decision, the controller fires
    it again (same identity, new stamp) instead of learning from it that the strokes do not move the part:
    every burst the planner learned from was applied by the simulator. Before, the planner counted the lost
    burst, saw no motion and raised the amplitude."""
    controller, _state, commands, lost = _feed_run(ros_context, False, True, interface)
    applied = commands.received - commands.repeated - commands.refused
    assert lost == 1 and controller.planner.bursts == applied
    assert controller.planner.status == 'reached' and controller.bursts_refired >= 1 and commands.refused == 0
    if interface == 'action':
        assert controller.goals.refused == 0 and controller.goals.repeated == commands.repeated


def test_an_actuator_goal_lost_is_sent_again_and_applied_once(ros_context: Context) -> None:
    """With the action, the actuator's goal request is lost (no answer at all): the burst goes again as a new
    goal under the same identity after 1 s, the simulator applies it once, and the goal runs to success.
    Before, the burst was sent once, and a lost goal was never applied."""
    simulator = Simulator(context=ros_context, overrides={'lockstep': False})
    lost = _losing_first_goal(simulator)
    actuator = Actuator(context=ros_context, overrides={'auto_start': True, 'stroke.count': 2,
                                                        'command_interface': 'action'})
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(simulator)
    executor.add_node(actuator)
    goals = actuator.goals
    try:
        wait_until(lambda: actuator.bursts == 1, 20.0, executor=executor, what='the auto start')
        wait_until(lambda: goals.succeeded == 1, 20.0, executor=executor, what='the goal sent again succeeding')
        _spin(executor, 2.5 * RECEIPT_WAIT_S)                    # past the next resend, were it still waiting
        assert lost[0] == 1 and actuator.delivery.resent == 1 and actuator.delivery.awaited is None
        assert goals.sent == 2 and goals.refused == goals.repeated == 0 and goals.state == 'succeeded'
        commands = simulator.commands
        assert commands.received == 1 and commands.refused == commands.repeated == 0 and actuator.bursts == 1
    finally:
        executor.shutdown()
        actuator.destroy_node()
        simulator.destroy_node()


def test_a_copy_of_an_applied_goal_is_a_duplicate_not_a_refusal_nor_a_second_grant(ros_context: Context) -> None:
    """A goal sent again when only its answers were lost: the simulator aborts the copy as a duplicate; the
    sender counts it in ``repeated`` (not ``refused``), keeps the first copy as the running goal and does not
    run ``on_handled`` (a lockstep controller's grant) a second time for the same burst."""
    simulator = Simulator(context=ros_context, overrides={'start_paused': True})   # the goal stays running
    client = Node('goal_client', context=ros_context)
    handled: list[str] = []
    goals = GoalSender(client, on_handled=lambda: handled.append('grant'))
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(simulator)
    executor.add_node(client)
    try:
        wait_until(goals.ready, 20.0, executor=executor, what='the action server')
        n = simulator.stepper.model.n_actuators
        knots = np.linspace(0.0, 1e-3, 5)
        burst = messages.trajectory(joint_names(n), knots, np.zeros((5, n)), np.zeros((5, n)), np.zeros((5, n)),
                                    Time())
        burst.header.frame_id = '/goal_client@1:b1'
        goals.send(burst)
        wait_until(lambda: goals.state == 'running' and goals.running is not None, 10.0, executor=executor,
                   what='the goal running, its acceptance in')    # the first feedback can come before it
        first = goals.running
        goals.send_copy(serialize_message(burst))
        wait_until(lambda: goals.repeated == 1, 10.0, executor=executor, what='the copy answered')
        assert simulator.commands.repeated == 1 and simulator.commands.refused == 0
        assert goals.refused == 0 and goals.last == '' and goals.sent == 2
        assert goals.running is first and goals.state == 'running' and handled == ['grant']
    finally:
        executor.shutdown()
        client.destroy_node()
        simulator.destroy_node()
