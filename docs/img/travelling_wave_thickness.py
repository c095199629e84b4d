"""Draw docs/img/travelling_wave_thickness.png: how far one stroke of the travelling wave
(config/travelling_wave.yaml: five actuators 0.5 mm apart fired 0.2 of a period apart, 150 µm at 1 kHz) moves
a part, against the plate's thickness (surface.thickness), for parts starting anywhere between the middle
actuators.

Run: .venv/bin/python docs/img/travelling_wave_thickness.py [OUT.png]   (also part of make figures)

Each point is one ``micro-feeder sweep`` row (the same evaluation): one stroke from rest, the distance once the
part is stuck again. Thickness 0 is the seed's surface, whose points move vertically only.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt

from micro_feeder.explore.evaluate import Job, evaluate
from micro_feeder.settings import load_settings

ROOT = Path(__file__).resolve().parents[2]
THICKNESS_M = np.linspace(0.0, 1.5e-3, 16)
START_M = np.linspace(0.6e-3, 1.4e-3, 9)


def main(out: Path) -> None:
    base = load_settings([str(ROOT / 'config' / 'travelling_wave.yaml')])
    job = Job({**base, 'stroke.count': 1})
    per_stroke = np.array([[evaluate(job, {'surface.thickness': t, 'particle.x0': x0})['distance_m']
                            for x0 in START_M] for t in THICKNESS_M]) * 1e6
    fig, ax = plt.subplots(figsize=(7.5, 4.5), layout='constrained')
    for k in range(START_M.size):
        ax.plot(THICKNESS_M * 1e3, per_stroke[:, k], '-', color='0.75', lw=0.8,
                label='one start position each (0.6 to 1.4 mm)' if k == 0 else None)
    ax.plot(THICKNESS_M * 1e3, np.nanmedian(per_stroke, axis=1), 'o-', color='#1b9e77', label='median over starts')
    ax.set_ylim(bottom=0.0)
    ax.set_xlabel('plate thickness t (mm)')
    ax.set_ylabel('distance in one stroke (µm)')
    ax.set_title('Travelling wave, one stroke: the plate\'s surface points also move along x', fontsize=11)
    ax.legend(loc='best', fontsize=8)
    fig.savefig(out, dpi=120)
    print(f'wrote {out}')
    print('thickness_mm median_um min_um max_um')
    for t, row in zip(THICKNESS_M, per_stroke, strict=True):
        print(f'{t * 1e3:.1f} {np.nanmedian(row):.3g} {np.nanmin(row):.3g} {np.nanmax(row):.3g}')


if __name__ == '__main__':
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_suffix('.png'))
