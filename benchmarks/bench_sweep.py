"""``nnid sweep`` on the Cascaded Tanks NARX (``configs/cascaded_tanks_narx_sweep.toml``: 3
hidden sizes x 8 seeds), the full grid on local processes against Ray Tune with ASHA early
stopping, in one run; both choose on the holdout protocol of RESULTS.md (never on Val).

    python benchmarks/bench_sweep.py [--workers 2]

ASHA's grace period and reduction factor are the config's ``[sweep]`` ``grace_epochs`` and
``reduction_factor`` (printed in the record), not options of this script.

The table (experiments est_head, est_tail, val) is made from ../shared/data in a temporary
folder: the data set is read from there, never copied into the repository. Prints a JSON
record: wall times, trials stopped early, epochs run, each run's chosen setting, and the chosen
setting's Val RMSE (reported, not used to choose).
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import pandas as pd
from bench_nlbench import holdout_parts
from common import machine

from nnid.config import TrainConfig, load_config
from nnid.datasets.benchmarks import load_benchmark
from nnid.scale.engines import LocalEngine
from nnid.scale.sweep import run_sweep, run_sweep_tune

REPO = Path(__file__).resolve().parents[1]
CONFIG = REPO / "configs" / "cascaded_tanks_narx_sweep.toml"
DATA = REPO.parent / "shared" / "data"
HOLDOUT = 768  # the tail fold of benchmarks/bench_nlbench.py --holdout: train on Est 0-767


def make_table(folder: Path) -> Path:
    """Est head (training), Est tail with 50 warm-up samples (validation), Val (test)."""
    bench = load_benchmark("cascaded_tanks", DATA)
    head, tail = holdout_parts(bench.splits["train"], HOLDOUT, bench.warmup, "tail")
    parts = {"est_head": head, "est_tail": tail, "val": bench.splits["test"]}
    table = pd.concat([p.assign(experiment=name) for name, p in parts.items()], ignore_index=True)
    path = folder / "cascaded_tanks.csv"
    table.to_csv(path, index=False)
    return path


def chosen(out: Path, ranked) -> dict:
    """The chosen setting, its validation score and the Val RMSE of its seeds (V)."""
    best = ranked[0]
    test = []
    for row in best.rows:
        metrics = out / row["id"] / "metrics.json"
        if row["status"] == "ok" and metrics.is_file():
            rmse = json.loads(metrics.read_text())["test"]["free_run_rmse"]["y"]
            test.append(rmse)
    return {
        "setting": best.setting,
        "validation_nrmse_mean": best.mean,
        "seeds_scored": sum(s is not None for s in best.scores),
        "val_rmse_V_per_seed": test,
        "val_rmse_V_median": statistics.median(test) if test else None,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    spec = load_config(CONFIG, TrainConfig).sweep
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        table = str(make_table(root))
        runs = {}
        t0 = time.perf_counter()
        full, ranked = run_sweep(CONFIG, root / "full", LocalEngine(args.workers), data=table)
        runs["full grid, local processes"] = {
            "wall_s": time.perf_counter() - t0,
            "trials": len(full.rows),
            "failed": len(full.failed),
            "chosen": chosen(root / "full", ranked),
        }
        t0 = time.perf_counter()
        asha, ranked = run_sweep_tune(CONFIG, root / "asha", None, data=table,
                                      num_cpus=args.workers)  # fmt: skip
        early = asha.extra["sweep"]["early_stopping"]
        runs["Ray Tune, ASHA"] = {
            "wall_s": time.perf_counter() - t0,
            "trials": len(asha.rows),
            "stopped_early": early["stopped"],
            "epochs_run": early["epochs_run"],
            "failed": sum(r["status"] == "failed" for r in asha.rows),
            "chosen": chosen(root / "asha", ranked),
        }
        full_s = runs["full grid, local processes"]["wall_s"]
        runs["Ray Tune, ASHA"]["time_saved_vs_full_grid"] = (
            1 - runs["Ray Tune, ASHA"]["wall_s"] / full_s
        )
        import ray

        print(
            json.dumps(
                {
                    "machine": machine(ray=ray.__version__),
                    "date": time.strftime("%Y-%m-%d"),
                    "grid": spec.grid,
                    "seeds": spec.seeds,
                    "asha": {
                        "grace_epochs": spec.grace_epochs,
                        "reduction_factor": spec.reduction_factor,
                    },
                    "runs": runs,
                },
                indent=2,
            )
        )


if __name__ == "__main__":
    main()
