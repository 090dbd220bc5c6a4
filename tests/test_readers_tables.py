"""Tables through a column map, `nnid inspect`, and bad input: one error naming file, column
and row, exit code 2; property-based tests of the CSV reader."""

from __future__ import annotations

import math
import re
from decimal import Decimal

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from nnid.cli import app
from nnid.datasets.log import validate_log
from nnid.datasets.mapping import (
    euler_from_rotation,
    rotation_from_euler,
    rotation_from_quaternion,
)
from nnid.datasets.readers import load_log
from nnid.errors import NnidInputError
from nnid.serialization import SCHEMA_VERSION, read_json

runner = CliRunner()


def _write_map(path, body):
    path.write_text(body)
    return path


def _sensor_tables(root):
    t = np.arange(0, 10, 0.013) + 1.6e9
    nav = pd.DataFrame({"run": "r1", "time": t, "yaw_deg": np.degrees(0.1 * (t - t[0])),
                        "depth": 0.5 + 0.01 * (t - t[0])})  # fmt: skip
    nav.to_csv(root / "nav.csv", index=False)
    tc = t[0] + np.array([0.0, 2.5, 5.1, 7.0])
    pd.DataFrame({"run": "r1", "time": tc, "pwm": [1500, 1700, 1300, 1500]}).to_csv(
        root / "cmd.csv", index=False
    )


MAP = """
rate = 20.0
gap = 0.5
experiment = "run"
[[sources]]
file = "nav.csv"
time = "time"
columns = { psi = { from = "yaw_deg", unit = "deg" }, z = "depth" }
[[sources]]
file = "cmd.csv"
time = "time"
method = "hold"
columns = { cmd_1 = { from = "pwm", offset = -1500, scale = 0.0025 } }
"""


def test_multi_rate_sources_onto_one_time_base(tmp_path):
    _sensor_tables(tmp_path)
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    assert np.allclose(np.diff(log["t"]), 0.05) and log["t"].iloc[0] == 0
    assert np.allclose(log["psi"], 0.1 * log["t"], atol=1e-9)  # degrees became radians
    assert np.allclose(log["z"], 0.5 + 0.01 * log["t"])

    def held(t):
        return log["cmd_1"].to_numpy()[np.argmin(np.abs(log["t"].to_numpy() - t))]

    assert held(2.45) == 0.0 and held(2.5) == 0.5 and held(5.15) == -0.5  # zero-order hold
    assert log["t"].iloc[-1] == pytest.approx(9.99, abs=0.05)  # the last command holds on
    assert any(s.step == "resample" for s in report.steps)


ON_GRID_MAP = """
rate = 10.0
experiment = "run"
[[sources]]
file = "nav.csv"
time = "time"
columns = { z = "depth" }
[[sources]]
file = "cmd.csv"
time = "time"
method = "hold"
columns = { cmd_1 = "pwm" }
"""


@pytest.mark.parametrize("start", ["0.3", "1700000000.123"])
def test_a_grid_time_that_is_a_logged_time_to_rounding_takes_that_sample(tmp_path, start):
    """Times logged every 0.1 s from a start that is not round: k/10 on the grid and the logged
    time less the start differ in the last bits (by ~1e-7 s on a UNIX epoch), and a command
    logged at 0.1 s or 0.6 s was held from the next sample (the one before held on); a
    measured value on a logged sample was interpolated, not that sample."""
    times = [str(Decimal(start) + Decimal(k) / 10) for k in range(10)]  # as a logger writes
    depth = np.sqrt(np.arange(10.0))  # not a straight line: interpolating it shows
    pd.DataFrame({"run": "r1", "time": times, "depth": depth}).to_csv(
        tmp_path / "nav.csv", index=False
    )
    changes = {0: 0.0, 1: 0.5, 6: -0.5}  # sample -> command, logged on change
    cmd = {"run": "r1", "time": [times[k] for k in changes], "pwm": list(changes.values())}
    pd.DataFrame(cmd).to_csv(tmp_path / "cmd.csv", index=False)
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", ON_GRID_MAP))
    assert np.allclose(log["t"], np.arange(10) / 10, rtol=0, atol=1e-12)
    held = [changes[max(c for c in changes if c <= k)] for k in range(10)]
    assert log["cmd_1"].tolist() == held
    assert log["z"].tolist() == depth.tolist()


@pytest.mark.parametrize(
    ("start", "unit"),
    [("1712345678.9", "s"), ("1700000000.123", "ms"), ("1700000000.1", "ns")],
)
def test_a_runs_last_logged_sample_on_the_grid_is_kept(tmp_path, start, unit):
    """300 samples logged every 0.1 s on an epoch clock (seconds, or integer ms or ns with a
    time_scale): stop - start carries the epoch's rounding (~1e-7 s), more than the grid's
    1e-9 samples of slack, and the run lost its last sample (299 rows). Logged 1 us before
    the grid time instead (1 ms on a ms clock; a float64 epoch resolves ~2.4e-7 s), that sample
    is not on the grid and no grid time past it is made."""
    ticks = {"s": None, "ms": 10**3, "ns": 10**9}[unit]
    scale = "" if ticks is None else f"time_scale = {1 / ticks:g}\n"
    depth = np.sqrt(np.arange(300.0))  # not a straight line: a value interpolated shows
    tick = Decimal("0.001") if unit == "ms" else Decimal("0.000001")
    for early in (0, 1):  # the last stamp on the grid time, or a tick before it
        times = [Decimal(start) + Decimal(k) / 10 for k in range(300)]
        times[-1] -= early * tick
        stamps = [str(x) if ticks is None else int(x * ticks) for x in times]
        nav = {"run": "r1", "time": stamps, "depth": depth, "pwm": depth}
        pd.DataFrame(nav).to_csv(tmp_path / "nav.csv", index=False)
        body = ON_GRID_MAP.split("[[sources]]")[:2]
        body[1] = body[1].replace('time = "time"\n', 'time = "time"\n' + scale)
        body[1] = body[1].replace('z = "depth"', 'z = "depth", cmd_1 = "pwm"')
        log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", "[[sources]]".join(body)))
        kept = 300 - early
        assert len(log) == kept and log["t"].iloc[-1] == pytest.approx((kept - 1) / 10)
        assert log["z"].tolist() == depth[:kept].tolist()


def test_a_clock_stamped_in_whole_ms_is_gridded_at_its_rate_when_no_rate_is_given(tmp_path):
    """No rate: the grid's period is the source's step. 120 Hz stamped in whole milliseconds
    steps 8, 8, 9 ms, whose median made a 125-Hz grid (25 more rows in 600 samples, values
    interpolated between the logged ones); its step is the mean of its one-sample steps, as
    the rest of nnid reads it (nnid.datasets.log.clock_step)."""
    n = 600
    stamps = np.round(np.arange(n) / 120, 3)
    assert set(np.round(np.diff(stamps) * 1000)) == {8.0, 9.0}
    depth = np.sqrt(np.arange(n, dtype=np.float64))
    nav = {"run": "r1", "time": stamps, "depth": depth, "pwm": depth}
    pd.DataFrame(nav).to_csv(tmp_path / "nav.csv", index=False)
    body = ON_GRID_MAP.split("[[sources]]")[:2]
    body[0] = body[0].replace("rate = 10.0\n", "")
    body[1] = body[1].replace('z = "depth"', 'z = "depth", cmd_1 = "pwm"')
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", "[[sources]]".join(body)))
    assert len(log) == n
    assert np.diff(log["t"]) == pytest.approx(np.full(n - 1, 1 / 120), rel=1e-3)


#: two runs of nanoseconds since the epoch, 100 Hz: the first's last stamp is 2.04 units of its
#: seconds' last place past its grid time once divided by 1e9 (time_unit), the second's that
#: much short once multiplied by 1e-9 (time_scale)
NS_EPOCH_RUNS = [('time_unit = "ns"', 1700570955193767552, 75),
                 ("time_scale = 1e-9", 1700357253267554176, 27)]  # fmt: skip


@pytest.mark.parametrize(("clock", "first", "n"), NS_EPOCH_RUNS)
def test_a_nanosecond_epoch_clock_keeps_its_samples_on_the_grid(tmp_path, clock, first, n):
    """Nanoseconds since the epoch (~1.7e18, ROS stamps) are held to 256 ns as float64
    before they become seconds: two stamps 10 ms apart could differ from 10 ms by 2.04 units
    of the seconds' last place, over the two the grid allowed, and the last sample was lost
    (the span short of its grid time) or taken off the grid (interpolated, a held command
    taken from the sample before). The snap allows the rounding of the unit read."""
    ns = first + np.arange(n, dtype=np.int64) * 10_000_000
    seconds = ns.astype(np.float64) / 1e9 if "unit" in clock else ns.astype(np.float64) * 1e-9
    off = (seconds[-1] - seconds[0]) - (n - 1) / 100.0
    assert abs(off) > 2 * np.spacing(seconds[-1])  # over the two units the grid allowed
    depth = np.sqrt(np.arange(n, dtype=np.float64))  # not a straight line: interpolating shows
    pd.DataFrame({"run": "r1", "time": ns, "depth": depth}).to_csv(
        tmp_path / "nav.csv", index=False
    )
    body = ON_GRID_MAP.replace("rate = 10.0", "rate = 100.0").replace("cmd.csv", "nav.csv")
    body = body.replace('time = "time"\n', f'time = "time"\n{clock}\n')
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", body.replace("pwm", "depth")))
    assert len(log) == n
    assert log["z"].tolist() == depth.tolist() and log["cmd_1"].tolist() == depth.tolist()


