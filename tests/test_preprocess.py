"""Preprocessing against analytic trajectories and filter theory."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.excitation import Multisine
from nnid.datasets.log import (
    POSE,
    VELOCITY,
    clock_step,
    declare_time_unit,
    log_step,
    typical_step,
)
from nnid.datasets.measurement import Measurement
from nnid.datasets.preprocess import (
    UNIFORM_TOLERANCE,
    PreprocessConfig,
    acceleration_gain2,
    check_uniform,
    derive_accelerations,
    derive_velocities,
    detect_jumps,
    estimate_accelerometer_bias,
    estimate_gyro_bias,
    first_order_lag,
    held_at,
    lowpass,
    off_steps,
    preprocess,
    repair_jumps,
    resample_log,
    savgol_derivative,
    savgol_noise_gain,
    savgol_window,
    uneven_runs,
    unwrap_angles,
    zoh_midpoint,
)
from nnid.datasets.simulator import simulate
from nnid.errors import NnidInputError
from nnid.vehicle import load_vehicle


@pytest.mark.parametrize(
    "rate, window, sigma, period",
    [(3.3, 21, 0.01, 26.0), (100.0, 51, 0.001, 10.0)],  # Caccia IV-D: 21 points at 3.3 Hz
)
def test_savgol_velocity_error_matches_filter_theory(rate, window, sigma, period):
    """Error of the SG derivative of a noisy analytic pose = sqrt(bias² + (σ·sqrt(Σcₖ²))²):
    the bias from the noise-free signal, the noise from the filter's coefficient energy."""
    rng = np.random.default_rng(0)
    t = np.arange(0, 2000, 1 / rate)
    w = 2 * np.pi / period
    x, dx = 0.8 * np.sin(w * t) + 0.01 * t, 0.8 * w * np.cos(w * t) + 0.01
    dt = 1 / rate
    clean = savgol_derivative(x, dt, window, 4)
    inner = slice(window, -window)
    bias = np.sqrt(np.mean((clean - dx)[inner] ** 2))
    noisy = savgol_derivative(x + rng.normal(0, sigma, t.size), dt, window, 4)
    err = np.sqrt(np.mean((noisy - dx)[inner] ** 2))
    predicted = np.sqrt(bias**2 + (sigma * savgol_noise_gain(window, 4, dt)) ** 2)
    assert err == pytest.approx(predicted, rel=0.05)
    assert err < 0.05 * 0.8 * w  # a few percent of the speed, as Caccia reports (< 3 %)


def _six_dof_log(measurement, seconds=60.0):
    t = np.arange(0, seconds, 0.01)
    amps = [30, 20, 20, 3, 0, 3]
    columns = []
    for k, a in enumerate(amps):
        sig = Multisine(
            channel="X",
            amplitude=max(a, 1),
            f_min=0.05 + 0.01 * k,
            f_max=0.5,
            n=5,
            duration=seconds,
        )(t)
        columns.append(sig if a else 0 * t)
    inputs = np.stack(columns, 1)
    return simulate(load_vehicle("seamor"), inputs, 0.01, measurement=measurement)


def test_body_velocities_from_noisy_mocap_pose():
    """ν = J⁻¹(η) η̇ from 100 Hz pose with 1 mm / 2 mrad noise: each DOF within the noise the
    SG filter predicts (rotations keep the norm, so the prediction carries over)."""
    sigma_p, sigma_a = 0.001, 0.002
    log = _six_dof_log(
        Measurement(kind="mocap", position_noise=sigma_p, angle_noise=sigma_a, truth=True)
    )
    report = CleaningReport()
    out = derive_velocities(log, 0.5, 4, report)
    gain = savgol_noise_gain(savgol_window(0.5, 100, 4), 4, 0.01)
    for c, sigma in zip("uvwpqr", [sigma_p] * 3 + [sigma_a] * 3, strict=True):
        err = (out[c] - out["true_" + c]).to_numpy()[60:-60]
        assert np.sqrt(np.mean(err**2)) < 1.3 * sigma * gain, c
    assert report.steps[-1].columns == list("uvwpqr")


def test_bias_estimation_recovers_injected_biases():
    """McCarter eqs 2.84-2.87: constant accelerometer and gyro biases within 5 %."""
    log = _six_dof_log(Measurement(kind="none"), seconds=120)
    t = log["t"].to_numpy()
    acc_bias, gyro_bias = np.array([0.05, -0.03, 0.02]), np.array([0.01, -0.02, 0.015])
    rng = np.random.default_rng(1)
    vel = log[["u", "v", "w"]].to_numpy() + rng.normal(0, 0.005, (t.size, 3))  # DVL noise
    acc = log[["du", "dv", "dw"]].to_numpy() + acc_bias + rng.normal(0, 0.02, (t.size, 3))
    gyro = log[["p", "q", "r"]].to_numpy() + gyro_bias + rng.normal(0, 0.002, (t.size, 3))
    att = log[["phi", "theta", "psi"]].to_numpy() + rng.normal(0, 0.002, (t.size, 3))
    assert np.allclose(estimate_accelerometer_bias(t, vel, acc), acc_bias, rtol=0.05)
    assert np.allclose(estimate_gyro_bias(t, att, gyro), gyro_bias, rtol=0.05)


def test_deriving_rates_from_the_attitude_does_not_need_torch(monkeypatch):
    """p, q, r = T_Θ⁻¹ Θ̇ and the gyro bias's T_Θ (McCarter eq. 2.14, 2.86) in numpy: reading and
    deriving a log imported torch for these 3x3 matrices alone."""
    import sys

    monkeypatch.setitem(sys.modules, "torch", None)  # `import torch` raises ImportError
    t = np.arange(0.0, 10.0, 0.01)
    log = pd.DataFrame({"t": t, "phi": 0.2 * np.sin(t), "theta": 0.1 * np.cos(0.5 * t),
                        "psi": 0.3 * t})  # fmt: skip
    out = derive_velocities(log, 0.5, 4)
    assert np.isfinite(out[["p", "q", "r"]].to_numpy()[30:-30]).all()
    gyro = out[["p", "q", "r"]].to_numpy()[30:-30] + 0.01
    bias = estimate_gyro_bias(t[30:-30], log[["phi", "theta", "psi"]].to_numpy()[30:-30], gyro)
    np.testing.assert_allclose(bias, 0.01, atol=1e-4)


def test_bias_estimation_refuses_a_gap_naming_it():
    """One empty angle cell spread through np.unwrap and the integrals: the gyro bias came out
    [nan, nan, nan] without a word. A gap in any argument is now refused, naming it."""
    log = _six_dof_log(Measurement(kind="none"), seconds=20)
    t = log["t"].to_numpy()
    att, gyro = (
        log[["phi", "theta", "psi"]].to_numpy(copy=True),
        log[["p", "q", "r"]].to_numpy(copy=True),
    )
    vel, acc = log[["u", "v", "w"]].to_numpy(copy=True), log[["du", "dv", "dw"]].to_numpy()
    assert np.isfinite(estimate_gyro_bias(t, att, gyro)).all()
    att[100, 2] = np.nan
    with pytest.raises(NnidInputError, match=r"angles: value empty .*a gap breaks") as err:
        estimate_gyro_bias(t, att, gyro)
    assert (err.value.field, err.value.row) == ("psi", 100)
    gyro[7, 0] = np.inf
    with pytest.raises(NnidInputError, match="gyro: value inf") as err:
        estimate_gyro_bias(t, np.nan_to_num(att), gyro)
    assert (err.value.field, err.value.row) == ("p", 7)
    vel[50, 1] = np.nan
    with pytest.raises(NnidInputError, match="velocity") as err:
        estimate_accelerometer_bias(t, vel, acc)
    assert (err.value.field, err.value.row) == ("v", 50)


