"""Options shared by the model commands: ``--params FILE`` and ``--set NAME=VALUE``."""

from __future__ import annotations

import argparse
from typing import Any

from ..settings import load_settings


def add_model_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--params`` (repeatable YAML file) and ``--set`` (repeatable NAME=VALUE, read as YAML)."""
    parser.add_argument('--params', metavar='FILE.yaml', action='append', default=[],
                        help='parameters file (plain YAML or a ROS 2 params file such as '
                             'config/feeder.yaml); repeatable, later files win')
    parser.add_argument('--set', metavar='NAME=VALUE', action='append', default=[], dest='overrides',
                        help='override one parameter, value read as YAML '
                             '(e.g. --set contact.beta=0.05 --set surface.centers=[0.0,2e-3]); repeatable')
    parser.add_argument('--force', action='store_true',
                        help='start even when the estimated cost (run time, memory) is beyond the sane limit')


_CHANGED: list[str] = []  # the parameters this command's --params/--set gave (for error messages)


def settings_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The flat parameter mapping the options describe (files first, then overrides), checked for an
    absurd cost before any work starts (:mod:`._cost`; ``--force`` skips what a user could mean)."""
    flat = load_settings(args.params, args.overrides)
    _CHANGED[:] = sorted(flat)
    from ._cost import check_cost
    check_cost(args, flat)
    return flat


def changed_parameters() -> list[str]:
    """The names the last :func:`settings_from_args` read from ``--params``/``--set``."""
    return list(_CHANGED)
