"""Empty motion cells (a DVL that drops out in bursts): accepted as gaps, bridged from the pose
where it allows, masked otherwise, and every one of them reported."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.gaps import MIN_SEGMENT, bridge_from_pose, find_gaps, mask_gaps
from nnid.datasets.log import validate_log
from nnid.datasets.preprocess import true_runs
from nnid.errors import NnidInputError


def _mocap_log(n: int = 400, dt: float = 0.05) -> pd.DataFrame:
    """A level vehicle turning slowly: pose and its exact body velocities."""
    t = np.arange(n) * dt
    psi = 0.3 * np.sin(0.5 * t)
    r = 0.15 * np.cos(0.5 * t)
    u_body = 0.2 + 0.05 * np.sin(0.7 * t)
    # integrate the NED position of u along psi (v = w = 0), exactly enough for SG rates
    x = np.concatenate([[0.0], np.cumsum(u_body[:-1] * np.cos(psi[:-1]) * dt)])
    y = np.concatenate([[0.0], np.cumsum(u_body[:-1] * np.sin(psi[:-1]) * dt)])
    zeros = np.zeros(n)
    return pd.DataFrame(
        {
            "t": t,
            "x": x,
            "y": y,
            "z": zeros + 2.0,
            "phi": zeros,
            "theta": zeros,
            "psi": psi,
            "u": u_body,
            "v": zeros,
            "w": zeros,
            "p": zeros,
            "q": zeros,
            "r": r,
            "tau_X": np.sin(t),
        }
    )


def test_empty_velocity_cells_are_gaps_but_text_and_inf_are_refused():
    log = _mocap_log()
    log.loc[10:19, ["u", "v", "w"]] = np.nan
    assert validate_log(log) is log
    for bad, what in ((np.inf, "inf"), ("fast", "'fast'")):
        broken = log.astype({"u": object})
        broken.loc[30, "u"] = bad
        with pytest.raises(NnidInputError) as err:
            validate_log(broken, source="dive.csv")
        assert err.value.field == "u" and err.value.row == 30 and what in str(err.value)
    empty = log.assign(v=np.nan)
    with pytest.raises(NnidInputError, match="empty") as err:
        validate_log(empty, source="dive.csv")
    assert err.value.field == "v"
    inputs = log.copy()
    inputs.loc[5, "tau_X"] = np.nan  # an input is never a gap
    with pytest.raises(NnidInputError) as err:
        validate_log(inputs)
    assert err.value.field == "tau_X" and err.value.row == 5


def test_gaps_are_found_with_their_length_and_columns():
    log = _mocap_log()
    log.loc[100:119, ["u", "v", "w"]] = np.nan  # 20 samples: 21 intervals between measurements
    log.loc[300:301, "r"] = np.nan
    gaps = find_gaps(log)
    assert [(g.rows, g.columns) for g in gaps] == [(20, ["u", "v", "w"]), (2, ["r"])]
    assert gaps[0].t == pytest.approx(5.0)
    assert gaps[0].length_s == pytest.approx(21 * 0.05)


def test_velocity_gaps_are_bridged_from_the_pose_and_long_ones_are_left():
    truth = _mocap_log()
    log = truth.copy()
    log.loc[100:119, ["u", "v", "w", "r"]] = np.nan  # 1 s
    log.loc[200:279, ["u", "v", "w"]] = np.nan  # 4 s: beyond max_bridge_s
    report = CleaningReport()
    out = bridge_from_pose(log, max_bridge_s=2.0, report=report)
    gap = slice(100, 119)
    for c in ("u", "v", "w", "r"):
        assert out.loc[gap, c].notna().all()
        assert np.abs(out.loc[gap, c] - truth.loc[gap, c]).max() < 2e-3, c
    assert out.loc[200:279, "u"].isna().all()
    assert (
        out.drop(index=range(100, 120)).fillna(0).equals(log.drop(index=range(100, 120)).fillna(0))
    )
    (step,) = report.steps
    assert step.step == "bridge velocity gaps" and "1 gap in" in step.detail


def test_attitude_alone_bridges_rates_but_not_translations():
    log = _mocap_log().drop(columns=["x", "y"])
    log.loc[100:119, ["u", "v", "w", "r"]] = np.nan
    out = bridge_from_pose(log)
    assert out.loc[100:119, "r"].notna().all()
    assert out.loc[100:119, ["u", "v", "w"]].isna().all().all()


def test_masking_cuts_runs_into_segments_and_reports_every_row():
    log = _mocap_log().assign(experiment="dive1")
    log.loc[100:119, "u"] = np.nan
    log.loc[121:122, "u"] = np.nan  # leaves a single sample between two gaps
    train, held = log.iloc[:250], log.iloc[250:]
    report = CleaningReport()
    masked_train, masked_held = mask_gaps([train, held], ["u", "r"], report)
    assert masked_held is held  # no gap there
    assert list(dict.fromkeys(masked_train["experiment"])) == ["dive1#0", "dive1#2"]
    assert masked_train["u"].notna().all()
    (step,) = report.steps
    assert step.rows_removed == 250 - len(masked_train) == 23  # 22 empty, 1 stranded
    assert "too short" in step.detail


def _masked_run_by_run(part: pd.DataFrame, columns: list[str], taken: np.ndarray) -> pd.DataFrame:
    """mask_gaps's cut of ``part`` computed one run at a time from that run's own rows (the
    rows of ``taken``, a slow run's, out whole): the reference for its one-pass grouping."""
    keep = part[columns].notna().all(axis=1).to_numpy() & ~taken
    label = np.full(len(part), None, dtype=object)
    piece_of = part["piece_of"].to_numpy(object).copy()
    for name in part["experiment"].unique():
        pos = np.flatnonzero(part["experiment"].to_numpy() == name)
        runs = true_runs(keep[pos])
        for k, (a, b) in enumerate(runs):
            rows = pos[a:b]
            keep[rows] &= b - a >= MIN_SEGMENT
            label[rows] = name if len(runs) == 1 else f"{name}#{k}"
            if len(runs) > 1:
                piece_of[rows] = [name if pd.isna(p) else p for p in piece_of[rows]]
    return part.assign(experiment=label, piece_of=piece_of)[keep].reset_index(drop=True)


def test_masking_many_runs_at_once_gives_what_each_run_alone_gives():
    """mask_gaps found each run's rows by looking its index labels up in the whole part (rows
    × runs: seconds on a log cut into thousands of pieces) and now groups the rows once; the
    output is pinned to the run-by-run computation on interleaved runs with shuffled index
    labels, gaps, a stranded sample, a reader's piece and a run slow in u (taken out whole).
    Passed before the change too: it pins equivalence, not a bug."""
    rng = np.random.default_rng(7)
    one = _mocap_log(60)[["t", "u", "v", "r"]]
    runs = {e: one.assign(experiment=e, piece_of=None) for e in "abc"}
    runs["b"]["piece_of"] = "b-file"  # a reader's piece: stays one when cut again
    runs["c"] = _slow(runs["c"], ["u"], 5)
    runs["a"].loc[10:14, "u"] = np.nan
    runs["a"].loc[16:17, "v"] = np.nan  # one sample stranded between two gaps
    runs["a"].loc[40:44, "r"] = np.nan
    runs["b"].loc[[3, 30, 50], "v"] = np.nan
    blocks = [runs[e].iloc[a : a + 20] for a in (0, 20, 40) for e in "abc"]  # interleaved
    log = pd.concat(blocks, ignore_index=True)
    log.index = rng.permutation(len(log)) * 3 + 100  # labels no position matches
    parts = [log.iloc[: len(log) // 2], log.iloc[len(log) // 2 :]]
    report = CleaningReport()
    got = mask_gaps(parts, ["u", "v", "r"], report)
    assert [s.step for s in report.steps] == ["mask gaps", "slow channels"]
    for part, out in zip(parts, got, strict=True):
        taken = (part["experiment"] == "c").to_numpy()
        pd.testing.assert_frame_equal(out, _masked_run_by_run(part, ["u", "v", "r"], taken))
    alone = [g for e in "ab" for g in find_gaps(log[log["experiment"] == e], ["u", "v", "r"])]
    assert find_gaps(log[log["experiment"] != "c"], ["u", "v", "r"]) == alone


def test_runs_joined_without_a_fresh_index_are_cut_each_on_its_own_rows():
    """Two runs joined by pd.concat keep their index labels 0..9 twice: mask_gaps found a
    run's rows by its labels, so run a's rows were labelled b's pieces ('b#0', 'b#1') and
    find_gaps counted b's one gap twice. Rows are now grouped by position."""
    a = pd.DataFrame({"t": np.arange(10) * 0.1, "u": np.arange(10.0), "experiment": "a"})
    log = pd.concat([a, a.assign(experiment="b")])
    log.iloc[4, 1] = np.nan  # in run a only
    (out,) = mask_gaps([log], ["u"])
    assert out["experiment"].tolist() == ["a#0"] * 4 + ["a#1"] * 5 + ["b"] * 10
    assert [(g.experiment, g.rows) for g in find_gaps(log, ["u"])] == [("a", 1)]


def test_a_piece_cut_at_a_gap_shorter_than_the_window_gets_no_derivative():
    """An empty cell 20 samples from a run's start cut it into a 20-sample piece, which the
    derivative window (21 samples) refused with an error blaming savgol_window; the piece now
    gets none, as a stretch between gaps within a run gets none, and the report says so. A
    whole run that short is still refused."""
    from nnid.datasets.preprocess import derive_accelerations

    t = np.arange(220) * 0.05
    log = pd.DataFrame({"t": t, "experiment": ["run0#1"] * 20 + ["run0#2"] * 200, "u": np.sin(t)})
    log["piece_of"] = "run0"  # as mask_gaps marks its pieces
    report = CleaningReport(source="log")
    out = derive_accelerations(log, 1.0, 4, report)
    assert out["du"].iloc[:20].isna().all() and np.isfinite(out["du"].iloc[30:-30]).all()
    assert "20 samples in pieces between gaps shorter than the window" in report.steps[-1].detail
    with pytest.raises(NnidInputError, match="run1' has 20 samples") as err:
        derive_accelerations(log.iloc[:20].assign(experiment="run1", piece_of=None), 1.0, 4)
    assert err.value.field == "savgol_window"


def test_gap_seconds_are_the_missing_samples_times_the_interval(tmp_path):
    """400 lone samples missing at 20 Hz are 20 s missing; each gap's span between the present
    samples around it counted 2 intervals, so ``nnid inspect`` said "400 samples, 40 s"."""
    from typer.testing import CliRunner

    from nnid.cli import app
    from nnid.datasets.inspect import summarize

    log = _mocap_log(4000)
    log.loc[np.arange(5, 4000, 10), "u"] = np.nan  # 400 gaps of one sample each
    missing = summarize(log)["missing"]
    assert (missing["count"], missing["samples"]) == (400, 400)
    assert missing["seconds"] == pytest.approx(400 * 0.05)
    assert missing["longest_s"] == pytest.approx(0.05)
    gap = missing["gaps"][0]
    assert gap["missing_s"] == pytest.approx(0.05) and gap["length_s"] == pytest.approx(0.1)
    report = CleaningReport()
    mask_gaps([log], ["u"], report)
    assert "400 samples, 20 s missing in total, longest 0.05 s" in report.steps[0].detail
    log.to_csv(tmp_path / "dive.csv", index=False)
    done = CliRunner().invoke(app, ["inspect", str(tmp_path / "dive.csv")])
    assert done.exit_code == 0, done.output
    assert "400 samples, 20 s missing, longest 0.05 s" in " ".join(done.output.split())


def test_a_piece_is_told_by_its_marker_not_by_a_hash_in_the_label():
    """A user's run named 'dive#1' was taken for a piece cut at a gap, so a run shorter than
    the derivative window went without a derivative instead of being refused; pieces are
    told by the ``piece_of`` column that mask_gaps writes."""
    from nnid.datasets.preprocess import derive_accelerations

    t = np.arange(20) * 0.05
    short = pd.DataFrame({"t": t, "experiment": "dive#1", "u": np.sin(t)})
    with pytest.raises(NnidInputError, match="dive#1' has 20 samples") as err:
        derive_accelerations(short, 1.0, 4)
    assert err.value.field == "savgol_window"
    log = _mocap_log().assign(experiment="dive#1")
    log.loc[20, "u"] = np.nan  # cuts a 20-sample piece off the run's start
    (masked,) = mask_gaps([log], ["u"])
    assert list(dict.fromkeys(masked["experiment"])) == ["dive#1#0", "dive#1#1"]
    assert (masked["piece_of"] == "dive#1").all()
    out = derive_accelerations(masked, 1.0, 4)
    assert out["du"].iloc[:20].isna().all() and np.isfinite(out["du"].iloc[40:-40]).all()


def test_a_piece_stays_one_through_resampling_and_is_no_unknown_column():
    """resample_log kept numeric columns only, so a piece lost its marker and a short one was
    then refused ("'dive#1' has 20 samples") where it had been skipped; inspect listed the
    marker among the log's unknown columns."""
    from nnid.datasets.inspect import summarize
    from nnid.datasets.preprocess import derive_accelerations, resample_log

    t = np.arange(400) * 0.05
    log = pd.DataFrame({"t": t, "experiment": "dive", "u": np.sin(t), "tau_X": np.cos(t)})
    log.loc[20, "u"] = np.nan
    (masked,) = mask_gaps([log], ["u"])
    assert summarize(masked)["columns"]["other"] == []
    again = resample_log(masked, 20.0)
    assert (again["piece_of"] == "dive").all()
    out = derive_accelerations(again, 1.0, 4)
    assert out["du"].iloc[:20].isna().all() and np.isfinite(out["du"].iloc[40:-40]).all()


def test_pieces_are_numbered_and_clocked_alike_by_mask_gaps_and_resample():
    """mask_gaps numbered a run's segments from #1 and kept the run's clock, while
    resample_log (and the readers) numbered them from #0 and restarted each piece's t at 0:
    one hole gave 'dive#1' or 'dive#0' depending on the step that cut it, and the hole was not
    in the resampled log's t. Both now give dive#0, dive#1 on the run's clock."""
    from nnid.datasets.preprocess import resample_log

    log = _mocap_log(400).assign(experiment="dive")
    t = log["t"].to_numpy()
    log.loc[200:239, "u"] = np.nan  # two seconds at 20 Hz
    (masked,) = mask_gaps([log], ["u"])
    resampled = resample_log(log.drop(index=range(200, 240)), 20.0, gap=0.5)
    for out in (masked, resampled):
        assert list(dict.fromkeys(out["experiment"])) == ["dive#0", "dive#1"]
        second = out[out["experiment"] == "dive#1"]
        assert second["t"].iloc[0] == pytest.approx(t[240] - t[0])


def test_a_sequence_step_naming_a_run_takes_all_its_pieces():
    """A Weiss sequence step names its run ('surge'); masked at a gap the run became pieces
    'surge#0', 'surge#1' (piece_of 'surge') and the step was refused: 'the log has no
    experiments ['surge']'. The step takes every piece of its run, and no other run."""
    from nnid.datasets.arrays import motion_arrays
    from nnid.trainers.sequence import _subset

    log = pd.concat(
        [_mocap_log(60).assign(experiment="surge"), _mocap_log(40).assign(experiment="yaw")],
        ignore_index=True,
    )
    log.loc[20:24, "u"] = np.nan
    [pieces] = mask_gaps([log], ["u"])
    assert list(pd.unique(pieces["experiment"])) == ["surge#0", "surge#1", "yaw"]
    data = motion_arrays(pieces)
    assert list(data["experiment_runs"]) == ["surge", "surge", "yaw"]
    assert _subset(data, ["surge"])["t"].size == 55
    assert _subset(data, ["surge#1"])["t"].size == 35  # a piece by its own name still
    with pytest.raises(NnidInputError, match=r"no experiments \['roll'\]"):
        _subset(data, ["roll"])


def test_a_run_cut_into_pieces_is_named_as_logged_in_a_split_and_in_exclude():
    """A reader cut run 'b' at a gap into 'b#0', 'b#1' (piece_of 'b'); a split that held out
    'b', the loop's held-out runs and ``--exclude b`` refused it as 'not in the log', though
    the user named the run as logged. A run's name stands for all its pieces; a piece is
    still named by its own label, and an unknown name is still refused."""
    from nnid.config import SplitSpec
    from nnid.datasets.log import run_pieces
    from nnid.loop.residual_loop import ResidualLoop
    from nnid.pipeline import make_split
    from nnid.runs import exclude_experiments

    runs = [_mocap_log(80).assign(experiment=e) for e in ("a", "b", "c")]
    log = pd.concat(runs, ignore_index=True)
    log.loc[110:114, "u"] = np.nan
    [pieces] = mask_gaps([log], ["u"])
    assert list(pd.unique(pieces["experiment"])) == ["a", "b#0", "b#1", "c"]
    assert run_pieces(pieces, ["b", "c", "b#1", "z"]) == ["b#0", "b#1", "c", "b#1", "z"]
    assert run_pieces(log, ["b"]) == ["b"]  # no pieces: as given
    split = make_split(pieces, SplitSpec(by="experiment", validation=["b"], test=["c"]))
    assert set(split.validation["experiment"]) == {"b#0", "b#1"}
    assert set(split.train["experiment"]) == {"a"}
    loop = ResidualLoop(None, validation_experiments=["b"])
    train, held = loop._split(pieces)
    assert set(held["experiment"]) == {"b#0", "b#1"} and set(train["experiment"]) == {"a", "c"}
    kept = exclude_experiments(pieces, ["b"], CleaningReport())
    assert list(pd.unique(kept["experiment"])) == ["a", "c"]
    with pytest.raises(NnidInputError, match=r"experiments z are not in the log"):
        exclude_experiments(pieces, ["z"], CleaningReport())


def test_a_config_keeps_the_pieces_of_a_run_it_names(tmp_path):
    """data.experiments = ["a", "b"] on a log whose reader cut 'b' into 'b#0', 'b#1' refused
    'b' as not in the log (the split and --exclude already took a run's name for its
    pieces); an unknown name is still refused, naming the runs the log has."""
    from nnid.config import TrainConfig, load_config
    from nnid.pipeline import load_inputs

    runs = [_mocap_log(80).assign(experiment=e) for e in ("a", "b", "c")]
    log = pd.concat(runs, ignore_index=True)
    log.loc[110:114, "u"] = np.nan
    [pieces] = mask_gaps([log], ["u"])
    pieces = pieces.assign(**{f"tau_{c}": 0.0 for c in "YZKMN" if f"tau_{c}" not in pieces})
    pieces.to_parquet(tmp_path / "cut.parquet")
    cfg = tmp_path / "t.toml"
    for names in (["a", "b"], ["a", "z"]):
        cfg.write_text(f'kind = "train"\n[data]\nlog = "cut.parquet"\nexperiments = {names}\n'
                       '[model]\nkind = "fossen"\ndofs = ["u"]\n')  # fmt: skip
        spec = load_config(cfg, TrainConfig)
        if names[1] == "z":
            with pytest.raises(NnidInputError, match=r"\['z'\] are not in the log \(it has "
                                                     r"\['a', 'b', 'c'\]\)"):  # fmt: skip
                load_inputs(spec, cfg, [spec.model], vehicle="seamor")
        else:
            inputs = load_inputs(spec, cfg, [spec.model], vehicle="seamor")
            assert list(pd.unique(inputs.log["experiment"])) == ["a", "b#0", "b#1"]


def _train_surge(tmp_path, log: pd.DataFrame):
    """``nnid train`` of a surge Fossen fit on ``log`` (written as dvl.csv): the CLI's result
    and its output on one line."""
    from typer.testing import CliRunner

    from nnid.cli import app

    log.to_csv(tmp_path / "dvl.csv", index=False)
    cfg = tmp_path / "t.toml"
    cfg.write_text('kind = "train"\nvehicle = "seamor"\n[data]\nlog = "dvl.csv"\n'
                   '[model]\nkind = "fossen"\ndofs = ["u"]\n')  # fmt: skip
    done = CliRunner().invoke(app, ["train", str(cfg), "--out", str(tmp_path / "out")])
    return done, " ".join(done.output.split())


def _slow(log: pd.DataFrame, columns: list[str], k: int) -> pd.DataFrame:
    """``columns`` kept on every ``k``-th row of each run only: a slower sensor on one clock."""
    out = log.copy()
    keep = np.zeros(len(log), dtype=bool)
    for idx in log.groupby("experiment").indices.values():
        keep[idx[::k]] = True
    out.loc[~keep, columns] = np.nan
    return out


def _inspected(log: pd.DataFrame, path) -> str:
    """What ``nnid inspect`` says of ``log`` written to ``path``, on one line."""
    from typer.testing import CliRunner

    from nnid.cli import app

    log.to_csv(path, index=False)
    done = CliRunner().invoke(app, ["inspect", str(path)])
    assert done.exit_code == 0, done.output
    return " ".join(done.output.split())


def test_inspect_says_a_slow_channel_is_its_rate_not_hundreds_of_gaps(tmp_path):
    """z kept on every 10th row was said as '36 gaps in z … masked where used': a sensor at
    2 Hz beside 20 Hz ones, not dropouts. The 9 rows after its last sample were then said as
    '1 gap in z (9 samples …)': they are outside its sampled span, and said so."""
    log = _slow(_mocap_log().assign(experiment="dive"), ["z"], 10)
    said = _inspected(log, tmp_path / "slow.csv")
    assert "slow z logged every 10th row: 2 Hz against 20 Hz (not filled" in said
    # after its last sample (row 390 of 400): outside its span, said so, and no gap
    assert "its samples end at t = 19.5 s: 9 rows after its last sample" in said
    assert "missing" not in said


def test_inspect_says_a_slow_channel_whose_rate_was_not_measured_once_not_as_gaps(tmp_path):
    """u on every 5th row of a 30-row run: too few samples to measure its rate. inspect
    listed it as slow and counted its 20 empty cells again as '5 gaps in u … bridged from the
    pose or masked where used'. They are said once, with the slow channel, as what they may
    be."""
    from nnid.datasets.inspect import summarize

    log = _slow(_mocap_log(30).assign(experiment="b"), ["u"], 5)
    info = summarize(log)
    assert [(ch["rate_hz"], ch["samples"]) for ch in info["slow"]] == [(None, [6])]
    assert info["missing"]["count"] == 0
    said = _inspected(log, tmp_path / "short.csv")
    assert "u's rate could not be measured in b (6 samples)" in said
    assert "nor its empty cells counted as gaps (they may be its rate)" in said
    assert "missing" not in said


def test_a_fit_on_a_slow_attitude_gives_the_full_logs_estimates(tmp_path):
    """φ, θ kept on every 5th row: every row lacked them, so the split masked the whole log
    ('the training split is empty'). Read between their samples with the gyro, the roll and
    pitch fit (restoring forces on every row) gives the full log's estimates within their
    standard errors, and the report says what was filled."""
    from importlib import resources

    from nnid.config import TrainConfig, load_config
    from nnid.datasets.measurement import Measurement
    from nnid.loop.scenarios import effect_log
    from nnid.pipeline import build_model, load_inputs, make_split
    from nnid.vehicle import load_vehicle

    minirov = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))
    meas = Measurement(kind="dvl_imu", velocity_noise=0.005)
    full = effect_log(load_vehicle(minirov), duration=60, n_experiments=3, seed=3, measurement=meas)
    fits = {}
    for name, log in (("full", full), ("slow", _slow(full, ["phi", "theta"], 5))):
        log.to_parquet(tmp_path / f"{name}.parquet")
        cfg = tmp_path / f"{name}.toml"
        cfg.write_text(f'kind = "train"\nvehicle = "{minirov}"\n[data]\nlog = "{name}.parquet"\n'
                       '[model]\nkind = "fossen"\ndofs = ["p", "q"]\n')  # fmt: skip
        spec = load_config(cfg, TrainConfig)
        inputs = load_inputs(spec, cfg, [spec.model])
        split = make_split(inputs.log, spec.split, report=inputs.report)
        model = build_model(spec.model, inputs, 0.0).fit(split.train, split.validation)
        fits[name] = (model.estimate_.as_dict(), inputs.report)
    (full_fit, _), (slow_fit, report) = fits["full"], fits["slow"]
    for key, est in full_fit.items():
        assert abs(slow_fit[key]["value"] - est["value"]) < est["stderr"], key
    step = next(s for s in report.steps if s.step == "slow channels")
    assert step.columns == ["phi", "theta"]
    assert "phi logged every 5th row: 4 Hz against 20 Hz" in step.detail
    assert "samples between its own filled" in step.detail and ": with the gyro" in step.detail


def test_a_slow_yaw_is_filled_where_the_gyro_has_samples_and_kept_in_the_logs_range():
    """A yaw logged every 5th row beside a gyro with one empty cell: that cell had kept every
    span from being filled (the report blamed differentiation), and a yaw logged in [0, 2π)
    came out past 2π. Now only the span holding the empty cell stays a gap, and every filled
    value is the turning the gyro measured, in the log's range."""
    from nnid.datasets.cleaning import CleaningReport
    from nnid.datasets.gaps import fill_slow

    t = np.arange(401) * 0.05
    truth = np.mod(1.0 + 0.5 * t, 2 * np.pi)  # a steady turn at 0.5 rad/s, logged in [0, 2π)
    log = pd.DataFrame({"t": t, "phi": 0.0, "theta": 0.0, "psi": truth, "p": 0.0, "q": 0.0})
    log["r"] = 0.5
    log.loc[103, "r"] = np.nan  # one dropout of the gyro, in the span from row 100 to 105
    slow = _slow(log.assign(experiment="turn"), ["psi"], 5)
    report = CleaningReport(source="test")
    out = fill_slow(slow, report)
    gap = np.isnan(out["psi"].to_numpy())
    assert list(np.flatnonzero(gap)) == [101, 102, 103, 104]
    np.testing.assert_allclose(out["psi"].to_numpy()[~gap], truth[~gap], atol=1e-12)
    assert out["psi"].max() < 2 * np.pi
    (step,) = report.steps
    assert "or where the gyro has empty cells left as gaps" in step.detail


def test_a_slow_velocity_without_the_pose_is_refused_not_masked_away(tmp_path):
    """u, v (a DVL) kept on every 5th row, thrust at the full rate, no x, y to bridge them
    from: masking their empty cells took all 200 rows out (pieces of one row, 'too short to
    use'), and ``nnid train`` said only 'the training split is empty'. It is refused (exit 2),
    naming the log, the channels and their rate against the log's."""
    log = _mocap_log(200).drop(columns=["x", "y"]).assign(experiment="dive")
    log = _slow(log.assign(**{f"tau_{c}": 0.0 for c in "YZKMN"}), ["u", "v"], 5)
    done, said = _train_surge(tmp_path, log)
    assert done.exit_code == 2, said
    assert "dvl.csv, field 'u': u logged every 5th row: 4 Hz against 20 Hz; v logged" in said
    assert "160 of the 200 rows" in said and "full rate" in said
    with pytest.raises(NnidInputError, match="u logged every 5th row"):
        mask_gaps([log], ["u"])  # the detector's and the loop's masking, too


def test_rows_outside_a_slow_attitudes_span_are_said_as_such():
    """A yaw kept on every 5th row of 403: the 2 rows after its last sample were counted among
    'left as gaps' with a longer hole's; they are said as outside its sampled span, with the
    time its samples end, and that they are taken out with the gaps."""
    from nnid.datasets.gaps import fill_slow

    t = np.arange(403) * 0.05
    log = pd.DataFrame({"t": t, "phi": 0.0, "theta": 0.0, "psi": 0.5 * t, "p": 0.0, "q": 0.0})
    log["r"] = 0.5
    report = CleaningReport(source="test")
    out = fill_slow(_slow(log.assign(experiment="turn"), ["psi"], 5), report)
    assert list(np.flatnonzero(out["psi"].isna())) == [401, 402]
    (step,) = report.steps
    assert (
        "320 samples between its own filled; its samples end at t = 20 s: 2 rows after its "
        "last sample: outside its sampled span, taken out with the gaps" in step.detail
    )
    assert "left as gaps" not in step.detail
    # in a log of several runs, the run is named
    two = pd.concat([log.assign(experiment="a"), log.iloc[:401].assign(experiment="b")])
    report = CleaningReport(source="test")
    fill_slow(_slow(two.reset_index(drop=True), ["psi"], 5), report)
    assert "in a, its samples end at t = 20 s: 2 rows" in report.steps[0].detail
    assert "in b," not in report.steps[0].detail
    # inspect: outside the span is no gap; a hole inside it still is
    from nnid.datasets.inspect import summarize

    z = _slow(_mocap_log().assign(experiment="dive"), ["z"], 10)
    z.loc[200:260, "z"] = np.nan
    info = summarize(z)
    after = {"experiment": None, "first_t": 0.0, "before": 0, "last_t": 19.5, "after": 9}
    assert info["slow"][0]["ends"] == [after]
    assert [g["rows"] for g in info["missing"]["gaps"]] == [79]


def test_each_run_is_measured_at_its_own_rate():
    """Run a at 20 Hz with psi on every 5th row and run b at 100 Hz with psi on every 50th got
    one stride from the whole log (5th row, 4 Hz against 20 Hz), so b's yaw, 50 rows between
    samples, was a hole past 3 strides and left unfilled. Each run is said at its own rate and
    filled."""
    from nnid.datasets.gaps import fill_slow, slow_channels

    runs = []
    for name, n, dt in (("a", 2000, 0.05), ("b", 1001, 0.01)):
        t = np.arange(n) * dt
        runs.append(pd.DataFrame({"t": t, "experiment": name, "phi": 0.0, "theta": 0.0,
                                  "psi": 0.2 * t, "p": 0.0, "q": 0.0, "r": 0.2}))  # fmt: skip
    log = pd.concat(runs, ignore_index=True)
    log.loc[np.r_[np.arange(2000) % 5 != 0, np.arange(1001) % 50 != 0], "psi"] = np.nan
    out = fill_slow(log)
    assert out["psi"].notna().sum() == len(log) - 4  # a's 4 rows after its last sample
    np.testing.assert_allclose(out["psi"].dropna(), 0.2 * log["t"][out["psi"].notna()])
    said = [ch.describe() for ch in slow_channels(log)]
    assert said == [
        "psi logged every 5th row in a: 4 Hz against 20 Hz",
        "psi logged every 50th row in b: 2 Hz against 100 Hz",
    ]


def test_a_slow_channel_on_a_millisecond_clock_is_said_at_the_clocks_rate():
    """A 120-Hz clock stamped in whole ms (8, 8, 9 ms) with psi on every 12th row: the runs'
    plain median step made it '10.4 Hz against 125 Hz'. Each run's step is its typical step
    (nnid.datasets.log.typical_step), so 10 Hz against 120 Hz."""
    from nnid.datasets.gaps import slow_channels

    true = np.arange(600) / 120
    log = pd.DataFrame({"t": np.round(true * 1e3) / 1e3, "experiment": "a", "phi": 0.0,
                        "theta": 0.0, "psi": 0.2 * true, "p": 0.0, "q": 0.0, "r": 0.2})  # fmt: skip
    log.loc[np.arange(600) % 12 != 0, "psi"] = np.nan
    (slow,) = slow_channels(log)
    assert slow.stride == 12
    assert slow.clock_hz == pytest.approx(120.0, rel=1e-3)
    assert slow.rate_hz == pytest.approx(10.0, rel=1e-3)


def test_a_millisecond_clock_resumed_after_another_run_keeps_its_rate():
    """Run a's rows come in two blocks with run b's between (a reader's resumed run): sorted
    by experiment, the step between a's blocks, 0.51 s, was read as 61 or 62 samples of its
    120-Hz clock stamped in whole ms, half a sample off the line of the stamps, so its step
    fell back on the 8-ms median: 'against 125 Hz'. Only steps between rows side by side in
    the log are sample steps, each block on a line of its own: 120 Hz."""
    from nnid.datasets.gaps import slow_channels

    def run(name: str, start: float) -> pd.DataFrame:
        true = start + np.arange(300) / 120
        psi = np.where(np.arange(300) % 12 == 0, 0.2 * true, np.nan)
        return pd.DataFrame({"t": np.round(true * 1e3) / 1e3, "experiment": name, "phi": 0.0,
                             "theta": 0.0, "psi": psi, "p": 0.0, "q": 0.0, "r": 0.2})  # fmt: skip

    log = pd.concat([run("a", 0.0), run("b", 0.0), run("a", 3.0042)], ignore_index=True)
    slow = slow_channels(log)
    assert slow and all(s.stride == 12 for s in slow)
    assert [s.clock_hz for s in slow] == pytest.approx([120.0] * len(slow), rel=1e-4)


def test_a_bridge_warns_of_an_uneven_run_by_its_name():
    """bridge_from_pose derives a run's velocities with its experiment column dropped, so a
    run with a dropped sample was warned of as 'the log is not evenly sampled', whichever of
    a log's runs it was. The warning names the run."""
    log = _mocap_log().assign(experiment="dive7")
    log = log.drop(index=50).reset_index(drop=True)  # a dropped sample: one step of two
    log.loc[100:109, ["u", "r"]] = np.nan
    with pytest.warns(UserWarning, match="not evenly sampled") as caught:
        out = bridge_from_pose(log)
    said = [str(w.message) for w in caught if "not evenly sampled" in str(w.message)]
    assert said and all(m.startswith("experiment 'dive7' is not evenly") for m in said), said
    assert out.loc[100:109, ["u", "r"]].notna().all().all()


def test_a_slow_channel_in_many_runs_is_said_in_a_few_names_and_kept_whole():
    """A log a reader cut into hundreds of runs at two rates was said 'psi logged every 5th
    row in r0, r1, … r349: …', a sentence hundreds of names long, in the cleaning report, the
    refusal and ``inspect``. Each rate names a few runs and counts the rest; the whole list
    stays in ``runs`` (``inspect``'s summary.json)."""
    from nnid.datasets.gaps import SlowChannel, slow_channels

    def run(name: str, k: int) -> pd.DataFrame:
        one = pd.DataFrame({"t": np.arange(60) * 0.05, "experiment": name, "psi": 0.0})
        one.loc[np.arange(60) % k != 0, "psi"] = np.nan
        return one

    log = pd.concat([run(f"r{i}", 5) for i in range(5)] + [run("s", 2)], ignore_index=True)
    five, two = slow_channels(log)
    assert five.runs == [f"r{i}" for i in range(5)] and two.runs == ["s"]
    assert (
        five.describe()
        == "psi logged every 5th row in 5 runs (r0, r1, r2 and 2 more): 4 Hz against 20 Hz"
    )
    assert two.describe() == "psi logged every 2nd row in s: 10 Hz against 20 Hz"
    many = SlowChannel("z", 20, 1.0, 20.0, [f"r{i}" for i in range(350)])
    assert many.describe() == (
        "z logged every 20th row in 350 runs (r0, r1, r2 and 347 more): 1 Hz against 20 Hz"
    )


def test_a_short_run_of_a_slow_channel_is_judged_by_its_other_runs_rate():
    """Run b holds 6 samples of u, every 5th row as in run a: under SLOW_MIN_STEPS steps, it
    was not judged slow, so its 24 empty cells were masked as '6 gaps in u' and its 6 samples
    lost as 'too short to use'. It is judged at a's rate, taken out whole as a's is, and a
    slow yaw in it is filled as a's is."""
    from nnid.datasets.gaps import SLOW_STEP, fill_slow, slow_channels

    a, b = _mocap_log(200).assign(experiment="a"), _mocap_log(30).assign(experiment="b")
    c = _mocap_log(100).assign(experiment="c")  # u on every row: what a fit has left
    log = pd.concat([_slow(pd.concat([a, b], ignore_index=True), ["u"], 5), c],
                    ignore_index=True)  # fmt: skip
    assert [(ch.stride, ch.runs) for ch in slow_channels(log)] == [(5, None)]
    report = CleaningReport(source="test")
    (kept,) = mask_gaps([log], ["u"], report)
    assert set(kept["experiment"]) == {"c"}
    assert [s.step for s in report.steps] == [SLOW_STEP]  # no "6 gaps in u" masked
    assert report.steps[0].detail.startswith(
        "a (200 rows): u logged every 5th row: 4 Hz against 20 Hz; b (30 rows): u logged"
    )
    yaw = fill_slow(_slow(pd.concat([a, b], ignore_index=True), ["psi"], 5))
    assert yaw.groupby("experiment")["psi"].count().to_dict() == {"a": 196, "b": 26}


def test_a_short_run_whose_rate_no_run_measures_is_said_so_not_masked_away():
    """The same short run alone (or beside a run at another rate): no channel was found slow,
    its empty cells were masked as gaps, pieces of one row, and mask_gaps handed back an
    empty log with '6 gaps in u masked'. Its rate could not be measured, and it is said so
    with the run and its samples: taken out whole, refused where that leaves nothing."""
    from nnid.datasets.gaps import SLOW_STEP, slow_channels

    b = _slow(_mocap_log(30).assign(experiment="b"), ["u"], 5)
    with pytest.raises(NnidInputError, match=r"u's rate could not be measured in b \(6 samples\)"):
        mask_gaps([b], ["u"])
    a = _slow(_mocap_log(200).assign(experiment="a"), ["u"], 2)  # at 10 Hz, b at 4 Hz
    c = _mocap_log(100).assign(experiment="c")
    log = pd.concat([a, b, c], ignore_index=True)
    at_a, unmeasured = slow_channels(log)
    assert (at_a.stride, at_a.runs) == (2, ["a"])
    assert (unmeasured.rate_hz, unmeasured.runs, unmeasured.samples) == (None, ["b"], [6])
    report = CleaningReport(source="test")
    (kept,) = mask_gaps([log], ["u"], report)
    assert set(kept["experiment"]) == {"c"} and [s.step for s in report.steps] == [SLOW_STEP]
    detail = report.steps[0].detail
    # the run named once (it read 'b (30 rows): u's rate could not be measured in b (…)'),
    # and its empty cells said as what they may be, not as what they are
    assert "b (30 rows): u's rate could not be measured (6 samples): fewer than" in detail
    assert "samples may be its rate" in detail


def test_a_run_with_a_slow_velocity_is_taken_out_and_said_the_others_fit(tmp_path):
    """Run a logs u, v on every row, run b on every 5th only: masking took b's rows out
    (pieces of one row) and the fit went on with a, until a slow channel in any run refused
    the whole log. It fits on a; the report says b was taken out for u's and v's rate, with
    its rows, not as gaps; refused only where that leaves nothing (the test above)."""

    from nnid.datasets.gaps import SLOW_STEP

    one = _mocap_log(200).drop(columns=["x", "y"]).assign(**{f"tau_{c}": 0.0 for c in "YZKMN"})
    log = pd.concat([one.assign(experiment="a"), one.assign(experiment="b")], ignore_index=True)
    log.loc[200:, ["u", "v"]] = _slow(log.loc[200:], ["u", "v"], 5)[["u", "v"]]
    log.loc[50:52, "w"] = np.nan  # an ordinary gap in a: said as a gap, apart
    report = CleaningReport(source="test")
    train, val = mask_gaps([log.iloc[np.r_[0:140, 200:340]], log.iloc[np.r_[140:200, 340:400]]],
                           ["u", "v", "w"], report)  # fmt: skip
    assert set(train["experiment"]) == {"a#0", "a#1"} and set(val["experiment"]) == {"a"}
    masked, slow = report.steps
    assert masked.detail.startswith("1 gap in w (3 samples") and masked.rows_removed == 3
    assert slow.step == SLOW_STEP and slow.rows_removed == 200
    assert slow.detail.startswith(
        "b (200 rows): u logged every 5th row: 4 Hz against 20 Hz, v logged every 5th row: "
        "4 Hz against 20 Hz: taken out, not masked as gaps"
    )
    done, said = _train_surge(tmp_path, log)
    assert done.exit_code == 0, said
    assert "slow channels: b (200 rows): u logged every 5th row" in said
    # refused where nothing is left (a's u dropped out on 3 of every 5 rows: pieces of one
    # row, gaps, not a rate): the rows it names are b's slow cells, not a's gaps with them
    log.loc[np.flatnonzero(np.arange(200) % 5 % 2 == 0), "u"] = np.nan
    with pytest.raises(NnidInputError, match="take 160 of the 400 rows out"):
        mask_gaps([log], ["u", "v"])


def test_a_slow_position_no_fit_reads_is_left_in_and_said_not_refused(tmp_path):
    """x, y from a 2-Hz GPS beside 20-Hz u..r, attitude and thrust: make_split masked every
    motion column, so the log was refused ('x logged every 10th row ...') although a Fossen
    least-squares fit reads only ν, ν̇ and the attitude. It trains, with the full log's
    estimates and scores, and the report says x, y were not masked and why; a slow u beside
    them (read by the fit, and no whole pose to bridge it from) is still refused."""
    from nnid.config import TrainConfig, load_config
    from nnid.pipeline import run_train

    one = _mocap_log(200).assign(**{f"tau_{c}": 0.0 for c in "YZKMN"})
    full = pd.concat([one.assign(experiment="a"), one.assign(experiment="b")], ignore_index=True)
    results = {}
    gps = _slow(full, ["x", "y"], 10)
    for name, log in (("full", full), ("gps", gps), ("dvl", _slow(gps, ["u"], 10))):
        log.to_csv(tmp_path / f"{name}.csv", index=False)
        cfg = tmp_path / f"{name}.toml"
        cfg.write_text(f'kind = "train"\nvehicle = "seamor"\n[data]\nlog = "{name}.csv"\n'
                       '[model]\nkind = "fossen"\ndofs = ["u"]\n')  # fmt: skip
        try:
            results[name] = run_train(load_config(cfg, TrainConfig), cfg)
        except NnidInputError as exc:
            results[name] = exc
    full_fit, gps = results["full"], results["gps"]
    assert not isinstance(gps, NnidInputError), gps.message
    assert gps.model.params == full_fit.model.params
    assert gps.metrics["validation"] == full_fit.metrics["validation"]
    said = [s for s in gps.report.steps if s.step in ("mask gaps", "unread motion")]
    assert [(s.step, s.columns) for s in said] == [("unread motion", ["x", "y"])]
    assert said[0].detail.startswith(
        "x, y not masked: no model of this run reads them (360 empty cells in x, 360 empty "
        "cells in y): their rows stay in the fit and the scores"
    )
    assert said[0].rows_removed == 0 and len(gps.split.train) == len(full_fit.split.train)
    assert isinstance(results["dvl"], NnidInputError)  # read by the fit: refused as before
    assert results["dvl"].message.startswith("u logged every 10th row: 2 Hz against 20 Hz: the")


def test_each_model_kind_says_the_motion_columns_it_reads():
    """What make_split masks gaps in (read_motion): a least-squares Fossen fit, SINDy and the
    synthesis read ν, ν̇ and the attitude; the UKF propagates the whole state and a model
    that does not say (Caccia, a hybrid) reads every motion column; a NARX its own columns;
    an ensemble its members'; under an autopilot replay, every column."""
    from conftest import make_vehicle

    from nnid.datasets.log import MOTION
    from nnid.evaluation.prediction import Replay
    from nnid.models import base
    from nnid.pipeline import read_motion
    from nnid.trainers.ukf import UnscentedKalman

    vehicle, log = make_vehicle(), pd.DataFrame(columns=["t", *MOTION, "tau_X"])
    equation = [*MOTION[3:]]  # phi theta psi, u..r, du..dr

    def reads(kind, **kw):
        return read_motion([base.model_class(kind)(**kw)], log)

    for kind in ("fossen", "sindy", "synthesis"):
        assert reads(kind, vehicle=vehicle) == equation, kind
    assert reads("fossen", vehicle=vehicle, pose_velocities=["u"]) == list(MOTION)
    assert reads("fossen", vehicle=vehicle, trainer=UnscentedKalman()) == list(MOTION)
    assert reads("caccia", vehicle=vehicle) == reads("hybrid", vehicle=vehicle) == list(MOTION)
    assert reads("narx", inputs=["tau_X", "x"], outputs=["u"]) == ["x", "u"]
    fossen = base.model_class("fossen")(vehicle=vehicle)
    assert reads("ensemble", model=fossen) == equation
    assert read_motion([fossen], log.drop(columns=["v"])) == [c for c in MOTION if c != "v"]
    assert read_motion([fossen], log, Replay(None, pd.DataFrame())) == list(MOTION)


def test_a_simulated_pose_starts_from_the_runs_nearest_sample_not_zero():
    """An empty x (a slow GPS no fit reads, left in) became 0 at a free run's start: the
    simulated x began at the origin. It is held from the run's last sample (else its
    first), each run on its own."""
    from nnid.evaluation.prediction import measured_states

    log = pd.DataFrame({"experiment": ["a"] * 3 + ["b"] * 3, "t": [0.0, 0.1, 0.2] * 2,
                        "x": [np.nan, 5.0, np.nan, np.nan, np.nan, 7.0], "u": 1.0})  # fmt: skip
    states = measured_states(log)
    assert list(states[:, 0]) == [5.0, 5.0, 5.0, 7.0, 7.0, 7.0]
    assert list(states[:, 6]) == [1.0] * 6 and not states[:, 1:6].any()


def test_unread_motion_is_not_said_as_the_logs_gaps_in_the_summary():
    """The 'x, y not masked' note was filed as a 'mask gaps' step: compare's summary read it
    as the log's gaps ("The log's gaps: x, y not masked: …; N of the M validation samples
    left are scored (the rest warm the pieces up)") with nothing masked. It is its own step,
    which the console still lists and the summary leaves out."""
    from nnid.config import SplitSpec
    from nnid.datasets.gaps import GAP_STEPS, UNREAD_STEP
    from nnid.pipeline import _masked_note, make_split
    from nnid.runs import lost_rows

    one = _mocap_log(200)
    log = _slow(pd.concat([one.assign(experiment="a"), one.assign(experiment="b")],
                          ignore_index=True), ["x", "y"], 20)  # fmt: skip
    report = CleaningReport(source="log")
    make_split(log, SplitSpec(by="experiment", validation=["b"]), report=report,
               read=["u", "r", "psi"])  # fmt: skip
    assert [s.step for s in report.steps] == [UNREAD_STEP] and UNREAD_STEP in GAP_STEPS
    assert lost_rows(report)[0].startswith("unread motion: x, y not masked")
    rows = [{"name": "a", "validation": {"samples": 190}}]
    assert _masked_note(report, rows, ["a"], "validation", 200) == ""


def test_a_slow_channel_that_empties_one_part_is_refused_as_such():
    """Runs a, b train, c validates, u logged every 5th row in c only: c was taken out
    whole and make_split said 'the validation split is empty: hold out an experiment or a
    block', untrue; with a and b slow, 'the training split is empty'. The error names the
    channel, its rate and the part it emptied, as the residual loop's does."""
    from nnid.config import SplitSpec
    from nnid.pipeline import make_split

    one = _mocap_log(100)
    log = pd.concat([one.assign(experiment=e) for e in "abc"], ignore_index=True)
    slow_c = log.copy()
    slow_c.loc[200:, "u"] = _slow(log.loc[200:], ["u"], 5)["u"]
    spec = SplitSpec(by="experiment", validation=["c"])
    with pytest.raises(NnidInputError, match=r"nothing of the validation part \(100 rows: c\)"
                       ) as err:  # fmt: skip
        make_split(slow_c, spec, read=["u"])
    assert err.value.message.startswith("u logged every 5th row: 4 Hz against 20 Hz: the")
    assert err.value.field == "u"
    slow_ab = log.copy()
    slow_ab.loc[:199, "u"] = _slow(log.loc[:199], ["u"], 5)["u"]
    with pytest.raises(NnidInputError, match="nothing of the training part"):
        make_split(slow_ab, spec, read=["u"])
    from conftest import make_vehicle

    from nnid.loop.residual_loop import ResidualLoop

    taus = {f"tau_{c}": 0.0 for c in "YZKMN"}
    loop = ResidualLoop(make_vehicle(), validation_experiments=["c"])
    with pytest.raises(NnidInputError, match="nothing of the held-out part"):
        loop.fit(slow_c.drop(columns=["x", "y"]).assign(**taus))  # no pose to bridge u from
    report = CleaningReport(source="log")  # held out where it logs u at the full rate: fits
    split = make_split(slow_c, SplitSpec(by="experiment", validation=["a"]), report=report,
                       read=["u"])  # fmt: skip
    assert set(split.train["experiment"]) == {"b"} and report.steps[-1].rows_removed == 100


def test_only_the_pose_a_derived_velocity_is_made_of_is_masked(tmp_path):
    """u v w from a DVL, the attitude at 20 Hz, z from a depth sensor, x y from a 1-Hz GPS,
    no p q r: p q r, derived from the attitude, masked the whole pose, so x y were found
    slow, every run taken out and the log refused. Only the attitude makes p q r: the fit
    runs, x and y said unmasked; u v w derived from the pose read x y z."""
    from nnid.datasets.log import ANGLES, MOTION
    from nnid.models.parametric import equation_columns

    log = _mocap_log(200).drop(columns=["p", "q", "r"])
    log = _slow(pd.concat([log.assign(experiment="a"), log.assign(experiment="b")],
                          ignore_index=True), ["x", "y"], 20)  # fmt: skip
    log = log.assign(**{f"tau_{c}": 0.0 for c in "YZKMN"})
    assert equation_columns(log.columns) == [*ANGLES, "u", "v", "w"]  # p q r: the angles
    equation = [c for c in MOTION if c not in ("x", "y", "z")]
    assert equation_columns(MOTION, ["p", "q", "r"]) == equation
    no_u = [c for c in MOTION if c != "u"]
    assert equation_columns(no_u) == no_u  # u from the whole pose
    no_xy = [c for c in MOTION if c not in ("x", "y")]
    # w from depth and the attitude reads z; a u no pose gives reads none of it
    assert equation_columns([c for c in no_xy if c != "w"]) == [c for c in no_xy if c != "w"]
    assert "z" not in equation_columns([c for c in no_xy if c != "u"])
    done, said = _train_surge(tmp_path, log)
    assert done.exit_code == 0, said
    assert "unread motion: x, y not masked" in said


def test_a_piece_without_a_pose_sample_starts_from_its_runs():
    """measured_states grouped by the piece label (a#1) that masking writes: a piece between
    two 1-Hz GPS samples held none and started x at 0. It takes its run's (``piece_of``)."""
    from nnid.evaluation.prediction import measured_states

    log = pd.DataFrame({"experiment": ["a#0"] * 2 + ["a#1"] * 2 + ["b"] * 2,
                        "piece_of": ["a"] * 4 + [None] * 2, "t": [0.0, 0.1] * 3,
                        "x": [np.nan, 5.0, np.nan, np.nan, 7.0, np.nan], "u": 1.0})  # fmt: skip
    assert list(measured_states(log)[:, 0]) == [5.0, 5.0, 5.0, 5.0, 7.0, 7.0]


def test_a_gap_bridged_in_a_log_joined_without_a_fresh_index_fills_its_own_run():
    """Two runs joined by pd.concat keep their index labels 0..399 twice: bridge_from_pose
    took a run's rows and wrote a bridged cell by label, so run a's gap was read as both runs'
    rows and its bridge written into run b's rows too. Rows are now taken by position."""
    truth = _mocap_log()
    a = truth.assign(experiment="a")
    a.loc[100:119, ["u", "r"]] = np.nan
    b = truth.assign(experiment="b", u=truth["u"] + 1.0)  # b has no gap: nothing of it changes
    out = bridge_from_pose(pd.concat([a, b]))
    alone = bridge_from_pose(a)
    pd.testing.assert_frame_equal(out.iloc[:400], alone)
    pd.testing.assert_frame_equal(out.iloc[400:], b)


def test_inspect_summarizes_runs_joined_without_a_fresh_index_as_alone():
    """pd.concat of two runs repeats the labels 0..199: ``summarize`` read each run's clock by
    label, so a run held the other's samples too (its duration negative, gaps that are none).
    By position, the summary is the one of the same log with a fresh index."""
    from nnid.datasets.inspect import summarize

    a = _mocap_log(400).assign(experiment="a")
    b = _mocap_log(200, dt=0.1).assign(experiment="b")
    joined = pd.concat([a, b])
    info = summarize(joined)
    assert info == summarize(joined.reset_index(drop=True))
    assert [e["samples"] for e in info["experiments"]] == [400, 200]
    assert info["gaps"] == []


def test_a_short_piece_cut_at_a_gap_is_left_unbridged_not_refused():
    """A run cut at a gap into pieces (``piece_of`` set) may leave a piece shorter than the
    Savitzky-Golay window. Velocities are not derived on such a piece, as on a stretch between
    gaps within a run; the bridge dropped ``piece_of`` before deriving, so a velocity gap in
    that piece was refused as a window too short for the whole log. It is left empty and not
    counted as bridged, and the long piece's gap is still bridged."""
    from nnid.datasets.preprocess import PIECE_OF

    whole = _mocap_log(300)
    long_piece = whole.iloc[:280].assign(experiment="dive#0")
    short = whole.iloc[292:].assign(experiment="dive#1")  # 8 samples: under the 0.5-s window
    log = pd.concat([long_piece, short], ignore_index=True)
    log[PIECE_OF] = "dive"
    log.loc[100:109, ["u", "r"]] = np.nan
    log.loc[len(long_piece) + 3 : len(long_piece) + 5, "r"] = np.nan
    report = CleaningReport()
    out = bridge_from_pose(log, report=report)
    assert out.loc[100:109, ["u", "r"]].notna().all().all()
    assert out.loc[len(long_piece) + 3 : len(long_piece) + 5, "r"].isna().all()
    (step,) = report.steps
    assert "1 gap in" in step.detail, step.detail


def test_a_piece_named_as_another_run_is_refused():
    """Cutting 'dive' at a gap made pieces 'dive#0' and 'dive#1' beside the log's own run
    'dive#1': rows go by label, so the two runs became one whose time went back."""
    first = _mocap_log(200).assign(experiment="dive")
    first.loc[100:109, "u"] = np.nan
    other = _mocap_log(200).assign(experiment="dive#1")
    log = pd.concat([first, other], ignore_index=True)
    with pytest.raises(NnidInputError, match="piece 'dive#1', the name of another") as err:
        mask_gaps([log], ["u", "v", "w", "p", "q", "r"])
    assert err.value.field == "experiment"
    # the same log with the other run named apart is cut as before
    cut = mask_gaps([log.replace({"experiment": {"dive#1": "dive2"}})], ["u"])[0]
    assert set(cut["experiment"]) == {"dive#0", "dive#1", "dive2"}
