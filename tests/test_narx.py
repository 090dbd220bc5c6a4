"""NARX network (Weiss IV.A.2, V.B) on the seamor simulator with light noise."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from nnid.config import SimulateConfig, load_config
from nnid.datasets.simulator import simulate_config
from nnid.models.narx import NarxModel
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
from nnid.vehicle import load_vehicle

ROOT = Path(__file__).resolve().parents[1]
FORCES = ["tau_X", "tau_Y", "tau_Z", "tau_N"]


@pytest.fixture(scope="module")
def seamor() -> pd.DataFrame:
    """Weiss's sequence; true velocities and forces with 1 % white noise (Weiss: 'low power')."""
    cfg = load_config(ROOT / "configs/seamor_sequence.toml", SimulateConfig)
    log = simulate_config(cfg, load_vehicle(cfg.vehicle))
    rng = np.random.default_rng(0)
    for c in "uvwr":
        log[c] = log["true_" + c] + rng.normal(0, 0.01 * log["true_" + c].std(), len(log))
    for c in FORCES:
        log[c] = log[c] + rng.normal(0, 0.01 * log[c].std(), len(log))
    return log


def _runs(log: pd.DataFrame, *names: str) -> pd.DataFrame:
    return log[log["experiment"].isin(names)].reset_index(drop=True)


def test_surge_three_nodes_two_delays_follows_free_run(seamor):
    # measured 0.045 (LM, 100 epochs); the bound leaves room for BLAS and seed differences
    surge = _runs(seamor, "surge")
    lm = LevenbergMarquardt(max_epochs=60, jacobian="samples")
    model = NarxModel(["tau_X"], ["u"], 2, 2, hidden=(3,), trainer=lm, seed=0).fit(surge)
    assert model.score(surge, "free_run")["u"] < 0.10


def test_coupled_four_output_network_predicts_unseen_surge_sway(seamor):
    # 10 nodes, 4 delays, u v w r; surge-sway never seen. Measured free run u 0.38-0.50, v
    # 0.53-1.07 over two noise draws after 30 LM epochs: only surge is asserted (sway is not
    # reliably predicted with this budget).
    train = _runs(
        seamor,
        "surge",
        "sway",
        "heave",
        "yaw",
        "surge-heave",
        "surge-yaw",
        "sway-yaw",
        "surge-sway-yaw",
    )
    lm = LevenbergMarquardt(max_epochs=30, jacobian="samples")
    model = NarxModel(FORCES, list("uvwr"), 4, 4, hidden=(10,), trainer=lm, lm_samples=3000)
    model.fit(train, validation_log=_runs(seamor, "sway-heave"))
    score = model.score(_runs(seamor, "surge-sway"), "free_run")
    assert score["u"] < 0.6


def test_ten_nodes_overfit_noisy_single_dof_more_than_three(seamor):
    # noisy (5 %) short surge record, no early stopping: the validation-training gap of the
    # 10-node net exceeds the 3-node net's (measured 8.4 vs 0.08 in normalised MSE)
    sub = _runs(seamor, "surge").iloc[:2400].copy()
    rng = np.random.default_rng(1)
    sub["u"] = sub["true_u"] + rng.normal(0, 0.05 * sub["true_u"].std(), len(sub))
    gaps = {}
    for h in (3, 10):
        lm = LevenbergMarquardt(max_epochs=60, max_fail=10_000, jacobian="samples")
        m = NarxModel(["tau_X"], ["u"], 2, 2, hidden=(h,), trainer=lm, lm_samples=1000).fit(sub)
        gaps[h] = m.history_.val_mse[-1] - m.history_.train_mse[-1]
    assert gaps[10] > gaps[3]


def test_save_load_round_trip_weights_only(seamor, tmp_path, monkeypatch):
    surge = _runs(seamor, "surge")
    lm = LevenbergMarquardt(max_epochs=3, jacobian="samples")
    model = NarxModel(["tau_X"], ["u"], 2, 2, hidden=(3,), trainer=lm).fit(surge)
    model.save(tmp_path)
    calls = []
    real = torch.load

    def spy(*args, **kwargs):
        calls.append(kwargs.get("weights_only"))
        return real(*args, **kwargs)

    monkeypatch.setattr(torch, "load", spy)
    back = NarxModel.load(tmp_path)
    assert calls == [True]
    for mode in ("one_step", "free_run", 5):
        pd.testing.assert_frame_equal(model.predict(surge, mode), back.predict(surge, mode))


def test_no_delay_vector_crosses_an_experiment_boundary(seamor):
    two = _runs(seamor, "surge", "sway")
    model = NarxModel(["tau_X", "tau_Y"], ["u", "v"], 3, 2, hidden=(4,))
    model._fit_normalisation(two)
    base = model.predict(two, "free_run")
    changed = two.copy()
    first = changed["experiment"] == "surge"
    changed.loc[first, ["u", "v", "tau_X", "tau_Y"]] += 5.0  # only the first experiment
    other = model.predict(changed, "free_run")
    second = ~first.to_numpy()
    pd.testing.assert_frame_equal(base[second], other[second])
    for _, part in two.groupby("experiment", sort=False):
        assert base.loc[part.index[: model.warmup]].isna().all().all()
    table = model._table(two)
    starts = np.flatnonzero(np.r_[True, np.diff(table["code"].numpy()) != 0])
    for s in starts:  # the delay states of each experiment carry no regressor
        assert (table["phi"][s : s + model.warmup] == 0).all()


def test_cli_train_narx_adam_writes_contract_metrics(tmp_path):
    text = (ROOT / "configs/seamor_narx_adam.toml").read_text()
    text = text.replace('"seamor_sequence.toml"', f'"{ROOT / "configs/seamor_sequence.toml"}"')
    text = text.replace("epochs = 40", "epochs = 1")
    cfg = tmp_path / "narx.toml"
    cfg.write_text(text)
    out = tmp_path / "out"
    from typer.testing import CliRunner

    from nnid.cli import app

    done = CliRunner().invoke(app, ["train", str(cfg), "--out", str(out)])
    assert done.exit_code == 0, done.output
    m = json.loads((out / "metrics.json").read_text())
    assert m["model"] == "narx" and m["trainer"] == "adam" and m["balanced"] is True
    assert m["params"]["n_params"]["value"] == 374
    for key in ("free_run_nrmse", "one_step_nrmse"):
        assert np.isfinite(m["validation"][key]["total"])
    assert m["seconds"] > 0
    assert (out / "narx.pt").exists() and (out / "narx.json").exists()
