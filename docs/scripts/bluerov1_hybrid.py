"""Regenerate the tables of docs/bluerov1_hybrid.md (issue 15: the hybrid on real data).

    python docs/scripts/bluerov1_hybrid.py            # print the tables (markdown)
    python docs/scripts/bluerov1_hybrid.py --write    # also replace them in the doc

The neural-ODE hybrid on the Liu BlueROV open-loop runs, with the split, the runs cut at their
last command, the least-squares physics and the attitude protocol of
docs/bluerov1_identification.md (``docs/scripts/bluerov1_identification.py``, whose functions
this script uses): the rotational equations p q r, translational forces removed and
u = v = w = 0 (exact here: B = W and r_g = 0), a DOF scored on a run only where that run's
thrusters drive it. The hybrid's physics is that script's least-squares fit (same config
model), its network corrects K, M and N and early-stops on the validation runs; the test runs
are scored 1 s ahead and in free run against the least-squares fit, the thesis model and
persistence. Reads ../shared; writes only the doc.
"""

from __future__ import annotations

import importlib.util
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

REPO = Path(__file__).resolve().parents[2]
DOC = REPO / "docs" / "bluerov1_hybrid.md"
SEEDS = (0, 1, 2)


def identification():
    """docs/scripts/bluerov1_identification.py as a module (its split, fit and protocol)."""
    path = Path(__file__).with_name("bluerov1_identification.py")
    spec = importlib.util.spec_from_file_location("bluerov1_identification", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def attitude_log(runs: pd.DataFrame, vehicle) -> pd.DataFrame:
    """The runs with the commands turned into generalized forces, the translational ones
    removed, and no u v w (the attitude protocol)."""
    from nnid.datasets.arrays import log_arrays

    tau = log_arrays(runs, vehicle)["tau"].copy()
    tau[:, 0:3] = 0.0
    keep = [c for c in runs.columns if not c.startswith("cmd_") and c not in ("u", "v", "w")]
    out = runs[keep].copy()
    for k, f in enumerate("XYZKMN"):
        out[f"tau_{f}"] = tau[:, k]
    return out


def hybrid(cfg, vehicle, train: pd.DataFrame, val: pd.DataFrame, seed: int):
    """The hybrid on the config's physics (p q r, its unknowns, its least squares)."""
    from nnid.models.hybrid import HybridModel
    from nnid.trainers.adam import Adam

    spec = cfg.model
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return HybridModel(
            vehicle,
            dofs=tuple(spec.dofs),
            unknowns=tuple(spec.unknowns),
            physics_trainer=spec.trainer.build(),
            savgol_window=spec.savgol_window,
            savgol_order=spec.savgol_order,
            zoh_midpoint=False,  # the least-squares fit of the identification doc, as it is
            segments=(0.5,),
            trainer=Adam(lr=0.01, max_epochs=100, max_fail=30),
            seed=seed,
        ).fit(train, val)


def score(ident, models: dict, runs: pd.DataFrame, vehicle, warmup_s: float) -> list[dict]:
    """Rows (run, dof, mode, model -> NRMSE) of the attitude protocol for fitted models
    (hybrids) and parts (the least-squares fit and the thesis model)."""
    from nnid.evaluation.metrics import nrmse, warmup_mask

    rows = []
    for name, g in runs.groupby("experiment", sort=False):
        g = g.drop(columns=[c for c in "uvw" if c in g]).reset_index(drop=True)
        a = attitude_log(g, vehicle)
        mask = warmup_mask(g, warmup_s, warmup_samples=1)
        dofs = ident.driven(g, vehicle)
        for mode in ident.MODES:
            preds = {}
            for m, model in models.items():
                if hasattr(model, "predict"):
                    preds[m] = model.predict(a, mode)
                else:
                    preds[m] = ident.predict(model, g, vehicle, mode, (0, 1, 2))
            for d in dofs:
                y = g[d].to_numpy()[mask]
                row = {"run": name, "dof": d, "mode": mode}
                for m, pr in preds.items():
                    value = nrmse(y, pr[d].to_numpy()[mask])
                    row[m] = value if np.isfinite(value) else None
                row["persistence"] = nrmse(y, ident.persistence(g, d, mode)[mask])
                rows.append(row)
    return rows


def table(ident, rows: list[dict], runs: list[str], models: list[str]) -> str:
    """Mean NRMSE over the runs that drive each DOF, per mode."""
    frame = pd.DataFrame(rows)
    frame = frame[frame.run.isin(runs)]
    names = " / ".join(models)
    lines = [
        "| DOF | runs | "
        + " | ".join(f"{ident.MODE_NAMES[m]}: {names}" for m in ident.MODES)
        + " |",
        "|---|---|" + "---|" * len(ident.MODES),
    ]
    for d in ("p", "q", "r"):
        sub = frame[frame.dof == d]
        if sub.empty:
            continue
        cells = []
        for m in ident.MODES:
            s = sub[sub["mode"].astype(str) == str(m)]
            cells.append(" / ".join(ident.f3(s[x].astype(float).mean()) for x in models))
        used = ", ".join(ident.short(n) for n in dict.fromkeys(sub.run))
        lines.append(f"| {d} | {used} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def build() -> str:
    from nnid.loop.explain import explain
    from nnid.physics.parts import Parts

    ident = identification()
    cfg, vehicle = ident.setup()
    _, cut, _ = ident.load_runs(cfg)
    s = cfg.split
    parts = {
        p: cut[cut.experiment.isin(names)]
        for p, names in (("train", s.train), ("validation", s.validation), ("test", s.test))
    }
    att = {p: attitude_log(g, vehicle) for p, g in parts.items()}
    models: dict = {}
    fits = {}
    for seed in SEEDS:
        fits[seed] = hybrid(cfg, vehicle, att["train"], att["validation"], seed)
        models[f"hybrid {seed}"] = fits[seed]
    first = fits[SEEDS[0]]
    models["least squares"] = first.baseline().parts_
    models["thesis"] = Parts.from_vehicle(vehicle)
    held = [*s.validation, *s.test]
    rows = score(ident, models, cut[cut.experiment.isin(held)], vehicle, cfg.warmup_s)
    for row in rows:
        values = [row[f"hybrid {k}"] for k in SEEDS]
        row["hybrid (mean of seeds)"] = (
            float(np.mean(values)) if all(v is not None for v in values) else None
        )
    shown = ["hybrid (mean of seeds)", "least squares", "thesis", "persistence"]
    expl = explain(first, att["train"])
    stages = [
        f"seed {k}: {m.stages_[0]['epochs']} epochs, best {m.stages_[0]['best_epoch']}, "
        f"{m.fit_seconds_:.0f} s"
        for k, m in fits.items()
    ]
    shares = first.correction_share(att["test"])
    out = [
        "### NRMSE on the test runs (mean over the runs that drive each DOF)",
        table(ident, rows, list(s.test), shown),
        "### NRMSE on the validation runs (used for early stopping)",
        table(ident, rows, list(s.validation), shown),
        "### Per seed, test runs",
        table(ident, rows, list(s.test), [f"hybrid {k}" for k in SEEDS]),
        "### Training",
        "; ".join(stages) + ".",
        "### What the network learned (seed 0, training runs)",
        "| term | meaning | value | share of the learned force |\n|---|---|---|---|\n"
        + "\n".join(
            f"| `{t.name}` | {t.meaning} | {t.value:.4g} | {100 * t.share:.0f} % |"
            for t in expl.terms[:6]
        )
        + f"\n\nTogether the kept terms explain {100 * expl.explained:.0f} % of the learned force. "
        "Network force over the physics' damping force (RMS, test runs): "
        + ", ".join(f"{k} {v:.2f}" for k, v in shares.items() if v is not None)
        + ".",
    ]
    return "\n\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> None:
    identification().regenerate(build, DOC, __doc__, argv)


if __name__ == "__main__":
    main()
