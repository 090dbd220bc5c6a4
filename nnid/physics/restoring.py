"""Restoring forces g(η) from weight W, buoyancy B, r_g and r_b (Weiss eq. 30; McCarter 2.42-2.44).

g(η) sits on the left-hand side of M ν̇ + C ν + D ν + g(η) = τ, as in Fossen (2011) eq. 4.6.
"""

from __future__ import annotations

import torch
from torch import Tensor


def restoring_force(
    eta: Tensor, weight: Tensor, buoyancy: Tensor, r_g: Tensor, r_b: Tensor
) -> Tensor:
    """g(η) for a submerged vehicle; only φ and θ matter."""
    phi, theta = eta[..., 3], eta[..., 4]
    sth, cth, sphi, cphi = torch.sin(theta), torch.cos(theta), torch.sin(phi), torch.cos(phi)
    weight = torch.as_tensor(weight, dtype=eta.dtype)
    buoyancy = torch.as_tensor(buoyancy, dtype=eta.dtype)
    w_b = weight - buoyancy
    mx = r_g[..., 0] * weight - r_b[..., 0] * buoyancy
    my = r_g[..., 1] * weight - r_b[..., 1] * buoyancy
    mz = r_g[..., 2] * weight - r_b[..., 2] * buoyancy
    return torch.stack(
        [
            w_b * sth,
            -w_b * cth * sphi,
            -w_b * cth * cphi,
            -my * cth * cphi + mz * cth * sphi,
            mz * sth + mx * cth * cphi,
            -mx * cth * sphi - my * sth,
        ],
        -1,
    )
