"""The augmented-state UKF (issue 4) and the observability of its formulation (Weiss V.D)."""

from __future__ import annotations

import numpy as np
import pytest

from nnid.datasets.arrays import log_arrays
from nnid.datasets.measurement import Measurement
from nnid.datasets.simulator import simulate
from nnid.models.parametric import ParametricFossen
from nnid.trainers.ukf import (
    UnscentedKalman,
    _Process,
    observability_rank,
    transition_jacobians,
)
from nnid.vehicle import load_vehicle

NAMES = ["X_udot", "X:u*abs(u)", "N_rdot", "N:r*abs(r)"]
TRUTH = np.array([-27.08, -61.117, -0.154, -1.772])  # seamor.toml (Weiss Table 3)
DT = 0.05
EXACT = Measurement(kind="none")
NOISY = Measurement(kind="dvl_imu")  # σ 0.005 m/s DVL, 0.002 rad/s gyro
CALIBRATED = 1e-4 / np.sqrt(DT)  # process noise per √s: 1e-4 per step of these 20-Hz logs


@pytest.fixture(scope="module")
def seamor():
    return load_vehicle("seamor")


def _steps(rng: np.random.Generator, n: int, amp: float, hold: tuple[float, float]):
    """Held random levels in [−amp, amp] for hold ∈ [lo, hi] s: sign-changing, multi-level."""
    out, k = np.zeros(n), 0
    while k < n:
        h = int(rng.uniform(*hold) / DT)
        out[k : k + h] = rng.uniform(-amp, amp)
        k += h
    return out


def _surge_yaw(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    inputs = np.zeros((n, 6))
    inputs[:, 0] = _steps(rng, n, 15.0, (2.0, 5.0))  # X (N)
    inputs[:, 5] = _steps(rng, n, 0.8, (1.0, 3.0))  # N (N m)
    return inputs


def _data(vehicle, inputs, measurement, **kw) -> dict[str, np.ndarray]:
    return log_arrays(simulate(vehicle, inputs, DT, measurement=measurement, **kw), vehicle)


def _structure(vehicle) -> ParametricFossen:
    return ParametricFossen(vehicle, NAMES, dofs=("u", "r"))


def test_process_is_the_physics_model(seamor):
    """The affine combination of parameter probes equals structure.parts(θ).model() + RK4."""
    data = _data(seamor, _surge_yaw(40), EXACT)
    proc = _Process(_structure(seamor), data)
    rng = np.random.default_rng(0)
    x = np.concatenate([data["nu"][20][[0, 5]], TRUTH])[None] * rng.uniform(0.5, 1.5, (5, 6))
    a, b = proc.step(x, 20, DT), proc.step_direct(x, 20, DT)
    np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)


def test_ukf_identifies_surge_and_yaw(seamor):
    """120 s of noisy DVL/gyro surge + yaw: each parameter within 5 % and inside ±2σ."""
    data = _data(seamor, _surge_yaw(2400), NOISY, seed=3)
    ukf = UnscentedKalman(process_noise=CALIBRATED, theta0=0.5 * TRUTH)
    est = ukf.fit(_structure(seamor), data)
    rel = np.abs(est.theta - TRUTH) / np.abs(TRUTH)
    assert np.all(rel < 0.05), rel
    assert np.all(np.abs(est.theta - TRUTH) < 2.0 * est.stderr), (est.theta, est.stderr)
    assert est.names == NAMES and est.cov.shape == (4, 4)
    assert 0.5 < est.sigma2 < 1.5  # normalised innovation squared per DOF: consistent filter
    assert est.history is not None and est.history.shape == (2400, 4)
    hist = ukf.history_
    assert hist["theta_std"].shape == (2400, 4) and hist["nu"].shape == (2400, 2)
    # the uncertainty shrinks by orders of magnitude from the prior (100 % of 0.5 θ)
    assert np.all(hist["theta_std"][-1] < 0.02 * hist["theta_std"][0])


