"""``resim``: a stepped-mode log recorded by the real recorder re-simulates bit for bit; a changed
parameter does not. The log comes from the simulator node driven in-process through ``simulator/step``
with trajectory and set-point commands (stamp 0, a future stamp, a refused one)."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import rclpy
from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from node_helpers import Probe
from rclpy.action import ActionClient
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from ros_helpers import wait_until
from std_msgs.msg import Float64MultiArray

from micro_feeder.cli import main as cli_main
from micro_feeder.interface import messages, stamps
from micro_feeder.interface.names import joint_names
from micro_feeder.logs.reader import LogReader
from micro_feeder.logs.summary import format_summary, summarize
from micro_feeder.nodes.recorder import Recorder
from micro_feeder.nodes.simulator import Simulator
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.sim.replay import stop_times
from micro_feeder.sim.resim import ResimError, resimulate
from micro_feeder.sim.stream import sample_waveform

STEP = 1e-4     # s: not a power of two, so sim times are sums that only the simulator's own additions reproduce
TIMEOUT = 10.0  # s, any single wait
STEPS = 260     # simulator/step calls in the recorded run


def _burst(stamp_s: float) -> object:
    """The actuator's burst (4 strokes, 80 um) stamped at ``stamp_s`` (s, sim time; 0 = on receipt)."""
    times, pos, vel, acc = sample_waveform(StrokeParams(count=4, amplitude=80e-6), 1, 40)
    return messages.trajectory(joint_names(1), times, pos, vel, acc, stamps.to_time(stamp_s))


def _hold(stamp_s: float, stroke: float) -> object:
    """Position-only knots (linear interpolation): from 0 to ``stroke`` (m) in 0.5 ms from ``stamp_s``."""
    zeros = np.zeros((2, 1))
    msg = messages.trajectory(joint_names(1), np.array([0.0, 5e-4]), np.array([[0.0], [stroke]]), zeros, zeros,
                              stamps.to_time(stamp_s))
    for point in msg.points:
        point.velocities, point.accelerations = [], []
    return msg


@contextlib.contextmanager
def _stepped_nodes(context: Context, path: Path
                   ) -> Iterator[tuple[Recorder, Simulator, Probe, SingleThreadedExecutor]]:
    """A paused simulator stepping ``STEP``, a recorder writing ``path`` and a probe, in one executor; all shut
    down and destroyed on exit."""
    recorder = Recorder(context=context, parameter_overrides=[Parameter('output', value=str(path)),
                                                              Parameter('flush_period', value=0.2)])
    sim = Simulator(context=context, overrides={'start_paused': True, 'step_period': STEP})
    probe = Probe(context=context)
    executor = SingleThreadedExecutor(context=context)
    for node in (recorder, sim, probe):
        executor.add_node(node)
    try:
        yield recorder, sim, probe, executor
    finally:
        executor.shutdown()
        recorder.close()
        for node in (probe, sim, recorder):
            node.destroy_node()


def _record_stepped_run(context: Context, path: Path) -> dict[str, int]:
    """Simulator paused, recorder and a probe in one executor; commands between steps. Returns what the
    recorder received per topic."""
    with _stepped_nodes(context, path) as (recorder, sim, probe, executor):
        def wait(predicate, what: str) -> None:
            wait_until(predicate, TIMEOUT, executor=executor, what=what)

        def send(topic: str, msg: object) -> None:
            count = recorder.received['/simulator/command_receipts']
            probe.publishers_[topic].publish(msg)
            wait(lambda: recorder.received['/simulator/command_receipts'] == count + 1, f'receipt of {topic}')

        wait(lambda: all(pub.get_subscription_count() == 3 for pub in probe.publishers_.values())  # +probe's own
             and sim.count_subscribers('particle/pose') == 2
             and sim.count_subscribers('simulator/command_receipts') == 2
             and recorder.received['/simulator/parameters'] == 1, 'recorder and probe matched')
        send('actuator/trajectory', _burst(0.0))                     # stamp 0 at t = 0: on receipt
        at_start = recorder.received['/particle/pose']  # 1 when the recorder matched before the pose at t = 0
        probe.step(executor, 60)
        send('actuator/trajectory', _hold(0.0093, 30e-6))            # a future stamp: at t = 9.3 ms
        probe.step(executor, 60)
        send('actuator/trajectory', _burst(0.0))                     # stamp 0 mid-run: at the paused time
        probe.step(executor, 80)
        send('actuator/command', Float64MultiArray(data=[10e-6]))    # a set-point, held from receipt
        probe.step(executor, 20)
        send('actuator/trajectory', _hold(0.0, 1.0))                 # outside the piezo limits: refused
        send('actuator/trajectory', _hold(0.001, 5e-6))              # stamped in the past, joined with a
        probe.step(executor, 40)                                     # jump: refused as well
        assert sim.rejected == 2, sim.last_rejection
        wait(lambda: recorder.received['/particle/pose'] == at_start + STEPS, 'every pose recorded')
        received = {topic: n for topic, n in recorder.received.items()}
    return received


