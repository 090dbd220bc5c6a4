"""Least squares speed (issue: parametric identification). Run by hand:
``python benchmarks/bench_least_squares.py``.

Target on the 2-core reference machine: the coupled 6-DOF regression of 100,000 samples
(600,000 rows) solved with uncertainty in under 0.5 s. The baseline in the same run is
``numpy.linalg.lstsq`` (SVD) on the same rows, without covariance or excitation checks.
"""

from __future__ import annotations

import datetime
import time

import numpy as np
from common import best_of, machine

from nnid.datasets.arrays import log_arrays
from nnid.datasets.excitation import Multisine
from nnid.datasets.simulator import simulate
from nnid.models.parametric import ParametricFossen
from nnid.trainers.least_squares import LeastSquares
from nnid.vehicle import load_vehicle

UNKNOWNS = [
    "X_udot",
    "Y_vdot",
    "Z_wdot",
    "K_pdot",
    "M_qdot",
    "N_rdot",
    "X:u*abs(u)",
    "Y:v*abs(v)",
    "Z:w*abs(w)",
    "K:p*abs(p)",
    "M:q*abs(q)",
    "N:r*abs(r)",
]


def main() -> None:
    veh = load_vehicle("seamor")
    n, dt = 100_000, 0.01
    t = np.arange(n) * dt
    amps = [30, 30, 30, 4, 0, 4]
    inputs = np.stack(
        [
            Multisine(
                channel="X",
                amplitude=max(a, 1),
                f_min=0.02 + 0.003 * k,
                f_max=1.0,
                n=12,
                duration=t[-1] + dt,
            )(t)
            * (a > 0)
            for k, a in enumerate(amps)
        ],
        1,
    )
    log = simulate(veh, inputs, dt)
    build_start = time.perf_counter()
    reg = ParametricFossen(veh, UNKNOWNS).regression(log_arrays(log, veh))
    build = time.perf_counter() - build_start
    trainer = LeastSquares()
    solve = best_of(lambda: trainer.solve(reg))
    baseline = best_of(lambda: np.linalg.lstsq(reg.phi, reg.y, rcond=None))
    est = trainer.solve(reg)
    truth = np.array([{**veh.added_mass, **veh.damping.coefficients}[u] for u in UNKNOWNS])
    print(f"machine: {machine()}")
    print(f"date: {datetime.date.today().isoformat()}")
    print(f"rows: {reg.phi.shape[0]:,} x {reg.phi.shape[1]} parameters")
    print(f"regressor build (physics, R(e_k) - R(0)): {build:.3f} s")
    print(
        f"LeastSquares.solve (feasible WLS, covariance, excitation, correlation time): "
        f"{solve:.3f} s (target < 0.5 s)"
    )
    print(
        f"numpy.linalg.lstsq baseline (SVD, estimate only): {baseline:.3f} s "
        f"-> ratio {baseline / solve:.1f}x"
    )
    print(f"max relative error vs truth (noise-free): {np.max(np.abs(est.theta / truth - 1)):.1e}")


if __name__ == "__main__":
    main()