@pytest.mark.parametrize(("start", "last"), [("0.3", 99), ("1712345678.987", 53)])
def test_a_run_cut_at_its_hold_timeout_ends_on_a_sample_not_stale(tmp_path, start, last):
    """Commands logged every 0.1 s until sample ``last``, hold_timeout 2 s: the run is cut 2 s
    after the last command, on a grid time. That sample was said to be "silent for up to
    2 s" (aged the timeout plus the clock's rounding), and on an epoch clock it was dropped."""
    times = [str(Decimal(start) + Decimal(k) / 10) for k in range(300)]
    pd.DataFrame({"run": "r1", "time": times, "depth": np.arange(300.0)}).to_csv(
        tmp_path / "nav.csv", index=False
    )
    cmd = {"run": "r1", "time": times[: last + 1], "pwm": np.arange(last + 1.0)}
    pd.DataFrame(cmd).to_csv(tmp_path / "cmd.csv", index=False)
    timed = ON_GRID_MAP.replace('method = "hold"', 'method = "hold"\nhold_timeout = 2.0')
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", timed))
    assert len(log) == last + 21 and log["cmd_1"].iloc[-1] == last  # 20 samples held
    assert [s.step for s in report.steps if "stale hold" in s.step] == ["cut stale hold"]


def test_gap_splits_instead_of_bridging(tmp_path):
    _sensor_tables(tmp_path)
    nav = pd.read_csv(tmp_path / "nav.csv")
    nav = nav[(nav["time"] - nav["time"].iloc[0] < 3) | (nav["time"] - nav["time"].iloc[0] > 4)]
    nav.to_csv(tmp_path / "nav.csv", index=False)
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    assert list(dict.fromkeys(log["experiment"])) == ["r1#0", "r1#1"]
    assert any(s.step == "split at gaps" and s.rows_removed > 0 for s in report.steps)


def test_a_lone_sample_after_a_gap_is_said_as_rows_removed(tmp_path):
    """A measured source's last sample 3 s after the rest (gap = 0.5 s): the run kept one piece,
    and the 3 s of grid and the lone sample were lost without a report line (said only when
    a run became two pieces). Every grid sample left out is now said."""
    _sensor_tables(tmp_path)
    t = 1.6e9 + np.r_[np.arange(0.0, 6.0, 0.05), 9.0]
    nav = pd.DataFrame({"run": "r1", "time": t, "yaw_deg": 0.0, "depth": 0.5})
    nav.to_csv(tmp_path / "nav.csv", index=False)
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    assert set(log["experiment"]) == {"r1"} and log["t"].iloc[-1] < 6.0
    grid = round(9.0 * 20) + 1  # 0 … 9 s at rate = 20 Hz
    split = [s for s in report.steps if s.step == "split at gaps"]
    assert [s.rows_removed for s in split] == [grid - len(log)]
    assert "1 lone sample" in split[0].detail


def test_rows_outside_the_span_all_sources_share_are_said(tmp_path):
    """Every source is trimmed to the times all share: an IMU logging before the first command
    lost those rows without a report line. Said per source; a command in force at the start
    (held into the run) is not among them."""
    t = np.arange(0.0, 10.0, 0.1)
    pd.DataFrame({"time": t, "u": t}).to_csv(tmp_path / "imu.csv", index=False)
    cmd = {"cmd.csv": [2.0, 2.5, 6.0, 12.0], "aux.csv": [0.5, 1.0, 3.0]}
    for name, tc in cmd.items():
        pd.DataFrame({"time": tc, "f": np.arange(len(tc))}).to_csv(tmp_path / name, index=False)
    body = 'rate = 10.0\n[[sources]]\nfile = "imu.csv"\ntime = "time"\ncolumns = { u = "u" }\n'
    for name, col in (("cmd.csv", "tau_X"), ("aux.csv", "tau_Y")):
        body += f'[[sources]]\nfile = "{name}"\ntime = "time"\nmethod = "hold"\n'
        body += f'columns = {{ {col} = "f" }}\n'
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", body))
    early = int((t < 2.0).sum())
    assert log["tau_Y"].iloc[0] == 1.0  # aux's row at 1.0 s is held into the run
    trim = [s for s in report.steps if s.step == "trim to common span"]
    assert len(trim) == 1 and f"imu.csv {early} rows before it and 0 after" in trim[0].detail
    # cmd's row at 12 s (after the IMU's last), aux's at 0.5 s (before the one in force)
    assert "cmd.csv 0 rows before it and 1 after, aux.csv 1 rows before it" in trim[0].detail


def test_a_pieces_clock_shows_the_hole_it_was_cut_at(tmp_path):
    """Each piece a reader cut a run into at a gap started again at t = 0, so the second of
    r1's pieces looked like a new run and ``nnid inspect`` counted no time in gaps: the hole
    (about 1 s of nav silence) was only in the cleaning report. Pieces keep the run's clock."""
    from nnid.datasets.inspect import summarize

    _sensor_tables(tmp_path)
    nav = pd.read_csv(tmp_path / "nav.csv")
    nav = nav[(nav["time"] - nav["time"].iloc[0] < 3) | (nav["time"] - nav["time"].iloc[0] > 4)]
    nav.to_csv(tmp_path / "nav.csv", index=False)
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    first, second = (log[log["experiment"] == e]["t"] for e in ("r1#0", "r1#1"))
    assert first.iloc[0] == 0.0 and first.iloc[-1] < 3.0 < 4.0 < second.iloc[0]
    assert np.allclose(log["psi"], 0.1 * log["t"], atol=1e-9)  # t is the run's own time
    info = summarize(log)
    hole = second.iloc[0] - first.iloc[-1]
    assert info["gap_s"] == pytest.approx(hole - 0.05)  # less one sample interval, as gaps
    assert info["duration_s"] == pytest.approx(np.ptp(first) + np.ptp(second))
    assert info["runs"] == 1


