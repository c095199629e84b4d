"""The simulator's lockstep mode and its loop thread, in-process: real rclpy, an isolated Context per test,
bounded waits.

Lockstep: sim time advances by exactly ``step_period`` per ``simulator/step`` call, per ``grant_step()`` and
per command message received (applied first, at the paused time), never on the wall clock. Loop thread:
the wall-clock loop runs on the node's own thread while an executor on another thread serves commands
and services, and both stop cleanly.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest
import rclpy
from node_helpers import stamp_s
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_helpers import spin_for, wait_until
from std_msgs.msg import Float64MultiArray, Header
from std_srvs.srv import SetBool, Trigger
from test_simulator_node import Rig
from trajectory_msgs.msg import JointTrajectory

from micro_feeder.interface import messages, stamps
from micro_feeder.interface.names import joint_names
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.sim.commands import parse_setpoints, parse_trajectory
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import sample_waveform

STEP = 1e-3
TIMEOUT = 10.0  # s, any single wait


class LockstepRig(Rig):
    """A lockstep simulator and a probe; every grant waits for the one pose it publishes."""

    def __init__(self, context: Context, **params: object):
        super().__init__(context, lockstep=True, step_period=STEP, **params)
        self.wait(lambda: all(p.get_subscription_count() > 0 for p in self.probe.publishers_.values())
                  and self.sim.count_subscribers('particle/pose') > 0
                  and self.probe.msgs['particle/contact_state'], 'probe and simulator matched')

    @property
    def poses(self) -> list[Any]:
        return self.probe.msgs['particle/pose']

    def grant(self, action: Callable[[], object], what: str) -> None:
        """Run ``action`` (a step call or a command) and wait for the pose of the step it grants."""
        count = len(self.poses)
        action()
        self.wait(lambda: len(self.poses) > count, f'pose after {what}')
        assert len(self.poses) == count + 1, f'{what} granted more than one step'

    def command(self, topic: str, msg: object) -> None:
        self.grant(lambda: self.probe.publishers_[topic].publish(msg), topic)


@pytest.fixture
def lockstep(ros_context: Context) -> Iterator[LockstepRig]:
    rig = LockstepRig(ros_context)
    yield rig
    rig.close()


def receipt_s(header: Header) -> float:
    """The sim time (s) of a ``simulator/command_receipts`` header."""
    return header.stamp.sec + header.stamp.nanosec * 1e-9


def ramp(stroke: float, duration: float = 1e-3) -> JointTrajectory:
    """Position-only knots from 0 to ``stroke`` (m) over ``duration`` (s), stamp 0 (from receipt)."""
    zeros = np.zeros((2, 1))
    msg = messages.trajectory(joint_names(1), np.array([0.0, duration]), np.array([[0.0], [stroke]]), zeros, zeros,
                              stamps.to_time(0.0))
    for point in msg.points:
        point.velocities, point.accelerations = [], []
    return msg


def burst() -> JointTrajectory:
    """The actuator's burst (3 strokes of 80 um), stamp 0."""
    times, pos, vel, acc = sample_waveform(StrokeParams(count=3, amplitude=80e-6), 1, 40)
    return messages.trajectory(joint_names(1), times, pos, vel, acc, stamps.to_time(0.0))


def test_time_advances_only_per_step_call_and_per_command(lockstep: LockstepRig) -> None:
    sim, probe = lockstep.sim, lockstep.probe
    before = len(lockstep.poses)
    spin_for(lockstep.executor, 0.3)                              # 300 wall ticks' worth: nothing moves
    assert sim.stepper.t == 0.0 and len(lockstep.poses) == before
    bad_joint = ramp(10e-6)
    bad_joint.joint_names = ['piezo_7']
    grants: list[tuple[str, Callable[[], object]]] = [
        ('simulator/step', lambda: probe.call(lockstep.executor, Trigger, 'simulator/step')),
        ('a trajectory', lambda: probe.publishers_['actuator/trajectory'].publish(ramp(10e-6))),
        ('a refused trajectory', lambda: probe.publishers_['actuator/trajectory'].publish(bad_joint)),
        ('a set-point', lambda: probe.publishers_['actuator/command'].publish(Float64MultiArray(data=[5e-6]))),
        ('a refused set-point', lambda: probe.publishers_['actuator/command'].publish(Float64MultiArray(data=[1.0]))),
        ('grant_step()', sim.grant_step),
    ]
    t = 0.0
    for what, action in grants:
        lockstep.grant(action, what)
        t += STEP                                                 # the simulator's own sum, bit for bit
        assert sim.stepper.t == t, what
        assert stamp_s(lockstep.poses[-1]) == pytest.approx(t, abs=1e-12), what
    assert sim.rejected == 2
    lockstep.wait(lambda: len(probe.msgs['simulator/command_receipts']) == 4, 'four command receipts')
    receipts = [receipt_s(h) for h in probe.msgs['simulator/command_receipts']]
    assert receipts == pytest.approx([STEP, 2 * STEP, 3 * STEP, 4 * STEP], abs=1e-12)   # each before its step
    # the wall clock cannot be switched on; pausing is accepted and changes nothing
    response = probe.pause(lockstep.executor, False)
    assert not response.success and 'lockstep' in response.message
    assert probe.pause(lockstep.executor, True).success
    spin_for(lockstep.executor, 0.2)
    assert sim.stepper.t == t and sim.paused
    values = {kv.key: kv.value for kv in sim.diagnostics().values}
    assert values['lockstep'] == 'True' and values['steps_granted'] == str(len(grants))


