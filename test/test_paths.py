"""One answer on every path a user takes, as a property over drawn scenarios (not a list of cases).

For each drawn scenario (waveform, count, pause, delay, duty, amplitude, frequency, 1-5 actuators with
phases and places, piezo model on or off) the part must move the same on

* ``offline``: ``FeederModel.run``, what ``micro-feeder simulate`` integrates (the analytic strokes);
* ``stepped``: the simulator's Stepper in 1 ms ticks, driven by the actuator's own serialized
  JointTrajectory messages (the whole burst in one message, or the streamed windows the actuator sends
  when it does not fit; its ``stream.max_points`` and ``stream.window`` are drawn too), decoded and
  checked by the simulator's command code. ``resim`` runs this same Stepper on the commands and stop times
  it reads from a log, which test_resim.py proves bit for bit;
* ``sweep``: the row of a one-point ``sweep`` (distance, transition counts, regime).

"Same" is: equal transition counts and final mode, distance within 1e-9 m or 1e-6 relative (or the
scenario's own sensitivity to a stroke change as small as the knots' error, :func:`_conditioning`, plus
each path's own integration error, :func:`_convergence`, where that is not enough).

Two runs of the property: ``make test`` (``pytest test -m 'not paths'``) runs it on 200 scenarios of a fixed
seed (the same ones every time, ~1 min) besides the listed scenarios (the issue's and those the property
found); on demand, ``MF_PATH_EXAMPLES=2000 .venv/bin/python -m pytest -m paths test/test_paths.py`` runs it
on that many fresh random scenarios (a failure prints the ``@reproduce_failure`` blob that replays it).
"""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st

from micro_feeder.explore.evaluate import regime
from micro_feeder.explore.sweep import sweep
from micro_feeder.interface import stamps, trajectory_cdr
from micro_feeder.interface.names import joint_names
from micro_feeder.physics.trajectory import sample_table
from micro_feeder.physics.waveforms import WAVEFORMS, StrokeParams, is_jump_gap, trajectory_table, waveform_table
from micro_feeder.settings import load_settings
from micro_feeder.sim.commands import parse_trajectory_cdr
from micro_feeder.sim.stepper import Stepper, build_model
from micro_feeder.sim.stream import StrokeStream, points_per_message, sample_waveform

FIXED_EXAMPLES = 200          # the property in make test: a fixed seed
EXAMPLES = int(os.environ.get('MF_PATH_EXAMPLES', '200'))    # on demand (-m paths): fresh random draws
TRACK_EXAMPLES = int(os.environ.get('MF_TRACK_PATH_EXAMPLES', '100'))   # in make test (not marked paths)
TICK = 1e-3                   # s: the simulator's default step_period
LEAD, WINDOW = 0.2, 0.02      # s: the actuator's default stream.lead and stream.window
MAX_POINTS = 2000             # the actuator's default stream.max_points
ABS_TOL, REL_TOL = 1e-9, 1e-6


def _harmonics(draw: st.DrawFn) -> dict[str, object]:
    """The terms of a ``harmonics`` stroke: 1-3 distinct harmonic numbers, amplitudes and phases."""
    numbers = draw(st.lists(st.integers(1, 5), min_size=1, max_size=3, unique=True))
    phases = [draw(st.floats(-math.pi, math.pi)) for _ in numbers]
    weights = [draw(st.floats(0.05, 1.0)) for _ in numbers]
    # |s| ≤ A Σ a_h (1 + |sin φ_h|): scaled to ≤ A, so the strokes stay within the piezo travel the simulator
    # accepts (the drawn amplitudes are below it)
    scale = sum(w * (1.0 + abs(math.sin(p))) for w, p in zip(weights, phases, strict=True))
    return {'stroke.harmonics': numbers, 'stroke.harmonic_amplitudes': [w / scale for w in weights],
            'stroke.harmonic_phases': phases}


