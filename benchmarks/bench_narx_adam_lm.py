"""Wall time for Levenberg-Marquardt and a tuned Adam to reach given validation errors (issue 6).

Same network (the 10-node, 4-delay u v w r NARX of ``configs/seamor_narx_*.toml``, 374
parameters), same data (the seamor coupled sequence with 1 % noise, 10 runs for training,
early-stopped / validated on surge-sway-yaw), same validation MSE (normalised one-step residual;
about 1 is persistence, since the network predicts the change of u v w r).

- LM: ``trainlm`` defaults (μ 1e-3, ×0.1 / ×10, max_fail 6, 1000 epochs), full batch of one
  balanced draw of 4,000 samples, ``jacobian="samples"``.
- Adam: a grid over learning rate × batch size, constant rate, gradient clipping at 1 (the nnid
  default), no early stopping (``max_fail`` 10⁶) and a wall-time cap ``--cap`` (default 10 s,
  about twice LM's whole run); each epoch is a fresh balanced draw of 16 batches.

Target levels are validation errors that LM and the tuned Adam both reach, per seed: L* is the
worse of the two best errors of that seed (LM's, and the best over the Adam grid), and the other
levels are 1/4, 1/2 and 3/4 of the way from 1 (≈ persistence) to L*. Time to a level is the
first epoch end at or below it, from each trainer's own history (``History.time``
of each: the ``fit`` clock, data preparation excluded). A short fit of each trainer is run
first, in both objectives, so that one-off costs (``torch.func`` set-up, about 1 s) are not
charged to the first seed. Adam is scored twice: the best grid setting for each seed and level
(an oracle, the most favourable case for Adam) and the one setting with the lowest median time
to L*.

A second, smaller case (``--case surge``): the 3-node, 2-delay X → u net of the tests, trained
on the surge run and validated on its block division (70 / 15 %), Adam capped at 3 s.

``--objective simulation`` (issue 14): the same question on the simulation (free-run) error.
Per seed, one series-parallel LM initialisation (trainlm defaults on the one-step error) is
shared by both trainers; then LM (sensitivity-recursion Jacobians, ``max_fail`` off,
``SIM_LM_EPOCHS``) and Adam (constant rate, clipping at 1, no early stopping, capped at the
time LM's run of the same seed took: equal budgets; until 2026-12-01 Adam's cap was a fixed
60 s (four-output net) or 5 s (surge net) against LM's whole runs of 58-605 s and 26-103 s)
minimise the output error of the
same fixed windows (``--window`` samples from measured delay states, every ``--every``-th
window of ``NarxModel.simulation_objective``, which start every half window; Adam takes them in
shuffled mini-batches of ``batch`` windows), and are scored after every epoch on the
validation runs' whole free run (the measure the NARX's free-run stages stop on: each run's
outputs over that run's std, an output the run does not excite left out). Levels are
geometric between the start's validation MSE and L*; where only one trainer ever improves on
the start, L* is its best, the other's times are "never" and the seed counts as the first's
win (ratio 0 or ∞); a level neither reaches is left out of the medians. Surge case: validated
on a surge run of other levels.
``--data shipped`` (coupled case, simulation objective): the training and validation runs of
``configs/seamor_narx_lm.toml`` as ``nnid train`` builds them (Weiss's sequence, the APRBS runs,
its validation runs) instead of the 10 sequence runs above. ``--transform fossen``
gives both networks the Fossen regressors (``NarxModel(output_transform=...)``), as the shipped
Seamor configs and the surge test use them. ``--lm-subset k``: each LM epoch on a fresh
seeded draw of 1/k of the windows; ``--lm-curvature k``: only each epoch's JᵀJ from such a
draw (scaled to all), the gradient and the SSE judging a step from every window. ``--lm-geodesic``:
LM's steps with geodesic acceleration (``LevenbergMarquardt(geodesic=True)``); ``--seed-list``
runs the seeds given instead of 0 .. ``--seeds`` − 1.

Run:  PYTHONPATH=. python benchmarks/bench_narx_adam_lm.py [--case coupled|surge|all]
(about 13 min for the coupled case, 4 min for the surge case, on 1 core); ``--save t.json``
keeps the histories and ``--load t.json`` redoes the tables from them; ``--lr`` / ``--batch``
narrow the grid (e.g. to re-time the chosen setting with ``--threads 2``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import statistics
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from benchmarks.common import machine
from nnid.config import SimulateConfig, load_config
from nnid.datasets.measurement import relative_noise
from nnid.datasets.simulator import simulate_config
from nnid.models.narx import NarxModel
from nnid.trainers.adam import Adam
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
from nnid.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
FORCES = ["tau_X", "tau_Y", "tau_Z", "tau_N"]
TRAIN = ["surge", "sway", "heave", "yaw", "surge-heave", "surge-yaw", "sway-heave", "sway-yaw",
         "heave-yaw", "surge-sway-heave"]  # fmt: skip
SAMPLES = 4000  # LM's fixed full batch
LRS = (1e-3, 3e-3, 1e-2, 3e-2, 1e-1)
BATCHES = (256, 1024, 4096)
STEPS_PER_EPOCH = 16  # Adam validates once per 16 steps
FRACTIONS = (0.25, 0.5, 0.75, 1.0)  # levels: this share of the way from 1 to L*
LABELS = {0.25: "1/4", 0.5: "1/2", 0.75: "3/4", 1.0: "L*"}

CASES = {
    "coupled": {"inputs": FORCES, "outputs": list("uvwr"), "delays": 4, "hidden": 10, "cap": 10.0},
    "surge": {"inputs": ["tau_X"], "outputs": ["u"], "delays": 2, "hidden": 3, "cap": 3.0},
}
Trace = tuple[list[float], list[float]]  # (seconds, validation MSE) at the end of each epoch


def data(case: str):
    cfg = load_config(ROOT / "configs/seamor_sequence.toml", SimulateConfig)
    log = simulate_config(cfg, load_vehicle(cfg.vehicle))
    sources = {c: "true_" + c for c in "uvwr"} | {c: c for c in FORCES}
    relative_noise(log, sources, 0.01, np.random.default_rng(0))

    def runs(names):
        return log[log["experiment"].isin(names)].reset_index(drop=True)

    if case == "surge":  # validation: the block division of the surge run
        return runs(["surge"]), None
    return runs(TRAIN), runs(["surge-sway-yaw"])


def net(case: str, trainer, seed: int, **kw) -> NarxModel:
    c = CASES[case]
    d = c["delays"]
    kw.setdefault("output_transform", c.get("transform"))  # --transform, unless given here
    return NarxModel(c["inputs"], c["outputs"], d, d, hidden=(c["hidden"],), trainer=trainer,
                     seed=seed, **kw)  # fmt: skip


def lm_fit(case: str, seed: int, train, val, max_epochs: int = 1000) -> NarxModel:
    lm = LevenbergMarquardt(max_epochs=max_epochs, jacobian="samples")
    model = net(case, lm, seed, lm_samples=SAMPLES)
    return model.fit(train, validation=val)


def lm_trace(case: str, seed: int, train, val, max_epochs: int = 1000) -> Trace:
    model = lm_fit(case, seed, train, val, max_epochs)
    return model.history_.time, model.history_.validation


def adam_trace(case, seed, lr, batch, cap, train, val, epochs=10**9) -> Trace:
    adam = Adam(lr=lr, max_epochs=epochs, schedule="constant", max_fail=10**6, max_seconds=cap)
    model = net(case, adam, seed, batch_size=batch, samples_per_epoch=STEPS_PER_EPOCH * batch)
    model.fit(train, validation=val)
    return model.history_.time, model.history_.validation


def best(trace: Trace) -> float:
    """The lowest finite validation MSE of a run (inf if none)."""
    return min((v for v in trace[1] if math.isfinite(v)), default=math.inf)


def time_to(level: float, trace: Trace) -> float:
    """Seconds to the first epoch end at or below ``level`` (inf if never)."""
    for t, v in zip(*trace, strict=True):
        if v <= level:
            return t
    return math.inf


SIM_LRS = (1e-3, 3e-3, 1e-2, 3e-2)
SIM_BATCHES = (4, 16)  # windows per Adam step
#: LM's epochs on the simulation objective; Adam's budget is the time LM's run took
SIM_LM_EPOCHS = {"coupled": 40, "surge": 200}


def surge_heldout(seed: int = 3):
    """A surge run of other stair levels than the sequence's (±28 N, within its ±30 N), at the
    same rate and noise: the held-out run of Weiss's 3-node surge network."""
    from nnid.config import Experiment
    from nnid.datasets.simulator import experiment_inputs, simulate

    stairs = {"kind": "stairs", "channel": "X", "levels": [25, -15, 28, 5, -28, 15, -8, 0]}
    exp = Experiment(name="surge-b", signals=[stairs | {"hold": 8.0}])
    inputs = experiment_inputs(exp, ("X", "Y", "Z", "K", "M", "N"), 0.01)
    log = simulate(load_vehicle("seamor"), inputs, 0.01, seed=seed)
    log["experiment"] = "surge-b"
    relative_noise(log, {"u": "u", "tau_X": "tau_X"}, 0.01, np.random.default_rng(seed))
    return log


