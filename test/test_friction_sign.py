"""The stuck step's proof that T_req keeps its sign (``required_friction_keeps_sign``: the dip search then
searches the stick margin as one smooth branch and does not retake a step that ends on its event) against
T_req itself at 201 points of the step; and the stroke ranges it rests on (``channel_ranges``) against each
stroke sampled densely, for every waveform, tight where a stroke is one sinusoid; the lower bound of the stick
margin's branches that lets the dip search skip one (``stick_branch_floor``) against the branches themselves."""

from __future__ import annotations

import numpy as np
import pytest
from model_variants import MARGIN_MODELS

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.dynamics import kernel as k
from micro_feeder.physics.dynamics.events import required_friction_keeps_sign, stick_branch_floor, stuck_ranges
from micro_feeder.physics.dynamics.layout import AUX_LOAD_INDEX, AUX_QMAX, AUX_T_REQ, N_AUX, STUCK
from micro_feeder.physics.dynamics.rhs import evaluate
from micro_feeder.physics.waveforms import WAVEFORMS, channel_ranges, channel_value


def stroke_model(waveform: str, **stroke: object) -> FeederModel:
    model = FeederModel()
    return model.replace(stroke=model.stroke.replace(waveform=waveform, count=3, pause=2e-4, delay=1e-4,
                                                     **stroke))


def sampled_range(src: tuple, channel: int, j: int, i: int, t0: float, t1: float, order: int) -> tuple[float, float]:
    values = [channel_value(src, channel, j, i, t)[order] for t in np.linspace(t0, t1, 401)]
    return min(values), max(values)


@pytest.mark.parametrize('waveform', WAVEFORMS)
@pytest.mark.parametrize('order', [0, 2])
def test_the_stroke_range_holds_every_value_of_the_window(waveform: str, order: int) -> None:
    model = stroke_model(waveform, duty=0.3)
    src = model._source_table(None).as_tuple()
    cur = np.zeros((src[0].size, 2), dtype=np.int64)
    scale = 0.0
    for t in np.linspace(0.0, 3.5e-3, 71):
        end = k.locate_all(src, t, cur)
        for h in (1e-6, 3e-5, 1e-4, 6e-4):
            t1 = min(t + h, end)
            lo, hi = channel_ranges(src, 0, cur[0, 0], cur[0, 1], t, t1)[order:order + 2]
            low, high = sampled_range(src, 0, cur[0, 0], cur[0, 1], t, t1, order)
            scale = max(scale, abs(low), abs(high))
            assert lo <= low + 1e-12 * max(scale, 1e-30) and hi >= high - 1e-12 * max(scale, 1e-30), (t, h)


@pytest.mark.parametrize('order', [0, 2])
def test_the_range_of_one_sinusoid_is_its_exact_range(order: int) -> None:
    """A raised cosine is one sinusoid about a constant: its range over any window is exact (to what 401
    samples resolve), where a bound by amplitudes would be ±A/2 (ω²) whatever the window."""
    model = stroke_model('raised_cosine')
    src = model._source_table(None).as_tuple()
    cur = np.zeros((src[0].size, 2), dtype=np.int64)
    scale = model.stroke.amplitude * (1.0 if order == 0 else (2 * np.pi * model.stroke.frequency) ** 2)
    for t in np.linspace(1.0e-4, 1.0e-3, 37):
        end = k.locate_all(src, t, cur)
        t1 = min(t + 1e-4, end)
        lo, hi = channel_ranges(src, 0, cur[0, 0], cur[0, 1], t, t1)[order:order + 2]
        low, high = sampled_range(src, 0, cur[0, 0], cur[0, 1], t, t1, order)
        assert lo == pytest.approx(low, abs=1e-4 * scale) and hi == pytest.approx(high, abs=1e-4 * scale)


def held_step(model: FeederModel, t: float, h: float, x: float) -> tuple:
    """(kernel model, src, cur, the step's length cut at the strokes' next breakpoint as the kernel's steps
    are, the state of a part held at rest at x, st, aux, a derivative buffer)."""
    kernel_model = model._kernel_model
    src = model._source_table(None).as_tuple()
    cur = np.zeros((src[0].size, 2), dtype=np.int64)
    h = min(h, k.locate_all(src, t, cur) - t)
    n = model.initial_state().y.size
    y = np.zeros(n)
    y[0] = x
    return kernel_model, src, cur, h, y, np.zeros((4, src[0].size)), np.zeros(N_AUX), np.zeros(n)