@pytest.fixture(scope='module')
def stepped_log(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    path = tmp_path_factory.mktemp('resim') / 'stepped'
    context = Context()
    rclpy.init(context=context)
    try:
        received = _record_stepped_run(context, path)
    finally:
        rclpy.shutdown(context=context)
    assert received['/actuator/trajectory'] == 5 and received['/actuator/command'] == 1
    yield path


def test_stepped_log_resimulates_bit_for_bit(stepped_log: Path) -> None:
    log = LogReader(stepped_log)
    xs = {m.message.pose.position.x for m in log.messages(['particle/pose'])}
    assert len(xs) > 10, 'the part must move, or a zero difference proves nothing'
    report = resimulate(log)
    assert report.poses == log.topics['/particle/pose'].count in (STEPS, STEPS + 1)  # + the pose at t = 0
    assert round(report.sim_time * 1e9) == round(STEPS * STEP * 1e9)
    assert report.commands_applied == 4 and report.commands_rejected == 2
    assert report.exact_stop_times and report.receipts == 'recorded' and report.mode == 'stepped'
    assert report.max_error == 0.0 and report.identical, report.verdict()
    assert report.parameters.startswith('recorded')


def _record_goal_driven_run(context: Context, path: Path) -> dict[str, int]:
    """A stepped run driven only by FollowJointTrajectory goals: one replaced by the next, one stamped ahead,
    one refused, one canceled (the simulator holds the strokes). Returns the goals' error codes by name."""
    with _stepped_nodes(context, path) as (recorder, sim, probe, executor):
        client = ActionClient(probe, FollowJointTrajectory, 'simulator/follow_joint_trajectory')

        def wait(predicate, what: str) -> None:
            wait_until(predicate, TIMEOUT, executor=executor, what=what)

        def send(trajectory: object) -> tuple[Any, Any]:
            """The goal's handle and its result's future, once the simulator has received it."""
            count = recorder.received['/simulator/command_receipts']
            future = client.send_goal_async(FollowJointTrajectory.Goal(trajectory=trajectory))
            wait(future.done, 'goal answered')
            wait(lambda: recorder.received['/simulator/command_receipts'] == count + 1, 'receipt of the goal')
            return future.result(), future.result().get_result_async()

        codes: dict[str, int] = {}
        try:
            wait(lambda: client.server_is_ready() and sim.count_subscribers('particle/pose') == 2
                 and sim.count_subscribers('simulator/trajectories_received') == 2
                 and sim.count_subscribers('simulator/command_receipts') == 2
                 and recorder.received['/simulator/parameters'] == 1, 'recorder, probe and action client matched')
            at_start = recorder.received['/particle/pose']
            _, replaced = send(_burst(0.0))                    # 4 ms of strokes
            probe.step(executor, 30)
            _, ahead = send(_hold(0.0093, 30e-6))              # replaces the burst at 3 ms; runs from t = 9.3 ms
            probe.step(executor, 90)
            _, refused = send(_hold(0.0, 1.0))                 # outside the piezo travel
            running, canceled = send(_burst(0.0))
            probe.step(executor, 30)
            count = recorder.received['/simulator/command_receipts']
            cancel = running.cancel_goal_async()
            wait(lambda: cancel.done() and canceled.done(), 'goal canceled')
            wait(lambda: recorder.received['/simulator/command_receipts'] == count + 1, 'receipt of the hold')
            probe.step(executor, 50)
            for name, future in (('replaced', replaced), ('ahead', ahead), ('refused', refused),
                                 ('canceled', canceled)):
                wait(future.done, f'result of the {name} goal')
                codes[name] = future.result().status
            wait(lambda: recorder.received['/particle/pose'] == at_start + 200, 'every pose recorded')
        finally:
            client.destroy()
    return codes


def test_a_goal_driven_log_resimulates_bit_for_bit(tmp_path: Path) -> None:
    """FollowJointTrajectory goals reach the log as the simulator's copies and receipts, so a run driven by
    goals alone re-simulates exactly, the cancel's hold included."""
    context = Context()
    rclpy.init(context=context)
    try:
        codes = _record_goal_driven_run(context, tmp_path / 'goals')
    finally:
        rclpy.shutdown(context=context)
    assert codes == {'replaced': GoalStatus.STATUS_ABORTED, 'ahead': GoalStatus.STATUS_SUCCEEDED,
                     'refused': GoalStatus.STATUS_ABORTED, 'canceled': GoalStatus.STATUS_CANCELED}
    log = LogReader(tmp_path / 'goals')
    assert '/actuator/trajectory' not in log.topics
    report = resimulate(log)
    assert report.commands_applied == 4 and report.commands_rejected == 1, report.verdict()
    assert len({m.message.pose.position.x for m in log.messages(['particle/pose'])}) > 10
    assert report.max_error == 0.0 and report.identical, report.verdict()


def test_a_changed_parameter_shows_as_a_difference(stepped_log: Path) -> None:
    report = resimulate(LogReader(stepped_log), {'particle.mass': 2.2e-9})
    assert report.poses >= STEPS
    assert report.max_error > 1e-9 and not report.identical


def test_cli_verdict_json_and_tolerance(stepped_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(['resim', str(stepped_log), '--tolerance', '0']) == 0
    out = capsys.readouterr().out
    assert out.startswith('resim: IDENTICAL: re-simulated bit for bit (26') and len(out.splitlines()) == 1
    assert cli_main(['resim', str(stepped_log), '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['identical'] and report['max_error'] == 0.0 and report['poses'] >= STEPS
    assert cli_main(['resim', str(stepped_log), '--set', 'gravity=5.0', '--tolerance', '1e-12']) == 1
    assert capsys.readouterr().out.startswith('resim: DIFFERENT: largest difference')


def test_real_time_stamps_are_not_exact_stop_times() -> None:
    stepped = [(round(k * 1e-3 * 1e9), 0.0, 0.0) for k in (1, 2, 5)]        # step 3 and 4 unrecorded
    stops, exact = stop_times(stepped, [1e-3])
    assert exact and [s.pose is not None for s in stops] == [True, True, False, False, True]
    assert stops[-1].t == 1e-3 + 1e-3 + 1e-3 + 1e-3 + 1e-3                     # the simulator's own sums
    stops, exact = stop_times([(1_000_370, 0.0, 0.0), (2_001_020, 0.0, 0.0)], [1e-3])   # wall-clock jitter
    assert not exact and [s.t for s in stops] == [1_000_370 / 1e9, 2_001_020 / 1e9]


def test_log_without_pose_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from micro_feeder.logs.writer import LogWriter
    writer = LogWriter(tmp_path / 'empty')
    writer.add_topic('/clock', 'rosgraph_msgs/msg/Clock', '')
    writer.close()
    assert cli_main(['resim', str(tmp_path / 'empty')]) == 2
    assert 'no particle/pose' in capsys.readouterr().err


def test_info_says_how_the_simulator_ran(stepped_log: Path) -> None:
    summary = summarize(LogReader(stepped_log))
    assert summary.simulator.mode == 'stepped' and summary.simulator.step_period == STEP
    assert summary.simulator.commands_received == 6
    rows = {t.name: t for t in summary.topics}
    assert rows['/actuator/trajectory'].rate is None and rows['/particle/pose'].rate > 0
    text = format_summary(summary)
    assert f'stepped through simulator/step, {STEP:g} s per step; 6 commands received' in text
    assert '– 0.026000 s (particle/pose stamps)' in text


def test_resim_decodes_each_message_once(stepped_log: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    created, decoded = [0], [0]
    make = LogReader._message

    def counting(self, *record):
        m = make(self, *record)
        created[0] += 1
        decode = m.decode
        m.decode = lambda data: (decoded.__setitem__(0, decoded[0] + 1), decode(data))[1]
        return m

    monkeypatch.setattr(LogReader, '_message', counting)
    report = resimulate(LogReader(stepped_log))
    assert report.identical and created[0] > report.poses
    assert 0 < decoded[0] <= created[0]


def _jittered_log(path: Path, offset: float = 0.0, lag_ns: float = 0.0, settings: dict[str, Any] | None = None
                  ) -> None:
    """Poses at wall-clock-like stamps (not sums of step periods), at the defaults' resting motion
    (no command; ``settings`` on top), re-simulated exactly when ``offset`` and ``lag_ns`` are 0; each pose is
    taken ``lag_ns`` after its stamp, as a real-time stop known to 1 ns can be, and moved ``offset`` (m)."""
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import serialize_message

    from micro_feeder.logs.writer import LogWriter
    from micro_feeder.settings import model_specs
    from micro_feeder.sim.stepper import Stepper, build_model

    stepper = Stepper(build_model({name: default for name, (_, default) in model_specs().items()} | (settings or {})))
    writer = LogWriter(path)
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    for ns in (1_000_370, 2_001_020, 3_000_910):
        stepper.advance((ns + lag_ns) / 1e9)
        obs = stepper.observe()
        msg = PoseStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
        msg.pose.position.x, msg.pose.position.z = obs.x + offset, obs.z
        writer.write('/particle/pose', serialize_message(msg), ns, ns)
    writer.close()


def test_real_time_note_only_with_a_difference(tmp_path: Path) -> None:
    _jittered_log(tmp_path / 'same')
    report = resimulate(LogReader(tmp_path / 'same'))
    assert not report.exact_stop_times and report.identical, report.verdict()
    assert not any('real-time run' in note for note in report.notes), report.notes
    _jittered_log(tmp_path / 'off', offset=1e-12)
    report = resimulate(LogReader(tmp_path / 'off'))
    assert not report.identical and any('real-time run' in note for note in report.notes), report.notes


def test_a_real_time_difference_the_rounded_stop_times_explain_matches(tmp_path: Path) -> None:
    """A pose taken 0.9 ns after its stamp (a real-time stop known to 1 ns) of a part sliding at ~0.16 m/s
    differs by ~1.4e-10 m, beyond integration.tolerance, and matches: its speed x 1 ns covers it; a 1e-9 m
    difference beyond that does not."""
    from micro_feeder.cli.resim import matches, verdict

    sliding = {'particle.v0': 0.2}
    _jittered_log(tmp_path / 'late', lag_ns=0.9, settings=sliding)
    report = resimulate(LogReader(tmp_path / 'late'), sliding)
    assert not report.exact_stop_times and 1.2e-10 < report.max_error < 1.8e-10, report.verdict()
    assert report.max_unexplained <= 0.0 and matches(report, 1e-10)
    line = verdict(report, 1e-10, 'integration.tolerance')
    assert line.startswith('resim: MATCHES within 1.') and "speed x 1 ns" in line, line
    _jittered_log(tmp_path / 'off', offset=1e-9, lag_ns=0.9, settings=sliding)
    report = resimulate(LogReader(tmp_path / 'off'), sliding)
    assert report.max_unexplained > 7e-10 and not matches(report, 1e-10), report.verdict()
    assert verdict(report, 1e-10, 'x').startswith('resim: DIFFERENT')


def test_resim_refuses_non_model_overrides(stepped_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_main(['resim', str(stepped_log), '--set', 'feed.target_x=1']) == 2
    assert '--set feed.target_x: not a model parameter' in capsys.readouterr().err
    with pytest.raises(ResimError, match='feed.target_x'):
        resimulate(LogReader(stepped_log), {'feed.target_x': 1.0})
    # a shared scenario file (feed controller settings included) still applies its model parameters
    config = Path(__file__).resolve().parents[1] / 'config' / 'feeder.yaml'
    assert cli_main(['resim', str(stepped_log), '--params', str(config), '--json']) in (0, 1)
    assert not any(name.startswith('feed.') for name in json.loads(capsys.readouterr().out)['overrides'])


def test_a_log_rewritten_by_rosbags_gives_the_same_results(stepped_log: Path, tmp_path: Path) -> None:
    """Sim time comes from the header stamps, not from the MCAP publish time (rosbags writes the receive
    time there): info, plot data, export and resim agree on the same messages written by another recorder."""
    from log_fixtures import rewrite_with_rosbags

    from micro_feeder.logs.export import export_csv
    from micro_feeder.logs.series import part_series

    other = tmp_path / 'rosbags'
    rewrite_with_rosbags(stepped_log, other)
    ours, theirs = LogReader(stepped_log), LogReader(other)
    pose = next(theirs.messages(['particle/pose']))
    assert pose.publish_time_ns == pose.log_time_ns != pose.stamp_ns    # the other recorder's convention

    def summary_text(log: LogReader) -> list[str]:
        # Path and size differ by construction; our recorder's loss counters (an MCAP metadata record) are
        # not the messages, so the rewrite has only those of its last /diagnostics.
        skip = ('log ', 'files ', 'loss ')
        return [line for line in format_summary(summarize(log)).splitlines() if not line.startswith(skip)]

    assert summary_text(theirs) == summary_text(ours)
    a, b = part_series(ours), part_series(theirs)
    assert a.time_axis == b.time_axis == 'sim time'
    for name in ('pose', 'twist', 'wrench', 'mode'):
        sa, sb = getattr(a, name), getattr(b, name)
        assert np.array_equal(sa.t, sb.t) and sa.values.keys() == sb.values.keys()
        assert all(np.array_equal(sa.values[k], sb.values[k]) for k in sa.values)
    files_a, files_b = export_csv(ours, tmp_path / 'csv_a'), export_csv(theirs, tmp_path / 'csv_b')
    assert [f.name for f in files_a] == [f.name for f in files_b]
    assert all(fa.read_text() == fb.read_text() for fa, fb in zip(files_a, files_b, strict=True))
    report_a, report_b = resimulate(ours).as_dict(), resimulate(theirs).as_dict()
    report_a.pop('log'), report_b.pop('log')
    assert report_b == report_a and report_a['identical']


def test_ctrl_c_stops_a_long_resim_within_a_second(tmp_path: Path) -> None:
    """A 150 s log (150,000 poses): resim shows progress, and SIGINT ends it within 1 s, status 130, no
    traceback."""
    from log_fixtures import T0, pose
    from rclpy.serialization import serialize_message

    from micro_feeder.logs.writer import LogWriter
    writer = LogWriter(tmp_path / 'long.mcap')
    writer.add_topic('/particle/pose', 'geometry_msgs/msg/PoseStamped')
    for i in range(150_000):
        writer.write('/particle/pose', serialize_message(pose(i)), T0 + i * 1_000_000)
    writer.close()
    env = {**os.environ, 'PYTHONUNBUFFERED': '1'}
    proc = subprocess.Popen([str(Path(sys.executable).parent / 'micro-feeder'), 'resim', str(tmp_path / 'long.mcap')],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        line = proc.stderr.readline()              # the first progress line (blocks until it comes)
        assert line.startswith('resim: ') and 'stops' in line and 's left' in line, line
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
        elapsed = time.monotonic() - sent
    finally:
        proc.kill()
        proc.wait()
    err = proc.stderr.read()
    assert proc.returncode == 130 and 'interrupted' in err and 'Traceback' not in err, err
    assert elapsed < 1.0, f'{elapsed:.2f} s to stop'


def test_parts_spawned_and_deleted_resimulate_bit_for_bit(tmp_path: Path) -> None:
    """Parts spawned and deleted during a stepped run (SpawnEntity, DeleteEntity) reach the log on
    simulator/entity_changes, and resim applies them at the same sim times: every part of every pose matches."""
    context = Context()
    rclpy.init(context=context)
    path = tmp_path / 'spawned'
    try:
        with _stepped_nodes(context, path) as (recorder, sim, probe, executor):
            wait_until(lambda: sim.count_subscribers('simulator/entity_changes') == 2
                       and sim.count_subscribers('particles/poses') == 2
                       and recorder.received['/simulator/parameters'] == 1, TIMEOUT, executor=executor,
                       what='recorder and probe matched')
            at_start = recorder.received['/particle/pose']
            sim.follow(_burst(0.0))
            probe.step(executor, 10)
            assert sim.spawn_part('guest', -0.45e-3)[0]
            assert not sim.spawn_part('guest', -0.8e-3)[0]          # the name is taken
            probe.step(executor, 30)
            assert sim.spawn_part('part_1', 1.0e-3)[0]
            assert not sim.spawn_part('crowd', 1.05e-3)[0]          # overlaps part_1: refused, nothing recorded
            probe.step(executor, 40)
            assert sim.delete_part('part_0')[0]
            probe.step(executor, 60)
            wait_until(lambda: recorder.received['/particle/pose'] == at_start + 140
                       and recorder.received['/simulator/entity_changes'] == 3, TIMEOUT, executor=executor,
                       what='every pose and change recorded')
    finally:
        rclpy.shutdown(context=context)
    log = LogReader(path)
    counts = [len(m.message.poses) for m in log.messages(['particles/poses'], decoded=True)]
    assert counts[0] == 1 and max(counts) == 3 and counts[-1] == 2, counts
    report = resimulate(log)
    assert report.identical and report.max_error == 0.0, report.verdict()
    assert any('3 parts spawned or deleted' in note for note in report.notes), report.notes
    text = format_summary(summarize(log))          # info: the changes, and no distance by part index
    assert '2 spawned, 1 deleted during the run' in text and 'moved' not in text.split('parts      ')[-1], text
    assert cli_main(['plot', str(path), '-o', str(tmp_path / 'run.png')]) == 0
    assert (tmp_path / 'run_parts.png').stat().st_size > 0
