"""Fixed-step RK4 in PyTorch, batched and differentiable (torchdiffeq-style functional surface).

The compiled kernel (:mod:`nnid.physics.compiled`) is the fast path for fixed parameters; this
one lets gradients flow to parameters and states (hybrid models, physics fits).
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import Tensor


def rk4(
    f: Callable[[Tensor, Tensor], Tensor], x0: Tensor, u: Tensor, dt: float, substeps: int = 1
) -> Tensor:
    """Integrate ẋ = f(x, u) with u held over each step.

    ``x0`` is ``[..., n]``, ``u`` is ``[N, ..., m]`` (time first); returns ``[N+1, ..., n]``.
    """
    h = dt / substeps
    x = x0
    out = [x]
    for k in range(u.shape[0]):
        uk = u[k]
        for _ in range(substeps):
            # fused add-with-scale: half the tensor operations of the textbook form, which
            # matters when the state is small and the per-operation overhead dominates
            k1 = f(x, uk)
            k2 = f(torch.add(x, k1, alpha=0.5 * h), uk)
            k3 = f(torch.add(x, k2, alpha=0.5 * h), uk)
            k4 = f(torch.add(x, k3, alpha=h), uk)
            acc = torch.add(k1, k2, alpha=2.0).add_(k3, alpha=2.0).add_(k4)
            x = torch.add(x, acc, alpha=h / 6.0)
        out.append(x)
    return torch.stack(out, 0)
