"""Held (zero-order-hold) inputs fitted without zoh_midpoint: the fits say so (a half-sample
delay of the force read as inertia), and only where it biases the added mass."""

import warnings

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.log import TAU
from nnid.datasets.measurement import Measurement
from nnid.datasets.preprocess import held_inputs
from nnid.datasets.simulator import simulate
from nnid.models.parametric import ParametricModel
from nnid.models.synthesis import SynthesisModel
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
