"""Held (zero-order-hold) inputs fitted without zoh_midpoint: the fits say so (a half-sample
delay of the force read as inertia), and only where it biases the added mass."""

import warnings

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.log import ACCELERATION, TAU
from nnid.datasets.measurement import Measurement
from nnid.datasets.preprocess import (
    PreprocessConfig,
    derive_accelerations,
    held_inputs,
    preprocess,
    savgol_derivative,
)
from nnid.datasets.simulator import simulate
from nnid.models.parametric import ParametricModel
from nnid.models.synthesis import SynthesisModel, residual_force
from nnid.trainers.least_squares import ExcitationWarning, LeastSquares
from nnid.vehicle import load_vehicle

# velocities logged without noise; the accelerations are derived (Savitzky-Golay)
EXACT_DVL = Measurement(
    kind="dvl_imu", velocity_noise=0, gyro_noise=0, depth_noise=0, attitude_noise=0
)


@pytest.fixture(scope="module")
def seamor():
    return load_vehicle("seamor")


def _yaw_log(vehicle, dt: float, held: bool):
    """60 s of yaw moment: random levels held 0.5-2 s, or a smooth two-sine signal."""
    rng = np.random.default_rng(0)
    t = np.arange(round(60.0 / dt) + 1) * dt
    u = np.zeros((t.size, 6))
    if held:
        k = 0
        while k < t.size:
            n = round(rng.uniform(0.5, 2.0) / dt)
            u[k : k + n, 5] = rng.uniform(-1.5, 1.5)
            k += n
    else:
        u[:, 5] = 0.9 * np.sin(2 * np.pi * 0.13 * t) + 0.6 * np.sin(2 * np.pi * 0.41 * t + 1)
    return simulate(vehicle, u, dt, experiment="run0", measurement=EXACT_DVL)


def _fossen(vehicle, zoh: bool):
    return ParametricModel(
        vehicle,
        ["N_rdot", "N:r*abs(r)"],
        ["r"],
        trainer=LeastSquares(filter_lambda=1.0),
        zoh_midpoint=zoh,
    )


def _quiet(model, log):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return model.fit(log)


def test_held_steps_at_20hz_warn_and_zoh_midpoint_removes_the_bias(seamor):
    log = _yaw_log(seamor, 0.05, held=True)
    assert held_inputs(log) == ["tau_N"]
    with pytest.warns(ExcitationWarning, match="the Fossen fit.*zoh_midpoint = true"):
        biased = _fossen(seamor, zoh=False).fit(log)
    fixed = _quiet(_fossen(seamor, zoh=True), log)
    truth = seamor.added_mass["N_rdot"]
    assert abs(biased.params["N_rdot"]["value"] - truth) > 0.1 * abs(truth)  # as it says
    assert abs(fixed.params["N_rdot"]["value"] - truth) < 0.03 * abs(truth)


def test_held_steps_warn_the_synthesis_fit(seamor):
    log = _yaw_log(seamor, 0.05, held=True)
    with pytest.warns(ExcitationWarning, match="the synthesis fit"):
        SynthesisModel(seamor, {"N": ["r*abs(r)"]}, filter_lambda=1.0).fit(log)
    _quiet(SynthesisModel(seamor, {"N": ["r*abs(r)"]}, filter_lambda=1.0, zoh_midpoint=True), log)


def test_no_warning_for_smooth_inputs_fast_sampling_or_logged_accelerations(seamor):
    smooth = _yaw_log(seamor, 0.05, held=False)
    assert held_inputs(smooth) == []
    _quiet(_fossen(seamor, zoh=False), smooth)
    # 100 Hz: the half-sample delay is a few % of N_rdot (measured -3 %), not warned of
    _quiet(_fossen(seamor, zoh=False), _yaw_log(seamor, 0.01, held=True))
    # exact accelerations logged at the sample see that sample's force: nothing to correct
    exact = simulate(
        seamor,
        _yaw_log(seamor, 0.05, held=True)[list(TAU)].to_numpy(),
        0.05,
        experiment="run0",
    )
    _quiet(ParametricModel(seamor, ["N_rdot", "N:r*abs(r)"], ["r"]), exact)


