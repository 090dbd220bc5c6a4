"""Seed ensembles (issue 14, "ensembles with a documented selection rule"): the pointwise
combination of members fitted once per seed, the members that diverge on the validation run
left out, the config table and ``nnid train`` with the members' spread in ``metrics.json``."""

from __future__ import annotations

import json
import re
import signal
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from conftest import child_pids, cmdline, needs_proc, stop_cli
from typer.testing import CliRunner

from nnid import load_model
from nnid.cli import app
from nnid.config import TrainConfig, load_config
from nnid.errors import NnidInputError
from nnid.models.base import NnidModel
from nnid.models.ensemble import EnsembleModel
from nnid.models.narx import NarxModel
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

ROOT = Path(__file__).resolve().parents[1]
SIM = ROOT / "configs/seamor_sequence_narx.toml"


class Offset(NnidModel):
    """A stand-in member: predicts the measured ``y`` plus its seed (1e9 for seed 99, which
    the divergence rule of the scores catches)."""

    kind = "offset"

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed

    def _fit(self, log, validation, progress):
        self.outputs_ = self.targets_ = ["y"]
        self.warmup_samples_ = 1
        self.offset_ = 1e9 if self.seed == 99 else float(self.seed)

    def _predict(self, log, mode):
        out = log[["y"]].astype(float) + self.offset_
        out.iloc[0] = np.nan
        return out

    def _params(self):
        return {"offset": {"value": self.offset_, "stderr": None}}

    def _state(self):
        return {"offset": self.offset_}, {}

    def _restore(self, state, tensors):
        self.offset_ = state["offset"]


@pytest.fixture
def log() -> pd.DataFrame:
    t = np.arange(200) * 0.1
    return pd.DataFrame({"t": t, "y": np.sin(t)})


@pytest.mark.parametrize(("combine", "shift"), [("mean", 2.0), ("median", 1.0)])
def test_members_combine_pointwise(log, combine, shift):
    model = EnsembleModel(Offset(), seeds=(0, 1, 5), combine=combine).fit(log)
    pred = model.predict(log)
    assert np.isnan(pred["y"].iloc[0])
    np.testing.assert_allclose(pred["y"].iloc[1:], log["y"].iloc[1:] + shift)
    assert [m.offset_ for m in model.members_] == [0.0, 1.0, 5.0]
    assert model.member_validation_ == [None, None, None]  # no validation log: not scored


def test_a_member_diverging_on_validation_is_dropped_and_said(log):
    model = EnsembleModel(Offset(), seeds=(0, 99, 2)).fit(log, log)
    assert model.member_seeds_ == [0, 2] and model.dropped_ == [99]
    np.testing.assert_allclose(model.predict(log)["y"].iloc[1:], log["y"].iloc[1:] + 1.0)
    # the validation free-run NRMSE of a constant offset c is c / std(y) (warm-up unscored)
    std = log["y"].iloc[1:].std(ddof=0)
    np.testing.assert_allclose(model.member_validation_, [0.0, 2.0 / std], atol=1e-12)
    assert model.describe()["dropped_seeds_diverged_on_validation"] == [99]
    assert "dropping diverged members" in model.validation_use
    kept = EnsembleModel(Offset(), seeds=(0, 99), drop_diverged=False).fit(log, log)
    assert kept.member_seeds_ == [0, 99] and kept.member_validation_[1] is None
    assert kept.validation_use is None


def test_the_median_is_undetermined_by_a_nan_member_and_ranks_a_wild_one(log):
    """The documented rule (module docstring): every kept member is combined. A NaN member
    has no rank, so the median is NaN there (scored as a divergence, never a median of the
    other members in silence); one at 1e9 or inf is ranked, as the median rule ranks it."""
    model = EnsembleModel(Offset(), seeds=(0, 1, 5), combine="median").fit(log)
    base = pd.DataFrame({"y": [0.0, 1.0]}, index=[0, 1])
    wild = [base, base + 1.0, base + 2.0, base + 3.0, base.assign(y=[np.nan, 1e9])]
    combined = model._combined(wild, base)["y"].to_numpy()
    assert np.isnan(combined[0]) and combined[1] == 3.0
    wild[-1] = base.assign(y=[np.inf, -np.inf])
    np.testing.assert_array_equal(model._combined(wild, base)["y"].to_numpy(), [2.0, 2.0])


