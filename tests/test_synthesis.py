"""Viscous-model synthesis (McCarter ch. 4-5): residual force, masked least squares, Nelder-Mead.

The reproduction: configs/vt690_truth.toml flies the VT 690 with McFarland's Appendix E damping
(216 coefficients) as truth, under a PD autopilot, with DVL/gyro/AHRS noise. Trained on cruise_1.0
and cruise_1.8 and validated on cruise_1.5 (McCarter: "similar maneuvers at different forward
speeds"), the McFarland fit recovers the coefficient matrix and the uncoupled models leave at
least three times its validation error J/J0 (eq. 4.25), as in McCarter's Table 5.1.

τ̄ is taken in the filtered form (F(s) = λ/(s + λ), λ = 2 rad/s, on both sides) with the logged
zero-order-held force averaged over consecutive samples. With Savitzky-Golay accelerations (1 s,
order 4) the same log gives about 6 % coefficient error even without any noise: the smoothed
acceleration and the held, autopilot-driven force are not simultaneous. u > 0 throughout, which
the McFarland basis tolerates (no two a*abs(b) terms coincide for u > 0); it is McCarter's low
excitation, not the sign of u, that the config's larger manoeuvres fix.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from nnid.config import load_config
from nnid.datasets.simulator import simulate_config
from nnid.models.synthesis import SynthesisModel, residual_force
from nnid.physics.damping_library import BasisLibrary
from nnid.physics.damping_masks import MASK_TERM_COUNTS, MASKS
from nnid.physics.dofs import FORCES
from nnid.trainers.synthesis import (
    force_error,
    mask_matrix,
    mask_term_list,
    masked_least_squares,
    nelder_mead,
)
from nnid.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
TRAIN = ("cruise_1.0", "cruise_1.8")
VALIDATION = ("cruise_1.5",)
FORM = {"filter_lambda": 2.0, "zoh_midpoint": True}


@pytest.fixture(scope="module")
def vt690():
    return load_vehicle("vt690")


@pytest.fixture(scope="module")
def campaign(vt690) -> tuple[pd.DataFrame, pd.DataFrame]:
    log = simulate_config(load_config(ROOT / "configs/vt690_truth.toml"), vt690)
    train = log[log["experiment"].isin(TRAIN)].reset_index(drop=True)
    val = log[log["experiment"].isin(VALIDATION)].reset_index(drop=True)
    return train, val


@pytest.fixture(scope="module")
def mcfarland(vt690, campaign) -> SynthesisModel:
    return SynthesisModel(vt690, "mcfarland", **FORM).fit(campaign[0])


def _truth(vehicle, terms: list[str]) -> np.ndarray:
    k = np.zeros((6, len(terms)))
    for key, value in vehicle.damping.coefficients.items():
        force, term = key.split(":")
        k[FORCES.index(force), terms.index(term)] = value
    return k


def test_mask_matrix_counts():
    for name in MASKS:
        terms = mask_term_list(name)
        assert mask_matrix(name, terms).sum() == MASK_TERM_COUNTS[name]


def test_mcfarland_recovers_appendix_e(vt690, mcfarland):
    """216 coefficients within 5 % (relative Frobenius error of K); got 1.4 %."""
    truth = _truth(vt690, mcfarland.terms_)
    assert mcfarland.n_params == 216
    err = np.linalg.norm(mcfarland.coefficient_matrix() - truth) / np.linalg.norm(truth)
    assert err < 0.05, err
    assert set(mcfarland.params) == set(vt690.damping.coefficients)


@pytest.mark.filterwarnings("ignore::nnid.trainers.least_squares.ExcitationWarning")
def test_uncoupled_models_three_times_worse(vt690, campaign, mcfarland):
    """Table 5.1 analogue: validation J/J0 of Fossen and Uncoupled >= 3x McFarland's
    (got 0.203 McFarland, 0.727 Uncoupled, 0.742 Fossen, at DVL/gyro noise that puts McFarland
    near McCarter's measured J/J0). With u > 0 Uncoupled's X terms u,
    abs(u), u*u, u*abs(u) alias pairwise (McCarter's Table E.10 drops two of them) and warn."""
    train, val = campaign
    j, j0 = mcfarland.error(val)
    ratio = j / j0
    assert ratio < 0.3
    for name in ("fossen", "uncoupled"):
        jm, j0m = SynthesisModel(vt690, name, **FORM).fit(train).error(val)
        assert j0m == pytest.approx(j0)
        assert jm / j0m >= 3 * ratio, (name, jm / j0m, ratio)


# -- Nelder-Mead on eqs 4.23-4.27, on a small mask ------------------------------------------------


@pytest.fixture(scope="module")
def fossen_problem(campaign):
    """ξ of the ``fossen`` mask on the logged ν (every 10th sample) and a τ̄ it explains."""
    nu = campaign[0][["u", "v", "w", "p", "q", "r"]].to_numpy()[::10]
    terms = mask_term_list("fossen")
    xi = BasisLibrary(terms)(nu)
    mask = mask_matrix("fossen", terms)
    rng = np.random.default_rng(3)
    k = np.where(mask, -rng.uniform(5.0, 50.0, mask.shape), 0.0)
    tau = xi @ k.T
    tau += 0.02 * tau.std(0) * rng.standard_normal(tau.shape)
    return xi, tau, mask, k


def test_nelder_mead_losses_match_least_squares_on_clean_data(fossen_problem):
    xi, tau, mask, k = fossen_problem
    ls = masked_least_squares(xi, tau, mask)
    j_ls, j0 = force_error(tau, ls.predict(xi))
    assert j_ls < 0.05 * j0
    for loss in ("mae", "mse", "rms", "mad"):
        fit = nelder_mead(xi, tau, mask, loss, start=ls)
        j, _ = force_error(tau, fit.predict(xi))
        assert np.isfinite(j)
        assert j <= 1.05 * j_ls, (loss, j, j_ls)
        # the medians of MAD (eqs 4.26-4.27) are the least efficient: 2.5 % here, LS 0.5 %
        assert np.linalg.norm(fit.coefficients - k) / np.linalg.norm(k) < 0.05, loss


def test_mae_more_robust_than_least_squares_to_outliers(fossen_problem):
    xi, tau, mask, k = fossen_problem
    rng = np.random.default_rng(5)
    bad = tau.copy()
    rows = rng.choice(bad.shape[0], bad.shape[0] // 50, replace=False)  # 2 % outliers
    bad[rows] += 20.0 * tau.std(0) * rng.choice([-1.0, 1.0], (rows.size, 6))
    bad[rows] = np.abs(bad[rows])  # one-sided, so they bias rather than average out
    ls = masked_least_squares(xi, bad, mask)
    mae = nelder_mead(xi, bad, mask, "mae", start=ls)
    err_ls = np.linalg.norm(ls.coefficients - k) / np.linalg.norm(k)
    err_mae = np.linalg.norm(mae.coefficients - k) / np.linalg.norm(k)
    assert err_mae < 0.5 * err_ls, (err_mae, err_ls)


def test_residual_force_shape_and_form(vt690, campaign):
    val = campaign[1]
    tau_sg, data = residual_force(vt690, val)
    tau_f, _ = residual_force(vt690, val, filter_lambda=2.0)
    assert tau_sg.shape == tau_f.shape == (len(val), 6)
    assert np.isfinite(tau_sg).all()
    assert np.isnan(tau_f[: int(1.5 / 0.05) - 1]).all()  # filter settling, 3/λ s
    assert data["nu"].shape == (len(val), 6)


def test_a_nelder_mead_search_stopped_by_its_budget_is_said(fossen_problem):
    """A search cut at its iteration limit returned its last simplex as if it were the
    minimum: it now names the forces where it stopped; a converged search is silent."""
    import warnings

    xi, tau, mask, _ = fossen_problem
    ls = masked_least_squares(xi, tau, mask)
    with pytest.warns(UserWarning, match=r"stopped at its iteration limit for X"):
        nelder_mead(xi, tau, mask, "mae", start=ls, forces=("X",), max_iter_per_param=2)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        nelder_mead(xi, tau, mask, "mse", start=ls, forces=("X",))


def test_nelder_mead_starts_from_the_least_squares_of_the_solves_floors():
    """X:u alone in its mask on a heave-only log whose u is rounding (1e-17): against Ξ's
    typical regressor (its own column, the only one) it is data, and the default start fitted
    X:u = -13.7 to rounding, which Nelder-Mead then searched. With the floors the model's solve
    uses (each term against the log's typical motion, :func:`library_floors`) the start is that
    solve's: X:u unidentified, held at 0. Given Ξ's column names (``terms``, as the solve is),
    the start's warning names X:u, where without them it said "X:0"."""
    from nnid.errors import ExcitationWarning
    from nnid.evaluation.persistence import library_floors

    rng = np.random.default_rng(0)
    n = 200
    nu = np.zeros((n, 6))
    nu[:, 0] = 1e-17 * rng.normal(size=n)
    nu[:, 2] = 0.3 * np.sin(0.1 * np.arange(n))
    xi = nu[:, :1].copy()
    tau = np.zeros((n, 6))
    tau[:, 0] = -13.7 * nu[:, 0]
    mask = mask_matrix({"X": ["u"]}, ["u"])
    floors = library_floors(nu, BasisLibrary(["u"]), 1.0)
    assert not masked_least_squares(xi, tau, mask).unidentified[0, 0]  # the scalar rule's
    with pytest.warns(ExcitationWarning, match=r"zero regressor\): X:0"):
        solve = masked_least_squares(xi, tau, mask, floors=floors)
    with pytest.warns(ExcitationWarning, match=r"zero regressor\): X:u"):
        fit = nelder_mead(xi, tau, mask, "mse", floors=floors, terms=["u"])
    assert solve.unidentified[0, 0] and fit.unidentified[0, 0]
    assert fit.coefficients[0, 0] == 0.0


def _heave_only():
    """The demo vehicle and a 30-s heave run of it whose u, v, p, q, r are exactly 0 (the
    regressor of X:u is zero)."""
    from importlib import resources

    from nnid.datasets.simulator import simulate

    vehicle = load_vehicle(str(resources.files("nnid.demo_data").joinpath("minirov.toml")))
    t = np.arange(300) * 0.1
    inputs = np.zeros((t.size, 6))
    inputs[:, 2] = 30.0 + 20.0 * np.sin(1.2 * t)
    log = simulate(vehicle, inputs, 0.1, substeps=2, experiment="heave")
    log[["u", "v", "p", "q", "r"]] = 0.0
    return vehicle, log


@pytest.mark.parametrize("method", ["ls", "mae"])
def test_an_unidentified_coefficient_stays_visible_not_an_estimate_of_zero(method, tmp_path):
    """A masked term no row reads (X:u of a heave-only log) is unidentified: least squares
    leaves it NaN and the model simulates it at 0 (K replaces the file's damping, eq. 4.6).
    Its 0 was in params as the estimate 0.0, in the saved state and the report alike; it is now
    null with simulated_at 0.0, said at the fit, kept through a save, and held at 0 by
    Nelder-Mead (no cost reads it)."""
    from nnid import load_model
    from nnid.errors import ExcitationWarning
    from nnid.reports.train_report import _params_table

    vehicle, log = _heave_only()
    mask = {"X": ["u"], "Z": ["w", "w*abs(w)"]}
    with pytest.warns(ExcitationWarning, match=r"X:u at 0 \(K replaces"):
        model = SynthesisModel(vehicle, mask, method, filter_lambda=1.0).fit(log)
    entry = model.params["X:u"]
    assert entry == {"value": None, "stderr": None, "simulated_at": 0.0}
    assert model.coef_[0, 0] == 0.0 and model.params["Z:w"]["value"] < 0
    assert model.n_params == 3
    _, rows = _params_table({"params": model.params})
    assert rows[0][:2] == ["`X:u`", "- (simulated at 0)"]
    model.save(tmp_path)
    back = load_model(tmp_path)
    assert back.params == model.params
    np.testing.assert_array_equal(back.coef_, model.coef_)


def test_an_older_file_shows_its_unidentified_coefficient_as_not_identified(tmp_path):
    """A file saved before the unidentified coefficients were kept (no "unidentified" in its
    state) showed X:u, which no row read, as the estimate 0.0. Such a file tells them apart:
    masked least squares left each at exactly 0 with no standard error, which no estimate
    is. Loaded, it reads as a file of today does: null, simulated at 0, the same predictions."""
    import json

    from nnid import load_model
    from nnid.errors import ExcitationWarning

    vehicle, log = _heave_only()
    mask = {"X": ["u"], "Z": ["w", "w*abs(w)"]}
    with pytest.warns(ExcitationWarning):
        model = SynthesisModel(vehicle, mask, filter_lambda=1.0).fit(log)
    model.save(tmp_path)
    path = tmp_path / "model.json"
    saved = json.loads(path.read_text())
    del saved["state"]["unidentified"]  # as an older nnid wrote it
    path.write_text(json.dumps(saved))
    older = load_model(tmp_path)
    assert older.params["X:u"] == {"value": None, "stderr": None, "simulated_at": 0.0}
    assert older.params == model.params  # the estimates, Z:w and Z:w*abs(w), as fitted
    pd.testing.assert_frame_equal(older.predict(log, "one_step"), model.predict(log, "one_step"))


@pytest.mark.parametrize("u_level", [1e-18, 0.0])
def test_a_regressor_of_rounding_or_zero_but_for_settling_rows_is_a_zero_regressor(u_level):
    """X:u of a heave-only log whose u is rounding (the simulator leaves 1e-17): alone in its
    force's block, the per-column scaling made it as excited as any, and it read X:u = -13.7 ±
    0.0006 off a target of rounding; it is a zero regressor against Ξ's largest column (eq.
    4.20). Exactly 0, the filtered form's NaN settling rows (NaN in every column) made it
    "not measured (every row that reads them was left out)"; a NaN reads nothing."""
    from nnid.errors import ExcitationWarning

    rng = np.random.default_rng(0)
    n = 200
    u = u_level * rng.normal(size=n)
    w = 0.3 * np.sin(0.1 * np.arange(n))
    xi = np.stack([u, w, w * np.abs(w)], 1)
    tau = np.zeros((n, 6))
    tau[:, 0] = -13.7 * u  # X: rounding too, as on the simulated log
    tau[:, 2] = xi[:, 1:] @ [-33.0, -190.0] + 0.01 * rng.normal(size=n)
    xi[:30], tau[:30] = np.nan, np.nan  # the filter's settling rows (synthesis_data)
    mask = mask_matrix({"X": ["u"], "Z": ["w", "w*abs(w)"]}, ["u", "w", "w*abs(w)"])
    with pytest.warns(ExcitationWarning) as caught:
        fit = masked_least_squares(xi, tau, mask, ["u", "w", "w*abs(w)"])
    said = " | ".join(str(x.message) for x in caught)
    assert "not excited by this data (zero regressor): X:u" in said
    assert "not measured" not in said and "only they read" not in said
    assert fit.unidentified[0, 0] and fit.coefficients[0, 0] == 0.0
    assert fit.coefficients[2, 1] == pytest.approx(-33.0, rel=0.05)


def test_one_column_singular_on_a_few_rows_does_not_make_the_others_rounding():
    """An (η − 1) term at U = 0 under a current (a DVL reading 0.000) reaches 1e12 on those
    rows: Ξ's largest column RMS, the reference of the rounding rule, made every ordinary
    column of every force "zero regressor" (K = 0). Against Ξ's typical regressor they stay
    live, and a column of rounding (1e-17) is still zero."""
    from nnid.errors import ExcitationWarning

    rng = np.random.default_rng(1)
    n = 400
    u = 1e-17 * rng.normal(size=n)
    w = 0.3 * np.sin(0.05 * np.arange(n))
    r = 0.2 * np.cos(0.03 * np.arange(n))
    singular = r * r * (0.1 / np.sqrt(w * w + 0.01) - 1.0)
    singular[[5, 77, 301]] = 1e12  # U = 0 there: u_c / sqrt(1e-30) - 1
    terms = ["u", "w", "w*abs(w)", "r*r*(eta-1)"]
    xi = np.stack([u, w, w * np.abs(w), singular], 1)
    tau = np.zeros((n, 6))
    tau[:, 0] = -13.7 * u
    tau[:, 2] = xi[:, 1:3] @ [-33.0, -190.0] + 0.01 * rng.normal(size=n)
    tau[:, 5] = 2.0 * singular + 0.01 * rng.normal(size=n)
    mask = mask_matrix({"X": ["u"], "Z": ["w", "w*abs(w)"], "N": ["r*r*(eta-1)"]}, terms)
    with pytest.warns(ExcitationWarning, match=r"zero regressor\): X:u$"):
        fit = masked_least_squares(xi, tau, mask, terms)
    assert fit.unidentified[0, 0] and fit.unidentified.sum() == 1
    assert fit.coefficients[2, 1] == pytest.approx(-33.0, rel=0.05)
    assert fit.coefficients[2, 2] == pytest.approx(-190.0, rel=0.05)


def test_a_w_at_rounding_level_fits_the_model_of_an_exact_zero():
    """A vehicle driven in surge, sway and yaw only, its w logged as exact zeros or as 1e-17
    rounding: the Vw regressors were ±V with the rounding's random sign, so a mask with Vw terms
    fitted noise coefficients to them where exact zeros leave them unidentified. Both logs give
    the same regression and the same model."""
    import warnings

    from nnid.datasets.simulator import simulate
    from nnid.trainers.least_squares import ExcitationWarning

    vehicle = load_vehicle("seamor")
    rng = np.random.default_rng(3)
    inputs = np.zeros((300, 6))
    inputs[20:, [0, 1, 5]] = np.repeat(rng.uniform(-30, 30, (15, 3)), 20, 0)[:280] * [1, 1, 0.2]
    log = simulate(vehicle, inputs, 0.1)
    assert not log[["w", "p", "q"]].to_numpy().any()
    rounding = log.assign(w=1e-17 * rng.standard_normal(len(log)))
    mask = {"X": ["u*abs(u)", "u*Vw"], "Y": ["v*abs(v)", "abs(r)*Vw"], "N": ["r*abs(r)", "v*Vw"]}
    fits, said = [], []
    for data in (log, rounding):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            fits.append(SynthesisModel(vehicle, mask).fit(data))
        said.append(" ".join(str(w.message) for w in caught if w.category is ExcitationWarning))
    exact, rounded = fits
    assert rounded.params == exact.params
    assert exact.params["X:u*Vw"] == {"value": None, "stderr": None, "simulated_at": 0.0}
    assert all("zero regressor" in text and "N:v*Vw" in text for text in said)


def test_the_named_mask_synthesis_does_not_import_pysindy():
    """The named-mask synthesis imported nnid.trainers.sindy, and with it pysindy and
    scikit-learn, for library_floors alone, which lives beside motion_floors now."""
    import os
    import subprocess
    import sys

    code = "import sys, nnid.models.synthesis; sys.exit('pysindy' in sys.modules)"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, timeout=120)
    assert done.returncode == 0, done.stderr.decode()[-2000:]


def test_the_damping_terms_are_of_the_velocity_through_the_water():
    """A Seamor flown in a 0.3 m/s current (its vehicle file's): its damping acts on
    ν_r = ν − ν_c, and τ̄ leaves out τ_D(ν_r). The basis terms were of the logged ν, and the
    Weiss quadratic terms came out at −25 (X) for −61, and no warning said; of ν_r
    they are the vehicle file's."""
    from nnid.datasets.simulator import simulate

    vehicle = load_vehicle("seamor").model_copy(update={"current": [0.3, 0.0, 0.0]})
    rng = np.random.default_rng(0)
    inputs = np.zeros((400, 6))
    inputs[20:, [0, 1, 5]] = np.repeat(rng.uniform(-30, 30, (19, 3)), 20, 0) * [1, 1, 0.2]
    log = simulate(vehicle, inputs, 0.1)
    mask = {"X": ["u*abs(u)"], "Y": ["v*abs(v)"], "N": ["r*abs(r)"]}
    fit = SynthesisModel(vehicle, mask).fit(log)
    truth = vehicle.damping.coefficients
    for key in ("X:u*abs(u)", "Y:v*abs(v)", "N:r*abs(r)"):
        assert fit.params[key]["value"] == pytest.approx(truth[key], rel=1e-3), key
