"""The Fossen model against analytic cases: steady speed, free decay, conservation laws."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pandas as pd
import pytest
import torch

from nnid.datasets.log import TAU
from nnid.datasets.simulator import Autopilot, integrate
from nnid.evaluation.prediction import Replay, fly_closed_loop, predict_closed_loop
from nnid.loop.scenarios import effect_log
from nnid.physics import compiled
from nnid.physics.fossen import FossenModel
from nnid.physics.parts import Parts
from nnid.physics.thrusters import apply_deadband, apply_installation
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


def test_one_of_an_added_mass_pair_is_its_mirror_too(vehicle_factory):
    """A vehicle file giving Y_rdot and Z_qdot without their mirrors: M_A is symmetric
    (McCarter eq. 2.33), so they fill N_vdot and M_wdot as well, and the vehicle conserves its
    energy as the one that gives both (an asymmetric M_A gained 690 % in 30 s); mirrors that
    differ are refused, and so is a fit of both as two unknowns."""
    from nnid.errors import NnidInputError
    from nnid.models.parametric import ParametricFossen, vehicle_with

    both = _free_body(vehicle_factory)
    added = {k: v for k, v in both.added_mass.items() if k not in ("N_vdot", "M_wdot")}
    one = vehicle_factory(added_mass=added, r_g=both.r_g, r_b=both.r_b, inertia=both.inertia)
    mass = FossenModel.from_vehicle(one).mass_matrix().numpy()
    assert np.array_equal(mass, FossenModel.from_vehicle(both).mass_matrix().numpy())
    x0 = [0, 0, 0, 0.1, -0.2, 0.3, 0.5, -0.3, 0.2, 0.4, -0.6, 0.8]
    states = _run(one, [0.0] * 6, 30.0, x0=x0)
    energy = FossenModel.from_vehicle(one).kinetic_energy(torch.as_tensor(states[:, 6:12]))
    assert np.abs(energy.numpy() / energy.numpy()[0] - 1).max() < 1e-8
    with pytest.raises(ValueError, match="Y_rdot = -2 and N_vdot = -3 differ"):
        vehicle_factory(added_mass={**both.added_mass, "N_vdot": -3.0})
    # a fitted value of one of a declared pair is the other's too
    assert vehicle_with(both, {"Y_rdot": -4.0}).added_mass["N_vdot"] == -4.0
    with pytest.raises(NnidInputError, match="'Y_rdot' and 'N_vdot' are one parameter"):
        ParametricFossen(both, ["Y_rdot", "N_vdot"])
    # the mirror reads as the matrix holds it (N_vdot read 0 where only Y_rdot was given)
    assert Parts.from_vehicle(one).get("N_vdot") == -2.0
    # a hybrid trained jointly moves both entries (it moved Y_rdot's alone)
    from nnid.models.hybrid import HybridPhysics

    physics = HybridPhysics(Parts.from_vehicle(one), ["Y_rdot", "X_udot"])
    with torch.no_grad():
        physics.delta[:] = torch.tensor([0.5, 0.2], dtype=torch.float64)
    m_a = physics.fossen().added_mass.detach().numpy()
    assert physics.values()["Y_rdot"] == pytest.approx(-2.0 + 0.5 * 2.0)  # θ + |θ| δ
    assert m_a[1, 5] == m_a[5, 1] == pytest.approx(1.0) and np.array_equal(m_a, m_a.T)


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


def _stepped(form, pilot, eta_pos, eta_neg, x0, tau_open, dt, substeps, deadband=0.0):
    """The closed-loop flight stepped from Python, one compiled RK4 call per sample."""
    states, commands = [np.asarray(x0, float)], []
    for j in range(tau_open.shape[0]):
        command = tau_open[j] + pilot.force(states[-1])
        applied = apply_installation(apply_deadband(command, deadband), eta_pos, eta_neg)
        commands.append(command)
        states.append(compiled.integrate_rk4(form, states[-1], applied[None], dt, substeps)[-1])
        if not np.isfinite(states[-1]).all():
            break
    return np.array(states), np.array(commands)


def test_compiled_pd_flight_is_the_flight_stepped_from_python(rng, all_numba_threads):
    """fly_pd (the PD autopilot, deadband and installation inside the compiled loop) gives the
    bits of the per-sample Python loop: commands, states, heading errors wrapped across ±π,
    one window or many (in parallel threads)."""
    form = FossenModel.from_vehicle(load_vehicle("vt690")).feature_form()
    pilot = Autopilot(
        kp=[0, 0, 40, 5, 60, 30], kd=[0, 0, 60, 1.5, 80, 80], reference=[0, 0, 2, 0, 0, 3.1]
    )
    eta_pos = np.array([1.0, 1.0, 0.9, 1.0, 1.1, 0.8])
    eta_neg = np.array([0.7, 1.0, 1.0, 0.95, 0.9, 1.2])
    tau = np.column_stack([np.full(300, 11.0), rng.normal(0, 3, (300, 5))])
    x0 = [0, 0, 2, 0, 0, -3.1, 1.5, 0, 0, 0, 0, 0]  # ψ_ref − ψ crosses π: the error wraps
    want, commands = _stepped(form, pilot, eta_pos, eta_neg, x0, tau[:-1], 0.05, 5, 0.5)
    assert np.ptp(want[:, 5]) > 0.05  # it turns, through the wrap
    got, record = compiled.fly_pd(
        form,
        np.array([x0], float),
        tau,
        np.zeros(1, int),
        299,
        0.05,
        pilot.pilot(eta_pos, eta_neg),
        0.5,
        5,
        record=True,
    )
    assert np.array_equal(got[0], want) and np.array_equal(record[0], commands)
    # many windows, from states along the flight
    starts = np.arange(0, 280, 2)
    windows, _ = compiled.fly_pd(
        form, want[starts], tau, starts, 20, 0.05, pilot.pilot(eta_pos, eta_neg), 0.5, 8
    )
    for b in (0, 57, starts.size - 1):
        s = starts[b]
        ref, _ = _stepped(form, pilot, eta_pos, eta_neg, want[s], tau[s : s + 20], 0.05, 8, 0.5)
        assert np.array_equal(windows[b], ref)


def test_compiled_pd_flight_stops_where_the_flight_diverges():
    """Without feedback the bare VT 690 hull diverges: the compiled flight keeps the first
    non-finite state as the Python loop computes it, and every later state is NaN."""
    form = FossenModel.from_vehicle(load_vehicle("vt690")).feature_form()
    pilot = Autopilot()
    ones = np.ones(6)
    tau = np.tile([11.0, 0, 0, 0, 0, 0], (2000, 1))
    x0 = [0, 0, 2, 0, 0, 0, 1.5, 0, 0, 0, 0.01, 0]
    want, commands = _stepped(form, pilot, ones, ones, x0, tau, 0.05, 1)
    stop = len(want) - 1
    assert stop < 2000 and not np.isfinite(want[-1]).all()
    got, record = compiled.fly_pd(
        form, np.array([x0], float), tau, np.zeros(1, int), 2000, 0.05,
        pilot.pilot(ones, ones), record=True,
    )  # fmt: skip
    assert np.array_equal(got[0, : stop + 1], want, equal_nan=True)
    assert np.isnan(got[0, stop + 1 :]).all()
    assert np.array_equal(record[0, :stop], commands[:stop])


def test_the_compiled_kernels_get_one_array_type_for_read_only_inputs(monkeypatch):
    """A read-only array (pandas' view of a log column) reaches the kernels as the writable
    type the other call sites pass, the same values: numba would compile a second variant
    of each kernel for it (seconds per process on a cold cache)."""
    import numba

    form = FossenModel.from_vehicle(load_vehicle("vt690")).feature_form()
    seen = {}

    def record(name):
        def kernel(*args):
            seen[name] = args

        return kernel

    for name in ("_fly_batch", "_integrate", "_rhs"):
        monkeypatch.setattr(compiled, name, record(name))
    tau = np.arange(24.0).reshape(4, 6)
    tau.flags.writeable = False
    x0 = np.zeros(12)
    x0.flags.writeable = False
    compiled.fly_pd(form, x0, tau, np.zeros(1, int), 3, 0.05, np.ones((5, 6)))
    compiled.integrate_rk4(form, x0, tau, 0.05)
    compiled.rhs(form, x0, tau[0])
    writable = numba.typeof(np.zeros((4, 6)))
    assert numba.typeof(seen["_fly_batch"][1]) == writable
    assert numba.typeof(seen["_integrate"][1]) == writable
    assert numba.typeof(seen["_integrate"][0]) == numba.typeof(np.zeros(12))
    assert numba.typeof(seen["_rhs"][0]) == numba.typeof(np.zeros(12))
    assert np.array_equal(seen["_fly_batch"][1], tau) and np.array_equal(seen["_rhs"][1], tau[0])


def test_physics_prediction_under_an_autopilot_is_the_stepped_one():
    """predict_closed_loop (one compiled flight per experiment, or per window for k steps)
    predicts what fly_closed_loop predicts stepping the compiled RK4 once per sample."""
    vehicle = load_vehicle(str(resources.files("nnid.demo_data").joinpath("minirov.toml")))
    log = effect_log(vehicle, duration=30.0, n_experiments=2, seed=3)
    parts = Parts.from_vehicle(vehicle)
    parts.eta_pos[2], parts.eta_neg[5] = 0.8, 1.2
    form = parts.model(check=False).feature_form()
    replay = Replay(Autopilot(kp=[0, 0, 20, 0, 0, 0.5], kd=[20, 20, 20, 0.1, 0.1, 0.2]),
                    log[list(TAU)])  # fmt: skip

    def stepper(_: int, dt: float):
        def step(state, command):
            return compiled.integrate_rk4(form, state, parts.applied(command)[:, None], dt, 2)[
                :, -1
            ]

        return step

    for mode in ("free_run", 1, 4):
        got = predict_closed_loop(parts, log, replay, mode, substeps=2)
        pd.testing.assert_frame_equal(got, fly_closed_loop(log, replay, stepper, mode))
        assert not np.allclose(got["z"], log["z"])  # it predicts, not copies


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


def test_restoring_matrix_is_fossens_and_the_same_at_every_call():
    # g(η) = G (sin θ, cos θ sin φ, cos θ cos φ) (Fossen 2011 eq. 4.6 for the Seamor's W, B,
    # r_g, r_b) to the bit, its zeros (W = B, CG and CB on one vertical) exactly zero, and the
    # same at every call: fitted to attitudes, it had last bits that moved with the memory
    # MKL's buffers lay in (lstsq), and with the processor's kernels (normal equations:
    # M = 1.5e-16 N m level here, -3.0e-16 on AVX2)
    model = FossenModel.from_vehicle(load_vehicle("seamor"))
    w, b = float(model.weight), float(model.buoyancy)
    (xg, yg, zg), (xb, yb, zb) = model.r_g.tolist(), model.r_b.tolist()
    expected = np.array(
        [
            [w - b, 0.0, 0.0],
            [0.0, -(w - b), 0.0],
            [0.0, 0.0, -(w - b)],
            [0.0, zg * w - zb * b, -(yg * w - yb * b)],
            [zg * w - zb * b, 0.0, xg * w - xb * b],
            [-(yg * w - yb * b), -(xg * w - xb * b), 0.0],
        ]
    )
    first = model.form().g_mat.numpy()
    np.testing.assert_array_equal(first, expected)
    keep = []
    for i in range(200):  # other allocations between the calls move the buffers
        keep.append(torch.empty(int(np.random.default_rng(i).integers(1, 3000))))
        assert np.array_equal(model.form().g_mat.numpy(), first), i


def test_a_level_run_driven_in_the_plane_stays_in_the_plane_exactly():
    """Surge, sway and yaw forces on a neutrally buoyant vehicle with its CB above its CG drive
    nothing out of the horizontal plane: w p q φ θ z stay exactly 0. A fitted restoring
    matrix's last bits pitched it (q of 1e-19 after one step at rest, w p q of 1e-16 in a
    run) by amounts that differed between processors, and a SINDy fit's selection, which
    weighs those DOFs' regressions, changed with them."""
    from nnid.datasets.simulator import simulate

    rng = np.random.default_rng(0)
    inputs = np.zeros((60, 6))
    inputs[10:, [0, 1, 5]] = np.repeat(rng.uniform(-30, 30, (5, 3)), 10, 0) * [1, 1, 0.2]
    log = simulate(load_vehicle("seamor"), inputs, 0.1)
    assert (log[["u", "v", "r"]].abs().max() > 0.05).all()  # it moved in the plane
    off_plane = ["z", "phi", "theta", "w", "p", "q", "dw", "dp", "dq"]
    assert (log[off_plane] == 0.0).all().all(), log[off_plane].abs().max()


def test_a_simulation_through_ninety_degrees_of_pitch_is_refused(vehicle_factory):
    """Euler angles are singular at θ = ±90° (Weiss eq. 17): a run started there came back
    with φ = ψ = −3.4e12 rad after one step and no error."""
    from nnid.datasets.simulator import simulate
    from nnid.errors import NnidInputError

    veh = vehicle_factory()
    x0 = np.zeros(12)
    x0[4], x0[11] = np.pi / 2, 0.1
    with pytest.raises(NnidInputError, match=r"pitched to 90.0° at t = 0.00 s.*singular"):
        simulate(veh, np.zeros((20, 6)), 0.05, x0=x0)
    x0[4] = np.radians(60)  # steep, not singular: simulated
    assert np.isfinite(simulate(veh, np.zeros((20, 6)), 0.05, x0=x0)["psi"]).all()
