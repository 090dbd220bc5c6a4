"""Recursive least squares speed (issue 4). Run by hand: ``python benchmarks/bench_recursive.py``.

Target on the 2-core reference machine: at least 20,000 samples/s for 12 parameters and 6 rows
per sample (a full 6-DOF regression). Problem: 100,000 samples of a random regression with
noise, forgetting λ = 0.999. The baseline in the same run is a pure-NumPy loop over the samples
doing the per-sample vector update K = PΦᵢᵀ(λI + ΦᵢPΦᵢᵀ)⁻¹ (vectorised inside a sample), which
also checks that the compiled row-by-row update gives the same θ.
"""

from __future__ import annotations

import datetime
import time

import numba
import numpy as np
from common import best_of, machine

from nnid.trainers.recursive import RecursiveLeastSquares
from nnid.trainers.regression import Regression

N_SAMPLES, N_ROWS, N_PAR, LAMBDA, P0 = 100_000, 6, 12, 0.999, 1e6


def numpy_rls(phi: np.ndarray, y: np.ndarray, m: int, lam: float, p0: float) -> np.ndarray:
    """The baseline: one vector update per sample with NumPy."""
    p_mat = np.eye(phi.shape[1]) * p0
    theta = np.zeros(phi.shape[1])
    eye = np.eye(m)
    for i in range(phi.shape[0] // m):
        f, yi = phi[i * m : (i + 1) * m], y[i * m : (i + 1) * m]
        fp = f @ p_mat
        gain = np.linalg.solve(lam * eye + fp @ f.T, fp).T
        theta = theta + gain @ (yi - f @ theta)
        p_mat = (p_mat - gain @ fp) / lam
        p_mat = 0.5 * (p_mat + p_mat.T)  # keep P symmetric (it drifts otherwise)
    return theta


def main() -> None:
    rng = np.random.default_rng(0)
    truth = rng.normal(0, 10, N_PAR)
    phi = rng.normal(0, 1, (N_SAMPLES * N_ROWS, N_PAR))
    y = phi @ truth + rng.normal(0, 0.1, N_SAMPLES * N_ROWS)
    reg = Regression(phi, y, [f"theta{k}" for k in range(N_PAR)], ("u",) * N_ROWS, N_SAMPLES)
    rls = RecursiveLeastSquares(forgetting=LAMBDA, p0=P0)
    t0 = time.perf_counter()
    rls.solve(Regression(phi[:60], y[:60], reg.names, reg.dofs, 10))  # compile or load cache
    first = time.perf_counter() - t0
    compiled = best_of(lambda: rls.solve(reg))
    est = rls.solve(reg)

    t0 = time.perf_counter()
    theta_np = numpy_rls(phi, y, N_ROWS, LAMBDA, P0)
    baseline = time.perf_counter() - t0

    rate, rate_np = N_SAMPLES / compiled, N_SAMPLES / baseline
    print(f"machine: {machine(numpy=np.__version__, numba=numba.__version__)}")
    print(f"date: {datetime.date.today().isoformat()}")
    print(f"problem: {N_SAMPLES:,} samples x {N_ROWS} rows, {N_PAR} parameters, λ = {LAMBDA}")
    print(f"first call (numba compile or cache load): {first:.2f} s")
    print(
        f"compiled RLS (row by row), best of 3: {compiled:.3f} s = {rate:,.0f} samples/s "
        f"(target >= 20,000)"
    )
    print(f"NumPy loop (vector update per sample): {baseline:.2f} s = {rate_np:,.0f} samples/s")
    print(f"ratio: {rate / rate_np:.0f}x")
    print(f"max |θ compiled − θ NumPy|: {np.abs(est.theta - theta_np).max():.1e}")
    print(f"max |θ − truth|: {np.abs(est.theta - truth).max():.1e}")


if __name__ == "__main__":
    main()
