"""Neural-ODE hybrid: training speed, and the scenarios of issue 15. Run by hand:

    python benchmarks/bench_hybrid.py speed        # one epoch, torchdiffeq against nnid's RK4
    python benchmarks/bench_hybrid.py free_run     # predictions: compiled kernel against torch
    python benchmarks/bench_hybrid.py scenarios [SEED ...]  # hybrid vs physics vs NARX per effect

``speed``: one training epoch over 10 minutes of 100 Hz data (minirov, every DOF excited) cut
into 1-second segments, Adam in minibatches of 64, 256 (the default) and 600 (all) segments,
target under 5 s on the 2-core reference machine; the same epoch with nnid's own classic RK4
in place of torchdiffeq's, same model, same run (the ratio is what torchdiffeq's generality
costs); and the neural state-space model's vector field integrated both ways (why it keeps its
own RK4).

``free_run``: the hybrid's predictions without gradients (what early stopping scores every
epoch and what ``predict`` returns), through the compiled kernel
(:mod:`nnid.models.hybrid_kernel`) against the torchdiffeq integration of the same vector field
(the baseline, same model and run): 5-s windows of a held-out part as early stopping flies them,
whole experiments of a 300-s log, and k-step predictions (k = 1 s) of every sample; the
default network with random weights (the untrained one's last layer is zero), in a current.
The same numbers either way (the largest difference is printed).

``scenarios``: for each effect kind of the loop (installation loss, coupled damping, actuator
lag, tether pull, current) and a clean log, seeds 11-13: ``configs/hybrid.toml`` against
``configs/fossen_ls.toml`` on the same split (test free-run NRMSE), a NARX of comparable size
(~2,000 weights, LM), the network's share of the damping force and the top terms of its learned
force. Writes nothing; paste the printed table into RESULTS.md.
"""

from __future__ import annotations

import datetime
import sys
import tempfile
import time
import warnings
from importlib import resources
from pathlib import Path

import numpy as np
import torch
from common import best_of, machine

REPO = Path(__file__).resolve().parents[1]
MINIROV = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))


def epoch_seconds(model) -> float:
    """Seconds of the first training epoch (the history's entry 1 minus its start)."""
    times = model.history_[0].time
    return times[1] - times[0]


def speed() -> None:
    from nnid.loop.scenarios import effect_log
    from nnid.models.hybrid import HybridModel
    from nnid.models.neural_state_space import StateSpaceNet
    from nnid.physics.integrate import rk4
    from nnid.physics.odeint import SampledInput, integrate
    from nnid.trainers.adam import Adam
    from nnid.vehicle import load_vehicle

    veh = load_vehicle(MINIROV)
    log = effect_log(veh, [("coupled_damping.N:u*v", -5.0)], duration=600.0, dt=0.01, seed=1)
    print(f"log: {len(log)} samples at 100 Hz, {log['experiment'].nunique()} experiments")
    rows = []
    for method in ("rk4", "nnid_rk4"):
        for batch in (64, 256, 600):
            model = HybridModel(
                veh,
                segments=(1.0,),
                batch_segments=batch,
                method=method,
                trainer=Adam(lr=0.01, max_epochs=2),
            ).fit(log)
            epochs = np.diff(model.history_[0].time)
            rows.append((method, batch, float(epochs.min())))
            print(f"  {method:9s} batch {batch:4d}: epoch {epochs.min():.2f} s (of {epochs})")
    base = {b: s for m, b, s in rows if m == "nnid_rk4"}
    print("\n| integrator | segments per step | epoch (s) | / nnid RK4 |\n|---|---|---|---|")
    for m, b, s in rows:
        print(f"| {m} | {b} | {s:.2f} | {s / base[b]:.2f} |")

    # the neural state-space model's field (Cascaded Tanks size): torchdiffeq against its RK4
    net = StateSpaceNet(2, 2, 1, 16, np.ones((2, 3), dtype=bool), generator=torch.Generator())
    gen = torch.Generator().manual_seed(0)
    u = torch.randn(100, 64, 1, generator=gen, dtype=torch.float64)
    x0 = torch.zeros(64, 2, dtype=torch.float64)

    def f(x, v):
        w1 = net.w1 * net.mask1
        h = torch.tanh(x @ w1[:, :2].T + v @ w1[:, 2:].T + net.b1)
        return h @ ((net.w2 * net.mask2).T * 0.1) + net.b2 * 0.1

    def own():
        rk4(f, x0, u, 1.0)[-1].sum().backward()

    def td():
        integrate(f, x0, SampledInput(u.transpose(0, 1), 1.0), steps=100)[-1].sum().backward()

    times = {}
    for name, fn in (("nnid_rk4", own), ("torchdiffeq rk4", td)):
        fn()
        best = min(_time(fn) for _ in range(5))
        times[name] = best
    print(
        "\nstate-space field, 100 steps x 64 windows, forward + backward: "
        + ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in times.items())
        + f" (ratio {times['torchdiffeq rk4'] / times['nnid_rk4']:.2f})"
    )
    print(f"\n{machine(torch=torch.__version__)}; {datetime.date.today()}")