def test_a_member_wild_on_a_new_log_is_named_and_still_combined(log):
    """Fitted without a validation log, seed 99 (1e9 off) is kept; on a new log the median
    ranked it away without a word (``nnid train`` lists each member's scores, the API did
    not): predict now names it, and the numbers are the median's as before."""
    import warnings

    from nnid.models.ensemble import WildMemberWarning

    model = EnsembleModel(Offset(), seeds=(0, 1, 99), combine="median").fit(log)
    with pytest.warns(WildMemberWarning, match=r"seed 99: the free_run prediction") as said:
        pred = model.predict(log)
    assert len(said) == 1 and "seed 0" not in str(said[0].message)
    np.testing.assert_allclose(pred["y"].iloc[1:], log["y"].iloc[1:] + 1.0)
    # two members: the data in the reference names the wild one only, not the sane one
    with pytest.warns(WildMemberWarning, match=r"seed 99:") as said:
        EnsembleModel(Offset(), seeds=(2, 99), combine="median").fit(log).predict(log, 3)
    assert "seed 2" not in str(said[0].message) and "3-step" in str(said[0].message)
    with warnings.catch_warnings():  # members a few ranges apart are no wild member
        warnings.simplefilter("error")
        EnsembleModel(Offset(), seeds=(0, 1, 5), combine="median").fit(log).predict(log)


class Flying(Offset):
    """An Offset member that also flies in closed loop: its flight is its prediction."""

    kind = "offset_flying"

    def closed_loop(self, log, replay, mode="free_run"):
        return self._predict(log, mode)


def test_a_wild_member_warning_points_at_the_users_line(log):
    """The warning's stacklevel named the user's line for predict but the ensemble's module
    for closed_loop (one frame too high): both now name this file."""
    from nnid.models.ensemble import WildMemberWarning

    model = EnsembleModel(Flying(), seeds=(0, 1, 99), combine="median").fit(log)
    with pytest.warns(WildMemberWarning) as said:
        model.predict(log)
    with pytest.warns(WildMemberWarning) as flown:
        model.closed_loop(log, None)
    assert [w.filename for w in [*said, *flown]] == [__file__, __file__]


class EarlyWild(Offset):
    """An Offset member whose seed 99 goes wild in the first half second of the run only."""

    kind = "offset_early"

    def _predict(self, log, mode):
        out = log[["y"]].astype(float) + (0.0 if self.seed == 99 else float(self.seed))
        out.iloc[0] = np.nan
        if self.seed == 99:
            out.iloc[1:5] = 1e9
        return out


def test_a_member_wild_only_in_the_unscored_warm_up_is_not_named(log):
    """The wild-member check read every row after the members' warm-up samples, where the
    scores also leave out each run's first ``warmup_s``: a member sane on every scored row
    was named wild."""
    import warnings

    from nnid.models.ensemble import WildMemberWarning

    model = EnsembleModel(EarlyWild(), seeds=(0, 1, 99), warmup_s=1.0).fit(log)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        model.predict(log)
    unscored = EnsembleModel(EarlyWild(), seeds=(0, 1, 99)).fit(log)  # no warm-up: it is wild
    with pytest.warns(WildMemberWarning, match="seed 99:"):
        unscored.predict(log)


class Says(Offset):
    """An Offset member whose fit warns."""

    kind = "offset_says"

    def _fit(self, log, validation, progress):
        import warnings

        super()._fit(log, validation, progress)
        warnings.warn(f"fit {self.seed} has something to say", UserWarning, stacklevel=2)


class InWorker:
    """joblib.Parallel in this process, whose calls' own warnings reach no one, as a loky
    worker's went to its stderr and never to the caller's record."""

    def __init__(self, **settings) -> None:
        pass

    def __call__(self, calls):
        import warnings

        for fn, args, kwargs in calls:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                result = fn(*args, **kwargs)
            yield result


