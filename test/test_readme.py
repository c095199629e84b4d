"""README's examples still hold (and those of docs/hil.md, marked the same way).

README marks what is checked with an HTML comment just above it, so its prose can change freely:

* ``<!-- readme-check: console -->`` above a ```console block: each ``$ COMMAND`` in it is run (from a scratch
  directory holding the repository's ``config/``; ``.venv/bin/X`` is X of this interpreter's environment) and
  its standard output must be the lines shown under it, where a line ``...`` stands for any number of lines;
* ``<!-- readme-check: console, while running: COMMAND -->``: the same with COMMAND running in the
  background (it must also appear in README's text, where the reader is told to start it);
* ``<!-- readme-check: file NAME -->`` above a fenced block: the block is written to NAME in the scratch
  directory before the console blocks run;
* ``<!-- readme-check: topics -->`` above a table: each topic's type and QoS are those of docs/interface.md;
* ``<!-- readme-check: commands -->`` above a table: it names every ``micro-feeder`` command, and no other.

Also: README's figures table and docs/performance.md are what ``bench/report.py`` builds from
``bench/results/*.json``, and the diagram's topics (docs/img/nodes_topics.py) agree with docs/interface.md.
"""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import signal
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / 'README.md'
PAGES = [README, ROOT / 'docs' / 'hil.md']          # the pages whose marked console examples are run
INTERFACE = ROOT / 'docs' / 'interface.md'
BIN = Path(sys.executable).parent
MARK = re.compile(r'^<!-- readme-check: (.*?) -->\s*$')
COMMAND_TIMEOUT = 240.0


@dataclass
class Block:
    """A marked block: the marker's words, the fence's language, its lines and where it starts."""

    page: Path
    mark: str
    language: str
    lines: list[str]
    line: int
    options: dict[str, str] = field(default_factory=dict)


def marked_blocks(page: Path) -> list[Block]:
    """Every fenced block or table that a ``readme-check`` comment stands just above."""
    lines = page.read_text().splitlines()
    blocks = []
    for i, line in enumerate(lines):
        found = MARK.match(line)
        if not found:
            continue
        kind, _, rest = found.group(1).partition(',')
        words = kind.split(maxsplit=1)
        options = {'name': words[1]} if len(words) > 1 else {}
        key, _, value = rest.strip().partition(':')
        if key:
            options[key.strip()] = value.strip()
        start = i + 1
        if start < len(lines) and lines[start].startswith('```'):
            end = next(j for j in range(start + 1, len(lines)) if lines[j].startswith('```'))
            blocks.append(Block(page, words[0], lines[start][3:].strip(), lines[start + 1:end], start + 2, options))
        else:
            end = next((j for j in range(start, len(lines)) if not lines[j].startswith('|')), len(lines))
            blocks.append(Block(page, words[0], 'table', lines[start:end], start + 1, options))
    return blocks


def table_rows(lines: list[str]) -> list[list[str]]:
    """The cells of a Markdown table's body rows (header and rule dropped)."""
    rows = [[cell.strip() for cell in re.split(r'(?<!\\)\|', line.strip())[1:-1]] for line in lines]
    return [row for row in rows[2:] if row]


def output_matches(expected: list[str], actual: list[str]) -> bool:
    """``actual`` is ``expected`` line for line (trailing blanks ignored), a line ``...`` in ``expected``
    standing for any number of lines."""
    want = [line.rstrip() for line in expected]
    got = [line.rstrip() for line in actual]

    def match(i: int, j: int) -> bool:
        if i == len(want):
            return j == len(got)
        if want[i] == '...':
            return any(match(i + 1, k) for k in range(j, len(got) + 1))
        return j < len(got) and want[i] == got[j] and match(i + 1, j + 1)

    return match(0, 0)


def console_commands(block: Block) -> list[tuple[str, list[str]]]:
    """(command, expected output lines) for each ``$ `` line of a console block."""
    runs: list[tuple[str, list[str]]] = []
    for line in block.lines:
        if line.startswith('$ '):
            runs.append((line[2:], []))
        elif runs:
            runs[-1][1].append(line)
        else:
            raise AssertionError(f'{block.page.name}:{block.line}: output before the first "$ " line')
    return runs


def argv(command: str) -> list[str]:
    """A README command line as arguments, its program taken from this environment."""
    words = shlex.split(command, comments=True)
    program = words[0].removeprefix('.venv/bin/')
    if program == 'python':
        return [sys.executable, *words[1:]]
    return [str(BIN / program), *words[1:]]


def visible_text(text: str) -> str:
    """A page without its HTML comments (what a reader sees)."""
    return re.sub(r'<!--.*?-->', '', text, flags=re.DOTALL)


BLOCKS = marked_blocks(README)
CONSOLE = [b for page in PAGES for b in marked_blocks(page) if b.mark == 'console']