@st.composite
def scenarios(draw: st.DrawFn) -> dict[str, object]:
    """Flat settings of one scenario; everything else at its default."""
    n = draw(st.integers(1, 5))
    spacing = draw(st.floats(0.4e-3, 1.5e-3))
    waveform = draw(st.sampled_from(WAVEFORMS))
    flat: dict[str, object] = {
        'stroke.waveform': waveform,
        'stroke.count': draw(st.integers(1, 4)),
        'stroke.pause': draw(st.sampled_from([0.0, 0.0, draw(st.floats(1e-4, 4e-3))])),
        'stroke.delay': draw(st.sampled_from([0.0, draw(st.floats(1e-5, 2e-3))])),
        'stroke.duty': draw(st.floats(0.1, 0.9)),
        'stroke.amplitude': draw(st.floats(10e-6, 150e-6)),
        'stroke.frequency': draw(st.floats(200.0, 3000.0)),
        'stroke.phases': [draw(st.floats(0.0, 1.0)) for _ in range(n)],
        'surface.centers': [(k - (n - 1) / 2) * spacing for k in range(n)],
        'surface.widths': [draw(st.floats(0.5e-3, 1.5e-3)) for _ in range(n)],
        'particle.x0': draw(st.floats(-1.5e-3, 1.5e-3)),
        'piezo.enabled': draw(st.booleans()),
        # the actuator's: a burst longer than max_points knots is streamed in windows of at most stream.window
        'stream.max_points': draw(st.sampled_from([MAX_POINTS, draw(st.integers(16, 200))])),
        'stream.window': draw(st.sampled_from([WINDOW, draw(st.floats(2e-4, 5e-3))])),
    }
    if waveform == 'samples':
        # first sample 0: a shape starting elsewhere jumps in *position* at the burst's start, which two knots
        # cannot place exactly (docs/dynamics.md §2, a known limit: up to 0.4 ns off, a few nm after a flight)
        flat['stroke.samples'] = [0.0] + [draw(st.floats(-0.3, 1.0)) for _ in range(draw(st.integers(3, 7)))]
    if waveform == 'harmonics':
        flat.update(_harmonics(draw))
    if not flat['piezo.enabled']:   # a bending plate's surface points move along x too (below the fold-over)
        flat['surface.thickness'] = draw(st.sampled_from([0.0, draw(st.floats(1e-5, 0.6e-3))]))
    return flat


# Tight enough that what differs between paths is the strokes they integrate, not the integrator's own error
# (each path steps differently: the analytic strokes' breakpoints against the knots; at the defaults, 1e-10 m
# per step and 1e-9 s, a flight amplifies that to a few 1e-9 m). 1e-12 was not: its velocity error (1e-8 m/s
# a step) summed to 1e-7 m/s over the ~10 µs a part spends in the attraction after a take-off, and the piezo
# model turns a stack's 1e-12 m into ω²·1e-12 ≈ 0.1 m/s² of surface acceleration, which moved a take-off by
# 0.4 ns; the paths then differed by up to 1.6e-7 m (piezo, flights to the end).
INTEGRATION = {'integration.tolerance': 1e-13, 'integration.event_tolerance': 1e-13}


def _settings(scenario: dict[str, object]) -> dict[str, object]:
    return {**load_settings(), **INTEGRATION, **scenario}


def _duration(flat: dict[str, object]) -> float:
    """A whole number of ticks past the burst's end (+3 ms to let the part settle)."""
    end = StrokeParams.from_flat(flat).burst_end_s() + 3e-3
    return math.ceil(end / TICK) * TICK


def _offline(flat: dict[str, object], duration: float) -> tuple[float, dict[str, int], str]:
    state = build_model(flat).run(duration).state
    return state.distance, state.transitions, state.mode


def _stepped(flat: dict[str, object], duration: float, max_points: int = MAX_POINTS,
             window: float = WINDOW) -> tuple[float, dict[str, int], str]:
    """The Stepper in ticks, fed the bytes the actuator publishes (``max_points`` and ``window``: its
    ``stream.*`` parameters), as the simulator node applies them."""
    stepper = _stepped_run(flat, duration, max_points, window)
    return stepper.state.distance, stepper.state.transitions, stepper.state.mode


def _stepped_run(flat: dict[str, object], duration: float, max_points: int = MAX_POINTS,
                 window: float = WINDOW) -> Stepper:
    """:func:`_stepped`'s Stepper at the end of the run."""
    stepper = Stepper(build_model(flat))
    params = StrokeParams.from_flat(flat)
    n = stepper.model.n_actuators
    names = joint_names(n)
    stream = None
    times, pos, vel, acc = sample_waveform(params, n)
    if times.size <= points_per_message(max_points, n):      # the actuator sends it whole, stamped 0
        stepper.command_trajectory(parse_trajectory_cdr(
            trajectory_cdr.encode(names, np.round(times * 1e9), pos, vel, acc, stamps.to_time(0.0)),
            names, stepper.limits))
    else:                                                     # streamed from the sim time it sees
        stream = StrokeStream(params, params.count, n, 0, window=window, max_points=max_points,
                              knots_per_stroke=0)
    for i in range(1, round(duration / TICK) + 1):
        while stream is not None and not stream.done and stream.scheduled_until < stepper.t + LEAD:
            stamp_ns, offsets_ns, knots = stream.next_window()
            data = trajectory_cdr.encode(names, offsets_ns, knots[0], knots[1], knots[2],
                                         stamps.to_time(stamp_ns * 1e-9))
            stepper.command_trajectory(parse_trajectory_cdr(data, names, stepper.limits))
        stepper.advance_parts(i * TICK)
    return stepper


def _same_distance(a: float, b: float, allowance: float = 0.0) -> bool:
    return abs(a - b) <= max(ABS_TOL, REL_TOL * max(abs(a), abs(b)), allowance)


