"""``micro-feeder resim LOG``: re-simulate a log's recorded commands and compare the part trajectory."""

from __future__ import annotations

import argparse
import json

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
                        help='exit with status 1 when the largest difference exceeds M metres')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..nodes.parameters import model_specs
    from ..nodes.resim import ResimError, resimulate  # the Stepper: numba kernel, message packages

    model = model_specs()
    overrides = settings_from_args(args)
    for text in args.overrides:
        name = parse_override(text)[0]
        if name not in model:
            raise CommandError(f'--set {name}: not a model parameter (resim changes only the simulated model; '
                               'the feed controller\'s feed.* settings do not apply)')
    # A parameters file may also hold other nodes' settings (config/feeder.yaml: feed.*): only the model's apply.
    overrides = {name: value for name, value in overrides.items() if name in model}
    log = open_log(args.log)
    progress = Progress('resim', 0, 'stops')
    try:
        report = resimulate(log, overrides, progress=progress, max_sim_time=None if args.force else MAX_SIM_TIME)
    except ResimError as err:
        raise CommandError(str(err)) from err
    finally:
        progress.close()
    if args.json:
        print(json.dumps(report.as_dict(), indent=2))
    else:
        print(report.verdict())
        for note in report.notes:
            print(f'  note: {note}')
    report_loss(log)
    if args.tolerance is not None and not report.max_error <= args.tolerance:
        return 1
    return 0
