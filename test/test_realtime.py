"""The simulator's rclpy-free parts: command coalescing, throttled refusal lines, the intake's bounds and
threads, the loop's grid and pause, the publishing handoff, the diagnostics function."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest
from ros_helpers import wait_until

from micro_feeder.realtime.diagnostics import ERROR, OK, WARN, LoopSnapshot, loop_status
from micro_feeder.realtime.handoff import Handoff
from micro_feeder.realtime.intake import CommandIntake, Received, ThrottledLog, plan
from micro_feeder.realtime.loop import TickLoop
from micro_feeder.sim.commands import start_time


def _parse(received: Received) -> str:
    if received.data == b'bad':
        raise ValueError('bad command')
    return received.data.decode()


def test_a_later_valid_command_starting_no_later_supersedes_unparsed() -> None:
    parsed: list[bytes] = []

    def parse(r: Received) -> str:
        parsed.append(r.data)
        return _parse(r)

    batch = [Received('actuator/trajectory', b'a', 0.0),          # starts now (t = 1): superseded by c
             Received('actuator/trajectory', b'b', 5.0),          # starts at 5: superseded by c (starts earlier)
             Received('actuator/command', b'c', 0.0),             # valid, starts now
             Received('actuator/trajectory', b'd', 3.0),          # starts later than c: kept
             Received('actuator/command', b'bad', 0.0)]           # invalid: refused, supersedes nothing
    outcomes = plan(batch, 1.0, start_time, parse)
    assert [o.coalesced for o in outcomes] == [True, True, False, False, False]
    assert [o.command for o in outcomes] == [None, None, 'c', 'd', None]
    assert outcomes[4].refused == 'bad command'
    assert parsed == [b'bad', b'd', b'c']         # newest first, the superseded never parsed
    no_coalescing = plan(batch, 1.0, start_time, _parse, coalesce=False)
    assert [o.command for o in no_coalescing] == ['a', 'b', 'c', 'd', None]


def test_refusals_are_logged_first_then_summarised_per_period() -> None:
    now = [0.0]
    log = ThrottledLog(period=5.0, clock=lambda: now[0])
    assert log.note('nan') == 'command rejected: nan'
    lines = [log.note(f'nan {i}') for i in range(1000)]
    assert lines == [None] * 1000 and log.flush() is None
    now[0] = 5.0
    assert log.flush() == '1000 commands rejected in the last 5 s; last: nan 999'
    assert log.flush() is None


def test_intake_refuses_oversized_drops_oldest_and_processes_on_its_thread() -> None:
    batches: list[list[Received]] = []
    threads: set[str] = set()

    def process(batch: list[Received]) -> None:
        threads.add(threading.current_thread().name)
        batches.append(batch)

    paused = [True]
    intake = CommandIntake(process, lambda: paused[0], max_message_bytes=10, max_queued_bytes=20)
    try:
        intake.submit(Received('actuator/command', b'x' * 11, 0.0))
        assert batches[-1][0].refused.startswith('actuator/command: message of 11 B over max_command_bytes')
        assert threads == {threading.current_thread().name}        # paused: processed at once, here
        with intake.busy:                                            # hold the worker off: three queue up
            paused[0] = False
            for data in (b'a' * 10, b'b' * 10, b'c' * 10):
                intake.submit(Received('actuator/command', data, 0.0))
        wait_until(lambda: len(batches) == 2, 5, what='the worker to take the batch')
        assert [r.data for r in batches[1]] == [None, b'b' * 10, b'c' * 10] and intake.dropped == 1
        assert 'simulator-intake' in threads
    finally:
        intake.stop()


def test_loop_ticks_on_its_thread_pauses_and_stops() -> None:
    ticks: list[float] = []
    loop = TickLoop(0.002, ticks.append, lambda err: None, name='test-loop')
    try:
        time.sleep(0.02)
        assert not ticks                         # starts paused
        loop.resume()
        wait_until(lambda: len(ticks) >= 20, 5, what='20 ticks')
        loop.pause()
        time.sleep(0.01)
        n = len(ticks)
        time.sleep(0.02)
        assert len(ticks) == n
        assert np.median(ticks) == pytest.approx(0.002, rel=0.5)
        periods, busy = loop.timing.drain()
        assert periods.size == busy.size >= 20
    finally:
        assert loop.stop(timeout=1.0)


def _snapshot(**changes: object) -> LoopSnapshot:
    base = dict(sim_time=1.5, mode='stuck', paused=False, lockstep=False, error='', rtf_target=1.0,
                achieved_rtf=1.0, publish_rate=1000.0, periods_ms=np.array([1.0, 1.0, 2.0]),
                busy_ms=np.array([0.1, 0.2, 0.3]), overruns=0, tick_age=0.0, steps_granted=0, states_published=1500,
                pending_reset=False, transitions={'stick_to_slip': 2}, intake={'rejected_commands': '3'})
    base.update(changes)
    return LoopSnapshot(**base)


def test_loop_status_levels_and_values() -> None:
    ok = loop_status(_snapshot())
    assert (ok.level, ok.message) == (OK, 'running')
    assert ok.values['tick_period_p50_ms'] == '1.000' and ok.values['rejected_commands'] == '3'
    assert ok.values['stick_to_slip'] == '2' and ok.values['publish_rate_achieved'] == '1000.0'
    assert loop_status(_snapshot(achieved_rtf=0.9)).level == WARN
    assert loop_status(_snapshot(achieved_rtf=0.9, paused=True)).level == OK
    wedged = loop_status(_snapshot(tick_age=3.0))
    assert wedged.level == ERROR and 'one tick has been working for 3.0 s' in wedged.message
    assert loop_status(_snapshot(error='SimulationError: x')).message == 'SimulationError: x'
    assert loop_status(_snapshot(periods_ms=np.zeros(0))).values['tick_period_p99_ms'] == 'nan'
    assert ok.values['publishes_refused'] == '0'
    refused = loop_status(_snapshot(refused={'/particle/pose': 4, '/clock': 1}, refused_new={'/particle/pose': 2}))
    assert refused.level == WARN and 'refused 2 message(s)' in refused.message
    assert '/particle/pose' in refused.message and '/clock' not in refused.message   # only where refusals are new
    assert refused.values['publishes_refused'] == '5' and refused.values['publishes_refused./clock'] == '1'
    assert loop_status(_snapshot(refused={'/clock': 1})).level == OK      # counted, nothing new to warn of


def test_the_handoff_runs_calls_in_order_on_its_thread_and_flush_waits_for_them() -> None:
    """The loop hands each tick's publishing over: the calls run in the order given, on one other thread; flush()
    returns only once every call handed over has finished (a lockstep step or a reset publishes after it); an
    exception goes to on_error and the calls after it still run; stop() runs what is left first."""
    done: list[int] = []
    threads: set[str] = set()
    errors: list[BaseException] = []
    release = threading.Event()

    def call(k: int) -> None:
        if k == 0:
            release.wait(5.0)               # the first call holds the rest back until released
        if k == 3:
            raise RuntimeError('publish failed')
        threads.add(threading.current_thread().name)
        done.append(k)

    handoff = Handoff(errors.append, name='test-handoff')
    for k in range(6):
        handoff.put(call, k)
    assert not handoff.flush(timeout=0.05) and done == []    # still held: flush times out
    release.set()
    assert handoff.flush(timeout=5.0)
    assert done == [0, 1, 2, 4, 5] and threads == {'test-handoff'}
    assert [str(err) for err in errors] == ['publish failed']
    for k in range(6, 50):
        handoff.put(call, k)
    assert handoff.stop(timeout=5.0) and done == [0, 1, 2, 4, 5, *range(6, 50)]


def test_a_handoff_that_falls_behind_holds_the_caller_back() -> None:
    """At most max_pending calls wait: put() then waits for room (the loop slows, states never pile up)."""
    release = threading.Event()
    handoff = Handoff(lambda err: None, max_pending=3)
    handoff.put(release.wait, 5.0)              # taken off the queue and running: the queue is empty again
    wait_until(lambda: not handoff._calls, 5.0)
    for _ in range(3):
        handoff.put(time.sleep, 0.0)
    fourth = threading.Thread(target=handoff.put, args=(time.sleep, 0.0))
    fourth.start()
    fourth.join(0.2)
    assert fourth.is_alive()                    # held back while three wait
    release.set()
    fourth.join(5.0)
    assert not fourth.is_alive() and handoff.flush(timeout=5.0) and handoff.stop()


def test_a_running_loop_leaves_what_existed_before_it_out_of_full_garbage_collections() -> None:
    """Once a loop runs, the garbage collector's full passes scan only objects made since (a full pass holds
    the GIL: over numpy's, scipy's, numba's and rclpy's objects it stopped every thread for 58-157 ms). In a
    fresh interpreter: after the first resume the imported objects are frozen, and a full pass scans a few."""
    import subprocess
    import sys
    code = '''
import gc, time
import numpy, scipy.optimize, micro_feeder.physics.dynamics
from micro_feeder.realtime.loop import TickLoop
before = len(gc.get_objects())
loop = TickLoop(0.001, lambda elapsed: None, print)
loop.resume()
time.sleep(0.05)
loop.stop()
print(before, gc.get_freeze_count(), len(gc.get_objects()))
'''
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120, check=True)
    before, frozen, scanned = map(int, out.stdout.split())
    assert before > 20_000 and frozen >= before * 0.9 and scanned < before / 20, (before, frozen, scanned)