def test_observability_full_when_excited(seamor):
    data = _data(seamor, _surge_yaw(600), EXACT)
    obs = observability_rank(_structure(seamor), data, TRUTH, measurement_noise=[0.005, 0.002])
    assert obs.n_states == 6 and obs.rank == 6 and obs.deficiency == 0
    assert obs.singular_values[-1] > 1e-3 * obs.singular_values[0]


def test_observability_at_rest_loses_every_parameter(seamor):
    """Zero input from rest: ν stays 0, no parameter moves the output; rank n_ν = 2."""
    data = _data(seamor, np.zeros((600, 6)), EXACT)
    obs = observability_rank(_structure(seamor), data, TRUTH, measurement_noise=[0.005, 0.002])
    assert obs.rank == 2 and obs.deficiency == 4
    assert np.all(obs.singular_values[2:] < 1e-12 * obs.singular_values[0])


def test_observability_at_trim_loses_added_mass(seamor):
    """Constant surge force in steady state (Weiss's frozen-point situation): ν̇ = 0 hides
    X_udot, and with r = N = 0 the yaw pair is invisible too: only X_u|u| is left."""
    inputs = np.zeros((600, 6))
    inputs[:, 0] = 10.0
    u_ss = np.sqrt(10.0 / -TRUTH[1])
    data = _data(seamor, inputs, EXACT, x0=[0.0] * 6 + [u_ss, 0, 0, 0, 0, 0])
    obs = observability_rank(_structure(seamor), data, TRUTH, measurement_noise=[0.005, 0.002])
    assert obs.rank == 3 and obs.deficiency == 3


def test_weiss_frozen_point_test_is_deficient_even_when_excited(seamor):
    """Weiss eq 135-136: [H; HΦ; HΦ²] with Φ frozen at one sample has rank 2 < 3 for the
    surge state [u, X_udot, X_u|u|] at every sample of an exciting run; the same run's
    trajectory observability matrix has full rank 3."""
    structure = ParametricFossen(seamor, NAMES[:2], dofs=("u",))
    data = _data(seamor, _surge_yaw(200), EXACT)
    theta = TRUTH[:2]
    h = np.array([[1.0, 0.0, 0.0]])
    for phi in transition_jacobians(structure, data, theta)[::20]:
        frozen = np.concatenate([h, h @ phi, h @ phi @ phi]) * np.r_[1.0, np.abs(theta)]
        sv = np.linalg.svd(frozen, compute_uv=False)
        assert sv[-1] < 1e-7 * sv[0]
    obs = observability_rank(structure, data, theta, measurement_noise=0.005)
    assert obs.rank == 3


def test_ratio_parameters_need_sign_changing_input(seamor):
    """η⁺ with X_udot and X_u|u| under a positive-only pure surge force: u̇ = (η⁺X +
    X_u|u| u|u|)/(m − X_udot) is unchanged by scaling (η⁺, X_u|u|, m − X_udot) together; the
    rank drops by exactly one however rich the levels. A force of both signs (η⁻ known), or
    yaw motion whose Coriolis force m v r (known gain) enters the surge equation, fixes the
    scale."""
    structure = ParametricFossen(seamor, ["eta.u.pos", *NAMES[:2]], dofs=("u",))
    theta = [1.0, *TRUTH[:2]]
    both = _surge_yaw(600)
    positive = np.zeros_like(both)
    positive[:, 0] = np.abs(both[:, 0])
    with_yaw = positive.copy()
    with_yaw[:, 5] = both[:, 5]
    obs = observability_rank(structure, _data(seamor, positive, EXACT), theta, 0, None, 1e-7, 0.005)
    assert obs.n_states == 4 and obs.deficiency == 1
    for inputs in (both * [1, 0, 0, 0, 0, 0], with_yaw):
        obs = observability_rank(
            structure, _data(seamor, inputs, EXACT), theta, 0, None, 1e-7, 0.005
        )
        assert obs.deficiency == 0


def test_window_must_stay_in_one_experiment(seamor):
    data = _data(seamor, np.zeros((20, 6)), EXACT)
    data["experiment"] = np.r_[np.zeros(10, int), np.ones(10, int)]
    with pytest.raises(ValueError, match="more than one experiment"):
        observability_rank(_structure(seamor), data, TRUTH)
    obs = observability_rank(
        _structure(seamor), data, TRUTH, start=10, length=10, measurement_noise=[0.005, 0.002]
    )
    assert obs.rank == 2


