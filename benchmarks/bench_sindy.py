"""SINDy speed (issue 5). Run by hand: ``python benchmarks/bench_sindy.py``.

Targets: the 132-term library on 100,000 samples under 0.2 s; one SINDy fit (STLSQ, one
threshold) over it on 100,000 samples and six outputs under 2 s. Baseline in the same run:
pysindy's default pipeline (``PolynomialLibrary(degree=2)`` on ν, STLSQ) on the same data.
"""

from __future__ import annotations

import datetime

import numpy as np
import pysindy as ps
from common import best_of, machine

from nnid.physics.damping_library import BasisLibrary
from nnid.trainers.sindy import SparsePath


def main() -> None:
    rng = np.random.default_rng(0)
    n = 100_000
    nu = rng.normal(size=(n, 6)) * np.array([1.0, 0.5, 0.5, 0.3, 0.3, 0.3])
    lib = BasisLibrary()
    truth = np.zeros((6, len(lib)))
    for i, term in enumerate(["u*abs(u)", "v*abs(v)", "w*abs(w)", "p*abs(p)", "q*abs(q)"]):
        truth[i, lib.index(term)] = -50.0
    truth[5, lib.index("r*abs(r)")] = -5.0
    y = lib(nu) @ truth.T + rng.normal(0, 0.01, (n, 6))
    print(f"machine: {machine(numpy=np.__version__, pysindy=ps.__version__)}")
    print(f"date: {datetime.date.today().isoformat()}")
    t_lib = best_of(lambda: lib(nu))
    one = SparsePath(thresholds=[0.05], selection="aic")
    t_fit = best_of(lambda: one.fit(lib(nu), y))
    path = SparsePath(selection="aic")
    t_path = best_of(lambda: path.fit(lib(nu), y), repeats=1)

    def default_pipeline() -> ps.SINDy:
        model = ps.SINDy(feature_library=ps.PolynomialLibrary(degree=2), optimizer=ps.STLSQ())
        return model.fit(nu, t=0.01, x_dot=y)

    t_ps = best_of(default_pipeline)
    print(f"library evaluation, 132 terms x {n} samples: {t_lib:.3f} s (target < 0.2 s)")
    print(
        f"nnid SINDy fit, one threshold, 6 outputs: {t_fit:.3f} s (target < 2 s), "
        f"{int(np.count_nonzero(one.coef_))} terms"
    )
    print(
        f"nnid SINDy path, {len(path.path_)} thresholds + selection: {t_path:.3f} s, "
        f"{int(np.count_nonzero(path.coef_))} terms"
    )
    print(f"pysindy default (PolynomialLibrary deg 2, 28 terms, STLSQ): {t_ps:.3f} s")


if __name__ == "__main__":
    main()
