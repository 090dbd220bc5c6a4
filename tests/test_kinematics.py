"""Kinematics against rotation-group facts (Weiss eqs 14-17; McCarter 2.5-2.15)."""

from __future__ import annotations

import numpy as np
import torch

from nnid.physics.kinematics import (
    body_velocity,
    eta_dot,
    euler_rate_matrix,
    euler_rate_matrix_inverse,
    kinematics_matrix,
    kinematics_matrix_inverse,
    rotation_matrix,
    skew,
)


def _angles(rng, n=64):
    a = rng.uniform(-np.pi, np.pi, (n, 3))
    a[:, 1] = rng.uniform(-1.4, 1.4, n)  # away from the θ = ±π/2 singularity
    return torch.tensor(a)


def test_rotation_is_orthonormal_with_unit_determinant(rng):
    r = rotation_matrix(_angles(rng))
    eye = torch.eye(3, dtype=torch.float64).expand_as(r)
    assert torch.allclose(r @ r.transpose(-1, -2), eye, atol=1e-14)
    assert torch.allclose(torch.linalg.det(r), torch.ones(r.shape[0], dtype=torch.float64))


def test_rotation_is_zyx_composition():
    """J₁ = R_z(ψ) R_y(θ) R_x(φ): a pure yaw of 90° maps body x to NED east (y)."""
    r = rotation_matrix(torch.tensor([0.0, 0.0, np.pi / 2]))
    assert torch.allclose(
        r @ torch.tensor([1.0, 0.0, 0.0]), torch.tensor([0.0, 1.0, 0.0]), atol=1e-15
    )
    r = rotation_matrix(torch.tensor([0.0, np.pi / 2, 0.0]))  # nose up: body x points up (−z)
    assert torch.allclose(
        r @ torch.tensor([1.0, 0.0, 0.0]), torch.tensor([0.0, 0.0, -1.0]), atol=1e-15
    )


def test_euler_rates_match_rotation_kinematics(rng):
    """Ṙ = R S(ω) with ω = T_Θ⁻¹ Θ̇: J₂ is the Euler-rate map of the rotation (Weiss eq. 17)."""
    angles = _angles(rng, 32)
    rates = torch.tensor(rng.normal(size=(32, 3)))
    h = 1e-6
    r_dot = (rotation_matrix(angles + h * rates) - rotation_matrix(angles - h * rates)) / (2 * h)
    omega = (euler_rate_matrix_inverse(angles) @ rates.unsqueeze(-1)).squeeze(-1)
    assert torch.allclose(r_dot, rotation_matrix(angles) @ skew(omega), atol=1e-8)
    back = (euler_rate_matrix(angles) @ omega.unsqueeze(-1)).squeeze(-1)
    assert torch.allclose(back, rates, atol=1e-12)


def test_j_and_its_inverse(rng):
    eta = torch.zeros(16, 6, dtype=torch.float64)
    eta[:, 3:6] = _angles(rng, 16)
    eye = torch.eye(6, dtype=torch.float64).expand(16, 6, 6)
    assert torch.allclose(kinematics_matrix(eta) @ kinematics_matrix_inverse(eta), eye, atol=1e-12)
    nu = torch.tensor(rng.normal(size=(16, 6)))
    assert torch.allclose(body_velocity(eta, eta_dot(eta, nu)), nu, atol=1e-12)


def test_skew_is_cross_product(rng):
    a, b = torch.tensor(rng.normal(size=(8, 3))), torch.tensor(rng.normal(size=(8, 3)))
    assert torch.allclose((skew(a) @ b.unsqueeze(-1)).squeeze(-1), torch.linalg.cross(a, b))


def test_the_numpy_euler_rate_matrices_are_the_kinematics(rng):
    """nnid.datasets.log's numpy T_Θ and T_Θ⁻¹ (read and derive without torch) are
    euler_rate_matrix and its inverse, to rounding (they differ by an ulp at most)."""
    from nnid.datasets.log import euler_rate_matrices

    angles = _angles(rng, 200)
    for inverse, torch_matrix in ((False, euler_rate_matrix), (True, euler_rate_matrix_inverse)):
        got = euler_rate_matrices(angles.numpy(), inverse=inverse)
        want = torch_matrix(angles).numpy()
        np.testing.assert_allclose(got, want, rtol=1e-14, atol=1e-15)