def test_a_smooth_input_resting_at_zero_between_bursts_is_not_held():
    """A sine that is off (zero) over most of the run repeats its zeros, which read as held
    steps; pairs of samples both at zero are no evidence of a hold, its burst is smooth."""
    t = np.arange(0.0, 60.0, 0.05)
    burst = np.where((t % 20.0) < 6.0, np.sin(2 * np.pi * 0.5 * t), 0.0)
    steps = np.where((t % 20.0) < 6.0, 1.0 + np.floor(t) % 3, 0.0)  # levels held 1 s
    log = pd.DataFrame({"t": t, "u": 0.0, "tau_N": burst, "tau_X": steps})
    assert held_inputs(log) == ["tau_X"]


# --- Savitzky-Golay accelerations on held inputs ----------------------------------------------


@pytest.fixture(scope="module")
def held_20hz(seamor):
    return _yaw_log(seamor, 0.05, held=True)


def test_a_derivative_cut_at_steps_is_exact_between_them_and_their_mean_at_one():
    """A velocity under held forces: continuous, its slope jumping at samples 30 and 45."""
    dt = 0.05
    t = np.arange(80) * dt
    slope = np.select([t < 30 * dt, t < 45 * dt], [1.0, -2.0], 0.5)
    y = np.concatenate([[0.0], np.cumsum(slope[:-1] * dt)])  # piecewise linear, from 0
    d = savgol_derivative(y, dt, 21, 4, steps=np.array([30, 45]))
    want = slope.copy()
    want[30], want[45] = 0.5 * (1.0 - 2.0), 0.5 * (-2.0 + 0.5)
    np.testing.assert_allclose(d, want, atol=1e-9)
    # without the steps the window smears each jump over 10 samples either side
    assert np.abs(savgol_derivative(y, dt, 21, 4) - slope)[19:56].max() > 0.5
    # a gap: each stretch between gaps on its own, the steps within it still cut
    y[5] = np.nan
    d = savgol_derivative(y, dt, 21, 4, steps=np.array([30, 45]))
    assert np.isnan(d[:6]).all()
    np.testing.assert_allclose(d[6:], want[6:], atol=1e-9)


def test_zoh_midpoint_does_not_smooth_the_acceleration_across_held_steps(seamor, held_20hz):
    """Least squares on Savitzky-Golay accelerations: smoothed across the steps, N_rdot was
    11 % off at 20 Hz even with zoh_midpoint (8-12 % at 10-100 Hz); cut at them, 2.4 %."""
    model = ParametricModel(seamor, ["N_rdot", "N:r*abs(r)"], ["r"], zoh_midpoint=True)
    fitted = _quiet(model, held_20hz)
    truth = seamor.added_mass["N_rdot"]
    assert abs(fitted.params["N_rdot"]["value"] - truth) < 0.03 * abs(truth)
    said = [s.detail for s in fitted.report_.steps if s.step == "derive accelerations"]
    assert said and "not across the" in said[0] and "held inputs tau_N" in said[0]


def test_accelerations_derived_before_the_fit_on_held_inputs_warn(seamor, held_20hz):
    """preprocess(accelerations=True) hands a fit its accelerations as if logged, where the
    fit's held-input warning cannot fire: preprocess says it."""
    log = held_20hz.drop(columns=list(ACCELERATION), errors="ignore")
    with pytest.warns(ExcitationWarning, match="across the steps of the inputs tau_N"):
        out, _ = preprocess(log, PreprocessConfig(accelerations=True))
    assert all(c in out for c in ACCELERATION)
    smooth = _yaw_log(seamor, 0.05, held=False).drop(columns=list(ACCELERATION), errors="ignore")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        preprocess(smooth, PreprocessConfig(accelerations=True))


def test_accelerations_derived_behind_an_actuator_lag_are_not_warned_of(seamor):
    """Behind a 0.3-s actuator lag the yaw moment felt is continuous: the Savitzky-Golay
    accelerations have no jump to smear, and N_rdot fitted on them is 4 % off (25 % without
    the lag). preprocess warned of a smear there all the same, and pointed to zoh_midpoint,
    which a fit ignores behind a lag; given the vehicle's lag, it says nothing."""
    lagged = seamor.model_copy(update={"actuator_lag": 0.3})
    log = _yaw_log(lagged, 0.05, held=True)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, _ = preprocess(log, PreprocessConfig(accelerations=True), actuator_lag=0.3)
        model = ParametricModel(lagged, ["N_rdot", "N:r*abs(r)"], ["r"]).fit(out)
    truth = seamor.added_mass["N_rdot"]
    assert model.params["N_rdot"]["value"] == pytest.approx(truth, rel=0.06)


