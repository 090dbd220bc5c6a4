"""One Levenberg-Marquardt iteration on a NARX's simulation error (issue 14).

Target: one LM iteration (Jacobian, JᵀJ and Jᵀr, damped Cholesky solve, trial free runs) on
the simulation (parallel, closed-loop) error of the 374-parameter network of
``configs/seamor_narx_lm.toml`` (10 tanh nodes, 4 input and 4 output delays, X Y Z N → u v w r)
over 10,000 simulated steps (20 windows of 500 samples from measured delay states) in at most
3 s, reported as a ratio to the same iteration on the one-step ("samples" mode) error of the
same 10,000 rows, measured in the same run. Two ways to the simulation Jacobian:

- ``supplied``: the sensitivity recursion (:meth:`NarxModel._simulation_rows`): local
  Jacobians of every step in one batched reverse-mode pass, then a linear recursion in time;
- ``forward``: forward-mode products through the closed loop, one tangent per parameter
  (what the trainer did before), timed on 2 of the 20 windows and scaled (it is linear in
  the windows), unless ``--forward-all``.

``--transform fossen --rest`` times the same iteration for the network of the shipped
config (the Fossen regressors and the rest equilibrium: 934 parameters).

Run:  PYTHONPATH=. python benchmarks/bench_narx_simulation.py [--threads N]
      [--transform products|fossen] [--rest]
"""

from __future__ import annotations

import argparse
import datetime
import time

import numpy as np
import torch

from benchmarks.bench_narx_adam_lm import data, net
from benchmarks.common import machine
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

WINDOWS, LENGTH = 20, 500


def iteration(model, batches, mode: str, rows=None, separable: bool = False) -> float:
    """Seconds for one LM epoch from the same starting weights (the model is restored)."""
    start = {k: v.clone() for k, v in model.net_.state_dict().items()}
    residual = model._one_step_residual if separable else model._window_residual
    lm = LevenbergMarquardt(max_epochs=1, jacobian=mode)
    t0 = time.perf_counter()
    lm.fit(model.net_, residual, batches, separable=separable, jacobian_rows=rows)
    seconds = time.perf_counter() - t0
    model.net_.load_state_dict(start)
    return seconds


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--threads", type=int, default=torch.get_num_threads())
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--forward-all", action="store_true")
    ap.add_argument("--transform", choices=["products", "fossen"], default=None)
    ap.add_argument("--rest", action="store_true", help="rest_equilibrium")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    train, _ = data("coupled")
    model = net(
        "coupled",
        LevenbergMarquardt(max_epochs=5),
        0,
        lm_samples=4000,
        output_transform=args.transform,
        rest_equilibrium=args.rest,
    )
    model.fit(train)
    tab = model._table(train)
    code = tab["code"].numpy()
    # 20 windows of 500 samples, spread over the experiments, each after its delay states
    starts = np.flatnonzero(np.r_[True, code[1:] != code[:-1]])
    stops = np.r_[starts[1:], code.size]
    ends = []
    for i in range(WINDOWS):
        e = i % len(starts)
        ends.append(stops[e] - 1 - (i // len(starts)) * LENGTH)
    sim = model._batch(tab, torch.as_tensor(sorted(ends)), LENGTH)
    one = model._batch(tab, torch.as_tensor(np.flatnonzero(model._eligible(code, 1))[:10_000]), 1)
    steps = sim[2].shape[0] * sim[2].shape[1]
    p = sum(v.numel() for v in model.net_.parameters())

    iteration(model, [sim], "auto", model._simulation_rows)  # warm-up (torch.func set-up)
    iteration(model, [one], "samples", separable=True)
    t_sim = min(
        iteration(model, [sim], "auto", model._simulation_rows) for _ in range(args.repeats)
    )
    t_one = min(iteration(model, [one], "samples", separable=True) for _ in range(args.repeats))
    part = sim if args.forward_all else tuple(x[:2] for x in sim)
    t_fwd = iteration(model, [part], "forward") * (1 if args.forward_all else WINDOWS / 2)

    print(f"machine: {machine(torch=torch.__version__, numpy=np.__version__)}")
    print(f"date: {datetime.date.today().isoformat()}, torch threads {args.threads}")
    print(f"network: {model.layer_sizes()}, {p} parameters; {steps} simulated steps "
          f"({WINDOWS} windows of {LENGTH}), 4 outputs")  # fmt: skip
    print("| iteration | time | ratio to one-step samples mode |")
    print("|---|---|---|")
    print(f"| one-step error, samples mode, {len(one[0])} rows | {t_one:.3f} s | 1 |")
    print(f"| simulation error, sensitivity recursion | {t_sim:.3f} s | {t_sim / t_one:.2f} |")
    label = "measured" if args.forward_all else "2 windows measured, ×10"
    print(f"| simulation error, forward mode ({label}) | {t_fwd:.2f} s | {t_fwd / t_one:.1f} |")


if __name__ == "__main__":
    main()