def _time(fn) -> float:
    t = time.perf_counter()
    fn()
    return time.perf_counter() - t


def free_run() -> None:
    from nnid.evaluation.prediction import measured_states
    from nnid.loop.scenarios import effect_log
    from nnid.models.hybrid import HybridModel
    from nnid.trainers.adam import Adam
    from nnid.vehicle import load_vehicle

    veh = load_vehicle(MINIROV)
    log = effect_log(veh, [("current.y", 0.15)], duration=300.0, dt=0.05, seed=11)
    model = HybridModel(veh, trainer=Adam(max_epochs=0), segments=(0.5,)).fit(log)
    dyn = model.dynamics_
    gen = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in dyn.net.parameters():
            p.add_(0.1 * torch.randn(p.shape, generator=gen, dtype=p.dtype))
    prepared, data = model._data(log, accelerations=False)
    channels = model._channels(prepared, data["tau"])
    states = measured_states(prepared)
    first = prepared["experiment"].to_numpy() == prepared["experiment"].iloc[0]
    held = np.flatnonzero(first)  # one experiment as the held-out part
    starts = held[: held.size - 100 : 100]
    x0, windows = (
        torch.as_tensor(states[starts]),
        torch.as_tensor(channels[starts[:, None] + np.arange(100)]),
    )
    torch_run = type(dyn).free_run

    def torch_path(self, x0, inputs, dt, substeps=1, params=None, arrays=None):
        with torch.no_grad():
            return self(x0, inputs, dt, substeps)

    cases = {
        f"early-stopping windows ({starts.size} x 5 s)": lambda: dyn.free_run(x0, windows, 0.05),
        f"free run of {log['experiment'].nunique()} experiments (300 s)": lambda: model.predict(
            log, "free_run"
        ),
        f"k-step (k = 20) of {len(log)} samples": lambda: model.predict(log, 20),
    }
    print("| prediction | torch (s) | compiled (s) | torch / compiled | max difference |")
    print("|---|---|---|---|---|")
    for name, fn in cases.items():
        fast = fn()  # compiles on a cold cache
        t_fast = best_of(fn)
        type(dyn).free_run = torch_path
        try:
            slow = fn()
            t_slow = best_of(fn)
        finally:
            type(dyn).free_run = torch_run
        a = fast.numpy() if isinstance(fast, torch.Tensor) else fast.to_numpy()
        b = slow.numpy() if isinstance(slow, torch.Tensor) else slow.to_numpy()
        diff = float(np.nanmax(np.abs(a - b)))
        print(f"| {name} | {t_slow:.3f} | {t_fast:.4f} | {t_slow / t_fast:.1f} | {diff:.1e} |")
    # a whole `nnid train configs/hybrid.toml` of a test scenario (tests/test_hybrid.py's
    # patience of 15): early stopping scores every epoch, then the metrics' predictions
    from nnid.config import TrainConfig, load_config
    from nnid.datasets.log import write_log
    from nnid.pipeline import run_train

    scenario = effect_log(veh, [("external_bias.u", -4.0)], duration=300.0, dt=0.05, seed=11)
    config = REPO / "configs" / "hybrid.toml"
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.parquet"
        write_log(scenario, path)
        runs = {}
        for name in ("compiled", "torch"):
            cfg = load_config(config, TrainConfig)
            cfg.model.trainer.max_fail = 15
            if name == "torch":
                type(dyn).free_run = torch_path
            try:
                start = time.perf_counter()
                res = run_train(cfg, config, str(path), MINIROV)
                runs[name] = (time.perf_counter() - start, res.metrics)
            finally:
                type(dyn).free_run = torch_run
    (t_fast, fast), (t_slow, slow) = runs["compiled"], runs["torch"]
    stage = [m["describe"]["stages"][0] if "describe" in m else {} for m in (fast, slow)]
    print(
        f"| nnid train configs/hybrid.toml (tether scenario, 300 s) | {t_slow:.1f} | "
        f"{t_fast:.1f} | {t_slow / t_fast:.2f} | test free run "
        f"{slow['test']['free_run_nrmse']['total']:.6f} / "
        f"{fast['test']['free_run_nrmse']['total']:.6f} |"
    )
    print(f"epochs / best epoch: {[(s.get('epochs'), s.get('best_epoch')) for s in stage]}")
    print(f"\n{machine(torch=torch.__version__)}; {datetime.date.today()}")


