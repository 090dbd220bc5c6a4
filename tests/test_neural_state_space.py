"""Continuous-time neural state-space model on a simulated two-tank cascade (Torricelli)."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest
import torch
from sklearn.exceptions import NotFittedError
from torch.func import jacrev

from nnid import load_model
from nnid.errors import NnidInputError
from nnid.models.neural_state_space import NeuralStateSpace
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

CASCADE = [[1, 1, 0], [0, 1, 1]]  # lower level: both levels; upper level: itself and the pump


def _tanks(n: int, seed: int, upper0: float, lower0: float, noise: float = 0.0) -> pd.DataFrame:
    """Two tanks in cascade sampled at 1 s (RK4, 10 substeps): the pump fills the upper tank,
    which drains by Torricelli into the lower one; only the lower level is measured."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(0.5, 2.0, n // 25 + 1), 25)[:n]

    def f(x: np.ndarray, uk: float) -> np.ndarray:
        up, low = np.maximum(x, 0.0)
        out = 0.3 * np.sqrt(up)
        return np.array([0.4 * uk - out, out - 0.25 * np.sqrt(low)])

    x = np.array([upper0, lower0])
    y = np.empty(n)
    h = 0.1
    for k in range(n):
        y[k] = x[1]
        for _ in range(10):
            k1 = f(x, u[k])
            k2 = f(x + h / 2 * k1, u[k])
            k3 = f(x + h / 2 * k2, u[k])
            k4 = f(x + h * k3, u[k])
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    y = y + noise * rng.standard_normal(n)
    return pd.DataFrame({"t": np.arange(n, dtype=float), "pump": u, "level": y})


@pytest.fixture(scope="module")
def fitted() -> tuple[NeuralStateSpace, pd.DataFrame]:
    train = _tanks(400, 0, 1.0, 1.0, noise=0.01)
    model = NeuralStateSpace(
        ["pump"],
        ["level"],
        hidden_states=1,
        hidden=8,
        structure=CASCADE,
        warmup=20,
        windows=(40, None),
        trainer=LevenbergMarquardt(max_epochs=30),
        fractions=(0.8, 0.2, 0.0),
        seed=0,
    )
    return model.fit(train), train


def test_free_run_of_an_unseen_run_from_another_initial_state(fitted):
    # A run the model never saw, starting with the upper tank nearly empty and the lower one
    # full: the initial state (the hidden upper level too) comes from the 20 warm-up samples.
    # Measured NRMSE 0.025-0.055 over seeds 0-2; a model that only holds the last level
    # (persistence) scores about 1.
    model, _ = fitted
    test = _tanks(300, 7, 0.2, 3.0)
    score = model.score(test)["level"]
    pred = model.predict(test)["level"].to_numpy()
    assert np.isnan(pred[:20]).all() and np.isfinite(pred[20:]).all()
    persistence = np.sqrt(np.mean((test["level"][20:] - test["level"][19]) ** 2))
    assert score < 0.1
    assert score * test["level"][20:].std() < 0.2 * persistence


def test_early_stopping_on_held_out_windows_restores_best(fitted):
    model, _ = fitted
    assert len(model.history_) == 2  # the 40-sample stage, then whole windows
    hist = model.history_[-1]
    assert np.isfinite(hist.validation).all()
    assert min(hist.validation) == pytest.approx(hist.validation[hist.best_epoch])


def test_structure_cuts_dependencies(fitted):
    # the upper tank's derivative must not depend on the lower level (structure row 2)
    model, _ = fitted
    net = model.net_
    x0 = torch.tensor([[0.3, -0.2]], dtype=torch.float64)
    u = torch.tensor([[[0.5]], [[0.5]]], dtype=torch.float64)
    jac = jacrev(lambda x: net(x, u)[1, 0])(x0)[:, 0]  # d x(1) / d x(0)
    assert jac[1, 0] == 0.0  # upper(1) does not see lower(0)
    assert jac[0, 1] != 0.0 and jac[1, 1] != 0.0
    assert model.n_params == 4 * 8 + 16 + 16 + 2  # masked-out weights are not counted