def test_an_overconfident_filter_widens_its_standard_errors_and_says_so(seamor):
    """Measurement noise declared three times too small: the innovations are far larger than the
    filter predicts (mean normalised innovation squared per DOF ≫ 1), so its covariance is
    overconfident. It is scaled by that statistic, as least squares scales by its residual
    variance, and a warning says by how much; a consistent filter is left as it is."""
    data = _data(seamor, _surge_yaw(1200), NOISY, seed=3)
    kw = {"process_noise": CALIBRATED, "theta0": 0.5 * TRUTH}
    sigma = np.asarray([0.005, 0.002]) * 0.3  # of NOISY's levels on u and r
    filt = UnscentedKalman(measurement_noise=sigma, **kw)
    with pytest.warns(UserWarning, match=r"innovations are [\d.]+ times the variance"):
        tight = filt.fit(_structure(seamor), data)
    assert tight.sigma2 > 5.0
    # the stored path's σ scaled as the covariance is: its last row was the filter's own,
    # √NIS = 3.3x below the s.e. reported beside it
    np.testing.assert_allclose(filt.history_["theta_std"][-1], tight.stderr, rtol=1e-12)
    assert np.all(np.abs(tight.theta - TRUTH) < 3.0 * tight.stderr), (tight.theta, tight.stderr)
    # the widened window bounded apart from the filter: three s.e. within 5 % of each value
    # (1200 samples of a surge-and-yaw run, noise at its true level, determine all four)
    assert np.all(3.0 * tight.stderr < 0.05 * np.abs(TRUTH)), (tight.stderr, TRUTH)


def test_ukf_gives_no_standard_error_to_what_its_data_did_not_inform(seamor):
    """Yaw never excited: the yaw pair kept near its prior and reported the prior σ as its
    standard error (N_rdot "significant" at 41 %), without a word (batch least squares: not
    excited, NaN)."""
    import warnings

    from nnid.trainers.least_squares import ExcitationWarning

    inputs = _surge_yaw(600)
    inputs[:, 5] = 0.0
    kw = {"process_noise": CALIBRATED, "theta0": 0.5 * TRUTH}
    with pytest.warns(ExcitationWarning, match=r"did not inform N_rdot, N:r\*abs\(r\) beyond"):
        est = UnscentedKalman(**kw).fit(_structure(seamor), _data(seamor, inputs, NOISY, seed=3))
    assert np.isnan(est.stderr[2:]).all() and not est.significant[2:].any()
    assert np.isfinite(est.stderr[:2]).all() and est.significant[:2].all()
    with warnings.catch_warnings():
        warnings.simplefilter("error", ExcitationWarning)  # excited: every s.e. is the data's
        est = UnscentedKalman(**kw).fit(_structure(seamor), _data(seamor, _surge_yaw(600), NOISY))
    assert np.isfinite(est.stderr).all()


def test_a_nan_velocity_is_no_measurement_not_a_divergence(seamor):
    """One NaN velocity sample stopped the filter with "the filter diverged ... widen the noise
    levels"; it is predicted through, without an update there, and said."""
    data = _data(seamor, _surge_yaw(600), NOISY, seed=3)
    kw = {"process_noise": CALIBRATED, "theta0": 0.5 * TRUTH}
    full = UnscentedKalman(**kw).fit(_structure(seamor), data)
    data["nu"][300, 0] = np.nan
    filt = UnscentedKalman(**kw)
    with pytest.warns(UserWarning, match="1 samples have no finite velocity of u"):
        est = filt.fit(_structure(seamor), data)
    np.testing.assert_allclose(est.theta, full.theta, rtol=0.02)
    # no innovation where no update was made: the first sample (ν starts from it) read 0
    innovation = filt.history_["innovation"]
    assert np.isnan(innovation[0]).all() and np.isnan(innovation[300, 0])
    assert np.isfinite(innovation[1:300]).all() and np.isfinite(innovation[300, 1])
    assert np.isfinite(est.stderr).all()


