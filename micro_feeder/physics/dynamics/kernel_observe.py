"""Every part's outputs in one compiled call (the simulator publishes 16 parts' outputs each 1 ms tick, where
a Python call of :func:`.kernel.observe` per part cost ~10 µs a part). A module of its own so that the
kernel's compiled code stays as it was cached."""

from __future__ import annotations

import numpy as np

from .._jit import jit
from .kernel import observe
from .layout import KernelModel


@jit
def observe_parts(t: float, ys: np.ndarray, ivs: np.ndarray, model: KernelModel, src: tuple, cur: np.ndarray,
                  st: np.ndarray, aux: np.ndarray, dy: np.ndarray, rows: np.ndarray,
                  stroke_velocities: np.ndarray) -> None:
    """:func:`.kernel.observe` of each row of ``ys`` / ``ivs`` (parts, ...) at ``t`` into the rows of ``rows``
    (parts, columns), and each one's stroke rates ṡ per actuator (m/s) into ``stroke_velocities`` (parts,
    actuators): the very numbers a call per part gives."""
    for p in range(ys.shape[0]):
        observe(t, ys[p], ivs[p], model, src, cur, st, aux, dy, rows[p])
        for c in range(stroke_velocities.shape[1]):
            stroke_velocities[p, c] = st[1, c]
