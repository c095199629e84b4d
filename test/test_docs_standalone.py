"""The repository stands alone: no file points at background material outside it, and every relative link
in the docs leads to a file that exists."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
OUTSIDE = re.compile(r'DYNAMICS(\.md|\b)|CONTACT_MODEL|DESIGN(\.md| §)|ROS_STACK|\.\./shared')


def tracked_text_files() -> list[Path]:
    names = subprocess.run(['git', 'ls-files'], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    files = []
    for name in names.splitlines():
        path = ROOT / name
        if path.is_file() and b'\0' not in path.read_bytes()[:4096]:
            files.append(path)
    return files


def test_no_file_refers_to_material_outside_the_repository() -> None:
    here = Path(__file__).resolve()
    offenders = [f'{path.relative_to(ROOT)}:{number}'
                 for path in tracked_text_files() if path != here
                 for number, line in enumerate(path.read_text(errors='replace').splitlines(), 1)
                 if OUTSIDE.search(line)]
    assert not offenders, offenders


def test_relative_links_in_the_docs_lead_somewhere() -> None:
    broken = []
    for page in [ROOT / 'README.md', *sorted((ROOT / 'docs').glob('*.md'))]:
        for target in re.findall(r'\]\(([^)#]+)(?:#[^)]*)?\)', page.read_text()):
            if '://' in target or target.startswith('mailto:'):
                continue
            if not (page.parent / target).exists():
                broken.append(f'{page.relative_to(ROOT)} -> {target}')
    assert not broken, broken
