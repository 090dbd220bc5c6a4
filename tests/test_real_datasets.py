"""Measured datasets through their reader configs, the BlueROV 1 vehicle file, the nlbench loaders,
and the reader additions they needed (row clock, multi-column experiment ids, angles interpolated
on the circle).

Tests that read ../shared/data skip with the reason when it is absent; the bundled Haizhe excerpt
and the reader-addition tests always run. The asserted numbers are the ones in the dataset cards
(datasets/*.md), with the stated margins.
"""

from __future__ import annotations

import gzip
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.benchmarks import load_benchmark
from nnid.datasets.column_map import load_column_map
from nnid.datasets.log import validate_log
from nnid.datasets.preprocess import derive_accelerations, derive_velocities, savgol_derivative
from nnid.datasets.readers import load_log, read_mapped
from nnid.errors import NnidInputError
from nnid.physics.thrusters import Actuation
from nnid.vehicle import load_vehicle

REPO = Path(__file__).parents[1]
SHARED = Path(__file__).parents[2] / "shared" / "data"
READERS = REPO / "configs" / "readers"
EXCERPT = REPO / "datasets" / "haizhe_excerpt.csv.gz"

_absent = pytest.mark.skipif(
    not SHARED.is_dir(), reason=f"measured data folder {SHARED} is absent (../shared/data)"
)


def needs_shared(test):
    """Mark a test as reading ../shared/data (marker ``shared``) and skip it when absent."""
    return pytest.mark.shared(_absent(test))


def _shared(folder: str) -> Path:
    path = SHARED / folder
    if not path.exists():
        pytest.skip(f"{path} is absent")
    return path


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(np.asarray(a, dtype=np.float64)))))


def _durations(log: pd.DataFrame) -> pd.Series:
    return log.groupby("experiment")["t"].max()


def _uniform(log: pd.DataFrame, dt: float) -> None:
    steps = log.groupby("experiment")["t"].diff().dropna()
    assert np.allclose(steps, dt, atol=1e-9)


def _xcorr_peak(f: np.ndarray, y: np.ndarray, dt: float, maxlag: int = 40) -> tuple[float, float]:
    """(peak correlation, lag in s) of y after f; parabolic interpolation around the peak."""
    f = (f - f.mean()) / f.std()
    y = (y - y.mean()) / y.std()
    lags = np.arange(-maxlag, maxlag + 1)
    c = np.array(
        [
            np.mean(f[max(-k, 0) : len(f) - max(k, 0)] * y[max(k, 0) : len(y) + min(k, 0)])
            for k in lags
        ]
    )
    i = int(np.argmax(c))
    off = 0.0
    if 0 < i < len(c) - 1:
        den = c[i - 1] - 2 * c[i] + c[i + 1]
        off = 0.5 * (c[i - 1] - c[i + 1]) / den if den else 0.0
    return float(c[i]), float((lags[i] + off) * dt)


# --- reader additions (always run) -------------------------------------------------------------


def test_row_clock_and_multi_column_experiment(tmp_path):
    """An hhmmss clock with 20 rows per second -> t = row / 20 per run; split/sample ids that
    repeat across splits stay separate runs; a dropped row leaves its gap."""
    rows = []
    for split in ("train", "test"):
        for k in range(45):
            rows.append({"split": split, "sample": "A_0", "time": 120000 + k // 20,
                         "depth": 0.01 * k, "pwm": 1100 + k})  # fmt: skip
    df = pd.DataFrame(rows)
    df.loc[50, "depth"] = np.nan  # test/A_0, row 5
    df.to_csv(tmp_path / "runs.csv", index=False)
    (tmp_path / "map.toml").write_text(
        'experiment = ["split", "sample"]\ndrop_nonfinite = true\nrate = 20.0\n'
        '[[sources]]\nfile = "runs.csv"\ntime = "time"\nrow_clock = 20.0\n'
        'columns = { z = "depth", cmd_1 = { from = "pwm", offset = -1000, scale = 0.001 } }\n'
    )
    log, report = load_log(tmp_path, tmp_path / "map.toml")
    assert sorted(log["experiment"].unique()) == ["test/A_0", "train/A_0"]
    train = log[log["experiment"] == "train/A_0"]
    assert len(train) == 45 and train["t"].iloc[-1] == pytest.approx(44 / 20)
    assert np.allclose(train["z"], 0.01 * np.arange(45))
    test = log[log["experiment"] == "test/A_0"]
    assert test["t"].iloc[-1] == pytest.approx(44 / 20)  # the dropped row does not shift time
    assert test["z"].iloc[5] == pytest.approx(0.05)  # interpolated across the one-row gap
    assert report.rows_removed == 1


