"""Fixed-step RK4 in PyTorch, batched and differentiable (torchdiffeq-style functional surface).

The compiled kernel (:mod:`nnid.physics.compiled`) is the fast path for fixed parameters; this
one lets gradients flow to parameters and states (hybrid models, physics fits).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import torch
from torch import Tensor


def rk4(
    f: Callable[[Tensor, Tensor], Tensor],
    x0: Tensor,
    u: Tensor,
    dt: float,
    substeps: int = 1,
    lag: float = 0.0,
    lagged: int | None = None,
) -> Tensor:
    """Integrate ẋ = f(x, u) with u held over each step.

    ``x0`` is ``[..., n]``, ``u`` is ``[N, ..., m]`` (time first); returns ``[N+1, ..., n]``.
    With ``lag`` T > 0 the last m states are a first-order actuator lag T ȧ = u − a of the
    first m inputs (m: ``lagged``, default all), stepped by its exact exponential as the
    compiled kernel steps it (the stages read it at a(t + c h) = u + (a − u) e^(−c h / T)):
    as an RK4 state it grows past h/T = 2.79.
    """
    h = dt / substeps
    if lag > 0.0:
        half = math.exp(-0.5 * h / lag)
        m = u.shape[-1] if lagged is None else lagged
    x = x0
    out = [x]
    for k in range(u.shape[0]):
        uk = u[k]
        for _ in range(substeps):
            # fused add-with-scale: half the tensor operations of the textbook form, which
            # matters when the state is small and the per-operation overhead dominates
            k1 = f(x, uk)
            if lag > 0.0:
                body, a, command = x[..., :-m], x[..., -m:], uk[..., :m]
                mid = torch.cat([body, command + (a - command) * half], -1)
                end = torch.cat([body, command + (a - command) * (half * half)], -1)
                k2 = f(mid + 0.5 * h * _zero_tail(k1, m), uk)
                k3 = f(mid + 0.5 * h * _zero_tail(k2, m), uk)
                k4 = f(end + h * _zero_tail(k3, m), uk)
                acc = torch.add(k1, k2, alpha=2.0).add_(k3, alpha=2.0).add_(k4)
                x = end + (h / 6.0) * _zero_tail(acc, m)
                continue
            k2 = f(torch.add(x, k1, alpha=0.5 * h), uk)
            k3 = f(torch.add(x, k2, alpha=0.5 * h), uk)
            k4 = f(torch.add(x, k3, alpha=h), uk)
            acc = torch.add(k1, k2, alpha=2.0).add_(k3, alpha=2.0).add_(k4)
            x = torch.add(x, acc, alpha=h / 6.0)
        out.append(x)
    return torch.stack(out, 0)


def _zero_tail(k: Tensor, m: int) -> Tensor:
    """``k`` with its last m entries zeroed: the lag states move by their exponential only."""
    return torch.cat([k[..., :-m], torch.zeros_like(k[..., -m:])], -1)