def test_validation_warmup_estimates_states_only(fitted):
    # The held-out windows' warm-ups estimate their initial states: no gradient reaches the
    # weights from them, so held-out data never trains the network.
    model, _ = fitted
    u = torch.zeros(25, 1, 1, dtype=torch.float64)
    y = torch.zeros(25, 1, 1, dtype=torch.float64)
    params = {"net." + k: v.detach() for k, v in model.net_.named_parameters()}
    params["x0"] = torch.zeros(1, 2, dtype=torch.float64)
    params["x0_val"] = torch.tensor([[0.5, 0.1]], dtype=torch.float64)
    jac = jacrev(model._shooting_residual)(params, ("state", u, y, None, None))
    assert all(float(jac[k].abs().max()) == 0.0 for k in params if k.startswith("net."))
    assert float(jac["x0_val"].abs().max()) > 0.0


def test_save_load_round_trip(fitted, tmp_path):
    model, _ = fitted
    test = _tanks(120, 3, 1.5, 0.5)
    model.save(tmp_path)
    cfg = json.loads((tmp_path / "model.json").read_text())["settings"]
    assert cfg["structure"] == CASCADE and cfg["hidden_states"] == 1
    again = load_model(tmp_path)
    np.testing.assert_allclose(again.predict(test), model.predict(test), rtol=1e-10)
    # every field of each stage's fit history comes back (InputOutputModel saves fit_history)
    assert again.history_ == model.history_ and again.stages_ == model.stages_
    saved = json.loads((tmp_path / "model.json").read_text())
    saved["state"].pop("fit_history")  # a file saved before the history was kept still loads
    (tmp_path / "model.json").write_text(json.dumps(saved))
    assert not hasattr(load_model(tmp_path), "history_")


def test_k_step_prediction_restarts_from_the_measured_level(fitted):
    # k steps ahead from the measured level (the hidden upper level from the free run): one
    # step is far closer than the free run, ten steps in between, and k = 1 is one step
    model, _ = fitted
    test = _tanks(300, 7, 0.2, 3.0)
    one, free = model.score(test, "one_step")["level"], model.score(test)["level"]
    ten = model.score(test, 10)["level"]
    assert one < ten < free and one < 0.5 * free
    pd.testing.assert_frame_equal(model.predict(test, 1), model.predict(test, "one_step"))
    ahead = model.predict(test, 10)["level"].to_numpy()
    assert np.isnan(ahead[: model.warmup_samples_ + 9]).all()
    assert np.isfinite(ahead[model.warmup_samples_ + 9 :]).all()


def test_output_bounds_clamp_the_free_run():
    train = _tanks(200, 1, 1.0, 1.0)
    hi = float(train["level"].max())
    model = NeuralStateSpace(
        ["pump"],
        ["level"],
        hidden=4,
        warmup=10,
        trainer=LevenbergMarquardt(max_epochs=2),
        output_bounds=[[None, "train"]],
        fractions=(1.0, 0.0, 0.0),
    ).fit(train)
    assert model.bounds_ == [[None, hi]]
    with torch.no_grad():
        model.net_.b2.add_(torch.tensor([50.0, 0.0], dtype=torch.float64))  # drive the level up
    assert np.nanmax(model.predict(train)["level"]) == pytest.approx(hi)


def test_bad_input_is_named():
    model = NeuralStateSpace(["pump"], ["level"], warmup=5)
    log = _tanks(50, 0, 1.0, 1.0)
    with pytest.raises(NnidInputError, match="pump2"):
        NeuralStateSpace(["pump2"], ["level"]).fit(log)
    bad_t = log.copy()
    bad_t.loc[10:, "t"] += 0.5
    with pytest.raises(NnidInputError, match="not uniformly sampled"):
        model.fit(bad_t)
    holes = log.copy()
    holes.loc[3, "level"] = np.nan
    with pytest.raises(NnidInputError, match="level"):
        model.fit(holes)
    with pytest.raises(NnidInputError, match="structure"):
        NeuralStateSpace(["pump"], ["level"], structure=[[1, 1]]).fit(log)
    with pytest.raises(NotFittedError, match="not fitted"):
        NeuralStateSpace(["pump"], ["level"]).predict(log)