def test_experiment_list_must_name_columns(tmp_path):
    (tmp_path / "map.toml").write_text(
        'experiment = ["file"]\n[[sources]]\nfile = "x.csv"\ntime = "t"\n'
    )
    with pytest.raises(NnidInputError, match="experiment"):
        load_column_map(tmp_path / "map.toml")


def test_angles_are_interpolated_on_the_circle(tmp_path):
    """A yaw crossing ±π, sampled at 7 Hz and resampled to 10 Hz, must not pass through 0."""
    t = np.arange(0, 1.0, 1 / 7)
    yaw = np.angle(np.exp(1j * (3.0 + 0.5 * t)))  # wraps from +π to −π at t ≈ 0.28 s
    pd.DataFrame({"t": t, "yaw": yaw, "pwm": 1500.0}).to_csv(tmp_path / "a.csv", index=False)
    (tmp_path / "map.toml").write_text(
        'rate = 10.0\n[[sources]]\nfile = "a.csv"\ntime = "t"\n'
        'columns = { psi = "yaw", cmd_1 = "pwm" }\n'
    )
    log, _ = load_log(tmp_path, tmp_path / "map.toml")
    expected = np.angle(np.exp(1j * (3.0 + 0.5 * log["t"].to_numpy())))
    assert np.abs(np.angle(np.exp(1j * (log["psi"] - expected)))).max() < 1e-9
    assert (log["psi"] < 0).any() and log["psi"].abs().min() > 2.8  # no excursion towards 0


# --- Haizhe: bundled excerpt (always) and the full set ----------------------------------------


def test_haizhe_excerpt_loads_with_the_same_config():
    with gzip.open(EXCERPT, "rt") as fh:
        header = fh.readline().strip().split(",")
    assert header == ["split", "label", "sample", "time", "pwm1", "pwm2", "pwm3", "pwm4", "depth",
                      "press", "voltage", "roll", "pitch", "yaw", "a_x", "a_y", "a_z", "w_row",
                      "w_pitch", "w_yaw"]  # fmt: skip
    assert EXCERPT.stat().st_size < 100_000
    log, report = load_log(EXCERPT, READERS / "haizhe_auv_fault.toml")
    validate_log(log, source=str(EXCERPT))
    assert report.rows_removed == 0
    assert len(log) == 1279 and log["experiment"].nunique() == 6
    labels = log.groupby("experiment").size().index.str.split("/").str[1].str.rsplit("_", n=1)
    expected = (
        ["AddWeight"] * 2 + ["Normal"] * 2 + ["PropellerDamage_bad", "PropellerDamage_slight"]
    )
    assert sorted(x[0] for x in labels) == expected
    _uniform(log, 0.05)
    assert _durations(log).between(9.6, 14.8).all()
    assert set(log.columns) == {"t", "experiment", "z", "phi", "theta", "psi", "p", "q", "r",
                                "acc_x", "acc_y", "acc_z", "voltage",
                                "cmd_1", "cmd_2", "cmd_3", "cmd_4"}  # fmt: skip
    assert log["cmd_1"].between(0.0, 0.25).all() and (log["cmd_1"] == log["cmd_4"]).all()
    assert log[["phi", "theta", "psi"]].abs().max().max() <= np.pi
    # attitude-derived rates vs the gyro (card: RMS 0.056 / 0.158 / 0.066 rad/s)
    d = derive_velocities(log.drop(columns=["p", "q", "r"]))
    rms = {c: _rms(log[c] - d[c]) for c in "pqr"}
    assert rms["p"] < 0.07 and rms["q"] < 0.2 and rms["r"] < 0.08
    assert np.corrcoef(log["r"], d["r"])[0, 1] > 0.9


