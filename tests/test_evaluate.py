"""Scores of a split of several runs: each run's free-run NRMSE on its own beside the pooled one
(``nnid.evaluation.evaluate``), and the train report's tables: those scores, and how each
training stage ended."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from nnid.evaluation.evaluate import evaluate
from nnid.models.base import NnidModel
from nnid.reports.stops import DROPPED, STILL_FALLING, STOP_WORDS, TRAINING_TITLE, UNDONE
from nnid.reports.train_report import RUNS_TITLE, _training, train_html, train_markdown


class Shifted(NnidModel):
    """A stand-in model: predicts the measured ``y`` plus 1 after one warm-up sample."""

    kind = "shifted"

    def _fit(self, log, validation, progress):
        self.outputs_ = self.targets_ = ["y"]
        self.warmup_samples_ = 1

    def _predict(self, log, mode):
        out = log[["y"]].astype(float) + 1.0
        out.iloc[0] = np.nan
        return out

    def _params(self):
        return {}

    def _state(self):
        return {}, {}

    def _restore(self, state, tensors):
        pass


@pytest.fixture
def runs() -> pd.DataFrame:
    # a run that moves y by ±10 and one that moves it by ±0.1: the same error of 1 is small in
    # the first and 14x the second's spread
    t = np.arange(300) * 0.1
    big = pd.DataFrame({"t": t, "y": 10 * np.sin(t), "experiment": "big"})
    small = pd.DataFrame({"t": t, "y": 0.1 * np.sin(t), "experiment": "small"})
    return pd.concat([big, small], ignore_index=True)


def test_each_run_is_scored_as_alone_and_the_pooled_score_hides_the_failing_one(runs):
    model = Shifted().fit(runs)
    scores = evaluate(model, runs, ("free_run",), warmup_s=1.0)
    per = scores["free_run_nrmse_per_experiment"]
    assert list(per) == ["big", "small"]
    for name, group in runs.groupby("experiment"):
        alone = evaluate(model, group.reset_index(drop=True), ("free_run",), warmup_s=1.0)
        assert "free_run_nrmse_per_experiment" not in alone  # one run: the pooled score is it
        assert per[name] == pytest.approx(alone["free_run_nrmse"], rel=1e-12)
        # an error of 1 over each run's own std (scored after the first second)
        y = group["y"].to_numpy()[10:]
        assert per[name]["y"] == pytest.approx(1.0 / y.std(), rel=1e-9)
    assert scores["free_run_nrmse"]["y"] < 0.2 < 10 < per["small"]["y"]


class RunsAway(Shifted):
    """Shifted, but ``off`` more in run "small" (5: 25 times that run's range, a quarter of
    the split's)."""

    kind = "runs_away"
    off = 5.0

    def _predict(self, log, mode):
        out = super()._predict(log, mode)
        out.loc[log["experiment"] == "small", "y"] += self.off
        return out


class SwayAway(Shifted):
    """Predicts u and v: u within 2 %, v (which the data barely moves) drifting to ``v_end``."""

    kind = "sway_away"
    v_end = 1e6

    def _fit(self, log, validation, progress):
        self.outputs_ = self.targets_ = ["u", "v"]
        self.warmup_samples_ = 0

    def _predict(self, log, mode):
        return pd.DataFrame(
            {"u": 1.02 * log["u"], "v": np.linspace(0.0, self.v_end, len(log))}, index=log.index
        )


@pytest.mark.parametrize(("v_end", "gone"), [(1e6, True), (np.inf, True), (0.5, False)])
def test_a_target_the_data_barely_moves_is_still_checked_for_divergence(v_end, gone):
    """v is not scored (its std is a thirtieth of u's): its NRMSE would divide by noise. Its
    free run leaving for 1e6 m/s was not checked either, and the total over u stayed finite.
    Against u's range it has diverged; a sway of 0.5 m/s (under 10 u-ranges) is coupling."""
    t = np.arange(0, 60, 0.1)
    noise = np.random.default_rng(0).normal(0, 0.01, t.size)
    log = pd.DataFrame({"t": t, "u": 0.3 * np.sin(0.5 * t), "v": noise})
    model = SwayAway().fit(log)
    model.v_end = v_end
    scores = evaluate(model, log, ("free_run",))
    assert scores["columns"] == ["u"] and scores["free_run_nrmse"]["u"] == pytest.approx(
        0.02, rel=0.01
    )
    assert ("v" in scores["diverged"]) is gone
    assert (scores["free_run_nrmse"]["total"] is None) is gone


def test_a_run_that_diverges_is_not_averaged_into_the_pooled_score(runs):
    """A miss of 5 in run small is 25 of its ranges but a quarter of the split's: a poor
    prediction, shown by small's own NRMSE, and no divergence (a run's own range is noise
    where it barely moves the output). A miss of 205 is inside the split's bounds widened
    by 10 of its ranges (±210), so the pooled score alone reads it as finite, but 10 split
    ranges beyond small's own values: the pooled column and total are None and the run is
    named, in every mode, as ARCHITECTURE's JSON rule says of a diverged free run."""
    from nnid.evaluation.evaluate import score_prediction

    model = RunsAway().fit(runs)
    poor = evaluate(model, runs, ("one_step", "free_run"), warmup_s=1.0)
    small = runs.loc[runs["experiment"] == "small", "y"].to_numpy()[10:]
    per = poor["free_run_nrmse_per_experiment"]
    assert per["small"]["y"] == pytest.approx(6.0 / small.std(), rel=1e-9)
    # pooled: the RMS of the error over both runs' scored rows (1 in big, 1 + off in small)
    # over the std of the pooled measured values there, by hand; one column: total = y's
    big = runs.loc[runs["experiment"] == "big", "y"].to_numpy()[10:]
    pooled = np.r_[big, small]

    def pooled_nrmse(off):
        err = np.r_[np.ones(big.size), np.full(small.size, 1.0 + off)]
        return np.sqrt(np.mean(err**2)) / pooled.std()

    expected = pooled_nrmse(5.0)
    assert poor["free_run_nrmse"] == pytest.approx({"y": expected, "total": expected}, rel=1e-9)
    assert poor["one_step_nrmse"] == pytest.approx({"y": expected, "total": expected}, rel=1e-9)
    assert not poor["diverged"]
    assert "diverged_per_experiment" not in poor
    model.off = 205.0
    scores = evaluate(model, runs, ("one_step", "free_run"), warmup_s=1.0)
    pred = model.predict(runs, "free_run")
    mask = np.arange(len(runs)) % 300 >= 10  # after each run's first second
    # pooled alone it reads as finite: the same hand computation with a miss of 205
    alone = score_prediction(runs, pred, ["y"], mask)[0]
    assert alone["total"] == pytest.approx(pooled_nrmse(205.0), rel=1e-9) == alone["y"]
    assert scores["free_run_nrmse"] == {"y": None, "total": None}
    assert scores["free_run_rmse"]["total"] is None and "y" in scores["diverged"]
    assert list(scores["diverged_per_experiment"]) == ["small"]
    # the healthy run keeps its own score: 1 over its std, as scored alone
    per = scores["free_run_nrmse_per_experiment"]
    assert per["big"]["y"] == pytest.approx(1.0 / big.std(), rel=1e-9)
    assert scores["one_step_nrmse"]["total"] is None and "y" in scores["one_step_diverged"]
    healthy = evaluate(Shifted().fit(runs), runs, ("free_run",), warmup_s=1.0)
    assert healthy["free_run_nrmse"]["total"] == pytest.approx(pooled_nrmse(0.0), rel=1e-9)
    assert not healthy["diverged"]
    assert "diverged_per_experiment" not in healthy


def test_a_calm_run_is_judged_for_divergence_by_the_splits_range():
    """A hover's smoothed w spans 0.002 m/s: judged by that range, a model drifting
    0.02 m/s had diverged, which voided the split's pooled w and total (compare ranked the
    model last, "Diverged in free run"). It is judged by the split's range now; its own NRMSE
    is unchanged, and a prediction that really leaves the physical range still diverges."""
    from nnid.evaluation.evaluate import score_split

    t = np.arange(400) * 0.1
    log = pd.DataFrame(
        {
            "t": np.r_[t, t],
            "experiment": ["dive"] * 400 + ["hover"] * 400,
            "w": np.r_[0.5 * np.sin(t), 0.001 * np.sin(3 * t)],
        }
    )
    hover = log["experiment"].to_numpy() == "hover"
    mask = np.ones(len(log), bool)
    for drift, diverges in ((0.02, False), (1e3, True), (np.inf, True)):
        pred = log[["w"]] + np.where(hover, drift, 0.0)[:, None]
        nrmse, _, diverged, runs, left = score_split(log, pred, ["w"], mask, lambda r: ["w"])
        assert ("hover" in left) is diverges and (nrmse["total"] is None) is diverges, drift
        assert bool(diverged) is diverges and "dive" not in left
    w = log.loc[hover, "w"].to_numpy()
    pred = log[["w"]] + np.where(hover, 0.02, 0.0)[:, None]
    runs = score_split(log, pred, ["w"], mask, lambda r: ["w"])[3]
    assert runs["hover"]["w"] == pytest.approx(0.02 / w.std(), rel=1e-9)  # as scored alone


def test_a_runs_pieces_are_scored_as_that_run_not_as_runs_of_their_own():
    """A gap cut run 'dive' into pieces dive#0 and dive#1: each piece was scored, and counted
    (compare's verdict, the per-run tables), as a held-out run. The pieces' squared errors
    are pooled into their run's score; one run in pieces has no per-run score at all."""
    from nnid.datasets.log import PIECE_OF
    from nnid.evaluation.evaluate import score_prediction, score_split

    t = np.arange(300) * 0.1
    log = pd.DataFrame(
        {
            "t": t,
            "experiment": ["dive#0"] * 100 + ["dive#1"] * 100 + ["hover"] * 100,
            PIECE_OF: ["dive"] * 200 + [None] * 100,
            "w": np.sin(t) * np.r_[np.ones(100), 2 * np.ones(100), 0.5 * np.ones(100)],
        }
    )
    pred = (
        log[["w"]] + np.r_[0.01 * np.ones(100), 0.05 * np.ones(100), 0.02 * np.ones(100)][:, None]
    )
    mask = np.ones(len(log), bool)
    runs = score_split(log, pred, ["w"], mask, lambda r: ["w"])[3]
    assert list(runs) == ["dive", "hover"]
    dive = score_prediction(log.iloc[:200], pred.iloc[:200], ["w"], mask[:200])[0]
    assert runs["dive"]["w"] == pytest.approx(dive["w"], rel=1e-12)
    one = log.iloc[:200]
    assert score_split(one, pred.iloc[:200], ["w"], mask[:200], lambda r: ["w"])[3] == {}


def test_the_train_report_lists_each_held_out_run(runs):
    model = Shifted().fit(runs)
    held = evaluate(model, runs, ("free_run",), warmup_s=1.0)
    metrics = {"model": "shifted", "params": {}, "seconds": 0.0, "validation": held}
    text = train_markdown(metrics)
    section = text[text.index(RUNS_TITLE) :]
    small = next(line for line in section.splitlines() if "| small |" in line)
    assert f"{held['free_run_nrmse_per_experiment']['small']['y']:.3g}" in small
    assert "| validation | big |" in section
    page = train_html({**metrics, "n_params": 0})
    assert RUNS_TITLE in page and "<td>small</td>" in page


def test_the_train_report_says_which_stage_stalled_diverged_or_was_undone():
    # an ensemble of two NARX members (one's free-run stage stalled on LM's μ and was undone)
    # and a third dropped for a diverged validation free run, beside a neural state-space
    # model's windows and a hybrid's segments: every stage is a row, a stop that is not
    # convergence reads as such, and a stage that spent its budget says whether it was still
    # improving at the end (kept epoch = last) or had levelled off
    first = {
        "history": {"epochs": 100, "stop_reason": "max_epochs", "best_epoch": 100},
        "simulation_finetune": {
            "stages": [
                {"window": 100, "epochs": 9, "best_epoch": 3, "stop_reason": "validation"},
                {"window": 500, "epochs": 2, "best_epoch": 1, "stop_reason": "mu_max"},
            ],
            "epochs": 11, "kept": False,
        },
    }  # fmt: skip
    second = {
        "history": {"epochs": 40, "stop_reason": "max_epochs", "best_epoch": 31},
        "simulation_finetune": None,
    }
    ensemble = {
        "describe": {
            "member_seeds": [3, 7], "members": [first, second],
            "dropped_seeds_diverged_on_validation": [5],
        }
    }  # fmt: skip
    head, rows = _training(ensemble)
    assert head == ["member", "stage", "epochs", "kept epoch", "how it ended"]
    assert rows == [
        ["seed 3", "one-step", "100", "100", STOP_WORDS["max_epochs"] + STILL_FALLING],
        ["seed 3", "free run, 100-sample windows", "9", "3", STOP_WORDS["validation"]],
        ["seed 3", "free run, 500-sample windows", "2", "1", STOP_WORDS["mu_max"]],
        ["seed 3", "free run", "11", "0", UNDONE],
        ["seed 7", "one-step", "40", "31", STOP_WORDS["max_epochs"]],
        ["seed 5", "whole fit", "-", "-", DROPPED],
    ]
    assert "stalled" in STOP_WORDS["mu_max"] and "diverged" in STOP_WORDS["non-finite loss"]
    # a model saved before the kept epochs were recorded: a dash, not a guess
    old = {"history": {"epochs": 8, "stop_reason": "max_epochs"}, "simulation_finetune": None}
    assert _training({"describe": old})[1] == [["one-step", "8", "-", STOP_WORDS["max_epochs"]]]
    staged = {
        "describe": {
            "stages": [
                {"window": 64, "epochs": 30, "stop_reason": "max_epochs", "best_epoch": 30},
                {"window": None, "epochs": 3, "stop_reason": "non-finite loss", "best_epoch": 2},
                {"segment_s": 2.0, "epochs": 12, "stop_reason": "validation"},
            ]
        }
    }
    head, rows = _training(staged)
    assert head == ["stage", "epochs", "kept epoch", "how it ended"]
    assert [r[:3] for r in rows] == [["window 64", "30", "30"], ["window whole runs", "3", "2"],
                                     ["segments of 2.0 s", "12", "-"]]  # fmt: skip
    assert rows[0][3] == STOP_WORDS["max_epochs"] + STILL_FALLING
    # a hybrid's segment asked longer than every run trains on the longest run: said
    capped = {"describe": {"stages": [{"segment_s": 100.0, "segment_s_trained": 24.0,
                                       "epochs": 3, "stop_reason": "max_epochs"}]}}  # fmt: skip
    assert _training(capped)[1][0][0] == "segments of 100.0 s (the longest run, 24 s)"
    assert rows[1][3] == STOP_WORDS["non-finite loss"]
    text = train_markdown({"model": "nss", "params": {}, "seconds": 0.0, **staged})
    assert f"## {TRAINING_TITLE}" in text and "| window whole runs | 3 | 2 | diverged" in text
    page = train_html({"model": "nss", "params": {}, "seconds": 0.0, "n_params": 0, **staged})
    assert TRAINING_TITLE in page and "<td>window whole runs</td>" in page
    # a model with no iterative stages (least squares) gets no section
    assert TRAINING_TITLE not in train_markdown({"model": "ls", "params": {}, "seconds": 0.0})


def test_a_run_diverging_in_a_column_the_pooled_score_leaves_out_does_not_void_it():
    """Run "sway" moves v slowly and its prediction of v runs away; pooled, v is not excited
    (a tenth of the surge run's u) and not scored: the pooled total stays, the run is named."""
    from nnid.evaluation.evaluate import score_split

    t = np.arange(300) * 0.1
    surge = pd.DataFrame({"t": t, "u": np.sin(t), "v": 0.0, "experiment": "surge"})
    sway = pd.DataFrame({"t": t, "u": 0.0, "v": 0.01 * np.sin(t), "experiment": "sway"})
    log = pd.concat([surge, sway], ignore_index=True)
    pred = log[["u", "v"]].copy()
    pred.loc[log["experiment"] == "sway", "v"] += 5.0
    mask = np.ones(len(log), bool)
    nrmse, _, diverged, runs, left = score_split(
        log, pred, ["u"], mask, lambda run: [c for c in "uv" if run[c].std() > 0]
    )
    assert nrmse == {"u": 0.0, "total": 0.0} and diverged == {}
    assert list(left) == ["sway"] and runs["sway"]["v"] is None


def test_k_step_scores_say_they_are_taken_over_fewer_samples(runs):
    """Each run's first k - 1 predictions after the warm-up need k steps of history, so the
    k-step scores are taken over fewer samples than the free run's; the header gave only the
    free run's count, as if both were over the same rows."""
    model = Shifted().fit(runs)
    held = evaluate(model, runs, ("free_run", "k_step"), k_step=15, warmup_s=1.0)
    # per run the free run skips the first 10 samples (1 s), the k-step the first 15
    assert held["k_step_scored"] == held["samples"] - 2 * 5
    metrics = {"model": "shifted", "params": {}, "seconds": 0.0, "warmup_s": 1.0}
    text = train_markdown({**metrics, "validation": held})
    assert f"{held['samples']} samples scored" in text
    assert f"k-step: {held['k_step_scored']} samples" in text


def test_force_scores_take_j_and_j0_over_the_same_samples():
    """McCarter's J/J₀ (eqs 4.25, 4.4) is a ratio of errors over one set of samples: rows where
    the residual is undefined were dropped from J only, so J₀ took in rows J never saw."""
    from types import SimpleNamespace

    from nnid.evaluation.evaluate import force_scores

    n = 200
    series = pd.DataFrame({"X": np.r_[np.full(100, 1.0), np.full(100, 10.0)]})
    resid = pd.DataFrame({"X": np.r_[np.full(100, 0.1), np.full(100, np.nan)]})
    model = SimpleNamespace(residual=lambda log: resid, force_series=lambda log: series)
    out = force_scores(model, pd.DataFrame({"t": np.arange(n)}), np.ones(n, bool))
    assert out["J"] == pytest.approx(0.1) and out["J0"] == pytest.approx(1.0)
    assert out["J_over_J0"] == pytest.approx(0.1)  # was 0.1 / 7.1


def test_a_run_with_one_scored_sample_is_judged_by_the_splits_range():
    """A piece of a run cut at gaps with one sample after the warm-up has a range of 0, so
    an error of 6 mm/s read as a divergence and voided the whole split's scores (a least-
    squares fit's train and validation alike); it is judged by the split's range now, and a
    prediction that really leaves that range still diverges."""
    from nnid.evaluation.evaluate import score_split

    t = np.r_[np.arange(400) * 0.05, np.arange(3) * 0.05]
    log = pd.DataFrame(
        {
            "t": t,
            "experiment": ["run5#1"] * 400 + ["run5#2"] * 3,
            "u": np.r_[np.sin(np.arange(400) * 0.05), 0.3, 0.3, 0.3],
        }
    )
    mask = np.r_[np.ones(400, bool), False, False, True]
    for error, diverges in ((0.006, False), (50.0, True)):
        pred = log[["u"]].copy()
        pred.iloc[-1, 0] += error
        nrmse, _, diverged, _, _ = score_split(log, pred, ["u"], mask, lambda r: ["u"])
        assert bool(diverged) is diverges and (nrmse["total"] is None) is diverges, error
    # a split that is one such run: pooled, the same rule (the whole run's range)
    one = pd.DataFrame({"t": t[:25], "experiment": "run9", "u": np.r_[np.sin(t[:24]), 0.3]})
    alone = np.r_[np.zeros(24, bool), True]
    pred = one[["u"]].copy()
    pred.iloc[-1, 0] += 0.006
    _, rmse, diverged, _, _ = score_split(one, pred, ["u"], alone, lambda r: ["u"])
    assert diverged == {} and rmse["u"] == pytest.approx(0.006)  # (one sample has no NRMSE)


def test_metrics_nrmse_does_not_score_a_prediction_that_diverged():
    """``metrics.nrmse`` (the docs' attitude protocol scores with it) dropped the samples where
    the prediction was not finite: a free run that left for NaN half-way scored 0.075, about
    the 0.071 of the one that did not, and ``per_dof``'s total averaged the columns left."""
    from nnid.evaluation.metrics import nrmse, per_dof

    y = np.sin(np.linspace(0.0, 20.0, 400))
    gone = y + 0.05
    gone[200:] = np.nan
    assert np.isfinite(nrmse(y, y + 0.05))
    assert np.isnan(nrmse(y, gone))
    assert np.isnan(nrmse(y, np.where(np.arange(400) < 300, y, np.inf)))
    # a sample the log lacks is not scored, whatever the prediction there
    missing = y.copy()
    missing[7] = np.nan
    assert nrmse(missing, np.where(np.isnan(missing), np.nan, y + 0.05)) == pytest.approx(
        nrmse(np.delete(y, 7), np.delete(y, 7) + 0.05), rel=1e-12
    )
    measured = pd.DataFrame({"u": y, "r": y})
    scores = per_dof(measured, pd.DataFrame({"u": y + 0.05, "r": gone}), ["u", "r"],
                     np.ones(400, bool))  # fmt: skip
    assert np.isfinite(scores["u"]) and np.isnan(scores["r"]) and np.isnan(scores["total"])


def test_metrics_rmse_does_not_score_a_prediction_that_diverged():
    """``metrics.rmse`` dropped every non-finite error, a diverged prediction's too: a free
    run that left for NaN half-way scored as the one that did not. It is NaN now, as
    ``nrmse``; a sample the log lacks is still not scored."""
    from nnid.evaluation.metrics import rmse

    y = np.sin(np.linspace(0.0, 20.0, 400))
    gone = y + 0.05
    gone[200:] = np.nan
    assert rmse(y, y + 0.05) == pytest.approx(0.05, rel=1e-12)
    assert np.isnan(rmse(y, gone)) and np.isnan(rmse(y, np.where(y > 0.9, np.inf, y)))
    missing = np.where(np.arange(400) == 7, np.nan, y)
    assert rmse(missing, np.where(np.isnan(missing), np.nan, y + 0.05)) == pytest.approx(0.05)


class Echo(Shifted):
    """Predicts u and v: the measured values plus 0.01 (NaN where the log has none)."""

    kind = "echo"

    def _fit(self, log, validation, progress):
        self.outputs_ = self.targets_ = ["u", "v"]
        self.warmup_samples_ = 1

    def _predict(self, log, mode):
        out = log[["u", "v"]].astype(float) + 0.01
        out.iloc[0] = np.nan
        return out


@pytest.mark.parametrize("v_scale", [1e-3, 1.0])
def test_a_sample_the_log_lacks_is_no_divergence_of_an_unscored_target(v_scale):
    """One missing sample of v (NaN, and so the one-step prediction from it) is skipped where v
    is scored; where the data barely moves v (not scored), the divergence check of the
    unscored targets called it a divergence at t = 15 s and voided the total."""
    t = np.arange(300) * 0.1
    log = pd.DataFrame({"t": t, "u": np.sin(t), "v": v_scale * np.cos(0.7 * t)})
    log.loc[150, "v"] = np.nan
    scores = evaluate(Echo().fit(log), log, ("one_step", "free_run"))
    assert scores["columns"] == (["u"] if v_scale < 0.1 else ["u", "v"])
    for mode in ("one_step", "free_run"):
        key = "diverged" if mode == "free_run" else f"{mode}_diverged"
        assert scores[key] == {}
        # the prediction is the measurement + 0.01: each scored column's NRMSE is 0.01 / std
        expected = np.mean([0.01 / log[c].iloc[1:].std() for c in scores["columns"]])
        assert scores[f"{mode}_nrmse"]["total"] == pytest.approx(expected, rel=0.02)


def test_runs_joined_without_a_fresh_index_are_refused_before_scoring(runs):
    """pd.concat([big, small]) gives each label to two rows; each run's scored rows and
    prediction were found by label. One clear error saying the fix, before any scoring."""
    from nnid.errors import NnidInputError

    model = Shifted().fit(runs)
    twice = pd.concat([g for _, g in runs.groupby("experiment")]).set_axis(
        np.r_[np.arange(300), np.arange(300)]
    )
    with pytest.raises(NnidInputError, match=r"repeats 300 labels.*reset_index\(drop=True\)"):
        evaluate(model, twice, ("free_run",), warmup_s=1.0)


def test_scoring_finds_each_runs_rows_by_position_where_labels_repeat(runs):
    """The warm-up mask, the blanked initial conditions and each run's own scores on runs
    joined without a fresh index (each label twice): found by label, they failed on the
    repeated labels. By position, each is what the same log with a fresh index gives."""
    from nnid.evaluation.evaluate import score_runs
    from nnid.evaluation.metrics import warmup_mask
    from nnid.evaluation.prediction import blank_initial

    big, small = (g.reset_index(drop=True) for _, g in runs.groupby("experiment"))
    twice = pd.concat([big, small.iloc[:200]])  # labels 0..199 name a row of each run
    fresh = twice.reset_index(drop=True)
    mask = warmup_mask(twice, 1.0, 3)
    np.testing.assert_array_equal(mask, warmup_mask(fresh, 1.0, 3))
    assert mask.sum() == 290 + 190  # each run's first second (10 samples) out
    predicted = twice[["y"]] + 1.0
    blanked = blank_initial(predicted, twice, 2)
    assert blanked.index.equals(twice.index)  # on the log's own labels
    np.testing.assert_array_equal(
        blanked.to_numpy(), blank_initial(predicted.reset_index(drop=True), fresh, 2).to_numpy()
    )
    scores = score_runs(twice, predicted, mask, lambda run: ["y"])
    assert scores == score_runs(fresh, predicted.reset_index(drop=True), mask, lambda r: ["y"])
    assert scores[0]["small"]["y"] > 10 * scores[0]["big"]["y"]  # each run over its own std


def test_a_closed_loop_replay_refuses_repeated_labels_naming_the_table():
    """A split's rows take the replay's open-loop inputs by label (the split is a subset of
    the log the replay was made for): where either index repeats a label, a row took the
    inputs of several (or of another run's row). Refused, naming which index repeats."""
    from nnid.datasets.log import TAU
    from nnid.errors import NnidInputError
    from nnid.evaluation.prediction import Replay, fly_closed_loop

    def stepper(starts, dt):
        raise AssertionError("nothing is flown")

    t = 0.1 * np.arange(20)
    run = pd.DataFrame({"t": t, **{c: 0.0 for c in ("x", "y", "z", "phi", "theta", "psi")},
                        **{c: 0.1 for c in ("u", "v", "w", "p", "q", "r")},
                        **{c: 1.0 for c in TAU}})  # fmt: skip
    joined = pd.concat([run.assign(experiment="a"), run.assign(experiment="b")])
    fresh = joined.reset_index(drop=True)
    with pytest.raises(NnidInputError, match=r"^the log's index repeats 20 labels \(the first"):
        fly_closed_loop(joined, Replay(None, fresh[list(TAU)]), stepper)
    with pytest.raises(
        NnidInputError, match=r"^the index of the replay's open-loop inputs repeats 20 labels"
    ):
        fly_closed_loop(fresh, Replay(None, joined[list(TAU)]), stepper)


def test_a_physics_models_substeps_read_its_runs_step_without_the_joins():
    """Two runs of 120 Hz stamped in whole ms, t restarting at 0: read over the whole log, the
    negative step at the join took the rounded clock off its line and the sub-steps came from
    the 8-ms median (2 of 4 ms) where each run alone steps 8.33 ms (3 of at most 4 ms). A log
    in which no run has two samples is still stepped once a sample."""
    from nnid.evaluation.prediction import substeps_for

    t = np.round(np.arange(360) / 120.0 * 1e3) / 1e3  # 8, 8, 9 ms steps
    run = pd.DataFrame({"t": t})
    log = pd.concat([run.assign(experiment=name) for name in ("a", "b")], ignore_index=True)
    assert substeps_for(run, max_step=0.004) == 3  # ceil(8.33 / 4): one run alone
    assert substeps_for(log, max_step=0.004) == 3
    singles = pd.DataFrame({"t": [0.0, 0.0], "experiment": ["a", "b"]})
    assert substeps_for(singles) == substeps_for(run.iloc[:1]) == 1
