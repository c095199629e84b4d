"""``micro-feeder contact``: the rough-surface contact model's headline numbers, curve and plot."""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from ..physics.contact import ContactModel, ContactParams
from ..physics.contact.summary import DMT_TABOR_LIMIT, headline
from ..physics.particle import ParticleParams
from ..settings import build_group
from . import CommandError
from ._common import add_model_options, settings_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        'contact', help='contact model: separation, friction and pull-off at the part weight',
        description='Evaluate the Kogut-Etsion rough-surface contact model (adhesion + static friction) '
                    'for the part on the feeder surface and print its headline numbers.',
        epilog='Examples: micro-feeder contact --set contact.preset=ke_literature; '
               'micro-feeder contact --json --d-nm 70,75,80; micro-feeder contact --plot out/contact.png')
    add_model_options(parser)
    parser.add_argument('--json', action='store_true', help='print one JSON object and nothing else')
    parser.add_argument('--d-nm', metavar='D1,D2,...', type=_separations_nm,
                        help='also evaluate the forces at these separations (nm), in the given order')
    parser.add_argument('--plot', metavar='FILE.png', help="write the seed's Figs. 4, 6 and 9 for this model")
    parser.set_defaults(func=run)


def _separations_nm(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(',') if v.strip()]
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'expected comma-separated numbers in nm, got {text!r}') from err
    if not values or not all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f'expected finite separations in nm, got {text!r}')
    return values


def run(args: argparse.Namespace) -> int:
    flat = settings_from_args(args)
    model = ContactModel(build_group(ContactParams, flat), build_group(ParticleParams, flat))
    numbers = headline(model)
    if args.d_nm:
        curve = model.curve(np.asarray(args.d_nm) * 1e-9)
        numbers['curve'] = [
            {'d_m': float(d), 'contact_load_n': float(p), 'adhesion_n': float(s), 'applied_load_n': float(f),
             'q_max_n': float(q)}
            for d, p, s, f, q in zip(curve.separation_m, curve.contact_load_n, curve.adhesion_n,
                                     curve.applied_load_n, curve.q_max_n, strict=True)]
    if args.plot:
        from ..plots.contact import plot_contact
        try:
            written = plot_contact(model, args.plot)
        except OSError as err:
            raise CommandError(f'cannot write the plot {args.plot}: {err.strerror}') from err
    if args.json:
        json.dump(numbers, sys.stdout)
        print()
        return 0
    print(format_headline(numbers))
    if args.plot:
        print(f'\nplot written to {written}')
    return 0


def format_headline(n: dict) -> str:
    """The human table of ``micro-feeder contact``."""
    rows = [
        ('preset', n['preset'], ''),
        ('part weight W', f"{n['weight_n']:.5g}", 'N'),
        ('separation d at W', f"{n['d_weight_m'] * 1e9:.4f}", 'nm'),
        ('contact load P at d(W)', f"{n['contact_load_weight_n']:.6g}", 'N'),
        ('adhesion F_s at d(W)', f"{n['adhesion_weight_n']:.6g}", 'N'),
        ('max static friction Q_max at W', f"{n['q_max_weight_n']:.6g}", 'N'),
        ('sliding threshold Q_max/m (flat)', f"{n['sliding_accel_mps2']:.4g}", 'm/s^2'),
        ('friction coefficient mu = Q_max/W', f"{n['mu_weight']:.4g}", ''),
        ('pull-off force F_po', f"{n['pull_off_n']:.6g}", 'N'),
        ('separation at pull-off d_min', f"{n['d_pull_off_m'] * 1e9:.3f}", 'nm'),
        ('critical interference omega_c', f"{n['critical_interference_m'] * 1e9:.3f}", 'nm'),
        ('implied summit radius R', f"{n['asperity_radius_m'] * 1e6:.2f}", 'um'),
        ('implied summit density eta', f"{n['asperity_density_per_m2']:.4g}", '1/m^2'),
        ('summits in the nominal area', f"{n['asperity_count']:.0f}", ''),
        ('Tabor parameter', f"{n['tabor_parameter']:.3g}", ''),
    ]
    width = max(len(r[0]) for r in rows)
    lines = [f'{label:<{width}}  {value:>12}  {unit}'.rstrip() for label, value, unit in rows]
    if not n['dmt_valid']:
        lines.append(f"warning: Tabor parameter {n['tabor_parameter']:.3g} >= {DMT_TABOR_LIMIT}: the DMT-type "
                     'adhesion of the KE model assumes a stiff contact; these inputs are in the DMT-JKR '
                     'transition, treat adhesion numbers as estimates')
    if 'curve' in n:
        lines.append('')
        lines.append(f"{'d (nm)':>10} {'P (N)':>13} {'F_s (N)':>13} {'F (N)':>13} {'Q_max (N)':>13}")
        for row in n['curve']:
            lines.append(f"{row['d_m'] * 1e9:>10.3f} {row['contact_load_n']:>13.5g} {row['adhesion_n']:>13.5g} "
                         f"{row['applied_load_n']:>13.5g} {row['q_max_n']:>13.5g}")
    return '\n'.join(lines)
