"""``micro-feeder resim LOG``: re-simulate a log's recorded commands and compare the part trajectory."""

from __future__ import annotations

import argparse
import json
from typing import Any

from ..progress import Progress
from ..settings import parse_override
from . import CommandError
from ._common import add_model_options, settings_from_args
from ._logs import open_log, report_loss

MAX_SIM_TIME = 6 * 3600.0  # s: a longer log is refused without --force (about 18 min of computing)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'resim', help='re-simulate a log\'s commands and compare the part trajectory',
        description='Feed the log\'s recorded actuator commands into a fresh simulation built from the '
                    'parameters the simulator recorded, each at the sim time the simulator received it, and '
                    'report the largest difference between the recorded and the re-simulated part position '
                    '(x, z) over every recorded particle/pose. A stepped-mode recording re-simulates bit for '
                    'bit (difference 0); a real-time one may differ very slightly, and the output says why. '
                    '--params/--set change model parameters on top of the recorded ones (what-if runs).')
    parser.add_argument('log', metavar='LOG', help='log directory or .mcap file')
    add_model_options(parser)
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    parser.add_argument('--tolerance', type=float, metavar='M',
                        help='exit with status 1 when the largest difference exceeds M metres (in a real-time '
                             'log, beyond the part\'s speed x 1 ns, its stop times\' rounding); the verdict says '
                             '"MATCHES within" a difference up to M (default M for the verdict: the run\'s '
                             'integration.tolerance, the position error its integrator allows per step)')
    parser.set_defaults(func=run)


def _tolerance(given: float | None, log: Any, overrides: dict[str, Any]) -> tuple[float, str]:
    """The difference (m) below which the verdict says the runs match, and where it comes from: ``--tolerance``,
    else the run's ``integration.tolerance``. Why that one: the integrator is allowed that position error per
    step, and a real-time log knows its stop and command times to 1 ns only, so the re-simulation evaluates
    poses and starts a command up to 1 ns off; differences below the error each step may make are numerical
    noise, not physics."""
    if given is not None:
        return given, '--tolerance'
    from ..logs.sim_parameters import recorded_parameters
    from ..physics.dynamics.params import IntegrationParams
    recorded = recorded_parameters(log)
    name = 'integration.tolerance'
    value = overrides.get(name, recorded[0].get(name) if recorded else None)
    if value is None:
        value = IntegrationParams().tolerance
    return float(value), f'{name}: the position error the integrator allows per step'


def matches(report: Any, tolerance: float) -> bool:
    """Whether the runs agree within ``tolerance`` (m): every pose, or in a real-time log (stop times known
    to 1 ns) every pose beyond what its stop time's rounding moves the part (speed × 1 ns)."""
    return report.max_error <= tolerance or (not report.exact_stop_times and report.max_unexplained <= tolerance)


def verdict(report: Any, tolerance: float, source: str) -> str:
    """The report's verdict, with "MATCHES within X (tolerance Y ...)" for a difference within the tolerance
    (the exact figures kept)."""
    line = report.verdict()
    if report.identical or not matches(report, tolerance):
        return line
    detail = line.split(': ', 2)[2]     # after 'resim: DIFFERENT: '
    rounding = '' if report.max_error <= tolerance else \
        ', plus the part\'s speed x 1 ns: the real-time stop times are known to 1 ns'
    return f'resim: MATCHES within {report.max_error:.2g} m (tolerance {tolerance:g} m, {source}{rounding}): {detail}'


def run(args: argparse.Namespace) -> int:
    from ..settings import model_specs
    from ..sim.resim import ResimError, resimulate  # the Stepper: numba kernel, message packages

    model = model_specs()
    overrides = settings_from_args(args)
    for text in args.overrides:
        name = parse_override(text)[0]
        if name not in model:
            raise CommandError(f'--set {name}: not a model parameter (resim changes only the simulated model; '
                               'the feed controller\'s feed.* settings do not apply)')
    # A parameters file may also hold other nodes' settings (config/feeder.yaml: feed.*): only the model's apply.
    overrides = {name: value for name, value in overrides.items() if name in model}
    log = open_log(args.log, 'resim')
    progress = Progress('resim', 0, 'stops')
    try:
        report = resimulate(log, overrides, progress=progress, max_sim_time=None if args.force else MAX_SIM_TIME)
    except ResimError as err:
        raise CommandError(str(err)) from err
    finally:
        progress.close()
    tolerance, source = _tolerance(args.tolerance, log, overrides)
    if args.json:
        print(json.dumps({**report.as_dict(), 'tolerance': tolerance, 'tolerance_source': source,
                          'matches': matches(report, tolerance)}, indent=2))
    else:
        print(verdict(report, tolerance, source))
        for note in report.notes:
            print(f'  note: {note}')
    report_loss(log)
    if args.tolerance is not None and not matches(report, args.tolerance):
        return 1
    return 0
