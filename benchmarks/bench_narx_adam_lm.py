"""Wall time for Levenberg-Marquardt and Adam to reach a given validation error (issue 6).

Same network (the 10-node, 4-delay u v w r NARX of ``configs/seamor_narx_*.toml``, 374
parameters), same data (the seamor coupled sequence with 1 % noise, early-stopped on
surge-sway-yaw, balanced draws of 4,000 training samples: LM's fixed full batch, Adam's draw per
epoch in batches of 256), same validation MSE (normalised one-step residual). The target is a
level that every run of both trainers reaches (the largest best-validation MSE over all runs,
+1 %); the time to reach it excludes data preparation (each trainer's ``fit`` clock only).
"""

from __future__ import annotations

import datetime
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from benchmarks.common import machine
from nnid.config import SimulateConfig, load_config
from nnid.datasets.simulator import simulate_config
from nnid.models.narx import NarxModel
from nnid.trainers.adam import Adam
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
from nnid.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
FORCES = ["tau_X", "tau_Y", "tau_Z", "tau_N"]
TRAIN = ["surge", "sway", "heave", "yaw", "surge-heave", "surge-yaw", "sway-heave", "sway-yaw",
         "heave-yaw", "surge-sway-heave"]  # fmt: skip
SEEDS = range(5)
SAMPLES = 4000


def data():
    cfg = load_config(ROOT / "configs/seamor_sequence.toml", SimulateConfig)
    log = simulate_config(cfg, load_vehicle(cfg.vehicle))
    rng = np.random.default_rng(0)
    for c in "uvwr":
        log[c] = log["true_" + c] + rng.normal(0, 0.01 * log["true_" + c].std(), len(log))
    for c in FORCES:
        log[c] = log[c] + rng.normal(0, 0.01 * log[c].std(), len(log))

    def runs(names):
        return log[log["experiment"].isin(names)].reset_index(drop=True)

    return runs(TRAIN), runs(["surge-sway-yaw"])


class TimedAdam(Adam):
    """Adam that stamps the end of each epoch (the next epoch's batch request, or the end)."""

    def fit(self, module, residual, train_batches, val_batches=None):
        stamps: list[float] = []

        def batches(epoch: int):
            stamps.append(time.perf_counter())
            return train_batches(epoch)

        hist = super().fit(module, residual, batches, val_batches)
        end = stamps[0] + hist.seconds  # the fit clock starts just before the first request
        self.times = [s - stamps[0] for s in stamps[1:]] + [end - stamps[0]]
        return hist


def trace(trainer: str, seed: int, train, val) -> tuple[list[float], list[float]]:
    """(seconds, validation MSE) after each epoch."""
    if trainer == "lm":
        lm = LevenbergMarquardt(max_epochs=200, jacobian="samples")
        model = NarxModel(FORCES, list("uvwr"), 4, 4, hidden=(10,), trainer=lm, seed=seed,
                          lm_samples=SAMPLES)  # fmt: skip
        model.fit(train, validation_log=val)
        return model.history_.time, model.history_.val_mse
    adam = TimedAdam()
    model = NarxModel(FORCES, list("uvwr"), 4, 4, hidden=(10,), trainer=adam, seed=seed,
                      samples_per_epoch=SAMPLES)  # fmt: skip
    model.fit(train, validation_log=val)
    return adam.times, model.history_.validation


def time_to(target: float, times: list[float], vals: list[float]) -> float:
    for t, v in zip(times, vals, strict=True):
        if v <= target:
            return t
    return float("nan")


def main() -> None:
    torch.manual_seed(0)
    train, val = data()
    traces = {(k, s): trace(k, s, train, val) for s in SEEDS for k in ("lm", "adam")}
    target = 1.01 * max(min(v) for _, v in traces.values())
    rows = []
    for s in SEEDS:
        lm, adam = (time_to(target, *traces[k, s]) for k in ("lm", "adam"))
        best = {k: min(traces[k, s][1]) for k in ("lm", "adam")}
        rows.append((s, lm, adam, adam / lm, best["lm"], best["adam"]))
    ratio = statistics.median(r[3] for r in rows)
    print("## NARX: LM vs Adam (`benchmarks/bench_narx_adam_lm.py`)\n")
    print(
        f"Machine: {machine(torch=torch.__version__, numpy=np.__version__)}. "
        f"Date: {datetime.date.today()}.\n"
    )
    print(
        "Network: 10 nodes, 4 delays, X Y Z N → u v w r (374 parameters); data: seamor "
        f"sequence, 1 % noise, {len(TRAIN)} runs for training ({SAMPLES} balanced samples), "
        'surge-sway-yaw for validation. LM: trainlm defaults, `jacobian="samples"`, full '
        f"batch. Adam: nnid defaults, {SAMPLES} samples per epoch in batches of 256. "
        f"Target validation MSE (normalised one-step residual): **{target:.4g}** (the largest "
        "best-validation MSE over all runs, +1 %).\n"
    )
    print("| seed | LM time | Adam time | Adam / LM | LM best val MSE | Adam best val MSE |")
    print("|---|---|---|---|---|---|")
    for s, lm, adam, r, bl, ba in rows:
        print(f"| {s} | {lm:.2f} s | {adam:.2f} s | {r:.1f}× | {bl:.4g} | {ba:.4g} |")
    print(f"\nMedian ratio Adam / LM: **{ratio:.1f}×**.")


if __name__ == "__main__":
    main()
