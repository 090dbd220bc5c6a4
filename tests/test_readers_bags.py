"""ROS 1 / ROS 2 bag reader: bags written here with rosbags, and the real LiU BlueROV bag."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.column_map import ColumnMap
from nnid.datasets.readers import load_log
from nnid.errors import NnidInputError

pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_typestore

T0_NS = 1_700_000_000 * 10**9
N = 100  # IMU and pose at 50 Hz
RECV_DELAY_NS = 5_000_000  # the recorder receives IMU and pose 5 ms after their stamps
ROLL, PITCH = 0.1, 0.05  # ENU/FLU attitude of the synthetic vehicle; yaw grows with k

SHARED_BAG = (
    Path(__file__).resolve().parents[1]
    / "../shared/data/liu-bluerov1-2016/raw_bags/all_3_2016-04-18-15-04-50.bag"
)

MAP = """
rate = 50.0

[[sources]]
file = "/imu/data"
time = "header.stamp"
frame = "enu_flu"
quaternion = ["orientation.w", "orientation.x", "orientation.y", "orientation.z"]
[sources.columns]
p = "angular_velocity.x"
q = "angular_velocity.y"
r = "angular_velocity.z"
du = "linear_acceleration.x"

[[sources]]
file = "/pose"
time = "header.stamp"
frame = "enu_flu"
[sources.columns]
x = "pose.position.x"
y = "pose.position.y"
z = { from = "pose.position.z", unit = "cm" }

