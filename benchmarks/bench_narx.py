"""Free-run prediction of 60,000 steps with a NARX network (target < 1 s), compiled
(:mod:`nnid.models.narx_kernel`) against the torch closed loop that training differentiates
(``NarxModel._rollout`` without gradients), same network, same run; with plain regressors and
with the Fossen regressors of ``configs/seamor_narx_*.toml``."""

from __future__ import annotations

import datetime

import numpy as np
import pandas as pd
import torch

from benchmarks.common import best_of, machine
from nnid.models.narx import NarxModel
from nnid.trainers.adam import Adam


def _model(log: pd.DataFrame, transform: str | None, rng: np.random.Generator) -> NarxModel:
    # the free run's cost does not depend on the weights: one Adam epoch on a short stretch
    model = NarxModel(
        ["tau_X", "tau_Y", "tau_Z", "tau_N"],
        list("uvwr"),
        4,
        4,
        hidden=(10,),
        output_transform=transform,
        trainer=Adam(max_epochs=1),
        samples_per_epoch=256,
    )
    noisy = log.assign(**{c: rng.normal(size=len(log)) for c in "uvwr"}).iloc[:2000]
    return model.fit(noisy, noisy)


def main() -> None:
    n = 60_000
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.01
    log = pd.DataFrame({"t": t, "experiment": "bench"})
    for c in ("tau_X", "tau_Y", "tau_Z", "tau_N"):
        log[c] = np.repeat(rng.uniform(-30, 30, n // 800 + 1), 800)[:n]
    for c in "uvwr":
        log[c] = 0.0
    rows = []
    for transform in (None, "fossen"):
        model = _model(log, transform, rng)
        model.predict(log.iloc[:100], "free_run")  # numba's compile or cache load, not timed
        compiled = best_of(lambda m=model: m.predict(log, "free_run"))
        (hist, uf, _, _), *_ = model._whole_runs(model._table(log), log)

        def rollout(m=model, hist=hist, uf=uf):
            with torch.no_grad():
                return m._rollout(m._weights(), hist, uf)

        torch_s = best_of(rollout, repeats=1)
        rows.append((transform or "plain", model.n_params, compiled, torch_s))
    print("## NARX (`benchmarks/bench_narx.py`)\n")
    print(
        f"Machine: {machine(torch=torch.__version__, numpy=np.__version__)}, "
        f"{torch.get_num_threads()} torch threads. Date: {datetime.date.today()}.\n"
    )
    print("| regressors | weights | target | compiled free run | torch closed loop | ratio |")
    print("|---|---|---|---|---|---|")
    for name, n_params, compiled, torch_s in rows:
        print(
            f"| {name}, 60,000 steps, 10 nodes, 4 delays, 4 inputs, 4 outputs | {n_params} | "
            f"< 1 s | **{compiled:.3f} s** | {torch_s:.2f} s | {torch_s / compiled:.0f} |"
        )


if __name__ == "__main__":
    main()
