"""Seeded fuzzing of the CLI and the log reader: no traceback, no hang, on malformed input.

* Logs: a small complete log garbled, zeroed, 2-byte-flipped, truncated or spliced at seeded random
  offsets, through ``info``, ``export``, ``recover``, ``resim`` (and ``plot`` for some): exit status 0 or 2,
  nothing escapes ``main`` (an exception reaching the test is a traceback a user would see), bounded time
  per call; ``info`` reports every change (a CRC or structure check catches it); after a same-length
  change ``recover`` keeps every message of every chunk the change did not touch (chunks as the mcap
  library reads the original).
* CLI: seeded random command lines (absurd, non-finite, wrong-typed option values; unknown and
  out-of-range parameters; binary, missing and directory paths) for ``simulate``, ``contact``, ``resim``
  and the log commands: exit status 0 or 2, nothing escapes ``main``, bounded time.

What was fuzzed, how many cases and the outcomes: docs/robustness.md.
"""

import contextlib
import io
import random
import time
from collections import Counter
from pathlib import Path

import pytest
from log_fixtures import chunks_of, write_motion_log

from micro_feeder.cli import main
from micro_feeder.logs.reader import LogReader

LOG_CASES = 48
CLI_CASES = 150
SECONDS_PER_CALL = 20.0    # bound on any one call (they take 0.01-1 s)


def run_cli(argv: list[str]) -> tuple[int, str]:
    """``micro-feeder ARGV`` in this process: (exit status, stderr). argparse's own exit counts as a status."""
    err = io.StringIO()
    started = time.monotonic()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            status = main(argv)
        except SystemExit as exit_:
            status = exit_.code if isinstance(exit_.code, int) else 2
    elapsed = time.monotonic() - started
    assert elapsed < SECONDS_PER_CALL, f'{argv} took {elapsed:.1f} s'
    assert 'Traceback' not in err.getvalue(), err.getvalue()
    return status, err.getvalue()


def mutate(raw: bytes, rng: random.Random) -> tuple[bytes, tuple[int, int] | None, str]:
    """A damaged copy of ``raw``, the byte range changed in place (None when the length changed), and how."""
    kind = rng.choice(['garble', 'garble', 'zero', 'flip2', 'truncate', 'splice'])
    at = rng.randrange(len(raw))
    if kind == 'truncate':
        return raw[:at], None, f'truncated at {at}'
    if kind == 'splice':
        size = rng.randrange(1, 200)
        return raw[:at] + rng.randbytes(size) + raw[at:], None, f'{size} random bytes inserted at {at}'
    size = min(2 if kind == 'flip2' else rng.randrange(1, 64), len(raw) - at)
    new = bytes(size) if kind == 'zero' else bytes(b ^ 0xA5 for b in raw[at:at + size]) if kind == 'flip2' \
        else rng.randbytes(size)
    return raw[:at] + new + raw[at + size:], (at, at + size), f'{kind} {size} bytes at {at}'


