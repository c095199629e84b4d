"""Faults of the running system with real processes, as a lab sees them (issue 30): many separate actuator
starts against a running simulator and recorder; a reset, a simulator restart and a stalled actuator while
it streams. Each asserts what the user must see, and that nothing was applied twice, late or thrown.

Marked ``faults`` (``make test`` runs them; ``-m faults`` runs only them).
"""

from __future__ import annotations

import math
import signal
import time
from collections import Counter
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistStamped
from node_helpers import start_process, stop_process
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from ros_helpers import wait_until
from sensor_msgs.msg import JointState
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from micro_feeder.interface.names import split_receipt_frame
from micro_feeder.interface.stamps import seconds
from micro_feeder.logs.reader import LogReader
from micro_feeder.nodes._ros import topic_qos
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.settings import load_settings
from micro_feeder.sim.stepper import build_model
from micro_feeder.sim.stream import sample_waveform

pytestmark = pytest.mark.faults

STARTS, AT_ONCE = 50, 5       # separate actuator processes, started this many at a time
LEAD, WINDOW = 0.2, 0.02      # s: the actuator's default stream.lead and stream.window
IN_FLIGHT = round(LEAD / WINDOW) + 2   # windows an actuator can have sent that the simulator has not applied yet


class Watcher(Node):
    """An outside client: receipts, strokes, the part's speed, every /diagnostics status."""

    def __init__(self, context: Context):
        super().__init__('fault_watcher', context=context)
        self.receipts: list[tuple[float, str, str]] = []          # (sim time, topic, command identity)
        self.strokes: list[tuple[float, float, float]] = []       # (sim time, stroke, stroke velocity) of joint 0
        self.speeds: list[tuple[float, float]] = []               # (sim time, part speed)
        self.status: dict[str, dict[str, str]] = {}               # last status by name
        self.statuses: Counter[str] = Counter()                   # statuses received by name
        self.create_subscription(Header, 'simulator/command_receipts', self._on_receipt,
                                 topic_qos('simulator/command_receipts', 1000))
        self.create_subscription(JointState, 'actuator/joint_states', self._on_joints,
                                 topic_qos('actuator/joint_states', 1000))
        self.create_subscription(TwistStamped, 'particle/twist', self._on_twist, topic_qos('particle/twist', 1000))
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, topic_qos('/diagnostics'))

    def _on_receipt(self, msg: Header) -> None:
        self.receipts.append((seconds(msg.stamp), *split_receipt_frame(msg.frame_id)))

    def _on_joints(self, msg: JointState) -> None:
        self.strokes.append((seconds(msg.header.stamp), msg.position[0], msg.velocity[0]))

    def _on_twist(self, msg: TwistStamped) -> None:
        self.speeds.append((seconds(msg.header.stamp), math.hypot(msg.twist.linear.x, msg.twist.linear.z)))

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            self.status[status.name] = {kv.key: kv.value for kv in status.values} | {'_message': status.message}
            self.statuses[status.name] += 1


def _spin(executor: SingleThreadedExecutor, seconds_: float) -> None:
    end = time.monotonic() + seconds_
    while time.monotonic() < end:
        executor.spin_once(timeout_sec=0.02)


def _bursts_received(watcher: Watcher) -> set[str]:
    """The identities of the trajectories the simulator acknowledged."""
    return {command_id for _, topic, command_id in watcher.receipts if topic == 'actuator/trajectory'}


