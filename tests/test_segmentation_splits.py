"""Transient labels, the balanced sampler (Weiss V.B), splits and persistence of excitation."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
import pytest

from nnid.config import Experiment
from nnid.datasets.measurement import Measurement
from nnid.datasets.segmentation import BalancedSampler, label_transients
from nnid.datasets.simulator import experiment_inputs, simulate
from nnid.datasets.splits import split_log
from nnid.errors import NnidInputError
from nnid.evaluation.persistence import excitation_report
from nnid.vehicle import load_vehicle


@pytest.fixture(scope="module")
def steady_heavy_log():
    """Seamor surge and yaw steps held 40 s each: mostly steady state, as Weiss's tank runs."""
    veh = load_vehicle("seamor")
    exp = Experiment(name="steps", signals=[
        {"kind": "stairs", "channel": "X", "levels": [20, 40, -20, 0], "hold": 40.0},
        {"kind": "stairs", "channel": "N", "levels": [0, 2, -2, 0], "hold": 40.0}])  # fmt: skip
    inputs = experiment_inputs(exp, ("X", "Y", "Z", "K", "M", "N"), 0.05)
    log = simulate(veh, inputs, 0.05, substeps=2, measurement=Measurement(kind="dvl_imu"), seed=2)
    log["experiment"] = "steps"
    return log


def test_transient_labels_follow_the_steps(steady_heavy_log):
    lab = label_transients(steady_heavy_log)
    t = steady_heavy_log["t"].to_numpy()
    assert lab[(t > 40.0) & (t < 41.0)].all()  # right after the second step
    assert not lab[(t > 70.0) & (t < 79.0)].any()  # settled at constant speed
    assert 0.05 < lab.mean() < 0.45  # a steady-state-heavy log


def test_balanced_sampler_gives_half_transients_and_is_deterministic(steady_heavy_log):
    lab = label_transients(steady_heavy_log)
    raw = BalancedSampler(lab, steady_heavy_log["experiment"].to_numpy(), window=4, balance=False)
    bal = BalancedSampler(lab, steady_heavy_log["experiment"].to_numpy(), window=4, seed=7)
    raw_share = raw.transient_share(raw.sample(40_000))
    share = bal.transient_share(bal.sample(40_000))
    assert abs(share - 0.5) <= 0.02
    assert abs(raw_share - lab.mean()) < 0.02 and raw_share < 0.45
    assert np.array_equal(bal.sample(500), BalancedSampler(lab, window=4, seed=7).sample(500))
    assert not np.array_equal(bal.sample(500, epoch=0), bal.sample(500, epoch=1))
    w = bal.weights()
    assert w[~bal.eligible].sum() == 0 and np.isclose(w[lab.to_numpy()].sum(), 0.5)


def _two_run_log():
    a = pd.DataFrame({"t": np.arange(100) * 0.1, "u": np.arange(100.0), "tau_X": 1.0})
    b = a.copy()
    a["experiment"], b["experiment"] = "a", "b"
    c = a.iloc[:50].copy()
    c["experiment"] = "c"
    return pd.concat([a, b, c], ignore_index=True)


def test_block_split_is_contiguous_per_experiment():
    log = _two_run_log()
    split = split_log(log, "block")
    for name, n in (("a", 100), ("c", 50)):
        parts = [split[p][split[p]["experiment"] == name]["u"].to_numpy() for p in
                 ("train", "validation", "test")]  # fmt: skip
        joined = np.concatenate(parts)
        assert np.array_equal(joined, np.arange(float(n)))  # nothing lost, order kept
        assert len(parts[0]) == round(0.7 * n) and parts[0].max() < parts[1].min()
    assert split.record["parts"]["validation"][0] == {"experiment": "a", "rows": [70, 85]}


def test_experiment_split_keeps_runs_whole():
    log = _two_run_log()
    split = split_log(log, "experiment", assignment={"train": ["a", "b"], "test": ["c"]})
    assert set(split.train["experiment"]) == {"a", "b"} and set(split.test["experiment"]) == {"c"}
    assert len(split.validation) == 0 and split.record["samples"]["train"] == 200
    with pytest.raises(NnidInputError, match="not in the log"):
        split_log(log, "experiment", assignment={"train": ["zz"]})
    auto = split_log(log, "experiment")
    for p in ("train", "validation", "test"):
        for name in set(auto[p]["experiment"]):
            assert len(auto[p][auto[p]["experiment"] == name]) in (100, 50)