def test_readme_has_checked_examples() -> None:
    """The markers are there (a README rewritten without them would silently check nothing)."""
    kinds = [b.mark for b in BLOCKS]
    assert kinds.count('console') >= 3 and 'topics' in kinds and 'commands' in kinds, kinds
    assert all(b.mark in {'console', 'file', 'topics', 'commands'} for b in BLOCKS), kinds


def test_the_matcher_refuses_what_differs() -> None:
    assert output_matches(['a', '...', 'c'], ['a', 'b', 'b', 'c'])
    assert output_matches(['a', '...'], ['a'])
    assert not output_matches(['a', 'c'], ['a', 'b', 'c'])
    assert not output_matches(['a', 'b'], ['a', 'b', 'c'])
    assert not output_matches(['distance     -2.60742 um'], ['distance     -2.60743 um'])


@pytest.mark.parametrize('block', CONSOLE, ids=[f'{b.page.name}:{b.line}' for b in CONSOLE])
def test_console_example_output_holds(block: Block, tmp_path: Path) -> None:
    (tmp_path / 'config').symlink_to(ROOT / 'config')
    for other in marked_blocks(block.page):
        if other.mark == 'file':
            (tmp_path / other.options['name']).write_text('\n'.join(other.lines) + '\n')
    env = {**os.environ, 'COLUMNS': '120'}
    background = None
    if 'while running' in block.options:
        command = block.options['while running']
        assert command in visible_text(block.page.read_text()), f'{block.page.name} never says to run {command}'
        background = subprocess.Popen(argv(command), cwd=tmp_path, env=env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, text=True)
    try:
        for command, expected in console_commands(block):
            done = subprocess.run(argv(command), cwd=tmp_path, env=env, capture_output=True, text=True,
                                  timeout=COMMAND_TIMEOUT)
            assert done.returncode == 0, f'{command}: exit status {done.returncode}\n{done.stderr[-3000:]}'
            shown = '\n'.join(expected)
            assert output_matches(expected, done.stdout.splitlines()), (
                f'{block.page.name}:{block.line}: `{command}` no longer prints what the page shows.\n'
                f'The page shows:\n{shown}\nIt prints:\n{done.stdout}')
    finally:
        if background is not None:
            background.send_signal(signal.SIGINT)
            try:
                background.wait(timeout=20)
            except subprocess.TimeoutExpired:
                background.kill()
                background.wait()


def interface_topics() -> dict[str, tuple[str, str]]:
    """docs/interface.md's topic table: name -> (type, QoS)."""
    lines = INTERFACE.read_text().splitlines()
    start = lines.index(next(line for line in lines if line.startswith('| topic | type | direction | QoS |')))
    end = next(j for j in range(start, len(lines)) if not lines[j].startswith('|'))
    rows = table_rows(lines[start:end])
    return {re.match(r'`([^`]+)`', row[0]).group(1): (row[1], qos_words(row[3])) for row in rows}


def qos_words(text: str) -> str:
    """A QoS cell without emphasis and remarks in parentheses."""
    return re.sub(r'\s*\([^)]*\)', '', text.replace('**', '')).strip()


def test_readme_topics_are_those_of_the_interface() -> None:
    promised = interface_topics()
    rows = [row for b in BLOCKS if b.mark == 'topics' for row in table_rows(b.lines)]
    assert rows
    for row in rows:
        name = row[0].strip('`')
        assert name in promised, f'README lists {name}, which docs/interface.md does not'
        assert (row[1], qos_words(row[2])) == promised[name], f'{name}: README and docs/interface.md differ'


def test_readme_lists_every_command() -> None:
    done = subprocess.run([str(BIN / 'micro-feeder'), '--help'], capture_output=True, text=True, check=True,
                          env={**os.environ, 'COLUMNS': '200'})
    section = done.stdout.split('positional arguments:', 1)[1].split('options:', 1)[0]
    commands = set(re.findall(r'^    ([a-z][a-z-]*)(?:\s{2,}|$)', section, flags=re.MULTILINE))
    listed = {row[0].strip('`') for b in BLOCKS if b.mark == 'commands' for row in table_rows(b.lines)}
    assert commands and listed == commands


def test_the_diagram_shows_the_interface_topics() -> None:
    spec = importlib.util.spec_from_file_location('nodes_topics', ROOT / 'docs' / 'img' / 'nodes_topics.py')
    diagram = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(diagram)
    drawn = {name: (kind, qos) for name, kind, qos in diagram.COMMANDS + diagram.STATE}
    assert drawn == interface_topics()


def test_figures_are_built_from_the_benchmark_results() -> None:
    spec = importlib.util.spec_from_file_location('bench_report', ROOT / 'bench' / 'report.py')
    report = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(report)
    results = report.load()
    assert (ROOT / 'docs' / 'performance.md').read_text() == report.performance_md(results), (
        'docs/performance.md differs from bench/results: run make performance-doc')
    assert report.readme_table(results) in README.read_text(), (
        "README's figures table differs from bench/results: run make performance-doc")
