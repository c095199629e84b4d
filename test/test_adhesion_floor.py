"""The adhesion margin's floor over a step (``adhesion_floor``: the dip search skips a step whose floor is above
zero) against the margin itself, evaluated at 201 points of the step's interpolant, as the search sees it;
and tight where the bound is exact: a part stuck at the bump centre while the stroke accelerates down hardest."""

from __future__ import annotations

import math

import numpy as np
import pytest
from model_variants import MARGIN_MODELS

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.dynamics import kernel as k
from micro_feeder.physics.dynamics.events import adhesion_floor, margins_at
from micro_feeder.physics.dynamics.layout import N_AUX, N_SCRATCH, SLIDING, STUCK
from micro_feeder.physics.dynamics.rhs import evaluate
from micro_feeder.physics.dynamics.steppers import dopri5_step

MODELS = {
    **MARGIN_MODELS,
    'take-off strokes (2 kHz)': lambda: FeederModel().replace(stroke=FeederModel().stroke.replace(frequency=2000.0)),
}


def floor_and_lowest(model: FeederModel, mode: int, direction: int, t: float, h: float, x: float, v: float,
                     dense: bool) -> tuple[float, float]:
    """(adhesion_floor, the adhesion margin's lowest value at 201 points of the step's interpolant) for a
    step from (x, v) at t: DOPRI5 with its own interpolant (``dense``), else an Euler step with the cubic
    Hermite interpolant. The step ends before the strokes' next breakpoint, as the kernel's steps do."""
    kernel_model = model._kernel_model
    src = model._source_table(None).as_tuple()
    cur = np.zeros((src[0].size, 2), dtype=np.int64)
    h = min(h, k.locate_all(src, t, cur) - t)
    n = model.initial_state().y.size
    st, aux, work = np.zeros((4, src[0].size)), np.zeros(N_AUX), np.zeros((N_SCRATCH, n))
    y0, f0, y1, f1 = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    y0[0], y0[1] = x, v
    evaluate(mode, direction, t, y0, kernel_model, src, cur, st, aux, f0)
    if dense:
        dopri5_step(mode, direction, t, y0, f0, h, kernel_model, src, cur, st, aux, work, y1)
    else:
        y1[:] = y0 + h * f0
    evaluate(mode, direction, t + h, y1, kernel_model, src, cur, st, aux, f1)
    floor = adhesion_floor(mode, t, h, y0, f0, y1, f1, work, dense, kernel_model, src, cur)
    lowest = min(margins_at(theta, mode, direction, t, h, y0, f0, y1, f1, kernel_model, src, cur, st, aux, work,
                            dense)[1] for theta in np.linspace(0.0, 1.0, 201))
    return floor, lowest


@pytest.mark.parametrize('name', MODELS)
@pytest.mark.parametrize('mode, direction, speed', [(STUCK, 0, 0.0), (SLIDING, 1, 0.02), (SLIDING, -1, -0.5)])
def test_the_floor_is_below_the_margin_on_every_step(name: str, mode: int, direction: int, speed: float) -> None:
    model = MODELS[name]()
    model = model.replace(stroke=model.stroke.replace(count=5))
    pull_off = model.contact_model.pull_off_n
    skipped = 0
    for t in np.linspace(1.3e-4, 2.4e-3, 13):
        for x in (model.particle.x0, 0.0, -2e-4):
            for h, dense in ((2e-5, False), (1e-4, False), (1e-4, True)):
                floor, lowest = floor_and_lowest(model, mode, direction, t, h, x, speed, dense)
                assert floor <= lowest + 1e-12 * pull_off, (t, x, h, dense)
                skipped += floor > 0.0
    # the bound proves something (steps whose search it saves), except where the strokes' downward
    # acceleration A/2 (2πf)² alone exceeds g + F_po/m: it bounds s̈ by the amplitude, whatever the phase
    assert (skipped > 0) == (name != 'take-off strokes (2 kHz)')


@pytest.mark.parametrize('relative', [0.8, 0.999, 1.001, 1.2])
def test_the_floor_is_the_margin_at_the_bump_centre_when_the_stroke_accelerates_down_hardest(
        relative: float) -> None:
    """At the bump centre (h_x = 0, L = 1) the margin of a stuck part is m (g + s̈) + F_po: at the raised
    cosine's middle s̈ = −A/2 (2πf)², the bound's own value. Around f* = √((g + F_po/m) / (A/2)) / 2π the
    floor crosses 0 with the margin (a bound that dropped ω², or a stroke's trigonometric amplitude,
    would not)."""
    probe = FeederModel.from_settings({'particle.x0': 0.0})
    lift = probe.particle.gravity + probe.contact_model.pull_off_n / probe.particle.mass
    frequency = relative * math.sqrt(lift / (probe.stroke.amplitude / 2)) / (2 * math.pi)
    model = FeederModel.from_settings({'particle.x0': 0.0, 'stroke.count': 1, 'stroke.frequency': frequency})
    middle, h = 0.5 / frequency, 1e-8
    floor, lowest = floor_and_lowest(model, STUCK, 0, middle - h / 2, h, 0.0, 0.0, False)
    scale = model.contact_model.pull_off_n
    assert abs(floor - lowest) <= 1e-6 * scale
    assert (floor > 0.0) == (relative < 1.0)