def test_lockstep_ignores_start_paused(ros_context: Context) -> None:
    rig = LockstepRig(ros_context, start_paused=False, real_time_factor=0.0)
    try:
        spin_for(rig.executor, 0.2)
        assert rig.sim.stepper.t == 0.0
        rig.grant(lambda: rig.probe.call(rig.executor, Trigger, 'simulator/step'), 'simulator/step')
        assert rig.sim.stepper.t == STEP
    finally:
        rig.close()


def test_a_command_takes_effect_at_the_paused_time(lockstep: LockstepRig) -> None:
    sim = lockstep.sim
    for _ in range(3):
        lockstep.grant(sim.grant_step, 'grant_step()')
    t_paused = sim.stepper.t
    joints = lockstep.probe.msgs['actuator/joint_states']
    assert joints[-1].position[0] == 0.0
    msg = ramp(20e-6)                                             # reaches 20 um 1 ms after receipt
    lockstep.command('actuator/trajectory', msg)
    lockstep.wait(lambda: lockstep.probe.msgs['simulator/command_receipts'], 'command receipt')
    (receipt,) = lockstep.probe.msgs['simulator/command_receipts']
    assert receipt_s(receipt) == pytest.approx(t_paused, abs=1e-12)
    assert sim.stepper.t == t_paused + STEP
    assert joints[-1].position[0] == pytest.approx(20e-6, rel=1e-12)   # one step later: the ramp's end
    lockstep.command('actuator/command', Float64MultiArray(data=[-7e-6]))
    assert joints[-1].position[0] == -7e-6                        # ideal actuator: held from receipt
    # the offline stepper fed the same commands at the same paused times publishes the same state
    offline = Stepper(build_model({}))
    for _ in range(3):
        offline.advance(offline.t + STEP)
    offline.command_trajectory(parse_trajectory(msg, joint_names(1), offline.limits))
    offline.advance(offline.t + STEP)
    offline.command_setpoints(parse_setpoints([-7e-6], 1, offline.limits))
    offline.advance(offline.t + STEP)
    obs, pose = offline.observe(), lockstep.poses[-1].pose
    assert (obs.t, obs.x, obs.z) == (sim.stepper.t, pose.position.x, pose.position.z)
    assert messages.tilt_quaternion(obs.theta)[1] == pose.orientation.y != 0.0     # the surface under it moved


def _lockstep_run(context: Context) -> list[tuple]:
    rig = LockstepRig(context)
    try:
        for _ in range(2):
            rig.grant(rig.sim.grant_step, 'grant_step()')
        rig.command('actuator/trajectory', burst())
        for _ in range(5):
            rig.grant(lambda: rig.probe.call(rig.executor, Trigger, 'simulator/step'), 'simulator/step')
        rig.command('actuator/trajectory', ramp(30e-6, 2e-3))     # replaces the burst mid-way
        for _ in range(3):
            rig.grant(rig.sim.grant_step, 'grant_step()')
        rig.command('actuator/command', Float64MultiArray(data=[1.0]))       # refused, still a step
        rig.command('actuator/command', Float64MultiArray(data=[0.0]))
        msgs = rig.probe.msgs
        state_topics = ('particle/twist', 'particle/contact_wrench', 'actuator/joint_states')
        rig.wait(lambda: all(len(msgs[t]) == len(rig.poses) for t in state_topics), 'every state message')
        return [(p.header.stamp.sec, p.header.stamp.nanosec, p.pose.position.x, p.pose.position.z,
                 p.pose.orientation.y, t.twist.linear.x, t.twist.linear.z, w.wrench.force.x, w.wrench.force.z,
                 tuple(j.position), tuple(j.velocity))
                for p, t, w, j in zip(msgs['particle/pose'], msgs['particle/twist'], msgs['particle/contact_wrench'],
                                      msgs['actuator/joint_states'], strict=True)]
    finally:
        rig.close()


def test_two_lockstep_runs_publish_bit_identical_states() -> None:
    runs = []
    for _ in range(2):
        context = Context()
        rclpy.init(context=context)
        try:
            runs.append(_lockstep_run(context))
        finally:
            rclpy.shutdown(context=context)
    assert len(runs[0]) == 14
    assert runs[0] == runs[1]
    assert len({row[2] for row in runs[0]}) > 1                    # the part moved