def test_persistence_of_excitation_names_unexcited_parameters():
    """Only surge excited, yaw parameters asked for: the report names them (Weiss eqs 95-98)."""
    rng = np.random.default_rng(0)
    u = rng.normal(size=500)
    phi = np.stack([u * np.abs(u), u, np.zeros(500), np.zeros(500)], 1)
    names = ["X:u*abs(u)", "X_udot", "N:r*abs(r)", "N_rdot"]
    rep = excitation_report(phi, names, groups={"surge": names[:2], "yaw": names[2:]})
    assert rep.unexcited == ["N:r*abs(r)", "N_rdot"] and not rep.persistent
    assert rep.rank == 2 and rep.group_min_singular["yaw"] == 0.0
    assert rep.group_min_singular["surge"] > 0.1
    assert "N:r*abs(r)" in rep.warnings[0]
    collinear = excitation_report(np.stack([u, 2 * u, u**2], 1), ["a", "b", "c"])
    assert collinear.collinear == ["a", "b"] and collinear.rank == 2
    good = excitation_report(np.stack([u, u**2, np.sin(u)], 1), ["a", "b", "c"])
    assert good.persistent and np.isfinite(good.condition) and not good.warnings


def test_replays_of_one_run_stay_on_one_side_of_a_split():
    """Copies of one run (a replay group the reader config declares) are one unit: a default
    split never puts two of them on different sides, and an explicit one that does is refused."""
    from nnid.datasets.log import REPLAY_GROUP
    from nnid.errors import NnidInputError

    names = ["a", "copy1", "copy2", "copy3", "b", "c"]
    log = pd.DataFrame({"t": np.tile(np.arange(100) * 0.1, 6), "experiment": np.repeat(names, 100)})
    log[REPLAY_GROUP] = log["experiment"].map(lambda e: "replays[0]" if "copy" in e else None)
    for fractions in [(0.5, 0.5, 0.0), (0.4, 0.3, 0.3), (0.7, 0.3, 0.0)]:
        split = split_log(log, "experiment", fractions)
        sides = {
            p
            for p in ("train", "validation", "test")
            if split[p]["experiment"].str.startswith("copy").any()
        }
        assert len(sides) == 1, (fractions, split.record["parts"])
    plain = split_log(log.drop(columns=REPLAY_GROUP), "experiment", (0.5, 0.5, 0.0))
    assert {"copy2", "copy3"} & set(
        plain.validation["experiment"]
    )  # the groups made the difference
    with pytest.raises(NnidInputError, match="copies of one run"):
        split_log(
            log, "experiment", (0.5, 0.5, 0.0), {"train": ["a", "copy1"], "validation": ["copy2"]}
        )


def _uneven_log(sizes=(400, 400, 33)) -> pd.DataFrame:
    return pd.concat(
        [pd.DataFrame({"t": 0.1 * np.arange(n), "u": 0.0, "experiment": f"run{k}"})
         for k, n in enumerate(sizes)],
        ignore_index=True,
    )  # fmt: skip


