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
            k1 = f(x, uk)
            k2 = f(x + 0.5 * h * k1, uk)
            k3 = f(x + 0.5 * h * k2, uk)
            k4 = f(x + h * k3, uk)
            x = x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        out.append(x)
    return torch.stack(out, 0)
