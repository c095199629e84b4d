"""Draw docs/img/track_landing_laws.png: the mean conveying velocity of a part on a horizontal vibratory track
against the throw number Γ, for the three landing laws, with the closed form of sticking landings.

Run: .venv/bin/python docs/img/track_landing_laws.py [OUT.png]   (also part of make figures)

Each point is one ``micro-feeder sweep`` row (the same evaluation: a sine of 100 Hz along β = 30°, Coulomb
friction μ = 0.5, 60 strokes, the velocity over the second half); the curve is the exact hopping solution
for plastic, sticking landings without slip (docs/tracks.md), which the stick points approach as μ grows.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt

from micro_feeder.explore.evaluate import Job, evaluate

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'test'))
from test_tracks import hopping_velocity_ratio

G, FREQUENCY, BETA, MU, COUNT = 9.81, 100.0, math.pi / 6, 0.5, 60
OMEGA = 2 * math.pi * FREQUENCY
# (landing law, μ): label, colour, marker
SERIES = {('keep', MU): ('landing keeps the tangential velocity (seed)', '#d95f02', 'o'),
          ('coulomb', MU): ('Coulomb impulse at landing', '#7570b3', 's'),
          ('stick', MU): ('landing sticks', '#1b9e77', 'D'),
          ('stick', 1e4): ('landing sticks, μ = 10⁴ (no slip in contact)', 'black', 'x')}


def main(out: Path) -> None:
    gammas = np.linspace(0.2, 3.2, 61)
    fig, ax = plt.subplots(figsize=(7.5, 4.5), layout='constrained')
    for (law, mu), (label, color, marker) in SERIES.items():
        job = Job({'surface.kind': 'track', 'track.vibration_angle': BETA, 'contact.model': 'coulomb',
                   'contact.mu': mu, 'landing.law': law, 'stroke.waveform': 'sine', 'stroke.frequency': FREQUENCY,
                   'stroke.count': COUNT}, duration=COUNT / FREQUENCY)
        ratios = []
        for gamma in gammas:
            amplitude = gamma * G / (OMEGA ** 2 * math.sin(BETA))
            row = evaluate(job, {'stroke.amplitude': amplitude})
            ratios.append(row['mean_velocity_mps'] / (amplitude * OMEGA * math.cos(BETA)))
        ax.plot(gammas, ratios, marker, ms=4, mfc='none' if marker != 'x' else None, color=color,
                label=f'simulated, μ = {mu:g}: {label}' if mu == MU else f'simulated: {label}')
    exact = np.linspace(1.0001, math.sqrt(1 + math.pi ** 2), 200)
    ax.plot(exact, [hopping_velocity_ratio(g) for g in exact], '-', color='black', lw=1,
            label='closed form: sticking landings, no slip')
    ax.axvline(1.0, color='0.6', lw=0.8, ls=':')
    ax.text(1.02, 0.72, 'Γ = 1: flight\nbegins', color='0.4', fontsize=8)
    ax.set_xlabel('throw number Γ = Aω² sin β / (g cos α)')
    ax.set_ylabel('mean velocity / (Aω cos β)')
    ax.set_title('Horizontal track, sine along β = 30°: below Γ = 1 the part slides, above it hops, and the '
                 'landing law\nsets its speed (points: micro-feeder sweep rows; line: the exact solution for '
                 'sticking landings)', fontsize=9)
    ax.legend(fontsize=7.5, loc='lower right')
    ax.grid(alpha=0.3)
    fig.savefig(out, dpi=120)
    print(f'wrote {out}')


if __name__ == '__main__':
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).with_suffix('.png'))