def _knot_error(flat: dict[str, object]) -> float:
    """The largest error of the knots' s̈ (the quintic Hermite between them, what the stepped path integrates)
    relative to the stroke's largest |s̈|, sampled across every knot interval but the ≤ 2-ns breakpoint
    gaps (1e-6 to 1e-5: it grows as (KNOT_TOLERANCE / amplitude)^(2/3); s and ṡ are far closer)."""
    params = StrokeParams.from_flat(flat)
    n = len(params.phases)
    times, pos, vel, acc = sample_waveform(params, n)
    gaps = np.diff(times)
    inside = (times[:-1, None] + gaps[:, None] * np.linspace(0.05, 0.95, 19))[~is_jump_gap(gaps)].ravel()
    exact = sample_table(waveform_table(params, n), inside)[2]
    knots = sample_table(trajectory_table(times, pos, vel, acc), inside)[2]
    return float(np.max(np.abs(knots - exact)) / max(np.max(np.abs(exact)), 1e-300))


def _stroke_changes(flat: dict[str, object]) -> list[dict[str, object]]:
    """Changes of the strokes as small as the knots' own error (:func:`_conditioning`)."""
    params = StrokeParams.from_flat(flat)
    eps = _knot_error(flat)
    shift = eps / (2.0 * math.pi)                  # in stroke periods: ε/ω seconds
    phases = list(params.phases)
    changes: list[dict[str, object]] = [{'stroke.amplitude': params.amplitude * f} for f in (1 - eps, 1 + eps)]
    if len(phases) > 1:
        changes += [{'stroke.phases': [p + shift * (k % 2 == odd) for k, p in enumerate(phases)]} for odd in (0, 1)]
    return changes


def _conditioning(flat: dict[str, object], duration: float, offline: tuple) -> tuple[bool, float]:
    """How the scenario answers a change of the strokes as small as the knots' own error ε (relative s̈,
    :func:`_knot_error`): (whether the transition counts and final mode survive it, 2x the distance it
    moves). Where a take-off or a landing grazes its threshold, or a part is still flying at the end, the
    physics turns that into more than 1e-9 m on any path (found by this test: half_sine and raised-cosine
    take-offs on phased actuators).

    The knots' error is ~ε·max|s̈| at any instant, of either sign, and different on each actuator. Two kinds
    of change span it: the amplitude ×(1 ± ε) changes s̈ by ε·s̈ (nothing where s̈ crosses 0), and a shift
    of every other actuator by ε/ω (ω = 2πf) changes it by ε·s⃛/ω (nothing at s̈'s extremes, where a
    take-off threshold is crossed). The first alone missed scenarios whose take-off time, set by the
    actuators' relative timing, moved the part 2-3x more under the knots (1.3e-9 and 1.5e-9 m; the
    amplitude probe 4.5e-10 and 7e-10 m). (A common shift of all actuators is a mere time translation.)
    Both missed a stick margin that the knots themselves took below 0 for 3.6 µs (an asymmetric stroke on
    5 phased actuators, a plate): the counts must also survive ``simulate`` driven by the knots."""
    allowance, stable = 0.0, True
    for change in _stroke_changes(flat):
        changed = _offline({**flat, **change}, duration)
        stable &= changed[1:] == offline[1:]
        allowance = max(allowance, 2.0 * abs(changed[0] - offline[0]))
    return stable and _offline_on_knots(flat, duration)[1:] == offline[1:], allowance


def _offline_on_knots(flat: dict[str, object], duration: float) -> tuple[float, dict[str, int], str]:
    """:func:`_offline` driven by the actuator's knots (the quintic Hermite between them) instead of the
    waveform."""
    model = build_model(flat)
    state = model.run(duration, source=trajectory_table(*sample_waveform(StrokeParams.from_flat(flat),
                                                                         model.n_actuators))).state
    return state.distance, state.transitions, state.mode


def _convergence(flat: dict[str, object], duration: float, offline: float, stepped: float,
                 streaming: dict[str, object]) -> float:
    """2x how far either path's distance moves when the integration tolerances are 10x looser: a bound on each
    path's own integration error, which adds to what the knots' error moves (:func:`_conditioning`). It matters
    where the answers themselves converge slowly: on a plate (``surface.thickness`` > 0) whose strokes jump in
    velocity (a trapezoid on 4 actuators: offline -9.14154, -9.14227, -9.14299 µm at 1e-11, 1e-12, 1e-13;
    stepped -9.14479, -9.14512, -9.14140 µm), and where a part is still flying at the end (an asymmetric stroke
    on 4 actuators, piezo on: each path moves 2.3-2.4e-10 m from 1e-12 to 1e-13, the knots 4e-10 m, the
    paths differ by 1.03e-9 m). A systematic difference does not hide in it: the resumed-step bug of
    test_split_runs.py gave 3.0e-9 m at every tolerance, and this allowance ~1e-11 m. Found by this test (the
    listed cases below); the slow convergence itself is not fixed."""
    looser = {**flat, 'integration.tolerance': 1e-12, 'integration.event_tolerance': 1e-12}
    return 2.0 * max(abs(_offline(looser, duration)[0] - offline),
                     abs(_stepped(looser, duration, **streaming)[0] - stepped))


