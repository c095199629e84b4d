"""A stream follows sim time wherever it goes (issue 30): after a reset (sim time back to 0, as a new simulator
also shows it), a new simulator whose sim time is already past the old one's, a stall of the sender (sim
time ran past the strokes scheduled) or a starved simulator (windows delivered late and refused, with the
windows continuing them: the sender learns it from the refusal), the stream re-phases
``stream.lead`` ahead of sim time, ramping from the strokes the simulator holds; it never replays stale
windows, never joins mid-stroke with a jump, and the part never moves faster than the same strokes move it
without the fault.

Driven as the nodes drive it, without ROS: the actuator's :class:`StrokeStream` windows, serialized and
parsed by the simulator's command code, applied to the simulator's Stepper, which is sampled finely (37 µs)
so that a jump in the stroke or a throw of the part cannot hide between samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest

from micro_feeder.interface.names import joint_names
from micro_feeder.physics.waveforms import StrokeParams
from micro_feeder.settings import load_settings
from micro_feeder.sim.commands import CommandRejected, parse_trajectory_cdr
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import StrokeStream, encode_window

LEAD, WINDOW = 0.02, 0.0053       # s: stream.lead and stream.window (short against the faults; not a whole number
                                    # of stroke periods, so that windows start mid-stroke)
SAMPLE = 1e-3 / 27                  # s: the simulator's state is looked at this often
DURATION = 0.3                      # s of sim time
FAULT_AT, FAULT_FOR = 0.1, 0.05     # s: when the fault happens; how long the sender is stalled
REFUSAL_DELAY = 0.004               # s: a refusal reaches the sender this long after it (it sends meanwhile)
SCENARIOS = {'one actuator': [], 'travelling wave': ['--params', 'config/travelling_wave.yaml']}


@dataclass
class Run:
    refused: list[str] = field(default_factory=list)
    rephased: list[tuple[float, str]] = field(default_factory=list)
    window_starts: list[float] = field(default_factory=list)   # sim time each applied window starts (s)
    max_stroke_step: float = 0.0     # largest change of any stroke between two samples (m)
    max_speed: float = 0.0           # the part's largest speed at a sample (m/s)


def _run(scenario: str, fault: str) -> Run:
    params_file = SCENARIOS[scenario][1:] if SCENARIOS[scenario] else []
    flat = load_settings(params_file)
    stepper = Stepper(build_model(flat))
    n = stepper.model.n_actuators
    stream = StrokeStream(StrokeParams.from_flat({**flat, 'stroke.count': 1}), 0, n, round(LEAD * 1e9),
                          window=WINDOW, max_points=2000, knots_per_stroke=0)
    run, previous, fault_done, new_simulator = Run(), None, False, False
    in_transit: list[tuple[int, bytes]] = []            # (window number, message) not yet delivered
    refusals: list[tuple[float, int]] = []              # (sim time it reaches the sender, window number)
    elapsed = 0.0                                       # sim time lived through, across the reset
    while elapsed < DURATION:
        faulty = FAULT_AT <= stepper.t < FAULT_AT + FAULT_FOR
        if not (fault == 'stall' and faulty):
            for number in [number for at, number in refusals if at <= stepper.t]:
                why = stream.refused(number, stepper.t, LEAD)
                if why is not None:
                    run.rephased.append((stepper.t, why))
            refusals = [(at, number) for at, number in refusals if at > stepper.t]
            windows, why = stream.follow(stepper.t, LEAD, new_simulator=new_simulator)
            new_simulator = False
            if why is not None:
                run.rephased.append((stepper.t, why))
            for window in windows:
                in_transit.append((stream.windows_made, encode_window(window, f'sender:b1:w{stream.windows_made}')))
        if not (fault == 'late delivery' and faulty):   # a starved simulator: the windows wait, in order
            for number, message in in_transit:
                cmd = parse_trajectory_cdr(message, joint_names(n), stepper.limits)
                try:
                    stepper.command_trajectory(cmd)
                    run.window_starts.append(cmd.stamp)
                except CommandRejected as err:           # what simulator/command_status tells the sender
                    run.refused.append(str(err))
                    refusals.append((stepper.t + REFUSAL_DELAY, number))
            in_transit.clear()
        stepper.advance(stepper.t + SAMPLE)
        elapsed += SAMPLE
        obs = stepper.observe()
        run.max_speed = max(run.max_speed, float(np.hypot(obs.xdot, obs.zdot)))
        if previous is not None:
            run.max_stroke_step = max(run.max_stroke_step, float(np.max(np.abs(obs.strokes - previous))))
        previous = obs.strokes.copy()
        if fault == 'reset' and not fault_done and stepper.t >= FAULT_AT:
            stepper.reset()                             # what ~/reset, or a restarted simulator, shows
            fault_done, previous = True, None
        if fault == 'new simulator' and not fault_done and stepper.t >= FAULT_AT:
            # a restarted simulator first seen when its sim time is a little past the old one's, inside the
            # strokes already scheduled: it holds none of them (the actuator learns it from the graph)
            fresh = Stepper(build_model(flat))
            fresh.advance(stepper.t + LEAD / 4)
            stepper, fault_done, previous, new_simulator = fresh, True, None, True
    return run


@pytest.fixture(scope='module')
def unfaulted() -> dict[str, Run]:
    return {scenario: _run(scenario, 'none') for scenario in SCENARIOS}


@pytest.mark.parametrize('scenario', list(SCENARIOS))
@pytest.mark.parametrize('fault', ['stall', 'reset', 'new simulator', 'late delivery'])
def test_a_stream_rephases_without_stale_windows_jumps_or_throws(scenario: str, fault: str,
                                                                  unfaulted: dict[str, Run]) -> None:
    reference, run = unfaulted[scenario], _run(scenario, fault)
    assert not reference.refused and not reference.rephased
    if fault == 'late delivery':     # the windows that came late are refused, and those continuing them
        assert run.refused and all('late by' in r or 'was not applied' in r for r in run.refused), run.refused
    else:
        assert not run.refused, run.refused[:3]             # no window late, none joined with a jump
    assert len(run.rephased) == 1, run.rephased
    when, why = run.rephased[0]
    assert {'reset': 'went back', 'stall': 'passed the strokes', 'new simulator': 'a new simulator',
            'late delivery': 'refused by the simulator'}[fault] in why, why
    resumed = min(t for t in run.window_starts if t >= when)
    assert resumed - when <= 2 * LEAD + 1e-9                # strokes again within 2 x stream.lead
    # the strokes move no faster than the waveform does, but for the ramp (a quintic from rest that joins the
    # waveform mid-stroke peaks up to 0.4 % above it here; a jump is 5-6x it), the part no faster than the
    # same strokes move it without the fault
    assert run.max_stroke_step <= reference.max_stroke_step * 1.01, (run.max_stroke_step,
                                                                     reference.max_stroke_step)
    assert run.max_speed <= reference.max_speed * 1.05, (run.max_speed, reference.max_speed)


def test_a_stalled_sender_skips_what_it_missed() -> None:
    """After a stall, the waveform continues where sim time puts it: nothing covers the stretch the sender
    missed (what an unstalled stream would have sent then is skipped, not replayed late); the next window
    starts ``stream.lead`` after the sender is back."""
    run = _run('one actuator', 'stall')
    when, _ = run.rephased[0]
    scheduled_at_stall = FAULT_AT + LEAD                  # what the sender had sent when it stalled
    skipped = [t for t in run.window_starts if scheduled_at_stall - 1e-9 <= t < when + LEAD - 1e-9]
    assert not skipped, skipped
    assert any(abs(t - (when + LEAD)) < 1e-9 for t in run.window_starts)
