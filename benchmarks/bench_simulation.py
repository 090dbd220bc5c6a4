"""Simulation speed (issue: Foundation). Run by hand: ``python benchmarks/bench_simulation.py``.

Targets on the 2-core reference machine: one 10-minute trajectory at 100 Hz (60,000 RK4 steps)
in at most 2 s, and 1,024 trajectories of 1,000 steps, batched, in at most 2 s. The baseline in
the same run is the differentiable torch RK4 on the same model (the one physics implementation
evaluated op by op), so the ratio shows what the compiled feature form buys.

Closed loop (no target; the VT 690 comparison flies every model this way): one 10-minute
trajectory at 20 Hz under the PD autopilot, the autopilot and installation inside the compiled
loop (``compiled.fly_pd``) against the same flight stepped from Python, one compiled RK4 call
per sample (how it was flown before). Both give the same bits, checked here.
"""

from __future__ import annotations

import datetime
import os

import numpy as np
import torch
from common import best_of, machine

from nnid.datasets.simulator import Autopilot, integrate
from nnid.physics import compiled
from nnid.physics.fossen import FossenModel
from nnid.physics.integrate import rk4
from nnid.physics.thrusters import apply_installation
from nnid.vehicle import load_vehicle


def main() -> None:
    torch.set_num_threads(os.cpu_count() or 1)
    model = FossenModel.from_vehicle(load_vehicle("seamor"))
    form = model.feature_form()
    rng = np.random.default_rng(0)
    dt = 0.01
    tau_long = np.repeat(rng.normal(0, 20, (600, 6)), 100, axis=0)  # 60,000 steps, 1 s holds
    x0 = np.zeros(12)
    compiled.integrate_rk4(form, x0, tau_long[:10], dt)  # compile outside the timing
    single = best_of(lambda: integrate(model, x0, tau_long, dt))

    n_torch = 2_000
    tau_t = torch.as_tensor(tau_long[:n_torch])
    torch_single = best_of(lambda: rk4(model.rhs, torch.as_tensor(x0), tau_t, dt), 1)
    torch_single_60k = torch_single * tau_long.shape[0] / n_torch

    tau_batch = rng.normal(0, 20, (1024, 1000, 6))
    x0b = np.zeros((1024, 12))
    compiled.integrate_rk4(form, x0b[:2], tau_batch[:2, :10], dt)
    batch = best_of(lambda: compiled.integrate_rk4(form, x0b, tau_batch, dt))
    tau_bt = torch.as_tensor(tau_batch[:, :100]).transpose(0, 1).contiguous()
    torch_batch = best_of(lambda: rk4(model.rhs, torch.as_tensor(x0b), tau_bt, dt), 1) * 10

    check = integrate(model, x0, tau_long[:n_torch], dt)
    ref = rk4(model.rhs, torch.as_tensor(x0), tau_t, dt).numpy()
    agree = float(np.abs(check - ref).max())

    print(f"machine: {machine(torch=torch.__version__)}")
    print(f"date: {datetime.date.today().isoformat()}")
    print(f"single 60,000 steps, compiled RK4: {single:.3f} s (target <= 2 s)")
    print(
        f"single 60,000 steps, torch RK4 (from {n_torch} steps): {torch_single_60k:.1f} s "
        f"-> compiled is {torch_single_60k / single:.0f}x faster"
    )
    print(f"batch 1,024 x 1,000 steps, compiled RK4 (threads): {batch:.3f} s (target <= 2 s)")
    print(
        f"batch 1,024 x 1,000 steps, torch RK4 (from 100 steps): {torch_batch:.2f} s "
        f"-> compiled is {torch_batch / batch:.1f}x faster"
    )
    print(f"max |compiled - torch| over {n_torch} steps: {agree:.1e}")
    closed_loop()


def closed_loop() -> None:
    form = FossenModel.from_vehicle(load_vehicle("vt690")).feature_form()
    pilot = Autopilot(
        kp=[0, 0, 40, 5, 60, 30], kd=[0, 0, 60, 1.5, 80, 80], reference=[0, 0, 2, 0, 0, 0]
    )
    eta = np.ones(6)
    dt, n = 0.05, 12_000
    rng = np.random.default_rng(1)
    tau = np.column_stack([np.full(n, 11.0), np.repeat(rng.normal(0, 1, (n // 40, 5)), 40, 0)])
    x0 = np.array([0, 0, 2, 0, 0, 0, 1.5, 0, 0, 0, 0, 0], float)

    def stepped() -> np.ndarray:
        states = np.empty((n, 12))
        states[0] = x0
        for k in range(n - 1):
            applied = apply_installation(tau[k] + pilot.force(states[k]), eta, eta)
            states[k + 1] = compiled.integrate_rk4(form, states[k], applied[None], dt, 5)[-1]
        return states

    def flown() -> np.ndarray:
        out = compiled.fly_pd(form, x0[None], tau, np.zeros(1, int), n - 1, dt,
                              pilot.pilot(eta, eta), None, 5)  # fmt: skip
        return out[0][0]

    reference = stepped()
    same = np.isfinite(reference).all() and np.array_equal(reference, flown())
    python = best_of(stepped, 1)
    kernel = best_of(flown)
    print(
        f"closed loop, VT 690 under the PD autopilot, {n:,} samples x 5 RK4 substeps: "
        f"compiled flight {kernel:.3f} s, stepped from Python {python:.2f} s "
        f"-> {python / kernel:.0f}x; same bits: {same}"
    )


if __name__ == "__main__":
    main()
