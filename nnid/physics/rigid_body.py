"""Rigid-body mass and Coriolis-centripetal terms, and a cuboid inertia estimate.

M_RB follows Fossen with the inertia tensor about the body origin (Weiss eq. 19; McCarter eq.
2.21). C_RB is Fossen (2011) eq. 3.60's parametrisation, which does not depend on the linear
velocity, not the one of Weiss eqs 23-26 (McCarter eq. 2.24), which does: the matrices differ,
C_RB(ν) ν is the same (the force is unique, its matrix is not). Both are skew-symmetric, so
νᵀ C_RB(ν) ν = 0.
"""

from __future__ import annotations

import torch
from torch import Tensor

from nnid.physics.kinematics import skew


def inertia_tensor(inertia: Tensor) -> Tensor:
    """Accept (Ix, Iy, Iz) or a full 3x3 tensor; return the 3x3 tensor."""
    if inertia.shape[-1] == 3 and (inertia.dim() == 1 or inertia.shape[-2:] != (3, 3)):
        return torch.diag_embed(inertia)
    return inertia


def rigid_body_mass_matrix(mass: Tensor, r_g: Tensor, inertia: Tensor) -> Tensor:
    """M_RB = [[m I₃, −m S(r_g)], [m S(r_g), I_o]] (Weiss eq. 19; McCarter 2.21)."""
    mass = torch.as_tensor(mass, dtype=r_g.dtype)
    m = mass[..., None, None]
    eye = torch.eye(3, dtype=r_g.dtype).expand(*r_g.shape[:-1], 3, 3)
    s = skew(r_g)
    top = torch.cat([m * eye, -m * s], -1)
    bottom = torch.cat([m * s, inertia_tensor(inertia)], -1)
    return torch.cat([top, bottom], -2)


def rigid_body_coriolis_matrix(mass: Tensor, r_g: Tensor, inertia: Tensor, nu: Tensor) -> Tensor:
    """C_RB(ν) = [[m S(ω), −m S(ω) S(r_g)], [m S(r_g) S(ω), −S(I_o ω)]]: Fossen (2011) eq.
    3.60, the form independent of the linear velocity; skew-symmetric.

    Not the matrix of Weiss eqs 23-26 (McCarter eq. 2.24), whose blocks hold u, v, w; the
    product C_RB(ν) ν, all the equations of motion use, is the same.
    """
    mass = torch.as_tensor(mass, dtype=nu.dtype)
    m = mass[..., None, None]
    omega = nu[..., 3:6]
    s_w = skew(omega)
    s_g = skew(r_g).expand(*s_w.shape)
    inertia = inertia_tensor(inertia)
    i_w = (inertia @ omega.unsqueeze(-1)).squeeze(-1)
    top = torch.cat([m * s_w, -m * s_w @ s_g], -1)
    bottom = torch.cat([m * s_g @ s_w, -skew(i_w)], -1)
    return torch.cat([top, bottom], -2)


def rigid_body_coriolis_force(mass: Tensor, r_g: Tensor, inertia: Tensor, nu: Tensor) -> Tensor:
    """C_RB(ν) ν without forming the matrix: [m(ω×v + ω×(ω×r_g)); m r_g×(ω×v) + ω×I_o ω]."""
    mass = torch.as_tensor(mass, dtype=nu.dtype)[..., None]
    v, omega = nu[..., 0:3], nu[..., 3:6]
    r_g = r_g.expand(*v.shape)
    w_x_v = torch.linalg.cross(omega, v)
    force = mass * (w_x_v + torch.linalg.cross(omega, torch.linalg.cross(omega, r_g)))
    i_w = (inertia_tensor(inertia) @ omega.unsqueeze(-1)).squeeze(-1)
    moment = mass * torch.linalg.cross(r_g, w_x_v) + torch.linalg.cross(omega, i_w)
    return torch.cat([force, moment], -1)


def cuboid_inertia(mass: float, length: float, width: float, height: float) -> tuple[float, ...]:
    """Principal inertias of a solid cuboid about its centre (Weiss eqs 32-34).

    I_x = m (w² + h²)/12, I_y = m (l² + h²)/12, I_z = m (l² + w²)/12.
    """
    return (
        mass * (width**2 + height**2) / 12.0,
        mass * (length**2 + height**2) / 12.0,
        mass * (length**2 + width**2) / 12.0,
    )
