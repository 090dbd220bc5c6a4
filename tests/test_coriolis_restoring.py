"""Coriolis and restoring terms against their defining properties (Weiss eqs 19-30)."""

from __future__ import annotations

import numpy as np
import torch

from nnid.physics.added_mass import (
    added_mass_coriolis_force,
    added_mass_coriolis_matrix,
)
from nnid.physics.kinematics import rotation_matrix
from nnid.physics.restoring import restoring_force
from nnid.physics.rigid_body import (
    rigid_body_coriolis_force,
    rigid_body_coriolis_matrix,
    rigid_body_mass_matrix,
)


def _random_rigid(rng):
    a = rng.normal(size=(3, 3))
    inertia = torch.tensor(a @ a.T + 3 * np.eye(3))
    return torch.tensor(25.0), torch.tensor(rng.normal(scale=0.1, size=3)), inertia


def _random_added_mass(rng):
    a = rng.normal(size=(6, 6))
    return torch.tensor(a @ a.T + 6 * np.eye(6))


def test_rigid_body_coriolis_does_no_work(rng):
    """νᵀ C_RB(ν) ν = 0 and C_RB is skew-symmetric (Fossen 2011 eq. 3.60)."""
    m, r_g, inertia = _random_rigid(rng)
    nu = torch.tensor(rng.normal(size=(50, 6)))
    c = rigid_body_coriolis_matrix(m, r_g, inertia, nu)
    assert torch.allclose(c, -c.transpose(-1, -2), atol=1e-12)
    force = rigid_body_coriolis_force(m, r_g, inertia, nu)
    assert torch.allclose(force, (c @ nu.unsqueeze(-1)).squeeze(-1), atol=1e-12)
    assert torch.allclose((nu * force).sum(-1), torch.zeros(50, dtype=torch.float64), atol=1e-11)


def test_added_mass_coriolis_does_no_work(rng):
    """νᵀ C_A(ν) ν = 0 for a full symmetric M_A (Weiss eqs 27-28)."""
    ma = _random_added_mass(rng)
    nu = torch.tensor(rng.normal(size=(50, 6)))
    c = added_mass_coriolis_matrix(ma, nu)
    assert torch.allclose(c, -c.transpose(-1, -2), atol=1e-12)
    force = added_mass_coriolis_force(ma, nu)
    assert torch.allclose(force, (c @ nu.unsqueeze(-1)).squeeze(-1), atol=1e-12)
    assert torch.allclose((nu * force).sum(-1), torch.zeros(50, dtype=torch.float64), atol=1e-10)


def test_rigid_body_coriolis_is_newton_euler(rng):
    """Force part equals m(ω×v + ω×(ω×r_g)), the centripetal acceleration of the CG."""
    m, r_g, inertia = _random_rigid(rng)
    nu = torch.tensor(rng.normal(size=6))
    v, w = nu[:3], nu[3:]
    expected = m * (torch.linalg.cross(w, v) + torch.linalg.cross(w, torch.linalg.cross(w, r_g)))
    assert torch.allclose(rigid_body_coriolis_force(m, r_g, inertia, nu)[:3], expected)


def test_rigid_body_mass_matrix_symmetric_positive_definite(rng):
    m, r_g, inertia = _random_rigid(rng)
    mrb = rigid_body_mass_matrix(m, r_g, inertia)
    assert torch.allclose(mrb, mrb.T)
    assert torch.linalg.eigvalsh(mrb).min() > 0


def test_restoring_equals_weight_and_buoyancy_in_body_frame(rng):
    """g(η) = −[f_G + f_B; r_g×f_G + r_b×f_B] with f_G = J₁ᵀ[0,0,W], f_B = −J₁ᵀ[0,0,B]
    (McCarter 2.42-2.44), checked against the closed form of Weiss eq. 30."""
    w_, b_ = 200.0, 205.0
    r_g = torch.tensor([0.02, -0.01, 0.05])
    r_b = torch.tensor([0.0, 0.01, -0.03])
    eta = torch.zeros(40, 6, dtype=torch.float64)
    eta[:, 3:6] = torch.tensor(rng.uniform(-1.2, 1.2, (40, 3)))
    rt = rotation_matrix(eta[:, 3:6]).transpose(-1, -2)
    f_g = rt @ torch.tensor([0.0, 0.0, w_])
    f_b = -rt @ torch.tensor([0.0, 0.0, b_])
    expected = -torch.cat(
        [
            f_g + f_b,
            torch.linalg.cross(r_g.expand(40, 3), f_g) + torch.linalg.cross(r_b.expand(40, 3), f_b),
        ],
        -1,
    )
    got = restoring_force(eta, torch.tensor(w_), torch.tensor(b_), r_g, r_b)
    assert torch.allclose(got, expected, atol=1e-12)


def test_bottom_heavy_restoring_opposes_tilt():
    """CG below CB: positive roll and pitch give moments that push back (g on the LHS)."""
    eta = torch.tensor([0.0, 0.0, 0.0, 0.2, 0.1, 0.0])
    g = restoring_force(
        eta, torch.tensor(100.0), torch.tensor(100.0), torch.tensor([0, 0, 0.05]), torch.zeros(3)
    )
    assert g[3] > 0 and g[4] > 0  # M ν̇ = −g: restoring accelerations are negative
    assert torch.allclose(g[:3], torch.zeros(3, dtype=torch.float64), atol=1e-14)
