"""The Fossen model against analytic cases: steady speed, free decay, conservation laws."""

from __future__ import annotations

import numpy as np
import torch

from nnid.datasets.simulator import integrate
from nnid.physics import compiled
from nnid.physics.fossen import FossenModel
from nnid.vehicle import load_vehicle


def _run(vehicle, tau, seconds, dt=0.01, x0=None, integrator="rk4"):
    model = FossenModel.from_vehicle(vehicle)
    n = round(seconds / dt)
    x = np.zeros(model.state_size)
    if x0 is not None:
        x[: len(x0)] = x0
    return integrate(model, x, np.tile(np.asarray(tau, float), (n, 1)), dt, integrator=integrator)


def test_steady_surge_speed_quadratic(vehicle_factory):
    """u_ss = sqrt(F / −X_u|u|) for quadratic-only surge drag."""
    veh = vehicle_factory(damping={"coefficients": {"X:u*abs(u)": -40.0}})
    states = _run(veh, [25.0, 0, 0, 0, 0, 0], 60.0)
    assert abs(states[-1, 6] - np.sqrt(25.0 / 40.0)) < 1e-6


def test_steady_surge_speed_linear(vehicle_factory):
    """u_ss = F / −X_u for linear surge drag."""
    veh = vehicle_factory(damping={"coefficients": {"X:u": -12.0}})
    states = _run(veh, [6.0, 0, 0, 0, 0, 0], 60.0)
    assert abs(states[-1, 6] - 0.5) < 1e-6


def test_free_decay_time_constant(vehicle_factory):
    """u(t) = u₀ exp(−t k_u / m_u), m_u = m − X_u̇ (the time constant is m_u / k_u)."""
    veh = vehicle_factory(damping={"coefficients": {"X:u": -8.0}})
    m_u = veh.mass - veh.added_mass["X_udot"]
    states = _run(veh, [0.0] * 6, 10.0, x0=[0, 0, 0, 0, 0, 0, 1.0, 0, 0, 0, 0, 0])
    t = np.arange(states.shape[0]) * 0.01
    slope = np.polyfit(t, np.log(states[:, 6]), 1)[0]
    assert abs(-1.0 / slope - m_u / 8.0) < 1e-6 * m_u / 8.0
    assert np.allclose(states[:, 6], np.exp(-t * 8.0 / m_u), atol=1e-9)


def _free_body(vehicle_factory):
    """No damping, no forces, neutral (W = B) with r_b = r_g, so g(η) = 0; full M_A."""
    added = {"X_udot": -10.0, "Y_vdot": -25.0, "Z_wdot": -30.0, "K_pdot": -0.8,
             "M_qdot": -1.5, "N_rdot": -1.2, "Y_rdot": -2.0, "N_vdot": -2.0,
             "Z_qdot": 1.5, "M_wdot": 1.5}  # fmt: skip
    inertia = [[1.2, 0.1, 0.05], [0.1, 2.5, 0.02], [0.05, 0.02, 2.8]]
    r = [0.02, 0.01, 0.04]
    return vehicle_factory(added_mass=added, r_g=r, r_b=r, inertia=inertia)


def test_kinetic_energy_conserved(vehicle_factory):
    """With no damping, forces or restoring, T = ½νᵀMν is constant over a long run."""
    veh = _free_body(vehicle_factory)
    x0 = [0, 0, 0, 0.1, -0.2, 0.3, 0.5, -0.3, 0.2, 0.4, -0.6, 0.8]
    states = _run(veh, [0.0] * 6, 300.0, x0=x0)
    model = FossenModel.from_vehicle(veh)
    energy = model.kinetic_energy(torch.as_tensor(states[:, 6:12])).numpy()
    assert np.abs(energy / energy[0] - 1).max() < 1e-8
    assert np.abs(states[-1, 6:12] - states[0, 6:12]).max() > 0.1  # it did move and turn


def test_kirchhoff_impulses_conserved(vehicle_factory):
    """Body in an ideal fluid: the world-frame linear impulse J₁(Mν)₁ and the angular impulse
    about the world origin J₁(Mν)₂ + x × J₁(Mν)₁ are constant (Kirchhoff's equations)."""
    veh = _free_body(vehicle_factory)
    x0 = [0, 0, 0, 0.1, -0.2, 0.3, 0.5, -0.3, 0.2, 0.4, -0.6, 0.8]
    states = torch.as_tensor(_run(veh, [0.0] * 6, 30.0, dt=0.005, x0=x0))
    model = FossenModel.from_vehicle(veh)
    impulse = states[:, 6:12] @ model.mass_matrix().T
    rot = rotation_matrix_of(states)
    lin = (rot @ impulse[:, :3].unsqueeze(-1)).squeeze(-1)
    ang = (rot @ impulse[:, 3:].unsqueeze(-1)).squeeze(-1) + torch.linalg.cross(states[:, :3], lin)
    # RK4 truncation error (it shrinks as dt⁴), not a physics error, sets the tolerance
    assert torch.allclose(lin, lin[0].expand_as(lin), atol=1e-7)
    assert torch.allclose(ang, ang[0].expand_as(ang), atol=1e-6)