@pytest.mark.parametrize("jobs", [1, 2])
def test_members_warnings_reach_the_caller_named_by_seed(log, monkeypatch, jobs):
    """Fitted in worker processes (``n_jobs`` > 1), the members' warnings never reached the
    caller (``nnid train``'s recorded warnings lost them); now every member's are said in
    the caller, named by its seed, in either case."""
    import joblib

    monkeypatch.setattr(joblib, "Parallel", InWorker)
    with pytest.warns(UserWarning) as said:
        EnsembleModel(Says(), seeds=(0, 1), n_jobs=jobs).fit(log)
    messages = [str(w.message) for w in said]
    assert messages.count("ensemble member with seed 0: fit 0 has something to say") == 1
    assert messages.count("ensemble member with seed 1: fit 1 has something to say") == 1


def test_member_validation_totals_leave_out_the_runs_warm_up(log, tmp_path):
    """``member_validation_free_run_nrmse`` scored each member with only its own warm-up left
    out, ``metrics.json``'s members with the config's ``warmup_s``: two totals for one member
    on one log. The ensemble scores with ``warmup_s``, which ``nnid train`` sets from its
    config."""
    from nnid.datasets.cleaning import CleaningReport
    from nnid.pipeline import Inputs, build_model

    model = EnsembleModel(Offset(), seeds=(0, 1), warmup_s=5.0).fit(log, log)
    alone = [m.score(log, "free_run", warmup_s=5.0)["total"] for m in model.members_]
    np.testing.assert_allclose(model.member_validation_, alone, rtol=1e-12)
    assert model.member_validation_[1] != pytest.approx(model.members_[1].score(log)["total"])
    text = _with_seeds((ROOT / "configs/seamor_narx_adam.toml").read_text(), "[0, 1]")
    cfg = load_config(_config(tmp_path, text.replace("warmup_s = 1.0", "warmup_s = 2.5")),
                      TrainConfig)  # fmt: skip
    inputs = Inputs(log, CleaningReport())
    assert build_model(cfg.model, inputs, cfg.warmup_s).warmup_s == 2.5


def test_all_members_diverging_keeps_them_all(log):
    model = EnsembleModel(Offset(), seeds=(99, 100)).fit(log, log)
    assert model.member_seeds_ == [99, 100] and model.dropped_ == []


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"seeds": (1,)}, "at least two different seeds"),
        ({"seeds": (1, 1)}, "at least two different seeds"),
        ({"combine": "max"}, "combine"),
        ({"warmup_s": -1.0}, "warmup_s is 0 or more"),
        ({"warmup_s": float("nan")}, "warmup_s is 0 or more"),
        ({"warmup_s": None}, "warmup_s is 0 or more"),
        ({"warmup_s": "1 s"}, "warmup_s is 0 or more"),
    ],
)
def test_bad_settings_are_one_clear_error(log, kw, match):
    with pytest.raises(NnidInputError, match=match):
        EnsembleModel(Offset(), **kw).fit(log)


def test_a_member_without_a_seed_is_refused(log):
    from nnid.models.parametric import ParametricModel
    from nnid.vehicle import load_vehicle

    with pytest.raises(NnidInputError, match="with a seed"):
        EnsembleModel(ParametricModel(load_vehicle("seamor"))).fit(log)


def test_a_member_whose_fit_ignores_its_seed_is_refused(log):
    # STLSQ is deterministic: five seeds would be one model repeated, its terms counted five
    # times and its spread zero; library ensembling draws its candidates with the seed
    from nnid.models.sindy import SindyDamping
    from nnid.vehicle import load_vehicle

    vehicle = load_vehicle("seamor")
    with pytest.raises(NnidInputError, match="does not depend on its seed") as err:
        EnsembleModel(SindyDamping(vehicle, optimizer="stlsq")).fit(log)
    assert err.value.field == "model"
    drawn = EnsembleModel(SindyDamping(vehicle, optimizer="ensemble"), seeds=(0, 1))
    assert drawn._check_settings() == [0, 1]


def _with_seeds(text: str, seeds: str) -> str:
    """The config text with its ensemble's seeds line replaced; a config that lost the line
    fails here instead of leaving the test to run on the shipped seeds."""
    text, count = re.subn(r"(?m)^seeds = \[[^\]]*\]", f"seeds = {seeds}", text)
    assert count == 1
    return text


def _config(tmp_path: Path, text: str) -> Path:
    cfg = tmp_path / "ensemble.toml"
    cfg.write_text(text.replace('"seamor_sequence_narx.toml"', f'"{SIM}"'))
    return cfg