def test_inspect_rate_is_one_the_log_has(tmp_path):
    """A run at 10 Hz and one at 100 Hz: inspect said "about 55 Hz", the median of the two
    rates, a rate no sample has; now the rate of most intervals, and the spread."""
    slow = pd.DataFrame({"t": 0.1 * np.arange(50), "experiment": "slow"})
    fast = pd.DataFrame({"t": 0.01 * np.arange(500), "experiment": "fast"})
    log = pd.concat([slow, fast]).assign(u=0.1, tau_X=1.0)
    path = tmp_path / "rates.csv"
    log.to_csv(path, index=False)
    result = runner.invoke(app, ["inspect", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    assert "about 100 Hz (experiments from 10 to 100 Hz)" in result.output
    info = read_json(tmp_path / "o" / "summary.json")
    assert info["rate_hz"] == pytest.approx(100.0)
    assert [e["rate_hz"] for e in info["experiments"]] == pytest.approx([10.0, 100.0])


def test_inspect_says_the_rate_of_a_clock_rounded_to_the_millisecond():
    """Two runs at 120 Hz stamped in whole ms (8, 8, 9 ms) with a dropped sample: inspect said
    125 Hz (1 / the 8-ms median) where lowpass and resample design at 120 Hz; each run's rate
    and the log's are its logged rate, and the dropped sample is the only gap."""
    from nnid.datasets.inspect import summarize

    true = np.arange(360) / 120.0
    runs = []
    for name in ("a", "b"):
        t = np.round(np.delete(true, 100) * 1e3) / 1e3
        runs.append(pd.DataFrame({"t": t, "experiment": name, "u": 0.1, "tau_X": 1.0}))
    info = summarize(pd.concat(runs, ignore_index=True))
    assert [e["rate_hz"] for e in info["experiments"]] == pytest.approx([120.0, 120.0], rel=1e-4)
    assert info["rate_hz"] == pytest.approx(120.0, rel=1e-4)
    assert [g["length_s"] for g in info["gaps"]] == pytest.approx([0.017, 0.017])


def test_inspect_says_a_run_whose_stamps_come_in_bursts_is_so_not_a_100_khz_run_of_gaps(
    tmp_path,
):
    """An IMU's run, ten samples 10 µs apart every 10 ms, beside a 100-Hz run with a 1-s hole:
    inspect said the IMU's run was at 1e+05 Hz (its median step, one inside a burst) with each
    burst's end a gap (29 of them). It says the run's clock comes in bursts, with the burst
    sentence the fits refuse it by and its rate over the run, and counts no gap in it; the
    hole in the even run is still a gap."""
    k = np.arange(300)
    imu = pd.DataFrame({"t": 0.01 * (k // 10) + 1e-5 * (k % 10), "experiment": "imu"})
    even_t = 0.01 * np.arange(400)
    even_t[200:] += 1.0
    even = pd.DataFrame({"t": even_t, "experiment": "even"})
    log = pd.concat([imu, even]).assign(u=0.1, tau_X=1.0)
    path = tmp_path / "imu.csv"
    log.to_csv(path, index=False)
    result = runner.invoke(app, ["inspect", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert "experiment 'imu': its stamps come in bursts: 1e-05 s apart (median)" in said, said
    assert "gaps 1 (longest 1.01 s) (not counted in the 1 run in bursts)" in said, said
    info = read_json(tmp_path / "o" / "summary.json")
    runs = {e["name"]: e for e in info["experiments"]}
    over_run = (imu["t"].size - 1) / np.ptp(imu["t"])  # the mean step: no pause in the run
    assert runs["imu"]["rate_hz"] == pytest.approx(over_run)
    assert f"{over_run:.0f} Hz over the run" in runs["imu"]["bursts"]
    assert runs["imu"]["gap_s"] is None and runs["even"]["bursts"] is None
    assert runs["even"]["rate_hz"] == pytest.approx(100.0)
    assert [g["experiment"] for g in info["gaps"]] == ["even"]


def test_inspect_counts_a_run_cut_at_a_gap_as_one_experiment(tmp_path):
    """One run cut into two pieces at a 1-s hole: inspect said "2 experiments" (it counted the
    pieces by their labels, r1#0 and r1#1) and "gaps 0" (each piece is gap-free)."""
    _sensor_tables(tmp_path)
    nav = pd.read_csv(tmp_path / "nav.csv")
    nav = nav[(nav["time"] - nav["time"].iloc[0] < 3) | (nav["time"] - nav["time"].iloc[0] > 4)]
    nav.to_csv(tmp_path / "nav.csv", index=False)
    cmap = _write_map(tmp_path / "map.toml", MAP)
    result = runner.invoke(app, ["inspect", str(tmp_path), "--columns", str(cmap), "--out",
                                 str(tmp_path / "o")])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "1 experiment (2 pieces: runs cut at gaps)" in result.output
    info = read_json(tmp_path / "o" / "summary.json")
    assert info["runs"] == 1 and [e["piece_of"] for e in info["experiments"]] == ["r1", "r1"]


def _pose_only_log(n: int = 600, rate: float = 20.0) -> pd.DataFrame:
    """Depth and attitude only, with RC commands: heave and yaw move, roll only trembles."""
    t = np.arange(n) / rate
    return pd.DataFrame({
        "t": t, "z": 0.3 * np.sin(0.5 * t), "phi": 1e-4 * np.sin(2.0 * t),
        "theta": 0.05 * np.sin(0.7 * t), "psi": 0.8 * np.sin(0.3 * t),
        "cmd_heave": np.where(np.sin(0.5 * t) > 0, 0.4, 0.0), "cmd_yaw": 0.2 * np.sin(t),
    })  # fmt: skip


def test_inspect_excites_a_pose_only_log_by_the_fits_derivative(tmp_path):
    """A log of depth and attitude (an ArduSub dive): inspect printed an empty excitation
    table, though the fits derive w, p, q, r from that pose, and never said which DOFs are
    excited. Now each is the fits' derivative (derive_velocities, [data]'s default window),
    marked as from the pose, and ``excited`` is excited_dofs of those velocities."""
    from nnid.datasets.inspect import summarize
    from nnid.datasets.preprocess import derive_velocities, excited_dofs

    log = _pose_only_log()
    info = summarize(log)
    derived = derive_velocities(log, 1.0, 4)
    assert info["velocity_from_pose"]["columns"] == ["w", "p", "q", "r"]
    assert info["velocity_from_pose"]["approximate"] == ["w"]
    for dof in ("w", "p", "q", "r"):
        assert info["excitation"][dof]["velocity_std"] == pytest.approx(derived[dof].std())
        assert info["excitation"][dof]["velocity_from_pose"] is True
    assert info["excited"] == excited_dofs(derived, ["u", "v", "w", "p", "q", "r"])
    assert info["excited"] == ["w", "q", "r"]  # roll only trembles
    log.to_csv(tmp_path / "dive.csv", index=False)
    done = runner.invoke(app, ["inspect", str(tmp_path / "dive.csv"), "--out", str(tmp_path / "o")])
    assert done.exit_code == 0, done.output
    text = " ".join(done.output.split())
    assert "from pose w, p, q, r (as train derives them: 1 s window, order 4; w approximate" in text
    assert "excited w, q, r; not excited: p" in text and "no velocity: u, v" in text
    assert "(from pose)" in text
    assert read_json(tmp_path / "o" / "summary.json")["excited"] == ["w", "q", "r"]


def test_inspect_says_commands_are_commands_without_a_vehicle(tmp_path):
    """A log with cmd_* columns and no tau_*: the excitation table's force columns were all
    '-', and the commands' own excitation was never shown. Now each channel's std and active
    share, titled as commands (no vehicle file maps them to forces), and no force columns."""
    from nnid.datasets.inspect import summarize

    log = _pose_only_log()
    info = summarize(log)
    assert set(info["commands"]) == {"cmd_heave", "cmd_yaw"}
    assert info["commands"]["cmd_yaw"]["std"] == pytest.approx(log["cmd_yaw"].std())
    share = (log["cmd_heave"] != 0).mean()
    assert info["commands"]["cmd_heave"]["active_share"] == pytest.approx(share)
    assert all("force_std" not in e for e in info["excitation"].values())
    log.to_csv(tmp_path / "dive.csv", index=False)
    done = runner.invoke(app, ["inspect", str(tmp_path / "dive.csv")])
    assert done.exit_code == 0, done.output
    assert "commands per channel (not forces: no vehicle file maps them)" in done.output
    assert "cmd_heave" in done.output and "force std" not in done.output


def test_inspect_duration_is_the_time_sampled_and_gaps_apart(tmp_path):
    """A 10-s hole in a run at 10 Hz: inspect said '30 s', gap time counted as data. Now the
    time sampled and the time in gaps (the hole less one interval, as missing samples are
    counted), each run's too."""
    from nnid.datasets.inspect import summarize

    t = np.r_[np.arange(100), np.arange(200, 300)] * 0.1
    log = pd.DataFrame({"t": t, "u": np.sin(t), "tau_X": np.cos(t)})
    info = summarize(log)
    assert info["duration_s"] == pytest.approx(19.9) and info["gap_s"] == pytest.approx(10.0)
    (run,) = info["experiments"]
    assert (run["duration_s"], run["gap_s"]) == pytest.approx((19.9, 10.0))
    log.to_csv(tmp_path / "holed.csv", index=False)
    done = runner.invoke(app, ["inspect", str(tmp_path / "holed.csv")])
    assert done.exit_code == 0, done.output
    assert "200 samples, 19.9 s of data (and 10 s in gaps), 1 experiment," in done.output
    assert "gaps 1 (longest 10.1 s)" in " ".join(done.output.split())


def test_inspect_says_why_a_pose_gives_no_velocities(tmp_path):
    """A pose-only run shorter than the derivative's window: the fits refuse it; inspect
    says so in a line rather than failing or leaving the velocities out without a word."""
    from nnid.datasets.inspect import summarize

    info = summarize(_pose_only_log(n=12))
    assert info["velocity_from_pose"]["columns"] == [] and info["excitation"] == {}
    assert "too few for the Savitzky-Golay window" in info["velocity_from_pose"]["error"]
    _pose_only_log(n=12).to_csv(tmp_path / "short.csv", index=False)
    done = runner.invoke(app, ["inspect", str(tmp_path / "short.csv")])
    assert done.exit_code == 0, done.output
    assert "from pose none:" in " ".join(done.output.split())


def test_enu_flu_and_quaternions(tmp_path):
    """A vehicle heading north-east in ENU (yaw 45° from east = 45° from north) with FLU body
    velocities: NED/FRD gives ψ = 45°, x = y, z = −up, v = −v_FLU."""
    n = 50
    yaw_enu = np.pi / 4
    q = [math.cos(yaw_enu / 2), 0.0, 0.0, math.sin(yaw_enu / 2)]
    df = pd.DataFrame({"t": np.arange(n) * 0.1, "px": 1.0, "py": 1.0, "pz": -2.0,
                       "qw": q[0], "qx": q[1], "qy": q[2], "qz": q[3],
                       "vx": 0.3, "vy": 0.1, "vz": 0.05, "f": 1.0})  # fmt: skip
    df.to_csv(tmp_path / "odom.csv", index=False)
    cmap = """
[[sources]]
file = "odom.csv"
time = "t"
frame = "enu_flu"
quaternion = ["qw", "qx", "qy", "qz"]
columns = { x = "px", y = "py", z = "pz", u = "vx", v = "vy", w = "vz", tau_X = "f" }
"""
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    row = log.iloc[0]
    assert (row["x"], row["y"], row["z"]) == pytest.approx((1.0, 1.0, 2.0))
    assert (row["phi"], row["theta"], row["psi"]) == pytest.approx((0.0, 0.0, np.pi / 4))
    assert (row["u"], row["v"], row["w"]) == pytest.approx((0.3, -0.1, -0.05))


def _enu_flu(ned: pd.DataFrame) -> pd.DataFrame:
    """A NED / FRD log in ENU / FLU, through the full rotations (not the column rules)."""
    from nnid.datasets.mapping import euler_from_rotation, rotation_from_euler

    t, f = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]]), np.diag([1.0, -1, -1])
    enu = ned.copy()
    enu[["x", "y", "z"]] = ned[["x", "y", "z"]].to_numpy() @ t.T
    for group in ("uvw", "pqr", ("du", "dv", "dw"), ("tau_X", "tau_Y", "tau_Z"),
                  ("tau_K", "tau_M", "tau_N")):  # fmt: skip
        enu[list(group)] = ned[list(group)].to_numpy() @ f.T
    angles = ["phi", "theta", "psi"]
    enu[angles] = euler_from_rotation(t @ rotation_from_euler(ned[angles].to_numpy()) @ f)
    return enu


@pytest.mark.parametrize("mapped", ["all", "depth, compass, two-axis DVL"])
def test_enu_flu_converts_every_column_it_maps_alone(tmp_path, mapped):
    """ENU / FLU back to NED / FRD: the forces were never converted (tau_Y, Z, M, N came back
    sign-flipped), and a column outside a whole group (z without x and y, ψ without φ and θ,
    u and v without w, r without p and q) was left as logged, with the report saying the log
    was converted."""
    rng = np.random.default_rng(0)
    n = 60
    cols = ["x", "y", "z", "phi", "theta", "psi", *"uvwpqr", "du", "dv", "dw",
            "tau_X", "tau_Y", "tau_Z", "tau_K", "tau_M", "tau_N"]  # fmt: skip
    ned = pd.DataFrame(rng.uniform(-1, 1, (n, len(cols))), columns=cols)
    ned["psi"] = rng.uniform(-3, 3, n)
    ned.insert(0, "t", np.arange(n) * 0.1)
    _enu_flu(ned).to_csv(tmp_path / "log.csv", index=False)
    keep = cols if mapped == "all" else ["z", "psi", "u", "v", "r", "tau_Y"]
    columns = ", ".join(f"{c} = '{c}'" for c in keep) + ", acc_x = 'du'"  # one of the user's own
    cmap = (
        f'[[sources]]\nfile = "log.csv"\ntime = "t"\nframe = "enu_flu"\ncolumns = {{ {columns} }}\n'
    )
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    for c in keep:
        assert np.allclose(log[c], ned[c], atol=1e-12), c
    frame = [s.detail for s in report.steps if s.step == "frame"]
    assert frame and frame[0].endswith("columns of its own left as logged: acc_x")
    if mapped != "all":  # x without y: ENU's x is NED's y, so one alone cannot be converted
        with pytest.raises(NnidInputError, match="converting the frame needs both x and y"):
            load_log(tmp_path, _write_map(tmp_path / "x.toml", cmap.replace("{ ", "{ x = 'x', ")))


def test_one_source_column_feeds_two_targets(tmp_path):
    """A column mapped twice, each with its own scale (one force logged once, fed to two
    axes), is read once and converted for each: it was a 2-D selection and a traceback."""
    n = 40
    df = pd.DataFrame({"t": np.arange(n) * 0.1, "depth": 1.0, "f": np.linspace(0, 1, n)})
    df.to_csv(tmp_path / "log.csv", index=False)
    cmap = """
[[sources]]
file = "log.csv"
time = "t"
columns = { z = "depth", tau_X = "f", tau_Y = { from = "f", scale = -2.0 } }
"""
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    assert np.allclose(log["tau_X"], df["f"]) and np.allclose(log["tau_Y"], -2.0 * df["f"])


def test_a_file_named_like_a_pattern_is_read_as_itself(tmp_path):
    """--data "dir [1]/dive [1].csv" with a reader config: the name went into the glob, so
    the brackets matched nothing ("no file matches") and a star took in dive_old.csv too."""
    folder = tmp_path / "dir [1]"
    folder.mkdir()
    t = np.arange(0, 10, 0.05)
    dive = pd.DataFrame({"run": "r1", "time": t, "depth": 0.5 + 0.01 * t, "pwm": 1600.0})
    dive.to_csv(folder / "dive [1].csv", index=False)
    dive.assign(run="r9").to_csv(folder / "dive_old.csv", index=False)
    cmap = _write_map(tmp_path / "map.toml", 'experiment = "run"\n[[sources]]\nfile = "dive*.csv"'
                      '\ntime = "time"\ncolumns = { z = "depth", cmd_1 = "pwm" }\n')  # fmt: skip
    log, report = load_log(folder / "dive [1].csv", cmap)
    assert set(log["experiment"]) == {"r1"}  # dive_old.csv's r9 stays out
    assert "dive [1].csv" in report.steps[0].detail  # named as it is, not escaped
    both, _ = load_log(folder, cmap)
    assert set(both["experiment"]) == {"r1", "r9"}  # the pattern, under a bracketed folder


def test_a_source_matching_no_file_names_the_reader_config(tmp_path):
    """The error names the reader config's file, where 'sources.0.file' is, not its name."""
    cmap = _write_map(tmp_path / "map.toml", 'name = "probe"\n' + MAP.replace("nav.csv", "x*.csv"))
    with pytest.raises(NnidInputError) as err:
        load_log(tmp_path, cmap)
    assert str(err.value).startswith(f"{cmap}, field 'sources.0.file': no file matches 'x*.csv'")


FILE_RUNS = """
experiment = "file"
[[sources]]
file = "PATTERN"
time = "t"
columns = { z = "depth", tau_Z = "thrust" }
"""


def _dive(path, depth0: float) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    t = np.arange(0.0, 5.0, 0.05)
    pd.DataFrame({"t": t, "depth": depth0 + 0.1 * t, "thrust": np.sin(t)}).to_csv(path, index=False)


def test_run_labels_are_read_as_text(tmp_path):
    """Labels 1 and 01 are two runs: read as numbers they were one, whose time then went
    backwards, said as "experiment np.int64(1)"."""
    t = np.arange(0.0, 2.0, 0.05)
    runs = [pd.DataFrame({"experiment": label, "t": t, "z": 1.0 + t, "tau_Z": np.sin(t)})
            for label in ("1", "01")]  # fmt: skip
    path = tmp_path / "runs.csv"
    pd.concat(runs).to_csv(path, index=False)
    log, _ = load_log(str(path))
    assert sorted(log["experiment"].unique()) == ["01", "1"]


def test_each_file_is_its_own_run_and_two_files_of_one_name_are_refused(tmp_path):
    """experiment = "file": a run is the file's name without its suffix. Cut at the first dot,
    two days' dives were both run 'dive', and the second day's samples at the same stamps were
    dropped; two folders' nav.csv were one run. Such a pair is now refused, naming both."""
    for day, depth0 in (("01", 1.0), ("02", 5.0)):
        _dive(tmp_path / f"dive.2024-05-{day}.csv", depth0)
    cmap = _write_map(tmp_path / "map.toml", FILE_RUNS.replace("PATTERN", "dive.*.csv"))
    log, _ = load_log(tmp_path, cmap)
    runs = log.groupby("experiment")["z"].first()
    assert runs.to_dict() == pytest.approx({"dive.2024-05-01": 1.0, "dive.2024-05-02": 5.0})
    assert len(log) == 200
    for folder in ("a", "b"):
        _dive(tmp_path / folder / "nav.csv", 1.0)
    cmap = _write_map(tmp_path / "map2.toml", FILE_RUNS.replace("PATTERN", "*/nav.csv"))
    with pytest.raises(
        NnidInputError, match=r"a/nav.csv and .*b/nav.csv, which both name run 'nav'"
    ):
        load_log(tmp_path, cmap)


def test_files_joined_into_one_run_must_not_overlap_in_time(tmp_path):
    """A glob's files without experiment = "file" are one run: two dives each restarting at
    t = 0 were joined, the second's rows at the same stamps dropped without a word. Refused,
    naming both files; consecutive slices of one session (tartan_auv.toml) are still read."""
    body = FILE_RUNS.replace('experiment = "file"\n', "").replace("PATTERN", "dive_*.csv")
    cmap = _write_map(tmp_path / "map.toml", body)
    for k in (1, 2):
        _dive(tmp_path / f"dive_{k}.csv", float(k))
    with pytest.raises(NnidInputError, match=r"dive_1.csv and .*dive_2.csv, whose times overlap"):
        load_log(tmp_path, cmap)
    later = pd.read_csv(tmp_path / "dive_2.csv")
    later.assign(t=later["t"] + 5.0).to_csv(tmp_path / "dive_2.csv", index=False)
    log, _ = load_log(tmp_path, cmap)
    assert len(log) == 200 and log["z"].iloc[0] == 1.0 and log["z"].iloc[-1] > 2.0


@pytest.mark.parametrize(
    ("column", "said"),
    [
        # NaN filled the column, text and true were coerced to 2.0 and 1.0
        ('{ from = "f", offset = nan }', "'sources.0.columns.tau_X.offset': must be a finite"),
        ('{ from = "f", scale = "2" }', "'sources.0.columns.tau_X.scale': Input should be a va"),
        ('{ from = "f", scale = true }', "'sources.0.columns.tau_X.scale': Input should be a va"),
        # the union's member name ("str", "ColumnSpec") was said as a key of the file
        ("{ offset = 1.0 }", "'sources.0.columns.tau_X.from': is required but missing"),
        ('{ from = "f", unit = "furlong" }', "'sources.0.columns.tau_X.unit': unknown unit"),
    ],
)
def test_a_column_spec_of_the_wrong_type_is_refused_naming_its_key(tmp_path, column, said):
    path, error = _refused_columns(tmp_path, f"tau_X = {column}")
    assert error.startswith(f"{path}, field {said}")


def test_an_unknown_unit_offers_only_units_a_column_takes(tmp_path):
    # "s" and "ms" were offered, and every column refuses them (time has its time_scale)
    _, error = _refused_columns(tmp_path, 'u = { from = "f", unit = "furlong" }')
    offered = error.split("expected one of ")[1].split(", ")
    assert {"m/s", "deg"} <= set(offered) and not {"s", "ms"} & set(offered)


def test_every_angle_without_a_unit_is_named_when_one_looks_like_degrees(tmp_path):
    """Roll and pitch of a few degrees pass the ±2π check: named with the yaw that is refused
    as degrees, or they were read as radians once the yaw alone was given unit = "deg"."""
    t = np.arange(0.0, 5.0, 0.1)
    angles = {"r": 3 * np.sin(t), "p": 4 * np.cos(t), "y": 170 * np.sin(t)}
    pd.DataFrame({"t": t, **angles, "f": 1.0}).to_csv(tmp_path / "log.csv", index=False)
    _, error = _refused_columns(tmp_path, 'phi = "r", theta = "p", psi = "y", tau_X = "f"')
    assert "looks like degrees for psi" in error
    assert "phi, theta of this source have no unit either" in error
    _, error = _refused_columns(
        tmp_path, 'phi = { from = "r", unit = "deg" }, theta = "p", psi = "y", tau_X = "f"'
    )
    assert "; theta of this source has no unit either" in error


def test_an_angle_without_a_unit_beside_one_with_a_unit_is_refused(tmp_path):
    """A roll and pitch of a few degrees pass the degrees guess: beside a yaw given in "deg"
    they were read as radians (3° as 3 rad). One unit declared asks for one on each angle."""
    t = np.arange(0.0, 5.0, 0.1)
    angles = {"r": 3 * np.sin(t), "p": 4 * np.cos(t), "y": 170 * np.sin(t)}
    pd.DataFrame({"t": t, **angles, "f": 1.0}).to_csv(tmp_path / "log.csv", index=False)
    _, error = _refused_columns(
        tmp_path, 'psi = { from = "y", unit = "deg" }, phi = "r", theta = "p", tau_X = "f"'
    )
    assert "field 'r'" in error
    assert "psi ('y') declares a unit but phi ('r'), theta ('p') of the same source" in error
    deg = '{ from = "r", unit = "deg" }, theta = { from = "p", unit = "deg" }'
    cmap = f'[[sources]]\nfile = "log.csv"\ntime = "t"\ncolumns = {{ phi = {deg}, '
    cmap += 'psi = { from = "y", unit = "deg" }, tau_X = "f" }\n'
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    assert np.allclose(log["phi"], np.radians(angles["r"]))


def _refused_columns(root, columns: str):
    """The reader config of one source with ``columns``, and the error that loading it gives."""
    cmap = f'[[sources]]\nfile = "log.csv"\ntime = "t"\ncolumns = {{ {columns} }}\n'
    path = _write_map(root / "map.toml", cmap)
    with pytest.raises(NnidInputError) as err:
        load_log(root, path)
    return path, str(err.value)


def _edit_nav(root, edit):
    _sensor_tables(root)
    nav = pd.read_csv(root / "nav.csv")
    edit(nav).to_csv(root / "nav.csv", index=False)


@pytest.mark.parametrize(
    ("case", "said"),
    [
        # the resampler wrapped degrees into [-π, π): 100° read as 100 rad, wrapped, unseen
        (
            lambda m, n: (m.replace('{ from = "yaw_deg", unit = "deg" }', '"yaw_deg"'), n),
            "field 'yaw_deg': reaches 57.28, which looks like degrees for psi: set unit",
        ),
        # a 10-s recording became 10,000 s
        (
            lambda m, n: (m, n.assign(time=n["time"] * 1000)),
            "field 'sources.0.time_scale': source 'nav.csv': time steps by 13 (median): this "
            "looks like milliseconds",
        ),
        # the samples of a reset were sorted in between the others
        (
            lambda m, n: (m, n.assign(time=np.where(n.index >= 400, n["time"] - 5.0, n["time"]))),
            "column 'time', row 400: time goes back by 4.987 s in experiment 'r1' and 370 of "
            "its 770 samples stay behind: two runs in one file?",
        ),
        # a reboot near the end (50 of 770 samples, under the share of a reset) restarts the
        # clock: sorted in, those samples took the times of the run's first 0.65 s
        (
            lambda m, n: (
                m,
                n.assign(
                    time=np.where(
                        n.index >= 720, n["time"] - (n["time"][720] - n["time"][0]), n["time"]
                    )
                ),
            ),
            "column 'time', row 720: time goes back from 1600000009.35 s to 1600000000 s in "
            "experiment 'r1', by 9.347 s: a late sample is sorted in up to 5 of its steps",
        ),
        (lambda m, n: (m, n.iloc[:0]), "nav.csv: has no rows"),
        (lambda m, n: (m.replace("rate = 20.0", "rate = 2e6"), n), "field 'rate': 2e+06 Hz"),
        (
            lambda m, n: (m, n.assign(run=n["run"].where(n.index != 9))),
            "column 'run', row 9: value empty (NaN) is no experiment label (1 such rows",
        ),
    ],
)
def test_a_source_clock_or_angle_in_the_wrong_unit_is_refused(tmp_path, case, said):
    """What the resampling would have hidden is said against the source file and column."""
    captured = {}

    def edit(nav):
        captured["map"], out = case(MAP, nav)
        return out

    _edit_nav(tmp_path, edit)
    with pytest.raises(NnidInputError) as err:
        load_log(tmp_path, _write_map(tmp_path / "map.toml", captured["map"]))
    assert said in str(err.value)


def test_a_few_repeated_or_late_stamps_are_repaired_and_said(tmp_path):
    """A stamp repeated now and then is kept once, a sample a little late is sorted in: both
    in the cleaning report, with the rows dropped counted."""

    def jitter(nav):
        t = nav["time"].to_numpy().copy()
        t[[50, 51]] = t[[51, 50]]  # one pair out of order
        t[100] = t[99]  # one repeated stamp
        return nav.assign(time=t)

    _edit_nav(tmp_path, jitter)
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    steps = {s.step: s for s in report.steps}
    assert steps["repeated stamps"].rows_removed == 1
    assert "1 late samples sorted in" in steps["sort"].detail
    assert np.allclose(log["psi"], 0.1 * log["t"], atol=2e-3)
    # many repeated stamps (two runs of one file, sorted; or stamps coarser than the samples):
    # the first of each kept, as before, but said with the count and what it may be
    _edit_nav(tmp_path, lambda n: pd.concat([n, n.assign(depth=1)]).sort_values("time"))
    _, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    said = next(s for s in report.steps if s.step == "repeated stamps")
    assert said.rows_removed == 770 and "770 of 1540 samples repeat a stamp" in said.detail
    assert "runs merged (experiment)?" in said.detail
    # commands logged on change every 2.5 s in whole seconds: a hold source's steps are its
    # commands', not a clock in milliseconds
    _edit_nav(tmp_path, lambda n: n)
    cmd = pd.read_csv(tmp_path / "cmd.csv")
    cmd.assign(time=cmd["time"].round()).to_csv(tmp_path / "cmd.csv", index=False)
    assert len(load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))[0]) > 100


def test_a_repeated_command_stamp_holds_the_later_command(tmp_path):
    """Two commands at one stamp: the later message is the one in force, but the first was
    held (as a measurement's first is kept). Said as such in the cleaning report."""
    _sensor_tables(tmp_path)
    cmd = pd.read_csv(tmp_path / "cmd.csv")
    later = cmd.iloc[[1]].assign(pwm=1900)  # a second command at 2.5 s, after the first
    pd.concat([cmd.iloc[:2], later, cmd.iloc[2:]]).to_csv(tmp_path / "cmd.csv", index=False)
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    held = log.loc[(log["t"] > 2.5) & (log["t"] < 5.0), "cmd_1"]
    assert np.allclose(held, (1900 - 1500) * 0.0025)
    said = next(s for s in report.steps if s.step == "repeated stamps")
    assert "cmd.csv" in said.detail and "the last of each kept" in said.detail


@pytest.mark.parametrize(
    ("columns", "said"),
    [
        ('U = "vx"', "'U' is no log column; did you mean 'u'?"),
        ('tau_n = "vx"', "'tau_n' is no log column; did you mean 'tau_N'?"),
        ('experiment = "vx"', "'experiment' comes from the source's 'time'"),
        ('z = { from = "vx", unit = "deg" }', "z in 'deg': z takes m, cm, mm"),
        ('u = { from = "vx", unit = "mm" }', "u in 'mm': u takes m/s, cm/s, mm/s"),
        # a length or angle unit on a force or acceleration scaled it by 0.01 or 0.0175 unseen
        ('tau_X = { from = "vx", unit = "cm" }', "tau_X in 'cm': tau_X takes no unit"),
        ('du = { from = "vx", unit = "m/s" }', "du in 'm/s': du takes no unit"),
        ('cmd_9 = { from = "vx", unit = "deg" }', "cmd_9 in 'deg': cmd_9 takes no unit"),
        ('acc_x = { from = "vx", unit = "cm" }', "acc_x in 'cm': acc_x takes no unit"),
        ('tau_Z = { from = "vx", offset = nan }', "'sources.0.columns.tau_Z.offset'"),
        # a copy-paste slip loaded as a vehicle moving diagonally
        ('u = "vx", v = { from = "vx" }', "u and v both read source column 'vx'"),
    ],
)
def test_a_column_target_that_is_a_typo_or_in_the_wrong_unit_is_refused(tmp_path, columns, said):
    """A misspelt target was kept as an extra column and the log's own one was missing
    (columns of the user's own that only resemble the log's are kept: the test below)."""
    assert re.search(re.escape(said), _refused_columns(tmp_path, columns)[1])


def test_two_sources_of_one_column_and_a_bad_pattern_are_refused(tmp_path):
    twice = MAP.replace("columns = { cmd_1", 'columns = { z = "pwm", cmd_1')
    with pytest.raises(NnidInputError, match="sources 0 and 1 both give 'z': map it from one"):
        load_log(tmp_path, _write_map(tmp_path / "map.toml", twice))
    # re.error is no ValueError: it was a traceback
    bad = 'include = "(r1"\n' + MAP
    with pytest.raises(NnidInputError, match="field 'include': '\\(r1' is not a regular"):
        load_log(tmp_path, _write_map(tmp_path / "map.toml", bad))


def test_speeds_in_millimetres_per_second_are_converted(tmp_path):
    df = pd.DataFrame({"t": np.arange(40) * 0.1, "vx": 250.0, "depth": 1.0, "f": 1.0})
    df.to_csv(tmp_path / "log.csv", index=False)
    cmap = """
[[sources]]
file = "log.csv"
time = "t"
columns = { u = { from = "vx", unit = "mm/s" }, z = "depth", tau_X = "f" }
"""
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    assert np.allclose(log["u"], 0.25)


def test_a_csv_header_with_spaces_after_the_commas_keeps_its_columns(tmp_path):
    """'t, experiment, u' read as ' experiment' and ' u': runs merged, velocity gone."""
    rows = ["t, experiment, u, tau_X"] + [f"{0.1 * k:.1f}, r{k // 20}, 0.1, 1.0" for k in range(40)]
    (tmp_path / "log.csv").write_text("\n".join(rows) + "\n")
    log, _ = load_log(tmp_path / "log.csv")
    assert list(log.columns) == ["t", "experiment", "u", "tau_X"]
    assert sorted(set(log["experiment"])) == ["r0", "r1"]


def test_quaternion_euler_round_trip(rng):
    angles = np.stack([rng.uniform(-3, 3, 200), rng.uniform(-1.5, 1.5, 200),
                       rng.uniform(-3, 3, 200)], 1)  # fmt: skip
    rot = rotation_from_euler(angles)
    assert np.allclose(euler_from_rotation(rot), angles, atol=1e-9)
    # rotation about z by a quaternion matches the Euler yaw
    q = np.array([math.cos(0.3), 0, 0, math.sin(0.3)])
    assert np.allclose(rotation_from_quaternion(q), rotation_from_euler(np.array([0, 0, 0.6])))


def test_nan_rows_error_or_dropped_with_count(tmp_path):
    """Not a number in a time, command or force column: refused, or its rows dropped with
    drop_nonfinite. (An empty motion cell is a missing measurement: the test below.)"""
    _sensor_tables(tmp_path)
    nav = pd.read_csv(tmp_path / "nav.csv")
    nav.loc[[10, 20, 21], "depth"] = np.nan
    nav.to_csv(tmp_path / "nav.csv", index=False)
    cmd = pd.read_csv(tmp_path / "cmd.csv")
    cmd.loc[[2], "pwm"] = np.nan
    cmd.to_csv(tmp_path / "cmd.csv", index=False)
    with pytest.raises(NnidInputError) as info:
        load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    msg = str(info.value)
    assert "cmd.csv" in msg and "column 'pwm'" in msg and "row 2" in msg and "1 rows" in msg
    nav.assign(time=nav["time"].where(nav.index != 10)).to_csv(tmp_path / "nav.csv", index=False)
    with pytest.raises(NnidInputError) as info:  # an empty stamp is no missing measurement
        load_log(tmp_path, _write_map(tmp_path / "map.toml", MAP))
    assert "nav.csv" in str(info.value) and "column 'time', row 10" in str(info.value)
    cmd.loc[[2], "pwm"] = 1300
    cmd.to_csv(tmp_path / "cmd.csv", index=False)
    nav.to_csv(tmp_path / "nav.csv", index=False)
    log, report = load_log(
        tmp_path, _write_map(tmp_path / "map2.toml", "drop_nonfinite = true\n" + MAP)
    )
    dropped = [s for s in report.steps if s.step == "drop non-finite"]
    assert dropped and dropped[0].rows_removed == 3 and np.isfinite(log["z"]).all()


def test_empty_cells_of_a_measured_motion_column_are_read_as_gaps(tmp_path):
    """A DVL writing NaN for u, v, w while it lost bottom lock refused the whole source (or,
    with drop_nonfinite, dropped the rows and their depth with them). The cells stay empty:
    a short loss is interpolated over, a long one stays a gap, and both are reported."""
    t = np.arange(0.0, 20.0, 0.2)
    dvl = pd.DataFrame({"t": t, "vx": 0.1 * t, "vy": 0.0, "vz": 0.0, "depth": 1.0 + 0.01 * t})
    lost = ((t > 3.9) & (t < 4.3)) | ((t > 10.0) & (t < 14.0))  # 0.4 s and 4 s
    dvl.loc[lost, ["vx", "vy", "vz"]] = np.nan
    dvl.to_csv(tmp_path / "dvl.csv", index=False)
    pd.DataFrame({"t": [0.0, 10.0], "f": 1.0}).to_csv(tmp_path / "cmd.csv", index=False)
    cmap = (
        'rate = 5.0\n[[sources]]\nfile = "dvl.csv"\ntime = "t"\n'
        'columns = { u = "vx", v = "vy", w = "vz", z = "depth" }\n'
        '[[sources]]\nfile = "cmd.csv"\ntime = "t"\nmethod = "hold"\n'
        'columns = { tau_X = "f" }\n'
    )
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    assert len(log) == t.size and report.rows_removed == 0
    assert np.allclose(log["z"], 1.0 + 0.01 * log["t"])  # the depth of those rows is kept
    short = (log["t"] > 3.9) & (log["t"] < 4.3)
    assert np.allclose(log.loc[short, "u"], 0.1 * log.loc[short, "t"])  # bridged
    long = (log["t"] > 10.0) & (log["t"] < 14.0)
    assert log.loc[long, ["u", "v", "w"]].isna().all().all()  # a gap, not made up
    assert log.loc[~long, ["u", "v", "w"]].notna().all().all()
    said = next(s for s in report.steps if s.step == "empty cells")
    assert f"{int(lost.sum())} rows with an empty cell in vx, vy, vz" in said.detail


BAD = """t,x,y,z,phi,theta,psi,tau_X
0.0,0,0,0,0,0,0,1
0.1,0,0,0,0,0,0,1
0.2,0,0,0,0,0,0,1
"""


@pytest.mark.parametrize(
    "text, words",
    [
        (BAD.replace("t,x", "time,x"), "required column 't'"),
        (BAD.replace("0.2,0", "0.1,0"), "column 't', row 2"),
        (BAD.replace("0.1,0,0,0,0,0", "0.1,0,inf,0,0,0"), "column 'y', row 1"),
        (BAD.replace("0.1,0,0,0,0,0", "0.1,0,north,0,0,0"), "column 'y', row 1"),
        (BAD.replace("0.2,0,0,0,0,0,0", "0.2,0,0,0,0,0,170"), "looks like degrees"),
        (BAD[:-8], "row 2"),  # truncated mid-row: the short row is named
    ],
)
def test_inspect_bad_logs_exit_2_with_one_line(tmp_path, text, words):
    path = tmp_path / "run.csv"
    path.write_text(text)
    result = runner.invoke(app, ["inspect", str(path)])
    assert result.exit_code == 2, result.output
    assert words in result.output and "run.csv" in result.output
    assert len(result.output.strip().splitlines()) == 1


def test_inspect_reports_and_writes_summary(tmp_path):
    _sensor_tables(tmp_path)
    cmap = _write_map(tmp_path / "map.toml", MAP)
    result = runner.invoke(app, ["inspect", str(tmp_path), "--columns", str(cmap), "--out",
                                 str(tmp_path / "o")])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert "1 experiment, " in result.output and "20 Hz" in result.output
    assert "p, q, r" not in result.output  # no roll/pitch: rates are not derivable
    assert (tmp_path / "o" / "cleaning.md").exists()
    for name in ("summary.json", "cleaning.json"):  # strict JSON with its schema, as every file
        assert read_json(tmp_path / "o" / name)["schema_version"] == SCHEMA_VERSION
    # one v sample: its std is undefined, written null (json.dumps wrote NaN, which read_json
    # and every strict JSON reader refuse)
    log = pd.DataFrame({"t": 0.05 * np.arange(40), "u": 0.1, "v": np.nan, "tau_X": 1.0})
    log.loc[0, "v"] = 0.2
    log.to_csv(tmp_path / "one_v.csv", index=False)
    result = runner.invoke(app, ["inspect", str(tmp_path / "one_v.csv"), "--out",
                                 str(tmp_path / "o2")])  # fmt: skip
    assert result.exit_code == 0, result.output
    assert read_json(tmp_path / "o2" / "summary.json")["excitation"]["v"]["velocity_std"] is None
    bad = _write_map(tmp_path / "bad.toml", MAP.replace('"depth"', '"depthh"'))
    res = runner.invoke(app, ["inspect", str(tmp_path), "--columns", str(bad)])
    assert res.exit_code == 2 and "'depthh'" in res.output and "nav.csv" in res.output


def test_short_log_for_filter_window_is_a_clear_error(tmp_path):
    from nnid.datasets.preprocess import derive_velocities

    log = pd.DataFrame({"t": np.arange(5) * 0.01, "phi": 0.0, "theta": 0.0, "psi": 0.0,
                        "tau_X": 0.0})  # fmt: skip
    with pytest.raises(NnidInputError, match="too few for the Savitzky-Golay window"):
        derive_velocities(log, window_s=0.5)


# property-based: random malformed tables give a valid log or the documented error, never else
_cell = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=32),
    st.integers(-10, 10),
    st.sampled_from(["", "abc", "1e400", "-", "nan", " 3 "]),
)
_columns = st.lists(st.sampled_from(["t", "x", "u", "psi", "tau_X", "cmd_a", "experiment", "junk"]),
                    min_size=1, max_size=6, unique=True)  # fmt: skip


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(columns=_columns, rows=st.lists(st.lists(_cell, min_size=6, max_size=6), max_size=8))
def test_csv_reader_returns_valid_log_or_documented_error(tmp_path, columns, rows):
    frame = pd.DataFrame([r[: len(columns)] for r in rows], columns=columns)
    path = tmp_path / "random.csv"
    frame.to_csv(path, index=False)
    try:
        log, _ = load_log(path)
    except NnidInputError as err:
        assert "random.csv" in str(err)
        return
    assert validate_log(log, "again") is log
    assert "t" in log and len(log) == len(rows)