def _check_paths(scenario: dict[str, object], drawn: bool = True) -> None:
    """Every path moves the part as ``simulate`` does. A scenario whose transition counts change with a
    change of the strokes as small as the knots' error has no path's answer: a drawn one is rejected
    (hypothesis draws another), a listed one must not be such a scenario."""
    scenario = dict(scenario)
    streaming = {'max_points': scenario.pop('stream.max_points', MAX_POINTS),
                 'window': scenario.pop('stream.window', WINDOW)}
    flat = _settings(scenario)
    duration = _duration(flat)
    offline = _offline(flat, duration)
    stable, allowance = _conditioning(flat, duration, offline)
    if drawn:
        assume(stable)            # counts on a knife's edge are no path's answer
    else:
        assert stable, ('a listed scenario on a knife\'s edge', scenario)
    stepped = _stepped(flat, duration, **streaming)
    assert stepped[1:] == offline[1:], (scenario, offline, stepped)
    if not _same_distance(stepped[0], offline[0], allowance):     # each path's own error adds to the knots'
        allowance += _convergence(flat, duration, offline[0], stepped[0], streaming)
    assert _same_distance(stepped[0], offline[0], allowance), (scenario, offline, stepped, allowance)
    row = sweep(flat, 'stroke.amplitude', [StrokeParams.from_flat(flat).amplitude], duration=duration)[0]
    assert row['error'] == '', (scenario, row)
    assert {k: row[k] for k in offline[1]} == offline[1], (scenario, offline, row)
    assert row['regime'] == regime(offline[1])
    assert row['final_mode'] == offline[2], (scenario, offline, row)
    assert _same_distance(row['final_offset_m'], offline[0]), (scenario, offline, row)