def test_the_residual_force_cuts_at_the_steps_as_logged(seamor, held_20hz):
    """McCarter's τ̄ with zoh_midpoint: the steps are found on the inputs as logged, before
    their midpoint (which repeats no sample, so would leave no input looking held)."""
    _, data = residual_force(seamor, held_20hz, zoh_midpoint=True)
    cut = derive_accelerations(held_20hz, 1.0, 4, cut_at_steps=True)
    np.testing.assert_array_equal(data["nu_dot"][:, 5], cut["dr"].to_numpy())


def test_the_noise_gain_of_a_derivative_cut_at_steps_is_that_of_its_pieces():
    """Cut at held steps, a sample's derivative comes from its piece's window (a slope for a
    piece of two samples) or, at a step, the mean of two one-sided ones: the variance per unit
    white noise is each row's Σ c², here read off the derivative of every unit impulse. The
    attenuation check took the full window's gain for every sample, under 1/50 of the mean.
    The run's own two ends keep their window's centre gain, as a run without steps does."""
    from nnid.datasets.preprocess import savgol_derivative_gain2, savgol_noise_gain

    n, dt, window = 50, 0.05, 21
    steps = np.array([3, 13, 18, 24, 27, 28, 32, 34, 45])
    rows = [savgol_derivative(np.eye(n)[j], dt, window, 4, steps=steps) for j in range(n)]
    exact = np.sum(np.stack(rows, axis=1) ** 2, axis=1)
    gain2 = savgol_derivative_gain2(n, dt, window, 4, 1, steps)
    ends = [0, n - 2, n - 1]  # the half windows of the 3- and 5-sample end pieces
    inner = np.setdiff1d(np.arange(n), ends)
    np.testing.assert_allclose(gain2[inner], exact[inner], rtol=1e-9)
    full = savgol_noise_gain(window, 4, dt) ** 2
    assert np.mean(gain2) > 50 * full
    np.testing.assert_allclose(savgol_derivative_gain2(n, dt, window, 4), full)


def test_an_acceleration_cut_at_frequent_steps_is_judged_with_its_pieces_noise(seamor):
    """Surge commands held 0.3-0.7 s at 10 Hz, 5-mm/s DVL noise, zoh_midpoint: the
    acceleration is cut at every step, and 30 % of its variance is noise (measured against
    the noise-free log). The check took the 21-sample window's gain and put that share at
    1 %: X_udot came out -13.2 for -27.1, 20 standard errors off, without a word. With the
    pieces' gains the share is 0.43 and X_udot is named."""
    rng = np.random.default_rng(0)
    levels: list[float] = []
    while len(levels) < 1201:
        levels += [10.0 + 10.0 * rng.uniform(-1, 1)] * int(rng.integers(3, 8))
    inputs = np.zeros((1201, 6))
    inputs[:, 0] = levels[:1201]
    log = simulate(
        seamor, inputs, 0.1, measurement=Measurement(kind="dvl_imu"), seed=0, experiment="s"
    )
    model = ParametricModel(seamor, ["X_udot", "X:u*abs(u)"], dofs=["u"], zoh_midpoint=True)
    with pytest.warns(ExcitationWarning, match=r"errors in variables.*X_udot = -13\.2 is about"):
        model.fit(log)
    truth, fitted = seamor.added_mass["X_udot"], model.params["X_udot"]
    assert fitted["value"] - truth > 10 * fitted["stderr"]
    rho, _ = model.attenuated_["X_udot"]
    assert 0.3 < rho < 0.6


def test_a_widened_window_is_warned_of_once_in_a_fit_cut_at_steps(seamor, held_20hz):
    """savgol_window = 0.1 s is 2 samples at 20 Hz, widened to 7: the attenuation check's
    gain of the pieces (acceleration_gain2) warned of it a second time, word for word."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ParametricModel(
            seamor, ["N_rdot", "N:r*abs(r)"], ["r"], zoh_midpoint=True, savgol_window=0.1
        ).fit(held_20hz)
    widened = [w for w in caught if "too few for a Savitzky-Golay" in str(w.message)]
    assert len(widened) == 1, [str(w.message) for w in widened]