def test_stale_commands_are_not_held_past_the_timeout(tmp_path):
    """Commands that stop while the measurements go on: with hold_timeout the run ends that
    long after the last command, and the report says so."""
    _sensor_tables(tmp_path)
    timed = MAP.replace('method = "hold"', 'method = "hold"\nhold_timeout = 0.5')
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", timed))
    assert log["t"].iloc[-1] == pytest.approx(7.0 + 0.5, abs=0.05)  # last command at 7.0 s
    assert any(s.step == "cut stale hold" for s in report.steps)


def test_repeated_cleaning_steps_are_summarised_with_counts_and_ranges():
    """A step repeated for every run of a 1,000-run set is one line with the run count and the
    range of each number (inspect prints these; the JSON keeps each run's line)."""
    from nnid.datasets.cleaning import CleaningReport

    report = CleaningReport()
    report.add("read", "5000 rows from 3 files")
    for i in range(1000):
        report.add("resample", f"'run{i}': {100 + i % 50} samples at 20 Hz (nav.csv: linear)")
        report.add("drop", f"'run{i}': duplicate times", rows_removed=1 + i % 4)
    report.add("skip experiment", "'odd': not every source has data")
    assert report.summary() == [
        "read: 5000 rows from 3 files",
        "resample in 1000 runs: 100-149 samples at 20 Hz (nav.csv: linear)",
        "drop in 1000 runs: duplicate times (2500 rows removed)",
        "skip experiment: 'odd': not every source has data",
    ]
    assert len(report.to_dict()["steps"]) == 2002


