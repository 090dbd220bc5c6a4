"""Free-run prediction of 60,000 steps with a NARX network (target < 1 s)."""

from __future__ import annotations

import datetime

import numpy as np
import pandas as pd
import torch

from benchmarks.common import best_of, machine
from nnid.models.narx import NarxModel
from nnid.trainers.adam import Adam


def main() -> None:
    n = 60_000
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.01
    log = pd.DataFrame({"t": t, "experiment": "bench"})
    for c in ("tau_X", "tau_Y", "tau_Z", "tau_N"):
        log[c] = np.repeat(rng.uniform(-30, 30, n // 800 + 1), 800)[:n]
    for c in "uvwr":
        log[c] = 0.0
    # the free run's cost does not depend on the weights: one Adam epoch on a short stretch
    model = NarxModel(
        ["tau_X", "tau_Y", "tau_Z", "tau_N"],
        list("uvwr"),
        4,
        4,
        hidden=(10,),
        trainer=Adam(max_epochs=1),
        samples_per_epoch=256,
    )
    noisy = log.assign(**{c: rng.normal(size=n) for c in "uvwr"}).iloc[:2000]
    model.fit(noisy, noisy)
    seconds = best_of(lambda: model.predict(log, "free_run"))
    print("## NARX (`benchmarks/bench_narx.py`)\n")
    print(
        f"Machine: {machine(torch=torch.__version__, numpy=np.__version__)}. "
        f"Date: {datetime.date.today()}.\n"
    )
    print("| step | target | time |\n|---|---|---|")
    print(
        f"| free run, 60,000 steps, 10 nodes, 4 delays, 4 inputs, 4 outputs | < 1 s | "
        f"**{seconds:.3f} s** |"
    )


if __name__ == "__main__":
    main()
