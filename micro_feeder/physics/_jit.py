"""The one switch between compiled and plain-Python numerics.

Every kernel function is decorated with :func:`jit`. Set the environment variable
``NUMBA_DISABLE_JIT=1`` before importing the package to run exactly the same code as plain Python
(slow, but steppable in a debugger and usable to check the compiled kernel).
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numba

F = TypeVar('F', bound=Callable)

# Floating-point freedom given to LLVM: only fusing a multiply and an add into one FMA instruction
# (rounded once instead of twice, so never less accurate). No reassociation, no approximate reciprocals
# and no assumption of finite values: the kernel detects a NaN state and must see it. Measured on the
# default scenario, interleaved on an idle machine: 230-250x real time against 208-226x without it.
FASTMATH = {'contract'}


def source_digest() -> str:
    """A digest of every source file of the physics package (16 hex digits)."""
    root = Path(__file__).parent
    digest = hashlib.sha256()
    for path in sorted(root.rglob('*.py')):
        digest.update(path.relative_to(root).as_posix().encode() + b'\0' + path.read_bytes())
    return digest.hexdigest()[:16]


def compile_cache_dir() -> str:
    """Where compiled machine code is cached: ``$NUMBA_CACHE_DIR`` (else ``~/.cache/micro_feeder/numba``)
    / the digest of the physics sources.

    numba keys a cached function on its own file's time stamp only, so a caller that inlined a function
    from another file (the kernel inlines the strokes of waveforms.py) kept running the old code after that
    file changed: a silent wrong answer after any edit or upgrade. Keyed on every source file, a change
    anywhere compiles afresh, and unchanged sources (sweep workers, a second clone) reuse the cache.
    """
    base = os.environ.get('NUMBA_CACHE_DIR') or os.path.join(
        os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache'), 'micro_feeder', 'numba')
    return os.path.join(base, source_digest())


numba.config.CACHE_DIR = compile_cache_dir()


def jit(function: F) -> F:
    """Compile ``function`` with numba in nopython mode, caching the machine code on disk.

    ``cache=True`` makes the first-call compile cost (several seconds for the whole kernel) a one-off
    per installation instead of per process, which matters for the sweep's worker processes.
    ``_nrt=False`` compiles without numba's reference counting: kernel functions never allocate
    (callers pass work arrays), and the atomic reference-count updates on every array view and tuple
    unpacking otherwise cost ~100 ns per call, 5-7x the arithmetic (measured in docs/dynamics.md).
    ``nogil=True`` releases the GIL while compiled code runs: the simulator node's loop thread then
    integrates while its executor thread serves commands and services, and a long integration no longer
    keeps the main thread from answering Ctrl-C/SIGTERM. ``fastmath``: :data:`FASTMATH`.
    """
    return numba.njit(cache=True, error_model='numpy', _nrt=False, nogil=True, fastmath=FASTMATH)(function)


def jit_exact(function: F) -> F:
    """:func:`jit` without :data:`FASTMATH`: every product and sum rounded on its own, as numpy rounds them, for
    compiled code that must take the very decisions of the numpy code it stands in for."""
    return numba.njit(cache=True, error_model='numpy', _nrt=False, nogil=True)(function)


def jit_inline(function: F) -> F:
    """:func:`jit` for the small functions of the hot path, inlined into their callers by numba.

    Each call otherwise passes the model and stroke-table tuples (dozens of machine words) by value;
    inlining halves the cost of one right-hand-side evaluation (115 -> 53 ns, docs/dynamics.md).
    """
    return numba.njit(cache=True, error_model='numpy', _nrt=False, nogil=True, inline='always',
                      fastmath=FASTMATH)(function)