@pytest.mark.parametrize(
    ("extra", "seeds", "match"),
    [("seed = 3", "[0, 1]", "member.seed"), ("", "[2, 2]", "seeds must differ")],
)
def test_config_refuses_member_seed_and_repeated_seeds(tmp_path, extra, seeds, match):
    text = (ROOT / "configs/seamor_narx_adam.toml").read_text()
    text = _with_seeds(text, seeds)
    cfg = _config(tmp_path, text.replace("[model.member]\n", f"[model.member]\n{extra}\n"))
    with pytest.raises(NnidInputError, match=match):
        load_config(cfg, TrainConfig)
    done = CliRunner().invoke(app, ["train", str(cfg), "--out", str(tmp_path / "out")])
    assert done.exit_code == 2 and not (tmp_path / "out").exists()


def test_cli_train_shipped_adam_ensemble_reports_every_member(tmp_path):
    # configs/seamor_narx_adam.toml with two members fitted in two processes, one epoch a stage
    text = (ROOT / "configs/seamor_narx_adam.toml").read_text()
    text = re.sub(r"(?m)^max_epochs = \d+", "max_epochs = 1", text)
    text = re.sub(r"(?m)^simulation_epochs = \d+", "simulation_epochs = 1", text)
    cfg = _config(tmp_path, _with_seeds(text, "[0, 1]"))
    out = tmp_path / "out"
    done = CliRunner().invoke(app, ["train", str(cfg), "--out", str(out)])
    assert done.exit_code == 0, done.output
    m = json.loads((out / "metrics.json").read_text())
    assert m["model"] == "ensemble" and m["trainer"] == "adam"
    member = m["settings"]["model"]
    assert member["$model"] == "narx" and member["params"]["balanced"] is True
    assert m["settings"]["seeds"] == [0, 1] and m["settings"]["n_jobs"] == 3
    # 4 lags × (4 outputs + their 10 products + 4 y|y|) + 4 lags × 4 forces → 10 tanh → 4
    one = (4 * (4 + 10 + 4) + 4 * 4) * 10 + 10 + 10 * 4 + 4
    assert m["n_params"] == 2 * one
    assert m["validation_used_for"] == "early stopping, dropping diverged members"
    for part in ("validation", "test"):
        for key in ("free_run_nrmse", "one_step_nrmse"):
            assert np.isfinite(m[part][key]["total"])
    held = {p: [e["experiment"] for e in m["split"]["parts"][p]] for p in ("validation", "test")}
    assert held == {"validation": ["surge-sway-yaw-b", "surge-sway-c"], "test": ["surge-sway-b"]}
    assert m["describe"]["member_seeds"] == [0, 1]
    for described in m["describe"]["members"]:  # each member's free-run stage ran and was judged
        ft = described["simulation_finetune"]
        assert ft["epochs"] == 1 and np.isfinite(ft["validation_free_run_nrmse_before"])
    assert [r["seed"] for r in m["members"]] == [0, 1]
    seed_totals = [r["test"]["free_run_nrmse"]["total"] for r in m["members"]]
    # one validation total per member: the one that chose the members is the one reported
    checked = [r["validation"]["free_run_nrmse"]["total"] for r in m["members"]]
    np.testing.assert_allclose(m["describe"]["member_validation_free_run_nrmse"], checked)
    assert seed_totals[0] != seed_totals[1]  # the seeds are different nets
    assert "## Ensemble members" in (out / "report.md").read_text()
    # the saved ensemble predicts the mean of its members, each as it would alone
    model = load_model(out)
    assert isinstance(model.members_[0], NarxModel) and model.member_seeds_ == [0, 1]
    assert [mb.seed for mb in model.members_] == [0, 1]
    cfg_obj = load_config(cfg, TrainConfig)
    from nnid.pipeline import load_inputs, make_split

    inputs = load_inputs(cfg_obj, cfg, [cfg_obj.model])
    test = make_split(inputs.log, cfg_obj.split, str(cfg), inputs.report).test
    preds = [mb.predict(test).to_numpy() for mb in model.members_]
    np.testing.assert_allclose(model.predict(test).to_numpy(), np.mean(preds, 0), rtol=1e-12)
    # A free run of this net amplifies last-bit differences: in one CI run the score below came
    # out 2.5e-7 (relative) off metrics.json, where a fresh process scoring the same saved files
    # gives metrics.json's value to the last bit (cause not found; not reproduced with 1 or 2
    # torch, BLAS or numba threads, nor under load). 1e-6 still catches a wrong member, weight
    # or combination.
    scored = model.score(test, "free_run", warmup_s=m["warmup_s"])
    np.testing.assert_allclose(scored["total"], m["test"]["free_run_nrmse"]["total"], rtol=1e-6)
    alone = [mb.score(test, "free_run", warmup_s=m["warmup_s"])["total"] for mb in model.members_]
    np.testing.assert_allclose(alone, seed_totals, rtol=1e-6)


