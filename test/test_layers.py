"""The layers of docs/architecture.md hold: everything outside the node and CLI packages imports and works
without rclpy (what Dask workers, offline scripts and the log tools rely on). The import-linter contracts in
pyproject.toml (run by ``make test``) check the same statically; this runs it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / 'micro_feeder'

BLOCK_RCLPY = """
import importlib, sys

class BlockRclpy:
    def find_spec(self, name, path=None, target=None):
        if name == 'rclpy' or name.startswith('rclpy.'):
            raise ImportError(f'{name} is blocked: this module must not need rclpy')
        return None

sys.meta_path.insert(0, BlockRclpy())
"""


def _modules_outside_nodes_and_cli() -> list[str]:
    names = []
    for path in sorted(PACKAGE.rglob('*.py')):
        parts = path.relative_to(PACKAGE.parent).with_suffix('').parts
        if parts[1] in ('nodes', 'cli'):
            continue
        names.append('.'.join(parts[:-1] if parts[-1] == '__init__' else parts))
    return names


def test_every_module_outside_the_nodes_and_cli_imports_where_rclpy_cannot() -> None:
    modules = _modules_outside_nodes_and_cli()
    assert 'micro_feeder.sim.stepper' in modules and 'micro_feeder.explore.calibrate' in modules
    code = BLOCK_RCLPY + f"""
for name in {modules!r}:
    importlib.import_module(name)
assert not any(m == 'rclpy' or m.startswith('rclpy.') for m in sys.modules)
print('imported', len({modules!r}))
"""
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    assert f'imported {len(modules)}' in result.stdout


def test_the_blocker_does_block_rclpy() -> None:
    """The check above can fail: a module that imports rclpy is refused under the same blocker."""
    code = BLOCK_RCLPY + "importlib.import_module('micro_feeder.nodes.spin')\n"
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and 'rclpy' in result.stderr and 'is blocked' in result.stderr