@pytest.mark.parametrize(
    ("sizes", "by", "said"),
    [
        ((400, 400, 33), "experiment", "validation 52% (asked 30%)"),  # 0.3 asked, 52 % held
        ((300, 300, 300, 300), "experiment", None),  # whole runs meet 0.7/0.3 within 0.1
        ((400, 400, 400), "auto", None),  # a test part asked, none given: blocks, not said
    ],
)
def test_a_held_out_share_whole_runs_cannot_meet_is_said_where_the_split_is_kept(sizes, by, said):
    """Runs are never cut, so by-experiment fractions are met only as finely as the runs: a
    share more than 10 % of the log off what was asked is warned of and kept in the record and
    the cleaning report, on the split the run keeps (the loop's, a config's)."""
    import warnings

    from nnid.config import SplitSpec
    from nnid.datasets.cleaning import CleaningReport
    from nnid.loop.residual_loop import ResidualLoop
    from nnid.pipeline import make_split

    log = _uneven_log(sizes)
    # auto: three runs of 400 give the test part none, so the split is cut in blocks
    spec = SplitSpec(by=by, fractions=[0.7, 0.2, 0.1] if by == "auto" else [0.7, 0.3, 0.0])
    report = CleaningReport()
    loop = ResidualLoop(load_vehicle("seamor"), validation=0.3)
    for run in (lambda: make_split(log, spec, report=report), lambda: loop._split(log)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            run()
        messages = [str(w.message) for w in caught]
        if said is None:
            assert not messages
        else:
            assert len(messages) == 1 and said in messages[0], messages
            assert "3 runs of 400, 400, 33 samples" in messages[0]
    if by == "auto":  # the loop holds out 0.3 of three runs of 400: one whole run, 33 %
        assert set(loop._split(log)[1]["experiment"]) == {"run2"}
    assert any(said in s.detail for s in report.steps) == (said is not None)


def test_an_empty_list_of_experiments_in_a_split_means_what_it_says(tmp_path):
    """``validation = []`` was read as no names at all, so the split went by fractions and
    held out a validation run the config said not to: now an empty train or validation list
    is refused (a fit needs both) naming the key, at exit code 2, and ``test = []`` beside
    named validation runs is no test part."""
    from typer.testing import CliRunner

    from nnid.cli import app
    from nnid.config import SplitSpec, TrainConfig, load_config
    from nnid.pipeline import make_split

    log = _uneven_log((300, 300, 300, 300))
    config = tmp_path / "train.toml"
    for key in ("validation", "train"):
        config.write_text(f'kind = "train"\n[split]\nby = "experiment"\n{key} = []\n'
                          '[model]\nkind = "sindy"\n')  # fmt: skip
        with pytest.raises(NnidInputError, match="an empty list names no") as err:
            load_config(config, TrainConfig)
        assert err.value.field == f"split.{key}" and str(config) in str(err.value)
    log.assign(u=np.sin(0.1 * log.index)).to_csv(tmp_path / "log.csv", index=False)
    done = CliRunner().invoke(
        app,
        ["train", str(config), "--data", str(tmp_path / "log.csv"), "--out", str(tmp_path / "o")],
    )
    assert done.exit_code == 2 and "split.train" in done.output, done.output
    split = make_split(log, SplitSpec(by="experiment", validation=["run1"], test=[]))
    assert set(split.validation["experiment"]) == {"run1"} and len(split.test) == 0
    # refused as the config is read, before any log is (a SplitSpec's own check)
    config.write_text('kind = "train"\n[split]\nby = "block"\ntest = []\n[model]\nkind = "sindy"\n')
    with pytest.raises(NnidInputError, match='only by = "experiment" uses') as err:
        load_config(config, TrainConfig)
    assert err.value.field == "split.test"


def test_runs_joined_without_a_fresh_index_are_split_and_labelled_each_on_its_own_rows():
    """Two runs joined by pd.concat keep their index labels 0..99 twice (as a Parquet file
    written from such a frame is read back): split_log took a run's rows by its labels, so
    each block held both runs' samples (140 training rows of 100) and run b, held out, was
    trained on too; label_transients failed in pandas. Rows are now taken by position."""
    t = np.arange(100) * 0.1
    a = pd.DataFrame({"t": t, "u": np.tanh(t - 5.0), "tau_X": 1.0, "experiment": "a"})
    log = pd.concat([a, a.assign(experiment="b", u=-np.tanh(t - 3.0))])
    fresh = log.reset_index(drop=True)
    for how in (
        {"by": "block"},
        {"by": "experiment", "assignment": {"train": ["a"], "test": ["b"]}},
    ):
        got, want = split_log(log, **how), split_log(fresh, **how)
        for part in ("train", "validation", "test"):
            pd.testing.assert_frame_equal(
                got[part].reset_index(drop=True), want[part].reset_index(drop=True)
            )
    assert np.array_equal(label_transients(log).to_numpy(), label_transients(fresh).to_numpy())


def test_a_split_part_too_short_to_score_is_refused_where_labels_repeat():
    """Two runs of 20 s joined by pd.concat (each label twice) split into blocks: the
    validation blocks (the last 6 s of each run) share their labels, and each run's span
    was read by label over both runs' rows (from 14 s to 119.9 s): a part all warm-up
    passed. By position, it is refused as on the same log with a fresh index."""
    from nnid.config import SplitSpec
    from nnid.pipeline import make_split

    t = 0.1 * np.arange(200)
    a = pd.DataFrame({"t": t, "experiment": "a", "u": np.sin(t), "tau_X": np.cos(t)})
    b = pd.DataFrame({"t": 100.0 + t, "experiment": "b", "u": np.cos(t), "tau_X": 1.0})
    joined = pd.concat([a, b])
    spec = SplitSpec(by="block", fractions=[0.7, 0.3, 0.0])
    said = r"the longest validation run is 5.9 s, no longer than the warm-up \(8 s\)"
    for log in (joined, joined.reset_index(drop=True)):
        with pytest.raises(NnidInputError, match=said):
            make_split(log, spec, warmup_s=8.0)
    assert len(make_split(joined, spec, warmup_s=5.0).validation) == 120  # 5.9 s scores


def test_transient_thresholds_come_from_the_rows_given_and_every_row_is_labelled():
    # A random division keeps its validation rows in the training log: their manoeuvres set
    # the scale that labels the training rows unless ``rows`` names the rows to measure on.
    # Run "a" moves 100x less than run "b": measured on both, none of a's samples is
    # transient; measured on a's rows, a is labelled as it would be alone.
    t = np.arange(0.0, 20.0, 0.01)
    rng = np.random.default_rng(0)

    def run(name: str, size: float) -> pd.DataFrame:
        step = np.repeat(rng.uniform(-size, size, 5), len(t) // 5)
        u = np.zeros(len(t))
        for k in range(1, len(t)):
            u[k] = u[k - 1] + 0.05 * (step[k - 1] - u[k - 1])
        u += 1e-4 * size * rng.standard_normal(len(t))
        return pd.DataFrame({"t": t, "u": u, "experiment": name})

    a, b = run("a", 0.01), run("b", 1.0)
    log = pd.concat([a, b], ignore_index=True)
    in_a = (log["experiment"] == "a").to_numpy()
    alone = label_transients(a).to_numpy()
    assert alone.any() and not label_transients(log).to_numpy()[in_a].any()
    given = label_transients(log, rows=in_a).to_numpy()
    np.testing.assert_array_equal(given[in_a], alone)
    assert given.size == len(log) and given[~in_a].any()


def _cut_at_gaps(log: pd.DataFrame, run: str) -> pd.DataFrame:
    """``log`` (one run, empty cells in ``u``) as the pieces between its empty cells, each
    ``<run>#<k>`` and marked ``piece_of`` the run, the empty rows left out."""
    keep = log["u"].notna().to_numpy()
    k = np.cumsum(~keep)[keep]
    return log[keep].assign(experiment=[f"{run}#{i}" for i in k], piece_of=run)


@pytest.mark.parametrize("gaps", [[2, 1000, 2000], [1000]], ids=["first window", "middle"])
def test_a_gap_in_a_velocity_labels_the_run_as_its_stretches(steady_heavy_log, gaps):
    """An empty velocity cell in a run's first window stopped the edge fit with a bare
    ValueError; one elsewhere made the noise and the 99th percentile NaN, and the DOF never
    labelled a transient. Away from the gaps (beyond the hold) the run now labels as the
    pieces between its gaps label."""
    log = steady_heavy_log[["t", "u", "experiment"]].copy()
    log.loc[gaps, "u"] = np.nan
    lab = label_transients(log).to_numpy()
    pieces = _cut_at_gaps(log, "steps")
    with warnings.catch_warnings():  # the first gap's short piece is said: another test
        warnings.simplefilter("ignore")
        alone = label_transients(pieces).to_numpy()
    hold = round(0.5 / 0.05)
    far = np.ones(len(log), dtype=bool)
    for g in gaps:
        far[max(0, g - hold) : g + hold + 1] = False
    kept = log["u"].notna().to_numpy()
    assert alone.any()
    assert np.array_equal(lab[kept & far], alone[far[kept]])


def test_a_piece_shorter_than_the_label_window_is_steady_and_said(steady_heavy_log):
    """A piece of five samples cut at a gap (``run#1``, ``piece_of`` set) was refused as
    'too few for the Savitzky-Golay window of 21 samples', naming no setting the user has:
    it has no acceleration, is labelled steady, and the warning says how many samples."""
    long = steady_heavy_log[["t", "u"]].assign(experiment="run#0", piece_of="run")
    short = long.iloc[:5].assign(experiment="run#1", t=long["t"].iloc[:5] + 200.0)
    log = pd.concat([long, short], ignore_index=True)
    with pytest.warns(UserWarning, match=r"5 samples in 1 piece of runs cut at gaps \(.*run#1"):
        lab = label_transients(log).to_numpy()
    assert not lab[len(long) :].any()
    assert np.array_equal(lab[: len(long)], label_transients(long).to_numpy())


def test_an_assignment_key_that_is_no_part_is_refused():
    """{"val": [...]} sent its runs to no part, without a word (an API caller's typo)."""
    log = _two_run_log()
    with pytest.raises(NnidInputError, match=r"\['val'\]") as err:
        split_log(log, "experiment", assignment={"train": ["a"], "val": ["b"], "test": ["c"]})
    assert err.value.field == "assignment"