SHIPPED = ROOT / "configs/seamor_narx_lm.toml"


def shipped_data():
    """The training and validation runs of ``configs/seamor_narx_lm.toml``, as ``nnid train``
    builds them."""
    from nnid.config import TrainConfig
    from nnid.pipeline import load_inputs, make_split

    cfg = load_config(SHIPPED, TrainConfig)
    inputs = load_inputs(cfg, SHIPPED, [cfg.model])
    split = make_split(inputs.log, cfg.split, str(SHIPPED), inputs.report)
    return split["train"].reset_index(drop=True), split["validation"].reset_index(drop=True)


def sim_data(case: str, window: int, source: str = "sequence"):
    """Per case: the training log and the validation log of the simulation objective."""
    if source == "shipped":
        if case != "coupled":
            raise SystemExit("--data shipped is the coupled case's data")
        return shipped_data()
    train, val = data(case)
    return train, (surge_heldout() if case == "surge" else val)


def sim_start(case: str, seed: int, train, val, window: int, every: int, epochs: int = 1000):
    """The shared initialisation (one-step LM, at most ``epochs``) and the batches of the
    simulation objective."""
    lm = LevenbergMarquardt(max_epochs=epochs, jacobian="samples")
    model = net(case, lm, seed, lm_samples=SAMPLES)
    model.fit(train, validation=val)
    obj = model.simulation_objective(train, window, val)  # the model's own free-run stage's
    # (delay states, inputs, targets), and the runs' weights when the net has a run floor
    windows = tuple(x[::every] for x in obj.windows)
    return model, {k: v.clone() for k, v in obj.module.state_dict().items()}, windows, obj