def test_shooting_windows_cover_every_sample_and_link_neighbours():
    # 100 samples in windows of 30: starts 0, 29, 58 (a window's last sample is the next one's
    # first) and 70 (the last window ends at the end); links say where each next window starts
    model = NeuralStateSpace(["pump"], ["level"], warmup=5)
    model._configure()
    model.net_ = model._new_net()
    win = model._windows(_tanks(100, 0, 1.0, 1.0), 30)
    assert [s for _, s in win.where] == [0, 29, 58, 70]
    (group,) = win.groups
    assert group.links.tolist() == [[0, 29, 1], [1, 29, 2], [2, 12, 3]]
    covered = np.zeros(100, bool)
    for _, s in win.where:
        covered[s : s + 30] = True
    assert covered.all() and group.u.shape == (30, 4, 1)
    np.testing.assert_allclose(group.y[12, 2], group.y[0, 3])  # the linked samples are one sample


def _runs(**logs: pd.DataFrame) -> pd.DataFrame:
    """One log of several experiments, named by the keywords."""
    return pd.concat([log.assign(experiment=name) for name, log in logs.items()], ignore_index=True)


def _bare(warmup: int = 5) -> NeuralStateSpace:
    model = NeuralStateSpace(["pump"], ["level"], warmup=warmup)
    model._configure()
    model.net_ = model._new_net()
    return model


def test_whole_runs_and_windows_are_never_cut_to_the_shortest_run():
    # a 30-sample run beside a 200-sample one cut every window, "whole runs" included, to 30
    # samples (the long run became seven free runs restarted from the data); now each run is
    # whole at its own length, and a run shorter than a window is one window of its length
    log = _runs(long=_tanks(200, 0, 1.0, 1.0), short=_tanks(30, 1, 1.0, 1.0))
    model = _bare()
    whole = model._windows(log, None)
    assert whole.where == [(0, 0), (1, 0)] and whole.window_lengths == [30, 200]
    cut = model._windows(log, 100)
    assert cut.where == [(0, 0), (0, 99), (0, 100), (1, 0)] and cut.window_lengths == [30, 100]
    assert cut.groups[0].links.tolist() == [[0, 99, 1], [1, 1, 2]]
    # the fit trains on them and its stages say the lengths simulated, held-out ones too
    fitted = NeuralStateSpace(
        ["pump"], ["level"], hidden=2, warmup=5, windows=(100, None),
        trainer=LevenbergMarquardt(max_epochs=2),
    ).fit(log, _runs(a=_tanks(120, 2, 1.0, 1.0), b=_tanks(40, 3, 1.0, 1.0)))  # fmt: skip
    assert [s["window_lengths"] for s in fitted.stages_] == [[30, 100], [30, 200]]
    assert fitted.stages_[-1]["validation_window_lengths"] == [40, 120]


class _Keeps(LevenbergMarquardt):
    """Levenberg-Marquardt that keeps the module it trained (the windows' initial states)."""

    def fit(self, module, *args, **kwargs):
        self.module_ = module
        return super().fit(module, *args, **kwargs)


def test_a_weight_penalty_leaves_the_windows_initial_states_free():
    # l2 pulled the windows' free initial states toward 0 with the weights. Under a penalty
    # that holds the weights at 0 (the states do not move; no continuity links), each
    # window's start is the mean level of its window, which lies away from 0 (the training
    # mean, where the old penalty held them: |start| < 1e-4)
    log = _tanks(150, 0, 1.0, 1.0)
    model = NeuralStateSpace(
        ["pump"], ["level"], hidden=2, warmup=5, windows=(30,), continuity=0.0,
        trainer=_Keeps(max_epochs=5, l2=1e6), fractions=(1.0, 0.0, 0.0),
    ).fit(log)  # fmt: skip
    start = model.trainer_.module_.x0.detach()[:, 0].numpy()
    ((_, level, _),) = model._segments(log)
    means = [level[s : s + 30, 0].mean() for s in (0, 29, 58, 87, 116, 120)]
    assert min(np.abs(means)) > 0.1
    np.testing.assert_allclose(start, means, atol=1e-3)