AUTOPILOT_SIM = """kind = "simulate"
vehicle = "seamor"
dt = 0.1
seed = 0
[autopilot]
kp = [0.0, 0.0, 40.0, 0.0, 0.0, 10.0]
kd = [0.0, 0.0, 40.0, 0.0, 0.0, 10.0]
reference = [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
"""
AUTOPILOT_RUN = """[[experiments]]
name = "{name}"
x0 = [0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0]
signals = [
  {{ kind = "multisine", channel = "X", amplitude = {x}, f_min = {f}, {rest} }},
  {{ kind = "multisine", channel = "Z", amplitude = {z}, f_min = {f}, {rest} }},
]
"""


def test_members_of_an_autopilot_flown_log_are_judged_by_the_free_runs_reported(tmp_path):
    """A log flown under the simulator's PD autopilot: ``nnid train`` flies a hybrid member's
    validation free run under the replayed autopilot (closed loop), while the ensemble scored
    its members open loop, 0.050 and 0.051 in ``describe`` for 0.038 and 0.042 in
    ``metrics.json``'s members, and dropped diverged members by runs it did not report. The
    run now passes its replay, and the two totals are one."""
    runs = [("a", 20.0, 10.0, 0.02), ("b", 25.0, 12.0, 0.03)]
    rest = "f_max = 0.3, n = 5, duration = 40.0"
    sim = AUTOPILOT_SIM + "".join(
        AUTOPILOT_RUN.format(name=n, x=x, z=z, f=f, rest=rest) for n, x, z, f in runs
    )
    (tmp_path / "sim.toml").write_text(sim)
    cfg = tmp_path / "train.toml"
    cfg.write_text(
        'kind = "train"\nvehicle = "seamor"\nwarmup_s = 1.0\n[data]\nsimulate = "sim.toml"\n'
        '[split]\nby = "experiment"\ntrain = ["a"]\nvalidation = ["b"]\n'
        '[model]\nkind = "ensemble"\nseeds = [0, 1]\n'
        '[model.member]\nkind = "hybrid"\ndofs = ["u", "w"]\nhidden = [4]\nmemory = []\n'
        'segments = [1.0]\ntrainer = { kind = "adam", max_epochs = 2 }\n'
    )
    out = tmp_path / "out"
    done = CliRunner().invoke(app, ["train", str(cfg), "--out", str(out)])
    assert done.exit_code == 0, done.output
    m = json.loads((out / "metrics.json").read_text())
    members = [r["validation"] for r in m["members"]]
    assert all(r["closed_loop"] == ["free_run"] for r in members)  # flown as the log was
    reported = [r["free_run_nrmse"]["total"] for r in members]
    described = m["describe"]["member_validation_free_run_nrmse"]
    np.testing.assert_allclose(described, reported, rtol=1e-9)
    # the ensemble flies as its members do, and the mean of their flights is no worse than
    # their mean score (the triangle inequality, column by column); open loop it read 0.050
    # beside members at 0.038 and 0.042
    assert m["validation"]["closed_loop"] == ["free_run"]
    assert m["validation"]["free_run_nrmse"]["total"] <= np.mean(reported) + 1e-12
    # the open-loop free runs score otherwise: the test tells the two apart
    from nnid.pipeline import load_inputs, make_split

    cfg_obj = load_config(cfg, TrainConfig)
    inputs = load_inputs(cfg_obj, cfg, [cfg_obj.model])
    validation = make_split(inputs.log, cfg_obj.split, str(cfg), inputs.report).validation
    model = load_model(out)
    open_loop = [mb.score(validation, "free_run", warmup_s=1.0)["total"] for mb in model.members_]
    assert not np.allclose(open_loop, reported, rtol=0.05)


