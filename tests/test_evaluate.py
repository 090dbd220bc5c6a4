"""Scores of a split of several runs: each run's free-run NRMSE on its own beside the pooled one
(``nnid.evaluation.evaluate``), and the train report's table of them."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from nnid.evaluation.evaluate import evaluate
from nnid.models.base import NnidModel
from nnid.reports.train_report import RUNS_TITLE, train_html, train_markdown


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
