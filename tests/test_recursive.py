"""Recursive estimators (Weiss eqs 52-53 and 62-70) on simulated Seamor data."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.arrays import log_arrays
from nnid.datasets.excitation import PRBS, Multisine
from nnid.datasets.log import POSE, VELOCITY
from nnid.datasets.simulator import simulate
from nnid.errors import NnidInputError
from nnid.models.parametric import ParametricFossen, ParametricModel
from nnid.trainers.least_squares import ExcitationWarning, LeastSquares
from nnid.trainers.recursive import GradientEstimator, RecursiveLeastSquares
from nnid.trainers.regression import Regression
from nnid.vehicle import load_vehicle

DT = 0.05  # 20 Hz
SURGE = ["X_udot", "X:u*abs(u)"]
X_UDOT, X_UU = -27.08, -61.117  # seamor preset (Weiss Table 3)


@pytest.fixture(scope="module")
def seamor():
    return load_vehicle("seamor")


def _surge_force(t: np.ndarray) -> np.ndarray:
    """15 N offset plus a 15 N multisine on 0.02-0.5 Hz: persistently exciting, u > 0."""
    wave = Multisine(channel="X", amplitude=15.0, f_min=0.02, f_max=0.5, n=8, duration=1e6)
    return 15.0 + wave(t)


def _surge_log(vehicle, t0: float, seconds: float, effects=(), x0=None) -> pd.DataFrame:
    t = t0 + np.arange(round(seconds / DT) + 1) * DT
    inputs = np.zeros((t.size, 6))
    inputs[:, 0] = _surge_force(t)
    log = simulate(vehicle, inputs, DT, effects=effects, x0=x0)
    log["t"] += t0
    return log


def _noisy(log: pd.DataFrame, sigma: float, seed: int = 0) -> pd.DataFrame:
    """White noise of ``sigma`` on the measured u (m/s) and du (m/s²): the regressor inputs."""
    rng = np.random.default_rng(seed)
    out = log.copy()
    out["u"] += rng.normal(0.0, sigma, len(out))
    out["du"] += rng.normal(0.0, sigma, len(out))
    return out


def _surge_regression(vehicle, log: pd.DataFrame) -> Regression:
    return ParametricFossen(vehicle, SURGE, dofs=("u",)).regression(log_arrays(log, vehicle))


def _block_rls(phi, y, m, lam, p0):
    """NumPy reference: one vector update per sample, K = PΦᵀ(λI + ΦPΦᵀ)⁻¹, P = (P − KΦP)/λ."""
    p_mat = np.eye(phi.shape[1]) * p0
    theta = np.zeros(phi.shape[1])
    for i in range(phi.shape[0] // m):
        f, yi = phi[i * m : (i + 1) * m], y[i * m : (i + 1) * m]
        gain = np.linalg.solve(lam * np.eye(m) + f @ p_mat @ f.T, f @ p_mat).T
        theta = theta + gain @ (yi - f @ theta)
        p_mat = (p_mat - gain @ f @ p_mat) / lam
    return theta, p_mat


def test_row_by_row_equals_block_update(rng):
    """Rows one at a time with forgetting once per sample = the per-sample vector update."""
    n, m, p = 400, 3, 5
    phi = rng.normal(size=(n * m, p))
    y = phi @ rng.normal(size=p) + 0.1 * rng.normal(size=n * m)
    reg = Regression(phi, y, [f"t{k}" for k in range(p)], ("u", "v", "w"), n)
    rls = RecursiveLeastSquares(forgetting=0.98, p0=100.0)
    est = rls.solve(reg)
    theta, p_mat = _block_rls(phi, y, m, 0.98, 100.0)
    np.testing.assert_allclose(est.theta, theta, rtol=1e-9)
    np.testing.assert_allclose(rls.p_matrix_, p_mat, rtol=1e-6, atol=1e-9)
    assert est.history.shape == (n, p)
    np.testing.assert_array_equal(est.history[-1], est.theta)


def test_rls_converges_to_batch_least_squares(seamor):
    """(a) λ = 1, noise-free 6-DOF data, 12 unknowns, 6 rows per sample: RLS = batch LS
    (up to the prior P₀⁻¹ = 10⁻⁶ I, measured 3e-7 relative)."""
    t = np.arange(round(60.0 / DT)) * DT
    amp = [20.0, 20.0, 20.0, 10.0, 10.0, 1.0]
    inputs = np.stack(
        [PRBS(channel="X", amplitude=a, hold=1.0, duration=1e6, seed=k + 1)(t) for k, a in
         enumerate(amp)], 1)  # fmt: skip
    log = simulate(seamor, inputs, DT)
    unknowns = [*seamor.added_mass, *seamor.damping.coefficients]
    assert len(unknowns) == 12
    reg = ParametricFossen(seamor, unknowns).regression(log_arrays(log, seamor))
    batch = LeastSquares(weighting="none", correlated=False).solve(reg)
    rls = RecursiveLeastSquares().solve(reg)
    np.testing.assert_allclose(rls.theta, batch.theta, rtol=1e-6)
    truth = [seamor.added_mass[k] for k in seamor.added_mass]
    truth += [seamor.damping.coefficients[k] for k in seamor.damping.coefficients]
    np.testing.assert_allclose(rls.theta, truth, rtol=1e-4)
    assert rls.history.shape == (reg.n_samples, 12)
    # with DVL and gyro noise: RLS is the unweighted estimator, so by Gauss-Markov it is
    # never more precise than batch least squares with each equation weighted by its own
    # residual variance (its s.e. were once taken as equal: too small for N_rdot, 0.5 of the
    # spread); σ̂² P pooled forces and moments and took every row as independent
    from nnid.datasets.measurement import Measurement
    from nnid.datasets.preprocess import derive_accelerations

    noisy = simulate(seamor, inputs, DT, measurement=Measurement(kind="dvl_imu"), seed=3)
    reg = ParametricFossen(seamor, unknowns).regression(
        log_arrays(derive_accelerations(noisy, 1.0, 4), seamor)
    )
    ls, rls = LeastSquares().solve(reg), RecursiveLeastSquares().solve(reg)
    assert (rls.stderr >= 0.98 * ls.stderr).all(), rls.stderr / ls.stderr
    assert (rls.stderr < 3 * ls.stderr).all(), rls.stderr / ls.stderr
    pooled = RecursiveLeastSquares().solve(reg)
    assert not np.allclose(rls.stderr, np.sqrt(pooled.sigma2 * np.diag(
        np.linalg.inv(reg.phi.T @ reg.phi))), rtol=0.5)  # fmt: skip


def test_rls_tracks_a_payload_change(seamor):
    """(b) X_u|u| grows by 50 % after 60 s; RLS with a 4 s memory (λ = 1 − Δt/4 s = 0.9875,
    1/(1 − λ) = 80 samples) is within 5 % of the new value within 20 s of data, and stays."""
    first = _surge_log(seamor, 0.0, 60.0)
    x0 = first[list(POSE) + list(VELOCITY)].iloc[-1].to_numpy()
    delta = 0.5 * X_UU
    second = _surge_log(seamor, 60.0, 60.0, effects=[("quadratic_damping.u", delta)], x0=x0)
    log = _noisy(pd.concat([first.iloc[:-1], second], ignore_index=True), 0.005)
    reg = _surge_regression(seamor, log)
    rls = RecursiveLeastSquares(forgetting=1.0 - DT / 4.0)
    assert rls.memory == pytest.approx(80.0)
    h = rls.solve(reg).history[:, 1]
    change = round(60.0 / DT)
    before = np.abs(h[change - round(20.0 / DT) : change] / X_UU - 1.0)
    assert before.max() < 0.05  # it had the old value
    after = np.abs(h[change:] / (X_UU + delta) - 1.0)
    outside = np.flatnonzero(after > 0.05)
    tracked_after = (outside[-1] + 1) * DT if outside.size else 0.0
    assert tracked_after <= 20.0, tracked_after  # measured 9.85 s
    # a memory too long for the requirement fails it: the test can tell
    slow = RecursiveLeastSquares(forgetting=1.0 - DT / 8.0).solve(reg).history[change:, 1]
    assert np.abs(slow / (X_UU + delta) - 1.0)[round(20.0 / DT) - 1] > 0.05


def test_gradient_estimator_noise_sensitivity(seamor):
    """(c) Weiss ch. VI.C, eqs 69-70: noise on the regressor inputs makes the gradient
    estimator's parameters jitter (std over the last 20 s grows with the noise level) and
    leaves it farther from the truth after 30 s than RLS on the same data."""
    log = _surge_log(seamor, 0.0, 60.0)
    truth = np.array([X_UDOT, X_UU])
    k30, last = round(30.0 / DT) - 1, round(20.0 / DT)
    spread, ge_err, rls_err = [], [], []
    for sigma in (0.0, 0.002, 0.005, 0.01):
        reg = _surge_regression(seamor, _noisy(log, sigma))
        ge = GradientEstimator(gain=50.0).solve(reg, dt=DT)
        rls = RecursiveLeastSquares().solve(reg)
        spread.append(ge.history[-last:].std(0))
        ge_err.append(np.abs(ge.history[k30] / truth - 1.0))
        rls_err.append(np.abs(rls.history[k30] / truth - 1.0))
    spread, ge_err, rls_err = np.array(spread), np.array(ge_err), np.array(rls_err)
    assert (np.diff(spread, axis=0) > 0).all(), spread  # both parameters, every step
    assert spread[-1].min() > 100 * spread[0].max()
    assert (np.linalg.norm(ge_err, axis=1) > np.linalg.norm(rls_err, axis=1)).all()
    assert (ge_err[:, 1] > rls_err[:, 1]).all(), (ge_err, rls_err)  # X_u|u|
    assert ge_err[0].max() < 0.01  # noise-free it does converge, slower than RLS


def test_parametric_model_with_rls(seamor):
    """(d) ParametricModel(..., trainer=RecursiveLeastSquares()).fit(log) end to end."""
    log = _surge_log(seamor, 0.0, 30.0)
    model = ParametricModel(
        seamor, SURGE, dofs=("u",), trainer=RecursiveLeastSquares(forgetting=0.999)
    ).fit(log)
    assert model.params["X_udot"]["value"] == pytest.approx(X_UDOT, rel=1e-6)
    assert model.params["X:u*abs(u)"]["value"] == pytest.approx(X_UU, rel=1e-6)
    assert model.estimate_.history.shape == (len(log), 2)
    assert np.isfinite(model.estimate_.stderr).all()  # RLS reports LS's covariance over its memory
    # the gradient law has no covariance: said, not left to a column of None
    with pytest.warns(UserWarning, match="gives no standard errors"):
        gradient = ParametricModel(
            seamor, SURGE, dofs=("u",), trainer=GradientEstimator(gain=50.0)
        ).fit(log)
    assert gradient.params["X:u*abs(u)"]["stderr"] is None
    assert gradient.estimate_.history.shape == (len(log), 2)
    assert gradient.params["X:u*abs(u)"]["value"] == pytest.approx(X_UU, rel=0.01)


def test_filtered_regressors_and_bad_arguments(seamor):
    """filter_lambda (Weiss eqs 85-92) needs no accelerations; arguments are checked."""
    log = _surge_log(seamor, 0.0, 30.0).drop(columns=["du"])
    model = ParametricModel(
        seamor, SURGE, dofs=("u",), trainer=RecursiveLeastSquares(filter_lambda=2.0)
    ).fit(log)
    assert model.params["X:u*abs(u)"]["value"] == pytest.approx(X_UU, rel=0.01)
    assert model.estimate_.history.shape[0] < len(log)  # the settling time is left out
    with pytest.raises(NnidInputError, match=r"forgetting must be in \(0, 1\]") as err:
        RecursiveLeastSquares(forgetting=1.5).solve(_surge_regression(seamor, log.assign(du=0)))
    assert err.value.field == "forgetting"
    # two parameters (X_udot, X:u*abs(u)): a gain of three is none of the shapes it may take
    with pytest.raises(NnidInputError, match=r"gain must be a scalar, \[2\] or \[2, 2\]") as err:
        GradientEstimator(gain=[1.0, 2.0, 3.0]).solve(_surge_regression(seamor, log.assign(du=0)))
    assert err.value.field == "gain"
    with pytest.warns(RuntimeWarning, match="diverged"):
        GradientEstimator(gain=1e6).solve(_surge_regression(seamor, _surge_log(seamor, 0, 5)))


@pytest.mark.parametrize(
    ("gain", "said"),
    [([[1.0, 2.0], [3.0]], "square: 2 rows, so 2 numbers in each"),  # numpy's own error
     ([1.0, [2.0, 3.0]], "square"),
     (np.array([[1.0, 2.0], [0.0, 1.0]]), "symmetric"),
     ([[-1.0, 0.0], [0.0, -1.0]], "positive definite"),  # it climbed the error, unsaid
     # a scalar or vector of 0 or below ran from Python (θ stood still, or climbed)
     (0.0, "a gain is a finite number above 0"),
     (-50.0, "a gain is a finite number above 0"),
     ([1.0, -2.0], r"each number of a gain vector \(Γ's diagonal\) is a finite .* 0, not -2"),
     (np.array([0.0, 1.0]), "each number of a gain vector"),
     (np.inf, "a gain is a finite number above 0")],
)  # fmt: skip
def test_a_gain_given_from_python_is_checked_as_a_configs(rng, gain, said):
    from nnid.config import GradientSpec

    reg = Regression(rng.normal(size=(20, 2)), rng.normal(size=20), ["a", "b"], ("u",), 20)
    with pytest.raises(NnidInputError, match=said) as err:
        GradientEstimator(gain=gain).solve(reg)
    assert err.value.field == "gain"
    # what a TOML file can hold (a config refuses inf, and a mixed list, by their types)
    rows = isinstance(gain, list) and all(isinstance(row, list) for row in gain)
    numbers = isinstance(gain, list) and all(isinstance(x, float) for x in gain)
    if rows or numbers or (isinstance(gain, float) and np.isfinite(gain)):
        with pytest.raises(ValueError, match=said):  # a config's gain: the same words
            GradientSpec(kind="gradient", gain=gain)


def test_a_gradient_estimator_still_moving_at_the_end_of_the_data_says_so(seamor):
    """A gain far too small for 30 s of data leaves the estimates drifting toward the truth
    when the log ends; they were reported as estimates without a word. Gain 50 converges and
    is silent."""
    import warnings

    reg = _surge_regression(seamor, _surge_log(seamor, 0.0, 30.0))
    with pytest.warns(UserWarning, match=r"has not converged: X_udot, X:u\*abs\(u\)"):
        GradientEstimator(gain=0.05).solve(reg, dt=DT)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        GradientEstimator(gain=50.0).solve(reg, dt=DT)
    assert not [w for w in caught if "has not converged" in str(w.message)]


def _two_regressors(n: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    phi = rng.normal(size=(n, 2))
    return phi, rng.normal(scale=0.5, size=n)


def test_rls_gives_no_standard_error_to_what_its_memory_does_not_determine():
    """Batch least squares' excitation check over the estimator's memory. b unexcited in the
    last half (λ = 0.99: a 100-sample memory): its θ is remembered from earlier, and its s.e.
    read 0.0 ("significant" at 0 %); a collinear pair read ±0.002, both "significant"."""
    phi, noise = _two_regressors()
    phi[1000:, 1] = 0.0
    y = phi @ np.array([2.0, -3.0]) + noise
    reg = Regression(phi, y, ["a", "b"], ("u",), y.size)
    with pytest.warns(ExcitationWarning, match=r"last 100 samples.*not excited.*: b"):
        est = RecursiveLeastSquares(forgetting=0.99).solve(reg)
    assert est.theta[1] == pytest.approx(-3.0, abs=0.2)  # remembered, and kept
    assert np.isnan(est.stderr[1]) and not est.significant[1]
    # the verdict is kept with the estimate, as batch least squares keeps its own (it was
    # said in a warning only: the tables read b's missing s.e. as a plain "no")
    assert est.excitation.unexcited == ["b"] and est.as_dict()["b"]["excited"] is False
    # a's s.e. is least squares' over the memory alone, by hand: the last 1/(1 − λ) = 100
    # samples, the noise's mean square over n − p there, over Σ φ_a² (b's column is zero
    # there). A memory off by 2x (50 or 200 samples) is off by √2 (0.069 or 0.035)
    window = round(1 / (1 - 0.99))
    a, e = phi[-window:, 0], noise[-window:]
    by_hand = np.sqrt(np.sum(e**2) / (window - 2) / np.sum(a**2))
    assert est.stderr[0] == pytest.approx(by_hand, rel=0.05) and est.significant[0]
    phi2 = np.repeat(phi[:, :1], 2, axis=1) * [1.0, 2.0]
    y2 = phi2 @ np.array([2.0, -3.0]) + noise
    reg2 = Regression(phi2, y2, ["a", "b"], ("u",), y2.size)
    with pytest.warns(ExcitationWarning, match="collinear regressors"):
        est = RecursiveLeastSquares().solve(reg2)
    assert np.isnan(est.stderr).all() and not est.significant.any()
    assert est.excitation.collinear == ["a", "b"] and est.as_dict()["a"]["collinear"]


def test_rls_memory_warning_words_match_the_case():
    """The memory's excitation warning said of every case "nor the value of one that no sample
    of the run excited: it never left theta0", also when the parameters were only collinear
    (each has a value) or excited before the memory (its value is remembered)."""
    phi, noise = _two_regressors(400)
    pair = np.repeat(phi[:, :1], 2, axis=1) * [1.0, 2.0]
    reg = Regression(pair, pair @ [2.0, -3.0] + noise, ["a", "b"], ("u",), noise.size)
    with pytest.warns(ExcitationWarning, match="collinear regressors") as caught:
        RecursiveLeastSquares().solve(reg)
    assert "theta0" not in str(caught[0].message) and "no sample" not in str(caught[0].message)
    phi[200:, 1] = 0.0  # b unexcited over the last 100 samples only: remembered
    reg = Regression(phi, phi @ [2.0, -3.0] + noise, ["a", "b"], ("u",), noise.size)
    with pytest.warns(ExcitationWarning, match=r"value remembered from earlier .*: b") as caught:
        RecursiveLeastSquares(forgetting=0.99).solve(reg)
    assert "theta0" not in str(caught[0].message)
    phi[:, 1] = 0.0  # b never excited: it never left theta0
    reg = Regression(phi, phi @ [2.0, -3.0] + noise, ["a", "b"], ("u",), noise.size)
    with pytest.warns(
        ExcitationWarning, match="value of b is not given: no sample .* never left theta0"
    ):
        RecursiveLeastSquares().solve(reg)


def _remembered_and_never(n: int = 400):
    """Three parameters, λ = 0.99 (a 100-sample memory): "X:u" excited throughout, "X:v"
    excited in the first half only (unexcited in the memory: its value is remembered), "X:w"
    never excited (NaN). Returns the estimate and the warnings' text."""
    phi, noise = _two_regressors(n)
    phi = np.c_[phi, np.zeros(n)]
    phi[n // 2 :, 1] = 0.0
    reg = Regression(phi, phi @ [2.0, -3.0, 1.0] + noise, ["X:u", "X:v", "X:w"], ("u",), n)
    with pytest.warns(ExcitationWarning) as caught:
        est = RecursiveLeastSquares(forgetting=0.99).solve(reg)
    return est, " | ".join(str(w.message) for w in caught)


def test_rls_says_a_value_learnt_before_its_memory_remembered_not_fitted_to_noise():
    """A parameter excited in the first half of a run and zero over the memory keeps the
    value learnt from the excited samples (-3.0), yet the estimate's verdict was a plain
    "excited": False, so the table's cell said "not excited", the Prime-system section "not
    excited by the data: fitted to noise" and the report's warning "zero regressor": false of
    a value learnt from excited data. A parameter no sample of the run excited keeps those."""
    from nnid.evaluation.persistence import REMEMBERED
    from nnid.pipeline import _nondimensional
    from nnid.reports.train_report import PRIME_NOT_EXCITED, _prime, _significance

    est, said = _remembered_and_never()
    assert est.theta[1] == pytest.approx(-3.0, abs=0.2) and np.isnan(est.theta[2])
    params = est.as_dict()
    assert params["X:v"]["excited"] is False and params["X:v"]["remembered"] is True
    assert params["X:w"]["excited"] is False and "remembered" not in params["X:w"]
    assert _significance(params["X:v"]) == REMEMBERED
    assert _significance(params["X:w"]) == "not excited"  # never excited: unchanged
    assert f"{REMEMBERED}: X:v" in said and "zero regressor): X:w" in said
    assert "zero regressor): X:v" not in said and "X:v, X:w" not in said
    _, items = _prime({"nondimensional": _nondimensional(params, load_vehicle("seamor"), 1.0)})
    prime = dict(items)
    assert "remembered from earlier samples" in prime["X:v'"]
    assert PRIME_NOT_EXCITED not in prime["X:v'"]  # X:w has no value: no Prime line


def test_rls_says_a_pair_collinear_over_its_run_collinear_not_remembered():
    """Two identical columns excited in the first half only, λ = 0.99: earlier samples fixed
    only their sum (-2), yet both were said "value remembered from earlier samples", with no
    word of collinearity, beside a split (-1.0, -1.0) no data chose. Collinear over the run,
    they keep that verdict."""
    from nnid.reports.train_report import _significance

    rng = np.random.default_rng(0)
    n = 400
    a, b = rng.normal(size=n), rng.normal(size=n)
    phi = np.c_[a, b, b]
    phi[n // 2 :, 1:] = 0.0
    y = phi @ [2.0, -3.0, 1.0] + 0.01 * rng.normal(size=n)
    reg = Regression(phi, y, ["X:u", "X:v", "X:w"], ("u",), n)
    with pytest.warns(ExcitationWarning, match=r"collinear regressors\): X:v, X:w") as caught:
        est = RecursiveLeastSquares(forgetting=0.99).solve(reg)
    assert est.excitation.remembered == [] and est.excitation.collinear == ["X:v", "X:w"]
    assert not any("remembered" in str(w.message) for w in caught)
    assert est.theta[1] + est.theta[2] == pytest.approx(-2.0, abs=0.01)
    params = est.as_dict()
    assert [_significance(params[k]) for k in ("X:v", "X:w")] == ["collinear"] * 2


def test_the_remembered_verdict_survives_saving_and_every_rebuilt_report():
    """The estimate saved and read back, renamed (Caccia's signs) or joined with others (a
    sequence's steps) says "remembered" as the fit did; a file saved before the verdict was
    kept reads as before (unexcited, said in its saved warnings)."""
    import json

    from nnid.evaluation.persistence import REMEMBERED, ExcitationReport, combined_excitation
    from nnid.serialization import dumps
    from nnid.trainers.least_squares import Estimate

    est, _ = _remembered_and_never()
    saved = json.loads(dumps(est.as_state()))
    back = Estimate.from_state(saved)
    assert back.as_dict()["X:v"].get("remembered") is True
    report = est.excitation
    renamed = report.renamed({"X:v": "Y:v"})
    union = combined_excitation([(est.names, report)], est.names)
    for rebuilt, name in ((back.excitation, "X:v"), (renamed, "Y:v"), (union, "X:v")):
        assert rebuilt.remembered == [name] and f"{REMEMBERED}: {name}" in rebuilt.warnings
    older = {k: v for k, v in saved["excitation"].items() if k != "remembered"}
    old = ExcitationReport.from_state(older)
    assert old.remembered == [] and old.unexcited == report.unexcited
    assert old.warnings == report.warnings  # its own words, as saved


def test_a_model_that_judges_the_run_noise_says_fitted_to_noise_not_remembered():
    """The model's own check (its velocities within their noise over the whole fit data,
    ``not_excited_``) outranks the recursive estimator's "remembered": whatever the samples
    before the memory read, the run's motion was noise, and its table says "not excited"."""
    from nnid.reports.train_report import _significance

    est, _ = _remembered_and_never()
    model = ParametricModel(load_vehicle("seamor"), ["X:u", "X:v", "X:w"])
    model.estimate_, model.from_file_ = est, {}
    model.not_excited_ = {"X:v": ["v"]}
    params = model._params()
    assert "remembered" not in params["X:v"] and _significance(params["X:v"]) == "not excited"
    model.not_excited_ = {}
    assert model._params()["X:v"]["remembered"] is True


def test_a_model_that_judges_the_run_noise_says_so_in_its_excitation_report_too():
    """Where the model's own check overrode "remembered", its table said fitted to noise but
    the excitation report it saves (its ``remembered`` and its warnings) still said
    remembered. The report now drops it too, as the fit and a loaded file set it."""
    from nnid.evaluation.persistence import REMEMBERED

    est, _ = _remembered_and_never()
    model = ParametricModel(load_vehicle("seamor"), ["X:u", "X:v", "X:w"])
    model.not_excited_ = {"X:v": ["v"]}
    report = model._noise_judged(est).excitation
    assert report.remembered == [] and report.unexcited == ["X:v", "X:w"]
    assert not any(REMEMBERED in w for w in report.warnings)
    assert "not excited by this data (zero regressor): X:v, X:w" in report.warnings
    model.not_excited_ = {}
    assert model._noise_judged(est) is est


def test_rls_that_has_not_converged_says_so():
    """p₀ = 1e-5: the recursion barely moves from zero (a = 0.04 against 2.0) and reported
    ±0.08, 24 standard errors from the truth, without a word."""
    phi, noise = _two_regressors()
    y = phi @ np.array([2.0, -3.0]) + noise
    reg = Regression(phi, y, ["a", "b"], ("u",), y.size)
    with pytest.warns(UserWarning, match="has not converged: a, b still moved"):
        est = RecursiveLeastSquares(p0=1e-5).solve(reg)
    assert abs(est.theta[0]) < 0.5 and np.isnan(est.stderr).all()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the default p0 converges: nothing to say
        est = RecursiveLeastSquares().solve(reg)
    assert est.theta == pytest.approx([2.0, -3.0], abs=0.05) and np.isfinite(est.stderr).all()
    # a parameter whose truth is 0 ends near 0, where any last change is a large part of it:
    # judged against its standard error, it is settled (it lost its s.e. and was "moving")
    zero = Regression(np.c_[phi, phi[::-1, 0]], y, ["a", "b", "c"], ("u",), y.size)
    for forgetting in (1.0, 0.99):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            est = RecursiveLeastSquares(forgetting=forgetting).solve(zero)
        assert np.isfinite(est.stderr).all() and abs(est.theta[2]) < 4 * est.stderr[2]
        # that s.e. bounded by hand: least squares' σ √[(ΦᵀΦ)⁻¹]_cc over the memory (the
        # whole run, or its last 1/(1 − λ) = 100 samples) with the noise's σ = 0.5
        window = y.size if forgetting == 1.0 else round(1 / (1 - forgetting))
        rows = zero.phi[-window:]
        by_hand = 0.5 * np.sqrt(np.linalg.inv(rows.T @ rows)[2, 2])
        assert est.stderr[2] < 1.5 * by_hand, (forgetting, est.stderr[2], by_hand)


def test_rls_standard_errors_cover_the_spread_of_its_estimates():
    """RLS (no forgetting) estimates the window's unweighted least squares; it reported the
    covariance of the per-DOF weighted estimator, which on 20 Seamor logs was 0.6 of the
    estimates' spread for X_udot (0.5 for N_rdot on Weiss's whole table). The sandwich of the
    unweighted estimator is never smaller than the spread (conservative by the residuals'
    correlation time)."""
    from nnid.loop.scenarios import effect_log
    from nnid.trainers.recursive import RecursiveLeastSquares
    from nnid.vehicle import load_vehicle

    vehicle = load_vehicle("seamor")
    names = ["X_udot", "X:u*abs(u)", "N_rdot", "N:r*abs(r)"]
    est, se = [], []
    for seed in range(20):
        log = effect_log(vehicle, duration=60, n_experiments=1, dt=0.05, seed=100 + seed)
        trainer = RecursiveLeastSquares()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            model = ParametricModel(vehicle, names, dofs=["u", "r"], trainer=trainer)
            model.set_params(zoh_midpoint=True).fit(log)
        est.append([model.params[n]["value"] for n in names])
        se.append([model.params[n]["stderr"] for n in names])
    ratio = np.mean(se, 0) / np.std(est, 0, ddof=1)
    assert (ratio > 0.9).all(), dict(zip(names, ratio.round(2), strict=True))


def test_rls_counts_only_the_rows_it_used_and_reports_no_value_for_what_it_never_saw():
    """The batch least-squares oracle on the same regression (λ = 1: the same estimator).
    Half the rows undefined (NaN target): the recursion skipped them, but σ̂², its per-DOF
    variance and n_obs counted them as zero residuals (σ̂² half the batch value, n_obs 2000
    for 1000 rows used). A regressor that is zero throughout left its parameter at theta0 and
    reported the value 0.0 (batch least squares: NaN)."""
    phi, noise = _two_regressors()
    y = phi @ np.array([2.0, -3.0]) + noise
    y[::2] = np.nan
    reg = Regression(phi, y, ["a", "b"], ("u",), y.size)
    rls = RecursiveLeastSquares().solve(reg)
    batch = LeastSquares(weighting="none").solve(reg)
    np.testing.assert_allclose(rls.theta, batch.theta, rtol=1e-6)
    assert rls.n_obs == batch.n_obs == 1000
    assert rls.sigma2 == pytest.approx(batch.sigma2, rel=1e-6)
    assert rls.dof_sigma2["u"] == pytest.approx(batch.dof_sigma2["u"], rel=0.01)
    phi[:, 1] = 0.0
    y = phi @ np.array([2.0, -3.0]) + noise
    reg = Regression(phi, y, ["a", "b"], ("u",), y.size)
    with pytest.warns(ExcitationWarning, match="not excited.*: b"):
        rls = RecursiveLeastSquares(theta0=np.array([0.0, 5.0])).solve(reg)
    with pytest.warns(ExcitationWarning, match="not excited.*: b"):
        batch = LeastSquares(weighting="none").solve(reg)
    assert np.isnan(rls.theta[1]) and np.isnan(batch.theta[1])
    assert rls.as_dict()["b"]["value"] is None
    assert rls.theta[0] == pytest.approx(batch.theta[0], rel=1e-6)
    assert rls.sigma2 == pytest.approx(batch.sigma2, rel=1e-6)


def test_rls_per_dof_variance_is_batch_least_squares_one():
    """Each DOF equation's residual variance, as batch least squares reports it
    (:func:`dof_variances`: centred, over n). RLS had its own, uncentred over n − 1: on a
    surge equation whose residual keeps a 0.3 N offset (a missing bias term) it read
    0.34 N² where batch least squares read 0.24 N²."""
    phi, noise = _two_regressors()
    n = phi.shape[0]
    rows = np.zeros((2 * n, 2))
    rows[0::2, 0], rows[1::2, 1] = phi[:, 0], phi[:, 1]
    y = np.empty(2 * n)
    y[0::2] = 2.0 * phi[:, 0] + noise + 0.3
    y[1::2] = -3.0 * phi[:, 1] + 10.0 * noise[::-1]
    reg = Regression(rows, y, ["a", "b"], ("u", "r"), n)
    rls = RecursiveLeastSquares().solve(reg)
    batch = LeastSquares(weighting="none").solve(reg)
    np.testing.assert_allclose(rls.theta, batch.theta, rtol=1e-6)
    for d in ("u", "r"):
        assert rls.dof_sigma2[d] == pytest.approx(batch.dof_sigma2[d], rel=1e-6), d


def test_dof_variances_of_an_equation_without_samples_is_nan_without_a_warning():
    """An equation with no finite residual: NaN, as RLS gave it, not numpy's "Degrees of
    freedom <= 0" RuntimeWarning."""
    from nnid.trainers.least_squares import dof_variances

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        var = dof_variances([np.array([np.nan, np.nan]), np.array([1.0, 3.0])])
    assert np.isnan(var[0]) and var[1] == 1.0


def test_dof_variances_read_finite_samples_only():
    """A row with an infinite regressor gives its equation an infinite residual: nanvar read
    it as a sample, the equation's variance came out NaN, and feasible weighting gave it the
    heaviest weight allowed. Finite samples only, as for NaN; an equation of infinities only
    has none (NaN)."""
    from nnid.trainers.least_squares import dof_variances

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        var = dof_variances(np.array([[1.0, np.inf], [np.inf, -np.inf], [3.0, np.nan]]))
    assert var[0] == 1.0 and np.isnan(var[1])


def test_rls_says_not_measured_of_a_parameter_only_its_skipped_rows_read():
    """The memory's excitation check zeroed the rows with an undefined target and called a
    parameter only they read "not excited (zero regressor)", as batch least squares once did:
    it is not measured, and both estimators now say so in the same words."""
    phi, noise = _two_regressors(400)
    phi[:200, 1] = 0.0  # b read only in the second half,
    y = phi @ np.array([2.0, -3.0]) + noise
    y[200:] = np.nan  # whose targets are undefined
    reg = Regression(phi, y, ["a", "b"], ("u",), y.size)
    with pytest.warns(ExcitationWarning) as caught:
        rls = RecursiveLeastSquares().solve(reg)
    said = " | ".join(str(w.message) for w in caught if w.category is ExcitationWarning)
    assert "not measured" in said and "zero regressor" not in said
    assert np.isnan(rls.theta[1]) and rls.theta[0] == pytest.approx(2.0, abs=0.2)


def test_rls_memory_check_is_not_set_by_one_column_huge_on_a_few_rows():
    """The recursive fit's check had ΦᵀΦ alone, so its zero rule's scale was the largest
    column RMS: a column 1e12 on three rows made the others "zero regressor". It now reads the
    typical regressor size and the unweighted RMS of its rows, as batch least squares does."""
    from nnid.trainers.recursive import window_covariance

    rng = np.random.default_rng(1)
    n = 300
    phi = np.stack([rng.normal(size=n), rng.normal(size=n), 0.1 * rng.normal(size=n)], 1)
    phi[[5, 77, 201], 2] = 1e12
    y = phi @ np.array([2.0, -3.0, 0.5]) + 0.01 * rng.normal(size=n)
    reg = Regression(phi, y, ["a", "b", "c"], ("u",), n)
    *_, report = window_covariance(reg, np.array([2.0, -3.0, 0.5]), 0)
    assert report.unexcited == [] and report.collinear == []


def test_rls_memory_check_weights_an_equation_of_exact_data_as_batch_least_squares_does():
    """Equation A reads a + b alone, exactly (σ̂² 1e-26: rounding); B, with regressors 100
    times A's and unit noise, separates them. The memory check weighted each equation by 1/σ̂²,
    A by 1e26: B fell below the check's tolerance, a and b read collinear and lost their
    standard errors. Its weights are batch least squares' feasible ones (floored, spread
    within 1/√eps), and both say what B measures: a and b apart, to 6e-4."""
    from nnid.trainers.recursive import window_covariance

    rng = np.random.default_rng(0)
    n = 300
    x, xb, zb = rng.normal(size=n), 100 * rng.normal(size=n), 100 * rng.normal(size=n)
    phi = np.zeros((2 * n, 2))  # rows: A, B of each sample
    phi[0::2], phi[1::2] = np.column_stack([x, x]), np.column_stack([xb, zb])
    y = phi @ [1.0, 2.0]
    y[0::2] += 1e-13 * rng.normal(size=n)
    y[1::2] += rng.normal(size=n)
    reg = Regression(phi, y, ["a", "b"], ("A", "B"), n)
    cov, _, report = window_covariance(reg, np.array([1.0, 2.0]), 0)
    assert report.collinear == [] and report.unexcited == []
    assert np.sqrt(np.diag(cov)) == pytest.approx(1 / (100 * np.sqrt(n)), rel=0.2)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ExcitationWarning)
        assert LeastSquares(correlated=False).solve(reg).excitation.collinear == []


def test_the_gradient_estimators_step_reads_its_runs_without_the_joins(seamor):
    """Two runs of 120 Hz stamped in whole ms, t restarting at 0: read over the whole data,
    the negative step at the join took the rounded clock off its line, and the gradient law
    was discretised over the 8-ms median, 4 % short of each run's 8.33 ms. Data in which no
    run has two samples still step one gain a sample (Δt None, as one sample had)."""
    seen = []

    class Seen(GradientEstimator):
        def solve(self, reg, dt=None, progress=None):
            seen.append(dt)
            return super().solve(reg, dt, progress)

    t = np.round(np.arange(360) / 120.0 * 1e3) / 1e3  # 8, 8, 9 ms steps
    u = 0.5 + 0.2 * np.sin(2 * np.pi * 0.5 * t)
    run = pd.DataFrame({"t": t, "u": u, "du": np.gradient(u, t)})
    run = run.assign(**{f"tau_{f}": 0.0 for f in "YZKMN"}, tau_X=20.0 * u)
    log = pd.concat([run.assign(experiment=name) for name in ("a", "b")], ignore_index=True)
    structure = ParametricFossen(seamor, SURGE, dofs=("u",))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no standard errors, not converged: not tested here
        Seen(gain=1.0).fit(structure, log_arrays(log, seamor))
        Seen(gain=1.0).fit(structure, log_arrays(log.iloc[[0, 360]], seamor))
    assert seen[0] == pytest.approx(1 / 120, rel=1e-5)
    assert seen[1] is None


def test_rls_standard_errors_are_each_equations_own():
    """RLS (no forgetting) over a force equation with a 1 N constant the model lacks and a
    correlated residual (τ ≈ 20), beside a white moment equation sharing no column. Its
    sandwich used each equation's centred variance (the constant dropped: X_a's s.e. √5 too
    small) and one mean τ for both (N_b's s.e. 3x too wide). Each parameter's s.e. is now the
    one its equation gives alone: rᵀr/(n − p) (Caccia eq. 12) times its own τ."""
    rng = np.random.default_rng(0)
    n = 4000
    x, z = rng.normal(size=(2, n))
    e = np.convolve(rng.normal(size=n + 19), np.ones(20) / np.sqrt(20), "valid")
    yx, yz = 2.0 * x + 1.0 + 0.5 * e, -0.5 * z + 0.1 * rng.normal(size=n)
    phi = np.zeros((2 * n, 2))
    phi[0::2, 0], phi[1::2, 1] = x, z
    y = np.empty(2 * n)
    y[0::2], y[1::2] = yx, yz
    both = RecursiveLeastSquares().solve(Regression(phi, y, ["X_a", "N_b"], ("u", "r"), n))
    alone = [
        RecursiveLeastSquares().solve(Regression(c[:, None], t, [nm], ("u",), n)).stderr[0]
        for c, t, nm in ((x, yx, "X_a"), (z, yz, "N_b"))
    ]
    np.testing.assert_allclose(both.stderr, alone, rtol=0.01)


def _steady(seed: int, step: float = 0.0, at: int = 1900) -> Regression:
    """2000 samples of ten unit regressors, noise σ 0.5; the fourth parameter jumps by
    ``step`` at sample ``at``."""
    rng = np.random.default_rng(seed)
    n, p = 2000, 10
    phi = rng.normal(size=(n, p))
    theta = np.tile(np.linspace(-2.0, 2.0, p), (n, 1))
    theta[at:, 3] += step
    y = (phi * theta).sum(1) + 0.5 * rng.normal(size=n)
    return Regression(phi, y, [f"p{k}" for k in range(p)], ("u",), n)


def test_rls_with_forgetting_does_not_call_a_steady_run_moving_but_a_step_still_is():
    """λ = 0.99 (memory 100 samples, a tenth of the run 200): the two ends still_moving compares
    are estimates from different data, whose difference spreads about one window s.e.; two
    s.e. was a 5 % test per parameter, and 24 % of steady runs of ten parameters were "still
    moving (tracking a change?)" and lost those s.e. (6 of these 20 seeds). The Bonferroni
    bound over the parameters (1 % for the run: 0 of 300 seeds measured) says none; a jump of
    0.5 (ten window s.e.) in one parameter 100 samples before the end is still said, of it
    alone."""
    rls = RecursiveLeastSquares(forgetting=0.99)
    for seed in range(20):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            est = rls.solve(_steady(seed))
        assert np.isfinite(est.stderr).all(), seed
    with pytest.warns(UserWarning, match=r"still moving \(tracking a change\?\): p3 still moved"):
        est = rls.solve(_steady(0, step=0.5))
    assert np.isnan(est.stderr).tolist() == [k == 3 for k in range(10)]


def test_gradient_estimator_checks_excitation_as_rls_does():
    """b's regressor zero throughout: the gradient law never moves it from theta0 (5.0), which
    was reported as its value with no warning (RLS and batch least squares: NaN, and said).
    The same check over its memory (the whole run), kept with the estimate."""
    phi, noise = _two_regressors()
    phi[:, 1] = 0.0
    y = phi @ np.array([2.0, -3.0]) + noise
    reg = Regression(phi, y, ["a", "b"], ("u",), y.size)
    with pytest.warns(ExcitationWarning, match=r"last 2000 samples.*not excited.*: b.*theta0") as w:
        est = GradientEstimator(gain=0.01, theta0=np.array([0.0, 5.0])).solve(reg)
    assert np.isnan(est.theta[1]) and np.isnan(est.history[:, 1]).all()
    assert est.theta[0] == pytest.approx(2.0, abs=0.1)
    assert est.excitation.unexcited == ["b"] and est.as_dict()["b"]["value"] is None
    assert "standard error" not in str(w[0].message)  # it gives none: none to withhold
    # RLS's path holds no theta0 for it either: its final value is NaN
    with pytest.warns(ExcitationWarning):
        rls = RecursiveLeastSquares(theta0=np.array([0.0, 5.0])).solve(reg)
    assert np.isnan(rls.history[:, 1]).all() and np.isfinite(rls.history[:, 0]).all()


def test_recursive_estimators_say_the_rows_they_skip_as_batch_least_squares_does():
    """b read only in rows whose target is NaN: batch least squares says "200 of 400 rows of
    the regression are left out ... only they read b"; RLS and the gradient estimator skipped
    the same rows without that word."""
    phi, noise = _two_regressors(400)
    phi[:200, 1] = 0.0
    y = phi @ np.array([2.0, -3.0]) + noise
    y[200:] = np.nan
    reg = Regression(phi, y, ["a", "b"], ("u",), y.size)
    said = []
    for estimator in (
        LeastSquares(weighting="none"),
        RecursiveLeastSquares(),
        GradientEstimator(gain=0.01),
    ):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            estimator.solve(reg)
        said.append([str(w.message) for w in caught if "rows of the regression" in str(w.message)])
    assert said[0] == said[1] == said[2] and len(said[0]) == 1, said
    assert said[0][0].startswith("200 of 400 rows of the regression are left out")


def test_rls_covariance_of_exact_data_is_floored_at_rounding_as_batch_least_squares():
    """Exact data: the residual is rounding, or 0. Batch least squares floors each equation's
    variance at a few ulps of its targets' mean square; the RLS window covariance did not, and
    read s.e. 0 (every parameter, a 1e-16 one too, "significant")."""
    from nnid.trainers.recursive import window_covariance

    rng = np.random.default_rng(0)
    phi = rng.integers(-3, 4, size=(300, 3)).astype(float)
    y = phi @ np.array([2.0, -3.0, 0.0])  # integers: the residual at the truth is exactly 0
    reg = Regression(phi, y, ["a", "b", "c"], ("u",), 300)
    cov = window_covariance(reg, np.array([2.0, -3.0, 0.0]), 0)[0]
    batch = LeastSquares(weighting="none", correlated=False).solve(reg)
    assert (np.diag(cov) > 0).all()
    np.testing.assert_allclose(cov, batch.cov, rtol=1e-6)