ISSUE_CASES = [   # issue 26: run against simulate, the strokes that differed (and the default)
    {'stroke.waveform': 'sine'},
    {'stroke.waveform': 'sine', 'stroke.count': 3},
    {'stroke.waveform': 'sine', 'stroke.pause': 0.004},
    {'stroke.waveform': 'trapezoid', 'stroke.duty': 0.3, 'stroke.amplitude': 150e-6, 'stroke.count': 2},
    {'stroke.waveform': 'asymmetric', 'stroke.duty': 0.8, 'stroke.frequency': 800.0, 'stroke.count': 4},
    {'stroke.waveform': 'half_sine', 'stroke.count': 3},
    {},
    # streamed in 2 ms windows: a window's first knot is the previous one's last, not the held value with
    # ṡ = 0 (which kinked the stroke at every joint and threw the soak's travelling wave 123 mm)
    {'stroke.count': 20, 'stream.max_points': 40, 'stream.window': 2e-3},
    {'stroke.waveform': 'sine', 'stroke.count': 20, 'stroke.phases': [0.0, 0.25, 0.5, 0.75],
     'surface.centers': [-1.5e-3, -0.5e-3, 0.5e-3, 1.5e-3], 'surface.widths': [1e-3] * 4,
     'stream.max_points': 64, 'stream.window': 1e-3},
]
FOUND_CASES = [   # found by the property below, fixed
    # a knot pair 2 ns apart read as 2.0000000000052 ns (not a breakpoint): a sine's end became a ~1e8 m/s²
    # quintic that threw a part resting on the bump's centre
    {'stroke.waveform': 'sine', 'stroke.count': 3, 'stroke.pause': 0.0, 'stroke.delay': 0.001953125,
     'stroke.duty': 0.5, 'stroke.amplitude': 5.438690040482426e-05, 'stroke.frequency': 200.0,
     'stroke.phases': [0.0], 'surface.centers': [0.0], 'surface.widths': [0.0005],
     'particle.x0': 0.0, 'piezo.enabled': False},
    # an acceleration jump placed 0.4 ns off changed the take-off velocity by Δs̈·δt
    {'stroke.waveform': 'asymmetric', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.875, 'stroke.amplitude': 0.00010487333060535685, 'stroke.frequency': 924.0,
     'stroke.phases': [1.0], 'surface.centers': [0.0], 'surface.widths': [0.0005],
     'particle.x0': 0.0005, 'piezo.enabled': False},
    # the take-off corner 0.01 ns before a streamed window's joint: the rule then kept the jump 0.1 gap from
    # the knots, 0.09 ns early, and the part flew off 2.5e-6 m/s faster (4.4e-9 m at rest)
    {'stroke.waveform': 'asymmetric', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.9, 'stroke.amplitude': 0.0001, 'stroke.frequency': 1499.9960644840098,
     'stroke.phases': [1.0], 'surface.centers': [0.0], 'surface.widths': [0.0005],
     'particle.x0': 0.0005, 'piezo.enabled': False, 'stream.max_points': 16, 'stream.window': 0.000126667},
    # offline missed a 27-µs slip: the stick margin Q_max - |T_req| has a kink (a maximum) where T_req changes
    # sign, a second extremum in the step that hid the dip from the dip search (docs/events.md); 1.8 µm
    {'stroke.waveform': 'asymmetric', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.28210386925299147, 'stroke.amplitude': 8.128422838568671e-05,
     'stroke.frequency': 2058.009929965201, 'stroke.phases': [1.6466573088440318e-93, 8.128422838568671e-05],
     'surface.centers': [-0.0007489773893742689, 0.0007489773893742689],
     'surface.widths': [0.001428445312394646, 0.0013675642198820773], 'particle.x0': 0.0008030048764981639,
     'piezo.enabled': False, 'stream.max_points': 2000, 'stream.window': 0.0018543775707760173},
    # the take-off time moved 0.4 ns with the knots' s̈ error, set by the actuators' relative timing: the
    # amplitude alone (the conditioning before) moved the part 4.5e-10 m, the knots 1.3e-9 m
    {'stroke.waveform': 'raised_cosine', 'stroke.count': 4, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.5709402699386963, 'stroke.amplitude': 8.059211944023799e-05,
     'stroke.frequency': 1744.5343169202931,
     'stroke.phases': [0.3260667272379845, 0.7842018738896972, 0.28451756140561796, 6.103515625e-05],
     'surface.centers': [-0.0010693348822469204, -0.00035644496074897346, 0.00035644496074897346,
                         0.0010693348822469204],
     'surface.widths': [0.0005, 0.0005, 0.0011248498718763565, 0.0005803988644788782],
     'particle.x0': 0.0006151348705953816, 'piezo.enabled': False, 'stream.max_points': 2000,
     'stream.window': 0.0002},
    # at the tolerance the property ran with before (1e-12): the step to a take-off root was not
    # error-controlled, and its last stage, past pull-off, read the Q_max(N) table's steep first segment as a
    # negative friction limit: 6.6e-7 m/s off, 6e-9 m after the flight (docs/dynamics.md §3)
    {'stroke.waveform': 'trapezoid', 'stroke.count': 2, 'stroke.pause': 0.0008325183224088391,
     'stroke.delay': 1e-05, 'stroke.duty': 0.7644245702820783, 'stroke.amplitude': 5.975268972100684e-05,
     'stroke.frequency': 483.7982470704699,
     'stroke.phases': [0.4764935894562107, 0.8675681738371626, 0.13588691802143663, 0.28275593150161243, 0.0],
     'surface.centers': [-0.0009704881465271961, -0.00048524407326359806, 0.0, 0.00048524407326359806,
                         0.0009704881465271961],
     'surface.widths': [0.0008619401964612638, 0.0007707212471302728, 0.0013490772789017161, 0.001,
                        0.0005347751656770557],
     'particle.x0': -4.4629663846022854e-35, 'piezo.enabled': True,
     'integration.tolerance': 1e-12, 'integration.event_tolerance': 1e-12},
    # (at 1e-12 too) a landing 44 ps after a take-off, then another take-off at once, twice: the gap grows as
    # t³ and had rounded to 0 (docs/dynamics.md §1)
    {'stroke.waveform': 'half_sine', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.000638217565220989,
     'stroke.duty': 0.2, 'stroke.amplitude': 7.245456850341623e-05, 'stroke.frequency': 2493.954057311436,
     'stroke.phases': [0.43774300850718995, 0.0], 'surface.centers': [-0.0005487054281496422, 0.0005487054281496422],
     'surface.widths': [0.001015354593822169, 0.0010788864691413944], 'particle.x0': 0.000638217565220989,
     'piezo.enabled': False, 'stream.max_points': 94, 'stream.window': 0.02,
     'integration.tolerance': 1e-12, 'integration.event_tolerance': 1e-12},
    # a take-off where a samples stroke starts, the part landing again 0.96 µs later: offline, whose first
    # step in flight passed the landing, located it 75 ps after the take-off on the step's interpolant
    # (a gap of 1e-20 m against its error), then took off and landed again (docs/dynamics.md §3)
    {'stroke.waveform': 'samples', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0, 'stroke.duty': 0.5,
     'stroke.amplitude': 8.030214426316448e-05, 'stroke.frequency': 1844.0,
     'stroke.phases': [0.0, 0.23343345223076867, 1.0, 0.0],
     'surface.centers': [-0.0012403593861573237, -0.0004134531287191079, 0.0004134531287191079,
                         0.0012403593861573237],
     'surface.widths': [0.0011676552493456412, 0.001441010559542227, 0.0013252422062852997, 0.0005],
     'particle.x0': -0.0015, 'piezo.enabled': False, 'stream.max_points': 2000, 'stream.window': 0.02,
     'stroke.samples': [0.0, 0.0, 0.0, 0.0005, 0.2681199214828744, 0.68359375, 0.521484375, 0.0]},
    # surface.thickness with a trapezoid (velocity jumps): offline and stepped differ by 1.6e-9 m, against 1.2e-9 m
    # from the strokes' conditioning; each path's own answer moves by up to 3.7e-9 m with the tolerance (_convergence)
    {'stroke.waveform': 'trapezoid', 'stroke.count': 3, 'stroke.pause': 0.00390625, 'stroke.delay': 0.0,
     'stroke.duty': 0.454, 'stroke.amplitude': 1e-05, 'stroke.frequency': 2698.734609067851,
     'stroke.phases': [0.0, 4.0314e-08, 0.484375, 0.0664655404193737],
     'surface.centers': [-0.00113535, -0.00037845, 0.00037845, 0.00113535],
     'surface.widths': [0.0005008200042605213, 0.0005000000000000001, 0.0012459380497229586, 0.0005858233869381344],
     'particle.x0': 0.000750093955661381, 'piezo.enabled': False, 'surface.thickness': 6.103515625e-05},
    # surface.thickness, a part at a bump's centre barely unstuck where one stroke ends and another starts: the
    # root search refined the slide margin as dir·ẋ, not dir·Ẋ (the slip relative to the moving material), and
    # found a reversal every 66 ps without end (the run never finished)
    {'stroke.waveform': 'raised_cosine', 'stroke.count': 1, 'stroke.amplitude': 2e-05, 'stroke.frequency': 1006.0,
     'stroke.phases': [0.0, 0.0, 0.0, 1.0, 0.0],
     'surface.centers': [-0.00235082777089654, -0.00117541388544827, 0.0, 0.00117541388544827, 0.00235082777089654],
     'surface.widths': [0.0010629381983843114, 0.0005, 0.0011635503230801908, 0.0008515501806361393,
                        0.0012974073390379136],
     'particle.x0': 0.0, 'piezo.enabled': False, 'surface.thickness': 0.00032915345963627966},
    # surface.thickness, a sine's end 15.8 µs after a reversal: offline's output steps ended a call inside that
    # step, and the resumed step left the slide "fresh", so the jump's reversal of the slip went unseen (the
    # part slid on the wrong way for 56 ns): 3.0e-9 m against stepped, whose 1 ms ticks fell elsewhere
    # (test_split_runs.py)
    {'stroke.waveform': 'sine', 'stroke.count': 4, 'stroke.pause': 0.0, 'stroke.delay': 0.0, 'stroke.duty': 0.5,
     'stroke.amplitude': 1.932453478860765e-05, 'stroke.frequency': 852.0,
     'stroke.phases': [0.3984375, 0.0078125, 0.71875], 'surface.centers': [-0.0004, 0.0, 0.0004],
     'surface.widths': [0.0005140165167146125, 0.0005, 0.001306796362616968],
     'particle.x0': 0.0, 'piezo.enabled': False, 'surface.thickness': 0.0002356499179202825},
    # flying at the end, piezo on, streamed in 16-point windows: the paths differ by 1.03e-9 m, the knots' error
    # moves the part 4e-10 m and each path's own integration error at 1e-13 is ~2.4e-10 m (_convergence)
    {'stroke.waveform': 'asymmetric', 'stroke.count': 2, 'stroke.pause': 0.0, 'stroke.delay': 0.001953125,
     'stroke.duty': 0.765625, 'stroke.amplitude': 0.00013534777236204486, 'stroke.frequency': 1372.0,
     'stroke.phases': [0.9375, 0.0, 0.7578125, 0.88671875],
     'surface.centers': [-0.0006602249275819911, -0.00022007497586066371, 0.00022007497586066371,
                         0.0006602249275819911],
     'surface.widths': [0.0005250102922585999, 0.000673391237972895, 0.001, 0.0012877018804127998],
     'particle.x0': 0.0, 'piezo.enabled': True, 'stream.max_points': 16, 'stream.window': 0.02},
    # a part stuck on a 10 µm plate slid for 2.8 µs inside the first cubic piece of a jerk-limited ramp (48 µs,
    # one step offline): the stick margin had two extrema in the step, which hid the dip; a stuck part on a
    # plate now steps at most a quarter of such a piece (kernel.polynomial_step)
    {'stroke.waveform': 'trapezoid', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.75, 'stroke.amplitude': 0.0001433827908177081, 'stroke.frequency': 649.0,
     'stroke.phases': [0.0], 'surface.centers': [0.0], 'surface.widths': [0.0005],
     'particle.x0': 0.0005756595688528617, 'piezo.enabled': False, 'stream.max_points': 2000,
     'stream.window': 0.02, 'surface.thickness': 1e-05},
    # stepped: at a knot (the ramp's jerk flip) the two commanded pieces gave a stuck part on a plate material
    # velocities 1.35e-11 m/s apart (rounding), read as a velocity jump (tolerance 1e-12): a zero-length slide
    {'stroke.waveform': 'trapezoid', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.859375, 'stroke.amplitude': 2e-05, 'stroke.frequency': 1468.0, 'stroke.phases': [0.0],
     'surface.centers': [0.0], 'surface.widths': [0.001], 'particle.x0': 0.0005666510997854919,
     'piezo.enabled': False, 'stream.max_points': 2000, 'stream.window': 0.02, 'surface.thickness': 1e-05},
    # offline missed a 2.8-µs slip: T_req changed sign twice in one 62-µs stuck step (two kinks of the stick
    # margin, which dipped between them), and the step ended on a later crossing, whose root the search took
    # (docs/events.md): both smooth branches are now searched, and a step ending on an event is retaken short
    {'stroke.waveform': 'raised_cosine', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.5, 'stroke.amplitude': 3.96221490037338e-05, 'stroke.frequency': 2013.0,
     'stroke.phases': [0.265625, 0.0, 0.21484375, 0.0],
     'surface.centers': [-0.0006828416109160792, -0.00022761387030535975, 0.00022761387030535975,
                         0.0006828416109160792],
     'surface.widths': [0.0011116734452532306, 0.001281186218553395, 0.0005782561820317379, 0.001281186218553395],
     'particle.x0': -0.0004940214723650181, 'piezo.enabled': False, 'stream.max_points': 2000,
     'stream.window': 0.02, 'surface.thickness': 0.0},
]


