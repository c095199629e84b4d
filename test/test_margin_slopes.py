"""The margins' closed-form time derivatives (``margin_slopes``, used by the dip search) against central
differences of the margins themselves: ``evaluate`` at t ± ε on the state moved by ± ε·ẏ (an independent
evaluation: its error is O(ε²), the state's curvature cancelling between the two sides)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from model_variants import MARGIN_MODELS

from micro_feeder.physics.dynamics import FeederModel
from micro_feeder.physics.dynamics import kernel as k
from micro_feeder.physics.dynamics.layout import N_AUX, SLIDING, STUCK
from micro_feeder.physics.dynamics.rhs import evaluate, margin_slopes
from micro_feeder.physics.waveforms import StrokeParams, waveform_table

EPS = 1e-9          # s


def _base_shaken() -> FeederModel:
    model = FeederModel()
    base = waveform_table(StrokeParams(waveform='sine', amplitude=1e-6, frequency=800.0, count=5), 1)
    return model.replace(base_acceleration=base)


MODELS = {**MARGIN_MODELS, 'base acceleration': _base_shaken}


def _margins(model: FeederModel, mode: int, direction: int, t: float, y: np.ndarray) -> tuple:
    """(margins, ẏ, slopes) at (t, y) through the kernel's own functions."""
    kernel_model = model._kernel_model
    src = model._source_table(None).as_tuple()
    cur = np.zeros((src[0].size, 2), dtype=np.int64)
    k.locate_all(src, t, cur)
    st, aux, dy = np.zeros((4, src[0].size)), np.zeros(N_AUX), np.zeros(y.size)
    margins = evaluate(mode, direction, t, y, kernel_model, src, cur, st, aux, dy)
    return np.array(margins), dy, np.array(margin_slopes(mode, direction, y, dy, kernel_model, st, aux))


@pytest.mark.parametrize('name', MODELS)
@pytest.mark.parametrize('mode, direction, speed', [(STUCK, 0, 0.0), (SLIDING, 1, 0.02), (SLIDING, -1, -0.03)])
def test_margin_slopes_equal_central_differences(name: str, mode: int, direction: int, speed: float) -> None:
    model = MODELS[name]()
    model = model.replace(stroke=model.stroke.replace(count=5))          # strokes all through the times below
    checked = 0
    for t in np.linspace(1.3e-4, 3.9e-3, 23):
        for x in (model.particle.x0, model.particle.x0 + 3e-4, -2e-4):
            y = np.zeros(model.initial_state().y.size)
            y[0], y[1] = x, speed
            _, dy, slopes = _margins(model, mode, direction, t, y)
            ahead, _, _ = _margins(model, mode, direction, t + EPS, y + EPS * dy)
            behind, _, _ = _margins(model, mode, direction, t - EPS, y - EPS * dy)
            differences = (ahead - behind) / (2 * EPS)
            scale = np.abs(differences).max() + np.abs(slopes).max()
            if not math.isfinite(scale) or scale == 0.0:
                continue
            # the Q_max(N) table is piecewise linear: a kink between t - ε and t + ε blurs the difference
            kinked = mode == STUCK and abs(slopes[0] - differences[0]) > 1e-4 * scale
            np.testing.assert_allclose(slopes[1], differences[1], rtol=1e-5, atol=1e-7 * scale)
            if not kinked:
                np.testing.assert_allclose(slopes[0], differences[0], rtol=1e-5, atol=1e-7 * scale)
                checked += 1
    assert checked > 40
