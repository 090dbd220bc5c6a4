"""Kinematics: rotation R(Θ), Euler-rate transform T(Θ) and J(η).

Weiss eqs 14-17; McCarter eqs 2.5-2.15 (the inverses: McCarter only, Weiss gives none).

Frames: NED world, FRD body, Euler angles zyx (φ roll, θ pitch, ψ yaw) in radians.
All functions take tensors with the components in the last dimension and broadcast over the rest.
"""

from __future__ import annotations

import torch
from torch import Tensor


def skew(a: Tensor) -> Tensor:
    """S(a) with S(a) b = a × b (Fossen's cross-product operator)."""
    zero = torch.zeros_like(a[..., 0])
    x, y, z = a[..., 0], a[..., 1], a[..., 2]
    return torch.stack(
        [
            torch.stack([zero, -z, y], -1),
            torch.stack([z, zero, -x], -1),
            torch.stack([-y, x, zero], -1),
        ],
        -2,
    )


def rotation_matrix(angles: Tensor) -> Tensor:
    """J₁(Θ) = R_z(ψ) R_y(θ) R_x(φ): body-to-NED rotation (Weiss eq. 16; McCarter eq. 2.5).

    ``angles`` is ``[..., 3]`` = (φ, θ, ψ); the result is ``[..., 3, 3]`` and orthonormal.
    """
    phi, theta, psi = angles[..., 0], angles[..., 1], angles[..., 2]
    cphi, sphi = torch.cos(phi), torch.sin(phi)
    cth, sth = torch.cos(theta), torch.sin(theta)
    cpsi, spsi = torch.cos(psi), torch.sin(psi)
    return torch.stack(
        [
            torch.stack(
                [cpsi * cth, -spsi * cphi + cpsi * sth * sphi, spsi * sphi + cpsi * cphi * sth], -1
            ),
            torch.stack(
                [spsi * cth, cpsi * cphi + sphi * sth * spsi, -cpsi * sphi + sth * spsi * cphi], -1
            ),
            torch.stack([-sth, cth * sphi, cth * cphi], -1),
        ],
        -2,
    )


def euler_rate_matrix(angles: Tensor) -> Tensor:
    """J₂(Θ) = T_Θ: body rates (p, q, r) to Euler-angle rates (Weiss eq. 17, its row 1
    corrected; McCarter eq. 2.7).

    Singular at θ = ±π/2, as every zyx Euler parametrisation is.
    """
    phi, theta = angles[..., 0], angles[..., 1]
    cphi, sphi = torch.cos(phi), torch.sin(phi)
    cth, tth = torch.cos(theta), torch.tan(theta)
    one, zero = torch.ones_like(phi), torch.zeros_like(phi)
    return torch.stack(
        [
            # sφ tθ, not Weiss eq. 17's printed sθ tθ (a misprint): φ̇ = p + (q sφ + r cφ) tθ,
            # as McCarter eq. 2.7 and Weiss's own Appendix A code (sin(phi)*tan(theta)) have it;
            # docs/seed_notes/weiss.md
            torch.stack([one, sphi * tth, cphi * tth], -1),
            torch.stack([zero, cphi, -sphi], -1),
            torch.stack([zero, sphi / cth, cphi / cth], -1),
        ],
        -2,
    )


def euler_rate_matrix_inverse(angles: Tensor) -> Tensor:
    """T_Θ⁻¹: Euler-angle rates to body rates (McCarter eq. 2.14)."""
    phi, theta = angles[..., 0], angles[..., 1]
    cphi, sphi = torch.cos(phi), torch.sin(phi)
    cth, sth = torch.cos(theta), torch.sin(theta)
    one, zero = torch.ones_like(phi), torch.zeros_like(phi)
    return torch.stack(
        [
            torch.stack([one, zero, -sth], -1),
            torch.stack([zero, cphi, cth * sphi], -1),
            torch.stack([zero, -sphi, cth * cphi], -1),
        ],
        -2,
    )


def _block_diag(a: Tensor, b: Tensor) -> Tensor:
    zeros = torch.zeros_like(a)
    return torch.cat([torch.cat([a, zeros], -1), torch.cat([zeros, b], -1)], -2)


def kinematics_matrix(eta: Tensor) -> Tensor:
    """J(η) = diag(J₁, J₂), the 6x6 map η̇ = J(η) ν (Weiss eqs 14-15; McCarter eqs 2.10-2.11)."""
    angles = eta[..., 3:6]
    return _block_diag(rotation_matrix(angles), euler_rate_matrix(angles))


def kinematics_matrix_inverse(eta: Tensor) -> Tensor:
    """J(η)⁻¹ = diag(J₁ᵀ, T_Θ⁻¹), the map ν = J⁻¹(η) η̇ (McCarter eqs 2.12-2.15;
    Weiss gives no inverse)."""
    angles = eta[..., 3:6]
    return _block_diag(rotation_matrix(angles).transpose(-1, -2), euler_rate_matrix_inverse(angles))


def eta_dot(eta: Tensor, nu: Tensor) -> Tensor:
    """η̇ = J(η) ν."""
    return (kinematics_matrix(eta) @ nu.unsqueeze(-1)).squeeze(-1)


def body_velocity(eta: Tensor, eta_rate: Tensor) -> Tensor:
    """ν = J(η)⁻¹ η̇: body velocities from pose rates."""
    return (kinematics_matrix_inverse(eta) @ eta_rate.unsqueeze(-1)).squeeze(-1)