def test_an_underconfident_filter_says_its_standard_errors_are_conservative(seamor):
    """Process noise 100 times the model error: innovations at 0.18 of the predicted variance
    and s.e. 10-30 times those of the calibrated filter, reported as if fine."""
    data = _data(seamor, _surge_yaw(600), NOISY, seed=3)
    calibrated = UnscentedKalman(process_noise=CALIBRATED, theta0=0.5 * TRUTH).fit(
        _structure(seamor), data
    )
    with pytest.warns(UserWarning, match=r"innovations are 0\.\d+ of the variance.*conservative"):
        wide = UnscentedKalman(process_noise=100 * CALIBRATED, theta0=0.5 * TRUTH).fit(
            _structure(seamor), data
        )
    assert wide.sigma2 < 0.5 and (wide.stderr > 3 * calibrated.stderr).all()


def test_a_parameter_the_vehicle_file_leaves_out_gets_a_diffuse_prior(seamor):
    """X_u|u| absent from the vehicle file: its θ₀ was 0 and its prior σ min_std = 1e-3 (SI),
    a prior 1e6 times more precise than 60 s of data, so it stayed at ~0 (truth -61), lost its
    s.e. and the warning blamed excitation. Its prior σ is now the force scale of the log."""
    import warnings

    from nnid.trainers.least_squares import ExcitationWarning

    coef = dict(seamor.damping.coefficients)
    del coef["X:u*abs(u)"]
    damping = seamor.damping.model_copy(update={"coefficients": coef})
    absent = seamor.model_copy(update={"damping": damping})
    data = _data(seamor, _surge_yaw(600), NOISY, seed=3)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ExcitationWarning)
        est = UnscentedKalman(process_noise=CALIBRATED).fit(_structure(absent), data)
    assert abs(est.theta[1] - TRUTH[1]) < 0.05 * abs(TRUTH[1]), est.theta
    assert np.isfinite(est.stderr).all()
    from nnid.trainers.ukf import force_scale

    assert force_scale(_structure(absent), data)[1] > abs(TRUTH[1])  # wider than the truth


@pytest.mark.filterwarnings("ignore:the filter's innovations")
def test_a_prior_tighter_than_the_data_is_named_in_the_warning(seamor):
    """A prior σ the data cannot move was reported as if the input had not excited it."""
    from nnid.trainers.least_squares import ExcitationWarning

    data = _data(seamor, _surge_yaw(600), NOISY, seed=3)
    std = [1e-3, 1e-3, 1.0, 1.0]
    with pytest.warns(ExcitationWarning, match=r"theta0_std: X_udot 0\.001.*tighter than the data"):
        UnscentedKalman(process_noise=CALIBRATED, theta0=0.5 * TRUTH, theta0_std=std).fit(
            _structure(seamor), data
        )


def test_a_prior_of_the_wrong_length_is_refused_by_name(seamor):
    """A theta0 or theta0_std of three values for four unknowns ended in numpy's broadcast
    error, naming neither the option nor the unknowns."""
    from nnid.errors import NnidInputError

    data = _data(seamor, _surge_yaw(40), EXACT)
    for option, value in (("theta0", TRUTH[:3]), ("theta0_std", [1.0] * 5)):
        with pytest.raises(
            NnidInputError,
            match=rf"{option} has \d values; the structure has 4 "
            r"unknowns \(X_udot, X:u\*abs\(u\), N_rdot, N:r\*abs\(r\)\)",
        ) as err:
            UnscentedKalman(**{option: value}).fit(_structure(seamor), data)  # fmt: skip
        assert err.value.field == option


def _smoothed_surge(seamor):
    """A surge model and 400 samples whose surge velocity carries noise correlated over ten
    samples (a smoothed DVL) of σ 0.005 m/s."""
    structure = ParametricFossen(seamor, NAMES[:2], dofs=("u",))
    n = 400
    data = _data(seamor, _surge_yaw(n), EXACT)
    rng = np.random.default_rng(0)
    data["nu"][:, 0] += 0.005 * np.convolve(rng.normal(size=n + 9), np.ones(10) / np.sqrt(10),
                                            "valid")  # fmt: skip
    return structure, data