def test_runs_too_short_for_the_warm_up_are_said():
    long, short = _tanks(120, 0, 1.0, 1.0), _tanks(8, 1, 1.0, 1.0)
    kw = dict(hidden=2, warmup=10, trainer=LevenbergMarquardt(max_epochs=1))
    said = r"1 training run no longer than the warm-up \(10 samples\) left out .*'short' \(8 sa"
    with pytest.warns(UserWarning, match=said):
        NeuralStateSpace(["pump"], ["level"], fractions=(1.0, 0.0, 0.0), **kw).fit(
            _runs(long=long, short=short)
        )
    # validation logs none of whose runs outlasts the warm-up: one run was trained on without
    # early stopping and without a word; two were refused as if the training log were short
    for validation in (short, _runs(a=short, b=short)):
        with pytest.warns(UserWarning, match="no run of the validation log .* without early"):
            model = NeuralStateSpace(["pump"], ["level"], **kw).fit(long, validation)
        assert model.validation_use is None and not model.history_[-1].validation


def test_the_training_windows_error_is_recorded_apart_from_the_objective():
    # one whole run, nothing held out: the objective is the windows' fit error alone
    model = NeuralStateSpace(
        ["pump"], ["level"], hidden=2, warmup=5, trainer=LevenbergMarquardt(max_epochs=2),
        fractions=(1.0, 0.0, 0.0),
    ).fit(_tanks(80, 0, 1.0, 1.0))  # fmt: skip
    (stage,) = model.stages_
    assert stage["train_windows_mse"] == pytest.approx(stage["train"][-1], rel=1e-9)


def test_train_bounds_that_cross_are_refused_naming_the_output():
    # a low above the training maximum's "train" high clamped every prediction to the high
    log = _tanks(60, 0, 1.0, 1.0)
    low = float(log["level"].min())
    assert low > 0.5
    model = NeuralStateSpace(
        ["pump"], ["level"], hidden=2, warmup=5, trainer=LevenbergMarquardt(max_epochs=1),
        output_bounds=[["train", 0.5]], fractions=(1.0, 0.0, 0.0),
    )  # fmt: skip
    with pytest.raises(NnidInputError, match=rf"of level: low {low:g} is not below high 0.5"):
        model.fit(log)


def test_cli_train_state_space_writes_contract_metrics(tmp_path):
    from typer.testing import CliRunner

    from nnid.cli import app

    runs = [_tanks(240, s, 1.0 + s, 1.0, noise=0.01).assign(experiment=f"run{s}") for s in range(4)]
    pd.concat(runs).to_csv(tmp_path / "tanks.csv", index=False)
    cfg = tmp_path / "tanks.toml"
    cfg.write_text(
        "warmup_s = 0.0\n"
        '[data]\nkind = "table"\nlog = "tanks.csv"\n'
        '[split]\nby = "experiment"\nvalidation = ["run2"]\ntest = ["run3"]\n'
        '[model]\nkind = "state_space"\ninputs = ["pump"]\noutputs = ["level"]\nhidden = 8\n'
        "structure = [[1, 1, 0], [0, 1, 1]]\nwindows = [40, 0]\nwarmup = 15\n"
        'output_bounds = [["open", "train"]]\n'
        '[model.trainer]\nkind = "lm"\nmax_epochs = 15\n'
    )
    runner = CliRunner()
    done = runner.invoke(app, ["train", str(cfg), "--out", str(tmp_path / "out")])
    assert done.exit_code == 0, done.output
    m = json.loads((tmp_path / "out/metrics.json").read_text())
    assert m["model"] == "state_space" and m["trainer"] == "lm"
    assert m["params"]["n_params"]["value"] == 4 * 8 + 16 + 16 + 2
    assert [s["window"] for s in m["describe"]["stages"]] == [40, None]
    assert m["validation"]["samples"] == 240 - 15
    # measured 0.037 on validation, 0.040 on test
    assert (
        m["validation"]["free_run_nrmse"]["total"] < 0.1
        and m["test"]["free_run_nrmse"]["total"] < 0.1
    )
    # the one-step error restarts from the measured level: far below the free run's
    assert m["test"]["one_step_nrmse"]["total"] < m["test"]["free_run_nrmse"]["total"]
    again = load_model(tmp_path / "out")
    assert again.bounds_[0][0] is None and again.windows_ == [40, None]
    # a model table without its outputs: one clear error naming the key, exit 2
    cfg.write_text(cfg.read_text().replace('outputs = ["level"]\n', ""))
    bad = runner.invoke(app, ["train", str(cfg), "--out", str(tmp_path / "bad")])
    assert bad.exit_code == 2 and "'model.outputs'" in bad.output


