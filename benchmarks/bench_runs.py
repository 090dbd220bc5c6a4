"""Per-run preprocessing on a log cut into many runs. Run by hand:
``python benchmarks/bench_runs.py [--rows 200000] [--runs 2000]``.

A reader cuts a long log at every gap or restart, so one file can hold thousands of runs. The
steps that work run by run (``mask_gaps``, ``find_gaps``, ``derive_velocities``) must cost about
what the same rows cost as one run: the baseline in the same run is the same log with every row
in one experiment. Before they took each run's rows by position (``experiment_rows``), finding a
run's labels in the whole log cost rows × runs. Prints each step's best-of-three time on both
logs and their ratio (target: a few times at most; the per-run Savitzky-Golay edge fits of
``derive_velocities`` are a fixed cost per run).
"""

from __future__ import annotations

import argparse
import datetime

import numpy as np
import pandas as pd
from common import best_of, machine

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.gaps import find_gaps, mask_gaps
from nnid.datasets.preprocess import derive_velocities


def cut_log(rows: int, runs: int, seed: int = 0) -> pd.DataFrame:
    """``rows`` samples at 20 Hz of a random-walk pose with velocities, in ``runs`` runs of equal
    length, 60 five-sample gaps in u."""
    rng = np.random.default_rng(seed)
    per = rows // runs
    log = pd.DataFrame(
        {
            "experiment": np.repeat([f"r{k:05d}" for k in range(runs)], per),
            "t": np.tile(np.arange(per) * 0.05, runs),
        }
    )
    for c in ("x", "y", "z", "phi", "theta", "psi"):
        log[c] = np.cumsum(rng.normal(0.0, 0.01, len(log)))
    log[["phi", "theta"]] *= 0.1
    for c in ("u", "v", "w", "p", "q", "r"):
        log[c] = rng.normal(size=len(log))
    for g in rng.choice(len(log) - 5, 60, replace=False):
        log.loc[g : g + 4, "u"] = np.nan
    return log


def one_run(log: pd.DataFrame) -> pd.DataFrame:
    """The same rows as one experiment on one clock (the baseline)."""
    out = log.copy()
    out["experiment"] = "all"
    out["t"] = np.arange(len(out)) * 0.05
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=200_000)
    ap.add_argument("--runs", type=int, default=2_000)
    args = ap.parse_args()
    cut = cut_log(args.rows, args.runs)
    whole = one_run(cut)
    pose = cut.drop(columns=["u", "v", "w", "p", "q", "r"])
    steps = {
        "mask_gaps": lambda log: mask_gaps([log], ["u", "v", "r"], CleaningReport()),
        "find_gaps": lambda log: find_gaps(log, ["u", "v", "r"]),
        "derive_velocities": lambda log: derive_velocities(log),
    }
    print(f"machine: {machine(numpy=np.__version__, pandas=pd.__version__)}")
    print(f"date: {datetime.date.today()}")
    print(f"log: {args.rows:,} rows in {args.runs:,} runs (baseline: the same rows as one run)")
    for name, step in steps.items():
        logs = (pose, one_run(pose)) if name == "derive_velocities" else (cut, whole)
        t_cut = best_of(lambda log=logs[0], step=step: step(log))
        t_one = best_of(lambda log=logs[1], step=step: step(log))
        ratio = t_cut / t_one
        print(f"{name}: {t_cut:.3f} s in {args.runs:,} runs, {t_one:.3f} s as one: {ratio:.1f}x")


if __name__ == "__main__":
    main()