def test_correlated_innovations_widen_the_standard_errors_and_are_said(seamor):
    """Velocity noise correlated over ten samples (a smoothed DVL), declared at its σ: the
    filter takes its innovations as white, and X_udot ended 5.5 of its s.e. from the truth.
    Least squares widens each equation by its residuals' correlation time; the filter now
    widens its covariance by its standardised innovations' (8.0 samples here), and says so."""
    import warnings

    import nnid.trainers.ukf as ukf

    structure, data = _smoothed_surge(seamor)
    kw = {"process_noise": CALIBRATED, "theta0": 0.5 * TRUTH[:2], "measurement_noise": 0.005}
    filt = UnscentedKalman(**kw)
    with pytest.warns(UserWarning, match=r"innovations are correlated \(u [\d.]+ samples"):
        est = filt.fit(structure, data)
    hist = filt.history_
    tau = ukf.equation_times(hist["innovation"] / hist["innovation_std"], about_zero=True)[0]
    assert tau > 5.0
    assert np.all(np.abs(est.theta - TRUTH[:2]) < 3.0 * est.stderr), (est.theta, est.stderr)
    # the widening is τ on the filter's own covariance, its path's σ with it
    with pytest.MonkeyPatch.context() as patch, warnings.catch_warnings():
        warnings.simplefilter("error")  # white by decree: nothing to say
        patch.setattr(ukf, "equation_times", lambda r, **kw: np.ones(np.shape(r)[1]))
        raw = UnscentedKalman(**kw).fit(structure, data)
    np.testing.assert_allclose(est.cov, raw.cov * tau, rtol=1e-10)
    np.testing.assert_allclose(filt.history_["theta_std"][-1], est.stderr, rtol=1e-12)


def test_a_standard_error_the_widening_takes_past_half_the_prior_is_withheld(seamor):
    """A prior σ far tighter than the data move: the prior-led check judged the filter's P
    before its scaling by the innovations' size (3.7) and correlation time (70 samples), so
    X_udot and X:u*abs(u) at 0.16 and 0.21 of their prior σ passed as measured, then were
    reported at 2.6 and 3.4 times it. Judged on the covariance as reported, no standard error
    is at or above half its prior σ."""
    from nnid.trainers.least_squares import ExcitationWarning

    structure, data = _smoothed_surge(seamor)
    std = np.array([1.0, 1.0])
    kw = {"process_noise": CALIBRATED, "theta0": 0.5 * TRUTH[:2], "measurement_noise": 0.005}
    with pytest.warns(ExcitationWarning, match="did not inform X_udot, X:u"):
        est = UnscentedKalman(**kw, theta0_std=std).fit(structure, data)
    assert not np.any(est.stderr >= 0.5 * std), est.stderr