def test_cli_table_data_names_the_missing_column_and_the_bad_row(tmp_path):
    from typer.testing import CliRunner

    from nnid.cli import app

    log = _tanks(60, 0, 1.0, 1.0)
    log.drop(columns="pump").to_csv(tmp_path / "nopump.csv", index=False)
    log.loc[[7], "t"] = 3.0  # time goes back at row 7
    log.to_csv(tmp_path / "back.csv", index=False)
    cfg = tmp_path / "t.toml"
    cfg.write_text(
        '[data]\nkind = "table"\nlog = "nopump.csv"\n'
        '[model]\nkind = "state_space"\ninputs = ["pump"]\noutputs = ["level"]\n'
    )
    runner = CliRunner()
    done = runner.invoke(app, ["train", str(cfg), "--out", str(tmp_path / "o")])
    assert done.exit_code == 2 and "nopump.csv" in done.output and "pump" in done.output
    args = ["train", str(cfg), "--data", str(tmp_path / "back.csv"), "--out", str(tmp_path / "o")]
    done = runner.invoke(app, args)
    assert done.exit_code == 2 and "row 7" in done.output and "decreasing" in done.output


def test_cli_table_data_trains_a_narx_too(tmp_path):
    from typer.testing import CliRunner

    from nnid.cli import app

    runs = [_tanks(200, s, 1.0 + s, 1.0).assign(experiment=f"run{s}") for s in range(3)]
    pd.concat(runs).to_csv(tmp_path / "tanks.csv", index=False)
    cfg = tmp_path / "narx.toml"
    cfg.write_text(
        "warmup_s = 0.0\n"
        '[data]\nkind = "table"\nlog = "tanks.csv"\n'
        '[split]\nby = "experiment"\nvalidation = ["run2"]\n'
        '[model]\nkind = "narx"\ninputs = ["pump"]\noutputs = ["level"]\nhidden = [4]\n'
        'balanced = false\nsimulation_epochs = 3\nsimulation_trainer = "lm"\n'
        'simulation_window = 100\noutput_bounds = [["open", "train"]]\n'
        '[model.trainer]\nkind = "lm"\nmax_epochs = 20\n'
    )
    done = CliRunner().invoke(app, ["train", str(cfg), "--out", str(tmp_path / "out")])
    assert done.exit_code == 0, done.output
    m = json.loads((tmp_path / "out/metrics.json").read_text())
    assert m["model"] == "narx" and m["validation"]["samples"] == 200 - 2
    assert m["validation"]["one_step_nrmse"]["total"] < 0.1  # one step ahead on a smooth level
    saved = json.loads((tmp_path / "out/model.json").read_text())  # the options pass
    top = max(runs[0]["level"].max(), runs[1]["level"].max())  # the training runs' maximum
    assert saved["settings"]["simulation_trainer"] == "lm"
    assert saved["settings"]["output_bounds"] == [[None, "train"]]
    assert saved["state"]["bounds"][0][0] is None
    assert saved["state"]["bounds"][0][1] == pytest.approx(top, rel=1e-12)
    assert m["describe"]["simulation_finetune"]["epochs"] >= 1


def test_adam_trains_the_same_model():
    # the trainer is pluggable: Adam on the same windows and residual lowers the held-out
    # free-run error from that of the untrained model (measured 0.95 -> 0.16 with 150 epochs)
    from nnid.trainers.adam import Adam

    train, test = _tanks(400, 0, 1.0, 1.0, noise=0.01), _tanks(300, 7, 0.2, 3.0)
    kw = dict(hidden=8, structure=CASCADE, warmup=20, windows=(40, None), fractions=(0.8, 0.2, 0))
    untrained = NeuralStateSpace(["pump"], ["level"], trainer=Adam(max_epochs=1, lr=1e-9), **kw)
    before = untrained.fit(train).score(test)["level"]
    model = NeuralStateSpace(["pump"], ["level"], trainer=Adam(lr=1e-2, max_epochs=150), **kw)
    after = model.fit(train).score(test)["level"]
    assert after < 0.5 * before and after < 0.3