SCENARIOS = {
    "none": (0.0, 300.0),
    "thruster_installation.w.neg": (0.6, 300.0),
    "coupled_damping.N:u*v": (-5.0, 300.0),
    "actuator_lag": (0.3, 300.0),
    "external_bias.u": (-4.0, 300.0),
    "current.y": (0.15, 600.0),
}


def scenarios(seeds=(11, 12, 13)) -> None:
    from nnid.config import TrainConfig, load_config
    from nnid.datasets.log import write_log
    from nnid.loop.scenarios import effect_log
    from nnid.models.narx import NarxModel
    from nnid.pipeline import make_split, run_train
    from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
    from nnid.vehicle import load_vehicle

    veh = load_vehicle(MINIROV)
    configs = REPO / "configs"
    print(
        "| effect | seed | physics (fossen_ls) | hybrid | ratio | NARX | share of damping force "
        "| top terms | hybrid fit (s) |\n|---|---|---|---|---|---|---|---|---|"
    )
    for effect, (value, seconds) in SCENARIOS.items():
        for seed in seeds:
            effects = [] if effect == "none" else [(effect, value)]
            log = effect_log(veh, effects, duration=seconds, dt=0.05, seed=seed)
            with tempfile.TemporaryDirectory() as tmp, warnings.catch_warnings():
                warnings.simplefilter("ignore")
                path = Path(tmp) / "log.parquet"
                write_log(log, path)
                res = {}
                for name in ("hybrid", "fossen_ls"):
                    cfg = load_config(configs / f"{name}.toml", TrainConfig)
                    res[name] = run_train(cfg, configs / f"{name}.toml", str(path), MINIROV)
                split = make_split(log, cfg.split)
                tau = [f"tau_{f}" for f in "XYZKMN"]
                narx = NarxModel(
                    tau,
                    list("uvwpqr"),
                    2,
                    2,
                    hidden=(32, 32),
                    seed=seed,
                    trainer=LevenbergMarquardt(max_epochs=100),
                ).fit(split.train, split.validation)
                narx_free = narx.score(split.test, "free_run", cfg.warmup_s)["total"]
            h, p = res["hybrid"].metrics, res["fossen_ls"].metrics
            hf = h["test"]["free_run_nrmse"]["total"]
            pf = p["test"]["free_run_nrmse"]["total"]
            share = h["correction"]["share_of_damping_force"]["test"]["max"]
            terms = [t["effect"] for t in h["correction"]["explanation"]["terms"][:3]]
            # a diverged test free run scores None: said, and no ratio made of it
            ratio = "diverged" if None in (hf, pf) else f"{hf / pf:.2f}"
            print(
                f"| {effect} | {seed} | {_total(pf, 4)} | {_total(hf, 4)} | {ratio} | "
                f"{_total(narx_free, 3)} | {share:.3f} | "
                f"{', '.join(terms) or '-'} | {res['hybrid'].model.fit_seconds_:.0f} |",
                flush=True,
            )
    print(f"\n{machine(torch=torch.__version__)}; {datetime.date.today()}")


def _total(value: float | None, digits: int) -> str:
    """A free-run total as printed: "diverged" where its score is None."""
    return "diverged" if value is None else f"{value:.{digits}f}"


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "speed"
    if what == "scenarios":
        scenarios(tuple(int(s) for s in sys.argv[2:]) or (11, 12, 13))
    elif what == "free_run":
        free_run()
    else:
        speed()
