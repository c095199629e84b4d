"""One line on stderr when numba starts compiling the physics kernel: once after installing or upgrading it
takes minutes (docs/dynamics.md §6), and a first command that prints nothing for that long looks hung."""

from __future__ import annotations

import sys

from numba.core import event

PHYSICS = 'micro_feeder.physics'
NOTICE = ('micro-feeder: compiling the physics kernel with numba (once after installing or upgrading: about '
          '2.5 min on one core; later runs load it from the cache in ~1.5 s) ...')


class KernelCompileNotice(event.Listener):
    """Prints :data:`NOTICE` at the first compile of a function of the physics package (loads from the cache
    are not compiles: numba emits no event for them)."""

    def __init__(self) -> None:
        self.shown = False

    def on_start(self, ev: event.Event) -> None:
        function = getattr((ev.data or {}).get('dispatcher'), 'py_func', None)
        if not self.shown and getattr(function, '__module__', '').startswith(PHYSICS):
            self.shown = True
            print(NOTICE, file=sys.stderr, flush=True)

    def on_end(self, ev: event.Event) -> None:
        pass


def announce_kernel_compiles() -> None:
    """Register the notice for this process's compiles."""
    event.register('numba:compile', KernelCompileNotice())
