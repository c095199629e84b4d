"""Benchmark: building the contact model's tables (target <= 100 ms, issue 2).

Usage: .venv/bin/python bench/bench_contact.py [--json PATH | --no-json]
Reports the first build in a fresh process (includes the one-off f(s) spline) and the median and best
of repeated builds, for both presets; writes them to bench/results/bench_contact.json.
"""

import argparse
import os
import statistics
import time

import results_json
from results_json import figure

from micro_feeder.physics.contact import ContactModel, ContactParams

TARGET_MS = 100.0
REPEATS = 15


def build_ms(params: ContactParams) -> float:
    start = time.perf_counter()
    ContactModel(params)
    return (time.perf_counter() - start) * 1e3


def main(args: argparse.Namespace) -> None:
    load = [round(x, 2) for x in os.getloadavg()]
    started = time.perf_counter()
    first = build_ms(ContactParams())
    print(f'contact tables, first build in process (seed_paper): {first:.1f} ms (target <= {TARGET_MS:.0f} ms)')
    figures = [figure('first_build_ms', 'contact tables, first build in a process (seed_paper)', round(first, 1),
                      'ms', op='<=', target=TARGET_MS)]
    for preset in ('seed_paper', 'ke_literature'):
        params = ContactParams.preset_values(preset)
        times = [build_ms(params) for _ in range(REPEATS)]
        print(f'contact tables, {preset}: median {statistics.median(times):.1f} ms, best {min(times):.1f} ms '
              f'over {REPEATS} builds (target <= {TARGET_MS:.0f} ms)')
        figures += [figure(f'{preset}_median_ms', f'contact tables, {preset}, median of {REPEATS} builds',
                           round(statistics.median(times), 1), 'ms', op='<=', target=TARGET_MS),
                    figure(f'{preset}_best_ms', f'contact tables, {preset}, best of {REPEATS} builds',
                           round(min(times), 1), 'ms', op='<=', target=TARGET_MS)]
    results_json.save(args, 'bench_contact', 'Contact model tables', figures, load_before=load,
                      purpose='Building the contact model\'s tables (issue 2).',
                      seconds=time.perf_counter() - started)


if __name__ == '__main__':
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    results_json.add_arguments(parser, 'bench_contact')
    main(parser.parse_args())