[[sources]]
file = "/cmd"
time = "t_recv"
method = "hold"
[sources.columns]
cmd_1 = { from = "data.0", offset = -1500.0, scale = 0.0025 }
cmd_2 = "data.1"
"""


def _yaw(k: np.ndarray | int) -> np.ndarray:
    return 0.3 + 0.01 * np.asarray(k)


def _cmd_time_ns(j: int) -> int:
    # the first command at t0, the rest 10 ms off the 50 Hz grid (no ties for the hold)
    return T0_NS + j * 100_000_000 + (10_000_000 if j else 0)


def _quat_zyx(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


def _messages(ts, ros1: bool):
    """(topic, msgtype, receive time ns, message) of the synthetic run, in time order."""
    t = ts.types
    header_kw = {"seq": 0} if ros1 else {}

    def header(ns: int):
        stamp = t["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
        return t["std_msgs/msg/Header"](stamp=stamp, frame_id="base_link", **header_kw)

    vec, quat = t["geometry_msgs/msg/Vector3"], t["geometry_msgs/msg/Quaternion"]
    out = []
    for k in range(N):
        ns = T0_NS + k * 20_000_000
        w, x, y, z = _quat_zyx(ROLL, PITCH, float(_yaw(k)))
        imu = t["sensor_msgs/msg/Imu"](
            header=header(ns),
            orientation=quat(x=x, y=y, z=z, w=w),
            orientation_covariance=np.zeros(9),
            angular_velocity=vec(x=0.1 + 0.001 * k, y=0.2, z=-0.01 * k),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=vec(x=0.5 * k, y=0.0, z=9.81),
            linear_acceleration_covariance=np.zeros(9),
        )
        pose = t["geometry_msgs/msg/PoseStamped"](
            header=header(ns),
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=0.1 * k, y=2.0 - 0.05 * k, z=-300.0),
                orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
            ),
        )
        out.append(("/imu/data", "sensor_msgs/msg/Imu", ns + RECV_DELAY_NS, imu))
        out.append(("/pose", "geometry_msgs/msg/PoseStamped", ns + RECV_DELAY_NS, pose))
    layout = t["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    for j in range(N // 5):
        data = np.array([1500.0 + 40.0 * (j % 3), float(j)])
        cmd = t["std_msgs/msg/Float64MultiArray"](layout=layout, data=data)
        out.append(("/cmd", "std_msgs/msg/Float64MultiArray", _cmd_time_ns(j), cmd))
    return sorted(out, key=lambda m: m[2])


def write_ros1_bag(path: Path) -> Path:
    from rosbags.rosbag1 import Writer

    ts = get_typestore(Stores.ROS1_NOETIC)
    with Writer(path) as writer:
        conns = {}
        for topic, msgtype, ns, msg in _messages(ts, ros1=True):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], ns, ts.serialize_ros1(msg, msgtype))
    return path


def write_ros2_bag(path: Path, storage: str = "sqlite3") -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer

    ts = get_typestore(Stores.ROS2_HUMBLE)
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=9, storage_plugin=plugin) as writer:
        conns = {}
        for topic, msgtype, ns, msg in _messages(ts, ros1=False):
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=ts)
            writer.write(conns[topic], ns, ts.serialize_cdr(msg, msgtype))
    return path


@pytest.fixture
def column_map(tmp_path: Path) -> Path:
    path = tmp_path / "bag_map.toml"
    path.write_text(MAP)
    return path


def _expected(t: np.ndarray) -> dict[str, np.ndarray]:
    """The NED/FRD log the synthetic run should give on the 50 Hz grid ``t``."""
    k = np.round(t / 0.02)
    j = np.maximum(0, np.floor((t - 0.01) / 0.1)).astype(int)
    return {
        "phi": np.full_like(t, ROLL),
        "theta": np.full_like(t, -PITCH),
        "psi": np.pi / 2 - _yaw(k),
        "p": 0.1 + 0.001 * k,
        "q": np.full_like(t, -0.2),
        "r": 0.01 * k,
        "du": 0.5 * k,
        "x": 2.0 - 0.05 * k,  # north = ENU y
        "y": 0.1 * k,  # east = ENU x
        "z": np.full_like(t, 3.0),  # -(-300 cm)
        "cmd_1": 0.0025 * 40.0 * (j % 3),
        "cmd_2": j.astype(float),
    }


def _check_log(df: pd.DataFrame, experiment: str) -> None:
    assert set(df["experiment"]) == {experiment}
    t = df["t"].to_numpy()
    assert t[0] == 0.0
    # the grid is built on time relative to the start, so its spacing is exact
    np.testing.assert_allclose(np.diff(t), 0.02, atol=1e-12)  # grid built on relative time
    assert len(df) == N  # the 50 Hz window spans the 100 IMU samples
    for col, want in _expected(t).items():
        # stamps are ~1.7e9 s: their float rounding (~2e-7 s) times the slope bounds the error
        np.testing.assert_allclose(df[col].to_numpy(), want, atol=1e-5, err_msg=col)


def test_ros1_bag_values_units_frames_and_time_base(tmp_path: Path, column_map: Path) -> None:
    bag = write_ros1_bag(tmp_path / "dive_7.bag")
    df, report = load_log(bag, columns=column_map)
    _check_log(df, "dive_7")
    steps = [s.step for s in report.steps]
    assert steps.count("read") == 3 and "frame" in steps and "resample" in steps


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
def test_ros2_bag_folder_and_file(tmp_path: Path, column_map: Path, storage: str) -> None:
    bag = write_ros2_bag(tmp_path / "run_ros2", storage)
    df, _ = load_log(bag, columns=column_map)
    _check_log(df, "run_ros2")
    # the storage file alone is a bag too
    (file,) = bag.glob("*.db3" if storage == "sqlite3" else "*.mcap")
    df_file, _ = load_log(file, columns=column_map)
    _check_log(df_file, file.stem)


def test_flattening_receive_time_and_header_stamp(tmp_path: Path) -> None:
    from nnid.datasets.rosbag import read_bag_sources

    bag = write_ros1_bag(tmp_path / "stamps.bag")
    cmap = ColumnMap.model_validate(
        {
            "experiment": "header.frame_id",
            "sources": [
                {
                    "file": "/imu/data",
                    "time": "t_recv",
                    "columns": {
                        "stamp": "header.stamp",
                        "cov8": "orientation_covariance.8",
                        "ax": "linear_acceleration.x",
                    },
                }
            ],
        }
    )
    report = CleaningReport()
    ((_, table),) = read_bag_sources(bag, cmap, report)
    assert len(table) == N
    assert set(table["experiment"]) == {"base_link"}  # an experiment column from the message
    stamps = (T0_NS + np.arange(N) * 20_000_000) * 1e-9
    np.testing.assert_allclose(table["stamp"], stamps, rtol=0, atol=1e-6)
    np.testing.assert_allclose(table["t"] - table["stamp"], RECV_DELAY_NS * 1e-9, atol=1e-6)
    np.testing.assert_allclose(table["ax"], 0.5 * np.arange(N))
    assert (table["cov8"] == 0.0).all()
    assert any("/imu/data: 100 messages" in s.detail for s in report.steps)


def test_receive_times_on_a_nanosecond_epoch_keep_the_last_sample(tmp_path: Path) -> None:
    """The bag's own receive time (ns since the epoch, ~1.7e18) was made float64 before its
    division, rounded to 256 ns: the last of 27 messages 10 ms apart came 2.04 units of the
    seconds' last place short of its grid time, and the run lost it. Converted as a header's
    stamp is (whole seconds and nanoseconds, rounded once), it is on the grid."""
    from rosbags.rosbag1 import Writer

    first, n = 1700357253267554176, 27
    ts = get_typestore(Stores.ROS1_NOETIC)
    array = ts.types["std_msgs/msg/Float64MultiArray"]
    layout = ts.types["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    values = np.sqrt(np.arange(n, dtype=np.float64))  # not a straight line: interpolating shows
    with Writer(tmp_path / "epoch.bag") as writer:
        conn = writer.add_connection("/cmd", array.__msgtype__, typestore=ts)
        for k in range(n):
            msg = array(layout=layout, data=np.array([values[k], values[k]]))
            writer.write(conn, first + k * 10_000_000, ts.serialize_ros1(msg, array.__msgtype__))
    source = '[[sources]]\nfile = "/cmd"\ntime = "t_recv"\n'
    cmap = tmp_path / "map.toml"
    cmap.write_text(
        f'rate = 100.0\n{source}[sources.columns]\nz = "data.0"\n'
        f'{source}method = "hold"\n[sources.columns]\ncmd_1 = "data.1"\n'
    )
    df, _ = load_log(tmp_path / "epoch.bag", columns=cmap)
    assert len(df) == n
    assert df["z"].tolist() == values.tolist() and df["cmd_1"].tolist() == values.tolist()


def test_unknown_topic_names_bag_and_lists_topics(tmp_path: Path) -> None:
    from nnid.datasets.rosbag import read_bag_sources

    bag = write_ros1_bag(tmp_path / "topics.bag")
    cmap = ColumnMap.model_validate({"sources": [{"file": "/dvl/twist", "time": "t_recv"}]})
    with pytest.raises(NnidInputError) as err:
        read_bag_sources(bag, cmap, CleaningReport())
    msg = str(err.value)
    assert "topics.bag" in msg and "'/dvl/twist'" in msg
    assert "/imu/data" in msg and "/pose" in msg and "/cmd" in msg


def test_missing_field_names_topic(tmp_path: Path) -> None:
    from nnid.datasets.rosbag import read_bag_sources

    bag = write_ros1_bag(tmp_path / "fields.bag")
    cmap = ColumnMap.model_validate(
        {"sources": [{"file": "/pose", "time": "t_recv", "columns": {"x": "pose.position.q"}}]}
    )
    with pytest.raises(NnidInputError, match=r"fields\.bag:/pose.*'pose\.position\.q'"):
        read_bag_sources(bag, cmap, CleaningReport())


def test_a_type_without_a_definition_names_topic_and_type(tmp_path: Path) -> None:
    """A ROS 2 .db3 bag without message definitions (Foxy to Humble) of a type rosbags' store
    lacks (mavros_msgs): deserializing raised KeyError, said as "cannot be read as a ROS bag
    (KeyError: 'mavros_msgs/msg/RCOut')". It names the topic and the type."""
    import sqlite3

    from rosbags.rosbag2 import Writer
    from rosbags.typesys import get_types_from_msg

    from nnid.datasets.rosbag import read_bag_sources

    ts, rc = get_typestore(Stores.ROS2_HUMBLE), "mavros_msgs/msg/RCOut"
    ts.register(get_types_from_msg("std_msgs/Header header\nuint16[] channels", rc))
    t = ts.types
    bag = tmp_path / "rc"
    with Writer(bag, version=8) as writer:
        conn = writer.add_connection("/mavros/rc/out", rc, typestore=ts)
        for k in range(3):
            header = t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=k, nanosec=0), frame_id=""
            )
            msg = t[rc](header=header, channels=np.array([1500, 1600], dtype=np.uint16))
            writer.write(conn, k * 10**9, ts.serialize_cdr(msg, rc))
    for db in bag.glob("*.db3"):  # as a bag recorded before Iron: no definitions
        con = sqlite3.connect(db)
        con.execute("DELETE FROM message_definitions")
        con.commit()
        con.close()
    columns = {"cmd_1": "channels.0"}
    cmap = ColumnMap.model_validate(
        {"sources": [{"file": "/mavros/rc/out", "time": "t_recv", "columns": columns}]}
    )
    with pytest.raises(NnidInputError, match=rf"rc.*topic '/mavros/rc/out': type {rc} has no"):
        read_bag_sources(bag, cmap, CleaningReport())


