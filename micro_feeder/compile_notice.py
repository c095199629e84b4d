"""One line when numba starts compiling the physics kernel: once after installing or upgrading it takes
minutes (docs/dynamics.md §6), and a command or node that says nothing for that long looks hung. Used by
the ``micro-feeder`` CLI (stderr) and by the node executables (their ROS logger)."""

from __future__ import annotations

from collections.abc import Callable

from numba.core import event

PHYSICS = 'micro_feeder.physics'
NOTICE = ('compiling the physics kernel with numba (once after installing or upgrading: about 10 min on one '
          'core and up to 7 GB of memory; later runs load it from the cache in ~1.5 s) ...')


class KernelCompileNotice(event.Listener):
    """Calls ``say(NOTICE)`` at the first compile of a function of the physics package (loads from the
    cache are not compiles: numba emits no event for them)."""

    def __init__(self, say: Callable[[str], object]) -> None:
        self.say = say
        self.shown = False

    def on_start(self, ev: event.Event) -> None:
        function = getattr((ev.data or {}).get('dispatcher'), 'py_func', None)
        if not self.shown and getattr(function, '__module__', '').startswith(PHYSICS):
            self.shown = True
            self.say(NOTICE)

    def on_end(self, ev: event.Event) -> None:
        pass


_registered: list[KernelCompileNotice] = []


def announce_kernel_compiles(say: Callable[[str], object]) -> None:
    """Have ``say`` told, once, when this process starts compiling the physics kernel. Idempotent: a process
    that calls it again (the CLI's ``main`` run several times in one test session) keeps its first listener."""
    if not _registered:
        _registered.append(KernelCompileNotice(say))
        event.register('numba:compile', _registered[0])
