"""Restoring forces g(η) from weight W, buoyancy B, r_g and r_b (Weiss eq. 30; McCarter 2.42-2.44).

g(η) sits on the left-hand side of M ν̇ + C ν + D ν + g(η) = τ, as in Fossen (2011) eq. 4.6.
It is linear in s(η) = (sin θ, cos θ sin φ, cos θ cos φ): g(η) = G s(η), G of W, B, r_g, r_b.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import Tensor


def restoring_matrix(
    weight: Tensor | float,
    buoyancy: Tensor | float,
    r_g: Tensor | Sequence[float],
    r_b: Tensor | Sequence[float],
    dtype: torch.dtype = torch.float64,
) -> Tensor:
    """G ``[..., 6, 3]`` with g(η) = G (sin θ, cos θ sin φ, cos θ cos φ), from its closed form.

    Built entry by entry, not fitted: a zero of G (W = B, or the centres of gravity and
    buoyancy on one vertical) is exactly zero, where a least-squares fit left last-bit forces
    that depend on the processor's kernels and moved a vehicle in DOFs nothing drives.
    """
    weight = torch.as_tensor(weight, dtype=dtype)
    buoyancy = torch.as_tensor(buoyancy, dtype=dtype)
    r_g, r_b = torch.as_tensor(r_g, dtype=dtype), torch.as_tensor(r_b, dtype=dtype)
    w_b = weight - buoyancy
    mx = r_g[..., 0] * weight - r_b[..., 0] * buoyancy
    my = r_g[..., 1] * weight - r_b[..., 1] * buoyancy
    mz = r_g[..., 2] * weight - r_b[..., 2] * buoyancy
    w_b, mx, my, mz = torch.broadcast_tensors(w_b, mx, my, mz)
    zero = torch.zeros_like(w_b)
    rows = [
        (w_b, zero, zero),
        (zero, -w_b, zero),
        (zero, zero, -w_b),
        (zero, mz, -my),
        (mz, zero, mx),
        (-my, -mx, zero),
    ]
    return torch.stack([torch.stack(row, -1) for row in rows], -2)


def restoring_force(
    eta: Tensor, weight: Tensor, buoyancy: Tensor, r_g: Tensor, r_b: Tensor
) -> Tensor:
    """g(η) = G s(η) for a submerged vehicle (:func:`restoring_matrix`); only φ and θ matter."""
    phi, theta = eta[..., 3], eta[..., 4]
    cth = torch.cos(theta)
    s = torch.stack([torch.sin(theta), cth * torch.sin(phi), cth * torch.cos(phi)], -1)
    g = restoring_matrix(weight, buoyancy, r_g, r_b, eta.dtype)
    s0, s1, s2 = s[..., 0], s[..., 1], s[..., 2]
    # G's nonzero entries only (at most two a row), as G s sums them: G's zeros add nothing
    # exactly, so these are its bits, without the [N, 6, 3] product (6x its cost on a log)
    return torch.stack(
        [
            g[..., 0, 0] * s0,
            g[..., 1, 1] * s1,
            g[..., 2, 2] * s2,
            g[..., 3, 1] * s1 + g[..., 3, 2] * s2,
            g[..., 4, 0] * s0 + g[..., 4, 2] * s2,
            g[..., 5, 0] * s0 + g[..., 5, 1] * s1,
        ],
        -1,
    )
