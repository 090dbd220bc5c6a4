"""The kernel warm-up (tests/kernel_warmup.py) compiles the argument types nnid passes."""

from __future__ import annotations

import numba
import numpy as np
from kernel_warmup import COMPILE_SECONDS, parts, signatures

from nnid.physics import compiled
from nnid.physics.fossen import FossenModel
from nnid.vehicle import load_vehicle


def test_the_warm_up_compiles_the_form_the_kernels_get_and_every_module():
    """The physics form as form_args passes it is the one the warm-up's signatures hold (a
    changed form would leave every kernel to compile where it is first called); each kernel
    module is compiled, in one process."""
    form = FossenModel.from_vehicle(load_vehicle("seamor")).feature_form()
    args = tuple(numba.typeof(a) for a in compiled.form_args(form))
    table = signatures()
    assert (
        table["nnid.physics.compiled"][1][1][4:-1] == args
    )  # _integrate(x0, tau, dt, n, *form, out)
    assert table["nnid.physics.compiled"][0][1][7] == numba.typeof(compiled.form_args(form))
    assert numba.typeof(np.zeros(3)) == table["nnid.physics.compiled"][1][1][0]
    assert set(table) == set(COMPILE_SECONDS)
    for n in (1, 2, 16):
        groups = parts(list(COMPILE_SECONDS), n)
        assert sorted(m for g in groups for m in g) == sorted(COMPILE_SECONDS)
        assert len(groups) == min(n, len(COMPILE_SECONDS))