def test_haizhe_gyro_without_its_unit_is_refused_as_deg_per_s(tmp_path):
    """The Haizhe gyro logs deg/s (the config says unit = "deg/s"); mapped without the unit
    it stayed under 100 "rad/s" on the excerpt and passed. Against the attitude's kinematic
    rate it reads about 47 times too fast (57.3 times the excerpt's p slope of ~0.8); with the
    unit every slope is 1.1 or under (the q axis, which barely pitches, -0.06 to 0.7)."""
    from nnid.datasets.log import RATE_CHECK_SECONDS, rate_slopes

    config = (READERS / "haizhe_auv_fault.toml").read_text()
    stripped = re.sub(r'(\b[pqr] = \{ from = "w_\w+"), unit = "deg/s" \}', r"\1 }", config)
    assert stripped.count('unit = "deg/s"') == 0 and config.count('unit = "deg/s"') == 3
    (tmp_path / "haizhe.toml").write_text(stripped)
    with pytest.raises(
        NnidInputError, match=r"field 'p'.*looks like deg/s.*unit = \"deg/s\""
    ) as err:
        load_log(EXCERPT, tmp_path / "haizhe.toml")
    assert str(EXCERPT) in str(err.value)
    log, _ = load_log(EXCERPT, READERS / "haizhe_auv_fault.toml")
    counted = [s for *_, s, seconds in rate_slopes(log) if seconds >= RATE_CHECK_SECONDS]
    assert len(counted) == 12 and max(counted) < 1.1


@needs_shared
def test_haizhe_full_set():
    root = _shared("haizhe-auv-fault-2021")
    log, _ = load_log(root, READERS / "haizhe_auv_fault.toml")
    validate_log(log, source=str(root))
    assert log["experiment"].nunique() == 1225 and len(log) == 240_823
    labels = pd.Series(log["experiment"].unique()).str.split("/").str[1].str.rsplit("_", n=1)
    counts = labels.str[0].value_counts().to_dict()
    assert counts == {
        "AddWeight": 268,
        "PressureGain_constant": 266,
        "PropellerDamage_slight": 260,
        "PropellerDamage_bad": 249,
        "Normal": 182,
    }
    _uniform(log, 0.05)
    assert _durations(log).between(6.7, 14.8).all()
    # the card's RMS on every 5th run (keeps the test fast): p 0.077, q 0.126, r 0.111 on all runs
    sub = log[log["experiment"].isin(log["experiment"].unique()[::5])]
    d = derive_velocities(sub.drop(columns=["p", "q", "r"]))
    spikes = (sub[["p", "q", "r"]].abs() > np.radians(300)).any(axis=1)
    rms = {c: _rms((sub[c] - d[c])[~spikes]) for c in "pqr"}
    assert rms["p"] < 0.07 and rms["q"] < 0.15 and rms["r"] < 0.1
    cross = np.corrcoef(sub[["p", "q", "r"]].T.to_numpy(), d[["p", "q", "r"]].T.to_numpy())[:3, 3:]
    assert (np.diag(cross) > 0.35).all() and (np.abs(cross - np.diag(np.diag(cross))) < 0.15).all()


# --- Liu BlueROV 1 -----------------------------------------------------------------------------

LIU_COLUMNS = {"t", "experiment", "cmd_1", "cmd_2", "cmd_3", "cmd_4", "cmd_5", "cmd_6",
               "p", "q", "r", "acc_x", "acc_y", "acc_z", "z", "phi", "theta", "psi"}  # fmt: skip
T_THESIS = np.array([[0, 0, 1, 1, 0, 0], [0, 0, 0, 0, 0, -1], [-1, -1, 0, 0, -1, 0],
                     [0.11, -0.11, 0, 0, 0, 0.11], [0.16, 0.16, 0, 0, -0.20, 0],
                     [0, 0, 0.11, -0.11, 0, 0]])  # fmt: skip


@pytest.fixture(scope="module")
def liu_open() -> pd.DataFrame:
    if not SHARED.is_dir():
        pytest.skip(f"measured data folder {SHARED} is absent (../shared/data)")
    root = _shared("liu-bluerov1-2016")
    log, _ = load_log(root, READERS / "liu_bluerov1_openloop.toml")
    return log