@pytest.mark.parametrize(
    ("sep", "decimal"),
    [(";", ","), ("\t", "."), (";", ".")],
    ids=["semicolon-comma", "tab", "semicolon"],
)
def test_semicolon_and_tab_separated_csv_are_read(tmp_path, sep, decimal):
    """A CSV written by a spreadsheet in a European locale (';' and a decimal comma) or as TSV
    is read as the same log, not refused as one column."""
    frame = pd.DataFrame({"t": [0.0, 0.1, 0.2], "u": [0.5, 0.25, -0.125], "tau_X": [1.5, 2.0, 2.5]})
    path = tmp_path / "log.csv"
    frame.to_csv(path, sep=sep, decimal=decimal, index=False)
    log, _ = load_log(path)
    pd.testing.assert_frame_equal(log[["t", "u", "tau_X"]], frame)


def test_extra_columns_that_resemble_the_logs_own_are_kept(tmp_path):
    df = pd.DataFrame({"t": np.arange(40) * 0.1, "a": 0.1, "b": 0.2, "depth": 1.0, "f": 1.0})
    df.to_csv(tmp_path / "log.csv", index=False)
    cmap = """
[[sources]]
file = "log.csv"
time = "t"
columns = { theta_d = "a", tau_X2 = "b", z = "depth", tau_X = "f" }
"""
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    assert {"theta_d", "tau_X2"} <= set(log.columns)


