"""Residual-loop speed (issue 7). Run by hand: ``python benchmarks/bench_loop.py``.

Target: the whole loop (split, Savitzky-Golay derivatives, baseline, every candidate of the
vocabulary with ~800 coupled damping terms, the 1-D searches, the free-run checks, the refit
and the before/after errors) on a 10-minute 50 Hz log in under 60 s. Baseline in the same run:
one weighted least-squares fit of the vehicle's damping structure on the same log (what a
user would run without the loop), so the ratio says what the diagnosis costs on top of it.

``python benchmarks/bench_loop.py refit [REPEATS]``: what the loop's refits cost (each builds
its regression and the columns' rounding floors afresh) on the demo's loop and the curated
BlueROV1 study (``configs/bluerov1_liu_loop.toml``, where ../shared/data holds its log): CPU
seconds (``time.process_time``), the median of REPEATS fits after a first one, of the whole
fit, of its refits, of the regressions they build, of the floors, of the builds that repeat one
already made in the same fit (all that a cache of them could save), and of the screen's
excitation check.
"""

from __future__ import annotations

import datetime
import hashlib
import os
import sys
import time
import warnings
from collections.abc import Callable
from importlib import resources
from pathlib import Path

import numpy as np
import pysindy
import torch
from common import machine

import nnid.loop.diagnose as diagnose
import nnid.loop.residual_loop as residual_loop
import nnid.runs as runs
from nnid.datasets.measurement import Measurement
from nnid.loop.residual_loop import ResidualLoop
from nnid.loop.scenarios import effect_log
from nnid.models.parametric import ParametricFossen, ParametricModel
from nnid.physics.parts import Parts
from nnid.trainers.least_squares import LeastSquares
from nnid.vehicle import load_vehicle

CASES = [("thruster_installation.w.neg", 0.6), ("current.y", 0.15), (None, 0.0)]
REPO = Path(__file__).resolve().parents[1]
BLUEROV1 = REPO / "configs" / "bluerov1_liu_loop.toml"
LIU = REPO.parent / "shared" / "data" / "liu-bluerov1-2016"  # the study's log


def loop_inputs(case: str) -> tuple:
    """(log, vehicle, ResidualLoop settings) of the demo's loop or of ``nnid loop`` on the
    BlueROV1 study's config: that command's own loading, stopped where the loop would start."""
    if case == "demo":
        from nnid.datasets.readers import load_log

        root = resources.files("nnid.demo_data")
        log, _ = load_log(str(root.joinpath("demo_minirov_heave.parquet")))
        return log, load_vehicle(str(root.joinpath("minirov.toml"))), {}
    from nnid.config import LoopConfig, load_config

    class Taken(Exception):
        """The loop's inputs, where the command would start it."""

    def take(log, vehicle, out_dir, *args, **settings) -> None:
        raise Taken(log, vehicle, settings)

    real, runs.residual_loop_run = runs.residual_loop_run, take
    try:
        runs.loop_run(load_config(BLUEROV1, LoopConfig), BLUEROV1, Path("unused"))
    except Taken as taken:
        return taken.args
    finally:
        runs.residual_loop_run = real
    raise RuntimeError("nnid loop returned without running the loop")


def timed(owner: object, name: str, spent: dict, key: str, after: Callable | None = None) -> None:
    """Replace ``owner.name`` by a wrapper adding its CPU seconds to ``spent[key]`` (and a call
    to ``spent[key + ' calls']``); ``after(args, result, seconds)`` runs outside the clock."""
    inner = getattr(owner, name)

    def wrapper(*args, **kwargs):
        start = time.process_time()
        result = inner(*args, **kwargs)
        seconds = time.process_time() - start
        spent[key] = spent.get(key, 0.0) + seconds
        spent[key + " calls"] = spent.get(key + " calls", 0) + 1
        if after is not None:
            after(args, result, seconds)
        return result

    setattr(owner, name, wrapper)


def refit_share(repeats: int) -> None:
    """The ``refit`` mode's table (the module docstring), one row a loop."""
    spent: dict = {}
    inside = [0]  # refit calls under way: a regression built there is one of its own
    built: set = set()

    def enter(owner: object, name: str) -> None:
        inner = getattr(owner, name)

        def wrapper(*args, **kwargs):
            inside[0] += 1
            try:
                return inner(*args, **kwargs)
            finally:
                inside[0] -= 1

        setattr(owner, name, wrapper)

    def seen(args, reg, seconds) -> None:  # a refit's build; "repeated": as one before
        if not inside[0]:
            return
        spent["builds"] = spent.get("builds", 0.0) + seconds
        key = hashlib.sha1(reg.phi.tobytes() + reg.y.tobytes() + str(reg.names).encode())
        if key.digest() in built:
            spent["repeated"] = spent.get("repeated", 0.0) + seconds
        built.add(key.digest())

    enter(diagnose, "refit")
    timed(diagnose, "refit", spent, "refit")
    residual_loop.refit = diagnose.refit  # the loop's own name for it
    timed(diagnose, "_regression", spent, "regression", seen)
    timed(ParametricFossen, "rounding_floors", spent, "floors")
    timed(diagnose.CandidateExcitation, "__init__", spent, "check")
    timed(diagnose.CandidateExcitation, "excited", spent, "check")
    print(f"machine: {machine(torch=torch.__version__, pysindy=pysindy.__version__)}")
    print(f"date: {datetime.date.today()}, load average before: {os.getloadavg()[0]:.1f}")
    print(f"CPU seconds, median of {repeats} fits after a first; share of the whole fit")
    print("| loop | samples | whole fit | refits (calls) | their regressions | floors | "
          "rebuilt as before (a cache's saving) | screen's excitation check |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for case in ("demo", "bluerov1"):
        if case == "bluerov1" and not LIU.is_dir():
            print(f"| BlueROV1 study | {LIU} is absent: not run | | | | | | |")
            continue
        log, vehicle, settings = loop_inputs(case)
        warnings.simplefilter("ignore")
        rows = []
        for k in range(repeats + 1):
            spent.clear()
            built.clear()
            start = time.process_time()
            ResidualLoop(vehicle, **settings).fit(log)
            if k:  # the first fit warms caches and compiled kernels
                rows.append({**spent, "fit": time.process_time() - start})
        keys = {key for r in rows for key in r}
        med = {key: float(np.median([r.get(key, 0.0) for r in rows])) for key in keys}
        cells = [share(med, key) for key in ("refit", "builds", "floors", "repeated", "check")]
        cells[0] += f" ({med['refit calls']:.0f})"
        name = "demo" if case == "demo" else "BlueROV1 study"
        print(f"| {name} | {len(log)} | {med['fit']:.2f} | " + " | ".join(cells) + " |")


def share(med: dict, key: str) -> str:
    """``med[key]`` seconds and its share of the whole fit's, ``med['fit']``."""
    return f"{med.get(key, 0.0):.3f} ({100 * med.get(key, 0.0) / med['fit']:.1f} %)"


def main() -> None:
    if sys.argv[1:2] == ["refit"]:
        refit_share(int(sys.argv[2]) if len(sys.argv) > 2 else 5)
        return
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