def test_resample_splits_at_gaps_and_holds_inputs():
    t = np.r_[np.arange(0, 5, 0.013), np.arange(8, 12, 0.013)]
    log = pd.DataFrame({"t": t, "u": t * 2.0, "tau_X": np.floor(t)})
    report = CleaningReport()
    out = resample_log(log, 20.0, gap=1.0, report=report)
    # a log without an experiment column: its pieces were labelled 'None#0', 'None#1'
    assert list(dict.fromkeys(out["experiment"])) == ["run#0", "run#1"]
    assert (out["piece_of"] == "run").all()
    first = out[out["experiment"] == "run#0"]
    assert np.allclose(np.diff(first["t"]), 0.05)
    assert np.allclose(first["u"], first["t"] * 2.0)  # linear signals interpolate exactly
    assert set(np.unique(first["tau_X"])) <= set(range(6))  # inputs are held, never blended
    assert "split in 2" in report.steps[0].detail
    # the second piece keeps the run's clock: its t restarted at 0, hiding the 3-s hole
    assert out.loc[out["experiment"] == "run#1", "t"].iloc[0] == pytest.approx(8.0)


def test_resampling_without_gap_says_the_hole_it_interpolates_over():
    """Without gap, a 10-s hole in a 10-Hz log became 99 invented rows without a word; the
    readers said the same case. Said alike: a warning and the report, the longest hole named."""
    t = np.r_[np.arange(0, 10.05, 0.1), np.arange(20, 30.05, 0.1)]
    log = pd.DataFrame({"t": t, "experiment": "dive", "u": np.sin(t), "tau_X": 1.0})
    report = CleaningReport()
    with pytest.warns(UserWarning, match=r"dive.*no sample for 10 s \(t = 10-20 s\)"):
        out = resample_log(log, 10.0, report=report)
    assert len(out) == 301  # bridged, as before: gap is the user's to set
    assert any(s.step == "interpolated over a silence" for s in report.steps)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # split at the gap, or no hole: nothing to say
        resample_log(log, 10.0, gap=1.0)
        resample_log(log[log["t"] < 15], 10.0)


def test_resampling_keeps_a_label_column_by_its_previous_value():
    """Columns that are not numbers (a mode, a fault label) and flags were dropped from the
    resampled log without a word; they are held as an input is, never blended."""
    t = np.r_[np.arange(0, 5, 0.013), np.arange(8, 12, 0.013)]
    mode = np.where(t < 3.0, "manual", "stabilize")
    log = pd.DataFrame(
        {"t": t, "experiment": "dive", "u": t * 2.0, "tau_X": 1.0, "mode": mode, "fault": t > 9}
    )
    with pytest.warns(UserWarning, match="anti-alias"):  # 77 Hz to 20 Hz, said
        out = resample_log(log, 20.0, gap=1.0)
    assert {"mode", "fault"} <= set(out.columns)
    assert out["fault"].dtype == bool and out["mode"].isin(["manual", "stabilize"]).all()
    t_log = out["t"]  # each piece on the run's clock
    # the label in force at each grid time: the last logged sample's at or before it
    k = np.searchsorted(t, t_log.to_numpy() + 1e-9, "right") - 1
    assert (out["mode"].to_numpy() == mode[k]).all()
    assert (out["fault"].to_numpy() == (t > 9)[k]).all()
    assert list(dict.fromkeys(out["experiment"])) == ["dive#0", "dive#1"]


def test_resampling_holds_an_integer_coded_label_column():
    """An integer mode or fault code was interpolated: 0 next to 2 became 1.0, a code the log
    never held. Held by its previous value, its type kept; a measured column still blends."""
    t = np.arange(0.0, 4.0, 0.1)
    code = np.where(t < 2.0, 0, 2)
    log = pd.DataFrame({"t": t, "u": t, "tau_X": 1.0, "fault_code": code})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 10 Hz to 13 Hz: interpolated samples, said
        out = resample_log(log, 13.0)
    assert out["fault_code"].dtype == log["fault_code"].dtype
    k = np.searchsorted(t, out["t"].to_numpy() + 1e-9, "right") - 1
    assert (out["fault_code"].to_numpy() == code[k]).all()
    assert np.allclose(out["u"], out["t"])  # interpolated, not held