def test_a_unit_given_is_believed_and_a_source_emptied_by_drop_nonfinite_is_said(tmp_path):
    """Unwrapped radians with unit = "rad" are read (the degrees guess is for no unit); a
    source left with no row by drop_nonfinite was a reduction traceback."""
    t = np.arange(200) * 0.1
    df = pd.DataFrame({"t": t, "yaw": 0.5 * t, "f": 1.0, "u": 0.1})
    df.to_csv(tmp_path / "log.csv", index=False)
    head = '[[sources]]\nfile = "log.csv"\ntime = "t"\n'
    cmap = head + 'columns = { psi = { from = "yaw", unit = "rad" }, u = "u", tau_X = "f" }\n'
    log, _ = load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap))
    assert np.allclose(np.unwrap(log["psi"]), 0.5 * log["t"])
    with pytest.raises(NnidInputError, match='or unit = "rad" for unwrapped radians'):
        load_log(tmp_path, _write_map(tmp_path / "map.toml", cmap.replace(', unit = "rad"', "")))
    df.assign(u=np.nan).to_csv(tmp_path / "log.csv", index=False)
    empty = "drop_nonfinite = true\n" + cmap
    with pytest.raises(NnidInputError, match="no row is left once the non-finite ones are dropped"):
        load_log(tmp_path, _write_map(tmp_path / "map.toml", empty))


