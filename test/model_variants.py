"""Model variants that exercise every term of the margins: the kernel-level tests check their formulas on each."""

from __future__ import annotations

from collections.abc import Callable

from micro_feeder.physics.dynamics import FeederModel


def three_actuators() -> FeederModel:
    """Three overlapping bumps of different widths, strokes a quarter period apart."""
    model = FeederModel()
    return model.replace(surface=model.surface.replace(centers=(-1e-3, 0.0, 1e-3), widths=(1e-3, 8e-4, 1.2e-3)),
                         stroke=model.stroke.replace(phases=(0.0, 0.25, 0.5), amplitude=150e-6))


MARGIN_MODELS: dict[str, Callable[[], FeederModel]] = {
    'default': FeederModel,
    'no convective terms': lambda: FeederModel().replace(
        integration=FeederModel().integration.replace(convective_terms=False)),
    'weight outside N': lambda: FeederModel().replace(detach=FeederModel().detach.replace(include_weight=False)),
    'three actuators': three_actuators,
}