@pytest.fixture(scope='module')
def base(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp('fuzz') / 'base.mcap'
    write_motion_log(path, n=600, chunk_size=12_000)
    return path


def test_fuzzed_logs_through_every_log_command(base, tmp_path):
    raw = base.read_bytes()
    chunks = chunks_of(base)
    assert len(chunks) >= 5
    rng = random.Random(20261122)
    outcomes: Counter[str] = Counter()
    for case in range(LOG_CASES):
        data, changed, how = mutate(raw, rng)
        log = tmp_path / f'case{case}.mcap'
        log.write_bytes(data)
        recovered = tmp_path / f'rec{case}.mcap'
        commands = [['info', str(log)], ['export', str(log), '--csv', str(tmp_path / f'csv{case}')],
                    ['recover', str(log), str(recovered)], ['resim', str(log)]]
        if case % 12 == 0:
            commands.append(['plot', str(log), '-o', str(tmp_path / f'plot{case}.png')])
        for argv in commands:
            status, err = run_cli(argv)
            assert status in (0, 2), f'{how}: {argv} -> {status}: {err}'
            outcomes[f'{argv[0]} exit {status}'] += 1
            if argv[0] == 'info' and data != raw:   # no silent corruption: every change is reported
                assert 'warning:' in err or status == 2, f'{how}: not reported'
            if status == 2:
                assert 'error' in err.strip().splitlines()[-1], err
        if changed is not None and recovered.exists():
            kept = {m.data for m in LogReader(recovered).messages()}
            untouched = {d for start, end, msgs in chunks if end <= changed[0] or start >= changed[1] for d in msgs}
            assert untouched <= kept, f'{how}: recover lost {len(untouched - kept)} messages of undamaged chunks'
    print('log fuzz outcomes:', dict(sorted(outcomes.items())))


NUMBERS = ['0', '-1', '1e-300', '1e300', 'nan', 'inf', '-inf', '1', '0.5', '3', '1e9', 'abc', '', '[1,2]', '[]',
           'true', '{a: 1}', '1e-15', '-0.0', '1_000']
PARAMETERS = ['stroke.count', 'stroke.frequency', 'stroke.amplitude', 'stroke.pause', 'stroke.delay', 'stroke.phases',
              'particle.x0', 'particle.mass', 'particle.area', 'surface.widths', 'surface.centers', 'gravity',
              'integration.dt', 'integration.tolerance', 'integration.check_step', 'integration.event_tolerance',
              'integration.method', 'contact.sigma', 'contact.beta', 'contact.preset', 'contact.sigmaa', 'nope',
              'stroke.waveform', 'piezo.enabled', 'piezo.natural_frequency']


def random_argv(rng: random.Random, paths: dict[str, str]) -> list[str]:
    """One random command line: a command, some of its options with random values, random --set's."""
    command = rng.choice(['simulate', 'simulate', 'contact', 'resim', 'info', 'export', 'recover', 'plot'])
    argv = [command]
    if command in ('resim', 'info', 'export', 'recover', 'plot'):
        argv.append(paths[rng.choice(list(paths))])
    if command == 'recover':
        argv.append(rng.choice([paths['missing'], paths['dir'], paths['out']]))
    if command == 'export':
        argv += ['--csv', rng.choice([paths['out'], paths['binary'], '/proc/nope'])]
    if command == 'plot':
        argv += ['-o', rng.choice([paths['out'] + '.png', '/proc/nope.png', paths['dir']])]
    if command in ('simulate', 'contact', 'resim'):
        for _ in range(rng.randrange(4)):
            argv += ['--set', f'{rng.choice(PARAMETERS)}={rng.choice(NUMBERS)}']
        if rng.random() < 0.2:
            argv += ['--params', paths[rng.choice(['binary', 'missing', 'dir', 'text', 'good'])]]
    if command == 'simulate':
        if rng.random() < 0.5:
            argv += ['--duration', rng.choice(NUMBERS)]
        argv += ['--out', paths['out']]
    if command == 'contact' and rng.random() < 0.5:
        argv += ['--d-nm', rng.choice(['50', '50,55', '-1', 'nan', 'abc', '1e300', ''])]
    if command == 'resim' and rng.random() < 0.3:
        argv += ['--tolerance', rng.choice(NUMBERS)]
    if rng.random() < 0.05:
        argv.append(rng.choice(['--bogus', '-x', '--', 'extra']))
    return argv


def test_fuzzed_command_lines(tmp_path):
    write_motion_log(tmp_path / 'good.mcap', n=50)
    (tmp_path / 'binary').write_bytes(random.Random(1).randbytes(400))
    (tmp_path / 'text.yaml').write_text('just: [text, not: parameters\n')
    (tmp_path / 'dir').mkdir()
    paths = {'good': str(tmp_path / 'good.mcap'), 'binary': str(tmp_path / 'binary'), 'dir': str(tmp_path / 'dir'),
             'missing': str(tmp_path / 'missing'), 'text': str(tmp_path / 'text.yaml'), 'out': str(tmp_path / 'out')}
    rng = random.Random(11)
    outcomes: Counter[str] = Counter()
    for _ in range(CLI_CASES):
        argv = random_argv(rng, paths)
        status, err = run_cli(argv)
        assert status in (0, 2), f'{argv} -> {status}: {err}'
        outcomes[f'exit {status}'] += 1
        if status == 2:
            assert err.strip(), argv
    print('CLI fuzz outcomes:', dict(sorted(outcomes.items())))