@pytest.mark.shared
def test_liu_open_loop_runs(liu_open):
    log = liu_open
    validate_log(log)
    names = log["experiment"].unique()
    assert len(names) == 20 and all(re.match(r"^(all|pitch_roll|yaw|resample)_", n) for n in names)
    assert not any("#" in n for n in names)  # no run split at gaps
    _uniform(log, 0.02)
    # runs end 0.5 s after their last thruster command (hold_timeout): the stream stops up to
    # 3.9 s before the bag ends while the vehicle coasts, and a stale command is not held
    assert _durations(log).between(7.0, 79.5).all()
    assert _durations(log).sum() == pytest.approx(954, abs=2)
    assert set(log.columns) == LIU_COLUMNS | {"replay_group"}
    # the eight replays of one run (card) form the reader config's one replay group
    group = log.groupby("experiment")["replay_group"].first()
    replays = group[group.notna()].index
    assert (group.dropna() == "replays[0]").all() and len(replays) == 8
    assert all(n.startswith(("all_1_", "resample_")) for n in replays)
    cmds = log[[f"cmd_{k}" for k in range(1, 7)]]
    assert cmds.min().min() >= -1.0 and cmds.max().max() <= 1.0
    assert log["acc_z"][log["experiment"].str.startswith("yaw_")].mean() == pytest.approx(
        -9.4, abs=0.3
    )


@pytest.mark.shared
def test_liu_gyro_agrees_with_ekf_attitude_on_independent_runs(liu_open):
    """Card: on the 12 independent 2016-04-18 runs with |θ| < 1.2 rad, window 0.3 s, RMS
    p 0.194, q 0.251, r 0.153 rad/s; the replayed 04-19/20 runs (diverged EKF) exceed 3 rad/s."""
    log = liu_open
    d = derive_velocities(log.drop(columns=["p", "q", "r"]), window_s=0.3)
    replay = log["experiment"].str.contains("2016-04-19|2016-04-20")
    assert log.loc[replay, "experiment"].nunique() == 8
    good = ~replay & (log["theta"].abs() < 1.2)
    rms = {c: _rms((log[c] - d[c])[good]) for c in "pqr"}
    assert rms["p"] < 0.25 and rms["q"] < 0.3 and rms["r"] < 0.2
    assert min(_rms((log[c] - d[c])[replay]) for c in "pqr") > 3.0


@pytest.mark.shared
def test_liu_imu_axes_match_the_thesis_thruster_geometry(liu_open):
    """Gyro angular acceleration correlates positively with the yaw moment T f(u) of the vehicle
    file in every yaw_* run: the board z axis is the thesis body z (down), no sign flip."""
    act = Actuation(load_vehicle(REPO / "configs" / "vehicles" / "bluerov1_liu.toml"))
    for name, run in liu_open.groupby("experiment"):
        if not name.startswith("yaw_"):
            continue
        tau = act.nominal(run[[f"cmd_{k}" for k in range(1, 7)]].to_numpy())
        rdot = savgol_derivative(run["r"].to_numpy(), 0.02, 15, 2)
        assert np.corrcoef(rdot, tau[:, 5])[0, 1] > 0.4, name


@needs_shared
def test_liu_closed_loop_runs():
    root = _shared("liu-bluerov1-2016")
    log, _ = load_log(root, READERS / "liu_bluerov1_closedloop.toml")
    validate_log(log)
    names = log["experiment"].unique()
    assert len(names) == 81 and "ratetest2_2016-05-20-08-28-25" in names
    assert not any(re.match(r"^(all|pitch_roll|yaw|resample)_|ratetest_2016", n) for n in names)
    _uniform(log, 0.02)
    assert _durations(log).between(5.5, 61.0).all()
    assert set(log.columns) == LIU_COLUMNS
    # card: the EKF attitude does not follow the gyro in closed loop (RMS 0.35 / 0.38 / 0.70)
    d = derive_velocities(log.drop(columns=["p", "q", "r"]))
    rms = {c: _rms(log[c] - d[c]) for c in "pqr"}
    assert 0.25 < rms["p"] < 0.45 and 0.25 < rms["q"] < 0.45 and 0.6 < rms["r"] < 0.8


