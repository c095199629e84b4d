"""Coulomb contact: Q_max = μ·max(N, 0), no adhesion (``contact.model`` 'coulomb'; docs/tracks.md).

The classical law of vibratory-conveying theory (Boothroyd, Sloot & Kruyt), for parts large enough that
adhesion does not matter. It honours the contact-law contract the dynamics read (:class:`ContactLaw` in
:mod:`.law`): load-indexed tables of the largest static friction and the separation, the pull-off force
(0 here: the part leaves the surface as soon as the normal load would pull) and the attraction in
flight (none).
"""

from __future__ import annotations

import numpy as np

from .model import ContactTables

TABLE_LOAD_N = 1.0     # N: the table's last load; beyond it Q_max is extrapolated linearly (exact: μ N)


class CoulombContact:
    """Q_max(N) = μ max(N, 0), separation 0, no pull-off force, no attraction in flight."""

    def __init__(self, mu: float):
        self.mu = float(mu)
        self.pull_off_n = 0.0
        load = np.array([-TABLE_LOAD_N, 0.0, TABLE_LOAD_N])
        self.tables = ContactTables(
            load_n=load, q_max_n=self.mu * np.maximum(load, 0.0), separation_m=np.zeros(3),
            gap_m=np.array([0.0, 1.0]), attraction_n=np.zeros(2), pull_off_n=0.0, d_pull_off_m=0.0)

    def q_max(self, load_n: float) -> float:
        """Largest static friction (N) at normal load ``load_n`` (N)."""
        return self.mu * max(load_n, 0.0)