KNIFE_EDGE_CASES = [    # drawn by the property below: no path's answer, rejected by _conditioning
    # the knots took the stick margin below 0 for 3.6 µs at 282 µs (a slip and a stick more on every path
    # the knots drive), the waveform and its amplitude and phase probes did not (2000 examples)
    {'stroke.waveform': 'asymmetric', 'stroke.count': 1, 'stroke.pause': 0.0, 'stroke.delay': 0.0,
     'stroke.duty': 0.4290989585308116, 'stroke.amplitude': 0.0001068234792220016, 'stroke.frequency': 2597.0,
     'stroke.phases': [0.623046875, 1.0, 1.0, 0.5769837327603907, 0.0],
     'surface.centers': [-0.001984797113646534, -0.000992398556823267, 0.0, 0.000992398556823267,
                         0.001984797113646534],
     'surface.widths': [0.0013645647252443168, 0.0005, 0.0005, 0.0011108884148460282, 0.0005],
     'particle.x0': -0.001129030334683652, 'piezo.enabled': False, 'surface.thickness': 4.6282725697181406e-05},
]


@pytest.mark.parametrize('scenario', KNIFE_EDGE_CASES)
def test_a_scenario_on_the_knots_edge_is_rejected(scenario: dict[str, object]) -> None:
    flat = _settings(scenario)
    duration = _duration(flat)
    offline = _offline(flat, duration)
    assert _offline_on_knots(flat, duration)[1:] != offline[1:]
    assert not _conditioning(flat, duration, offline)[0]


