"""The Fossen model against invariances and closed-form motions that the term-by-term tests
(test_fossen_analytic, test_coriolis_restoring) do not reach: a uniform current as an inertial
frame, the metacentric period, energy with the restoring forces on, quadratic free decay and
Prime-system similarity (Weiss Table 4) of the simulator and of a starter vehicle file."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest
import torch

from nnid.datasets.simulator import integrate
from nnid.physics.fossen import FossenModel
from nnid.physics.kinematics import rotation_matrix
from nnid.physics.nondimensional import (
    added_mass_scale,
    damping_scale,
    inertia_scale,
    mass_scale,
    nondimensional_coefficients,
)
from nnid.vehicle import load_vehicle, vehicle_from_dict

_INERTIA = [[1.2, 0.1, 0.05], [0.1, 2.5, 0.02], [0.05, 0.02, 2.8]]
_ADDED = {"X_udot": -10.0, "Y_vdot": -25.0, "Z_wdot": -30.0, "K_pdot": -0.8, "M_qdot": -1.5,
          "N_rdot": -1.2, "Y_rdot": -2.0, "Z_qdot": 1.5, "X_wdot": -0.7}  # fmt: skip


def test_a_uniform_current_is_an_inertial_frame(vehicle_factory):
    """With C_RB independent of the linear velocity, M_RB ν̇ + C_RB(ν)ν = M_RB ν̇_r +
    C_RB(ν_r)ν_r for an irrotational current (Fossen 2011 §10.3), so the motion through the
    water is the still-water motion: same attitude, ν − ν_c(η) = ν_still, and positions that
    differ by v_c t. Every term on: r_g ≠ 0, coupled M_A, coupled damping, W ≠ B, bias."""
    common = dict(
        inertia=_INERTIA, added_mass=_ADDED, r_g=[0.02, -0.01, 0.06], r_b=[0.0, 0.01, -0.02],
        buoyancy=300.0, external_bias=[1, 2, -1, 0.1, 0.2, 0.3],
        damping={"coefficients": {"X:u*abs(u)": -30, "Y:v": -5, "Y:v*abs(v)": -20,
                 "Z:w*abs(w)": -25, "K:p": -2, "M:q": -3, "N:r*abs(r)": -1.5,
                 "N:v*abs(r)": -2, "M:q*V": -1.5}},
    )  # fmt: skip
    v_c = np.array([0.3, -0.2, 0.1])
    still = FossenModel.from_vehicle(vehicle_factory(**common))
    moving = FossenModel.from_vehicle(vehicle_factory(**common, current=v_c.tolist()))
    x0 = np.array([0, 0, 0, 0.2, -0.1, 0.5, 0.4, -0.3, 0.2, 0.3, -0.2, 0.4])
    tau = np.random.default_rng(0).normal(size=(400, 6)) * [20, 20, 20, 2, 2, 2]
    dt = 0.02
    xc = integrate(moving, x0, tau, dt, 2)
    xs0 = x0.copy()
    xs0[6:] -= moving.current_body(torch.tensor(x0[:6])).numpy()
    xs = integrate(still, xs0, tau, dt, 2)
    nu_c = moving.current_body(torch.tensor(xc[:, :6])).numpy()
    t = np.arange(xc.shape[0]) * dt
    assert np.ptp(xc[:, 5]) > 1.0  # it turned: ν_c moved around the body
    np.testing.assert_allclose(xc[:, 3:6], xs[:, 3:6], atol=1e-7)
    np.testing.assert_allclose(xc[:, 6:] - nu_c, xs[:, 6:], atol=1e-7)
    np.testing.assert_allclose(xc[:, :3] - t[:, None] * v_c, xs[:, :3], atol=1e-7)


@pytest.mark.parametrize("dof", [3, 4])
def test_small_tilts_oscillate_at_the_metacentric_period(vehicle_factory, dof):
    """Neutral, CG z_g below CB, no damping: (I − K_ṗ − m² z_g² / (m − Y_v̇)) φ̈ = −W z_g φ for
    roll about the body origin (the sway that M_RB's m S(r_g) couples in shortens the
    period), likewise pitch with surge. The period at 0.01 rad is the linear one × (1 + φ₀²/16)."""
    z_g, amp = 0.05, 0.01
    veh = vehicle_factory(r_g=[0, 0, z_g])
    x0 = np.zeros(12)
    x0[dof] = amp
    dt = 0.005
    y = integrate(FossenModel.from_vehicle(veh), x0, np.zeros((4000, 6)), dt)[:, dof]
    down = np.flatnonzero((y[:-1] > 0) & (y[1:] <= 0))
    crossings = (down + y[down] / (y[down] - y[down + 1])) * dt
    period = np.diff(crossings).mean()
    rot, trans = ("K_pdot", "Y_vdot") if dof == 3 else ("M_qdot", "X_udot")
    inertia = (
        veh.inertia[dof - 3]
        - veh.added_mass[rot]
        - veh.mass**2 * z_g**2 / (veh.mass - veh.added_mass[trans])
    )
    linear = 2 * np.pi / np.sqrt(veh.weight * z_g / inertia)
    assert period == pytest.approx(linear * (1 + amp**2 / 16), rel=1e-6)


def test_energy_with_restoring_forces_is_conserved(vehicle_factory):
    """No damping, no forces: T + V is constant, V = −(W − B) z − W (J₁ r_g)_z + B (J₁ r_b)_z
    the potential of weight and buoyancy, so g(η) = J(η)ᵀ ∇V holds along the motion (with
    W ≠ B, r_g and r_b off the z axis, a full inertia tensor and coupled added mass)."""
    veh = vehicle_factory(inertia=_INERTIA, added_mass=_ADDED, r_g=[0.03, -0.02, 0.06],
                          r_b=[-0.01, 0.01, -0.03], buoyancy=300.0)  # fmt: skip
    model = FossenModel.from_vehicle(veh)
    x0 = [0, 0, 0, 0.3, -0.2, 0.5, 0.2, -0.1, 0.1, 0.4, -0.3, 0.2]
    x = torch.as_tensor(integrate(model, np.array(x0, float), np.zeros((3000, 6)), 0.005))
    kinetic = model.kinetic_energy(x[:, 6:12])
    rot = rotation_matrix(x[:, 3:6])
    w, b = float(model.weight), float(model.buoyancy)
    potential = -(w - b) * x[:, 2] - w * (rot @ model.r_g)[:, 2] + b * (rot @ model.r_b)[:, 2]
    energy = (kinetic + potential).numpy()
    assert np.ptp(kinetic.numpy()) > 50.0  # the energy moved between the two
    assert np.abs(energy - energy[0]).max() < 1e-8 * np.ptp(kinetic.numpy())


@pytest.mark.parametrize("key", ["X:u*abs(u)", "Z:w*abs(w)", "N:r*abs(r)"])
def test_quadratic_free_decay(vehicle_factory, key):
    """m_ν ν̇ = k ν|ν| from ν₀: ν(t) = ν₀ / (1 + |k ν₀| t / m_ν), and nothing else moves."""
    veh = vehicle_factory(damping={"coefficients": {key: -40.0}})
    i = "XYZKMN".index(key[0])
    dof = "uvwpqr"[i]
    rigid = veh.mass if i < 3 else veh.inertia[i - 3]
    m_nu = rigid - veh.added_mass[f"{key[0]}_{dof}dot"]
    x0 = np.zeros(12)
    x0[6 + i] = -1.5
    states = integrate(FossenModel.from_vehicle(veh), x0, np.zeros((1000, 6)), 0.005)
    t = np.arange(states.shape[0]) * 0.005
    np.testing.assert_allclose(states[:, 6 + i], -1.5 / (1 + 40 * 1.5 * t / m_nu), atol=1e-6)
    assert not np.delete(states[:, 6:], i, 1).any()


def test_prime_similar_vehicles_move_alike():
    """Prime system I (Weiss Table 4): a vehicle λ times as long with the same primes (at the
    same ρ and U) flies the same motion in t U / L, positions × λ and rates / λ, under forces
    × λ² and moments × λ³, where gravity plays no part (W = B, r_b = r_g). Coupled damping
    terms with U, V and |·| factors hold each term's divisor to its dimensions."""
    base = dict(name="a", mass=30.0, length=1.0, rho=1000.0, inertia=[1.2, 2.5, 2.8],
                r_g=[0.02, -0.01, 0.05], r_b=[0.02, -0.01, 0.05], added_mass=_ADDED,
                damping={"coefficients": {"X:u*abs(u)": -30, "Y:v": -5, "N:v*abs(r)": -2,
                         "M:q*V": -1.5, "K:abs(p)*Vw": -0.3, "Z:w*Vv": -0.2, "N:r": -1.0,
                         "K:p*abs(p)": -0.4, "Y:r*abs(r)": -0.5, "M:w*abs(q)": -0.3,
                         "X:U*u": -3, "M:q*r": 0.2}})  # fmt: skip
    small = vehicle_from_dict(base)
    lam, rho = 2.0, 1000.0
    primes = nondimensional_coefficients(small, 1.0)
    big = dict(base, name="b", length=lam, r_g=[lam * x for x in base["r_g"]])
    big["r_b"] = big["r_g"]
    big["mass"] = primes["mass"] * mass_scale(rho, lam)
    big["inertia"] = [primes[k] * inertia_scale(rho, lam) for k in ("Ix", "Iy", "Iz")]
    big["added_mass"] = {k: primes[k] * added_mass_scale(k, rho, lam) for k in _ADDED}
    big["damping"] = {
        "coefficients": {
            k: primes[k] * damping_scale(k, rho, lam, 1.0) for k in base["damping"]["coefficients"]
        }
    }
    tau = np.random.default_rng(0).normal(size=(300, 6)) * [10, 10, 10, 1, 1, 1]
    state_scale = np.array([lam] * 3 + [1.0] * 6 + [1 / lam] * 3)
    x0 = np.array([0, 0, 0, 0.1, 0.2, -0.3, 0.4, -0.2, 0.1, 0.3, -0.2, 0.1])
    a = integrate(FossenModel.from_vehicle(small), x0, tau, 0.02, 2)
    force_scale = np.array([lam**2] * 3 + [lam**3] * 3)
    b = integrate(
        FossenModel.from_vehicle(vehicle_from_dict(big)), x0 * state_scale, tau * force_scale,
        0.02 * lam, 2,
    )  # fmt: skip
    assert np.ptp(a[:, 5]) > 0.5
    np.testing.assert_allclose(b / state_scale, a, atol=1e-12)


