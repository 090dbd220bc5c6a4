"""``validation_used_for`` (``metrics.json``, the reports, compare's verdict) says what this fit
did with its validation log, not what the model kind would do with one: a fit without one, or
with one too short to score, stopped on nothing held out, and its scores on other data are
independent of it."""

from __future__ import annotations

import json
import warnings
from importlib import resources

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from nnid import load_model
from nnid.cli import app
from nnid.loop.scenarios import effect_log
from nnid.models.ensemble import EnsembleModel
from nnid.models.narx import NarxModel
from nnid.models.neural_state_space import NeuralStateSpace
from nnid.models.sindy import SindyDamping
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
from nnid.vehicle import load_vehicle

MINIROV = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))


def _tank(n: int, seed: int) -> pd.DataFrame:
    """A saturating first-order tank driven by held random steps, sampled at 1 s."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(0.2, 1.3, n // 20 + 1), 20)[:n]
    y = np.zeros(n)
    for k in range(1, n):
        y[k] = min(0.9 * y[k - 1] + 0.1 * u[k - 1] + 0.05 * np.sin(3 * u[k - 1]), 1.0)
    return pd.DataFrame({"t": np.arange(n, dtype=float), "u": u, "y": y})


def _narx(delays: int = 2, **kw) -> NarxModel:
    lm = LevenbergMarquardt(max_epochs=2, jacobian="samples")
    return NarxModel(["u"], ["y"], delays, delays, hidden=(3,), trainer=lm, balanced=False, **kw)


def test_a_narx_says_early_stopping_only_where_it_stopped_on_the_validation_log(tmp_path):
    train, val = _tank(300, 0), _tank(100, 1)
    assert _narx().validation_use == "early stopping"  # before a fit: what a fit would do
    assert _narx().fit(train, val).validation_use == "early stopping"
    # no validation log: the fit stopped on a block of its own training log
    own = _narx().fit(train)
    assert own.division_["by"] == "block" and own.validation_use is None
    # a validation run shorter than the delays: nothing scored, nothing stopped on
    with pytest.warns(UserWarning, match="without early stopping"):
        short = _narx(40, lm_samples=100).fit(_tank(600, 0), _tank(20, 1))
    assert short.history_.validation == [] and short.validation_use is None
    short.save(tmp_path / "m")  # a loaded model says what the fit did, not the kind's role
    assert load_model(tmp_path / "m").validation_use is None
    _narx().fit(train, val).save(tmp_path / "m")
    assert load_model(tmp_path / "m").validation_use == "early stopping"


def test_metrics_json_does_not_claim_early_stopping_on_a_validation_run_too_short(tmp_path):
    """``nnid train`` with a 30-sample validation run under 40 delays: the NARX warned that it
    trains without early stopping, while metrics.json said "early stopping" and the summary
    line "used for early stopping while fitting"."""
    runs = [_tank(400, 0).assign(experiment="a"), _tank(30, 1).assign(experiment="b")]
    pd.concat(runs).to_csv(tmp_path / "tank.csv", index=False)
    cfg = tmp_path / "narx.toml"
    cfg.write_text(
        "warmup_s = 0.0\n"
        '[data]\nkind = "table"\nlog = "tank.csv"\n'
        '[split]\nby = "experiment"\nvalidation = ["b"]\n'
        '[model]\nkind = "narx"\ninputs = ["u"]\noutputs = ["y"]\nhidden = [3]\n'
        "input_delays = 40\noutput_delays = 40\nbalanced = false\nlm_samples = 100\n"
        '[model.trainer]\nkind = "lm"\nmax_epochs = 2\n'
    )
    done = CliRunner().invoke(app, ["train", str(cfg), "--out", str(tmp_path / "out")])
    assert done.exit_code == 0, done.output
    m = json.loads((tmp_path / "out/metrics.json").read_text())
    assert any("without early stopping" in w for w in m["warnings"])
    assert m["validation_used_for"] is None
    assert "used for" not in done.output


def test_a_state_space_fit_without_validation_used_none():
    log = _tank(200, 0).rename(columns={"u": "pump", "y": "level"})
    lm = LevenbergMarquardt(max_epochs=2)
    kw = dict(hidden=3, warmup=5, trainer=lm, fractions=(0.8, 0.2, 0.0))
    own = NeuralStateSpace(["pump"], ["level"], **kw).fit(log)
    assert own.division_["by"] == "block" and own.validation_use is None
    given = NeuralStateSpace(["pump"], ["level"], **kw).fit(log, log)
    assert given.validation_use == "early stopping"


def test_sindy_selects_on_the_validation_log_only_when_given_one():
    log = effect_log(load_vehicle(MINIROV), duration=20.0, n_experiments=2, seed=5)
    first = log["experiment"] == log["experiment"].iloc[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        own = SindyDamping(load_vehicle(MINIROV)).fit(log[first])
        given = SindyDamping(load_vehicle(MINIROV)).fit(log[first], log[~first])
    assert own.validation_use is None  # chosen on a holdout of its training log
    assert given.validation_use == "model selection"


def test_an_ensemble_without_validation_dropped_nothing_on_it():
    """With drop_diverged (the default) it said "dropping diverged members" of a fit that had
    no validation log to judge them on; its members' own uses are said as they did them."""
    train, val = _tank(300, 0), _tank(100, 1)
    assert EnsembleModel(_narx(), seeds=(0, 1)).fit(train).validation_use is None
    both = EnsembleModel(_narx(), seeds=(0, 1)).fit(train, val)
    assert both.validation_use == "early stopping, dropping diverged members"