def sim_traces(
    case, seed, grid, window, every, train, val, lm_subset=1, lm_curvature=1, lm_tau=None,
    lm_geodesic=False, warmup=False,
) -> list[dict]:  # fmt: skip
    """LM and every Adam setting from the same start; (seconds, validation MSE) per epoch.
    Equal budgets: LM runs ``SIM_LM_EPOCHS``, and each Adam setting is capped at the time that
    run took on its own ``fit`` clock (``budget``; Adam stops at the first epoch end past it).
    ``warmup``: two epochs of each (and of the one-step start), untimed, to pay one-off costs.
    ``lm_subset`` k > 1: each LM epoch on a fresh seeded draw of 1/k of the windows;
    ``lm_curvature`` k > 1: only its JᵀJ from such a draw, the gradient and SSE from all;
    ``lm_tau``: LM's starting μ is τ · max diag(JᵀJ) of its first system (Madsen, Nielsen &
    Tingleff 2004, section 3.2), not trainlm's 10⁻³ (that system built once more, untimed);
    ``lm_geodesic``: LM's steps with Transtrum & Sethna's geodesic acceleration."""
    epochs = 2 if warmup else None
    model, start, windows, obj = sim_start(case, seed, train, val, window, every, epochs or 1000)
    runs = obj.validation
    out = []
    n = windows[0].shape[0]

    def lm_batches(epoch: int) -> list:  # the draws of NarxModel's own LM stage (its seed)
        idx = obj.order(n, epoch)[: max(1, n // max(lm_subset, lm_curvature))]
        return [tuple(x[idx] for x in windows)]

    mu = 1e-3
    obj.module.load_state_dict(start)
    if lm_tau is not None:
        first = lm_batches(0) if max(lm_subset, lm_curvature) > 1 else [windows]
        ne = LevenbergMarquardt().normal_equations(
            obj.module, obj.residual, first, jacobian_rows=obj.jacobian_rows
        )
        k = max(lm_subset, lm_curvature)  # a draw of 1/k of the windows stands for all
        mu = lm_tau * float(ne.jtj.diagonal().max()) * k
    lm = LevenbergMarquardt(
        max_epochs=epochs or SIM_LM_EPOCHS[case], max_fail=10**6, mu=mu, geodesic=lm_geodesic
    )
    h = lm.fit(obj.module, obj.residual, lm_batches if lm_subset > 1 else [windows],
               runs, jacobian_rows=obj.jacobian_rows,
               curvature_batches=lm_batches if lm_curvature > 1 else None)  # fmt: skip
    budget = math.inf if warmup else h.time[-1]  # LM's whole run: Adam's cap
    out.append({"seed": seed, "trainer": "lm", "trace": (h.time, h.validation),
                "stop": h.stop_reason, "n_params": model.n_params,
                "budget": budget})  # fmt: skip
    for lr, b in grid:
        order = torch.Generator().manual_seed(seed)

        def batches(epoch: int, b=b, order=order) -> list:
            idx = torch.randperm(n, generator=order)
            return [tuple(x[i] for x in windows) for i in idx.split(b)]

        obj.module.load_state_dict(start)
        adam = Adam(lr=lr, max_epochs=epochs or 10**9, schedule="constant", max_fail=10**6,
                    max_seconds=budget)  # fmt: skip
        h = adam.fit(obj.module, obj.residual, batches, runs)
        out.append({"seed": seed, "trainer": "adam", "lr": lr, "batch": b,
                    "trace": (h.time, h.validation)})  # fmt: skip
    return out


def _not_improving(lm_best: float, adam_best: float, start: float) -> str:
    """Which of the two trainers never goes below the start's validation MSE (one does)."""
    return "LM never" if lm_best >= start else "Adam never"


def _median_ratio(ratios) -> float:
    """Median of Adam / LM time ratios; a level neither reaches (∞ / ∞) is no race: left out."""
    kept = [r for r in ratios if not math.isnan(r)]
    return statistics.median(kept) if kept else math.nan


def fmt_t(t: float) -> str:
    return f"{t:.3g} s" if math.isfinite(t) else "never"


def fmt_r(r: float) -> str:
    if math.isnan(r):
        return "neither"
    return f"{r:.2f}×" if math.isfinite(r) else "∞"


def train_case(case: str, seeds: Sequence[int], cap: float, grid: list[tuple[float, int]]) -> dict:
    """LM and the Adam grid on one case; the histories and the load average around them."""
    load0 = os.getloadavg()[0]
    train, val = data(case)
    n_params = lm_fit(case, 0, train, val, max_epochs=2).n_params  # warm-up, not timed
    adam_trace(case, 0, 1e-2, 256, math.inf, train, val, epochs=2)
    runs = []
    for s in seeds:  # interleaved, so that load changes hit both trainers alike
        runs.append({"seed": s, "trainer": "lm", "trace": lm_trace(case, s, train, val)})
        for lr, b in grid:
            tr = adam_trace(case, s, lr, b, cap, train, val)
            runs.append({"seed": s, "trainer": "adam", "lr": lr, "batch": b, "trace": tr})
    return {"case": case, "cap": cap, "load": [load0, os.getloadavg()[0]], "runs": runs,
            "n_params": n_params}  # fmt: skip


def train_sim_case(
    case, seeds, grid, window: int, every: int, source: str, lm_subset: int = 1,
    lm_curvature: int = 1, lm_tau: float | None = None, lm_geodesic: bool = False,
) -> dict:  # fmt: skip
    """LM and the Adam grid on the simulation objective of one case, each Adam run capped at
    LM's whole run of its seed (``cap``: seed → seconds); the load average around them."""
    load0 = os.getloadavg()[0]
    train, val = sim_data(case, window, source)
    options = (lm_subset, lm_curvature, lm_tau, lm_geodesic)
    # one-off costs (torch.func set-up, the first sensitivity recursion) charged to no seed
    sim_traces(case, seeds[0], grid, window, every, train, val, *options, warmup=True)
    runs = []
    for s in seeds:
        runs += sim_traces(case, s, grid, window, every, train, val, *options)
    cap = {r["seed"]: r["budget"] for r in runs if r["trainer"] == "lm"}
    return {"case": case, "cap": cap, "load": [load0, os.getloadavg()[0]], "runs": runs,
            "n_params": runs[0]["n_params"], "objective": "simulation", "window": window,
            "every": every, "data": source}  # fmt: skip


def report(res: dict) -> None:
    """Print one case's part of the RESULTS.md section."""
    case, cap = res["case"], res["cap"]
    c = CASES[case]
    lm = {r["seed"]: r["trace"] for r in res["runs"] if r["trainer"] == "lm"}
    stops = {r["seed"]: r.get("stop") for r in res["runs"] if r["trainer"] == "lm"}
    adam = {
        (r["seed"], r["lr"], r["batch"]): r["trace"] for r in res["runs"] if r["trainer"] == "adam"
    }
    seeds = sorted(lm)
    grid = sorted({(lr, b) for _, lr, b in adam}, key=lambda g: (g[1], g[0]))
    lm_best = {s: best(lm[s]) for s in seeds}
    adam_best = {s: min(best(adam[s, lr, b]) for lr, b in grid) for s in seeds}
    top = {s: max(lm_best[s], adam_best[s]) for s in seeds}
    sim = res.get("objective") == "simulation"
    stuck: list[int] = []  # seeds where neither trainer improves on the start: nothing to time
    one_sided: list[int] = []  # seeds where only one trainer improves: the other never arrives
    if sim:  # geometric from the shared start's validation MSE to L*
        v0 = {s: lm[s][1][0] for s in seeds}
        one_sided = [s for s in seeds if (lm_best[s] < v0[s]) != (adam_best[s] < v0[s])]
        stuck = [s for s in seeds if top[s] >= v0[s] and s not in one_sided]
        for s in one_sided:  # the improving trainer's best: a win it earned, counted
            top[s] = min(lm_best[s], adam_best[s])
        level = {(s, f): v0[s] ** (1 - f) * top[s] ** f for s in seeds for f in FRACTIONS}
    else:
        level = {(s, f): 1 - f * (1 - top[s]) for s in seeds for f in FRACTIONS}
    t_lm = {(s, f): time_to(level[s, f], lm[s]) for s in seeds for f in FRACTIONS}
    t_ad = {
        (s, f, g): time_to(level[s, f], adam[(s, *g)])
        for s in seeds
        for f in FRACTIONS
        for g in grid
    }
    oracle = {
        (s, f): min(grid, key=lambda g, s=s, f=f: t_ad[s, f, g]) for s in seeds for f in FRACTIONS
    }
    timed_seeds = [s for s in seeds if s not in stuck] or seeds
    med = {g: statistics.median(t_ad[s, 1.0, g] for s in timed_seeds) for g in grid}
    fixed = min(grid, key=lambda g: med[g])

    d, h = c["delays"], c["hidden"]
    n_par = res.get("n_params")  # of a fitted net; histories saved before it was recorded: none
    names = " ".join(x.removeprefix("tau_") for x in c["inputs"])
    data_text = (
        "the surge run, validation on "
        + ("a surge run of other levels" if sim else "its block division (70 / 15 %)")
        if case == "surge"
        else f"{len(TRAIN)} runs for training, surge-sway-yaw for validation"
    )
    if res.get("data") == "shipped":
        data_text = (
            f"the runs of {SHIPPED.relative_to(ROOT)} (sequence and APRBS), its validation runs "
            "for validation"
        )
    load0, load1 = res["load"]
    extra = f', `output_transform = "{c["transform"]}"`' if c.get("transform") else ""
    print(
        f"### {h} nodes, {d} delays, {names} → {' '.join(c['outputs'])}{extra}"
        + (f" ({n_par} parameters)" if n_par is not None else "")
        + "\n"
    )
    what = (
        f"free-run MSE of the whole validation runs (each run's outputs over that run's std, "
        f"outputs it does not excite left out); windows of "
        f"{res.get('window')} samples, every {res.get('every')}th of those starting each half "
        "window; start: the shared one-step LM initialisation"
        if sim
        else "validation MSE of the normalised one-step residual (≈ 1 is persistence)"
    )
    if isinstance(cap, dict):  # the simulation objective: Adam's cap is LM's run of the seed
        lm_s = ", ".join(f"seed {k} {v:.3g} s" for k, v in cap.items())
        cap_text = f"Adam capped at LM's whole run of the same seed (equal budgets): {lm_s}"
    elif sim:  # histories saved before 2026-12-01: LM ran its epochs, Adam to a fixed cap
        lm_s = ", ".join(f"seed {s} {lm[s][0][-1]:.3g} s" for s in seeds)
        cap_text = f"Adam cap {cap:g} s against LM's whole runs of {lm_s}: unequal budgets"
    else:
        cap_text = f"Adam cap {cap:g} s"
    print(
        f"Data: Seamor, 1 % noise, {data_text}; {what}. {cap_text}. "
        f"{len(seeds)} seeds (initialisation and sample draws). Load average {load0:.1f} at "
        f"the start, {load1:.1f} at the end.\n"
    )
    print("Adam grid: median over seeds of the time to L*, seeds that reach it, median best MSE.\n")
    print("| lr | batch | median time to L* | seeds reaching L* | median best val MSE |")
    print("|---|---|---|---|---|")
    for lr, b in grid:
        n = sum(math.isfinite(t_ad[s, 1.0, (lr, b)]) for s in seeds)
        b_med = statistics.median(best(adam[s, lr, b]) for s in seeds)
        mark = " **(chosen)**" if (lr, b) == fixed else ""
        print(f"| {lr:g} | {b} | {fmt_t(med[lr, b])}{mark} | {n} | {b_med:.4g} |")
    print("\n| seed | LM best val MSE | LM epochs (whole run) | Adam grid best val MSE | L* |")
    print("|---|---|---|---|---|")
    for s in seeds:
        n_ep = len(lm[s][0]) - 1
        whole = fmt_t(lm[s][0][-1]) + (f"; stop: {stops[s]}" if stops[s] else "")
        print(f"| {s} | {lm_best[s]:.4g} | {n_ep} ({whole}) | {adam_best[s]:.4g} | {top[s]:.4g} |")
    fl, fb = fixed
    print(
        "\n| level | seed | val MSE | LM | best Adam for the seed (lr, batch) | Adam / LM | "
        f"Adam lr {fl:g}, batch {fb} | Adam / LM |"
    )
    print("|---|---|---|---|---|---|---|---|")
    summary = []
    for f in FRACTIONS:
        r_or, r_fx = [], []
        for s in seeds:
            a = t_lm[s, f]
            g = oracle[s, f]
            o, x = t_ad[s, f, g], t_ad[s, f, fixed]
            r_or.append(o / a)
            r_fx.append(x / a)
            print(
                f"| {LABELS[f]} | {s} | {level[s, f]:.4g} | {fmt_t(a)} | {fmt_t(o)} "
                f"({g[0]:g}, {g[1]}) | {fmt_r(o / a)} | {fmt_t(x)} | {fmt_r(x / a)} |"
            )
        timed = [i for i, s in enumerate(seeds) if s in timed_seeds]
        summary.append((f, _median_ratio(r_or[i] for i in timed),
                        _median_ratio(r_fx[i] for i in timed)))  # fmt: skip
    if one_sided:
        print(
            "\n"
            + " ".join(
                f"Seed {s}: {_not_improving(lm_best[s], adam_best[s], v0[s])} improves on the "
                "start's validation MSE."
                for s in one_sided
            )
            + " L* is then the other trainer's best, which the first never reaches: counted in "
            "the medians below as a win of the other (ratio 0 or ∞)."
        )
    if stuck:
        print(
            "\n"
            + " ".join(
                f"Seed {s}: neither trainer ever improves on the start's validation MSE."
                for s in stuck
            )
            + " Nothing to time: left out of the medians below."
        )
    print("\n| level | median Adam / LM, best Adam per seed | median Adam / LM, chosen setting |")
    print("|---|---|---|")
    for f, a, b in summary:
        print(f"| {LABELS[f]} | **{fmt_r(a)}** | {fmt_r(b)} |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", choices=[*CASES, "all"], default="all")
    ap.add_argument("--seeds", type=int, default=5, help="seeds 0 .. n-1")
    ap.add_argument("--seed-list", type=int, nargs="+", help="these seeds instead of --seeds")
    ap.add_argument(
        "--cap",
        type=float,
        help="one-step objective: Adam wall-time cap per run, s (case default); the simulation "
        "objective caps it at LM's whole run of the seed",
    )
    ap.add_argument("--threads", type=int, default=1, help="torch threads (1: robust to load)")
    ap.add_argument("--lr", type=float, nargs="+", default=list(LRS))
    ap.add_argument("--batch", type=int, nargs="+", default=list(BATCHES))
    ap.add_argument("--save", type=Path, help="write the histories to this JSON file")
    ap.add_argument("--load", type=Path, help="report from saved histories (no training)")
    ap.add_argument("--objective", choices=["one-step", "simulation"], default="one-step")
    ap.add_argument("--window", type=int, default=500, help="simulation windows, samples")
    ap.add_argument("--every", type=int, default=4, help="keep every n-th window")
    ap.add_argument(
        "--data",
        choices=["sequence", "shipped"],
        default="sequence",
        help="coupled simulation case: the 10 sequence runs or the shipped config's",
    )
    ap.add_argument(
        "--transform",
        choices=["products", "fossen"],
        help="the networks' output_transform (default: none, Weiss's plain regressors)",
    )
    ap.add_argument(
        "--lm-subset",
        type=int,
        default=1,
        help="simulation objective: each LM epoch on a fresh draw of 1/k of the windows",
    )
    ap.add_argument(
        "--lm-curvature",
        type=int,
        default=1,
        help="simulation objective: each LM epoch's JᵀJ from a fresh draw of 1/k of the windows "
        "(gradient and trial SSE from all)",
    )
    ap.add_argument(
        "--lm-tau",
        type=float,
        help="simulation objective: LM's starting mu = tau * max diag(JᵀJ) of its first system "
        "(default: trainlm's 1e-3)",
    )
    ap.add_argument(
        "--lm-geodesic",
        action="store_true",
        help="simulation objective: LM's steps with geodesic acceleration (Transtrum & Sethna)",
    )
    args = ap.parse_args()
    seeds = args.seed_list or range(args.seeds)
    if args.cap is not None and args.objective == "simulation":
        ap.error("--objective simulation caps Adam at LM's whole run of the same seed: no --cap")
    if args.lm_subset < 1 or args.lm_curvature < 1:
        ap.error("--lm-subset and --lm-curvature are positive integers k (1/k of the windows)")
    if args.lm_subset > 1 and args.lm_curvature > 1:
        ap.error("--lm-subset and --lm-curvature are two ways to draw: give one")
    transform = json.loads(args.load.read_text()).get("transform") if args.load else args.transform
    for c in CASES.values():  # this process's networks, for training and for the report
        c["transform"] = transform
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    sim = args.objective == "simulation"
    if sim:
        args.lr = args.lr if args.lr != list(LRS) else list(SIM_LRS)
        args.batch = args.batch if args.batch != list(BATCHES) else list(SIM_BATCHES)
    grid = [(lr, b) for b in args.batch for lr in args.lr]
    if args.load:
        saved = json.loads(args.load.read_text())
    else:
        cases = list(CASES) if args.case == "all" else [args.case]
        saved = {"threads": args.threads, "date": str(datetime.date.today()), "cases": [],
                 "transform": args.transform, "lm_subset": args.lm_subset,
                 "lm_curvature": args.lm_curvature, "lm_tau": args.lm_tau,
                 "lm_geodesic": args.lm_geodesic}  # fmt: skip
        for case in cases:
            if sim:
                saved["cases"].append(
                    train_sim_case(
                        case,
                        seeds,
                        grid,
                        args.window,
                        args.every,
                        args.data,
                        args.lm_subset,
                        args.lm_curvature,
                        args.lm_tau,
                        args.lm_geodesic,
                    )
                )
                continue
            cap = args.cap or CASES[case]["cap"]
            saved["cases"].append(train_case(case, seeds, cap, grid))
        if args.save:
            args.save.write_text(json.dumps(saved))
    objective = saved["cases"][0].get("objective", "one-step") if saved["cases"] else ""
    print(f"## NARX: LM vs Adam, {objective} objective (`benchmarks/bench_narx_adam_lm.py`)\n")
    print(
        f"Machine: {machine(torch=torch.__version__, numpy=np.__version__)}; torch threads "
        f"{saved['threads']}. Date: {saved['date']}.\n"
    )
    lrs = sorted({r["lr"] for c in saved["cases"] for r in c["runs"] if "lr" in r})
    bs = sorted({r["batch"] for c in saved["cases"] for r in c["runs"] if "batch" in r})
    if objective == "simulation":
        k = saved.get("lm_subset", 1)
        drawn = f", each epoch on a fresh draw of 1/{k} of the windows" if k > 1 else ""
        c = saved.get("lm_curvature", 1)
        if c > 1:
            drawn = (
                f", each epoch's JᵀJ from a fresh draw of 1/{c} of the windows scaled to all, "
                "its gradient Jᵀr (reverse mode) and trial SSE from every window"
            )
        if saved.get("lm_geodesic"):
            drawn += ", geodesic acceleration (Transtrum & Sethna 2012, ratio 0.75)"
        # histories saved before 2026-12-01 capped Adam at a fixed time, whatever LM took
        equal = all(isinstance(c["cap"], dict) for c in saved["cases"])
        capped = "capped at LM's whole run of the same seed" if equal else "a wall-time cap"
        if saved.get("lm_tau") is not None:
            drawn += (
                f", starting μ {saved['lm_tau']:g} × the largest diagonal entry of its first JᵀJ"
            )
        print(
            "Start: per seed, LM on the one-step error (trainlm defaults, early-stopped on the "
            "validation runs). Then LM (sensitivity-recursion Jacobian, trainlm's μ rule, "
            f"no early stop{drawn}) and Adam (constant rate, clipping at 1, no early stop, "
            f"{capped}; shuffled mini-batches of windows) on the same windows' output error; "
            f"grid lr ∈ {{{', '.join(f'{x:g}' for x in lrs)}}} × windows per step ∈ "
            f"{{{', '.join(map(str, bs))}}}. Times from each trainer's history (`fit` clock). "
            "Levels, per seed: L* is the worse of LM's and the grid's best Adam's best "
            "validation MSE (where only one of them improves on the start, its best); 1/4, 1/2, "
            "3/4: geometric steps from the start's MSE to L*.\n"
        )
        for res in saved["cases"]:
            report(res)
        return
    print(
        f'LM: trainlm defaults, `jacobian="samples"`, full batch of {SAMPLES} balanced samples. '
        "Adam: constant rate, gradient clipping at 1, no early stopping, a wall-time cap, a "
        f"fresh balanced draw of {STEPS_PER_EPOCH} batches per epoch; grid lr ∈ "
        f"{{{', '.join(f'{x:g}' for x in lrs)}}} × batch ∈ {{{', '.join(map(str, bs))}}}. "
        "Times from each trainer's history (`fit` clock). Levels, per seed: L* is the worse of "
        "LM's and the grid's best Adam's best validation MSE, and 1/4, 1/2, 3/4 of the way "
        "from 1 to L*.\n"
    )
    for res in saved["cases"]:
        report(res)


if __name__ == "__main__":
    main()