def test_bluerov1_vehicle_file():
    vehicle = load_vehicle(REPO / "configs" / "vehicles" / "bluerov1_liu.toml")
    act = Actuation(vehicle)
    assert act.channels == ("1", "2", "3", "4", "5", "6")
    assert np.allclose(act.matrix, T_THESIS, atol=1e-12)
    assert vehicle.mass == 6.621 and vehicle.r_b == [0.0, 0.0, -0.05]
    assert vehicle.buoyancy == pytest.approx(vehicle.weight)
    for thruster in vehicle.thrusters:
        assert thruster.curve.kind == "table" and len(thruster.curve.cmd) == 81
        assert thruster.curve.thrust[0] == -40.0788 and thruster.curve.thrust[-1] == 49.9531
    # lumped identified inertias of the thesis (A_p, B_q, C_r) are kept exactly
    inertia = np.asarray(vehicle.inertia)
    added = np.array([vehicle.added_mass[k] for k in ("K_pdot", "M_qdot", "N_rdot")])
    assert np.allclose(inertia - added, [0.9625, 0.7108, 1.2649], atol=1e-4)
    if (SHARED / "liu-bluerov1-2016" / "thrust_map_measured.csv").exists():
        table = pd.read_csv(SHARED / "liu-bluerov1-2016" / "thrust_map_measured.csv")
        assert np.allclose(vehicle.thrusters[0].curve.cmd, table["u_normalized"])
        assert np.allclose(vehicle.thrusters[0].curve.thrust, table["thrust_N"])


# --- Tartan AUV ---------------------------------------------------------------------------------


@needs_shared
def test_tartan_session_velocity_frame_and_latency():
    root = _shared("tartan-auv-2022") / "raw"
    log, _ = load_log(root, READERS / "tartan_auv.toml")
    validate_log(log)
    assert log["experiment"].unique().tolist() == ["0"]
    _uniform(log, 0.05)
    assert log["t"].iloc[-1] == pytest.approx(957.4, abs=0.5)
    assert set(log.columns) == {"t", "experiment", "x", "y", "z", "phi", "theta", "psi",
                                "u", "v", "w", "tau_X", "tau_Y", "tau_Z", "tau_K", "tau_M",
                                "tau_N"}  # fmt: skip
    # velocity frame: body (card, 0.5 s window: body RMS 0.024 / 0.035, world 0.041 / 0.045)
    d = derive_velocities(log, overwrite=True)
    world = {c: savgol_derivative(log[c].to_numpy(), 0.05, 11, 4) for c in "xy"}
    body = {"u": _rms(log["u"] - d["u"]), "v": _rms(log["v"] - d["v"])}
    assert body["u"] < 0.03 and body["v"] < 0.04
    assert _rms(log["u"] - world["x"]) > 1.5 * body["u"]
    assert _rms(log["v"] - world["y"]) > 1.2 * body["v"]
    # the measured velocity lags the position derivative by 0.18-0.20 s
    _, lag_u = _xcorr_peak(d["u"].to_numpy(), log["u"].to_numpy(), 0.05)
    assert 0.1 < lag_u < 0.3
    # command -> acceleration: +0.18 s through the (lagging) velocity, about 0 through attitude
    acc = derive_accelerations(derive_velocities(log))
    corr_z, lag_z = _xcorr_peak(acc["tau_Z"].to_numpy(), acc["dw"].to_numpy(), 0.05)
    corr_n, lag_n = _xcorr_peak(acc["tau_N"].to_numpy(), acc["dr"].to_numpy(), 0.05)
    assert corr_z > 0.35 and 0.1 < lag_z < 0.3
    assert corr_n > 0.5 and -0.15 < lag_n < 0.05


# --- NTNU BlueROV2 Heavy ------------------------------------------------------------------------


@needs_shared
def test_ntnu_runs_duplicates_and_heave_sign():
    root = _shared("ntnu-bluerov2heavy-2024")
    log, _ = load_log(root, READERS / "ntnu_bluerov2heavy.toml")
    validate_log(log)
    names = pd.Series(log["experiment"].unique())
    assert len(names) == 57 and names.str.contains(r"/ff_n?b\d").sum() == 31
    _uniform(log, 0.1)
    assert _durations(log).between(86.0, 178.5).all()
    cmds = ["cmd_pitch", "cmd_roll", "cmd_heave", "cmd_yaw", "cmd_surge", "cmd_sway"]
    assert set(log.columns) == {"t", "experiment", "phi", "theta", "psi", "z", *cmds}
    free = log["experiment"].str.contains(r"/ff_n?b\d")
    assert (log.loc[free, cmds] == 0).all().all()
    assert (log[["cmd_pitch", "cmd_roll"]] == 0).all().all()
    a = log[log["experiment"] == "stock_config"].drop(columns="experiment").reset_index(drop=True)
    b = log[log["experiment"] == "Day1/Exp1/exp1_1"].drop(columns="experiment")
    pd.testing.assert_frame_equal(a, b.reset_index(drop=True))
    # positive cmd_heave drives the vehicle down (card: corr +0.82 about 1.1 s later)
    run = derive_velocities(log[log["experiment"] == "Day1/Exp1/exp1_1"], window_s=1.0)
    corr, lag = _xcorr_peak(run["cmd_heave"].to_numpy(), run["w"].to_numpy(), 0.1, maxlag=30)
    assert corr > 0.6 and 0.5 < lag < 2.0


