"""Injected effects: each name changes the plant as its physics says, and the log keeps the
nominal inputs so the effect stays undeclared."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.simulator import simulate
from nnid.physics.effects import EFFECT_PATTERNS, apply_effect, parse_effect

QUAD = {"coefficients": {"X:u*abs(u)": -40.0, "Y:v*abs(v)": -60.0, "Z:w*abs(w)": -80.0,
                         "K:p*abs(p)": -2.0, "M:q*abs(q)": -3.0, "N:r*abs(r)": -2.5}}  # fmt: skip


def _steady(veh, tau, effects=(), seconds=60.0):
    inputs = np.tile(np.asarray(tau, float), (int(seconds / 0.01), 1))
    return simulate(veh, inputs, 0.01, effects=effects)


def test_every_vocabulary_name_parses():
    names = ["linear_damping.u", "quadratic_damping.r", "coupled_damping.N:v*abs(r)",
             "thruster_installation.w.neg", "buoyancy_offset", "restoring_offset.M", "current.y",
             "external_bias.q", "actuator_lag", "thruster_deadband", "added_mass.v"]  # fmt: skip
    assert {parse_effect(n)[0] for n in names} == set(EFFECT_PATTERNS)
    for bad in ("linear_damping.x", "coupled_damping.Q:u", "coupled_damping.X:u*z", "gremlins"):
        with pytest.raises(ValueError):
            parse_effect(bad)


def test_installation_loss_on_one_direction(vehicle_factory):
    """Caccia eq. 3: upward heave thrust at η = 0.56 gives a steady speed sqrt(0.56) of nominal
    (quadratic drag); downward is untouched. The log holds the nominal force."""
    veh = vehicle_factory(damping=QUAD)
    eff = [("thruster_installation.w.neg", 0.56)]
    up = _steady(veh, [0, 0, -20.0, 0, 0, 0], eff)
    down = _steady(veh, [0, 0, 20.0, 0, 0, 0], eff)
    nominal = np.sqrt(20.0 / 80.0)
    assert up["w"].iloc[-1] == pytest.approx(-nominal * np.sqrt(0.56), rel=1e-6)
    assert down["w"].iloc[-1] == pytest.approx(nominal, rel=1e-6)
    assert (up["tau_Z"] == -20.0).all()


def test_current_carries_the_vehicle(vehicle_factory):
    """With no thrust, the hydrodynamic forces act on ν − ν_c: the vehicle ends up drifting with
    the water, so the over-ground velocity equals the current. (A current along x only: an
    oblique one would also turn the vehicle through the Munk moment of C_A.)"""
    veh = vehicle_factory(damping={"coefficients": {"X:u": -20.0, "X:u*abs(u)": -40.0}})
    log = _steady(veh, [0.0] * 6, [("current.x", 0.3)], seconds=30)
    assert log["u"].iloc[-1] == pytest.approx(0.3, abs=1e-6)
    thrust = _steady(veh, [10.0, 0, 0, 0, 0, 0], [("current.x", 0.3)], seconds=30)
    # with thrust the water-relative speed is the no-current steady speed
    u_r = (-20 + np.sqrt(20**2 + 4 * 40 * 10)) / (2 * 40)
    assert thrust["u"].iloc[-1] == pytest.approx(0.3 + u_r, abs=1e-6)


def test_external_bias_and_linear_damping(vehicle_factory):
    veh = vehicle_factory()
    log = _steady(veh, [0.0] * 6, [("linear_damping.u", -10.0), ("external_bias.u", 5.0)])
    assert log["u"].iloc[-1] == pytest.approx(0.5, rel=1e-6)


def test_buoyancy_offset_sinks(vehicle_factory):
    """W − B = 8 N with quadratic heave drag: w_ss = sqrt(8 / 80) (down is +z in NED)."""
    log = _steady(vehicle_factory(damping=QUAD), [0.0] * 6, [("buoyancy_offset", 8.0)])
    assert log["w"].iloc[-1] == pytest.approx(np.sqrt(0.1), rel=1e-5)


def test_actuator_lag_delays_the_response(vehicle_factory):
    veh = vehicle_factory(damping=QUAD)
    fast = _steady(veh, [30.0, 0, 0, 0, 0, 0], seconds=5)
    slow = _steady(veh, [30.0, 0, 0, 0, 0, 0], [("actuator_lag", 0.5)], seconds=5)
    i = 30  # 0.3 s after the step
    assert slow["u"].iloc[i] < 0.6 * fast["u"].iloc[i]
    assert slow["u"].iloc[-1] == pytest.approx(fast["u"].iloc[-1], rel=1e-3)


def test_deadband_swallows_small_commands(vehicle_factory):
    veh = vehicle_factory(damping=QUAD)
    small = _steady(veh, [2.0, 0, 0, 0, 0, 0], [("thruster_deadband", 3.0)], seconds=5)
    big = _steady(veh, [5.0, 0, 0, 0, 0, 0], [("thruster_deadband", 3.0)], seconds=30)
    assert np.abs(small["u"]).max() == 0.0
    assert big["u"].iloc[-1] == pytest.approx(np.sqrt(5.0 / 40.0), rel=1e-4)


def test_field_level_changes(vehicle_factory):
    veh = vehicle_factory(damping=QUAD)
    assert apply_effect(veh, "restoring_offset.M", 0.02).r_g[2] == pytest.approx(0.02)
    assert apply_effect(veh, "added_mass.v", -5.0).added_mass["Y_vdot"] == pytest.approx(-30.0)
    coupled = apply_effect(veh, "coupled_damping.N:abs(r)*v", -1.5).damping.coefficients
    assert coupled["N:v*abs(r)"] == -1.5
    quad = apply_effect(veh, "quadratic_damping.u", -10.0).damping.coefficients
    assert quad["X:u*abs(u)"] == -50.0
    assert veh.damping.coefficients["X:u*abs(u)"] == -40.0  # the original is not touched


@pytest.mark.parametrize(("lag", "tol"), [(0.03, 1e-3), (0.05, 3e-4), (0.5, 3e-6)])
def test_a_lag_shorter_than_the_sample_is_stepped_exactly(vehicle_factory, lag, tol):
    """T ȧ + a = τ with τ held is stepped by its exact exponential, not as an RK4 state: at
    10 Hz a 0.03-s lag (h/T = 3.3) grew by 2.2 a step and diverged, and a 0.05-s lag was
    1.1e-2 m/s off the adaptive DOP853 integration (now 1.6e-4: what is left is RK4's
    quadrature of the force's fast rise within one step)."""
    veh = vehicle_factory(damping={"coefficients": {"X:u": -20.0, "X:u*abs(u)": -40.0}})
    inputs = np.tile([30.0, 0, 0, 0, 0, 0], (50, 1))
    inputs[25:, 0] = -10.0
    stepped = simulate(veh, inputs, 0.1, effects=[("actuator_lag", lag)])
    exact = simulate(veh, inputs, 0.1, effects=[("actuator_lag", lag)], integrator="adaptive")
    assert np.abs(stepped["u"] - exact["u"]).max() < tol  # u reaches 0.64 m/s
    torch_path = simulate(veh, inputs, 0.1, effects=[("actuator_lag", lag)], integrator="torch")
    # the same exact step in torch (differentiable): as an RK4 state the 0.03-s lag diverged
    assert np.abs(torch_path["u"] - stepped["u"]).max() < 1e-10


@pytest.mark.parametrize(("dt", "lag"), [(0.1, 0.1), (0.05, 0.3), (0.2, 0.1)])
def test_a_lagged_vehicle_is_predicted_as_the_simulator_flies_it(vehicle_factory, dt, lag):
    """A vehicle file's actuator lag is integrated in every prediction, from the force
    commanded, exactly: the loop's simulation held the lag's sampled values, which delays the
    force by half a sample (free-run NRMSE 0.07-0.30 of the true vehicle on noise-free data),
    and a fitted Fossen model left the lag out (0.28-0.60)."""
    from nnid.evaluation.prediction import MAX_STEP
    from nnid.loop.diagnose import predict
    from nnid.models.parametric import ParametricModel
    from nnid.physics.effects import apply_effect

    veh = vehicle_factory(damping={"coefficients": {"X:u": -20.0, "Y:v": -30.0, "N:r": -5.0}})
    rng = np.random.default_rng(3)
    inputs = np.zeros((400, 6))
    # held levels from rest (the simulator's force starts at zero, as a log's filter does on
    # a first command of zero)
    levels = rng.uniform(-30, 30, size=(20, 3))
    inputs[20:, [0, 1, 5]] = np.repeat(levels, 20, 0)[:380] * [1, 1, 0.2]
    truth = apply_effect(veh, "actuator_lag", lag)
    log = simulate(truth, inputs, dt)
    # a fitted model steps at most MAX_STEP (the loop's simulation, one step a sample)
    fine = simulate(truth, inputs, dt, substeps=int(np.ceil(dt / MAX_STEP - 1e-9)))
    fitted = ParametricModel(truth, unknowns=()).fit(fine)
    for pred, flown in (
        (predict(truth, log, "free_run"), log),
        (predict(truth, log, 5), log),
        (fitted.predict(fine, "free_run"), fine),
        (fitted.predict(fine, 5), fine),
    ):
        for dof in "uvr":
            err = (pred[dof] - flown[dof]).abs().max()
            assert err < 1e-6 * flown[dof].abs().max(), (dof, err)


def test_a_vehicle_files_deadband_is_in_a_fitted_models_forces(vehicle_factory):
    """Commands inside the vehicle file's deadband give no force in a fitted model's
    prediction, as in the simulator (log_arrays left the deadband out)."""
    from nnid.models.parametric import ParametricModel

    veh = vehicle_factory(damping={"coefficients": {"X:u": -20.0, "N:r": -5.0}})
    inputs = np.zeros((300, 6))
    inputs[10:, 0] = np.repeat([4.0, -4.0, 20.0, 3.0, -25.0, 0.0], 50)[:290]  # 5-N deadband
    inputs[10:, 5] = np.repeat([2.0, -6.0, 8.0, -3.0, 0.0, 4.0], 50)[:290]
    truth = apply_effect(veh, "thruster_deadband", 5.0)
    log = simulate(truth, inputs, 0.05)
    pred = ParametricModel(truth, unknowns=()).fit(log).predict(log, "free_run")
    for dof in "ur":
        assert (pred[dof] - log[dof]).abs().max() < 1e-6 * log[dof].abs().max()


def test_a_closed_loop_flight_has_the_deadband_and_the_lag(vehicle_factory):
    """Under a zero-gain autopilot the commands are the log's, so the closed-loop prediction
    is the open-loop one: with a deadband it was not (2.2 std apart: the open loop applied the
    deadband, the compiled autopilot loop did not); a lagged vehicle, once refused, flies its
    lag from the force felt at each window's start as the open loop does."""
    from nnid.datasets.log import TAU
    from nnid.datasets.simulator import Autopilot
    from nnid.evaluation.prediction import Replay
    from nnid.models.parametric import ParametricModel

    veh = vehicle_factory(damping={"coefficients": {"X:u": -20.0, "N:r": -5.0}})
    inputs = np.zeros((300, 6))
    inputs[10:, 0] = np.repeat([4.0, -4.0, 20.0, 3.0, -25.0, 0.0], 50)[:290]
    inputs[10:, 5] = np.repeat([2.0, -6.0, 8.0, -3.0, 0.0, 4.0], 50)[:290]
    truth = apply_effect(veh, "thruster_deadband", 5.0)
    log = simulate(truth, inputs, 0.05)
    model = ParametricModel(truth, unknowns=()).fit(log)
    replay = Replay(Autopilot(), log[list(TAU)])
    for mode in ("free_run", 3):
        a, b = model.predict(log, mode), model.closed_loop(log, replay, mode)
        assert ((a - b)[["u", "r"]].abs().max() < 1e-9).all(), mode
    lagged = ParametricModel(apply_effect(veh, "actuator_lag", 0.2), unknowns=()).fit(log)
    for mode in ("free_run", 3):
        a, b = lagged.predict(log, mode), lagged.closed_loop(log, replay, mode)
        assert ((a - b)[["u", "r"]].abs().max() < 1e-9).all(), mode
        assert ((a - model.predict(log, mode))[["u", "r"]].abs().max() > 1e-3).any()  # felt


@pytest.mark.parametrize(("dt", "lag"), [(0.05, 0.3), (0.1, 0.03)])
def test_the_true_model_flies_a_lagged_vehicles_autopilot_log(vehicle_factory, dt, lag):
    """A lagged vehicle flown under an autopilot (noise-free, the simulator's integrator and
    sub-steps): the true model's closed-loop prediction is the log, free run and k steps, each
    window's lag started from the log's commands (refused before; a lag 3.3 times shorter
    than the 0.1-s sample tests the exact step of the lag, which RK4 would not follow)."""
    from nnid.datasets.log import TAU
    from nnid.datasets.simulator import Autopilot
    from nnid.evaluation.prediction import MAX_STEP, Replay
    from nnid.models.parametric import ParametricModel

    veh = vehicle_factory(damping={"coefficients": {"X:u": -20.0, "Y:v": -30.0, "N:r": -5.0}})
    truth = apply_effect(apply_effect(veh, "actuator_lag", lag), "thruster_deadband", 2.0)
    rng = np.random.default_rng(5)
    n = round(30.0 / dt)
    inputs = np.zeros((n, 6))  # from rest, as the simulator's lag state starts
    inputs[10:, [0, 1, 5]] = np.repeat(rng.uniform(-30, 30, (n, 3)), 20, 0)[: n - 10] * [1, 1, 0.2]
    pilot = Autopilot(kp=[0, 0, 20, 0, 0, 2.0], kd=[5, 5, 20, 0.1, 0.1, 1.0])
    substeps = int(np.ceil(dt / MAX_STEP - 1e-9))
    log = simulate(truth, inputs, dt, substeps=substeps, autopilot=pilot)
    replay = Replay(pilot, pd.DataFrame(inputs, columns=list(TAU), index=log.index))
    model = ParametricModel(truth, unknowns=()).fit(log)
    for mode in ("free_run", 1, 7):
        pred = model.closed_loop(log, replay, mode)
        for dof in ("x", "y", "psi", "u", "v", "r"):
            err = float(np.nanmax(np.abs(pred[dof] - log[dof])))
            assert err < 1e-9 * log[dof].abs().max(), (mode, dof, err)


def test_a_thruster_deadband_is_in_command_units_not_on_logged_forces():
    """A thruster vehicle's deadband is a command's (36 µs of PWM): a log that carries the
    forces themselves is past it, and 36 N of every force were zeroed."""
    from nnid.datasets.arrays import log_arrays
    from nnid.vehicle import load_vehicle

    veh = load_vehicle("configs/vehicles/octorov_sim.toml").model_copy(update={"deadband": 36.0})
    assert veh.thrusters
    forces = np.linspace(-50, 50, 60)[:, None] * np.ones((1, 6))
    log = pd.DataFrame(forces, columns=[f"tau_{f}" for f in "XYZKMN"])
    log.insert(0, "t", np.arange(60) * 0.1)
    for col in ("x", "y", "z", "phi", "theta", "psi", "u", "v", "w", "p", "q", "r"):
        log[col] = 0.0
    assert np.array_equal(log_arrays(log, veh)["tau"], forces)


def test_a_lagged_force_is_regressed_as_sampled_not_at_the_midpoint(vehicle_factory):
    """zoh_midpoint averages held inputs at a sample; a lagged force is continuous, and its
    midpoint (as the loop already knew) gave X_udot -3.7 for -6.4 on noise-free data."""
    from nnid.models.parametric import ParametricModel

    veh = vehicle_factory(damping={"coefficients": {"X:u": -20.0, "X:u*abs(u)": -40.0}})
    truth = apply_effect(veh, "actuator_lag", 0.3)
    rng = np.random.default_rng(4)
    inputs = np.zeros((600, 6))
    inputs[:, 0] = np.repeat(rng.uniform(-40, 40, 60), 10)
    log = simulate(truth, inputs, 0.1, substeps=8)
    model = ParametricModel(truth, ["X_udot"], dofs=["u"], zoh_midpoint=True).fit(log)
    assert model.params["X_udot"]["value"] == pytest.approx(veh.added_mass["X_udot"], rel=0.05)


def test_a_thruster_vehicles_closed_loop_leaves_logged_forces_past_its_deadband():
    """A thruster vehicle's deadband is of commands; its open-loop prediction leaves logged
    forces as they are, and its closed-loop flight put them through it (0.86 m/s in u and
    2.3 rad/s in r apart under a zero-gain autopilot)."""
    from nnid.datasets.log import TAU
    from nnid.datasets.simulator import Autopilot
    from nnid.evaluation.prediction import Replay
    from nnid.models.parametric import ParametricModel
    from nnid.vehicle import load_vehicle

    veh = load_vehicle("configs/vehicles/octorov_sim.toml").model_copy(update={"deadband": 36.0})
    plain = veh.model_copy(update={"thrusters": [], "deadband": 0.0})
    inputs = np.zeros((300, 6))
    inputs[10:, 0] = np.repeat([4.0, -4.0, 20.0, 3.0, -25.0, 0.0], 50)[:290]
    inputs[10:, 5] = np.repeat([2.0, -6.0, 8.0, -3.0, 0.0, 4.0], 50)[:290]
    log = simulate(plain, inputs, 0.05)
    model = ParametricModel(veh, unknowns=()).fit(log)
    a = model.predict(log, "free_run")
    b = model.closed_loop(log, Replay(Autopilot(), log[list(TAU)]), "free_run")
    assert ((a - b)[["u", "r"]].abs().max() < 1e-9).all()