@pytest.mark.parametrize(
    ("inputs", "outputs", "field"),
    [([0], ["level"], "inputs.0"), ((["pump"],), ["level"], "inputs.0"),
     (["pump"], [["level"]], "outputs.0"), (["pump"], ["level", "level"], "outputs"),
     (["pump"], 3, "outputs")],
)  # fmt: skip
def test_columns_that_are_not_names_are_refused_naming_the_setting(inputs, outputs, field):
    """Settings given in Python skip the config's checks: a list of ints or a tuple holding a
    list failed deep in the fit with "unhashable type: 'list'" (or, a log having a column 0,
    trained on it). Now one error naming the setting and the entry."""
    log = _tanks(50, 0, 1.0, 1.0).assign(**{"0": 0.0}).rename(columns={"0": 0})
    with pytest.raises(NnidInputError) as err:
        NeuralStateSpace(inputs, outputs, warmup=5).fit(log)
    assert err.value.field == field
    # one string is one column (was list("pump"): the columns p, u, m, p)
    model = NeuralStateSpace("pump", "level", warmup=5)
    model._configure()
    assert (model.inputs_, model.outputs_) == (["pump"], ["level"])


@pytest.mark.parametrize(
    ("hidden", "says"),
    [(1.5, "a whole number"), (float("nan"), "a whole number"), (0, "at least 1"),
     (200_000, "at most 100000"), ("8", "a whole number")],
)  # fmt: skip
def test_the_width_given_in_python_is_checked_and_capped_as_the_config_does(hidden, says):
    """Given in Python, ``hidden`` skipped the config's checks: 1.5 trained one unit wide
    (``int``), NaN passed ``hidden < 1`` and was a bare ValueError, 200 000 (over the
    config's MAX_WIDTH, a typo) built the layer, and 0 was named 'state_space'."""
    with pytest.raises(NnidInputError, match=rf"^field 'hidden': .*{says}"):
        NeuralStateSpace(["pump"], ["level"], hidden=hidden, warmup=5).fit(_tanks(50, 0, 1, 1))


@pytest.mark.parametrize(
    ("setting", "value"),
    [("hidden_states", 1.5), ("hidden_states", -1), ("substeps", float("nan")),
     ("substeps", 0), ("warmup", 2.5)],
)  # fmt: skip
def test_the_state_settings_given_in_python_are_whole_and_named(setting, value):
    """``hidden_states``, ``substeps`` and ``warmup`` given in Python passed 1.5 and NaN
    (``nan < 1`` is False) and a bad one was named 'state_space' for all three."""
    given = {"hidden": 4, "warmup": 5, setting: value}
    with pytest.raises(NnidInputError, match=rf"^field '{setting}': a whole number"):
        NeuralStateSpace(["pump"], ["level"], **given).fit(_tanks(50, 0, 1, 1))


@pytest.mark.parametrize(
    ("setting", "value", "says"),
    [("continuity", float("nan"), "a finite number"), ("continuity", -1.0, "at least 0"),
     ("state_epochs", 0, "a whole number"), ("state_epochs", 2.5, "a whole number"),
     ("windows", (12.7,), "a whole number"), ("windows", (None, float("nan")), "a whole number"),
     ("inputs", ["pump", "level"], "an output and an input")],
)  # fmt: skip
def test_the_training_settings_given_in_python_are_checked_as_the_config_does(setting, value, says):
    """Given in Python, a NaN ``continuity`` stopped Levenberg-Marquardt at its first epoch
    and returned the initial weights without an error, a negative one made the links' weight
    complex, ``state_epochs`` was checked only at prediction, a 12.7-sample window trained 12
    long, and an output read as an input was fitted. Each is refused as the fit starts."""
    given = {"inputs": ["pump"], "outputs": ["level"], "hidden": 2, "warmup": 5}
    model = NeuralStateSpace(**given, trainer=LevenbergMarquardt(max_epochs=1)).set_params(
        **{setting: value}
    )
    with pytest.raises(NnidInputError, match=rf"^field '{setting}': .*{says}"):
        model.fit(_tanks(50, 0, 1.0, 1.0))