def rotation_matrix_of(states):
    from nnid.physics.kinematics import rotation_matrix

    return rotation_matrix(states[:, 3:6])


def test_bottom_heavy_vehicle_rights_itself():
    """Seamor (CB 5 cm above CG, Weiss App. A) released at 0.5 rad roll and 0.3 rad pitch settles
    back towards level under its quadratic damping."""
    veh = load_vehicle("seamor")
    states = _run(veh, [0.0] * 6, 120.0, x0=[0, 0, 0, 0.5, 0.3, 0.0])
    first, last = states[:2000], states[-2000:]
    for k in (3, 4):  # roll, pitch: amplitude shrinks and oscillates about level
        assert np.abs(last[:, k]).max() < 0.3 * np.abs(first[:, k]).max()
        assert abs(last[:, k].mean()) < 0.03
        assert np.sign(first[:, k]).min() < 0  # it swung through level, not drifted


def test_compiled_rhs_equals_torch_rhs(vehicle_factory, rng):
    """The compiled kernel evaluates the same physics as the torch terms, every term switched
    on: coupled damping with V and η terms, full M_A, offsets, current, bias and lag."""
    veh = vehicle_factory(
        inertia=[[1.2, 0.1, 0.05], [0.1, 2.5, 0.02], [0.05, 0.02, 2.8]],
        r_g=[0.01, -0.02, 0.05], r_b=[0.0, 0.0, -0.01], buoyancy=300.0,
        added_mass={"X_udot": -5, "Y_vdot": -10, "Z_wdot": -12, "K_pdot": -0.5, "M_qdot": -0.7,
                    "N_rdot": -0.9, "Y_rdot": -0.3, "N_vdot": -0.3},
        damping={"u_c": 1.2, "coefficients": {"X:u*abs(u)": -30, "Y:v": -5, "N:v*abs(r)": -2,
                 "M:q*V": -1.5, "X:u*v*(eta-1)": 0.4, "K:abs(p)*Vw": -0.3, "Z:w*Vv": -0.2}},
        current=[0.1, -0.2, 0.05], external_bias=[1, 2, 3, 0.1, 0.2, 0.3], actuator_lag=0.3,
    )  # fmt: skip
    model = FossenModel.from_vehicle(veh)
    form = model.feature_form()
    for _ in range(20):
        x, tau = rng.normal(size=18), rng.normal(size=6) * 10
        expected = model.rhs(torch.tensor(x), torch.tensor(tau)).numpy()
        assert np.allclose(compiled.rhs(form, x, tau), expected, atol=1e-12)


def test_integrators_agree(vehicle_factory):
    """Compiled RK4, torch RK4 and the adaptive DOP853 give the same trajectory."""
    veh = load_vehicle("seamor")
    tau = [20.0, 10.0, -5.0, 1.0, 0.0, 2.0]
    a = _run(veh, tau, 5.0, integrator="rk4")
    b = _run(veh, tau, 5.0, integrator="torch")
    c = _run(veh, tau, 5.0, integrator="adaptive")
    assert np.abs(a - b).max() < 1e-10
    assert np.abs(a - c).max() < 1e-6


def test_batched_equals_single(vehicle_factory, rng):
    veh = load_vehicle("seamor")
    form = FossenModel.from_vehicle(veh).feature_form()
    tau = rng.normal(size=(3, 200, 6)) * 10
    x0 = np.zeros((3, 12))
    batch = compiled.integrate_rk4(form, x0, tau, 0.01, 2)
    for b in range(3):
        assert np.array_equal(batch[b], compiled.integrate_rk4(form, x0[b], tau[b], 0.01, 2))


def test_rhs_is_differentiable_in_the_parameters(vehicle_factory):
    """Gradients reach damping coefficients, added mass and mass (for hybrids and physics fits):
    gradcheck against finite differences in float64."""
    veh = vehicle_factory(damping={"coefficients": {"X:u*abs(u)": -40.0, "N:v*abs(r)": -2.0}})
    base = FossenModel.from_vehicle(veh)
    x = torch.tensor([0.1, 0.2, 0.3, 0.1, -0.2, 0.4, 0.5, -0.3, 0.2, 0.1, -0.2, 0.3])
    tau = torch.tensor([5.0, 1.0, -2.0, 0.1, 0.2, -0.3])

    def f(coef, added, mass):
        base.damping.coefficients = coef
        base.added_mass = added
        base.mass = mass
        return base.rhs(x, tau)

    args = (
        base.damping.coefficients.clone().requires_grad_(True),
        base.added_mass.clone().requires_grad_(True),
        base.mass.clone().requires_grad_(True),
    )
    assert torch.autograd.gradcheck(f, args)
