"""ArduPilot / ArduSub reader: .tlog and dataflash .bin logs written here with pymavlink."""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.column_map import ColumnMap
from nnid.datasets.readers import load_log
from nnid.errors import NnidInputError

pytest.importorskip("pymavlink")
from pymavlink import DFReader

N = 100  # samples at 50 Hz
T_RECV0 = 1_700_000_000.0  # the ground station's clock at the first message (UNIX s)
BOOT0_MS = 60_000  # the autopilot has been up a minute


def _attitude(k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return 0.1 + 0.002 * k, -0.05 + 0.0 * k, 0.02 * k - 1.0


def _pwm(k: np.ndarray, channel: int) -> np.ndarray:
    return 1500 + 4 * channel * ((k // 10) % 3 - 1)


def write_tlog(path: Path, wire: int = 2) -> Path:
    """ATTITUDE and SERVO_OUTPUT_RAW at 50 Hz, each behind the 8-byte tlog receive stamp."""
    if wire == 2:
        from pymavlink.dialects.v20 import ardupilotmega as mavlink
    else:
        from pymavlink.dialects.v10 import ardupilotmega as mavlink
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    with path.open("wb") as f:
        for k in range(N):
            boot_ms = BOOT0_MS + 20 * k
            recv_us = round((T_RECV0 + 0.02 * k + 0.003) * 1e6)  # 3 ms link delay
            roll, pitch, yaw = (float(a) for a in _attitude(np.array(k)))
            msgs = [
                mavlink.MAVLink_attitude_message(boot_ms, roll, pitch, yaw, 0.3, -0.1, 0.01 * k),
                mavlink.MAVLink_servo_output_raw_message(
                    boot_ms * 1000, 0, *(int(_pwm(np.array(k), c)) for c in range(1, 9))
                ),
            ]
            for msg in msgs:
                f.write(struct.pack(">Q", recv_us) + msg.pack(mav))
    return path


_FMT = DFReader.DFFormat(0x80, "FMT", 89, "BBnNZ", "Type,Length,Name,Format,Columns")
_ATT = DFReader.DFFormat(
    0x81, "ATT", 0, "QccccCCCCB", "TimeUS,DesRoll,Roll,DesPitch,Pitch,DesYaw,Yaw,ErrRP,ErrYaw,AEKF"
)
_RCOU = DFReader.DFFormat(0x82, "RCOU", 0, "QHHHHHH", "TimeUS,C1,C2,C3,C4,C5,C6")
_IMU = DFReader.DFFormat(0x83, "IMU", 0, "QBffffff", "TimeUS,I,GyrX,GyrY,GyrZ,AccX,AccY,AccZ")
_FMTU = DFReader.DFFormat(0x84, "FMTU", 0, "QBNN", "TimeUS,FmtType,UnitIds,MultIds")


def _df(fmt: DFReader.DFFormat, *values) -> bytes:
    return struct.pack("BBB", 0xA3, 0x95, fmt.type) + struct.pack(fmt.msg_struct, *values)


def _df_format(fmt: DFReader.DFFormat) -> bytes:
    length = struct.calcsize(fmt.msg_struct) + 3
    names = ",".join(fmt.columns).encode()
    return _df(_FMT, fmt.type, length, fmt.name.encode(), fmt.format.encode(), names)


def write_bin(path: Path) -> Path:
    """A dataflash log as ArduSub writes it: FMT/FMTU, then ATT, RCOU and two IMUs at 50 Hz.

    ATT angles are centidegrees (format 'c'), which pymavlink turns into degrees.
    """
    with path.open("wb") as f:
        for fmt in (_FMT, _ATT, _RCOU, _IMU, _FMTU):
            f.write(_df_format(fmt))
        f.write(_df(_FMTU, 0, _IMU.type, b"s#EEEoo", b"F-00000"))  # '#': IMU.I is the instance
        for k in range(N):
            us = (BOOT0_MS + 20 * k) * 1000
            roll, pitch, yaw = (np.degrees(a) for a in _attitude(np.array(k)))
            f.write(_df(_ATT, us, 0, round(roll * 100), 0, round(pitch * 100), 0,
                        round((yaw % 360) * 100), 0, 0, 0))  # fmt: skip
            f.write(_df(_RCOU, us, *(int(_pwm(np.array(k), c)) for c in range(1, 7))))
            for i in (0, 1):
                f.write(_df(_IMU, us, i, 0.01 * k + i, 0.0, 0.0, 0.0, 0.0, -9.81))
    return path


TLOG_MAP = """
rate = 50.0
[[sources]]
file = "ATTITUDE"
time = "t_boot"
[sources.columns]
phi = "roll"
theta = "pitch"
psi = "yaw"
p = "rollspeed"
q = "pitchspeed"
r = "yawspeed"
[[sources]]
file = "SERVO_OUTPUT_RAW"
time = "t_boot"
method = "hold"
[sources.columns]
cmd_1 = { from = "servo1_raw", offset = -1500.0, scale = 0.0025 }
cmd_8 = { from = "servo8_raw", offset = -1500.0, scale = 0.0025 }
"""

BIN_MAP = """
rate = 50.0
[[sources]]
file = "ATT"
time = "TimeUS"
time_scale = 1e-6
[sources.columns]
phi = { from = "Roll", unit = "deg" }
theta = { from = "Pitch", unit = "deg" }
psi = { from = "Yaw", unit = "deg" }
[[sources]]
file = "IMU[1]"
time = "t_boot"
[sources.columns]
p = "GyrX"
q = "GyrY"
r = "GyrZ"
[[sources]]
file = "RCOU"
time = "t_boot"
method = "hold"
[sources.columns]
cmd_1 = { from = "C1", offset = -1500.0, scale = 0.0025 }
cmd_6 = { from = "C6", offset = -1500.0, scale = 0.0025 }
"""


def _map(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "ap_map.toml"
    path.write_text(text)
    return path


def _check_time_base(t: np.ndarray) -> np.ndarray:
    assert t[0] == 0.0
    np.testing.assert_allclose(np.diff(t), 0.02, atol=1e-9)
    return np.round(t / 0.02)


@pytest.mark.parametrize("wire", [1, 2])
def test_tlog_values_and_time_base(tmp_path: Path, wire: int) -> None:
    log = write_tlog(tmp_path / f"dive_{wire}.tlog", wire)
    df, report = load_log(log, columns=_map(tmp_path, TLOG_MAP))
    assert set(df["experiment"]) == {f"dive_{wire}"}
    assert len(df) == N
    k = _check_time_base(df["t"].to_numpy())
    roll, pitch, yaw = _attitude(k)
    np.testing.assert_allclose(df["phi"], roll, atol=1e-6)
    np.testing.assert_allclose(df["theta"], pitch, atol=1e-6)
    np.testing.assert_allclose(df["psi"], yaw, atol=1e-6)
    np.testing.assert_allclose(df["r"], 0.01 * k, atol=1e-6)
    np.testing.assert_allclose(df["cmd_1"], (_pwm(k, 1) - 1500) * 0.0025)
    np.testing.assert_allclose(df["cmd_8"], (_pwm(k, 8) - 1500) * 0.0025)
    assert any("ATTITUDE: 100 messages" in s.detail for s in report.steps)


def test_tlog_columns_receive_time_and_sender(tmp_path: Path) -> None:
    from nnid.datasets.ardupilot import read_ardupilot_sources

    log = write_tlog(tmp_path / "stamps.tlog")
    cmap = ColumnMap.model_validate(
        {
            "sources": [
                {
                    "file": "SERVO_OUTPUT_RAW",
                    "time": "t_recv",
                    "columns": {"boot": "t_boot", "sys": "src_system", "s3": "servo3_raw"},
                }
            ]
        }
    )
    ((_, table),) = read_ardupilot_sources(log, cmap, CleaningReport())
    k = np.arange(N)
    np.testing.assert_allclose(table["t"], T_RECV0 + 0.02 * k + 0.003, rtol=0, atol=2e-6)
    # SERVO_OUTPUT_RAW carries time_usec since boot: t_boot is on the ATTITUDE clock
    np.testing.assert_allclose(table["boot"], BOOT0_MS * 1e-3 + 0.02 * k, atol=1e-9)
    assert (table["sys"] == 1).all()
    np.testing.assert_array_equal(table["s3"], _pwm(k, 3))


def test_tlog_message_type_of_two_senders_is_refused_naming_them(tmp_path: Path) -> None:
    """ATTITUDE from two systems on one link was interleaved into one source, the second
    vehicle's samples read between the first's. Refused, naming each sender."""
    from pymavlink.dialects.v20 import ardupilotmega as mavlink

    senders = [mavlink.MAVLink(None, srcSystem=s, srcComponent=1) for s in (1, 2)]
    log = tmp_path / "two.tlog"
    with log.open("wb") as f:
        for k in range(N):
            boot = BOOT0_MS + 20 * k
            for j, mav in enumerate(senders):
                msg = mavlink.MAVLink_attitude_message(boot + 10 * j, 0.1 + j, 0, 0, 0, 0, 0)
                recv = round((T_RECV0 + 0.02 * k + 0.01 * j) * 1e6)
                f.write(struct.pack(">Q", recv) + msg.pack(mav))
            msg = mavlink.MAVLink_servo_output_raw_message(boot * 1000, 0, *([1500] * 8))
            f.write(struct.pack(">Q", round((T_RECV0 + 0.02 * k) * 1e6)) + msg.pack(senders[0]))
    with pytest.raises(NnidInputError) as err:
        load_log(log, columns=_map(tmp_path, TLOG_MAP))
    said = str(err.value)
    assert "two.tlog" in said and "'ATTITUDE' comes from 2 senders" in said
    assert f"1/1 ({N} messages), 2/1 ({N} messages)" in said


def test_bin_values_units_instances_and_time_base(tmp_path: Path) -> None:
    log = write_bin(tmp_path / "00000042.BIN".lower())
    df, _ = load_log(log, columns=_map(tmp_path, BIN_MAP))
    assert set(df["experiment"]) == {"00000042"}
    assert len(df) == N
    k = _check_time_base(df["t"].to_numpy())
    roll, pitch, yaw = _attitude(k)
    np.testing.assert_allclose(df["phi"], roll, atol=2e-4)  # centidegree resolution
    np.testing.assert_allclose(df["theta"], pitch, atol=2e-4)
    np.testing.assert_allclose(np.angle(np.exp(1j * (df["psi"] - yaw))), 0.0, atol=2e-4)
    np.testing.assert_allclose(df["p"], 0.01 * k + 1.0, atol=1e-6)  # IMU[1], not IMU[0]
    np.testing.assert_allclose(df["cmd_6"], (_pwm(k, 6) - 1500) * 0.0025)


def test_bin_several_instances_must_be_named(tmp_path: Path) -> None:
    from nnid.datasets.ardupilot import read_ardupilot_sources

    log = write_bin(tmp_path / "inst.bin")
    cmap = ColumnMap.model_validate({"sources": [{"file": "IMU", "time": "t_boot"}]})
    with pytest.raises(NnidInputError, match=r"inst\.bin.*'IMU' has several instances \(0, 1\)"):
        read_ardupilot_sources(log, cmap, CleaningReport())
    cmap = ColumnMap.model_validate({"sources": [{"file": "IMU[2]", "time": "t_boot"}]})
    with pytest.raises(NnidInputError, match=r"'IMU' has no instance 2; its instances are 0, 1"):
        read_ardupilot_sources(log, cmap, CleaningReport())


@pytest.mark.parametrize(
    ("name", "writer", "missing", "present"),
    [
        ("types.tlog", write_tlog, "SCALED_PRESSURE", ["ATTITUDE", "SERVO_OUTPUT_RAW"]),
        ("types.bin", write_bin, "BARO", ["ATT", "IMU", "RCOU"]),
    ],
)
def test_unknown_message_type_lists_types(tmp_path: Path, name, writer, missing, present) -> None:
    from nnid.datasets.ardupilot import read_ardupilot_sources

    log = writer(tmp_path / name)
    cmap = ColumnMap.model_validate({"sources": [{"file": missing, "time": "t_boot"}]})
    with pytest.raises(NnidInputError) as err:
        read_ardupilot_sources(log, cmap, CleaningReport())
    msg = str(err.value)
    assert name in msg and f"'{missing}'" in msg
    assert all(p in msg for p in present)


@pytest.mark.parametrize(
    ("name", "writer", "text"),
    [("cut.tlog", write_tlog, TLOG_MAP), ("cut.bin", write_bin, BIN_MAP)],
)
def test_truncated_logs(tmp_path: Path, name, writer, text) -> None:
    log = writer(tmp_path / name)
    data = log.read_bytes()
    columns = _map(tmp_path, text)
    # cut inside the first messages: nothing usable, a clean error naming the file
    for cut in (0, 5, 30):
        log.write_bytes(data[:cut])
        with pytest.raises(NnidInputError, match=rf"{name}.*(empty|truncated)"):
            load_log(log, columns=columns)
    # cut in the middle of a message: the complete messages before it are read
    log.write_bytes(data[: len(data) // 2 + 7])
    df, _ = load_log(log, columns=columns)
    assert N // 2 - 3 <= len(df) < N // 2 + 1
    k = _check_time_base(df["t"].to_numpy())
    np.testing.assert_allclose(df["phi"], _attitude(k)[0], atol=2e-4)


def test_corrupt_bin_is_read_around_and_reported(tmp_path: Path) -> None:
    log = write_bin(tmp_path / "noisy.bin")
    data = log.read_bytes()
    log.write_bytes(data[:4000] + np.random.default_rng(3).bytes(600) + data[4000:])
    df, report = load_log(log, columns=_map(tmp_path, BIN_MAP))
    assert len(df) > N // 2
    assert any(s.step == "reader warnings" and "noisy.bin" in s.detail for s in report.steps)


def test_garbage_log_is_a_clean_input_error(tmp_path: Path) -> None:
    log = tmp_path / "noise.bin"
    log.write_bytes(np.random.default_rng(1).bytes(3000))
    with pytest.raises(NnidInputError, match=r"noise\.bin"):
        load_log(log, columns=_map(tmp_path, BIN_MAP))


def test_ardupilot_log_needs_a_column_map(tmp_path: Path) -> None:
    log = write_tlog(tmp_path / "plain.tlog")
    with pytest.raises(NnidInputError, match=r"plain\.tlog.*--columns"):
        load_log(log)


def test_missing_ardupilot_extra_says_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    log = write_tlog(tmp_path / "noextra.tlog")
    for name in [m for m in sys.modules if m == "pymavlink" or m.startswith("pymavlink.")]:
        monkeypatch.setitem(sys.modules, name, None)
    with pytest.raises(NnidInputError) as err:
        load_log(log, columns=_map(tmp_path, TLOG_MAP))
    msg = str(err.value)
    assert "reading ArduPilot logs needs the 'ardupilot' extra" in msg
    assert "pip install 'nnid[ardupilot]'" in msg


def test_a_reboot_is_no_uint32_wrap_of_a_since_boot_clock() -> None:
    """time_usec since boot (uint32 µs) wraps every 71.6 min: any drop over 2^31 µs was read
    as a wrap, so a reboot after 40 min of uptime put the new boot's samples 71.6 min on.
    A wrap is a step from near 2^32 to a small value, a typical step across."""
    import pandas as pd

    from nnid.datasets.ardupilot import _boot_time

    step = 20_000.0
    before = 2.0**32 - 3 * step + step * np.arange(3)
    wrapped = _boot_time(pd.DataFrame({"time_usec": np.r_[before, 5_000.0, 25_000.0]}))
    np.testing.assert_allclose(np.diff(wrapped), np.r_[step, step, step + 5_000, step] * 1e-6)
    uptime = 40 * 60e6 + step * np.arange(3)
    rebooted = _boot_time(pd.DataFrame({"time_usec": np.r_[uptime, 1_000.0, 21_000.0]}))
    assert rebooted.iloc[-1] == pytest.approx(0.021)
