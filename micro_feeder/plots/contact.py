"""The contact model's curves: load vs separation with pull-off, separation vs load against the seed's fit,
and static friction vs separation (the quantities of the seed's Figs. 4, 6 and 9)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.ticker import FormatStrFormatter

from ..physics.contact import ContactModel
from ..physics.contact.seed_fit import VALID_LOAD_RANGE_N, seed_separation_nm
from .units import scale

NM = 1e9


def plot_contact(model: ContactModel, path: Path | str) -> Path:
    """Write a three-panel PNG: applied load vs d with the pull-off point; separation vs load, model and
    the seed's rational fit; static friction limit and coefficient vs d."""
    sigma = model.contact.sigma
    d_min = model.d_pull_off_m
    d_low = float(model.separation_at_load(min(3.0 * model.pull_off_n + model.weight_n,
                                               0.5 * model.tables.load_n[-1])))
    d = np.linspace(d_low, d_min + 3.0 * sigma, 600)
    curve = model.curve(d)
    d_weight = float(model.separation_at_load(model.weight_n))

    fig, (ax_load, ax_fit, ax_friction) = plt.subplots(1, 3, figsize=(16, 4.8))
    f, unit = scale(np.array([4 * model.pull_off_n]), 'N')
    ax_load.plot(d * NM, curve.applied_load_n * f, label='applied load F = P − F_s')
    ax_load.plot(d * NM, curve.contact_load_n * f, lw=0.8, ls='--', label='contact load P')
    ax_load.plot(d * NM, -curve.adhesion_n * f, lw=0.8, ls=':', label='adhesion −F_s')
    ax_load.plot([d_min * NM], [-model.pull_off_n * f], 'o', color='C3',
                 label=f'pull-off {model.pull_off_n * f:.4g} {unit} at {d_min * NM:.2f} nm')
    ax_load.axhline(0.0, color='k', lw=0.5)
    ax_load.set(xlabel='separation d (nm)', ylabel=f'force ({unit})',
                title='Load on the part vs separation: adhesion pulls, contact pushes',
                ylim=(-3 * model.pull_off_n * f, 4 * model.pull_off_n * f))
    ax_load.legend(fontsize=8)

    loads = np.linspace(*VALID_LOAD_RANGE_N, 200)
    f, unit = scale(loads, 'N')
    ax_fit.plot(loads * f, model.separation_at_load(loads) * NM, label=f'model ({model.contact.preset})')
    ax_fit.plot(loads * f, seed_separation_nm(loads), ls='--', label="seed's rational fit d(x)")
    ax_fit.set(xlabel=f'applied load ({unit})', ylabel='separation d (nm)',
               title='Equilibrium separation vs applied load')
    ax_fit.legend(fontsize=8)

    d_pressed = np.linspace(d_low, float(model.separation_at_load(0.0)), 400)[:-1]
    pressed = model.curve(d_pressed)
    f, unit = scale(pressed.q_max_n, 'N')
    ax_friction.plot(d_pressed * NM, pressed.q_max_n * f, color='C0', label='Q_max')
    ax_friction.axvline(d_weight * NM, color='k', lw=0.5, ls=':', label=f'd at weight ({d_weight * NM:.2f} nm)')
    ax_friction.set(xlabel='separation d (nm)', ylabel=f'max static friction Q_max ({unit})', yscale='log',
                    title='Static friction limit and coefficient vs separation')
    ax_friction.yaxis.set_major_formatter(FormatStrFormatter('%g'))
    ax_friction.yaxis.set_minor_formatter(FormatStrFormatter('%g'))
    ax_mu = ax_friction.twinx()
    ax_mu.plot(d_pressed * NM, pressed.q_max_n / pressed.applied_load_n, color='C1',
               label='mu = Q_max / F (diverges as F -> 0)')
    ax_mu.set(ylabel='friction coefficient mu', yscale='log')
    handles = ax_friction.get_legend_handles_labels()[0] + ax_mu.get_legend_handles_labels()[0]
    ax_friction.legend(handles=handles, fontsize=8)

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
