"""Benchmark: building the contact model's tables (target <= 100 ms, issue 2).

Usage: .venv/bin/python bench/bench_contact.py
Reports the first build in a fresh process (includes the one-off f(s) spline) and the median and best
of repeated builds, for both presets.
"""

import argparse
import statistics
import time

from micro_feeder.physics.contact import ContactModel, ContactParams

TARGET_MS = 100.0
REPEATS = 15


def build_ms(params: ContactParams) -> float:
    start = time.perf_counter()
    ContactModel(params)
    return (time.perf_counter() - start) * 1e3


def main() -> None:
    first = build_ms(ContactParams())
    print(f'contact tables, first build in process (seed_paper): {first:.1f} ms (target <= {TARGET_MS:.0f} ms)')
    for preset in ('seed_paper', 'ke_literature'):
        params = ContactParams.preset_values(preset)
        times = [build_ms(params) for _ in range(REPEATS)]
        print(f'contact tables, {preset}: median {statistics.median(times):.1f} ms, best {min(times):.1f} ms '
              f'over {REPEATS} builds (target <= {TARGET_MS:.0f} ms)')


if __name__ == '__main__':
    argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter).parse_args()
    main()