@pytest.mark.parametrize("kind", ["ros1", "sqlite3", "mcap"])
def test_truncated_bag_is_a_clean_input_error(tmp_path: Path, column_map: Path, kind: str) -> None:
    if kind == "ros1":
        target = write_ros1_bag(tmp_path / "cut.bag")
        bag = target
    else:
        bag = write_ros2_bag(tmp_path / "cut", kind)
        (target,) = bag.glob("*.db3" if kind == "sqlite3" else "*.mcap")
    data = target.read_bytes()
    target.write_bytes(data[: len(data) // 2])
    with pytest.raises(NnidInputError, match="cannot be read as a ROS bag") as err:
        load_log(bag, columns=column_map)
    assert "cut" in str(err.value)


def test_garbage_bag_is_a_clean_input_error(tmp_path: Path, column_map: Path) -> None:
    bag = tmp_path / "noise.bag"
    bag.write_bytes(np.random.default_rng(1).bytes(4096))
    with pytest.raises(NnidInputError, match=r"noise\.bag.*cannot be read as a ROS bag"):
        load_log(bag, columns=column_map)


def test_bag_needs_a_column_map(tmp_path: Path) -> None:
    bag = write_ros1_bag(tmp_path / "plain.bag")
    with pytest.raises(NnidInputError, match=r"plain\.bag.*--columns"):
        load_log(bag)


def test_missing_ros_extra_says_how_to_install(
    tmp_path: Path, column_map: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    bag = write_ros1_bag(tmp_path / "noextra.bag")
    for name in [m for m in sys.modules if m == "rosbags" or m.startswith("rosbags.")]:
        monkeypatch.setitem(sys.modules, name, None)
    with pytest.raises(NnidInputError) as err:
        load_log(bag, columns=column_map)
    assert "reading ROS bags needs the 'ros' extra: pip install 'nnid[ros]'" in str(err.value)


# --- the real bag of the LiU BlueROV (2016) against the CSVs flattened from it -----------------

REAL_MAP = {
    "sources": [
        {
            "file": "/rovio/imu/data",
            "time": "t_recv",
            "columns": {
                "arduino_ms": "data.0",
                **{f"{s}_{a}": f"data.{1 + 3 * i + j}" for i, s in enumerate(["gyro", "acc"])
                   for j, a in enumerate("xyz")},
            },
        },
        {
            "file": "/rovio/thrusters",
            "time": "t_recv",
            "method": "hold",
            "columns": {f"pwm_{i}": f"data.{i - 1}" for i in range(1, 7)},
        },
    ]
}  # fmt: skip


@pytest.fixture
def shared_bag() -> Path:
    if not SHARED_BAG.is_file():
        pytest.skip(f"the shared LiU BlueROV data is absent ({SHARED_BAG.resolve()})")
    return SHARED_BAG


@pytest.mark.shared
def test_real_ros1_bag_matches_flattened_csvs(shared_bag: Path) -> None:
    from nnid.datasets.rosbag import read_bag_sources

    run = shared_bag.stem
    cmap = ColumnMap.model_validate(REAL_MAP)
    (_, imu), (_, thr) = read_bag_sources(shared_bag, cmap, CleaningReport())
    for table, csv in ((imu, "imu.csv.gz"), (thr, "thrusters.csv.gz")):
        ref = pd.read_csv(shared_bag.parent.parent / csv)
        ref = ref[ref["run"] == run].reset_index(drop=True)
        assert len(ref) > 50 and len(table) == len(ref), csv
        assert set(table["experiment"]) == {run}
        np.testing.assert_allclose(table["t"], ref["t_unix_s"], rtol=0, atol=2e-6, err_msg=csv)
        for col in [c for c in ref.columns if c not in ("run", "t_unix_s")]:
            np.testing.assert_allclose(
                table[col], ref[col], rtol=1e-6, atol=2e-6, err_msg=f"{csv}: {col}"
            )


@pytest.mark.shared
def test_real_ros1_bag_loads_as_a_contract_log(shared_bag: Path, tmp_path: Path) -> None:
    cmap = tmp_path / "liu_bag.toml"
    cmap.write_text(
        "rate = 50.0\n"
        '[[sources]]\nfile = "/rovio/imu/data"\ntime = "t_recv"\n'
        '[sources.columns]\np = "data.1"\nq = "data.2"\nr = "data.3"\n'
        '[[sources]]\nfile = "/rovio/thrusters"\ntime = "t_recv"\nmethod = "hold"\n'
        "[sources.columns]\n"
        + "".join(
            f'cmd_{i} = {{ from = "data.{i - 1}", offset = -1500.0, scale = 0.0025 }}\n'
            for i in range(1, 7)
        )
    )
    df, report = load_log(shared_bag, columns=cmap)
    assert set(df["experiment"]) == {shared_bag.stem}
    np.testing.assert_allclose(np.diff(df["t"]), 0.02, atol=1e-12)
    cmds = df[[f"cmd_{i}" for i in range(1, 7)]].to_numpy()
    assert np.abs(cmds).max() <= 1.0 and np.abs(cmds).max() > 0.5  # telegraph steps, ±220..±360 µs
    assert df[["p", "q", "r"]].abs().to_numpy().max() < 20.0  # rad/s, not deg/s
    assert report.rows_removed == 0
