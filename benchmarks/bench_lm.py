"""Levenberg-Marquardt speed (issue 6). Run by hand: ``python benchmarks/bench_lm.py``.

Target: one LM iteration (Jacobian, JᵀJ and Jᵀr accumulation, damped Cholesky solve, trial
evaluation) for a ~300-parameter MLP on 40,000 residuals within 3× the time of the JᵀJ product
alone (``J.T @ J`` on the materialised 40,000 × P float64 Jacobian), measured in the same run.
The product is timed through torch and through numpy (``a.T @ a``); the ratio is to the one
the trainer's ``add_gram`` computes at this torch thread count (numpy's with one thread,
torch's with more, since 2026-11-27).
"""

from __future__ import annotations

import datetime

import torch
from common import best_of, machine
from torch.func import functional_call, jacrev, vmap

from nnid.trainers.levenberg_marquardt import LevenbergMarquardt


def main() -> None:
    torch.manual_seed(0)
    net = torch.nn.Sequential(
        torch.nn.Linear(3, 20),
        torch.nn.Tanh(),
        torch.nn.Linear(20, 10),
        torch.nn.Tanh(),
        torch.nn.Linear(10, 2),
    ).double()
    n_par = sum(p.numel() for p in net.parameters())
    x = torch.randn(20_000, 3, dtype=torch.float64)
    y = torch.stack([torch.sin(x[:, 0]) * x[:, 1], torch.cos(x[:, 2])], 1)
    batches = [(x, y)]

    def residual(params: dict[str, torch.Tensor], batch: tuple) -> torch.Tensor:
        xb, yb = batch
        return (functional_call(net, params, (xb,)) - yb).reshape(-1)

    start = {k: v.clone() for k, v in net.state_dict().items()}

    def one_iteration(mode: str) -> None:
        net.load_state_dict(start)
        LevenbergMarquardt(max_epochs=1, jacobian=mode).fit(net, residual, batches)

    # The materialised Jacobian for the baseline (per-sample reverse mode).
    params = {k: v.detach() for k, v in net.named_parameters()}
    per = vmap(jacrev(lambda p, xi, yi: residual(p, (xi[None], yi[None]))), in_dims=(None, 0, 0))
    jac = torch.cat([j.reshape(2 * len(x), -1) for j in per(params, x, y).values()], dim=1)

    print(f"machine: {machine(torch=torch.__version__)}")
    print(f"date: {datetime.date.today().isoformat()}")
    print(f"problem: MLP 3-20-10-2, {n_par} parameters, {jac.shape[0]} residuals, float64")
    one_iteration("samples")  # warm-up
    a = jac.numpy()

    def numpy_gram() -> None:
        a.T @ a

    t_jtj = best_of(lambda: jac.T @ jac, repeats=5)
    t_np = best_of(numpy_gram, repeats=5)
    t_lm = best_of(lambda: one_iteration("samples"), repeats=5)
    t_jtj2 = best_of(lambda: jac.T @ jac, repeats=5)
    t_np2 = best_of(numpy_gram, repeats=5)
    t_fwd = best_of(lambda: one_iteration("forward"), repeats=1)
    t_torch, t_numpy = min(t_jtj, t_jtj2), min(t_np, t_np2)
    threads = torch.get_num_threads()
    t_ref = t_numpy if threads == 1 else t_torch  # the trainer's product (add_gram)
    shape = f"{jac.shape[0]} x {n_par}"
    print(
        f"JtJ product alone ({shape}): torch {t_torch:.4f} s, numpy {t_numpy:.4f} s; "
        f"the trainer's at {threads} torch threads: {'numpy' if threads == 1 else 'torch'}"
    )
    print(f"one LM iteration, samples mode: {t_lm:.4f} s, ratio {t_lm / t_ref:.2f} (target <= 3)")
    print(f"one LM iteration, forward mode (any residual): {t_fwd:.4f} s")


if __name__ == "__main__":
    main()