def test_the_reader_config_page_agrees_with_the_code(tmp_path):
    """docs/reader_config.md: its example is a valid reader config, and its two key tables
    list exactly the fields of a reader config and of a source (a key added to the code, or
    one the page names that the code lacks, fails here)."""
    from pathlib import Path

    from nnid.datasets.column_map import ColumnMap, Source, load_column_map

    page = (Path(__file__).resolve().parents[1] / "docs" / "reader_config.md").read_text()
    example = re.findall(r"```toml\n(.*?)```", page, re.S)[0]
    (tmp_path / "r.toml").write_text(example)
    cmap = load_column_map(tmp_path / "r.toml")
    assert [s.file for s in cmap.sources] == ["thrusters.csv", "dvl.csv", "ahrs.csv"]
    assert cmap.sources[0].columns["cmd_t1"].scale == 0.0025

    def keys(title: str) -> set[str]:
        table = page.split(title, 1)[1].split("\n\n", 2)[1]
        rows = [line for line in table.splitlines() if line.startswith("| `")]
        return {k.strip("`[] ") for row in rows for k in row.split("|")[1].split(",")}

    assert keys("### Top-level keys") == set(ColumnMap.model_fields) - {"sources"}
    fields = {f.alias or n for n, f in Source.model_fields.items()}
    assert keys("### Each `[[sources]]`") == (fields - {"columns"}) | {"sources.columns"}


def test_a_silence_inside_a_held_source_is_said(tmp_path):
    """hold_timeout cuts a run where its commands stop; a silence of 6 s in the middle was
    held over without a word. It is said, with its length and the samples it covers; the
    samples and values are as before (the command 1.0 held at t = 5 s)."""
    t = np.arange(0, 10.01, 0.1)
    nav = pd.DataFrame({"t": t, **{c: np.sin(t) if c == "u" else 0 * t for c in "uvwpqr"}})
    nav.to_csv(tmp_path / "nav.csv", index=False)
    tc = np.r_[np.arange(0, 2, 0.1), np.arange(8, 10.01, 0.1)]
    cmd = pd.DataFrame({"t": tc, "c": np.r_[np.ones(20), np.zeros(tc.size - 20)]})
    cmd.to_csv(tmp_path / "cmd.csv", index=False)
    body = ('[[sources]]\nfile = "nav.csv"\ntime = "t"\n[sources.columns]\n'
            + "".join(f'{c} = "{c}"\n' for c in "uvwpqr")
            + '[[sources]]\nfile = "cmd.csv"\ntime = "t"\nmethod = "hold"\n'
            'hold_timeout = 0.5\n[sources.columns]\ncmd_a = "c"\n')  # fmt: skip
    log, report = load_log(tmp_path, _write_map(tmp_path / "map.toml", body))
    assert len(log) == 101 and log.loc[(log["t"] - 5.0).abs() < 1e-9, "cmd_a"].item() == 1.0
    (said,) = [s for s in report.steps if s.step == "stale hold"]
    # held at 2.5-7.9 s, 6 s old at most: at 8.0 s the next command is logged (the grid, at
    # the rate of nav's median step, is 3e-14 s early there, and held the old one: 6.1 s, 56)
    assert "cmd.csv is silent for up to 6 s" in said.detail and said.rows_removed == 0
    assert "held over those 55 samples" in said.detail, said.detail


def test_what_the_time_base_makes_up_is_said(tmp_path):
    """Through a reader config without gap or hold_timeout: a 20-s hole was interpolated
    (400 rows became 801 samples, inspect said "gaps 0"), a command file that ended 25 s
    before the run was held to its end, and run labels "01" and "1" were read as one number
    and merged. Each is said now; the labels are two runs."""
    t = np.arange(0, 40, 0.05)
    nav = pd.DataFrame({"t": t, "depth": 1.0 + 0.01 * t})
    nav = nav[(t < 10) | (t > 30)]  # a 20-s hole
    nav.to_csv(tmp_path / "nav.csv", index=False)
    pd.DataFrame({"t": np.arange(0, 15, 0.05), "pwm": 0.2}).to_csv(
        tmp_path / "cmd.csv", index=False
    )
    cmap = _write_map(
        tmp_path / "map.toml",
        """
rate = 20.0
[[sources]]
file = "nav.csv"
time = "t"
columns = { z = "depth" }
[[sources]]
file = "cmd.csv"
time = "t"
method = "hold"
columns = { cmd_1 = "pwm" }
""",
    )
    with pytest.warns(UserWarning) as said:
        _, report = load_log(tmp_path, cmap)
    text = " ".join(str(w.message) for w in said)
    assert "nav.csv has no sample for 20.1 s" in text and "set gap" in text
    # a command held to the end is recorded, not warned of: one logged on change holds so
    held = [s.detail for s in report.steps if s.step == "held past its end"]
    assert held and "cmd.csv ends 25 s before the run" in held[0] and "cmd.csv" not in text
    assert any(s.step == "interpolated over a silence" for s in report.steps)
    runs = pd.DataFrame({"run": ["01"] * 100 + ["1"] * 100, "t": np.r_[t[:100], t[:100]],
                         "depth": 1.0, "pwm": 0.2})  # fmt: skip
    runs.to_csv(tmp_path / "runs.csv", index=False)
    body = 'experiment = "run"\n[[sources]]\nfile = "runs.csv"\ntime = "t"\n'
    labelled = _write_map(
        tmp_path / "runs.toml", body + 'columns = { z = "depth", cmd_1 = "pwm" }\n'
    )
    log, _ = load_log(tmp_path / "runs.csv", labelled)
    assert sorted(set(log["experiment"])) == ["01", "1"]


def test_a_column_mapped_with_scale_zero_is_said(tmp_path):
    """scale = 0 (a channel known to stay neutral, as the NTNU BlueROV2 config maps roll and
    pitch) is kept, and said in the cleaning report: it was silent."""
    t = np.arange(0, 5, 0.05)
    pd.DataFrame({"t": t, "depth": 1.0 + 0.01 * t, "f": 3.0}).to_csv(
        tmp_path / "a.csv", index=False
    )
    body = '[[sources]]\nfile = "a.csv"\ntime = "t"\n'
    cmap = _write_map(
        tmp_path / "m.toml",
        body + 'columns = { z = "depth", tau_Z = { from = "f", scale = 0.0 }, cmd_1 = "f" }\n',
    )
    log, report = load_log(tmp_path, cmap)
    assert (log["tau_Z"] == 0).all()
    assert any(s.step == "zero scale" and "tau_Z" in s.detail for s in report.steps)


