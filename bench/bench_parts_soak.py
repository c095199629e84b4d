"""Soak benchmark of many parts over ROS (issue 28): 16 parts 0.3 mm apart on a vibratory track (the feeder labs buy:
Coulomb friction μ 0.5, a 100 Hz sine stroke of 60 µm along 30°, a throw number 1.2, so the parts hop forward),
continuous strokes streamed by the actuator, the simulator publishing every part at 1 kHz, for ``--minutes``
(default 1) in two cases: the ``simulator`` and the ``actuator`` as separate processes (as a lab runs them; ``--case
separate``), and ``micro-feeder run --record`` (one process, the recorder included; ``--case record``), then
``micro-feeder resim`` of its log, which compares every part at every pose. ``--wave``: the parts one per millimetre
along a 16-actuator travelling wave instead (1 mm apart, phases (k mod 4)/4): each part then meets 16 actuators'
streamed knots, ~500 breakpoints per millisecond, and costs what one part on that wave does (the single-part soak's
16-actuator case).

Targets: median real-time factor (the simulator's ``/diagnostics``, once a second) >= 0.99; resim of the log
IDENTICAL or within the real-time stop rounding (docs/logs.md); the recorder loses nothing.

    .venv/bin/python bench/bench_parts_soak.py [--minutes M] [--parts N] [--case separate|record|both]
                                               [--json PATH | --no-json]

Results: bench/results/bench_parts_soak.json.
"""

from __future__ import annotations

import argparse
import os
import re
import time

import results_json
from bench_soak import LOG_DIR, case_figures, report, run_case, run_figures, run_record_case, run_report, wave_settings
from results_json import figure


def parts_settings(n: int, wave: bool = False) -> dict[str, object]:
    """n parts on a vibratory track 0.3 mm apart; with ``wave``, n actuators and one part 0.3 mm past each
    actuator's centre."""
    if wave:
        return {**wave_settings(n), 'particle.x0': [round(k * 1e-3 + 0.3e-3, 6) for k in range(n)]}
    return {'surface.kind': 'track', 'contact.model': 'coulomb', 'contact.mu': 0.5, 'stroke.waveform': 'sine',
            'stroke.frequency': 100.0, 'stroke.amplitude': 60e-6,
            'particle.x0': [round(k * 0.3e-3, 6) for k in range(n)]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--minutes', type=float, default=1.0, help='minutes of continuous strokes (default 1)')
    parser.add_argument('--parts', type=int, default=16, help='parts, default 16')
    parser.add_argument('--wave', action='store_true', help='on a travelling wave of as many actuators')
    parser.add_argument('--case', choices=('separate', 'record', 'both'), default='both',
                        help='separate simulator and actuator processes, run --record, or both (default)')
    results_json.add_arguments(parser, 'bench_parts_soak')
    args = parser.parse_args()
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    print(f'load average before: {os.getloadavg()}')
    settings = {key: str(value).replace(' ', '') for key, value in parts_settings(args.parts, args.wave).items()}
    where = f'a {args.parts}-actuator travelling wave' if args.wave else 'a vibratory track'
    figures = []
    if args.case in ('separate', 'both'):
        ros_args = [arg for key, value in settings.items() for arg in ('-p', f'{key}:={value}')]
        separate = run_case(args.parts if args.wave else 1, args.minutes, 100.0, ros_args,
                            name=f'soak_parts_{args.parts}_separate')
        print(f'{args.parts} parts on {where}, simulator and actuator as separate processes:')
        print(report(separate), flush=True)
        figures += [{**f, 'key': f'parts_separate_{f["key"]}',
                     'what': f'{args.parts} parts on {where}, separate processes: '
                             + re.sub(r'^\d+ actuator\(s\)[,:] ', '', f['what'])}
                    for f in case_figures(separate)]
    if args.case in ('record', 'both'):
        result = run_record_case(args.minutes, settings, name=f'soak_parts_{args.parts}')
        print(f'{args.parts} parts on {where}, micro-feeder run --record:')
        print(run_report(result), flush=True)
        verdict = result['resim']['stdout'].splitlines()[0] if result['resim']['stdout'] else '(no verdict)'
        figures += [{**f, 'key': f'parts_{f["key"]}', 'what': f'{args.parts} parts on {where}: {f["what"]}'}
                    for f in run_figures(result)]
        figures.append(figure('parts_resim_verdict', f'{args.parts} parts: resim of the log',
                              verdict.split(':')[1].strip() if ':' in verdict else verdict, '', note=verdict))
    print(f'load average after: {os.getloadavg()}')
    results_json.save(args, 'bench_parts_soak', f'{args.parts} parts over ROS (soak)', figures, load_before=load,
                      seconds=time.perf_counter() - started,
                      purpose=f'{args.parts} parts on {where}, continuous strokes, the simulator publishing every '
                              'part at 1 kHz: as separate simulator and actuator processes, and under run --record '
                              '(one process, the recorder included), then resim of its log.')


if __name__ == '__main__':
    main()