def test_fifty_separate_actuator_starts_are_each_applied_and_logged_once(ros_context: Context,
                                                                         tmp_path: Path) -> None:
    """A recorder on the graph used to start an actuator before the simulator listened (the burst lost), and
    a second tick of the start timer sent it twice; 50 actuators started against a running simulator and
    recorder now give 50 bursts, each applied once under its own identity (a burst lost in discovery all
    the same is sent again until its receipt, and the copy refused as a duplicate), every receipt logged
    once, and every message received logged once (the simulator's copy)."""
    sim = start_process('simulator')
    recorder = start_process('recorder', '-p', f'output:={tmp_path / "log"}')
    watcher = Watcher(ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(watcher)
    actuators = []
    try:
        ready = lambda: {topic: (watcher.count_publishers(topic), watcher.count_subscribers(topic))  # noqa: E731
                         for topic in ('particle/pose', 'simulator/trajectories_received')}
        try:
            wait_until(lambda: all(p > 0 and s >= 1 for p, s in ready().values()), 120, executor=executor,
                       what='simulator and recorder')
        except AssertionError as err:   # say what was missing and what the processes said (CI, once)
            raise AssertionError(f'{err}: (publishers, subscribers) {ready()}; simulator: {stop_process(sim)}; '
                                 f'recorder: {stop_process(recorder)}') from err
        for first in range(0, STARTS, AT_ONCE):
            batch = [start_process('actuator', '-r', f'__node:=actuator_{k}', '-p', 'stroke.count:=1')
                     for k in range(first, first + AT_ONCE)]
            actuators += batch
            # bursts, not receipts: a burst whose receipt was slow is sent again, and the copy has one too
            wait_until(lambda n=first + AT_ONCE: len(_bursts_received(watcher)) >= n, 120, executor=executor,
                       what=f'{first + AT_ONCE} bursts received')
            for proc in batch:
                assert stop_process(proc)[0] == 0
        _spin(executor, 1.5)                                     # a second burst would arrive meanwhile
        # the status once a second: wait for the one that counts every message received
        wait_until(lambda: watcher.status['simulator: loop']['commands_received'] == str(len(watcher.receipts)),
                   10, executor=executor, what="the simulator's status counting every receipt")
        simulator_status = watcher.status['simulator: loop']
    finally:
        executor.shutdown()
        watcher.destroy_node()
        for proc in actuators:
            stop_process(proc)
        recorder_code, recorder_out = stop_process(recorder)
        stop_process(sim)
    identities = [command_id for _, topic, command_id in watcher.receipts if topic == 'actuator/trajectory']
    # a burst lost in discovery is sent again until its receipt: its copies are received and refused as
    # duplicates, so each burst is applied once whatever arrived twice
    applied = _bursts_received(watcher)
    copies = len(identities) - len(applied)
    assert len(applied) == STARTS, Counter(identities).most_common(3)
    assert len({command_id.split('@')[0] for command_id in applied}) == STARTS     # one burst per actuator
    assert simulator_status['rejected_commands'] == '0'
    assert simulator_status['commands_received'] == str(len(identities))
    assert simulator_status['commands_repeated'] == str(copies)
    assert recorder_code == 0, recorder_out
    log = LogReader(tmp_path / 'log')
    logged_receipts = [split_receipt_frame(m.message.frame_id)[1]
                       for m in log.messages(['simulator/command_receipts'], decoded=True)]
    assert sorted(logged_receipts) == sorted(identities)        # every receipt logged, once
    # every message received in the log once, in the simulator's copy of what it received, whatever the
    # recorder had discovered of each new actuator when its burst went (seconds late, on a loaded machine)
    held = Counter(m.message.header.frame_id
                   for m in log.messages(['simulator/trajectories_received'], decoded=True))
    assert held == Counter(identities), (held - Counter(identities), Counter(identities) - held)
    assert log.command_source('actuator/trajectory') == '/simulator/trajectories_received'
    # the senders' topic as the recorder saw it: a burst sent before the recorder matched its sender is
    # missing there, and one sent again may be there twice
    logged = Counter(m.message.header.frame_id for m in log.messages(['actuator/trajectory'], decoded=True))
    assert set(logged) <= applied, set(logged) - applied
    print(f'the log holds {len(held)} of {STARTS} bursts received ({copies} sent again and refused as '
          f'duplicates), {len(logged)} as the recorder saw them sent')


def _stream_rig(ros_context: Context) -> tuple:
    sim = start_process('simulator')
    actuator = start_process('actuator', '-p', 'stroke.count:=0')
    watcher = Watcher(ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(watcher)
    wait_until(lambda: len(watcher.strokes) > 500 and any(abs(v) > 0 for _, _, v in watcher.strokes[-200:]), 120,
               executor=executor, what='the stream under way')
    return sim, actuator, watcher, executor


def _moving_again_after(watcher: Watcher, t_from: float, before: float = math.inf) -> float | None:
    """Sim time of the first moving stroke in [``t_from``, ``before``): ``before`` leaves out the samples of
    a run of sim time that a reset ended, which can still be queued when the test clears the list."""
    for t, _, v in watcher.strokes:
        if t_from <= t < before and abs(v) > 1e-9:
            return t
    return None


def _assert_nothing_late_joined_nothing_twice(sim_status: dict[str, str], lost: int = 0) -> None:
    """Every refusal was of a late window or of a window continuing a refused one (none was a duplicate or
    invalid), and none joined: a window can reach the simulator late when a process is starved or stopped
    for longer than stream.lead (windows in flight when the actuator stopped are repaired by its reliable
    writer only when it runs again; a loaded CI machine starved the simulator ~0.2 s once), and the simulator
    must refuse it rather than jump, and refuse the windows continuing it. The actuator re-phases on the
    first refusal, so each late window costs at most the windows it had in flight (a loop of refusals cost
    137 windows against 2 late ones once). ``lost``: windows that may never reach the simulator (the first
    ones a new simulator's subscription gets before it has matched the actuator's writer), each of which
    costs the same as a late one: the windows continuing it are refused until the actuator re-phases."""
    rejected, late = int(sim_status['rejected_commands']), int(sim_status['commands_late'])
    said = f"{rejected} refused, {late} late; the last refusal: {sim_status['last_rejection']}"
    assert rejected <= (late + lost) * (1 + IN_FLIGHT), said
    assert rejected == 0 or any(why in sim_status['last_rejection'] for why in ('late by', 'continues')), said


def _strokes_speed_bound(seconds_: float = 3.0) -> float:
    """The fastest the configured (default) strokes move the part offline (m/s): the surface's fastest
    stroke (a stuck part rides it up and down) plus the part's fastest motion relative to the feeder over
    ``seconds_`` of strokes (``simulate``'s max speed). A sample of the part's speed before the fault is no
    bound: at 1 kHz against 1 kHz strokes it sees one phase of the stroke, and a re-phase shifts it."""
    flat = load_settings()
    params = StrokeParams.from_flat({**flat, 'stroke.count': 1})
    surface = float(abs(sample_waveform(params, len(params.phases))[2]).max())
    relative = build_model({**flat, 'stroke.count': round(seconds_ * params.frequency)}).run(seconds_).state.max_speed
    return surface + relative


def _assert_no_throw(watcher: Watcher, before: float) -> None:
    """The part never faster than the configured strokes move it offline (5 % margin); ``before``, its
    fastest sample before the fault, is reported."""
    peak = max(s for _, s in watcher.speeds[-20000:])
    bound = _strokes_speed_bound()
    assert peak <= 1.05 * bound, (f'part at {peak:.3f} m/s, the strokes move it at most {bound:.3f} m/s offline '
                                  f'({before:.3f} m/s sampled before the fault)')


@pytest.mark.parametrize('fault', ['reset', 'sigstop'])
def test_a_stream_follows_sim_time_through_a_reset_and_a_stalled_actuator(ros_context: Context, fault: str) -> None:
    sim, actuator, watcher, executor = _stream_rig(ros_context)
    try:
        _spin(executor, 1.0)
        before = max(s for _, s in watcher.speeds)
        old_run = math.inf                                  # sim times of the run before the fault, if it ended
        if fault == 'reset':
            # the old run's samples still queued after the reset's answer come at or after the last one seen
            # (CI under load: a moving stroke at 1.505 s, read as the strokes moving 1.5 s after the reset);
            # the new run's come from 0, and the rig ran well over 2 stream.lead before the reset
            old_run = watcher.strokes[-1][0]
            service = watcher.create_client(Trigger, 'simulator/reset')
            wait_until(service.service_is_ready, 30, executor=executor, what='simulator/reset')
            future = service.call_async(Trigger.Request())
            wait_until(future.done, 30, executor=executor, what='reset answered')
            watcher.strokes.clear()
            resumed_at = 0.0
        else:
            stopped_at = watcher.strokes[-1][0]
            actuator.send_signal(signal.SIGSTOP)
            _spin(executor, 2.0)
            # a stall the stream must notice is one that outlasts the strokes scheduled ahead in sim time: on a
            # starved machine 2 s of wall time once gave less than stream.lead of sim time (no re-phase needed)
            wait_until(lambda: watcher.strokes[-1][0] - stopped_at > 2 * LEAD, 30, executor=executor,
                       what='sim time passing the strokes scheduled before the stop')
            resumed_at = watcher.strokes[-1][0]
            actuator.send_signal(signal.SIGCONT)
        wait_until(lambda: _moving_again_after(watcher, resumed_at, old_run) is not None, 30, executor=executor,
                   what='strokes moving again')
        moving = _moving_again_after(watcher, resumed_at, old_run)
        assert moving - resumed_at <= 2 * LEAD + 0.05, f'strokes again {moving - resumed_at:.3f} s after the fault'
        wait_until(lambda: 're-phase' in watcher.status.get('actuator: stroke', {}).get('_message', ''), 30,
                   executor=executor, what='the actuator reporting the re-phase')
        _spin(executor, 1.0)
        sim_status, actuator_status = watcher.status['simulator: loop'], watcher.status['actuator: stroke']
        _assert_no_throw(watcher, before)
    finally:
        executor.shutdown()
        watcher.destroy_node()
        stop_process(actuator)
        stop_process(sim)
    assert int(actuator_status['stream_rephases']) >= 1
    _assert_nothing_late_joined_nothing_twice(sim_status)
    if fault == 'sigstop':                                         # no replay of the past: windows in the
        assert int(actuator_status['windows_sent']) < 400          # usual ~50/s, not a burst of stale ones


def test_a_stream_survives_a_simulator_restart(ros_context: Context) -> None:
    sim, actuator, watcher, executor = _stream_rig(ros_context)
    try:
        _spin(executor, 1.0)
        before = max(s for _, s in watcher.speeds)
        assert stop_process(sim)[0] == 0
        wait_until(lambda: 'no simulator' in watcher.status.get('actuator: stroke', {}).get('_message', ''), 30,
                   executor=executor, what='the actuator saying the simulator is gone')
        watcher.strokes.clear()
        sim = start_process('simulator')
        wait_until(lambda: _moving_again_after(watcher, 0.0) is not None, 60, executor=executor,
                   what='the new simulator moving')
        moving = _moving_again_after(watcher, 0.0)
        first = watcher.strokes[0][0]
        seen = watcher.statuses['actuator: stroke']        # a status the actuator published after the moving stroke
        wait_until(lambda: watcher.statuses['actuator: stroke'] >= seen + 2, 30, executor=executor,
                   what="the actuator's status after the strokes moved")
        actuator_status = dict(watcher.status['actuator: stroke'])
        # empty when this stream has not re-phased: the new simulator took its windows as they came
        rephased = float(actuator_status['last_rephase_at'] or 'nan')
        # discovery decides when the new simulator is reached (0.1-1.9 s of sim time, idle or loaded machine):
        # the actuator re-phases when its publisher matches the new simulator's subscription, and again when
        # the simulator refuses a window continuing one lost before its reader matched the actuator's writer.
        # From that last re-phase the stream is the actuator's. This client discovers the simulator on its own
        # time too, and sees nothing before its first state.
        since = first if math.isnan(rephased) else max(rephased, first)
        assert moving - since <= 2 * LEAD + 0.05, (f"strokes again {moving - since:.3f} s after the actuator's "
                                                   f'last re-phase ({rephased:.3f} s) or the first state seen '
                                                   f'({first:.3f} s); the actuator: {actuator_status}')
        assert moving - first <= 10.0, f'strokes again {moving - first:.3f} s after the new simulator began'
        _spin(executor, 1.0)
        sim_status = watcher.status['simulator: loop']
        _assert_no_throw(watcher, before)
    finally:
        executor.shutdown()
        watcher.destroy_node()
        stop_process(actuator)
        stop_process(sim)
    # the actuator's writer matches the new simulator's reader before the reader matches it: a window sent in
    # between is lost (CI once: 10 refused, 0 late, each a window continuing the lost one), and the stream
    # re-phases on the first refusal
    _assert_nothing_late_joined_nothing_twice(sim_status, lost=1)
