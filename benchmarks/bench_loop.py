"""Residual-loop speed (issue 7). Run by hand: ``python benchmarks/bench_loop.py``.

Target: the whole loop (split, Savitzky-Golay derivatives, baseline, every candidate of the
vocabulary with ~800 coupled damping terms, the 1-D searches, the free-run checks, the refit
and the before/after errors) on a 10-minute 50 Hz log in under 60 s. Baseline in the same run:
one weighted least-squares fit of the vehicle's damping structure on the same log (what a
user would run without the loop), so the ratio says what the diagnosis costs on top of it.
"""

from __future__ import annotations

import datetime
import os
import time
import warnings
from importlib import resources

import pysindy
import torch
from common import machine

from nnid.datasets.measurement import Measurement
from nnid.loop.residual_loop import ResidualLoop
from nnid.loop.scenarios import effect_log
from nnid.models.parametric import ParametricModel
from nnid.physics.parts import Parts
from nnid.trainers.least_squares import LeastSquares
from nnid.vehicle import load_vehicle

CASES = [("thruster_installation.w.neg", 0.6), ("current.y", 0.15), (None, 0.0)]


def main() -> None:
    warnings.simplefilter("ignore")
    vehicle = load_vehicle(str(resources.files("nnid.demo_data").joinpath("minirov.toml")))
    print(f"machine: {machine(torch=torch.__version__, pysindy=pysindy.__version__)}")
    print(f"date: {datetime.date.today()}, load average before: {os.getloadavg()[0]:.1f}")
    print("| injected effect | samples | baseline LS fit [s] | whole loop [s] | ratio | added |")
    print("|---|---|---|---|---|---|")
    for effect, value in CASES:
        effects = [(effect, value)] if effect else []
        log = effect_log(
            vehicle,
            effects,
            duration=600.0,
            dt=0.02,
            n_experiments=10,
            seed=7,
            measurement=Measurement(kind="dvl_imu"),
        )
        t0 = time.perf_counter()
        unknowns = list(Parts.from_vehicle(vehicle).damping)
        ParametricModel(vehicle, unknowns, trainer=LeastSquares(filter_lambda=1.0)).fit(log)
        base = time.perf_counter() - t0
        t0 = time.perf_counter()
        loop = ResidualLoop(vehicle).fit(log)
        whole = time.perf_counter() - t0
        added = ", ".join(f"{s.name} = {s.value:.4g}" for s in loop.added_) or "none"
        print(
            f"| {effect or 'none'} | {len(log)} | {base:.2f} | {whole:.1f} | "
            f"{whole / base:.0f}× | {added} |"
        )


if __name__ == "__main__":
    main()