def test_a_starter_file_scales_as_the_prime_system():
    """`nnid vehicle --mass --size` for a vehicle λ times the BlueROV2 Heavy with λ³ its mass
    has the Heavy's added mass and damping in Prime-system I, rotational terms included
    (K_ṗ and K_p|p| ∝ λ⁵, M_q ∝ λ⁴): they were scaled by area × arm alone (λ³), a quarter of
    the added inertia and of the quadratic rotational damping at twice the size."""
    from nnid.vehicle_starter import starter_text

    ref = load_vehicle("bluerov2_heavy")
    for lam in (0.5, 2.0):
        size = (0.457 * lam, 0.575 * lam, 0.254 * lam)  # the Heavy's box
        data = tomllib.loads(starter_text("scaled", ref.mass * lam**3, size))
        for key, value in ref.added_mass.items():
            ratio = added_mass_scale(key, 1.0, lam) / added_mass_scale(key, 1.0, 1.0)
            assert data["added_mass"][key] == pytest.approx(value * ratio, rel=1e-3), key
        for key, value in ref.damping.coefficients.items():
            ratio = damping_scale(key, 1.0, lam, 1.0) / damping_scale(key, 1.0, 1.0, 1.0)
            assert data["damping"]["coefficients"][key] == pytest.approx(value * ratio, rel=1e-3)