@pytest.mark.parametrize('scenario', ISSUE_CASES + FOUND_CASES)
def test_listed_scenarios_move_the_part_the_same_on_every_path(scenario: dict[str, object]) -> None:
    _check_paths(scenario, drawn=False)


HEALTH = [HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much]


@settings(max_examples=FIXED_EXAMPLES, derandomize=True, deadline=None, database=None, suppress_health_check=HEALTH)
@given(scenario=scenarios())
def test_every_path_moves_the_part_the_same(scenario: dict[str, object]) -> None:
    """The property on a fixed seed's 200 scenarios (make test)."""
    _check_paths(scenario)


@pytest.mark.paths
@pytest.mark.timeout(600 + EXAMPLES)     # ~0.1-0.3 s an example on 2 shared cores; the suite's 300 s is for one test
@settings(max_examples=EXAMPLES, deadline=None, database=None, print_blob=True, suppress_health_check=HEALTH)
@given(scenario=scenarios())
def test_every_path_moves_the_part_the_same_on_random_draws(scenario: dict[str, object]) -> None:
    """The property on ``MF_PATH_EXAMPLES`` fresh random scenarios (on demand: ``-m paths``)."""
    _check_paths(scenario)


@st.composite
def track_scenarios(draw: st.DrawFn) -> dict[str, object]:
    """A vibratory track (issue 27): either drive, any waveform, inclination, vibration angle, contact and
    landing law."""
    waveform = draw(st.sampled_from([w for w in WAVEFORMS if w != 'samples']))
    beta = draw(st.floats(0.05, 1.3))
    frequency = draw(st.floats(50.0, 400.0))     # with 5-150 µm: throw numbers ~0.03-90, stick, slide and hop
    two_way = draw(st.booleans())
    drive = {'track.drive': 'two_way', 'surface.centers': [0.0, 0.0], 'surface.widths': [1e-3, 1e-3],
             'stroke.phases': [0.0, draw(st.floats(0.0, 1.0))]} if two_way else {}
    return {
        **drive,
        'surface.kind': 'track', 'track.inclination': draw(st.floats(-0.3, 0.3)), 'track.vibration_angle': beta,
        'contact.model': draw(st.sampled_from(['coulomb', 'ke'])), 'contact.mu': draw(st.floats(0.1, 1.0)),
        'landing.law': draw(st.sampled_from(['keep', 'coulomb', 'stick'])),
        'landing.restitution': draw(st.sampled_from([0.0, draw(st.floats(0.0, 0.8))])),
        'stroke.waveform': waveform, 'stroke.count': draw(st.integers(1, 6)), 'stroke.frequency': frequency,
        'stroke.amplitude': draw(st.floats(5e-6, 150e-6)),
        'stroke.duty': draw(st.floats(0.1, 0.9)), 'stroke.delay': draw(st.sampled_from([0.0, 1e-3])),
        'particle.x0': 0.0,
        **(_harmonics(draw) if waveform == 'harmonics' else {}),
    }