def test_a_quaternion_in_ros_order_is_refused_naming_the_order(tmp_path):
    """quaternion = ["orientation.x", ".y", ".z", ".w"] (ROS's field order): four columns of
    norm 1, read as w, x, y, z, another attitude without a word. Names that all end in .w,
    .x, .y, .z are refused in any other order, the expected one named."""
    n = 20
    df = pd.DataFrame({"t": np.arange(n) * 0.1, "orientation.w": 1.0, "orientation.x": 0.0,
                       "orientation.y": 0.0, "orientation.z": 0.0, "u": 0.1, "f": 1.0})  # fmt: skip
    df.to_csv(tmp_path / "odom.csv", index=False)
    body = '[[sources]]\nfile = "odom.csv"\ntime = "t"\ncolumns = { u = "u", tau_X = "f" }\n'
    ros = '["orientation.x", "orientation.y", "orientation.z", "orientation.w"]'
    wrong = _write_map(tmp_path / "ros.toml", f"{body}quaternion = {ros}\n")
    expected = "orientation.w, orientation.x, orientation.y, orientation.z"
    with pytest.raises(NnidInputError, match=f"w, x, y, z in that order.*give {expected}"):
        load_log(tmp_path, wrong)
    listed = ", ".join(f'"{c}"' for c in expected.split(", "))
    good = _write_map(tmp_path / "good.toml", f"{body}quaternion = [{listed}]\n")
    assert np.allclose(load_log(tmp_path, good)[0]["psi"], 0.0)


@pytest.mark.parametrize(
    ("names", "expected"),
    [
        (["qx", "qy", "qz", "qw"], "qw, qx, qy, qz"),
        (["quat_X", "quat_Y", "quat_Z", "quat_W"], "quat_W, quat_X, quat_Y, quat_Z"),
    ],
)
def test_a_quaternion_of_undotted_names_in_ros_order_is_refused(tmp_path, names, expected):
    """Only dotted names were checked for the order: ["qx", "qy", "qz", "qw"] passed the norm
    check and read another attitude without a word."""
    from nnid.datasets.column_map import load_column_map

    listed = ", ".join(f'"{c}"' for c in names)
    body = f'[[sources]]\nfile = "a.csv"\ntime = "t"\nquaternion = [{listed}]\n'
    with pytest.raises(NnidInputError, match=f"w, x, y, z in that order.*give {expected}"):
        load_column_map(_write_map(tmp_path / "map.toml", body))
    right = ", ".join(f'"{c}"' for c in expected.split(", "))
    load_column_map(_write_map(tmp_path / "map.toml", body.replace(listed, right)))


def test_quaternion_columns_that_are_no_quaternion_are_refused(tmp_path):
    """quaternion = ["qw", "qx", "qy", "u"]: normalised row by row, any four columns made an
    attitude. Norms far from 1 are refused, naming the columns; a zero row (a sensor not yet
    initialised) is not counted."""
    n = 60
    yaw = np.linspace(0, 1, n)
    df = pd.DataFrame({"t": np.arange(n) * 0.1, "qw": np.cos(yaw / 2), "qx": 0.0, "qy": 0.0,
                       "qz": np.sin(yaw / 2), "u": np.linspace(0, 2.0, n), "f": 1.0})  # fmt: skip
    df.loc[0, ["qw", "qz"]] = 0.0
    df.loc[30, ["qw", "qz"]] = 0.0  # one inside the run: bridged by its neighbours
    df.to_csv(tmp_path / "odom.csv", index=False)
    body = '[[sources]]\nfile = "odom.csv"\ntime = "t"\ncolumns = { u = "u", tau_X = "f" }\n'
    good = _write_map(tmp_path / "good.toml", body + 'quaternion = ["qw", "qx", "qy", "qz"]\n')
    log, report = load_log(tmp_path, good)
    # the zero first row is a gap (its one NaN made the whole run's angles NaN, "empty")
    assert np.allclose(log["psi"].iloc[1:], yaw[1:]) and np.isnan(log["psi"].iloc[0])
    assert any(s.step == "zero quaternion" for s in report.steps)
    wrong = _write_map(tmp_path / "wrong.toml", body + 'quaternion = ["qw", "qx", "qy", "u"]\n')
    with pytest.raises(NnidInputError, match="qw, qx, qy, u do not keep one norm") as err:
        load_log(tmp_path, wrong)
    assert err.value.field == "quaternion"
    # stored at a fixed scale (integers × 10⁴): one norm throughout, read as before
    df[["qw", "qx", "qy", "qz"]] *= 1e4
    df.to_csv(tmp_path / "odom.csv", index=False)
    scaled, _ = load_log(tmp_path, good)
    assert np.allclose(scaled["psi"], log["psi"], equal_nan=True)
    # thirty seconds of zero quaternions (an AHRS not yet up): a gap, not one held heading
    t = np.arange(600) * 0.1
    yaw = 0.5 * np.sin(0.2 * t)
    late = pd.DataFrame({"t": t, "qw": np.cos(yaw / 2), "qx": 0.0, "qy": 0.0,
                         "qz": np.sin(yaw / 2), "u": 0.1, "f": 1.0})  # fmt: skip
    late.loc[:299, ["qw", "qz"]] = 0.0
    late.to_csv(tmp_path / "odom.csv", index=False)
    held, _ = load_log(tmp_path, good)
    assert held["psi"].iloc[:300].isna().all() and np.allclose(held["psi"].iloc[300:], yaw[300:])


@pytest.mark.parametrize("how", ["date-times", "durations", "index"])
def test_a_time_column_stored_otherwise_than_as_seconds_is_named_so(tmp_path, how):
    """A Parquet t of date-times or durations was advised "looks like nanoseconds (divide by
    1e9)"; a t stored as the file's index was "'t' is missing"."""
    t = np.arange(20) * 0.1
    df = pd.DataFrame({"t": t, "u": 0.1, "tau_X": 1.0})
    if how == "date-times":
        df["t"] = pd.to_datetime(t, unit="s", utc=True)
    elif how == "durations":
        df["t"] = pd.to_timedelta(t, unit="s")
    else:
        df = df.set_index("t")
    df.to_parquet(tmp_path / "log.parquet")
    said = "write it as a column" if how == "index" else "store seconds"
    with pytest.raises(NnidInputError, match=said):
        load_log(tmp_path / "log.parquet")


def test_a_source_in_integer_milliseconds_at_500_hz_is_refused_at_its_time_scale(tmp_path):
    """Milliseconds step by 2 at 500 Hz, under the 5 of the milliseconds rule: a 4-s run was
    read as a 2,000-s one at 0.5 Hz; now refused at the source's time_scale, which mends it."""
    n = 2000
    t = 1.7e12 + 2.0 * np.arange(n)
    f = np.sin(np.arange(n) * 0.01)
    pd.DataFrame({"t": t, "u": 0.1 * f, "f": f}).to_csv(tmp_path / "log.csv", index=False)
    body = '[[sources]]\nfile = "log.csv"\ntime = "t"\ncolumns = { u = "u", tau_X = "f" }\n'
    path = _write_map(tmp_path / "map.toml", body)
    with pytest.raises(NnidInputError, match="every step is a whole number: this looks like mil"):
        load_log(tmp_path, path)
    _write_map(path, body.replace('time = "t"', 'time = "t"\ntime_scale = 0.001'))
    log, _ = load_log(tmp_path, path)
    assert log["t"].iloc[-1] - log["t"].iloc[0] == pytest.approx(4.0, abs=0.01)


def test_a_parquet_of_runs_joined_without_a_fresh_index_is_read_on_row_numbers(tmp_path):
    """pd.read_parquet restores the index a frame was written with: two runs joined by
    pd.concat without ignore_index were read with labels 0..199 twice, and the split's parts
    found each run's rows by label, so a run's rows were both runs'. A file is read on fresh
    row numbers, as a CSV is."""
    from nnid.config import SplitSpec
    from nnid.datasets.preprocess import experiment_rows
    from nnid.pipeline import make_split

    t = np.arange(200) * 0.1
    run = pd.DataFrame({"t": t, "u": 0.1 * np.sin(t), "tau_X": np.sin(t)})
    pd.concat([run.assign(experiment="a"), run.assign(experiment="b")]).to_parquet(
        tmp_path / "two.parquet"
    )
    log, _ = load_log(tmp_path / "two.parquet")
    assert log.index.equals(pd.RangeIndex(400))
    split = make_split(log, SplitSpec(by="block", fractions=[0.7, 0.3, 0.0]))
    for part in (split.train, split.validation):
        for name, pos in experiment_rows(part):
            assert (part["experiment"].iloc[pos] == name).all()


def test_a_column_stored_as_a_parquet_files_index_is_refused_naming_it(tmp_path):
    """A frame indexed by its runs written to Parquet keeps 'experiment' as the file's index,
    which pandas reads back as the index, not a column: the runs were read as one. Refused
    naming the column, as t stored so is, never dropped with the old index."""
    t = np.arange(20) * 0.1
    log = pd.DataFrame({"t": np.r_[t, t], "experiment": ["a"] * 20 + ["b"] * 20, "u": 0.1,
                        "tau_X": 1.0})  # fmt: skip
    log.set_index("experiment").to_parquet(tmp_path / "log.parquet")
    with pytest.raises(NnidInputError, match="column 'experiment' is stored as the file's index"):
        load_log(tmp_path / "log.parquet")
    # a RangeIndex that only has a name is no stored column: read as the row numbers
    log.rename_axis("t").to_parquet(tmp_path / "named.parquet")
    assert load_log(tmp_path / "named.parquet")[0].index.equals(pd.RangeIndex(40))


def test_names_whose_numbers_are_equal_sort_the_same_whatever_order_they_come_in():
    """run1.csv and run01.csv were equal to the natural sort: their order (files of a
    pattern, runs of a log) was the order the file system listed them in, or a set's."""
    from nnid.datasets.readers import _natural

    names = ["run1.csv", "run10.csv", "run01.csv", "run2.csv", "run001.csv"]
    expected = ["run001.csv", "run01.csv", "run1.csv", "run2.csv", "run10.csv"]
    assert sorted(names, key=_natural) == expected
    assert sorted(reversed(names), key=_natural) == expected