# -- the loop thread ------------------------------------------------------------------------------------


def _loop_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name == 'simulator-loop']


def _poll(predicate: Callable[[], bool], what: str) -> None:
    wait_until(predicate, TIMEOUT, what=what)


def test_executor_on_another_thread_while_the_loop_runs(ros_context: Context) -> None:
    """Commands, services and parameter sets from other threads while the loop ticks; no deadlock on the
    way out (the known hazard is an EventsExecutor spun off the main thread). Not with rclpy's
    MultiThreadedExecutor, which starves the loop thread in-process (docs/interface.md, loop limitation)."""
    rig = Rig(ros_context)
    sim, probe = rig.sim, rig.probe
    rig.executor.remove_node(sim)
    rig.executor.remove_node(probe)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(sim)
    executor.add_node(probe)
    spinning = threading.Event()
    spinning.set()

    def spin() -> None:
        while spinning.is_set():
            executor.spin_once(timeout_sec=0.05)

    # stopped before executor.shutdown(): shutting an executor down while another thread spins it races
    # with its guard condition (rclpy raises InvalidHandle in that thread)
    spinner = threading.Thread(target=spin, name='test-executor', daemon=True)
    spinner.start()
    try:
        _poll(lambda: len(probe.msgs['particle/pose']) > 100, 'poses from the loop thread')
        assert len(_loop_threads()) == 1

        def call(srv_type: type, name: str, request: Any = None) -> Any:
            client = probe.create_client(srv_type, name)
            _poll(client.service_is_ready, f'service {name}')
            future = client.call_async(request if request is not None else srv_type.Request())
            _poll(future.done, f'response of {name}')
            probe.destroy_client(client)
            return future.result()

        assert call(SetBool, 'simulator/pause', SetBool.Request(data=True)).success
        t_paused = sim.stepper.t
        assert call(Trigger, 'simulator/step').success and sim.stepper.t == t_paused + 1e-3
        assert call(SetBool, 'simulator/pause', SetBool.Request(data=False)).success
        _poll(lambda: sim.stepper.t > t_paused + 0.05, 'sim time running again')
        pub = probe.publishers_['actuator/trajectory']
        _poll(lambda: pub.get_subscription_count() > 0, 'trajectory subscriber')
        receipts = probe.msgs['simulator/command_receipts']
        for i in range(50):                       # commands between ticks (the subscription keeps 10)
            pub.publish(ramp(10e-6 if i % 2 else -10e-6))
            _poll(lambda n=i + 1: len(receipts) == n, f'command {i} received')
        (result,) = sim.set_parameters([Parameter('real_time_factor', value=0.0)])      # as fast as possible
        assert result.successful
        t0 = sim.stepper.t
        _poll(lambda: sim.stepper.t > t0 + 0.01, 'sim time advancing as fast as possible')
        assert call(SetBool, 'simulator/pause', SetBool.Request(data=True)).success      # gets in between ticks
        assert sim.rejected == 0 and not sim.error
    finally:
        spinning.clear()
        spinner.join(TIMEOUT)
        alive = spinner.is_alive()
        executor.shutdown()
        probe.destroy_node()
        sim.destroy_node()
    assert not alive, 'executor thread did not stop'
    assert not _loop_threads(), 'loop thread still running after destroy_node'


def test_context_shutdown_stops_the_loop_thread() -> None:
    """A simulator left alive is destroyed by rclpy.shutdown, which stops and joins its loop thread."""
    from micro_feeder.nodes.simulator import Simulator
    context = Context()
    rclpy.init(context=context)
    try:
        Simulator(context=context)
        assert len(_loop_threads()) == 1
    finally:
        rclpy.shutdown(context=context)
    assert not _loop_threads()


def test_a_command_stamped_at_the_current_sim_time_is_not_late(lockstep: LockstepRig) -> None:
    """A sender stamps with the sim time it reads (whole nanoseconds) while the simulator's time is a sum of
    step periods (0.1 + 0.1 + 0.1 != 0.3): equal to the nanosecond is on time, not "late by 0.000 ms"."""
    sim = lockstep.sim
    for _ in range(12):                  # 12 x 1e-3 = 0.012000000000000004 in floats, stamped 0.012 s
        lockstep.grant(sim.grant_step, 'grant_step()')
    assert sim.stepper.t > 0.012
    stamp = lockstep.probe.msgs['actuator/joint_states'][-1].header.stamp
    zeros = np.zeros((2, 1))
    msg = messages.trajectory(joint_names(1), np.array([0.0, 1e-3]), np.array([[0.0], [5e-6]]), zeros, zeros, stamp)
    lockstep.command('actuator/trajectory', msg)
    assert sim.commands.late == 0
    assert sim.commands.refused == 0
