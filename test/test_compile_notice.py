"""The CLI says so when numba starts compiling the physics kernel (minutes once after installing)."""

import numba
from numba.core import event

from micro_feeder.compile_notice import NOTICE, KernelCompileNotice


def _fresh_function(module: str):
    def probe(x):
        return x + 1
    probe.__module__ = module
    return numba.njit(probe)


def test_a_physics_compile_is_announced_once() -> None:
    said: list[str] = []
    with event.install_listener('numba:compile', KernelCompileNotice(said.append)):
        _fresh_function('micro_feeder.plots.probe')(1)
        assert said == []
        _fresh_function('micro_feeder.physics.probe')(1)
        _fresh_function('micro_feeder.physics.probe')(1.5)
    assert said == [NOTICE]


def test_announcing_again_keeps_one_listener() -> None:
    from micro_feeder.compile_notice import _registered, announce_kernel_compiles
    announce_kernel_compiles(print)
    first = list(_registered)
    announce_kernel_compiles(print)
    assert _registered == first and len(first) == 1