@settings(max_examples=TRACK_EXAMPLES, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(scenario=track_scenarios())
def test_every_path_moves_a_part_on_a_track_the_same(scenario: dict[str, object]) -> None:
    """simulate, the stepped simulator fed the actuator's bytes, and sweep agree on drawn track scenarios."""
    _check_paths(scenario)


PARTS_EXAMPLES = int(os.environ.get('MF_PARTS_PATH_EXAMPLES', '30'))   # in make test (not marked paths)


@st.composite
def parts_scenarios(draw: st.DrawFn) -> dict[str, object]:
    """Several parts (issue 28) on a vibratory track or the bump surface, spaced at random (some touching),
    with initial velocities and a restitution between them."""
    n = draw(st.integers(2, 5))
    size = draw(st.floats(50e-6, 150e-6))
    gaps = [draw(st.sampled_from([0.0, draw(st.floats(0.0, 400e-6))])) for _ in range(n - 1)]
    x0 = [draw(st.floats(-1.0e-3, 0.0))]
    for gap in gaps:
        x0.append(x0[-1] + size + gap)
    parts = {'particle.x0': x0, 'particle.size': size, 'particle.restitution': draw(st.floats(0.0, 1.0)),
             'particle.v0': [draw(st.sampled_from([0.0, draw(st.floats(-0.05, 0.05))])) for _ in range(n)]}
    if draw(st.booleans()):
        return {**draw(track_scenarios()), **parts}
    return {**draw(scenarios()), 'piezo.enabled': False, 'surface.thickness': 0.0, **parts}  # neither with parts


@pytest.mark.timeout(300 + 2 * PARTS_EXAMPLES)    # ~1 s an example on 2 shared cores; 300 s is for one test
@settings(max_examples=PARTS_EXAMPLES, derandomize=True, deadline=None, database=None,
          suppress_health_check=HEALTH)
@given(scenario=parts_scenarios())
def test_every_path_moves_many_parts_the_same(scenario: dict[str, object]) -> None:
    """Several parts: offline (``PartsModel.run``, what ``simulate`` integrates) and the simulator's Stepper in
    ticks fed the actuator's bytes give every part the same transitions and final mode, the same number of
    impacts, and positions within 1e-9 m or 1e-6 relative (or the scenario's own sensitivity, as for one part)."""
    from micro_feeder.physics.parts import PartsModel

    flat = _settings(scenario)
    duration = _duration(flat)

    def outcome(changes: dict[str, object]) -> tuple[np.ndarray, list]:
        state = PartsModel(build_model({**flat, **changes})).run(duration).state
        return state.positions, [state.collisions] + [(p.transitions, p.mode) for p in state.parts]

    positions, counts = outcome({})
    event('impacts: ' + ('none' if counts[0] == 0 else '1-9' if counts[0] < 10 else '10 or more'))
    allowance = np.zeros(positions.size)
    for change in _stroke_changes(flat):                 # as for one part: no path's answer on a knife's edge
        changed_positions, changed_counts = outcome(change)
        assume(changed_counts == counts)
        allowance = np.maximum(allowance, 2.0 * np.abs(changed_positions - positions))
    stepped = _stepped_run(flat, duration).parts_state
    assert [stepped.collisions] + [(p.transitions, p.mode) for p in stepped.parts] == counts, (scenario, counts)
    for i, (x, y) in enumerate(zip(positions, stepped.positions, strict=True)):
        assert _same_distance(x, y, allowance[i]), (scenario, i, x, y, allowance[i])