def test_members_fitted_in_worker_processes_match_the_sequential_fit():
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(-1, 1, 40), 15)
    y = np.zeros(u.size)
    for k in range(1, u.size):
        y[k] = 0.9 * y[k - 1] + 0.1 * np.tanh(2 * u[k - 1])
    log = pd.DataFrame({"t": np.arange(u.size) * 0.1, "u": u, "y": y})
    train, val = log.iloc[:400], log.iloc[400:].reset_index(drop=True)
    lm = LevenbergMarquardt(max_epochs=5, jacobian="samples")
    member = NarxModel(["u"], ["y"], hidden=(3,), trainer=lm, balanced=False, lm_samples=300)
    one = EnsembleModel(member, seeds=(0, 1, 2)).fit(train, val)
    calls = []
    two = EnsembleModel(member, seeds=(0, 1, 2), n_jobs=2)
    two.fit(train, val, progress=lambda done, total, msg, **kw: calls.append((done, total)))
    assert calls == [(1, 3), (2, 3), (3, 3)]
    assert two.member_seeds_ == [0, 1, 2]
    np.testing.assert_allclose(two.member_validation_, one.member_validation_, rtol=1e-6)
    np.testing.assert_allclose(two.predict(val), one.predict(val), rtol=1e-6, atol=1e-9)


@needs_proc
def test_sigterm_to_the_cli_ends_the_ensemble_workers(tmp_path):
    # the console entry turns SIGTERM into SystemExit: an ensemble's loky workers, mid-fit,
    # end with the command instead of training on as orphans (by default SIGTERM kills only
    # the parent)
    (tmp_path / "sim.toml").write_text(
        'kind = "simulate"\nvehicle = "seamor"\ndt = 0.05\n'
        + "".join(
            f'[[experiments]]\nname = "{n}"\nduration = 60.0\nsignals = [{{ kind = "aprbs", '
            f'channel = "X", amplitude = 20.0, hold_min = 1.0, hold_max = 4.0, '
            f"duration = 60.0, seed = {k} }}]\n"
            for k, n in enumerate(("a", "b"))
        )
    )
    (tmp_path / "train.toml").write_text(
        'kind = "train"\n[data]\nsimulate = "sim.toml"\n[split]\nby = "experiment"\n'
        'validation = ["b"]\n[model]\nkind = "ensemble"\nseeds = [0, 1]\nn_jobs = 2\n'
        '[model.member]\nkind = "narx"\ninputs = ["tau_X"]\noutputs = ["u"]\nhidden = [4]\n'
        '[model.member.trainer]\nkind = "adam"\nmax_epochs = 1000000\n'
    )

    def loky_workers(pid: int) -> list[int]:
        """Both of loky's workers once they run (and its resource tracker)."""
        found = [p for p in child_pids(pid) if "loky" in cmdline(p)]
        return found if sum("popen_loky" in cmdline(p) for p in found) == 2 else []

    args = ["train", str(tmp_path / "train.toml"), "--out", str(tmp_path / "out")]
    code, alive = stop_cli(args, loky_workers, tmp_path / "stderr.txt")
    assert alive == []
    assert code == 128 + signal.SIGTERM
    assert not (tmp_path / "out" / "metrics.json").exists()


def test_a_member_predicting_a_small_coupling_on_a_still_dof_is_not_wild():
    """A log that holds w at rest (range 0): the members' w differs by a few mm/s, a
    hundredth of u's range, and the one apart was named wild ("diverged or left the range").
    A velocity is judged on its scale's widest range (u v w), as the scores judge one the
    data barely moves; a w 10 ranges of u away is still named."""
    from nnid.models.ensemble import wild_members

    t = np.arange(200) * 0.05
    log = pd.DataFrame({"t": t, "u": np.sin(t), "w": 0.0})
    u = np.sin(t)
    preds = np.stack(
        [np.stack([u, np.full(t.size, w)], 1) for w in (0.001, 0.0012, 0.02)]
    )  # members x rows x (u, w)
    mask = np.ones(t.size, dtype=bool)
    assert wild_members(preds, log, ["u", "w"], mask) == []
    preds[2, :, 1] = 25.0  # 12 ranges of u: wild
    assert wild_members(preds, log, ["u", "w"], mask) == [2]
