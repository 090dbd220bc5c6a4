"""What the Seamor simulator's own model scores on the NARX configs' held-out runs (issue 14,
round 23): the floor the free-run protocol puts under any model of these data.

Builds the data of ``configs/seamor_narx_lm.toml`` (the noisy motion-capture log, 1 % white
noise on forces and velocities) and flies the ``seamor`` preset, the vehicle that simulated
the log (Weiss Table 3 truth), over the validation and test runs: a free run from each run's
first sample driven by the logged forces, scored as ``metrics.json`` scores a run (the
free-run NRMSE of u, v and r after the config's warm-up, over the run's own std). Three
starts: the measured state (what every model gets), the true state (``true_*`` columns), and
the true state with only the velocities u, v, w measured.

Run: ``python benchmarks/bench_seamor_truth_floor.py`` (about a minute, most of it simulating
the log); ``--all-runs`` scores the training runs too (among them the sequence's surge-sway and
surge-sway-yaw, the issue's own held-out runs before the configs moved them into training).
"""

from __future__ import annotations

import argparse
from datetime import date
from pathlib import Path

import numpy as np
from common import machine

from nnid.config import TrainConfig, load_config
from nnid.datasets.log import POSE, TAU, VELOCITY
from nnid.evaluation.evaluate import score_prediction, scored_rows
from nnid.evaluation.prediction import predict_states
from nnid.physics.parts import Parts
from nnid.pipeline import load_inputs, make_split
from nnid.vehicle import load_vehicle

CONFIG = Path(__file__).resolve().parents[1] / "configs" / "seamor_narx_lm.toml"
STATE = POSE + VELOCITY
SCORED = ["u", "v", "r"]


def free_run_nrmse(
    parts: Parts, run, start: dict[str, float], warmup_s: float
) -> dict[str, float | None]:
    """NRMSE of u, v, r of the free run from ``start`` (the first row's state), after the
    warm-up, each over the run's own std of the measured output, by ``score_prediction`` (the
    scoring behind ``metrics.json``: None for an output whose free run diverged)."""
    run = run.copy()
    first = run.index[0]
    for name, value in start.items():
        run.loc[first, name] = value
    tau = run[list(TAU)].to_numpy(np.float64)
    pred = predict_states(parts, run, tau, "free_run")
    nrmse, _, _ = score_prediction(run, pred, SCORED, scored_rows(run, warmup_s, 1))
    return nrmse


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--all-runs", action="store_true", help="score the training runs too")
    args = parser.parse_args()
    cfg = load_config(CONFIG, TrainConfig)
    inputs = load_inputs(cfg, CONFIG, [cfg.model])
    split = make_split(inputs.log, cfg.split, str(CONFIG), inputs.report)
    parts = Parts.from_vehicle(load_vehicle("seamor"))
    print(f"Machine: {machine()}. Date: {date.today()}. Config: {CONFIG.name}")
    print("| run | start | u | v | r |\n|---|---|---|---|---|")
    for part in ("validation", "test", *(["train"] if args.all_runs else [])):
        log = getattr(split, part)
        for name, run in log.groupby("experiment", sort=False):
            row0 = run.iloc[0]
            true = {s: float(row0[f"true_{s}"]) for s in STATE}
            starts = {
                "measured": {},
                "true": true,
                "true, u v w measured": {**true, **{s: float(row0[s]) for s in "uvw"}},
            }
            for label, start in starts.items():
                scores = free_run_nrmse(parts, run, start, float(cfg.warmup_s))
                cells = " | ".join(
                    "diverged" if scores[s] is None else f"{scores[s]:.3f}" for s in SCORED
                )
                print(f"| {name} ({part}) | {label} | {cells} |", flush=True)


if __name__ == "__main__":
    main()