# --- nlbench -----------------------------------------------------------------------------------


@needs_shared
@pytest.mark.parametrize(
    "name, sizes, inputs, outputs, dt, warmup",
    [
        ("silverbox", {"train": 65062, "test_multisine": 21688, "test_arrow_full": 40475,
                       "test_arrow_no_extrapolation": 32000}, ["V1"], ["V2"], 1 / 610.35, 50),
        ("cascaded_tanks", {"train": 1024, "test": 1024}, ["u"], ["y"], 4.0, 50),
        ("emps", {"train": 24841, "test": 24841}, ["vir"], ["qm"], 1e-3, 20),
        ("boucwen", {"train": 40960, "test_multisine": 8192, "test_sinesweep": 153000},
         ["u"], ["y"], 1 / 750, 0),
        ("f16", {"train": 2 * 73728, "test": 2 * 73728}, ["Force"],
         ["Acceleration1", "Acceleration2", "Acceleration3"], 1 / 400, 50),
    ],
)  # fmt: skip
def test_nlbench_splits(name, sizes, inputs, outputs, dt, warmup):
    if name == "boucwen":
        pytest.importorskip("h5py", reason="the Bouc-Wen training file needs h5py")
    bench = load_benchmark(name, SHARED)
    assert {k: len(v) for k, v in bench.splits.items()} == sizes
    assert (bench.inputs, bench.outputs, bench.warmup) == (inputs, outputs, warmup)
    assert bench.dt == pytest.approx(dt, rel=1e-6)
    assert bench.published == {}
    for table in bench.splits.values():
        assert list(table.columns) == ["t", "experiment", *inputs, *outputs]
        assert np.isfinite(table[inputs + outputs].to_numpy()).all()
        assert (table.groupby("experiment")["t"].first() == 0).all()


@needs_shared
def test_nlbench_known_values():
    silver = load_benchmark("silverbox", SHARED / "nlbench-silverbox")
    raw = pd.read_csv(SHARED / "nlbench-silverbox" / "SNLS80mV.csv")
    assert silver.splits["test_arrow_full"]["V2"].iloc[0] == raw["V2"].iloc[100]
    assert silver.splits["train"]["V1"].iloc[0] == raw["V1"].iloc[40650]
    f16 = load_benchmark("f16", SHARED)
    assert sorted(f16.splits["test"]["experiment"].unique()) == [
        "F16Data_FullMSine_Level2_Validation", "F16Data_FullMSine_Level4_Validation"]  # fmt: skip


def test_nlbench_errors_name_the_file(tmp_path, monkeypatch):
    with pytest.raises(NnidInputError, match="unknown benchmark"):
        load_benchmark("wiener_hammerstein", tmp_path)
    with pytest.raises(NnidInputError, match=r"SNLS80mV\.csv"):
        load_benchmark("silverbox", tmp_path)
    (tmp_path / "train_forgione_generated.h5").write_bytes(b"not hdf5")
    monkeypatch.setitem(__import__("sys").modules, "h5py", None)  # h5py not installed
    with pytest.raises(NnidInputError, match=r"train_forgione_generated\.h5.*h5py"):
        load_benchmark("boucwen", tmp_path)


def test_reader_configs_validate():
    for path in sorted(READERS.glob("*.toml")):
        cmap = load_column_map(path)
        assert cmap.rate and cmap.root and cmap.root.startswith("../../../shared/data/"), path


@needs_shared
def test_haizhe_subset_through_read_mapped():
    """The include regex selects runs on split/label: the test split has 245 runs."""
    cmap = load_column_map(READERS / "haizhe_auv_fault.toml").model_copy(
        update={"include": "^test/"}
    )
    log, _ = read_mapped(cmap, _shared("haizhe-auv-fault-2021"))
    assert log["experiment"].nunique() == 245