def required_friction(model: FeederModel, t: float, h: float, x: float) -> tuple[bool, np.ndarray]:
    """(the proof's answer, T_req at 201 points) for a part held at rest at x over [t, t + h]."""
    kernel_model, src, cur, h, y, st, aux, f = held_step(model, t, h, x)
    kept = required_friction_keeps_sign(t, h, y, kernel_model, src, cur)
    values = []
    for tau in np.linspace(t, t + h, 201):
        evaluate(STUCK, 0, tau, y, kernel_model, src, cur, st, aux, f)
        values.append(aux[AUX_T_REQ])
    return kept, np.array(values)


MODELS = {
    **MARGIN_MODELS,
    'sine strokes': lambda: stroke_model('sine'),
    'trapezoid strokes': lambda: stroke_model('trapezoid', duty=0.3),
    'harmonics': lambda: stroke_model('harmonics'),
}


def three_strokes(name: str) -> tuple[FeederModel, list[tuple[float, float, float]]]:
    """The model ``name`` with 3 strokes, and the steps (t, h, x) of a held part the tests look at."""
    model = MODELS[name]()
    steps = [(t, h, x) for t in np.linspace(0.0, 3.2e-3, 41) for x in (model.particle.x0, 0.0, -3e-4, 1.2e-3)
             for h in (2e-5, 1e-4)]
    return model.replace(stroke=model.stroke.replace(count=3)), steps


@pytest.mark.parametrize('name', MODELS)
def test_required_friction_keeps_its_sign_wherever_the_proof_says_so(name: str) -> None:
    model, steps = three_strokes(name)
    proved = refused = 0
    for t, h, x in steps:
        kept, values = required_friction(model, t, h, x)
        scale = max(np.max(np.abs(values)), 1e-300)
        if kept:
            assert np.all(values >= -1e-9 * scale) or np.all(values <= 1e-9 * scale), (t, x, h)
            proved += 1
        elif np.any(values > 1e-6 * scale) and np.any(values < -1e-6 * scale):
            refused += 1
    # the proof saves searches (most steps of a held part), and T_req does change sign in some steps
    assert proved > 0 and refused > 0


def stick_branches(model: FeederModel, t: float, h: float, x: float) -> tuple[tuple | None, np.ndarray]:
    """(the stuck step's ranges or None where not derived, Q_max − b·T_req for b = +1, −1 at 201 points)."""
    kernel_model, src, cur, h, y, st, aux, f = held_step(model, t, h, x)
    derived, *ranges = stuck_ranges(t, h, y, kernel_model, src, cur)
    values = []
    for tau in np.linspace(t, t + h, 201):
        evaluate(STUCK, 0, tau, y, kernel_model, src, cur, st, aux, f)
        values.append([aux[AUX_QMAX] - aux[AUX_T_REQ], aux[AUX_QMAX] + aux[AUX_T_REQ]])
    return (tuple(ranges) if derived else None), np.array(values)


@pytest.mark.parametrize('name', MODELS)
def test_the_stick_branch_floor_is_below_the_branch_everywhere_in_the_step(name: str) -> None:
    """``stick_branch_floor``, the bound that lets the dip search skip a branch of the stick margin, against
    the branch Q_max ∓ T_req itself at 201 points of the step (where the ranges are derived); and it does
    prove some branches clear of their event, or it would save nothing."""
    model, steps = three_strokes(name)
    derived = cleared = 0
    for t, h, x in steps:
        ranges, values = stick_branches(model, t, h, x)
        if ranges is None:
            continue
        derived += 1
        for column, branch in enumerate((1.0, -1.0)):
            lowest = values[:, column].min()
            floors = set()
            for hint in (0.0, 1e9):         # the table walk starts at either end (the last load's interval)
                aux = np.zeros(N_AUX)
                aux[AUX_LOAD_INDEX] = hint
                floors.add(stick_branch_floor(branch, *ranges, model._kernel_model, aux))
            floor, = floors
            assert floor <= lowest, (t, x, h, branch, floor, lowest)
            cleared += floor > 0.0
    if derived:
        assert cleared > 0
