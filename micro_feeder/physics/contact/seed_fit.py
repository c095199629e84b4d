"""The seed paper's rational curve fit of separation vs applied load (docs/contact.md §5).

d in nm, applied load x in N; meaningful only for 0 <= x <= ~2e-5 N (the range it was fitted on).
Used to compare the model with the seed (the plot of Fig. 6 and the tests), never for dynamics.
"""

from __future__ import annotations

import numpy as np

NUMERATOR = (69.86, 0.0494, 2.885e-6, 4.249e-11, 1.839e-16)                   # x^4 ... x^0
DENOMINATOR = (1.0, 1.37, 7.569e-4, 4.0314e-8, 5.7e-13, 2.436e-18)           # x^5 ... x^0
VALID_LOAD_RANGE_N = (0.0, 2e-5)


def seed_separation_nm(load_n: np.ndarray) -> np.ndarray:
    """The seed's d(x) in nm at applied load x in N."""
    x = np.asarray(load_n, dtype=float)
    return np.polyval(NUMERATOR, x) / np.polyval(DENOMINATOR, x)
