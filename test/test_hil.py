"""Hardware in the loop (issue 6): the example feed controller closes the loop over ROS topics.

Real-time runs use the ``micro-feeder hil`` command as a user would; the crash test runs the simulator,
recorder and controller as separate processes and kills the controller mid-run.
"""

from __future__ import annotations

import json
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from node_helpers import Probe, stamp_s, start_process, stop_process
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from ros_helpers import wait_until

from micro_feeder.logs.reader import LogReader

CLI = str(Path(sys.executable).parent / 'micro-feeder')
TRAVELLING_WAVE = ['--params', str(Path(__file__).parents[1] / 'config' / 'travelling_wave.yaml')]


def run_hil(*args: str) -> dict:
    result = subprocess.run([CLI, 'hil', '--json', *args], capture_output=True, text=True, timeout=300)
    assert result.stdout, result.stderr
    return json.loads(result.stdout)


@pytest.mark.parametrize(('scenario', 'target_x'), [('single', 0.47e-3), ('wave', 0.9e-3)])
def test_reaches_the_target_in_real_time(scenario, target_x):
    args = [*(TRAVELLING_WAVE if scenario == 'wave' else []), '--set', f'feed.target_x={target_x}']
    result = run_hil(*args)
    assert result['reached'], result
    assert abs(result['final_error_m']) <= 1e-6
    assert result['final_mode'] == 'stuck' and result['strokes'] > 0 and result['time_to_target_s'] > 0


def test_unreachable_target_is_reported_not_hidden():
    """One actuator only draws the part toward its bump centre (x = 0): a target beyond x0 is unreachable."""
    result = run_hil('--set', 'feed.target_x=0.6e-3')
    assert not result['reached'] and result['status'] == 'unreachable'
    assert 'toward its bump centre' in result['reason']


