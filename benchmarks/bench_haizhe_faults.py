"""Real faults: the residual monitor on the Haizhe AUV fault set (issue 16).

Run by hand: ``python benchmarks/bench_haizhe_faults.py``; it reads
../shared/data/haizhe-auv-fault-2021.

Protocol (unsupervised): the Fossen model of configs/vehicles/haizhe.toml (heave, roll, pitch and
yaw equations; damping, thrust gain, buoyancy, constant moments and the centre of gravity fitted;
the assumed inertia fixes the scale) is fitted on every other Normal run of the authors' TRAINING
split, the monitor calibrated on the remaining Normal training runs, and nothing else is seen
before the test split. On the test split each run gets the score max over the run of
max(T / h_T, g / h_g) (an alarm when it exceeds 1); per fault class against the Normal test runs:
the ROC AUC of that score (scikit-learn) and the detection rate at the calibrated threshold, and
the effects the isolation names for the alarms it raises. A second table checks the set itself:
the ROC AUC of single per-run summaries (mean command, mean pitch, ...) that no physical fault
of the class should move.
"""

from __future__ import annotations

import sys
import warnings
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.metrics import roc_auc_score

from nnid.datasets.readers import load_log
from nnid.fault.detect import isolated_alarm
from nnid.fault.isolation import isolate
from nnid.fault.monitor import ResidualMonitor, monitor_inputs
from nnid.models.parametric import ParametricModel
from nnid.trainers.least_squares import LeastSquares
from nnid.vehicle import load_vehicle

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data" / "haizhe-auv-fault-2021"
COLUMNS = ["t", "experiment", "z", "phi", "theta", "psi", "cmd_1", "cmd_2", "cmd_3", "cmd_4"]
DOFS = ["w", "p", "q", "r"]
UNKNOWNS = ["Z:w", "Z:w*abs(w)", "eta.w.pos", "buoyancy", "K:p", "M:q", "N:r",
            "external_bias.p", "external_bias.q", "external_bias.r", "r_g.z"]  # fmt: skip


def auc_table(score: pd.Series, label: pd.Series) -> dict[str, float]:
    out = {}
    for c in sorted(set(label) - {"Normal"}):
        idx = label[label.isin([c, "Normal"])].index
        out[c] = float(roc_auc_score((label[idx] == c).astype(int), score[idx]))
    return out


def main() -> None:
    if not DATA.is_dir():
        sys.exit(f"{DATA} not found")
    log, _ = load_log(DATA, REPO / "configs" / "readers" / "haizhe_auv_fault.toml")
    parts = log["experiment"].str.split("/")
    split, label = parts.str[0], parts.str[1].str.rsplit("_", n=1).str[0]
    runs = pd.DataFrame({"split": split, "label": label, "experiment": log["experiment"]})
    runs = runs.drop_duplicates("experiment").set_index("experiment")
    normal = sorted(runs.index[(runs["split"] == "train") & (runs["label"] == "Normal")])
    veh = load_vehicle(REPO / "configs" / "vehicles" / "haizhe.toml")
    # rates from the attitude (the gyro has glitches up to 1,290 deg/s; the card)
    data = log[COLUMNS]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model = ParametricModel(
            veh, UNKNOWNS, DOFS, trainer=LeastSquares(filter_lambda=2.0), zoh_midpoint=True,
            savgol_window=0.5,
        ).fit(data[data["experiment"].isin(normal[::2])])  # fmt: skip
        monitor = ResidualMonitor(model, time_constant_s=0.5, rearm_s=2.0)
        monitor.fit(data[data["experiment"].isin(normal[1::2])])
    print("fitted:", {k: round(v["value"], 3) for k, v in model.params.items()})
    print("warnings:", sorted({str(w.message)[:90] for w in caught}))
    h_t, h_g = monitor.threshold_values
    print(
        f"thresholds T {h_t:.3g}, g {h_g:.3g}; calibrated on {monitor.calibration_['hours']:.3f} h"
    )
    test = data[data["experiment"].isin(runs.index[runs["split"] == "test"])]
    trace = monitor.run(test)
    frame = trace.frame()
    frame["s"] = np.maximum(frame["T"] / h_t, frame["g"] / h_g)
    score = frame.groupby("experiment")["s"].max()
    lab = runs.loc[score.index, "label"]
    aucs = auc_table(score, lab)
    arrays = monitor_inputs(test, monitor.plant_)
    named: dict[str, Counter] = {c: Counter() for c in sorted(set(lab))}
    for k in np.flatnonzero(trace.alarm):
        a = isolated_alarm(monitor, arrays, trace, int(k), 5.0)[0]
        named[runs.loc[a["experiment"], "label"]][a["effect"] or a["thruster"] or a["kind"]] += 1
    # the diagnosis of every run, alarm or not: what the isolation names on the run after its
    # first 2 s (the surface exit), as if an alarm had been raised there
    diagnosed: dict[str, Counter] = {c: Counter() for c in sorted(set(lab))}
    for name in score.index:
        rows = np.flatnonzero(
            (trace.experiment == name) & (trace.t >= trace.t[trace.experiment == name].min() + 2.0)
        )
        if rows.size < 20:
            continue
        d = isolate(monitor, arrays, trace.values[:, 0:6], rows)
        diagnosed[lab[name]][d.effect or d.thruster or d.kind] += 1
    normal_fa = float((score[lab == "Normal"] > 1).mean())
    print(f"Normal test runs with an alarm: {normal_fa:.3f} ({(lab == 'Normal').sum()} runs)")
    print(
        "| class | runs | ROC AUC (max statistic) | detected at the calibrated threshold | named |"
    )
    print("|---|---|---|---|---|")
    for c in sorted(set(lab)):
        rate = float((score[lab == c] > 1).mean())
        top = ", ".join(f"{k} ×{n}" for k, n in named[c].most_common(3)) or "-"
        auc = f"{aucs[c]:.3f}" if c in aucs else "-"
        print(f"| {c} | {(lab == c).sum()} | {auc} | {rate:.3f} | {top} |")
    g = log[log["t"] >= 2.0].groupby("experiment")
    summaries = {
        "mean command": g["cmd_1"].mean(),
        "mean depth": g["z"].mean(),
        "mean roll": g["phi"].mean(),
        "mean pitch": g["theta"].mean(),
        "median gyro yaw rate": g["r"].median(),
        "mean battery voltage": g["voltage"].mean(),
    }
    test_runs = runs.index[runs["split"] == "test"]
    print("| class | what the isolation names on each whole run (2 s on), most frequent first |")
    print("|---|---|")
    for c in sorted(set(lab)):
        top = ", ".join(f"{k} ×{n}" for k, n in diagnosed[c].most_common(4))
        print(f"| {c} | {top} |")
    print("| per-run summary | " + " | ".join(sorted(set(lab) - {"Normal"})) + " |")
    print("|---|" + "---|" * (len(set(lab)) - 1))
    for name, s in summaries.items():
        a = auc_table(s[test_runs], runs.loc[test_runs, "label"])
        print(f"| {name} | " + " | ".join(f"{max(v, 1 - v):.2f}" for v in a.values()) + " |")


if __name__ == "__main__":
    main()
