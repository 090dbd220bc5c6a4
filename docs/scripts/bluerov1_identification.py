"""Regenerate the tables of docs/bluerov1_identification.md (issue 4: BlueROV 1 on real data).

    python docs/scripts/bluerov1_identification.py            # print the tables (markdown)
    python docs/scripts/bluerov1_identification.py --write    # also replace them in the doc

Reads ../shared/data/liu-bluerov1-2016 through configs/bluerov1_liu_ls.toml; nothing from it is
written into the repository (the cut runs pass through a temporary file outside it). Library code
only: the fit is ``nnid.pipeline.run_train`` on that config, the predictions are
``nnid.evaluation.prediction.predict_states`` for the identified parts and for
``Parts.from_vehicle`` of the vehicle file as it is (the thesis model).

Evaluation protocol (why it is not the pipeline's own free-run score):

- Runs are cut at their last logged thruster command (:func:`commanded_ends`): the command stream
  stops 0.1-3.9 s before the end of most runs while the vehicle coasts to rest, and the reader
  would hold the last command over that tail. Fit and scores use the cut runs.
- Attitude (p q r): u, v, w are not measured and the vehicle file has no surge/sway/heave damping
  (the thesis identified none), so a simulation driven by the translational thrust runs away in
  u and v and feeds back into p q r through the Munk and Coriolis terms. The attitude models are
  scored decoupled from translation: the translational forces are
  removed and u = v = w = 0 throughout (exactly, since B = W and r_g = 0: with zero linear
  velocity the rotational equations do not involve it). A DOF is scored on a run only when that
  run's thrusters drive its moment (yaw_*: r; pitch_roll_*: p, q; all_*: p, q, r).
- Heave (w): only on the level yaw_* runs, where w = z_dot / (cos theta cos phi) is defined;
  surge and sway forces removed, w starts from that estimate.
- Modes: one step (20 ms), k steps of 0.5 s and 1 s from the measured state, and free run from
  the first sample; the first ``warmup_s`` of each run is not scored. "persistence" predicts
  the value measured k steps earlier (the no-model baseline for k-step scores).
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "configs" / "bluerov1_liu_ls.toml"
DOC = REPO / "docs" / "bluerov1_identification.md"
BEGIN, END = "<!-- generated:begin -->", "<!-- generated:end -->"
MODES = ("one_step", 25, 50, "free_run")
MODE_NAMES = {"one_step": "one step", 25: "0.5 s", 50: "1 s", "free_run": "free run"}
LAMBDAS = (1.0, 2.0, 5.0, 10.0, 20.0)


def short(name: str) -> str:
    """``yaw_3_2016-04-18-13-50-03`` -> ``yaw_3``."""
    return re.sub(r"_\d{4}-\d{2}-\d{2}-.*$", "", name)


def setup():
    from nnid.config import TrainConfig, load_config
    from nnid.vehicle import load_vehicle

    cfg = load_config(CONFIG, TrainConfig)
    data = (CONFIG.parent / cfg.data.log).resolve()
    if not data.is_dir():
        raise SystemExit(f"{data} is absent: this script needs ../shared/data/liu-bluerov1-2016")
    return cfg, load_vehicle(CONFIG.parent / cfg.vehicle)


def commanded_ends(cfg) -> dict[str, float]:
    """Per run, the time (on the reader's grid) of the last logged thruster command: the same
    reader config read with every source interpolated, so that the commands bound the window
    as the measurements do."""
    from nnid.datasets.column_map import load_column_map
    from nnid.datasets.readers import read_mapped

    cmap = load_column_map(CONFIG.parent / cfg.data.columns)
    bounded = cmap.model_copy(
        update={"sources": [s.model_copy(update={"method": "linear"}) for s in cmap.sources]}
    )
    log, _ = read_mapped(bounded, CONFIG.parent / cfg.data.log)
    return log.groupby("experiment")["t"].max().to_dict()


def load_runs(cfg) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, float]]:
    """The config's runs as read, and cut at their last command."""
    from nnid.datasets.readers import load_log

    full, _ = load_log(CONFIG.parent / cfg.data.log, CONFIG.parent / cfg.data.columns)
    full = full[full["experiment"].isin(cfg.data.experiments)].reset_index(drop=True)
    ends = commanded_ends(cfg)
    keep = full["t"].to_numpy() <= full["experiment"].map(ends).to_numpy() + 1e-9
    return full, full[keep].reset_index(drop=True), ends


def fit(cfg, vehicle, log: pd.DataFrame | None = None, **update):
    """``run_train`` on the config (``update`` replaces fields of its model), on ``log`` if
    given (through a temporary Parquet file outside the repository)."""
    from nnid.config import VehicleData
    from nnid.pipeline import run_train

    cfg = cfg.model_copy(update={"model": cfg.model.model_copy(update=update)})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if log is None:
            return run_train(cfg, CONFIG)
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "runs.parquet"
            log.to_parquet(path)
            data = VehicleData(
                log=str(path),
                savgol_window=cfg.data.savgol_window,
                savgol_order=cfg.data.savgol_order,
            )
            return run_train(cfg.model_copy(update={"data": data}), CONFIG)


def driven(log: pd.DataFrame, vehicle) -> list[str]:
    """The rotational DOFs whose input moment varies in this run."""
    from nnid.datasets.arrays import log_arrays

    tau = log_arrays(log, vehicle)["tau"]
    return [d for k, d in zip((3, 4, 5), "pqr", strict=True) if np.std(tau[:, k]) > 1e-9]


def predict(parts, log: pd.DataFrame, vehicle, mode, zero: tuple[int, ...]) -> pd.DataFrame:
    from nnid.datasets.arrays import log_arrays
    from nnid.evaluation.prediction import predict_states

    tau = log_arrays(log, vehicle)["tau"].copy()
    tau[:, list(zero)] = 0.0
    return predict_states(parts, log, tau, mode)


def persistence(log: pd.DataFrame, column: str, mode) -> np.ndarray:
    y = log[column].to_numpy()
    if mode == "free_run":
        return np.full_like(y, y[0])
    k = 1 if mode == "one_step" else mode
    return np.concatenate([y[:k], y[:-k]])


def score_runs(models: dict, runs: pd.DataFrame, vehicle, warmup_s: float) -> list[dict]:
    """NRMSE rows (run, dof, mode, model -> value) of the attitude protocol."""
    from nnid.evaluation.metrics import nrmse, warmup_mask

    rows = []
    for name, g in runs.groupby("experiment", sort=False):
        g = g.drop(columns=[c for c in "uvw" if c in g]).reset_index(drop=True)
        mask = warmup_mask(g, warmup_s, warmup_samples=1)
        dofs = driven(g, vehicle)
        for mode in MODES:
            preds = {m: predict(p, g, vehicle, mode, (0, 1, 2)) for m, p in models.items()}
            for d in dofs:
                y = g[d].to_numpy()[mask]
                row = {"run": name, "dof": d, "mode": mode}
                row |= {m: nrmse(y, pr[d].to_numpy()[mask]) for m, pr in preds.items()}
                row["persistence"] = nrmse(y, persistence(g, d, mode)[mask])
                rows.append(row)
    return rows


def score_heave(models: dict, runs: pd.DataFrame, vehicle, cfg) -> list[dict]:
    """NRMSE of w on the level (yaw_*) runs, w from the depth rate."""
    from nnid.datasets.preprocess import derive_velocities
    from nnid.evaluation.metrics import nrmse, warmup_mask

    rows = []
    for name, g in runs.groupby("experiment", sort=False):
        if not short(name).startswith("yaw"):
            continue
        g = derive_velocities(
            g.reset_index(drop=True), cfg.data.savgol_window, cfg.data.savgol_order
        )
        mask = warmup_mask(g, cfg.warmup_s, warmup_samples=1)
        y = g["w"].to_numpy()[mask]
        for mode in MODES:
            row = {"run": name, "dof": "w", "mode": mode}
            for m, p in models.items():
                row[m] = nrmse(y, predict(p, g, vehicle, mode, (0, 1))["w"].to_numpy()[mask])
            row["persistence"] = nrmse(y, persistence(g, "w", mode)[mask])
            rows.append(row)
    return rows


# --- markdown --------------------------------------------------------------------------------


def f3(x) -> str:
    return "—" if x is None or not np.isfinite(x) else f"{x:.3f}"


def sig(x, se=None) -> str:
    if x is None or not np.isfinite(x):
        return "—"
    return f"{x:.4g}" if se is None else f"{x:.4g} ± {se:.2g}"


def data_table(cfg, full, cut, ends) -> str:
    s = cfg.split
    parts = [("train", s.train), ("validation", s.validation), ("test", s.test)]
    lines = [
        "| split | run | kind | length read (s) | cut at last command (s) | tail removed (s) |"
    ]
    lines.append("|---|---|---|---|---|---|")
    kinds = {"yaw": "thrusters 3, 4", "pitch": "thrusters 1, 2, 5, 6", "all": "all six"}
    for part, names in parts:
        for n in names:
            t_full = float(full.loc[full.experiment == n, "t"].max())
            t_cut = float(cut.loc[cut.experiment == n, "t"].max())
            kind = kinds[short(n).split("_")[0]]
            lines.append(
                f"| {part} | `{short(n)}` | {kind} | {t_full:.1f} | {t_cut:.1f} | "
                f"{t_full - t_cut:.1f} |"
            )
    total = {p: sum(float(cut.loc[cut.experiment == n, "t"].max()) for n in ns) for p, ns in parts}
    lines.append("")
    lines.append("Cut durations: " + ", ".join(f"{p} {v:.1f} s" for p, v in total.items()) + ".")
    return "\n".join(lines)


def param_table(res, res_full, vehicle) -> str:
    from nnid.physics.parts import Parts

    thesis = Parts.from_vehicle(vehicle)
    p, pf = res.metrics["params"], res_full.metrics["params"]
    lines = [
        "| parameter | identified (cut runs) ± stderr | significant (95 %) | thesis (vehicle file) "
        "| identified on the reader's runs (`nnid train`) |",
        "|---|---|---|---|---|",
    ]
    for name, e in p.items():
        lines.append(
            f"| `{name}` | {sig(e['value'], e['stderr'])} | {'yes' if e['significant'] else 'no'} "
            f"| {sig(thesis.get(name))} | {sig(pf[name]['value'], pf[name]['stderr'])} |"
        )
    # lumped inertias, the quantities the thesis identified (A_p = Ix - K_pdot, ...)
    inertia = np.diag(vehicle.inertia_matrix())
    lumped = []
    for k, (d, key) in enumerate((("p", "K_pdot"), ("q", "M_qdot"), ("r", "N_rdot"))):
        a_id = inertia[k] - p[key]["value"]
        a_th = inertia[k] - thesis.get(key)
        lumped.append(f"{d}: {a_id:.3f} (thesis {a_th:.4f})")
    lines.append("")
    lines.append(
        "Lumped inertia I − (added mass), kg m², identified vs thesis: " + "; ".join(lumped) + "."
    )
    return "\n".join(lines)


def nrmse_table(rows: list[dict], models: list[str], runs: list[str]) -> str:
    head = "| run | DOF | " + " | ".join(f"{MODE_NAMES[m]}: {' / '.join(models)}" for m in MODES)
    lines = [head + " |", "|---|---|" + "---|" * len(MODES)]
    table = pd.DataFrame(rows)
    for run in runs:
        sub = table[table.run == run]
        for d in dict.fromkeys(sub.dof):
            cells = []
            for m in MODES:
                r = sub[(sub.dof == d) & (sub["mode"].astype(str) == str(m))].iloc[0]
                vals = [r[x] for x in models]
                best = int(np.nanargmin(vals[:2])) if f3(vals[0]) != f3(vals[1]) else -1
                txt = [f"**{f3(v)}**" if i == best else f3(v) for i, v in enumerate(vals)]
                cells.append(" / ".join(txt))
            lines.append(f"| `{short(run)}` | {d} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def summary_table(rows: list[dict], runs: list[str]) -> str:
    """Mean NRMSE over the given runs per DOF and mode: identified, thesis, persistence."""
    table = pd.DataFrame(rows)
    table = table[table.run.isin(runs)]
    lines = [
        "| DOF | runs | "
        + " | ".join(f"{MODE_NAMES[m]}: ident / thesis / persist." for m in MODES)
        + " |",
        "|---|---|" + "---|" * len(MODES),
    ]
    for d in ("p", "q", "r", "w"):
        sub = table[table.dof == d]
        if sub.empty:
            continue
        cells = []
        for m in MODES:
            s = sub[sub["mode"].astype(str) == str(m)]
            cells.append(
                f"{f3(s['identified'].mean())} / {f3(s['thesis'].mean())} / "
                f"{f3(s['persistence'].mean())}"
            )
        names = ", ".join(short(n) for n in dict.fromkeys(sub.run))
        lines.append(f"| {d} | {names} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def equation_table(models: dict, runs: pd.DataFrame, vehicle, cfg) -> str:
    """RMS of the filtered equation error (the quantity least squares minimises), N m, per
    held-out run and driven DOF, after the filters settle (3/λ s)."""
    from nnid.datasets.arrays import log_arrays
    from nnid.models.parametric import ParametricFossen

    lam = float(cfg.model.trainer.filter_lambda)
    structure = ParametricFossen(vehicle, [], ("p", "q", "r"))
    lines = [
        "| run | DOF | " + " | ".join(f"{m} (N m)" for m in models) + " |",
        "|---|---|" + "---|" * len(models),
    ]
    for name, g in runs.groupby("experiment", sort=False):
        g = g.drop(columns=[c for c in "uvw" if c in g]).reset_index(drop=True)
        data = log_arrays(g, vehicle)
        keep = g["t"].to_numpy() >= 3.0 / lam
        res = {m: structure.equation_residual(p, data, lam)[keep] for m, p in models.items()}
        for d in driven(g, vehicle):
            k = 3 + "pqr".index(d)
            vals = [float(np.sqrt(np.mean(r[:, k] ** 2))) for r in res.values()]
            lines.append(f"| `{short(name)}` | {d} | " + " | ".join(f3(v) for v in vals) + " |")
    return "\n".join(lines)


def lambda_table(cfg, vehicle, cut) -> str:
    """Validation 1 s-ahead NRMSE (attitude protocol) for each filter bandwidth."""
    val = cut[cut.experiment.isin(cfg.split.validation)]
    lines = ["| λ (rad/s) | mean 1 s-ahead NRMSE on the validation runs |", "|---|---|"]
    for lam in LAMBDAS:
        trainer = cfg.model.trainer.model_copy(update={"filter_lambda": lam})
        res = fit(cfg, vehicle, cut, trainer=trainer)
        rows = [
            r
            for r in score_runs({"identified": res.model.parts_}, val, vehicle, cfg.warmup_s)
            if r["mode"] == 50
        ]
        chosen = " (chosen)" if lam == cfg.model.trainer.filter_lambda else ""
        lines.append(f"| {lam:g}{chosen} | {np.mean([r['identified'] for r in rows]):.3f} |")
    return "\n".join(lines)


def data_facts(cfg, full, cut) -> str:
    """The facts the prose relies on: command message interval, attitude range of the level
    runs, size of the depth-rate w estimate in the tumbling runs, cut vs uncut fit."""
    from nnid.datasets.column_map import load_column_map
    from nnid.datasets.preprocess import derive_velocities

    cmap = load_column_map(CONFIG.parent / cfg.data.columns)
    source = next(s for s in cmap.sources if s.method == "hold")
    raw = pd.read_csv(CONFIG.parent / cfg.data.log / source.file)
    raw = raw[raw[cmap.experiment].isin(set(cut.experiment))]
    step = raw.groupby(cmap.experiment)[source.time].diff().dropna()
    level = cut[cut.experiment.map(short).str.startswith("yaw")]
    tumbling = cut[~cut.experiment.map(short).str.startswith("yaw")]
    w = derive_velocities(tumbling, cfg.data.savgol_window, cfg.data.savgol_order)["w"]
    return (
        f"Thruster command messages: median interval {step.median():.3f} s "
        f"(95th percentile {step.quantile(0.95):.3f} s) over the {raw[cmap.experiment].nunique()} "
        f"runs. Level yaw_* runs: max |θ| {level.theta.abs().max():.2f} rad, max |φ| "
        f"{level.phi.abs().max():.2f} rad. Tumbling runs: max |φ| {tumbling.phi.abs().max():.2f} "
        f"rad, max |θ| {tumbling.theta.abs().max():.2f} rad; the depth-rate estimate "
        f"ż/(cos θ cos φ) reaches |w| = {w.abs().max():.3g} m/s "
        f"(median |w| {w.abs().median():.2f} m/s)."
    )


def shift_table(res, res_full) -> str:
    """Cut minus uncut fit, in standard errors of the cut fit."""
    p, pf = res.metrics["params"], res_full.metrics["params"]
    cells = [
        f"{k} {(pf[k]['value'] - v['value']) / v['stderr']:+.1f}σ"
        for k, v in p.items()
        if v["stderr"]
    ]
    return (
        "Reader's runs (0.5 s hold timeout) − cut fit, in standard errors of the cut fit: "
        + ", ".join(cells)
        + "."
    )


def heave_fit(cfg, vehicle, cut) -> str:
    """The heave equation fitted on the level training runs: the degenerate answer."""
    from nnid.config import SequenceStep

    yaw = [n for n in cfg.split.train if short(n).startswith("yaw")]
    step = SequenceStep(experiments=yaw, dofs=["w"], unknowns=["Z_wdot", "Z:w", "Z:w*abs(w)"])
    res = fit(cfg, vehicle, cut, sequence=[step])
    p = res.metrics["params"]
    vals = ", ".join(f"`{k}` = {sig(v['value'])}" for k, v in p.items())
    heave_mass = vehicle.mass - p["Z_wdot"]["value"]
    return (
        f"Heave equation alone on {', '.join(short(n) for n in yaw)} (w from the depth rate, "
        f"unknowns Z_wdot, Z:w, Z:w·|w|): {vals}. Heave mass m − Z_wdot = {heave_mass:.3g} kg "
        f"(m = {vehicle.mass:g} kg)."
    )


def coupled_note(res) -> str:
    """``run_train``'s validation free run: every force applied, u v w free (and undamped)."""
    val = res.metrics["validation"]
    free = ", ".join(f"{d} {f3(v)}" for d, v in val["free_run_nrmse"].items() if d != "total")
    one = ", ".join(f"{d} {f3(v)}" for d, v in val["one_step_nrmse"].items() if d != "total")
    return (
        f"`run_train` validation (all forces applied, u v w integrated without damping): "
        f"free-run NRMSE {free}; one-step {one}."
    )


def build() -> str:
    from nnid.physics.parts import Parts

    cfg, vehicle = setup()
    full, cut, ends = load_runs(cfg)
    res = fit(cfg, vehicle, cut)
    res_full = fit(cfg, vehicle)
    models = {"identified": res.model.parts_, "thesis": Parts.from_vehicle(vehicle)}
    held = [*cfg.split.validation, *cfg.split.test]
    runs = cut[cut.experiment.isin(held)]
    rows = score_runs(models, runs, vehicle, cfg.warmup_s)
    rows += score_heave(models, runs, vehicle, cfg)
    order = [n for n in held if n in set(runs.experiment)]
    out = [
        "### Runs",
        data_table(cfg, full, cut, ends),
        "### Parameters",
        param_table(res, res_full, vehicle),
        shift_table(res, res_full),
        "### NRMSE on the test runs (mean over the runs that drive each DOF)",
        summary_table(rows, list(cfg.split.test)),
        "### NRMSE on the validation runs (mean)",
        summary_table(rows, list(cfg.split.validation)),
        "### NRMSE per held-out run (identified / thesis / persistence; bold: the better "
        "of the two models where they differ at three decimals)",
        nrmse_table(rows, ["identified", "thesis", "persistence"], order),
        "### Filtered equation error on the held-out runs (what least squares minimises)",
        equation_table(models, runs, vehicle, cfg),
        "### Filter bandwidth (validation only)",
        lambda_table(cfg, vehicle, cut),
        "### Heave check",
        heave_fit(cfg, vehicle, cut),
        "### Data facts used in the text",
        data_facts(cfg, full, cut),
        "### The pipeline's own validation score (translation coupled, for contrast)",
        coupled_note(res),
    ]
    return "\n\n".join(out) + "\n"


def regenerate(make, doc: Path, description: str, argv: list[str] | None = None) -> None:
    """Print the tables ``make()`` returns and, with ``--write``, put them between the
    generated markers of ``doc`` (the command line of every docs script)."""
    parser = argparse.ArgumentParser(description=description.splitlines()[0])
    parser.add_argument("--write", action="store_true", help=f"replace the tables in {doc}")
    args = parser.parse_args(argv)
    text = make()
    sys.stdout.write(text)
    if args.write:
        page = doc.read_text()
        a, b = page.index(BEGIN) + len(BEGIN), page.index(END)
        doc.write_text(page[:a] + "\n" + text + page[b:])


def main(argv: list[str] | None = None) -> None:
    regenerate(build, DOC, __doc__, argv)


if __name__ == "__main__":
    main()