def test_controller_crash_leaves_the_simulator_running_and_the_log_complete(ros_context: Context, tmp_path):
    log_path = tmp_path / 'crash'
    sim = start_process('simulator', '-p', 'markers_rate:=5.0')
    recorder = start_process('recorder', '-p', f'output:={log_path}', '-p', 'flush_period:=0.2')
    probe = Probe(context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(probe)
    controller = None
    try:
        msgs = probe.msgs
        try:
            wait_until(lambda: len(msgs['particle/pose']) > 10, 120, executor=executor, what='the simulator')
        except AssertionError as err:   # say why: a simulator that exited, or one that runs but is not heard
            status, out = stop_process(sim)
            raise AssertionError(f'{err}; simulator exit {status} ({sim.args}), its log:\n{out[-3000:]}') from None
        # ~30 strokes away, 1 s of sim time (the most settle_time allows) between bursts: still running when the
        # recorder has matched it (with 0.5 s a loaded CI run saw the controller done first, nothing recorded)
        controller = start_process('feed_controller', '-p', 'feed.target_x:=0.2e-3', '-p', 'settle_time:=1.0')
        # kill the controller once the recorder reports a burst recorded (its first bursts can go out before
        # the new process and the recorder have matched), and once the part moved
        def recorded_bursts() -> int:
            return max((int(kv.value) for d in msgs['/diagnostics'] for st in d.status
                        if st.name.startswith('recorder') for kv in st.values
                        if kv.key == 'received./actuator/trajectory'), default=0)

        x0 = msgs['particle/pose'][-1].pose.position.x
        wait_until(lambda: recorded_bursts() >= 1 and msgs['particle/pose'][-1].pose.position.x < x0 - 1e-6, 60,
                   executor=executor, what='a burst recorded and the part moved by the controller')
        controller.send_signal(signal.SIGKILL)
        controller.wait(10)
        killed_at = stamp_s(msgs['particle/pose'][-1])
        count = len(msgs['particle/pose'])
        wait_until(lambda: len(msgs['particle/pose']) > count + 200, 20, executor=executor,
                   what='poses after the controller died')
        assert sim.poll() is None, 'the simulator died with the controller'
        assert probe.pause(executor, True).success      # and it still answers its services
        rec_status, rec_out = stop_process(recorder)
        assert rec_status == 0, rec_out
    finally:
        executor.shutdown()
        probe.destroy_node()
        if controller is not None and controller.poll() is None:
            controller.kill()
        sim_status, sim_out = stop_process(sim)
        if recorder.poll() is None:
            recorder.kill()
    assert sim_status == 0, sim_out
    log = LogReader(log_path)
    assert not log.truncated
    assert log.topics[log.resolve('actuator/trajectory')].count >= 1
    last_pose = log.last(log.resolve('particle/pose'))
    assert stamp_s(last_pose.message) > killed_at + 0.15


@pytest.mark.parametrize(('scenario', 'target_x'), [('single', 0.45e-3), ('wave', 0.8e-3)])
def test_reaches_the_target_in_lockstep(scenario, target_x):
    args = [*(TRAVELLING_WAVE if scenario == 'wave' else []), '--lockstep', '--set', f'feed.target_x={target_x}']
    result = run_hil(*args)
    assert result['reached'], result
    assert abs(result['final_error_m']) <= 1e-6 and result['final_mode'] == 'stuck'


WALL_CLOCK_PACED = ('/diagnostics', '/surface/markers')


def recorded_sequences(path: Path) -> dict[str, list[object]]:
    """Every recorded message but the wall-clock-paced topics (``/diagnostics`` at 1 Hz with wall-clock figures,
    ``surface/markers`` at ~30 Hz of wall time), decoded into its rclpy class, in order per topic.
    Decoded, because rclpy leaves CDR padding bytes uninitialised (equal messages can serialise to
    different bytes); log and publish times are left out, because they are wall-clock receive times for
    messages without a header (stamped messages carry their sim time inside)."""
    from rclpy.serialization import deserialize_message

    from micro_feeder.nodes._ros import message_class

    log = LogReader(path)
    out: dict[str, list[object]] = {}
    for topic in log.topics.values():
        if topic.name in WALL_CLOCK_PACED:
            continue
        cls = message_class(topic.type)
        out[topic.name] = [_without_start_time(deserialize_message(m.data, cls)) for m in log.messages([topic.name])]
    return out


def _without_start_time(msg: object) -> object:
    """The simulator's parameter events carry its wall-clock start (``started_at_ns``, which tells a
    simulator from a twin of its name), and a command's identity (``header.frame_id`` of the controller's
    trajectories and of their receipts, ``/feed_controller@<start>:b1``) the controller's: the fields two
    lockstep runs must not share."""
    header = getattr(msg, 'header', msg if hasattr(msg, 'frame_id') else None)
    if header is not None and '@' in header.frame_id:
        header.frame_id = re.sub(r'@[0-9a-f]+:', '@<start>:', header.frame_id)
    if hasattr(msg, 'new_parameters'):
        kept = [p for p in msg.new_parameters if p.name != 'started_at_ns']
        assert len(kept) == len(msg.new_parameters) - 1, 'a parameter event without started_at_ns'
        msg.new_parameters = kept
    return msg


def test_two_lockstep_runs_record_identical_logs(tmp_path):
    results, logs = [], []
    for run in ('a', 'b'):
        results.append(run_hil('--lockstep', '--set', 'feed.target_x=0.46e-3', '--record', str(tmp_path / run)))
        logs.append(recorded_sequences(tmp_path / run))
    assert results[0]['reached'] and results[1]['reached']
    assert set(logs[0]) == set(logs[1])
    assert len(logs[0]['/particle/pose']) > 10 and len(logs[0]['/actuator/trajectory']) >= 2
    for topic in logs[0]:
        assert logs[0][topic] == logs[1][topic], f'{topic} differs between two lockstep runs'


def feed_controller(context: Context, target_x: float, delay_s: float):
    """A lockstep FeedController whose every command takes ``delay_s`` more (a slow controller)."""
    from micro_feeder.nodes.feed_controller import FeedController

    class Delayed(FeedController):
        slept_s = 0.0

        def send(self, msg):
            time.sleep(delay_s)
            self.slept_s += delay_s
            return super().send(msg)

    return Delayed(context=context, overrides={'feed.target_x': target_x, 'lockstep': True})


def test_a_slow_controller_reaches_the_same_state_in_lockstep(ros_context: Context):
    """In lockstep the physics neither waits for nor runs ahead of the controller: sleeping 20 ms per
    command changes nothing in the final state, to the last bit."""
    from micro_feeder.nodes.simulator import Simulator
    from micro_feeder.nodes.spin import spin_nodes

    finals = {}
    for delay in (0.0, 0.02):
        sim = Simulator(context=ros_context, overrides={'lockstep': True})
        controller = feed_controller(ros_context, 0.46e-3, delay)
        try:
            spin_nodes([sim, controller], lambda c=controller, s=sim: c.done or s.stepper.t > 1.0, ros_context)
            state = sim.stepper.state
            finals[delay] = (controller.planner.status, state.t, state.x, state.xdot, controller.commands_sent)
            assert controller.slept_s == pytest.approx(delay * controller.commands_sent)
        finally:
            controller.destroy_node()
            sim.destroy_node()
    assert finals[0.0][0] == 'reached' and finals[0.0][4] >= 2
    assert finals[0.02] == finals[0.0]


def test_goals_give_the_lockstep_run_that_topic_commands_give(ros_context: Context):
    """command_interface action: each burst a FollowJointTrajectory goal, the grant sent once the simulator
    has handled it. The lockstep run ends in the same state, to the last bit, as with actuator/trajectory."""
    from micro_feeder.nodes.feed_controller import FeedController
    from micro_feeder.nodes.simulator import Simulator
    from micro_feeder.nodes.spin import spin_nodes

    finals = {}
    for interface in ('topic', 'action'):
        sim = Simulator(context=ros_context, overrides={'lockstep': True})
        controller = FeedController(context=ros_context, overrides={'feed.target_x': 0.46e-3, 'lockstep': True,
                                                                     'command_interface': interface})
        try:
            spin_nodes([sim, controller], lambda c=controller, s=sim: c.done or s.stepper.t > 1.0, ros_context)
            state = sim.stepper.state
            finals[interface] = (controller.planner.status, state.t, state.x, state.xdot, controller.commands_sent,
                                 sim.commands.received)
        finally:
            controller.destroy_node()
            sim.destroy_node()
    assert finals['topic'][0] == 'reached' and finals['topic'][4] >= 2
    assert finals['action'] == finals['topic']
    assert controller.goals.sent == controller.commands_sent + controller.delivery.resent
    assert controller.goals.refused == 0


def test_timeout_stops_at_the_requested_sim_time():
    result = run_hil('--timeout', '0.01', '--set', 'feed.target_x=0.9e-3')
    assert not result['reached'] and result['sim_time_s'] == 0.01, result


def test_lockstep_in_a_namespace_gives_the_same_run(tmp_path):
    """``--namespace``: the controller finds the simulator's step service and topics in the namespace; the
    run is the one of the root namespace, step for step, and the log holds only the namespace's topics."""
    args = ['--lockstep', '--set', 'feed.target_x=0.45e-3']
    root = run_hil(*args)
    spaced = run_hil(*args, '--namespace', 'cell_3', '--record', str(tmp_path / 'log'))
    assert spaced['reached'] and root['reached'], (root, spaced)
    for key in ('strokes', 'bursts', 'final_error_m', 'sim_time_s', 'time_to_target_s'):
        assert spaced[key] == root[key], key
    topics = set(LogReader(tmp_path / 'log').topics)
    assert all(t.startswith('/cell_3/') or t == '/diagnostics' for t in topics), topics
