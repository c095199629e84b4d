"""The static friction limit Q_max(N) of the contact model the simulator ran with (its recorded
``simulator/parameters``), for showing friction against ±Q_max where only the wrench was published. No rclpy.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np


def static_limit(params: Mapping[str, Any]) -> Callable[[np.ndarray], np.ndarray]:
    """Q_max (N) at normal loads N (N) for the contact and part parameters in ``params`` (flat names, the
    defaults for any missing), NaN where the model has no equilibrium (at or below the pull-off load, above its
    table). Builds the contact tables: tens of milliseconds."""
    from ..physics.contact.model import ContactModel
    from ..physics.contact.params import ContactParams
    from ..physics.particle import ParticleParams
    contact = ContactParams.from_flat(params)
    if contact.model == 'coulomb':
        return lambda normal_n: contact.mu * np.maximum(np.asarray(normal_n, dtype=float), 0.0)
    model = ContactModel(contact, ParticleParams.from_flat(params))
    top = model.tables.load_n[-1]

    def q_max(normal_n: np.ndarray) -> np.ndarray:
        normal = np.asarray(normal_n, dtype=float)
        q = np.full(normal.shape, np.nan)
        ok = np.isfinite(normal) & (normal > -model.pull_off_n) & (normal <= top)
        q[ok] = model.q_max_at_load(normal[ok])
        return q
    return q_max
