"""The resim verdict's tolerance wording (cli/resim.py) and the plots' unit choice (plots/units.py)."""

from __future__ import annotations

import numpy as np

from micro_feeder.cli.resim import verdict
from micro_feeder.plots.units import scale
from micro_feeder.sim.resim import ResimReport


def report(max_error: float, explained: float = 0.0, exact: bool = False) -> ResimReport:
    """A report whose difference the stop times' 1-ns rounding explains up to ``explained`` (m)."""
    return ResimReport(log='run', mode='real time', parameters='recorded', overrides={}, poses=2983,
                       sim_time=3.0, max_error=max_error, max_dx=9.8e-16, max_dz=max_error, t_max_error=0.0671,
                       commands_applied=1, commands_rejected=0, exact_stop_times=exact, receipts='recorded',
                       max_unexplained=max_error - explained)


def test_a_difference_within_the_tolerance_matches_and_keeps_the_exact_figure() -> None:
    line = verdict(report(3.6e-14), 1e-10, 'integration.tolerance')
    assert line.startswith('resim: MATCHES within 3.6e-14 m (tolerance 1e-10 m, integration.tolerance): ')
    assert 'largest difference 3.600e-14 m at t = 0.067100 s' in line and '2983 poses' in line


def test_a_difference_beyond_the_tolerance_stays_different_and_zero_stays_identical() -> None:
    assert verdict(report(2e-10), 1e-10, 'x').startswith('resim: DIFFERENT: largest difference 2.000e-10 m')
    assert verdict(report(1e-10), 1e-10, 'x').startswith('resim: MATCHES within 1e-10 m')      # at the bound
    assert verdict(report(0.0), 1e-10, 'x').startswith('resim: IDENTICAL: re-simulated bit for bit')


def test_a_real_time_difference_within_the_rounding_matches_and_says_so() -> None:
    line = verdict(report(1.55e-10, explained=1.6e-10), 1e-10, 'integration.tolerance')
    assert line.startswith('resim: MATCHES within 1.6e-10 m (tolerance 1e-10 m, integration.tolerance, plus the '
                           "part's speed x 1 ns"), line
    assert verdict(report(1.55e-10, explained=0.5e-10), 1e-10, 'x').startswith('resim: DIFFERENT')
    # exact stop times (stepped runs) have no rounding to allow for
    assert verdict(report(1.55e-10, explained=1.6e-10, exact=True), 1e-10, 'x').startswith('resim: DIFFERENT')


def test_units_put_the_largest_magnitude_between_1_and_1000() -> None:
    assert scale(np.array([1.29e-5, -2e-6]), 'm') == (1e6, 'µm')
    assert scale([np.array([8e-8]), np.array([-1.1e-7])], 'N') == (1e9, 'nN')
    assert scale(np.array([0.048]), 'm/s') == (1e3, 'mm/s')
    assert scale(np.array([2.5]), 'm') == (1.0, 'm')
    assert scale(np.array([3e-12]), 'm') == (1e9, 'nm')          # below nano: nano, not a smaller prefix
    assert scale(np.array([0.0, np.nan]), 'N') == (1.0, 'N')