def test_resampling_a_log_at_its_own_rate_changes_nothing():
    """The grid t0 + k/rate is not the logged k·0.1 in floating point (k/10 and k·0.1, or a
    cumulative sum of 0.1, differ in the last bits), so a log resampled at its own rate had
    every value interpolated a rounding away from its sample, an angle unwrapped and wrapped
    back, and a held input taken from the sample before where the grid fell just short."""
    n = 300
    rng = np.random.default_rng(4)
    run = {
        "u": rng.normal(size=n),
        "psi": np.angle(np.exp(1j * (3.0 + 0.07 * np.arange(n)))),  # wraps at ±π
        "theta": rng.normal(0.0, 0.1, n),
        "tau_X": np.repeat(rng.normal(size=n // 3), 3),  # held over three samples
    }
    log = pd.concat(
        [
            pd.DataFrame({"t": np.arange(n) * 0.1, "experiment": "a", **run}),
            pd.DataFrame({"t": np.cumsum(np.full(n, 0.1)) - 0.1, "experiment": "b", **run}),
        ],
        ignore_index=True,
    )
    assert np.any(np.arange(n) / 10.0 != log["t"].to_numpy()[:n])  # the grid is not the log's
    out = resample_log(log, 10.0)
    assert list(out.columns) == list(log.columns) and len(out) == len(log)
    for col in log.columns:
        np.testing.assert_array_equal(out[col].to_numpy(), log[col].to_numpy(), err_msg=col)


def test_resampling_an_epoch_clock_at_its_own_rate_changes_nothing():
    """An epoch clock (~1.7e9 s) as read from text is held to units of 2.4e-7 s: its span fell
    1.4e-7 s short of 29.9 s, and the 1e-9 samples of slack lost the last sample, which is on
    the grid; grid times a unit off their samples (1e-10 s to snap to) were interpolated a
    rounding away, a held input taken from the sample before. The grid's end and its samples
    are the clock's rounding (the readers' rule): the log comes back as it was, its clock
    from 0."""
    n = 300
    rng = np.random.default_rng(4)
    t = np.array([float(f"{1700000000.2 + k / 10:.1f}") for k in range(n)])  # as read from text
    assert (t[-1] - t[0]) * 10.0 < n - 1  # the span is short of the last grid time
    assert np.any(t[0] + np.arange(n) / 10.0 != t)  # the grid is not the log's
    log = pd.DataFrame(
        {
            "t": t,
            "experiment": "a",
            "u": rng.normal(size=n),
            "psi": np.angle(np.exp(1j * (3.0 + 0.07 * np.arange(n)))),  # wraps at ±π
            "tau_X": np.repeat(rng.normal(size=n // 3), 3),  # held over three samples
        }
    )
    out = resample_log(log, 10.0)
    assert list(out.columns) == list(log.columns) and len(out) == n
    want = log.assign(t=t - t[0])  # each run's clock starts at 0 at its first sample
    for col in log.columns:
        np.testing.assert_array_equal(out[col].to_numpy(), want[col].to_numpy(), err_msg=col)


def test_resampling_a_log_declared_in_epoch_nanoseconds_keeps_its_last_sample():
    """A log whose t was declared in nanoseconds since the epoch (~1.7e18, held to 256 ns
    as float64 before the division by 1e9): its span came 2.04 units of the seconds' last
    place short of its last grid time, over the two the grid allowed, and the last sample
    was lost. The declared unit's rounding is allowed for: the log comes back as it was."""
    first, n = 1700980056381051776, 27
    ns = first + np.arange(n, dtype=np.int64) * 10_000_000
    values = np.sqrt(np.arange(n, dtype=np.float64))  # not a straight line: interpolating shows
    log, _ = declare_time_unit(pd.DataFrame({"t": ns, "u": values, "tau_X": values}), "ns")
    t = log["t"].to_numpy()
    assert abs((t[-1] - t[0]) - (n - 1) / 100.0) > 2 * np.spacing(t[-1])  # the case
    out = resample_log(log, 100.0)
    assert len(out) == n
    assert out["u"].tolist() == values.tolist() and out["tau_X"].tolist() == values.tolist()


def test_resampling_does_not_interpolate_a_wrapped_angle_through_zero():
    """A yaw stepping from 3.14 to -3.14 was interpolated through 0 between the two samples: a
    turn of 2.4 rad in 1/13 s that the vehicle never made."""
    t = np.arange(0, 10, 0.1)
    heading = 3.0 + 0.1 * t  # crosses π at t = 1.4 s
    log = pd.DataFrame({"t": t, "psi": np.angle(np.exp(1j * heading)), "tau_N": 1.0})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # 10 Hz to 13 Hz: interpolated samples, said
        out = resample_log(log, 13.0)
    # the log's own convention (within ±π) kept: unwrapping is the preprocess config's step
    assert np.allclose(np.exp(1j * out["psi"]), np.exp(1j * (3.0 + 0.1 * out["t"])))
    assert np.abs(out["psi"]).max() <= np.pi


def test_unwrap_and_degree_guard():
    psi = np.angle(np.exp(1j * np.linspace(0, 20, 500)))
    log = pd.DataFrame({"t": np.arange(500) * 0.1, "psi": psi})
    out = unwrap_angles(log)
    assert np.allclose(out["psi"], np.linspace(0, 20, 500))


def test_an_empty_angle_cell_stays_one_gap_when_unwrapped():
    """np.unwrap carried one empty psi cell into every later sample: a single missing yaw
    sample of a pose-only log masked the rest of its run (1100 samples) once velocities were
    derived from it."""
    t = np.arange(500) * 0.1
    heading = np.linspace(0, 20, 500)  # three turns: unwrapping has work to do after the gap
    psi = np.angle(np.exp(1j * heading))
    psi[100] = np.nan
    log = pd.DataFrame({"t": t, "x": np.cos(t), "y": np.sin(t), "z": 0 * t, "phi": 0 * t,
                        "theta": 0 * t, "psi": psi})  # fmt: skip
    out = unwrap_angles(log)
    assert out["psi"].isna().sum() == 1
    kept = np.arange(500) != 100
    assert np.allclose(out["psi"][kept], heading[kept])
    derived = derive_velocities(log, window_s=0.5)
    assert derived["psi"].isna().sum() == 1
    assert derived["r"].notna().sum() == 499  # the rate only at the missing sample is missing


def test_lowpass_is_zero_phase_and_rejects_short_logs():
    t = np.arange(0, 20, 0.01)
    slow = np.sin(2 * np.pi * 0.2 * t)
    noisy = slow + 0.2 * np.sin(2 * np.pi * 30 * t)
    out = lowpass(pd.DataFrame({"t": t, "u": noisy}), ["u"], cutoff=2.0)
    assert np.abs(out["u"] - slow)[200:-200].max() < 0.01  # no delay, no ripple
    with pytest.raises(NnidInputError, match="too few for the low-pass"):
        lowpass(pd.DataFrame({"t": t[:10], "u": noisy[:10]}), ["u"], cutoff=2.0)
    with pytest.raises(NnidInputError, match="too few for the Savitzky-Golay"):
        savgol_derivative(noisy[:11], 0.01, 21, 4)


def test_lowpass_refuses_a_log_whose_stamps_come_in_bursts_and_filters_it_resampled():
    """An IMU delivering ten samples together every 10 ms (1 kHz over the run, median step
    10 us): the filter was designed at the median step's 100 kHz, so a 5 Hz cut-off acted at
    about 0.05 Hz on the samples and removed the 1 Hz motion it was to keep. No one rate fits
    samples in bursts: refused, naming the run's rate and the fix, which then works."""
    t = (np.arange(300)[:, None] * 0.01 + np.arange(10)[None, :] * 1e-5).ravel()
    motion = np.sin(2 * np.pi * t)
    log = pd.DataFrame({"t": t, "u": motion + 0.3 * np.sin(2 * np.pi * 30 * t)})
    with pytest.raises(NnidInputError, match="in bursts") as err:
        lowpass(log, ["u"], cutoff=5.0)
    rate = float(re.search(r"(\d+) Hz over the run", err.value.message).group(1))
    assert 900 < rate < 1100 and "resample" in err.value.message
    grid = resample_log(log, 1000.0)
    out = lowpass(grid, ["u"], cutoff=5.0)
    off = np.abs(out["u"] - np.sin(2 * np.pi * grid["t"]))[300:-300]
    assert off.max() < 0.02  # the 30 Hz gone (0.3 before), the 1 Hz kept


def _transient_accelerations(log: pd.DataFrame, window_s: float) -> pd.DataFrame:
    from nnid.datasets.segmentation import accelerations_with_noise

    return accelerations_with_noise(log, window_s)[0]


#: each Savitzky-Golay derivative over a run's samples: (call, column, its true amplitude)
_DERIVATIVES = {
    "derive_velocities": (lambda log, w: derive_velocities(log, w), "r", 0.5 * np.pi),
    "derive_accelerations": (lambda log, w: derive_accelerations(log, w), "du", np.pi),
    "segmentation": (_transient_accelerations, "u", np.pi),
}


@pytest.mark.parametrize("path", list(_DERIVATIVES))
def test_a_derivative_refuses_a_log_whose_stamps_come_in_bursts_and_is_right_resampled(path):
    """Ten samples together every 10 ms (1 kHz over the run, median step 10 us): the window
    was set at the median step's 100 kHz, so 0.02 s took 2001 samples (2 s) spaced 10 us,
    and a rate of amplitude pi came out at about 600. Refused as lowpass refuses it, naming
    the run and the fix, which then derives it."""
    call, column, amplitude = _DERIVATIVES[path]
    t = (np.arange(600)[:, None] * 0.01 + np.arange(10)[None, :] * 1e-5).ravel()
    wave = np.sin(np.pi * t)
    log = pd.DataFrame({"t": t, "phi": 0.0, "theta": 0.0, "psi": 0.5 * wave, "u": wave})
    with pytest.raises(NnidInputError, match="in bursts") as err:
        call(log, 0.02)
    assert err.value.field == "t" and err.value.message.startswith("the log: its stamps")
    assert "Savitzky-Golay" in err.value.message and "resample_log" in err.value.message
    grid = resample_log(log, 1000.0)
    got = call(grid, 0.02)[column].to_numpy()
    assert np.abs(got - amplitude * np.cos(np.pi * grid["t"].to_numpy())).max() < 0.01


def _dropped(t: np.ndarray) -> np.ndarray:
    """``t`` without 20 of its samples (one in ten from its 300th)."""
    return np.delete(t, np.arange(300, 500, 10))


@pytest.mark.parametrize("path", ["lowpass", *_DERIVATIVES], ids=["lowpass", *_DERIVATIVES])
def test_a_run_with_dropped_samples_is_warned_of_by_name_and_its_steps_spread(path):
    """A 100-Hz run with 20 samples dropped: the filter (designed at the median step's rate)
    and the derivatives (at the median step) take its samples as evenly spaced, so across
    each hole they acted over half the time, without a word. Warned of, naming the run and
    its steps' spread; a run whose stamps only jitter within 10 % is not, nor a uniform one."""
    rng = np.random.default_rng(0)
    even = np.arange(1000) * 0.01
    runs = {
        "even": even,
        "jitter": even + rng.uniform(-4e-4, 4e-4, even.size),
        "gaps": _dropped(even),
    }
    log = pd.concat(
        [pd.DataFrame({"t": t, "experiment": name}) for name, t in runs.items()], ignore_index=True
    )
    wave = np.sin(np.pi * log["t"])
    log = log.assign(phi=0.0, theta=0.0, psi=0.5 * wave, u=wave)
    if path == "lowpass":
        step = lambda log: lowpass(log, ["u"], 2.0)  # noqa: E731
    else:
        step = lambda log: _DERIVATIVES[path][0](log, 0.5)  # noqa: E731
    with pytest.warns(UserWarning, match="not evenly sampled") as caught:
        step(log)
    said = [str(w.message) for w in caught if "not evenly sampled" in str(w.message)]
    assert len(said) == 1 and said[0].startswith("experiment 'gaps' is not evenly sampled")
    assert "20 of its 979 steps" in said[0] and "from 0.01 to 0.02 s" in said[0]
    assert "other runs" not in said[0] and "resample_log" in said[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        step(log[log["experiment"] != "gaps"])


def _ms_clock(rate: float, seconds: float = 2.0) -> pd.DataFrame:
    """A ``rate``-Hz log sampled on time, stamped in whole milliseconds (120 Hz steps 8, 8,
    9 ms): u = sin(2 pi 2 t) at the true times, so du's amplitude is 4 pi."""
    true = np.arange(round(seconds * rate)) / rate
    return pd.DataFrame({"t": np.round(true * 1e3) / 1e3, "u": np.sin(4 * np.pi * true)})


@pytest.mark.parametrize("rate", [120.0, 300.0])
def test_a_clock_rounded_to_the_millisecond_is_one_sample_a_step_at_its_rate(rate):
    """The median step of 120 Hz in ms is 8 ms (300 Hz: 3 ms), not 8.33: every derivative
    came out 4 % (11 %) too large, each 9-ms step was warned of as not one sample, and
    check_uniform refused the log though no sample is missing. The clock's rounding is one
    sample: the rate is the run's, nothing is said, the log is accepted."""
    log = _ms_clock(rate)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        du = derive_accelerations(log, 0.1)["du"].to_numpy()
    middle = du[log["t"].between(0.5, 1.5)]
    assert np.max(np.abs(middle)) == pytest.approx(4 * np.pi, rel=5e-3)
    assert not [w for w in caught if "not evenly sampled" in str(w.message)]
    interval = check_uniform(log, "a NARX model")
    assert interval == pytest.approx(1 / rate, rel=1e-3)
    assert typical_step(log["t"].to_numpy(), np.nan) == interval


@pytest.mark.parametrize("rate", [120.0, 300.0])
def test_a_rounded_clock_that_drops_a_sample_or_changes_rate_is_still_refused(rate):
    """A millisecond clock's rounding is one sample, a dropped sample (a step of two) is
    not, nor a rate that changes from 8 to 9 ms (both multiples of the rounding)."""
    log = _ms_clock(rate)
    dropped = log.drop(index=log.index[len(log) // 2]).reset_index(drop=True)
    with pytest.warns(UserWarning, match="not evenly sampled"):
        derive_accelerations(dropped, 0.1)
    with pytest.raises(NnidInputError, match="not uniformly sampled"):
        check_uniform(dropped, "a NARX model")
    steps = np.repeat([0.008, 0.009], 120)
    changed = pd.DataFrame({"t": np.round(np.cumsum(steps) * 1e3) / 1e3, "u": 0.0})
    with pytest.raises(NnidInputError, match="not uniformly sampled"):
        check_uniform(changed, "a NARX model")


def test_runs_at_rates_a_few_percent_apart_are_not_one_rate():
    """A sample-counting model's runs at one rate: 0.050 and 0.054 s (20 and 18.5 Hz) passed
    the 10 % of one interval's jitter and were trained (the hybrid flew both at 0.052 s).
    Refused naming both rates; runs of one rate on a clock rounded to the millisecond still
    pass, a short one's least-squares step (1.4 % off: read to the rounding over its steps)
    too."""
    runs = [
        pd.DataFrame({"experiment": name, "t": np.arange(40) * dt, "u": 0.0})
        for name, dt in (("a", 0.050), ("b", 0.054))
    ]
    with pytest.raises(NnidInputError, match=r"every 0\.054 s, against 0\.05 s in its fir") as e:
        check_uniform(pd.concat(runs, ignore_index=True), "a NARX model", one_rate=True)
    assert e.value.field == "t" and "experiment a" in str(e.value)
    with pytest.raises(NnidInputError, match=r"every 0\.054 s, against 0\.05 s at training"):
        check_uniform(runs[1], "a NARX model", interval=0.05, one_rate=True)
    long, short = _ms_clock(240.0), _ms_clock(240.0).iloc[1:11]
    assert abs(clock_step(short["t"].to_numpy())[0] * 240 - 1) > 0.01
    same = pd.concat([long.assign(experiment="long"), short.assign(experiment="short")])
    interval = check_uniform(same.reset_index(drop=True), "a NARX model", one_rate=True)
    assert interval == pytest.approx(1 / 240, rel=1e-3)


def test_a_clock_not_rounded_coarsely_keeps_the_median_step_bit_for_bit():
    """Float stamps (a grid, jitter within 10 %, an epoch clock, 120 Hz not rounded, a
    clock whose rate is a whole number of its rounding, a rate that changes) keep the
    median step and the median rule of which steps are off, to the last bit."""
    rng = np.random.default_rng(1)
    k = np.arange(600)
    clocks = {
        "grid": k * 0.01,
        "division": k / 120,
        "jitter": k * 0.01 + rng.uniform(-4e-4, 4e-4, k.size),
        "epoch": 1.7e9 + k * 0.01,
        "100 Hz in ms": np.round(k * 10.0) / 1e3,
        "rate change": np.cumsum(np.repeat([0.01, 0.02], 300)),
        "dropped": _dropped(k * 0.01),
    }
    for name, t in clocks.items():
        steps = np.diff(t)
        median = float(np.median(steps))
        assert typical_step(t, np.nan) == median, name
        typical, off, rounding = off_steps(t)
        assert (typical, rounding) == (median, 0.0), name
        expected = np.flatnonzero(np.abs(steps - median) > UNIFORM_TOLERANCE * median)
        np.testing.assert_array_equal(off, expected, err_msg=name)


def _prepare_motion(log: pd.DataFrame) -> pd.DataFrame:
    from nnid.models.parametric import prepare_motion

    return prepare_motion(log, ["r"], 0.5, 4, True)


def _loop_prepare(log: pd.DataFrame) -> pd.DataFrame:
    from nnid.loop.residual_loop import ResidualLoop

    loop = ResidualLoop(load_vehicle("bluerov2_heavy"))
    loop.savgol_window = 0.5
    return loop._prepare(log)


_CHAINS = {
    "preprocess": lambda log: preprocess(
        log, PreprocessConfig(velocities="derive", accelerations=True)
    )[0],
    "prepare_motion": _prepare_motion,
    "residual_loop": _loop_prepare,
}


@pytest.mark.parametrize("chain", list(_CHAINS))
def test_a_chain_that_derives_velocities_then_accelerations_warns_of_dropped_samples_once(chain):
    """A pose-only run with 20 samples dropped, its velocities and then its accelerations
    derived in one call (the preprocessing, a model's motion, the residual loop's data): each
    derivative warned that it was not evenly sampled, the same sentence twice for one clock.
    Said once; the accelerations alone still say it."""
    t = _dropped(np.arange(1000) * 0.01)
    wave = np.sin(np.pi * t)
    log = pd.DataFrame({"t": t, "experiment": "gaps", "z": 0.1 * wave, "phi": 0.0,
                        "theta": 0.0, "psi": 0.5 * wave})  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = _CHAINS[chain](log)
    said = [str(w.message) for w in caught if "not evenly sampled" in str(w.message)]
    assert len(said) == 1 and said[0].startswith("experiment 'gaps' is not evenly sampled"), said
    assert "dr" in out
    with pytest.warns(UserWarning, match="experiment 'gaps' is not evenly sampled"):
        derive_accelerations(out.drop(columns=[c for c in out if c.startswith("d")]), 0.5)


def test_held_at_reads_a_clock_rounded_to_the_millisecond_at_its_rate():
    """held_at's sample time (a held force's lag, whether zoh_midpoint is warned of) was the
    plain median of the steps, 8 ms for 120 Hz stamped in whole ms (8, 8, 9 ms): it reads
    the runs' steps as the rest of nnid does (clock_step), each run's joins left out."""
    runs = []
    for name in ("a", "b"):
        run = _ms_clock(120.0, 3.0).iloc[:241].assign(experiment=name)  # 0 to 2 s, whole stamps
        run["tau_X"] = np.repeat(np.arange(1.0, 122.0), 2)[:241]  # held over two samples
        runs.append(run)
    held, dt = held_at(pd.concat(runs, ignore_index=True))
    assert held == ["tau_X"]
    # 2 s of whole-ms stamps fix the rate to a few 1e-6 (the run's slope, rounded_clock)
    assert dt == pytest.approx(1 / 120, rel=1e-5)


def test_steps_split_between_two_rates_keep_their_median():
    """Steps split evenly between two rates far apart (0.01 and 0.1 s) have a median near
    neither: rounded_clock found no step near it and raised NumPy's 'zero-size array to
    reduction operation minimum' from typical_step, held_at (runs at 100 and 10 Hz read
    together) and the unit checks, instead of reading the median."""
    assert typical_step(np.array([0.0, 0.01, 0.11]), np.nan) == pytest.approx(0.055)
    runs = [
        pd.DataFrame({"t": np.arange(3) * dt, "experiment": name, "tau_X": [1.0, 1.0, 2.0]})
        for name, dt in (("fast", 0.01), ("slow", 0.1))
    ]
    held, dt = held_at(pd.concat(runs, ignore_index=True))
    assert held == ["tau_X"] and dt == pytest.approx(0.055)


def test_an_uneven_clock_or_one_glitch_is_no_rounded_clock():
    """Float stamps of a clock alternating 0.04 and 0.06 s step by multiples of 0.02 s: read
    as a clock rounded to 0.02 s, check_uniform accepted them for a sample-counting model and
    nothing warned. A clock's resolution is a decimal unit, so they stay uneven. One 11-ms
    step on an exact 10-ms grid read as 1-ms rounding (step 10.0017 ms): a glitch is no
    share of the steps, so the grid keeps its median."""
    t = np.cumsum(np.r_[0.0, np.tile([0.04, 0.06], 100)])
    assert clock_step(t)[1] == 0.0
    alternating = pd.DataFrame({"t": t, "experiment": "alt", "u": 0.0})
    with pytest.raises(NnidInputError, match="not uniformly sampled"):
        check_uniform(alternating, "a NARX model")
    with pytest.warns(UserWarning, match="experiment 'alt' is not evenly sampled"):
        uneven_runs(alternating, "the filter")
    grid = np.arange(600) * 0.01
    grid[300:] += 0.001
    assert clock_step(grid) == (float(np.median(np.diff(grid))), 0.0)


def test_a_rounded_clock_with_dropped_samples_is_read_at_its_rate():
    """120 Hz stamped in whole ms for 20 s, 40 samples dropped: its step was the mean of its
    one-sample steps, whose error drifted the stamps more than 3 ms off its line, so the
    rule fell back to the 8-ms median and took every 9-ms step for a dropped sample. The
    step is the rate over the run, and only the dropped samples' steps are off."""
    rng = np.random.default_rng(0)
    true = np.arange(2400) / 120.0
    kept = np.sort(np.delete(np.arange(2400), rng.choice(np.arange(1, 2399), 40, False)))
    t = np.round(true[kept] * 1e3) / 1e3
    step, rounding = clock_step(t)
    assert step == pytest.approx(1 / 120, rel=1e-5)
    assert rounding == pytest.approx(1e-3)
    _, off, _ = off_steps(t)
    np.testing.assert_array_equal(off, np.flatnonzero(np.diff(kept) > 1))


def test_a_clock_step_with_no_sample_step_is_not_measured():
    """Runs of one sample each have no step within a run: clock_step took the median of
    nothing (NaN with NumPy's 'Mean of empty slice'); it says NaN, the step not measured."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        step, rounding = clock_step(np.arange(4.0), np.zeros(3, dtype=bool))
        assert np.isnan(step) and rounding == 0.0
        assert np.isnan(log_step(np.zeros(3), np.array(["a", "b", "c"])))


def test_a_whole_log_reads_its_runs_steps_without_the_joins():
    """Two runs of 120 Hz stamped in ms, t restarting at 0: read over the whole log, the
    negative step at the join took the rounded clock off its line, so the fault monitor's
    rearm gap, the hybrid model's step and the actuator lag's bound read the 8-ms median
    where each run alone reads 8.33 ms. log_step leaves the join out."""
    from nnid.loop.effects import candidates

    log = pd.concat(
        [_ms_clock(120.0, 3.0).assign(experiment=name) for name in ("a", "b")],
        ignore_index=True,
    )
    assert log_step(log["t"].to_numpy(), log["experiment"].to_numpy()) == pytest.approx(
        1 / 120, rel=1e-5
    )
    log = log.assign(**{f"tau_{d}": 0.0 for d in ("X", "Y", "Z", "K", "M", "N")})
    lag = next(
        c for c in candidates(load_vehicle("bluerov2_heavy"), log) if c.name == "actuator_lag"
    )
    assert lag.bounds[1] == pytest.approx(100 / 120, rel=1e-5)


def test_lowpass_refuses_a_run_of_one_sample_as_too_short_without_reading_its_rate():
    """A run of one sample has no step: its rate was read first (NumPy's "mean of empty
    slice" and scipy's divide warnings) before it was refused as too short."""
    log = pd.DataFrame(
        {"t": [0.0, *np.arange(100) * 0.01], "experiment": ["a"] + ["b"] * 100, "u": 0.0}
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(NnidInputError, match="experiment 'a' has 1 samples, too few"):
            lowpass(log, ["u"], cutoff=2.0)


def test_a_log_without_experiments_is_named_the_log_in_the_derivatives_errors():
    """A log without an experiment column has one run, named None by ``experiment_rows``: its
    errors said "experiment None", where the rest of nnid says "the log"."""
    t = np.arange(0, 0.1, 0.01)  # 10 samples, fewer than the 0.5 s window's 51
    log = pd.DataFrame({"t": t, "phi": 0.0, "theta": 0.0, "psi": 0.01 * t, "u": 0.1 * t})
    for call in (
        lambda: derive_velocities(log.drop(columns="u"), window_s=0.5),
        lambda: derive_accelerations(log, window_s=0.5),
        lambda: lowpass(log, ["u"], cutoff=2.0),
    ):
        with pytest.raises(NnidInputError, match="too few") as err:
            call()
        assert err.value.message.startswith("the log has 10 samples")
        assert "None" not in str(err.value)
    labelled = log.assign(experiment="a")
    with pytest.raises(NnidInputError, match="experiment 'a' has 10 samples"):
        derive_accelerations(labelled, window_s=0.5)


def test_a_run_of_one_sample_is_refused_by_name_and_a_piece_of_one_gets_no_derivative():
    """A run of one sample has no time step: its window's count was NaN and scipy said
    "cannot convert float NaN to integer". It is refused naming the run and the samples the
    shortest window needs (order 4: 7); a one-sample piece cut at a gap is left underived."""
    pose = {"phi": 0.0, "theta": 0.0, "psi": 0.0, "u": 0.0}
    one = pd.DataFrame({"t": [0.0], "experiment": "solo"} | pose)
    ten = pd.DataFrame({"t": np.arange(10) * 0.1, "experiment": "long"} | pose)
    log = pd.concat([ten, one], ignore_index=True)
    for call in (
        lambda: derive_velocities(log.drop(columns="u"), window_s=0.7, order=4),
        lambda: derive_accelerations(log, window_s=0.7, order=4),
    ):
        with pytest.raises(NnidInputError, match=r"experiment 'solo' has 1 sample\b") as err:
            call()
        assert "at least 7 samples" in str(err.value)
    pieces = log.assign(piece_of="run")  # both runs pieces of one cut at gaps
    out = derive_velocities(pieces.drop(columns="u"), window_s=0.5, order=2)
    assert out["r"].iloc[:10].notna().all() and np.isnan(out["r"].iloc[10])


def test_occlusion_jumps_are_found_and_repaired():
    rng = np.random.default_rng(3)
    t = np.arange(0, 30, 0.01)
    x = np.sin(0.5 * t) + rng.normal(0, 0.001, t.size)
    jumped = x.copy()
    spikes = [500, 1200, 2500]
    jumped[spikes] += [0.3, -0.5, 0.2]  # the tracker swaps markers for a frame
    assert set(np.flatnonzero(detect_jumps(jumped))) == set(spikes)
    report = CleaningReport()
    fixed = repair_jumps(pd.DataFrame({"t": t, "x": jumped}), ["x"], report=report)
    assert np.abs(fixed["x"] - x).max() < 0.01
    assert report.steps[0].detail.startswith("3 samples")


def test_heave_rate_from_depth_stays_bounded_when_tilted():
    """w ≈ ż/(cos θ cos φ) without x, y: near 90° of pitch the divisor is held at 0.5, and the
    report counts the samples where w is only a bound."""
    t = np.arange(0, 10, 0.01)
    theta = np.clip(0.3 * t, 0, 1.5)  # pitches up to 86°
    log = pd.DataFrame({"t": t, "z": 0.1 * t, "phi": 0.0, "theta": theta, "psi": 0.0, "tau_Z": 0.0})
    report = CleaningReport()
    out = derive_velocities(log, 0.5, 4, report)
    assert np.abs(out["w"]).max() <= 0.1 / 0.5 + 1e-6
    level = t < 1.0
    assert np.allclose(out["w"][level], 0.1 / np.cos(theta[level]), rtol=1e-3)
    assert "tilted beyond 60°" in report.steps[-1].detail


def test_savgol_derivative_is_scipys_bit_for_bit_without_its_dispatch(monkeypatch):
    """scipy's savgol_filter cost about 1 ms a call on a 2-s window, ten times its arithmetic
    (its array-API dispatch, the coefficients remade at every call), and ``detect --follow``
    took six derivatives every 0.5 s of rows. savgol_derivative now convolves with
    coefficients made once per setting and fits each end's half window as scipy does: scipy's
    result bit for bit over windows, orders, derivatives and lengths, between gaps and between
    steps, without calling it. The same of each column of a 2-D signal (one edge solve for
    all, as scipy's axis=0): the noise gain of a derivative cut at steps takes each piece's
    weights from the unit impulses' (:func:`_between_steps_gain2`), as scipy made them."""
    import scipy.signal
    from scipy.signal import savgol_filter

    from nnid.datasets import preprocess

    def scipys(y, window, order, deriv, dt):
        return savgol_filter(y, window, order, deriv=deriv, delta=dt, axis=0, mode="interp")

    def refused(*args, **kwargs):
        raise AssertionError("scipy's savgol_filter called")

    assert "savgol_filter" not in vars(preprocess)  # one implementation: savgol_interp
    monkeypatch.setattr(scipy.signal, "savgol_filter", refused)
    rng = np.random.default_rng(3)
    settings = [(3, 1, 1), (5, 2, 1), (7, 3, 3), (9, 2, 3), (11, 2, 0), (21, 4, 1), (21, 4, 2)]
    for window, order, deriv in settings:
        for n in (window, window + 1, 3 * window + 4):
            y = np.cumsum(rng.normal(size=n)) * 10.0 ** rng.uniform(-3, 3)
            dt = float(rng.uniform(0.005, 0.5))
            got = savgol_derivative(y, dt, window, order, deriv)
            np.testing.assert_array_equal(got, scipys(y, window, order, deriv, dt))
    y = np.cumsum(rng.normal(size=60))
    y[25] = np.nan  # a gap: each stretch on its own
    got = savgol_derivative(y, 0.05, 21, 4)
    np.testing.assert_array_equal(got[:25], scipys(y[:25], 21, 4, 1, 0.05))
    np.testing.assert_array_equal(got[26:], scipys(y[26:], 21, 4, 1, 0.05))
    y[25], steps = 0.0, np.array([17, 40])  # steps: each piece on its own, as scipy has it
    with monkeypatch.context() as scipy_pieces:
        scipy_pieces.setattr(preprocess, "savgol_interp", scipys)
        expected = savgol_derivative(y, 0.05, 21, 4, steps=steps)
    np.testing.assert_array_equal(savgol_derivative(y, 0.05, 21, 4, steps=steps), expected)
    for window, order, deriv in settings:
        impulses = np.eye(window)
        dt = float(rng.uniform(0.005, 0.5))
        np.testing.assert_array_equal(
            preprocess.savgol_interp(impulses, window, order, deriv, dt),
            scipys(impulses, window, order, deriv, dt),
        )
    steps = np.array([3, 13, 18, 24, 27, 28, 32, 45])  # pieces of 2 to 14 samples
    with monkeypatch.context() as scipy_pieces:
        scipy_pieces.setattr(preprocess, "savgol_interp", scipys)
        expected = preprocess.savgol_derivative_gain2(50, 0.05, 21, 4, 1, steps)
    got = preprocess.savgol_derivative_gain2(50, 0.05, 21, 4, 1, steps)
    np.testing.assert_array_equal(got, expected)


def test_a_savgol_window_too_short_for_its_order_is_widened_with_a_warning():
    """0.4 s at 5 Hz is 2 samples, too few for a quartic (6): the derivative uses 7 samples,
    and the setting's name says so; a window that fits, or no name (an internal default), is
    silent."""
    import warnings

    t = np.arange(100) * 0.2
    log = pd.DataFrame({"t": t, "u": np.sin(t), "experiment": "a"})
    with pytest.warns(UserWarning, match=r"savgol_window = 0.4 s is 2 samples at 5 Hz.*7 samples"):
        derive_accelerations(log, window_s=0.4, order=4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        derive_accelerations(log, window_s=2.0, order=4)
        assert savgol_window(0.5, 5.0, 4) == 7


@pytest.mark.parametrize(
    ("roll_rate", "dofs", "refused"),
    [
        ("bias", "uvwpqr", False),  # a level vehicle, a gyro biased by 0.5°/s: not a roll
        ("small", "uvwpqr", False),  # ±0.03 rad: the restoring moment it misses is noise
        ("rolls", "uvwpqr", True),  # ±0.3 rad
        ("tilts and holds", "uvwpqr", True),  # 0.19 rad in 5 s, held: the mean called it bias
        ("rolls", "ur", False),  # the surge and yaw restoring forces of this vehicle read no φ
        ("no rate", "uvwpqr", False),  # an empty p says nothing (and warned "empty slice")
    ],
)
def test_a_log_without_roll_is_refused_only_where_the_vehicle_rolled(roll_rate, dofs, refused):
    """The check integrates p with its mean (a gyro's bias) taken out, and asks whether the
    restoring forces of the fitted DOFs read φ (Weiss eq. 30): a biased level vehicle was
    refused (0.5°/s turns 1 rad in two minutes), and so was one whose fit reads no φ."""
    from nnid.datasets.preprocess import check_attitude

    vehicle = load_vehicle("seamor")  # r_g below r_b: roll and pitch moments read φ and θ
    t = np.arange(0, 120, 0.1)
    p = {"bias": np.full(t.size, np.radians(0.5)), "small": 0.03 * np.cos(t),
         "rolls": 0.3 * np.cos(t), "tilts and holds": np.where(t < 5, 0.038, 0.0),
         "no rate": np.full(t.size, np.nan)}[roll_rate]  # fmt: skip
    log = pd.DataFrame({"t": t, "experiment": "a", "u": 0.2, "p": p, "q": 0.0, "r": 0.0})
    if refused:
        with pytest.raises(NnidInputError, match="no phi column, and its p in experiment 'a'"):
            check_attitude(log, vehicle, list(dofs))
    else:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_attitude(log, vehicle, list(dofs))


@pytest.mark.parametrize("table", ["data", "model"])
def test_a_savgol_window_longer_than_a_run_is_refused_naming_the_key_that_set_it(tmp_path, table):
    """[data] savgol_window derives the velocities, [model] savgol_window the accelerations: a
    window longer than a run was refused naming only the config file."""
    from importlib import resources

    from typer.testing import CliRunner

    from nnid.cli import app

    log = pd.read_parquet(resources.files("nnid.demo_data").joinpath("demo_minirov_heave.parquet"))
    if table == "data":  # velocities to derive from the pose
        log = log.drop(columns=list("uvwpqr")).assign(x=0.0, y=0.0)
    log.to_csv(tmp_path / "log.csv", index=False)
    vehicle = resources.files("nnid.demo_data").joinpath("minirov.toml")
    (tmp_path / "t.toml").write_text(
        f'kind = "train"\nvehicle = "{vehicle}"\n[data]\nlog = "log.csv"\n'
        + ("savgol_window = 400.0\n" if table == "data" else "")
        + '[split]\nby = "experiment"\n[model]\nkind = "fossen"\n'
        + ("savgol_window = 400.0\n" if table == "model" else "")
    )
    res = CliRunner().invoke(app, ["train", str(tmp_path / "t.toml"), "--out", str(tmp_path / "o")])
    assert res.exit_code == 2, res.output
    assert f"field '{table}.savgol_window'" in res.output and "shorter savgol_window" in res.output


def test_resampling_far_from_the_logs_rate_is_warned_of():
    """A log taken from 100 Hz to 5 Hz keeps every 20th sample with what lay above 2.5 Hz
    folded in (no filter runs first), and one taken to 1 kHz is nine tenths interpolation:
    both said, with the rates; a log near its own rate is not."""
    t = np.arange(0, 10, 0.01)
    log = pd.DataFrame({"t": t, "u": np.sin(t), "tau_X": np.floor(t)})
    with pytest.warns(UserWarning, match="from 100 Hz to 5 Hz without an anti-alias filter"):
        resample_log(log, 5.0)
    with pytest.warns(UserWarning, match="interpolated, not measured"):
        resample_log(log, 1000.0)
    report = CleaningReport()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        resample_log(log, 80.0, report=report)
    assert "1000 samples at 100 Hz -> uniform 80 Hz" in report.steps[0].detail


def test_resampling_a_log_whose_stamps_come_in_bursts_reads_its_rate_over_the_run():
    """An IMU delivering ten samples together every 10 ms (1 kHz over the run, median step
    10 us) was quoted at its median step's 100 kHz: the anti-alias warning and the cleaning
    report said 100 kHz, and a grid at 600 Hz (within twice 1 kHz) was warned of as aliasing.
    The rate said and used is the run's (paced_step), as the readers take it."""
    t = (np.arange(100)[:, None] * 0.01 + np.arange(10)[None, :] * 1e-5).ravel()
    log = pd.DataFrame({"t": t, "u": np.sin(t), "tau_X": np.floor(10 * t)})
    report = CleaningReport()
    with pytest.warns(UserWarning, match="anti-alias") as caught:
        resample_log(log, 100.0, report=report)
    said = float(re.search(r"from (\S+) Hz", str(caught[0].message)).group(1))
    reported = float(re.search(r"samples at (\S+) Hz", report.steps[0].detail).group(1))
    assert 900 < said < 1100 and 900 < reported < 1100
    assert "in bursts" in report.steps[0].detail
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # 1 kHz to 600 Hz is within RESAMPLE_RATIO
        resample_log(log, 600.0)


def test_runs_joined_without_a_fresh_index_get_each_their_own_velocities():
    """Two runs joined by pd.concat keep their index labels 0..59 twice: derive_velocities
    (and the unwrapping before it) read and wrote a run by its labels, so each run took the
    other's samples too. Rows are now taken by position: each run is derived as it is alone."""
    t = np.arange(60) * 0.05
    zero = 0 * t
    a = pd.DataFrame({"t": t, "experiment": "a", "x": np.cos(t), "y": np.sin(t), "z": zero,
                      "phi": zero, "theta": zero, "psi": np.angle(np.exp(3j * t))})  # fmt: skip
    b = a.assign(experiment="b", x=0.5 * t, y=zero, psi=0.2 * t)
    # a run of another length, with a gap: the runs of one length are unwrapped together,
    # the attitude's matrices made for all rows at once; each run's numbers are its own
    c = a.head(45).assign(experiment="c", psi=np.angle(np.exp(-2j * t[:45])), theta=0.1 * t[:45])
    c.loc[20, "psi"] = np.nan
    runs = [a, b, c]
    joined = derive_velocities(pd.concat(runs), window_s=0.5)
    alone = pd.concat([derive_velocities(run, window_s=0.5) for run in runs])
    pd.testing.assert_frame_equal(joined, alone, check_exact=True)  # to the bit


def test_an_infinite_pose_or_velocity_is_refused_naming_its_column_and_row():
    """An inf at a run's end stopped scipy's Savitzky-Golay edge fit ('array must not contain
    infs or NaNs', naming no column or row), and one inside a run turned the window around it
    into ±inf and NaN without a word; a NaN time failed as 'cannot convert float NaN to
    integer'. Each is refused, naming its column and row (the index label)."""
    t = np.arange(60) * 0.05
    pose = pd.DataFrame({"t": t, "x": np.sin(t), "y": t, "z": 0 * t, "phi": 0 * t,
                         "theta": 0 * t, "psi": 0.1 * t}, index=np.arange(60) + 100)  # fmt: skip
    for col, row, value in [("y", 101, np.inf), ("psi", 130, -np.inf), ("t", 140, np.nan)]:
        bad = pose.copy()
        bad.loc[row, col] = value
        with pytest.raises(NnidInputError, match="not a finite number") as err:
            derive_velocities(bad, window_s=0.5)
        assert (err.value.field, err.value.row) == (col, row)
    velocity = derive_velocities(pose, window_s=0.5)
    velocity.loc[159, "q"] = np.inf  # the last row: the edge fit
    with pytest.raises(NnidInputError, match="accelerations") as err:
        derive_accelerations(velocity, window_s=0.5)
    assert (err.value.field, err.value.row) == ("q", 159)


def _joined_with_repeated_labels() -> pd.DataFrame:
    """Two runs of different rates and lengths joined by pd.concat without ignore_index:
    labels 0..39 name a row of each, each run with a jump in u and a held input."""
    rng = np.random.default_rng(4)
    ta, tb = np.arange(80) * 0.05, np.arange(40) * 0.1
    a = pd.DataFrame({"t": ta, "experiment": "a", "u": np.sin(ta) + rng.normal(0, 0.01, 80)})
    a["r"], a["tau_X"] = np.cos(2 * ta), np.repeat(rng.normal(0, 5, 16), 5)
    b = pd.DataFrame({"t": tb, "experiment": "b", "u": 0.3 * tb + rng.normal(0, 0.01, 40)})
    b["r"], b["tau_X"] = -np.sin(tb), np.repeat(rng.normal(0, 5, 10), 4)
    a.loc[30, "u"] += 2.0
    b.loc[12, "u"] -= 2.0
    return pd.concat([a, b])


@pytest.mark.parametrize(
    "step",
    [
        lambda log: lowpass(log, ["u", "r"], 2.0),
        lambda log: derive_accelerations(log, window_s=1.0),
        lambda log: derive_accelerations(log, window_s=1.0, cut_at_steps=True),
        lambda log: repair_jumps(log, ["u"], min_jump=0.5),
        lambda log: resample_log(log, 10.0),
    ],
    ids=["lowpass", "derive_accelerations", "cut_at_steps", "repair_jumps", "resample_log"],
)
def test_runs_joined_without_a_fresh_index_are_each_processed_as_alone(step):
    """pd.concat([a, b]) gives labels 0..39 to a row of each run: each run's rows were found by
    label, so a run was read (and written) with the other's rows too. Found by position, every
    row comes out as it does from the same log with a fresh index."""
    joined = _joined_with_repeated_labels()
    fresh = joined.reset_index(drop=True)
    got, want = step(joined), step(fresh)
    assert not got.equals(joined)  # the step changed something to compare
    pd.testing.assert_frame_equal(got.reset_index(drop=True), want.reset_index(drop=True))


def test_arrays_of_runs_joined_without_a_fresh_index_are_each_made_as_alone():
    """check_uniform, held_at (held_inputs), zoh_midpoint, first_order_lag and
    acceleration_gain2 on runs whose labels repeat (pd.concat): the same as on a fresh index,
    row by row."""
    joined = _joined_with_repeated_labels()
    fresh = joined.reset_index(drop=True)
    # the first run's interval; reading both runs' t under each label was a clock going back
    interval = check_uniform(joined, "the test")
    assert interval == check_uniform(fresh, "the test") == pytest.approx(0.05)
    held = held_at(joined)
    assert held == held_at(fresh) and held[0] == ["tau_X"]  # held over 5 and 4 samples
    tau = joined[["tau_X"]].to_numpy(np.float64)
    np.testing.assert_array_equal(zoh_midpoint(tau, joined), zoh_midpoint(tau, fresh))
    np.testing.assert_array_equal(
        first_order_lag(tau, joined, 0.3), first_order_lag(tau, fresh, 0.3)
    )
    np.testing.assert_array_equal(
        acceleration_gain2(joined, 1.0, 4, True), acceleration_gain2(fresh, 1.0, 4, True)
    )


def test_a_roll_is_judged_run_by_run_where_labels_repeat():
    """A level run whose gyro is biased, joined by pd.concat after a longer one that trembles:
    each run's p was read by label, with the other's rows under the same labels, and the
    mixture's median left an offset that "rolled" the vehicle 0.8 rad. By position, neither
    run is refused, as with a fresh index."""
    from nnid.datasets.preprocess import check_attitude

    vehicle = load_vehicle("seamor")
    ta, tb = np.arange(0, 120, 0.1), np.arange(0, 60, 0.1)
    a = pd.DataFrame({"t": ta, "experiment": "a", "u": 0.2, "p": 0.03 * np.cos(ta), "q": 0.0})
    b = pd.DataFrame({"t": tb, "experiment": "b", "u": 0.2, "p": np.radians(0.5), "q": 0.0})
    joined = pd.concat([a, b])
    check_attitude(joined.reset_index(drop=True), vehicle, list("uvwpqr"))
    check_attitude(joined, vehicle, list("uvwpqr"))
    with pytest.raises(NnidInputError, match="its p in experiment 'a'"):  # a roll still is one
        check_attitude(pd.concat([a.assign(p=0.3 * np.cos(ta)), b]), vehicle, list("uvwpqr"))


def test_lowpass_filters_each_stretch_between_gaps_on_its_own():
    """One empty cell made filtfilt (IIR, forward and backward) turn the whole run's column
    NaN while the report said 'zero-phase Butterworth'. Each stretch between gaps is filtered
    on its own, one too short for filtfilt's padding is left as logged and counted, and an
    infinite value is refused, naming its column."""
    rng = np.random.default_rng(4)
    t = np.arange(400) * 0.05
    u = np.sin(t) + 0.05 * rng.standard_normal(t.size)
    log = pd.DataFrame({"t": t, "u": u})
    gaps = [200, 300, 305]  # 301-304: four samples, fewer than filtfilt's padding
    log.loc[gaps, "u"] = np.nan
    report = CleaningReport()
    out = lowpass(log, ["u"], cutoff=2.0, report=report)["u"].to_numpy()
    assert np.array_equal(np.flatnonzero(np.isnan(out)), gaps)
    for a, b in [(0, 200), (201, 300), (306, 400)]:
        alone = lowpass(log.iloc[a:b], ["u"], cutoff=2.0)["u"].to_numpy()
        assert np.allclose(out[a:b], alone, rtol=0, atol=1e-12)
    assert np.array_equal(out[301:305], u[301:305])
    assert "4 samples in stretches" in report.steps[0].detail
    with pytest.raises(NnidInputError, match="Butterworth") as err:
        lowpass(log.assign(u=np.where(t == t[10], np.inf, u)), ["u"], cutoff=2.0)
    assert err.value.field == "u"


def test_resampling_counts_a_sample_alone_between_gaps_and_refuses_a_log_of_them():
    """A piece of one sample was dropped without a word (rows_removed 0), and a log of only
    such pieces ended in pandas' 'No objects to concatenate'."""
    log = pd.DataFrame({"t": [0.0, 0.1, 0.2, 5.0, 10.0, 10.1, 10.2], "u": np.arange(7.0)})
    report = CleaningReport()
    out = resample_log(log, 10.0, gap=1.0, report=report)
    assert report.rows_removed == 1 == len(log) - len(out)  # the grid is the samples here
    assert "1 sample without another within 1 s" in report.steps[0].detail
    with pytest.raises(NnidInputError, match="no run of the log has two samples") as err:
        resample_log(log.iloc[[0, 3, 4]], 10.0, gap=1.0)
    assert err.value.field == "gap"


@pytest.mark.parametrize("step", ["velocities", "accelerations"])
def test_the_derive_report_counts_samples_in_stretches_shorter_than_the_window(step):
    """Between two empty cells five samples apart the four samples are finite, but no
    window fits there: they were left without a derivative while the report counted only
    the short pieces. Said now; the values are as before."""
    t = np.arange(400) * 0.05
    log = pd.DataFrame({c: np.sin(0.1 * (k + 1) * t) for k, c in enumerate([*POSE, *VELOCITY])})
    log.insert(0, "t", t)
    column = "x" if step == "velocities" else "u"
    log.loc[[100, 105], column] = np.nan
    report = CleaningReport()
    if step == "velocities":
        out = derive_velocities(log[["t", *POSE]], 0.5, report=report)["u"]
    else:
        out = derive_accelerations(log, 0.5, report=report)["du"]
    window = savgol_window(0.5, 20.0, 4)
    assert 4 < window  # the stretch 101-104 holds no window
    assert out.iloc[101:105].isna().all() and out.iloc[106:].notna().all()
    assert "; 4 samples in stretches between empty cells shorter than the window: none" in (
        report.steps[-1].detail
    )


def test_a_gap_does_not_stop_jump_repair():
    """An empty cell made the robust spread NaN, so no jump of the run was found or repaired.
    The gap now stays a gap, the jump is found and mended, and the samples beside the gap
    are not taken for jumps (their neighbours' median is a symmetric one)."""
    rng = np.random.default_rng(3)
    t = np.arange(0, 20, 0.05)
    x = np.sin(t) + 0.01 * rng.standard_normal(t.size)
    jumped = x.copy()
    jumped[50] += 1.0
    jumped[[300, 301, 302]] = np.nan
    assert np.array_equal(np.flatnonzero(detect_jumps(jumped)), [50])
    report = CleaningReport()
    fixed = repair_jumps(pd.DataFrame({"t": t, "x": jumped}), ["x"], report=report)["x"]
    assert np.isnan(fixed.iloc[300:303]).all()
    assert abs(fixed.iloc[50] - x[50]) < 0.05
    assert report.steps[0].detail.startswith("1 samples")


def test_a_runs_ends_are_read_as_a_gap_by_jump_detection():
    """The ends were padded with the end sample, which was then half its own reference: a
    clean sine's first and last samples were jumps, and a glitch there had to be about 12
    robust σ to be found. Beyond the ends is now read as a gap."""
    t = np.arange(0, 30, 0.01)
    clean = np.sin(0.5 * t) + 1e-4 * np.random.default_rng(3).standard_normal(t.size)
    assert not detect_jumps(clean).any()
    found = 0
    for seed in range(10):
        x = np.sin(0.5 * t) + 1e-3 * np.random.default_rng(seed).standard_normal(t.size)
        # about 7 of the detector's robust σ (1.2e-3 on this noise)
        for at, sign in [(0, 1), (0, -1), (-1, 1), (-1, -1)]:
            glitched = x.copy()
            glitched[at] += sign * 8.5e-3
            found += bool(detect_jumps(glitched)[at])
    # the one-sided reference at an end carries noise of its own: most, not all (1 of 40
    # with the end padded)
    assert found >= 25