def test_the_noise_settings_are_per_second_so_the_sampling_rate_keeps_the_standard_errors(seamor):
    """One 30-s surge dive logged at 10 and 50 Hz by a DVL of one noise density (σ per sample
    √5 times larger at 50 Hz, so both logs hold the same information): with the process and
    parameter noise per step, the 50-Hz log walked 5 times as far per second and its s.e. were
    1.7-1.8 times the 10-Hz log's; per √s they agree within 10 % (1 % here)."""
    structure = ParametricFossen(seamor, NAMES[:2], dofs=("u",))
    rng = np.random.default_rng(1)
    levels = np.repeat(rng.uniform(-15.0, 15.0, 10), 30)  # 3-s surge levels on a 0.1-s grid
    stderr = []
    for hz in (10, 50):
        inputs = np.zeros((levels.size * hz // 10, 6))
        inputs[:, 0] = np.repeat(levels, hz // 10)
        sigma = 0.005 * np.sqrt(hz / 10)
        sensor = Measurement(kind="dvl_imu", velocity_noise=sigma)
        data = log_arrays(simulate(seamor, inputs, 1.0 / hz, measurement=sensor, seed=3), seamor)
        est = UnscentedKalman(
            process_noise=CALIBRATED,
            parameter_noise=CALIBRATED,
            measurement_noise=sigma,
            theta0=0.5 * TRUTH[:2],
        ).fit(structure, data)
        stderr.append(est.stderr)
    ratio = stderr[1] / stderr[0]
    assert np.all(np.abs(ratio - 1.0) < 0.1), ratio


def _pushed(seamor, seed: int, push: float) -> dict[str, np.ndarray]:
    """400 samples of a surge run with an unlogged constant surge force ``push`` (N)."""
    inputs = _surge_yaw(400, seed) * [1, 0, 0, 0, 0, 0]
    inputs[:, 0] += push
    data = _data(seamor, inputs, NOISY, seed=seed)
    data["tau"][:, 0] -= push
    return data


def test_the_innovations_correlation_time_is_read_per_experiment(seamor):
    """Two runs, each with an unlogged constant surge force (a model error) that offsets its
    innovations. Read over the two runs concatenated, the offsets' jump between them entered
    the autocorrelation: the second run's force of the opposite sign read τ 134 samples, of
    the same sign 49. Per experiment, pooled and about zero (the filter's innovations are
    zero-mean: a run's offset is a model error correlated over the run), 218 and 208: the
    sign of one run's force against the other's does not count."""
    import warnings

    structure = ParametricFossen(seamor, NAMES[:2], dofs=("u",))
    first = _pushed(seamor, 1, 0.5)
    times = []
    for push in (0.5, -0.5):
        second = _pushed(seamor, 2, push)
        data = {k: np.concatenate([v, second[k]]) if np.shape(v)[:1] == (400,) else v
                for k, v in first.items()}  # fmt: skip
        data["experiment"] = np.repeat([0, 1], 400)
        filt = UnscentedKalman(
            process_noise=CALIBRATED, measurement_noise=0.005, theta0=0.5 * TRUTH[:2]
        )
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            filt.fit(structure, data)
        widened = [str(w.message) for w in said if "correlated (u " in str(w.message)]
        assert len(widened) == 1
        times.append(float(widened[0].split("correlated (u ")[1].split(" ")[0]))
    assert max(times) < 1.5 * min(times), times


def test_a_covariance_losing_definiteness_gets_a_jitter_relative_to_each_variance():
    """A velocity variance of 1e-10 (m/s)² beside a singular parameter block of 1e4 kg²: the
    jitter, scaled by the largest variance, added 1e-8 to every one and made the velocity's
    101 times what it was. Relative to each variance it keeps each to 1e-9, and says it."""
    from nnid.trainers.ukf import _cholesky

    p = np.diag([1e-10, 0.0, 0.0]) + np.outer([0.0, 100.0, 100.0], [0.0, 100.0, 100.0])
    chol, jitter = _cholesky(p)
    np.testing.assert_allclose(np.diag(chol @ chol.T), np.diag(p), rtol=1e-9)
    assert 0 < jitter < 1e-9
    held = np.diag([1e-10, 0.0, 4.0])  # a parameter a zero prior σ holds: no jitter needed
    chol, jitter = _cholesky(held)
    np.testing.assert_allclose(chol @ chol.T, held, rtol=1e-15, atol=0.0)
    assert jitter == 0.0


def test_a_fit_whose_covariance_needed_jitter_says_so_once(seamor):
    """The jitter was added without a word; a fit that needed it at every prediction says so
    once, with the count."""
    import nnid.trainers.ukf as ukf

    data = _data(seamor, _surge_yaw(40), EXACT)
    cholesky, calls = np.linalg.cholesky, []

    def definite_only_with_jitter(a):  # refuses every first try: a P that needs jitter
        calls.append(a)
        if len(calls) % 2:
            raise np.linalg.LinAlgError("not positive definite")
        return cholesky(a)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(ukf.np.linalg, "cholesky", definite_only_with_jitter)
        with pytest.warns(UserWarning) as said:
            UnscentedKalman(measurement_noise=[0.005, 0.002], theta0=0.5 * TRUTH).fit(
                _structure(seamor), data
            )
    jittered = [w for w in said if "lost positive definiteness" in str(w.message)]
    assert len(jittered) == 1 and "at 39 of 39 predictions" in str(jittered[0].message)
