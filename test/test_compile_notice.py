"""The CLI says so when numba starts compiling the physics kernel (minutes once after installing)."""

import numba
from numba.core import event

from micro_feeder.cli._compile_notice import NOTICE, KernelCompileNotice


def _fresh_function(module: str):
    def probe(x):
        return x + 1
    probe.__module__ = module
    return numba.njit(probe)


def test_a_physics_compile_prints_the_notice_once(capsys) -> None:
    notice = KernelCompileNotice()
    with event.install_listener('numba:compile', notice):
        _fresh_function('micro_feeder.plots.probe')(1)
        assert capsys.readouterr().err == ''
        _fresh_function('micro_feeder.physics.probe')(1)
        _fresh_function('micro_feeder.physics.probe')(1.5)
    assert capsys.readouterr().err == NOTICE + '\n'
