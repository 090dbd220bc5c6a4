"""A corpus of malformed input through every command of the CLI.

Each case writes one broken file (a log, a vehicle file, a config, an output path, a model
folder) and runs the command in-process. Every case must end in exit code 2 with exactly one
``error:`` line that names the file and the field, column or row, and no traceback: meaningless
input is never accepted and never crashes.
"""

from __future__ import annotations

import functools
import json
import os
import re
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from nnid.cli import app

REPO = Path(__file__).resolve().parents[1]
MINIROV = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))
OCTO = str(REPO / "configs" / "vehicles" / "octorov_sim.toml")
TRAIN = str(REPO / "configs" / "fossen_ls.toml")
COMPARE = str(REPO / "configs" / "seamor_families.toml")


def _demo_log() -> pd.DataFrame:
    root = resources.files("nnid.demo_data")
    log = pd.read_parquet(root.joinpath("demo_minirov_heave.parquet"))
    # three short runs: the refusals come before any fit, so a small log is enough
    log = log[log["experiment"].isin(["run0", "run1", "run2"])]
    return log.groupby("experiment").head(300).reset_index(drop=True)


def _parquet_indexed(df: pd.DataFrame) -> bytes:
    """The log written by pandas with its run labels as the index."""
    import io

    buf = io.BytesIO()
    df.set_index("experiment").to_parquet(buf)
    return buf.getvalue()


# -- log mutations: (name, what the error must name, mutate(df, input column) -> df | bytes) ----
def _set(col: str, row: int, value):
    def mutate(df: pd.DataFrame, inp: str) -> pd.DataFrame:
        name = inp if col == "INPUT" else col
        out = df.astype({name: object})
        out.loc[row, name] = value
        return out

    return mutate


def _parquet_naming_u_twice(df: pd.DataFrame) -> bytes:
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    names = ["u" if c == "v" else c for c in df.columns]
    table = pa.Table.from_arrays([pa.array(df[c]) for c in df.columns], names=names)
    buf = io.BytesIO()
    pq.write_table(table, buf)
    return buf.getvalue()


def _decimal_point_at_row_49(df: pd.DataFrame) -> bytes:
    """The log as a European locale writes it (';' and decimal commas), but for one velocity
    written with a decimal point in data row 49 (the file's line 51)."""
    lines = df.to_csv(index=False, sep=";", decimal=",").split("\n")
    cells = lines[50].split(";")
    cells[list(df.columns).index("u")] = "2.45"
    lines[50] = ";".join(cells)
    return "\n".join(lines).encode()


def _latin1_row(df: pd.DataFrame) -> bytes:
    """The log as a logger on a Latin-1 locale writes it: a degree sign in row 30's label."""
    lines = df.to_csv(index=False).split("\n")
    lines[31] = lines[31].replace(",", ",\u00b0", 1)
    return "\n".join(lines).encode("latin-1")


LOG_CASES: list[tuple[str, str, Callable]] = [
    ("no time column", "'t'", lambda df, i: df.drop(columns="t")),
    ("text in time", "'t'", _set("t", 5, "noon")),
    ("empty time cell", "'t'", _set("t", 7, np.nan)),
    ("infinite time", "'t'", _set("t", 9, np.inf)),
    (
        "duplicated time",
        "'t'",
        lambda df, i: df.assign(t=df["t"].where(df.index != 11, df["t"][10])),
    ),
    ("decreasing time", "'t'", lambda df, i: df.assign(t=df["t"].where(df.index != 12, -1.0))),
    ("time in milliseconds", "'t'", lambda df, i: df.assign(t=(df["t"] * 1000).round())),
    # milliseconds computed in floating point: whole numbers but for the last bits
    ("time in float milliseconds", "'t'", lambda df, i: df.assign(t=df["t"] * 1000 + 1e-9)),
    ("time in nanoseconds", "'t'", lambda df, i: df.assign(t=(df["t"] * 1e9).round())),
    # 20 Hz in microseconds steps by 50000: read as seconds, a fit ran for minutes on it
    ("time in microseconds", "'t'", lambda df, i: df.assign(t=(df["t"] * 1e6).round())),
    # a logger's milliseconds with jitter: not whole numbers, still not seconds
    (
        "time in jittered milliseconds",
        "'t'",
        lambda df, i: df.assign(t=(df["t"] * 1000 + 0.3 * np.sin(np.arange(len(df)))).round(3)),
    ),
    # 20 Hz in hours steps by 1.4e-5: refused as a warmup_s or savgol_window too long
    ("time in hours", "'t'", lambda df, i: df.assign(t=df["t"] / 3600)),
    # a contract column but for case or spaces: kept as an unknown column, phi then missing
    ("an angle named in capitals", "'PHI'", lambda df, i: df.rename(columns={"phi": "PHI"})),
    ("an input name with a space", "INPUT", lambda df, i: df.rename(columns={i: f" {i}"})),
    ("empty experiment label", "'experiment'", _set("experiment", 20, np.nan)),
    ("blank experiment label", "'experiment'", _set("experiment", 21, " ")),
    # a control character in a run's label: a line break split every report line naming it
    (
        "a line break in an experiment label",
        "column 'experiment', row 0: experiment label 'dive\\n1'",
        lambda df, i: df.assign(
            experiment=df["experiment"].replace(df["experiment"][0], "dive\n1")
        ),
    ),
    (
        "a tab in an experiment label",
        "column 'experiment', row 0: experiment label 'dive\\t1'",
        lambda df, i: df.assign(
            experiment=df["experiment"].replace(df["experiment"][0], "dive\t1")
        ),
    ),
    # a stray label makes an experiment of one sample: no sample period to derive or fit with
    ("a one-sample experiment", "'experiment'", _set("experiment", 22, "stray")),
    ("text in an input", "INPUT", _set("INPUT", 30, "full")),
    ("infinite input", "INPUT", _set("INPUT", 31, np.inf)),
    ("empty input cell", "INPUT", _set("INPUT", 32, np.nan)),
    ("text in a velocity", "'u'", _set("u", 40, "fast")),
    ("infinite velocity", "'u'", _set("u", 41, -np.inf)),
    ("a corrupt velocity sample", "'u'", _set("u", 42, 1e30)),
    ("velocity column all empty", "'u'", lambda df, i: df.assign(u=np.nan)),
    # one spike in the pose or a logged acceleration: as bounded as a velocity or a force
    ("a corrupt angle sample", "'phi'", _set("phi", 43, 1e30)),
    ("a corrupt depth sample", "'z'", _set("z", 44, -1e30)),
    (
        "a corrupt acceleration sample",
        "'du'",
        lambda df, i: df.assign(du=0.0).pipe(
            lambda d: d.assign(du=d["du"].where(d.index != 45, 1e300))
        ),
    ),
    ("angle in degrees", "'psi'", lambda df, i: df.assign(psi=np.degrees(df["psi"]) + 200)),
    # a length unit slip under every bound: 12 cm/s logged as 12 m/s was fitted as it stood
    (
        "velocities in cm per s",
        "'w'",
        lambda df, i: df.assign(**{c: df[c] * 100 for c in ("u", "v", "w")}),
    ),
    ("depth in cm", "'z'", lambda df, i: df.assign(z=df["z"] * 100)),
    # a height (positive up) where the depth belongs: read as a vehicle that climbs as it dives
    ("height for the depth", "'z'", lambda df, i: df.assign(z=-df["z"])),
    ("text in an angle", "'phi'", _set("phi", 50, "level")),
    (
        "no motion columns",
        "motion",
        lambda df, i: df[["t", *[c for c in df if c.startswith(("tau_", "cmd_"))]]],
    ),
    (
        "no input columns",
        "input",
        lambda df, i: df.drop(columns=[c for c in df if c.startswith(("tau_", "cmd_"))]),
    ),
    ("header only", "no rows", lambda df, i: df.iloc[:0]),
    (
        "a column named twice",
        "'u'",
        lambda df, i: df.to_csv(index=False).replace(",v,", ",u,", 1).encode(),
    ),
    # pyarrow's error was a 25-line schema dump
    ("a parquet column named twice", "'u'", lambda df, i: _parquet_naming_u_twice(df)),
    # pandas reads a column written as the index back as the index: the runs were read as one
    ("runs stored as the parquet's index", "'experiment'", lambda df, i: _parquet_indexed(df)),
    # a parquet column of strings: every number readable, every later step meets text
    ("numbers stored as text", "'u'", lambda df, i: df.assign(u=df["u"].astype(str))),
    # a parquet column of booleans: read as 1 or 0 newtons without a word
    ("an input stored as booleans", "INPUT", lambda df, i: df.assign(**{i: df[i] > 0})),
    ("empty file", "", lambda df, i: b""),
    ("binary garbage", "", lambda df, i: bytes(range(256)) * 8),
    ("one garbled line", "", lambda df, i: b"t,u\n0.0,1,2,3,4\n"),
    # --follow read it as text: a UnicodeDecodeError traceback
    ("a Latin-1 character", "UTF-8", lambda df, i: _latin1_row(df)),
    # kept as an unknown column, and u said missing beside the column that holds it
    (
        "a unit after a column's name",
        "'u [m/s]'",
        lambda df, i: df.rename(columns={"u": "u [m/s]"}),
    ),
    # the column was read as text and refused at row 0, "399 such rows", not at the cell
    (
        "a decimal point among decimal commas",
        "column 'u', row 49",
        lambda df, i: _decimal_point_at_row_49(df),
    ),
    # read as the header: "required column 't' is missing", without a word of the line read
    (
        "a comment line above the header",
        "line 1 ('# logged by rov1')",
        lambda df, i: ("# logged by rov1\n" + df.to_csv(index=False)).encode(),
    ),
]
LOG_SUFFIX = {
    "empty file": ".csv",
    "binary garbage": ".parquet",
    "numbers stored as text": ".parquet",
    "an input stored as booleans": ".parquet",
    "an input name with a space": ".parquet",  # a CSV header's spaces are stripped on reading
    "a parquet column named twice": ".parquet",
    "runs stored as the parquet's index": ".parquet",
}


@dataclass
class Case:
    id: str
    args: Callable[[Path, dict], list[str]]
    names: tuple[str, ...]  # what the error line must contain (the file first)


def _write_log(tmp: Path, name: str, content) -> Path:
    path = tmp / f"{name.replace(' ', '_')}{LOG_SUFFIX.get(name, '.csv')}"
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif path.suffix == ".parquet":
        content.to_parquet(path, index=False)
    else:
        content.to_csv(path, index=False)
    return path


SIMULATE = str(REPO / "configs" / "seamor_sequence.toml")


def _command(command: str, tmp: Path, fx: dict, *, data=None, vehicle=MINIROV, out=None,
             config=None, model=None) -> list[str]:  # fmt: skip
    """The arguments of ``command`` with good inputs except those given."""
    target = str(out if out is not None else fx["out"])
    if command == "demo":
        return ["demo", "--out", target]
    if command == "simulate":
        return ["simulate", config or SIMULATE, "--vehicle", str(vehicle), "--out", target]
    if command == "detect":
        data = data or _write_log(tmp, "octo", fx["octo_log"])
        model = model or fx["monitor"]
        return ["detect", "--model", str(model), "--data", str(data), "--out", target]
    data = str(data or _write_log(tmp, "good", fx["demo_log"]))
    if command == "inspect":
        return ["inspect", data, *(["--out", target] if out is not None else [])]
    config = str(config or {"train": TRAIN, "compare": COMPARE, "loop": ""}[command])
    return [command, *([config] if config else []), "--data", data, "--vehicle", str(vehicle),
            "--out", target]  # fmt: skip


NARX_TRAIN = (
    'kind = "train"\n[split]\nby = "experiment"\nvalidation = ["run2"]\n'
    '[model]\nkind = "narx"\ninputs = ["tau_Z"]\noutputs = ["w"]\n'
)


def _narx_on_a_rate_change(tmp: Path, log: pd.DataFrame) -> tuple[Path, Path]:
    """A NARX config and the demo log with run1 at 20 Hz, then 100 Hz."""
    run = log[log["experiment"] == "run1"]
    fast = pd.DataFrame({c: np.repeat(run[c].to_numpy()[150:], 5) for c in run}).assign(
        t=lambda d: run["t"].iloc[150] + 0.01 * np.arange(len(d))
    )
    log = pd.concat([log[log["experiment"] != "run1"], run.iloc[:150], fast])
    config = tmp / "narx.toml"
    config.write_text(NARX_TRAIN)
    return config, _write_log(tmp, "rate change", log)


def _log_cases() -> list[Case]:
    cases = []
    for command in ("inspect", "loop", "train", "compare", "detect"):
        for name, field, _ in LOG_CASES:

            def args(tmp, fx, name=name, command=command):
                base = fx["octo_log"] if command == "detect" else fx["demo_log"]
                inp = next(c for c in base if c.startswith(("tau_", "cmd_")))
                mutate = {n: m for n, _, m in LOG_CASES}[name]
                return _command(command, tmp, fx, data=_write_log(tmp, name, mutate(base, inp)))

            cases.append(Case(f"{command}: {name}", args, ("LOG", field)))

    def short(tmp, fx):  # one 3 s run: its held-out part is shorter than the warm-up
        log = fx["demo_log"][fx["demo_log"]["experiment"] == "run0"].head(60)
        return _command("loop", tmp, fx, data=_write_log(tmp, "too short", log))

    cases.append(Case("loop: too short for the warm-up", short, ("LOG", "warmup_s")))

    def no_u(tmp, fx):  # no u and no x, y, z to derive it: read as zero it was fitted as rest
        log = fx["demo_log"].drop(columns=["u"])
        return _command("train", tmp, fx, data=_write_log(tmp, "no u", log))

    cases.append(Case("train: a velocity neither logged nor derivable", no_u, ("LOG", "'u'")))

    def no_u_sindy(tmp, fx):  # SINDy's library reads every velocity: said against the log too
        config = tmp / "sindy.toml"
        config.write_text('kind = "train"\n[split]\nby = "experiment"\n[model]\nkind = "sindy"\n')
        log = fx["demo_log"].drop(columns=["u"])
        return _command("train", tmp, fx, data=_write_log(tmp, "no u", log), config=config)

    cases.append(Case("train: SINDy without a velocity", no_u_sindy, ("LOG", "'u'", "all six")))

    def no_attitude(command: str):  # rolling (p) with no phi: read as level, the restoring
        # moments of the octorov were wrong, K_pdot came out +0.49, and detect alarmed
        def args(tmp, fx):
            # the fixture's autopilot holds roll within 0.02 rad: one that rolls ±0.3 rad
            log = fx["octo_log"].drop(columns=["phi", "theta"])
            log["p"] += 0.3 * np.cos(log["t"])
            data = _write_log(tmp, "no attitude", log)
            return _command(command, tmp, fx, data=data, vehicle=OCTO)

        return args

    for command in ("train", "detect", "loop"):
        cases.append(Case(f"{command}: rolling with no attitude", no_attitude(command),
                          ("LOG", "'phi'", "restoring")))  # fmt: skip

    def in_bursts(tmp, fx, command, follow=False):  # an IMU's stamps: five samples 10 us
        # apart every 0.25 s (20 Hz over the run); every model, and the monitor, steps at a
        # run's typical step, one inside a burst (detect watched pairs of them, exit 0)
        detecting = command == "detect"
        log = fx["octo_log" if detecting else "demo_log"].copy()
        rows = (log["experiment"] == ("h2" if detecting else "run1")).to_numpy()
        k = np.arange(int(rows.sum()))
        log.loc[rows, "t"] = 0.25 * (k // 5) + 1e-5 * (k % 5)
        config = None
        if command == "compare":  # the shipped one names the Seamor runs, refused before
            config = tmp / "compare.toml"
            config.write_text('kind = "compare"\n[[models]]\nkind = "fossen"\n')
        data = _write_log(tmp, "in bursts", log)
        args = _command(command, tmp, fx, data=data, config=config)
        return [*args, "--follow"] if follow else args

    for command, follow in (("train", False), ("compare", False), ("loop", False),
                            ("detect", False), ("detect", True)):  # fmt: skip
        run = "h2" if command == "detect" else "run1"
        cases.append(
            Case(
                f"{command}{' --follow' if follow else ''}: a run whose stamps come in bursts",
                functools.partial(in_bursts, command=command, follow=follow),
                ("LOG", "'t'", f"experiment '{run}': its stamps come in bursts"),
            )
        )

    def rate_change(tmp, fx):  # a NARX counts delays in samples: 20 Hz, then 100 Hz in run1
        config, data = _narx_on_a_rate_change(tmp, fx["demo_log"])
        return _command("train", tmp, fx, data=data, config=config)

    cases.append(Case("train: a NARX on a run whose rate changes", rate_change, ("LOG", "'t'")))

    def huge_effect(tmp, fx):  # an injected effect no vehicle survives: named, not a traceback
        path = tmp / "huge_effect.toml"
        text = (
            Path(SIMULATE)
            .read_text()
            .replace(
                "seed = 0\n", 'seed = 0\neffects = [{ name = "buoyancy_offset", value = 1e9 }]\n', 1
            )
        )
        path.write_text(text)
        return _command("simulate", tmp, fx, config=str(path), out=tmp / "sim.csv")

    cases.append(
        Case(
            "simulate: an effect too large for the vehicle",
            huge_effect,
            ("CONFIG", "buoyancy_offset", "buoyancy"),
        )
    )

    one_run = '[[experiments]]\nname = "%s"\nduration = 1.0\n%s\n[sequence]'
    simulate_cases = {  # the config named, with the field or the experiment
        "negative seed": ("seed", ("seed = 0\n", "seed = -1\n")),
        # the log the run would write was refused, blamed on the --out file (not written)
        "an initial depth of 1e300 m": (
            "experiments.0.x0",
            ("[sequence]", one_run % ("e1", "x0 = [0, 0, 1e300, 0, 0, 0]\n")),
        ),
        "a position noise of 1e300 m": (
            "measurement.position_noise",
            ("position_noise = 0.001", "position_noise = 1e300"),
        ),
        # a line break in a label splits every line naming the run
        "an experiment name on two lines": (
            "experiments.0.name",
            ("[sequence]", one_run % ("dive\\n1", "")),
        ),
        "an experiment named twice": (
            "used twice",
            (
                "[sequence]",
                '[[experiments]]\nname = "e1"\nduration = 1.0\n[[experiments]]\n'
                'name = "e1"\nduration = 1.0\n\n[sequence]',
            ),
        ),
    }
    for name, (field, change) in simulate_cases.items():

        def sim(tmp, fx, name=name, change=change):
            path = tmp / f"{name.replace(' ', '_')}.toml"
            path.write_text(Path(SIMULATE).read_text().replace(*change, 1))
            return _command("simulate", tmp, fx, config=str(path), out=tmp / "sim.csv")

        cases.append(Case(f"simulate: {name}", sim, ("CONFIG", field)))

    # --follow reads row by row, not through the log reader: the row checks it repeats, with
    # the same column and row numbers
    follow_cases = ("text in time", "duplicated time", "decreasing time", "text in a velocity",
                    "infinite input", "empty input cell", "velocities in cm per s",
                    "a Latin-1 character", "a tab in an experiment label")  # fmt: skip
    for name in follow_cases:

        def followed(tmp, fx, name=name):
            base = fx["octo_log"]
            inp = next(c for c in base if c.startswith("cmd_"))
            mutate = {n: m for n, _, m in LOG_CASES}[name]
            data = _write_log(tmp, name, mutate(base, inp))
            return [*_command("detect", tmp, fx, data=data), "--follow"]

        field = {n: f for n, f, _ in LOG_CASES}[name]
        cases.append(Case(f"detect --follow: {name}", followed, ("LOG", field, "row ")))

    def quoted_break_followed(tmp, fx):  # "dive<newline>1" quoted: its halves were said as rows
        # of too few fields "(a decimal comma, or a cell with a comma in it?)"
        log = fx["octo_log"].assign(experiment="dive\n1")
        return [*_command("detect", tmp, fx, data=_write_log(tmp, "quoted", log)), "--follow"]

    cases.append(
        Case(
            "detect --follow: a line break inside a quoted experiment label",
            quoted_break_followed,
            ("LOG", "column 'experiment', row 0", "line break inside quotes"),
        )
    )

    def table_label(tmp, fx, label):  # a generic table's rows of no run: taken without a word
        config = tmp / "narx_table.toml"
        config.write_text(NARX_TRAIN.replace("[split]", '[data]\nkind = "table"\n\n[split]'))
        log = fx["demo_log"].astype({"experiment": object})
        log.loc[20:21, "experiment"] = label
        return _command("train", tmp, fx, data=_write_log(tmp, "table", log), config=config)

    for label, said in (
        (np.nan, "empty experiment label"),
        (" ", "empty experiment label"),
        ("dive\u20281", "one line"),
    ):
        cases.append(
            Case(
                f"train: a generic table's experiment label {label!r}",
                functools.partial(table_label, label=label),
                ("LOG", "column 'experiment', row 20", said),
            )
        )

    def parquet_followed(tmp, fx):  # read as text, row by row: a UnicodeDecodeError traceback
        path = tmp / "octo.parquet"
        fx["octo_log"].to_parquet(path, index=False)
        return [*_command("detect", tmp, fx, data=path), "--follow"]

    cases.append(Case("detect --follow: a Parquet log", parquet_followed, ("LOG", "--follow")))

    def stray_command(tmp, fx, command, follow=False):  # a thruster the vehicle does not have
        log = fx["octo_log"].assign(cmd_v5=0.0)
        data = _write_log(tmp, "stray command", log)
        vehicle = {} if command == "detect" else {"vehicle": OCTO}
        args = _command(command, tmp, fx, data=data, **vehicle)
        return [*args, "--follow"] if follow else args

    for command, follow in (("detect", False), ("detect", True), ("loop", False), ("train", False)):
        cases.append(
            Case(
                f"{command}{' --follow' if follow else ''}: a command no thruster takes",
                functools.partial(stray_command, command=command, follow=follow),
                ("LOG", "cmd_v5", "no thruster"),
            )
        )

    def stray_command_beside_forces(tmp, fx, command):  # the forces drive; cmd_* is read by none
        log = fx["demo_log"].assign(cmd_foo=0.0)
        return _command(command, tmp, fx, data=_write_log(tmp, "stray command forces", log))

    for command in ("loop", "train"):
        cases.append(
            Case(
                f"{command}: a command beside the six forces, on a vehicle without thrusters",
                functools.partial(stray_command_beside_forces, command=command),
                ("LOG", "cmd_foo", "no thrusters"),
            )
        )

    def two_samples(tmp, fx):  # the split leaves one sample in a part
        log = fx["demo_log"].head(2)
        return _command("train", tmp, fx, data=_write_log(tmp, "two samples", log))

    cases.append(
        Case("train: a log too short for the split", two_samples, ("CONFIG", "split", "single"))
    )

    # the minirov has no thrusters, so no commands: cmd_X … cmd_N are not its inputs, and
    # every command reading the inputs says so the same way (one reading of the log contract)
    def commands(tmp, fx, command):
        log = fx["demo_log"].rename(columns=lambda c: c.replace("tau_", "cmd_"))
        return _command(command, tmp, fx, data=_write_log(tmp, "commands", log))

    for command in ("loop", "train", "compare"):
        cases.append(
            Case(
                f"{command}: forces logged as commands of a vehicle without thrusters",
                functools.partial(commands, command=command),
                ("LOG", "no thrusters", "tau_X"),
            )
        )
    return cases


# -- vehicle files -------------------------------------------------------------------------------
GOOD_VEHICLE = """name = "probe"
mass = 11.5
inertia = [0.16, 0.16, 0.16]
r_g = [0.0, 0.0, 0.02]
[added_mass]
X_udot = -5.5
[damping.coefficients]
"X:u" = -4.0
"""
_THRUSTER = """[[thrusters]]
name = "h1"
position = [0.1, 0.1, 0.0]
direction = [1.0, 0.0, 0.0]
cmd_min = -1.0
cmd_max = 1.0
curve = { kind = "signed_quadratic", k = 40.0 }
"""
VEHICLE_CASES = [
    ("mass nan", "mass", ("mass = 11.5", "mass = nan")),
    ("mass inf", "mass", ("mass = 11.5", "mass = inf")),
    ("mass negative", "mass", ("mass = 11.5", "mass = -3")),
    ("mass in grams", "mass", ("mass = 11.5", "mass = 11500000")),
    ("r_g nan", "r_g", ("r_g = [0.0, 0.0, 0.02]", "r_g = [0.0, nan, 0.02]")),
    ("r_g absurd", "r_g", ("r_g = [0.0, 0.0, 0.02]", "r_g = [0.0, 0.0, 2000.0]")),
    ("r_g two values", "r_g", ("r_g = [0.0, 0.0, 0.02]", "r_g = [0.0, 0.02]")),
    ("inertia negative", "inertia", ("[0.16, 0.16, 0.16]", "[0.16, -0.16, 0.16]")),
    ("inertia inf", "inertia", ("[0.16, 0.16, 0.16]", "[0.16, inf, 0.16]")),
    ("unknown key", "masss", ("mass = 11.5", "mass = 11.5\nmasss = 2")),
    ("added mass key", "added_mass", ("X_udot", "X_uddot")),
    ("added mass nan", "X_udot", ("X_udot = -5.5", "X_udot = nan")),
    ("damping nan", "X:u", ('"X:u" = -4.0', '"X:u" = nan')),
    ("damping absurd", "X:u", ('"X:u" = -4.0', '"X:u" = -4e12')),
    ("damping bad key", "coefficients", ('"X:u"', '"X:speed"')),
    # one term spelt twice: the last one read won without a word (-900 over -4)
    ("damping term twice", "X: u", ('"X:u" = -4.0', '"X:u" = -4.0\n"X: u" = -900.0')),
    ("rho absurd", "rho", ("mass = 11.5", "mass = 11.5\nrho = 1.2")),
    ("toml syntax", "", ("mass = 11.5", "mass = = 11.5")),
    ("text mass", "mass", ("mass = 11.5", 'mass = "heavy"')),
    # a number written as text, or a boolean, is refused, never coerced (true was 1 kg)
    ("number as text", "mass", ("mass = 11.5", 'mass = "11.5"')),
    ("empty name", "name", ('name = "probe"', 'name = " "')),
    ("actuator lag absurd", "actuator_lag", ("mass = 11.5", "mass = 11.5\nactuator_lag = 1e9")),
    (
        "external bias absurd",
        "external_bias",
        ("mass = 11.5", "mass = 11.5\nexternal_bias = [1e12, 0, 0, 0, 0, 0]"),
    ),
    (
        "command range upside down",
        "cmd_min",
        ('"X:u" = -4.0', '"X:u" = -4.0\n' + _THRUSTER.replace("cmd_min = -1.0", "cmd_min = 1.0")),
    ),
    (
        "thruster named twice",
        "h1 appear twice",
        ('"X:u" = -4.0', '"X:u" = -4.0\n' + _THRUSTER + _THRUSTER),
    ),
    ("boolean mass", "mass", ("mass = 11.5", "mass = true")),
    # a thrust gain in the wrong unit: exit 0 at 1e15, a traceback in the monitor at 1e100
    (
        "thrust curve absurd",
        "thrusters.0.curve.k",
        ('"X:u" = -4.0', '"X:u" = -4.0\n' + _THRUSTER.replace("k = 40.0", "k = 1e15")),
    ),
    # a thruster that makes no thrust: accepted without a word, a column of zeros in B
    (
        "thrust curve of no thrust",
        "thrusters.0.curve.k",
        ('"X:u" = -4.0', '"X:u" = -4.0\n' + _THRUSTER.replace("k = 40.0", "k = 0.0")),
    ),
    # a name on two lines: accepted, and every one-line error naming the vehicle split in two
    ("name on two lines", "name", ('name = "probe"', 'name = "pro\\nbe"')),
    # a vector as a table of named values: said to be "a list of tables ([[r_g]] …)", and the
    # inertia's field named 'inertia.list[list[float]]', a member of pydantic's union
    (
        "r_g as a table",
        "r_g = [0.0, 0.0, 0.02]",
        ("r_g = [0.0, 0.0, 0.02]", "r_g = { x = 0.0, y = 0.0, z = 0.02 }"),
    ),
    (
        "inertia as a table",
        "field 'inertia': is a list of values (inertia = [0.16, 0.16, 0.16])",
        ("inertia = [0.16, 0.16, 0.16]", "inertia = { Ixx = 0.16, Iyy = 0.16, Izz = 0.16 }"),
    ),
    # named 'inertia.0', the first row read as the vector's first number
    (
        "text in the inertia tensor",
        "field 'inertia.1.1'",
        ("inertia = [0.16, 0.16, 0.16]", 'inertia = [[0.16, 0, 0], [0, "a", 0], [0, 0, 0.16]]'),
    ),
    # accepted without a word: no force ever passed the band, and every score "diverged"
    ("deadband absurd", "deadband", ("mass = 11.5", "mass = 11.5\ndeadband = 1e300")),
    (
        "commanded speed negative",
        "damping.u_c",
        ("[damping.coefficients]", "[damping]\nu_c = -1.0\n[damping.coefficients]"),
    ),
    (
        "commanded speed absurd",
        "damping.u_c",
        ("[damping.coefficients]", "[damping]\nu_c = 1e300\n[damping.coefficients]"),
    ),
]


def _vehicle_cases() -> list[Case]:
    cases = []
    for command in ("loop", "train", "simulate"):
        for name, field, (old, new) in VEHICLE_CASES:

            def args(tmp, fx, name=name, old=old, new=new, command=command):
                path = tmp / f"{name.replace(' ', '_')}.toml"
                path.write_text(GOOD_VEHICLE.replace(old, new))
                return _command(command, tmp, fx, vehicle=path,
                                out=tmp / "sim.csv" if command == "simulate" else None)  # fmt: skip

            cases.append(Case(f"{command} vehicle: {name}", args, ("VEHICLE", field)))
    return cases


# -- configs ---------------------------------------------------------------------------------
TRAIN_TEXT = (REPO / "configs" / "fossen_ls.toml").read_text()
#: one sequence step (its run, its unknown) in place of TRAIN_TEXT's unknowns (a sequence's
#: steps name theirs: the model's beside it are refused)
_UNKNOWNS = 'unknowns = ["added_mass", "damping"]'
_STEP = 'sequence = [{ experiments = ["%s"], dofs = ["w"], unknowns = ["%s"] }]'
CONFIG_CASES = [
    ("train", "unknown key", "warmup", ("warmup_s = 2.0", "warmup = 2.0")),
    ("train", "nan setting", "warmup_s", ("warmup_s = 2.0", "warmup_s = nan")),
    ("train", "negative setting", "warmup_s", ("warmup_s = 2.0", "warmup_s = -2.0")),
    ("train", "number as text", "warmup_s", ("warmup_s = 2.0", 'warmup_s = "2.0"')),
    # every held-out run all warm-up: no score at all, once reported as "diverged"
    ("train", "warm-up longer than every run", "warmup_s", ("warmup_s = 2.0", "warmup_s = 1e9")),
    ("train", "boolean for a number", "warmup_s", ("warmup_s = 2.0", "warmup_s = true")),
    # "Input should be a valid dictionary or object to extract fields from"
    ("train", "a path where the [split] table goes", "split", ("[split]", 'split = "a.csv"\n[x]')),
    # overflowed the sample count, or underflowed the prime-system scale: tracebacks
    ("train", "k-step horizon of 1e308 s", "k_step_s", ("k_step_s = 1.0", "k_step_s = 1e308")),
    # settles after every run: nothing fitted and exit 0, or a singular discretisation; named
    # where the config sets it (was 'filter_lambda', a key of no table of the config)
    (
        "train",
        "a filter slower than every run",
        "model.trainer.filter_lambda",
        ("filter_lambda = 1.0", "filter_lambda = 1e-6"),
    ),
    ("compare", "second model's trainer filter too slow", "models.1.trainer.filter_lambda", None),
    (
        "train",
        "ensemble member's physics trainer filter too slow",
        "model.member.physics_trainer.filter_lambda",
        None,
    ),
    (
        "train",
        "nondimensional speed of 1e-300",
        "nondimensional_speed",
        ("warmup_s = 2.0", "warmup_s = 2.0\nnondimensional_speed = 1e-300"),
    ),
    ("train", "fractions not summing to 1", "fractions", ("[0.6, 0.2, 0.2]", "[0.6, 0.6, 0.2]")),
    ("train", "everything validation", "split", ("[0.6, 0.2, 0.2]", "[0.0, 1.0, 0.0]")),
    ("train", "unknown model kind", "kind", ('kind = "fossen"', 'kind = "fosen"')),
    ("train", "unknown trainer", "trainer", ('kind = "ls"', 'kind = "lsq"')),
    ("train", "unknown unknowns", "unknowns", ('"added_mass", "damping"', '"added_mass", "drag"')),
    # a name given twice is a typo, not a weight
    (
        "train",
        "unknowns named twice",
        "unknowns",
        ('"added_mass", "damping"', '"damping", "damping"'),
    ),
    ("train", "wrong kind of config", "kind", ('kind = "train"', 'kind = "compare"')),
    ("train", "toml syntax", "", ("warmup_s = 2.0", "warmup_s = 2.0.0")),
    (
        "train",
        "validation experiments unknown",
        "validation",
        ('by = "auto"', 'by = "experiment"\nvalidation = ["dive9"]'),
    ),
    # a run on both sides: the "held-out" score would be of data the fit has seen
    (
        "train",
        "an experiment trained on and validated on",
        "split.validation",
        ('by = "auto"', 'by = "experiment"\ntrain = ["run0", "run1"]\nvalidation = ["run1"]'),
    ),
    (
        "train",
        "an experiment validated on and tested on",
        "split.test",
        ('by = "auto"', 'by = "experiment"\nvalidation = ["run1"]\ntest = ["run1"]'),
    ),
    (
        "train",
        "named experiments a block split ignores",
        "split.validation",
        ('by = "auto"', 'by = "block"\nvalidation = ["run1"]'),
    ),
    (
        "train",
        "every experiment held out",
        "split",
        ('by = "auto"', 'by = "experiment"\nvalidation = ["run0", "run1", "run2"]'),
    ),
    # refused by the model at fit, named where the config sets it
    ("train", "narx input not in the log", "model.inputs", None),
    ("train", "narx bounds upside down", "model.output_bounds", None),
    ("train", "narx output also an input", "w is an output and an input", None),
    ("train", "narx input named twice", "model.inputs", None),
    ("train", "narx delay beyond every run", "model.input_delays", None),
    ("train", "sindy term not of the library", "model.terms", None),
    ("train", "sindy without thresholds", "model.thresholds", None),
    ("train", "narx bound not a number", "model.output_bounds.0.0", None),
    ("train", "adam floor above its rate", "model.trainer", None),
    ("train", "synthesis mask of no terms", "model.mask", None),
    ("train", "synthesis mask term twice", "model.mask", None),
    ("train", "fossen dofs named twice", "model.dofs", None),
    # a list where a number or a list is allowed: the element is named, not "a valid integer"
    ("train", "narx delay list with a negative delay", "model.input_delays.1", None),
    # said against the config alone ("narx.toml: input_delays must be ..."), no field named
    ("train", "narx empty input delay list", "model.input_delays", None),
    ("train", "narx empty output delay list", "model.output_delays", None),
    ("train", "ensemble member output not in the log", "model.member.outputs", None),
    ("compare", "second model input not in the log", "models.1.inputs", None),
    # a sequence step's experiments and unknowns: the step's, not the model's own `unknowns`
    (
        "train",
        "sequence step on a missing run",
        "model.sequence",
        (_UNKNOWNS, _STEP % ("dive9", "Z_wdot")),
    ),
    (
        "train",
        "sequence step's unknowns a shortcut",
        "model.sequence",
        (_UNKNOWNS, _STEP % ("run0", "added_mass")),
    ),
    ("loop", "unknown dof", "dofs", None),
    ("loop", "held-out run not in log", "validation", None),
    ("loop", "unknown key", "alhpa", None),
    ("loop", "nan alpha", "alpha", None),
    ("loop", "every run held out", "validation", None),
    ("loop", "empty dofs", "dofs", None),
    ("loop", "dofs named twice", "dofs", None),
    # [] was read as no list: every run kept, and fitted, without a word
    (
        "train",
        "an empty experiment list",
        "data.experiments",
        ("[split]", "[data]\nexperiments = []\n\n[split]"),
    ),
    ("loop", "an empty experiment list", "data.experiments", None),
    # kept in metrics.json and compared with nothing
    (
        "train",
        "a reference naming no fitted parameter",
        ("reference.Z_wdott", "did you mean 'Z_wdot'?"),
        ("zoh_midpoint = true", "zoh_midpoint = true\n\n[reference]\nZ_wdott = -18.7"),
    ),
    # named 'savgol_window', a key of no table of this config
    (
        "train",
        "a savgol window longer than a held-out run",
        "model.savgol_window",
        ("zoh_midpoint = true", "zoh_midpoint = true\nsavgol_window = 21.0"),
    ),
    # each taken, exit 0: no alarm ever isolated, no threshold, every score "diverged"
    (
        "train",
        "an isolation window longer than the log",
        "detect.window_s",
        ("zoh_midpoint = true", "zoh_midpoint = true\n\n[detect]\nwindow_s = 1e308"),
    ),
    # the window slides within one run: three 15-s runs are 45 s together, and it was taken
    (
        "train",
        "an isolation window longer than every run",
        ("detect.window_s", "longest run of the log (14.95 s)"),
        ("zoh_midpoint = true", "zoh_midpoint = true\n\n[detect]\nwindow_s = 20.0"),
    ),
    (
        "train",
        "a false-alarm target of 1e308 an hour",
        "detect.false_alarm_per_hour",
        ("zoh_midpoint = true", "zoh_midpoint = true\n\n[detect]\nfalse_alarm_per_hour = 1e308"),
    ),
    ("train", "noise of 1e300", "data.noise", ("[split]", "[data]\nnoise = 1e300\n\n[split]")),
    # blamed on the log ("good.csv, field 'savgol_window'"), with a 300-digit window
    ("loop", "a savgol window longer than every run", "savgol_window", None),
    ("loop", "a savgol window of 1e300 s", ("savgol_window", "window of 2e+301 samples"), None),
    # λ dt/2 lost beside 1: the filter's steady start was singular, a LinAlgError traceback
    (
        "loop",
        "a filter of 1e-300 rad per s",
        ("filter_lambda", "lost beside 1", "experiment 'run0'"),
        None,
    ),
    ("train", "sindy filter of 1e-300 rad per s", ("model.filter_lambda", "lost beside 1"), None),
    # accepted, exit 0: a model's name and the reference's label head the reports' rows and
    # columns, which a line break or a tab broke, and a blank one labelled nothing
    ("compare", "a model name with a tab", ("models.0.name", "one line"), None),
    ("compare", "a model name of spaces", ("models.1.name", "visible character"), None),
    ("train", "a model name on two lines", ("model.name", "one line"), None),
    (
        "train",
        "a reference label on two lines",
        ("reference_label", "one line"),
        ("k_step_s = 1.0", 'k_step_s = 1.0\nreference_label = "Weiss\\nTable 3"'),
    ),
    (
        "train",
        "a blank reference label",
        ("reference_label", "visible character"),
        ("k_step_s = 1.0", 'k_step_s = 1.0\nreference_label = "  "'),
    ),
]
LOOP_TEXT = {
    "unknown dof": 'kind = "loop"\ndofs = ["u", "x"]\n',
    "held-out run not in log": 'kind = "loop"\nvalidation = ["dive9"]\n',
    "unknown key": 'kind = "loop"\nalhpa = 0.01\n',
    "nan alpha": 'kind = "loop"\nalpha = nan\n',
    "every run held out": 'kind = "loop"\nvalidation = ["run0", "run1", "run2"]\n',
    "empty dofs": 'kind = "loop"\ndofs = []\n',  # [] is not "all": leave the key out for all
    "dofs named twice": 'kind = "loop"\ndofs = ["w", "w"]\n',
    "an empty experiment list": 'kind = "loop"\n[data]\nexperiments = []\n',
    "a savgol window longer than every run": 'kind = "loop"\nsavgol_window = 21.0\n',
    "a savgol window of 1e300 s": 'kind = "loop"\nsavgol_window = 1e300\n',  # 20 Hz runs
    "a filter of 1e-300 rad per s": 'kind = "loop"\nfilter_lambda = 1e-300\n',
}


_NARX = 'kind = "narx"\ninputs = ["tau_Z"]\noutputs = ["w"]\n'
#: the model sections after TRAIN_TEXT's split (compare: its Fossen fit, then a bad model)
MODEL_TEXT = {
    "narx input not in the log": f"[model]\n{_NARX.replace('tau_Z', 'tau_Q')}",
    "narx bounds upside down": f"[model]\n{_NARX}output_bounds = [[1.0, 0.0]]\n",
    # the model would read the measured answer, in free run too
    "narx output also an input": "[model]\n" + _NARX.replace('["tau_Z"]', '["tau_Z", "w"]'),
    "narx input named twice": "[model]\n" + _NARX.replace('["tau_Z"]', '["tau_Z", "tau_Z"]'),
    "narx delay beyond every run": f"[model]\n{_NARX}input_delays = 5000\n",
    "sindy term not of the library": '[model]\nkind = "sindy"\nterms = ["u*banana"]\n',
    "sindy without thresholds": '[model]\nkind = "sindy"\nthresholds = []\n',
    "sindy filter of 1e-300 rad per s": '[model]\nkind = "sindy"\nfilter_lambda = 1e-300\n',
    "narx delay list with a negative delay": f"[model]\n{_NARX}input_delays = [0, -1]\n",
    "narx empty input delay list": f"[model]\n{_NARX}input_delays = []\n",
    "narx empty output delay list": f"[model]\n{_NARX}output_delays = []\n",
    # a NaN bound was said as "Input should be 'train'"
    "narx bound not a number": f"[model]\n{_NARX}output_bounds = [[nan, 1.0]]\n",
    "adam floor above its rate": (
        f'[model]\n{_NARX}trainer = {{ kind = "adam", lr = 1e-3, lr_min = 1e-2 }}\n'
    ),
    "synthesis mask of no terms": '[model]\nkind = "synthesis"\nmask = { Z = [] }\n',
    "synthesis mask term twice": '[model]\nkind = "synthesis"\nmask = { Z = ["w", "w"] }\n',
    "fossen dofs named twice": '[model]\nkind = "fossen"\ndofs = ["w", "w"]\n',
    "ensemble member output not in the log": (
        '[model]\nkind = "ensemble"\nseeds = [0, 1]\n[model.member]\n'
        + _NARX.replace('["w"]', '["heave"]')
    ),
    "second model input not in the log": (
        f"[[models]]{TRAIN_TEXT.split('[model]')[1]}[[models]]\n{_NARX.replace('tau_Z', 'tau_Q')}"
    ),
    "a model name with a tab": f'[[models]]{TRAIN_TEXT.split("[model]")[1]}name = "fossen\\tls"\n',
    "a model name of spaces": (
        f'[[models]]{TRAIN_TEXT.split("[model]")[1]}[[models]]\n{_NARX}name = "   "\n'
    ),
    "a model name on two lines": f'[model]\n{_NARX}name = "narx\\n1"\n',
    "second model's trainer filter too slow": (
        f'[[models]]{TRAIN_TEXT.split("[model]")[1]}[[models]]\nkind = "fossen"\n'
        'name = "filtered"\ntrainer = { kind = "rls", filter_lambda = 1e-6 }\n'
    ),
    "ensemble member's physics trainer filter too slow": (
        '[model]\nkind = "ensemble"\nseeds = [0, 1]\n[model.member]\nkind = "hybrid"\n'
        'physics_trainer = { kind = "ls", filter_lambda = 1e-6 }\n'
    ),
}


def _config_cases() -> list[Case]:
    cases = []
    for command, name, field, change in CONFIG_CASES:

        def args(tmp, fx, command=command, name=name, change=change):
            path = tmp / f"{name.replace(' ', '_')}.toml"
            if name in MODEL_TEXT:
                head = TRAIN_TEXT.split("[model]")[0]
                text = head.replace('kind = "train"', f'kind = "{command}"') + MODEL_TEXT[name]
            else:
                text = TRAIN_TEXT.replace(*change) if change else LOOP_TEXT[name]
            path.write_text(text)
            return _command(command, tmp, fx, config=path)

        fields = (field,) if isinstance(field, str) else field
        cases.append(Case(f"{command} config: {name}", args, ("CONFIG", *fields)))
    return cases


# -- output paths and model folders ------------------------------------------------------------
def _out_cases() -> list[Case]:
    cases = []
    for where in ("a file", "/proc", "below a file"):

        def out(tmp, where=where):
            if where == "a file":
                (tmp / "taken").write_text("x")
                return tmp / "taken"
            if where == "below a file":
                (tmp / "taken").write_text("x")
                return tmp / "taken" / "out"
            return Path("/proc/nnid-out")

        for command in ("train", "compare", "loop", "detect", "demo", "inspect", "simulate"):

            def args(tmp, fx, command=command, out=out, where=where):
                target = out(tmp)
                if command == "simulate" and where != "a file":
                    target = target / "x.csv"
                return _command(command, tmp, fx, out=target)

            cases.append(Case(f"{command} --out {where}", args, ("OUT",)))
    for extra in ([], ["--follow"]):  # its outputs replaced the model's report.html

        def into_model(tmp, fx, extra=extra):
            return [*_command("detect", tmp, fx, out=fx["monitor"]), *extra]

        cases.append(Case(f"detect{' --follow' * bool(extra)} --out: the --model folder",
                          into_model, ("OUT", "--model")))  # fmt: skip
    model_cases = {
        "no such model folder": lambda tmp, fx: tmp / "nothing",
        "folder without a monitor": lambda tmp, fx: tmp,
        "corrupt monitor.json": lambda tmp, fx: _corrupt_monitor(tmp),
        # said against model.json itself, not wrapped as a fault of monitor.json
        "model.json naming no vehicle": lambda tmp, fx: _damaged_model(tmp, fx["monitor"]),
    }
    for name, folder in model_cases.items():

        def args(tmp, fx, folder=folder):
            return _command("detect", tmp, fx, model=folder(tmp, fx), out=tmp / "o")

        cases.append(Case(f"detect --model: {name}", args, ("MODEL",)))
    # a hand-edited model.json loaded without a word, and detect ran on it
    edits = {
        "a DOF that is none": (("settings", "dofs"), ["x"], "settings.dofs"),
        "an unknown parameter": (("settings", "unknowns"), ["bogus"], "settings.unknowns"),
        "a window written as text": (("settings", "savgol_window"), "1", "settings.savgol_window"),
        "outputs the model does not predict": (("outputs",), ["zz"], "field 'outputs'"),
        "a trainer that did not fit it": (("trainer",), "bogus", "field 'trainer'"),
    }
    for name, (key, value, field) in edits.items():

        def edited(tmp, fx, key=key, value=value):
            folder = _damaged_model(tmp, fx["monitor"], key, value)
            return _command("detect", tmp, fx, model=folder, out=tmp / "o")

        cases.append(Case(f"detect --model: model.json with {name}", edited, ("MODEL", field)))
    # the isolation window the model was trained with, read from metrics.json unchecked: text
    # a traceback or taken ("10"), a negative, zero or infinite window taken as it stood
    windows = {
        "a window written as text": ('{"window_s": "10"}', "detect.settings.window_s"),
        "a negative window": ('{"window_s": -5}', "detect.settings.window_s"),
        "a window of zero": ('{"window_s": 0}', "detect.settings.window_s"),
        "an infinite window": ('{"window_s": 1e999}', "detect.settings.window_s"),
        "a window as a list": ('{"window_s": [10]}', "detect.settings.window_s"),
        "settings as a list": ("[10]", "field 'detect.settings'"),
    }
    for name, (settings_json, field) in windows.items():

        def metrics(tmp, fx, settings_json=settings_json):
            import shutil

            folder = tmp / "edited_model"
            shutil.copytree(fx["monitor"], folder)
            text = '{"detect": {"settings": ' + settings_json + "}}"
            (folder / "metrics.json").write_text(text)
            return _command("detect", tmp, fx, model=folder, out=tmp / "o")

        cases.append(
            Case(
                f"detect --model: metrics.json with {name}",
                metrics,
                ("MODEL", "metrics.json", field),
            )
        )
    return cases


def _damaged_model(
    tmp: Path, good: Path, key: tuple[str, ...] = ("settings", "vehicle"), value: object = "zzz"
) -> Path:
    """A copy of the model folder ``good`` with model.json's ``key`` (a path) set to ``value``."""
    import json
    import shutil

    folder = tmp / "damaged_model"
    shutil.copytree(good, folder)
    payload = json.loads((folder / "model.json").read_text())
    node = payload
    for step in key[:-1]:
        node = node[step]
    node[key[-1]] = value
    (folder / "model.json").write_text(json.dumps(payload))
    return folder


def _corrupt_monitor(tmp: Path) -> Path:
    folder = tmp / "broken_model"
    folder.mkdir()
    (folder / "monitor.json").write_text('{"kind": "residual_monitor", "mu": [1, 2')
    return folder


CASES = [*_log_cases(), *_vehicle_cases(), *_config_cases(), *_out_cases()]


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    """A good minirov log, a good octorov log and a calibrated monitor for it."""
    from nnid.datasets.faults import simulate_faults
    from nnid.fault.monitor import ResidualMonitor
    from nnid.models.parametric import ParametricModel
    from nnid.trainers.least_squares import LeastSquares
    from nnid.vehicle import load_vehicle

    tmp = tmp_path_factory.mktemp("corpus")
    octo = load_vehicle(OCTO)
    logs = [simulate_faults(octo, 40, seed=s, experiment=f"h{s}") for s in range(3)]
    model = ParametricModel(
        octo, ["added_mass", "damping"], trainer=LeastSquares(filter_lambda=1.0), zoh_midpoint=True
    ).fit(logs[0])
    monitor = ResidualMonitor(model).fit(pd.concat(logs[1:], ignore_index=True))
    model.save(tmp / "monitor")
    monitor.save(tmp / "monitor")
    return {
        "demo_log": _demo_log(),
        "octo_log": logs[2].iloc[:400].reset_index(drop=True),
        "monitor": tmp / "monitor",
        "out": tmp / "never_written",
    }


def test_the_corpus_is_large_and_covers_every_command():
    commands = {c.id.split()[0].rstrip(":") for c in CASES}
    assert len(CASES) >= 150
    assert commands >= {"simulate", "inspect", "train", "compare", "loop", "detect", "demo"}


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_is_refused_in_one_line_naming_the_file_and_field(case, fixtures, tmp_path):
    args = case.args(tmp_path, fixtures)
    followed = tmp_path / "followed"
    if "--follow" in args and str(fixtures["out"]) in args:
        # a row refused after rows were watched writes theirs, said stopped: not to the shared out
        args[args.index(str(fixtures["out"]))] = str(followed)
    result = CliRunner().invoke(app, args)
    output = result.output
    assert "Traceback" not in output and not isinstance(result.exception, Exception | None)
    assert result.exit_code == 2, output
    errors = [line for line in output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, output
    line = errors[0]
    kind, *fields = case.names
    if kind == "LOG":
        named = [a for a in args if a.endswith((".csv", ".parquet"))][-1]
        assert Path(named).name in line, line
    elif kind == "VEHICLE":
        assert ".toml" in line, line
    elif kind == "CONFIG":
        assert Path(args[1]).name in line, line
    elif kind == "OUT":
        assert "--out" in line or "nnid-out" in line or "taken" in line, line
    elif kind == "MODEL":
        assert any(n in line for n in ("--model", "monitor", "model.json", "metrics.json")), line
        # a fault of model.json is said against it, not wrapped as one of monitor.json
        assert not ("model.json: damaged" in line and "is not a monitor" in line), line
    for field in fields:
        if field == "INPUT":
            field = "tau_" if not args[0] == "detect" else "cmd_"
        assert field.lower() in line.lower(), line
    assert not fixtures["out"].exists()  # nothing written by a refused run
    if followed.exists():  # the rows before the refused one
        stopped = json.loads((followed / "detect.json").read_text())["stopped"]
        assert stopped.startswith("stopped at row ") and "wrote " in output, output


# -- property-based: the vehicle-file loader ---------------------------------------------------
_value = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e12, max_value=1e12),
    st.sampled_from(["", "heavy", None, [], [1.0]]),
)
_FIELDS = ("mass", "rho", "g", "length", "buoyancy", "actuator_lag", "deadband")


@settings(max_examples=60, deadline=None)
@given(
    field=st.sampled_from([*_FIELDS, "r_g", "r_b", "inertia", "added_mass", "damping"]),
    value=_value,
    index=st.integers(0, 2),
)
def test_vehicle_loader_gives_a_vehicle_or_names_the_field(field, value, index):
    """Any value in any field: a valid vehicle (every number finite and within the physical
    bounds), or the input error naming that field; never another exception."""
    from nnid.errors import NnidInputError
    from nnid.vehicle import MAX_MASS, vehicle_from_dict

    data = {"name": "probe", "mass": 11.5, "inertia": [0.2, 0.2, 0.3]}
    if field in ("r_g", "r_b", "inertia"):
        vector = [0.0, 0.0, 0.0] if field != "inertia" else [0.2, 0.2, 0.3]
        vector[index] = value
        data[field] = vector
    elif field == "added_mass":
        data[field] = {"X_udot": value}
    elif field == "damping":
        data[field] = {"coefficients": {"X:u": value}}
    else:
        data[field] = value
    try:
        vehicle = vehicle_from_dict(data, source="probe.toml")
    except NnidInputError as err:
        assert "probe.toml" in str(err) and field in str(err), str(err)
        return
    numbers = [vehicle.mass, vehicle.rho, vehicle.g, *vehicle.r_g, *vehicle.r_b]
    numbers += list(vehicle.added_mass.values()) + list(vehicle.damping.coefficients.values())
    assert all(np.isfinite(numbers)) and 0 < vehicle.mass <= MAX_MASS


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        ({"inertia": [1600.0, 1600.0, 1600.0]}, "radius of gyration 11.8 m exceeds the vehicle's"),
        # an inertia that holds a CG 2 m out (46 kg m² of it m |r_g|²): with 0.16 the rigid
        # body is refused (test_an_inertia_about_the_centre_of_gravity_is_refused...)
        ({"r_g": [0.0, 0.0, 2.0], "inertia": [46.2, 46.2, 0.32]},
         "r_g is 2 m from the origin, beyond the vehicle's length"),
        ({"thrusters": [{"name": "h1", "position": [20.0, 0.0, 0.0], "direction": [1, 0, 0],
                         "curve": {"kind": "signed_quadratic", "k": 40.0}}]},
         "thruster h1's position is 20 m out"),
        ({"thrusters": [{"name": "h1", "position": [0.2, 0.0, 0.0], "direction": [1, 0, 0],
                         "curve": {"kind": "table", "cmd": [-0.2, 0.0, 0.2],
                                   "thrust": [-10.0, 0.0, 10.0]},
                         "cmd_min": -0.5, "cmd_max": 0.5}]},
         "spans commands -0.2 to 0.2, short of its cmd_min -0.5, its cmd_max 0.5"),
    ],
)  # fmt: skip
def test_geometry_no_vehicle_of_its_size_has_is_warned_of(edit, said):
    """A unit slip in the geometry was absorbed by the fit without a word: an inertia in
    kg cm² came back as K_pdot = M_qdot = N_rdot = +1600, "significant"; r_g and thruster
    positions in cm diverged with a warning that blamed the added mass; a table short of the
    command range clamped the thrust. A sound file (every preset) says nothing."""
    from nnid.vehicle import PRESETS, load_vehicle, vehicle_from_dict

    base = {"name": "probe", "mass": 11.5, "length": 0.46, "inertia": [0.16, 0.16, 0.16]}
    with pytest.warns(UserWarning, match=re.escape(said)):
        vehicle_from_dict({**base, **edit}, source="probe.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vehicle_from_dict(base, source="probe.toml")
        for name in PRESETS:
            load_vehicle(name)


def test_an_inertia_about_the_centre_of_gravity_is_refused_naming_inertia_and_r_g():
    """The origin at the nose, r_g = [1, 0, 0], mass 40 and a datasheet's Iy = Iz = 10 about
    the CG loaded silently though M_RB (McCarter eq. 2.21) is not positive definite: I_CG =
    I_o + m S(r_g)² = 10 − 40 < 0; simulate then refused naming no field, and a fit blamed
    the added mass. Refused at load, naming both fields, the moments about the CG and the
    I_o = I_CG − m S(r_g)² the datasheet's values give; that I_o loads."""
    from nnid.errors import NnidInputError
    from nnid.vehicle import vehicle_from_dict

    nose = {"name": "probe", "mass": 40.0, "inertia": [2.0, 10.0, 10.0], "r_g": [1.0, 0, 0]}
    with pytest.raises(NnidInputError) as err:
        vehicle_from_dict(nose, source="nose.toml")
    said = str(err.value)
    assert said.startswith("nose.toml, field 'inertia': ") and "r_g = [1, 0, 0]" in said, said
    assert "-30, -30, 2 kg m²" in said and "give inertia = [2, 50, 50]" in said, said
    assert "about the body origin" in said and "I_o = I_CG − m S(r_g)²" in said, said
    vehicle_from_dict({**nose, "inertia": [2.0, 50.0, 50.0]}, source="nose.toml")


def test_principal_moments_no_body_has_are_refused():
    """I₁ > I₂ + I₃ (beyond 0.1 %) no body has about any point (I₂ + I₃ − I₁ = 2 Σ m x₁²):
    it was only warned of, and loaded. Refused naming the file and 'inertia'; a thin disc's
    I_z = I_x + I_y (the bound itself) loads, and so does every shipped vehicle."""
    from nnid.errors import NnidInputError
    from nnid.vehicle import vehicle_from_dict

    base = {"name": "probe", "mass": 11.5, "length": 0.46}
    with pytest.raises(NnidInputError, match=r"probe.toml, field 'inertia': the largest princ"):
        vehicle_from_dict({**base, "inertia": [0.1, 0.1, 0.5]}, source="probe.toml")
    vehicle_from_dict({**base, "inertia": [0.1, 0.1, 0.2001]}, source="probe.toml")


def test_a_thrust_table_that_pushes_at_zero_command_is_warned_of():
    """A table with thrust(0) ≠ 0 pushes a thruster at rest with a constant force, and
    loaded without a word. Warned of, naming the thruster and the value; not where its
    commands exclude 0 (cmd_min > 0), nor for a table through 0 N."""
    from nnid.vehicle import vehicle_from_dict

    def probe(thrust: list[float], **limits: float) -> dict:
        curve = {"kind": "table", "cmd": [-1.0, 0.0, 1.0], "thrust": thrust}
        t1 = {"name": "t1", "position": [0.1, 0, 0], "direction": [1, 0, 0], "curve": curve}
        return {"name": "probe", "mass": 11.5, "inertia": [0.2, 0.2, 0.3],
                "thrusters": [{**t1, **limits}]}  # fmt: skip

    said = "thruster t1's thrust table gives 0.3 N at command 0"
    with pytest.warns(UserWarning, match=re.escape(said)):
        vehicle_from_dict(probe([-5.0, 0.3, 6.0]), source="probe.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vehicle_from_dict(probe([-5.0, 0.0, 6.0]), source="probe.toml")
        vehicle_from_dict(probe([-5.0, 0.3, 6.0], cmd_min=0.2, cmd_max=1.0), source="p.toml")


def test_a_length_in_centimetres_is_refused_naming_the_file_and_field():
    """A small ROV's length of 45 for 0.45 m loaded without a word: its thruster positions in
    cm then lay within it, unwarned (size_slips reads them against the length), and its
    rounding arm was 100 times too long. It is refused, naming the file, the field, the value
    and the unit; every vehicle file the repository ships loads."""
    from nnid.errors import NnidInputError
    from nnid.vehicle import PRESETS, load_vehicle, saved_vehicle, vehicle_from_dict

    base = {"name": "probe", "mass": 11.5, "length": 0.45, "inertia": [0.16, 0.16, 0.16]}
    thruster = {"name": "h1", "position": [20.0, 0.0, 0.0], "direction": [1, 0, 0],
                "curve": {"kind": "signed_quadratic", "k": 40.0}}  # fmt: skip
    with pytest.raises(
        NnidInputError, match=r"field 'length': 45 m is 199 times .* the length is in metres"
    ) as err:
        vehicle_from_dict({**base, "length": 45.0, "thrusters": [thruster]}, source="rov.toml")
    assert err.value.field == "length" and err.value.source == "rov.toml"
    assert vehicle_from_dict(base, source="rov.toml").length == 0.45
    shipped = [*REPO.glob("configs/vehicles/*.toml"), REPO / "nnid/demo_data/minirov.toml"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # size and sign warnings are other tests'
        # new input only: a model saved before the refusal, its length in cm, still loads
        assert saved_vehicle({**base, "length": 45.0, "thrusters": [thruster]}).length == 45.0
        for name in [*PRESETS, *map(str, shipped)]:
            load_vehicle(name)


def test_a_derivative_of_the_energy_adding_sign_or_a_weight_in_kg_is_warned_of():
    """SNAME signs (Fossen: M_A = −[X_u̇ …], D = −[X_u …]): a positive X_udot, or a positive
    diagonal damping in a row with nothing else, is said once naming the file; a coupled row's
    positive diagonal term (McCarter's VT690 K_{p|p|} = +0.421) is not, nor a sound file."""
    from nnid.vehicle import load_vehicle, vehicle_from_dict

    base = {"name": "probe", "mass": 11.5, "inertia": [0.2, 0.2, 0.3]}
    slipped = {
        **base,
        "added_mass": {"X_udot": 5.5, "Y_vdot": -5.0},
        "damping": {"coefficients": {"X:u": 4.0, "Y:v": -4.0, "N:r*abs(r)": 0.5}},
    }
    with pytest.warns(UserWarning) as caught:
        vehicle_from_dict(slipped, source="probe.toml")
    said = [str(w.message) for w in caught]
    assert len(said) == 3 and all(m.startswith("probe.toml: ") for m in said), said
    text = " | ".join(said)
    assert all(p in text for p in ("X_udot = 5.5", "'X:u' = 4", "'N:r*abs(r)' = 0.5")), said
    with pytest.warns(UserWarning, match=r"probe.toml: weight 11.5 N is not mass × g"):
        vehicle_from_dict({**base, "weight": 11.5}, source="probe.toml")  # kg written as N
    weight = base["mass"] * 9.81
    with pytest.warns(UserWarning, match=r"probe.toml: buoyancy 1000 N is .* times the weight"):
        vehicle_from_dict({**base, "buoyancy": 1000.0}, source="probe.toml")
    coupled = {**base, "damping": {"coefficients": {"K:p*abs(p)": 0.4, "K:p*abs(u)": -0.4}}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vehicle_from_dict(coupled, source="probe.toml")
        vehicle_from_dict({**base, "added_mass": {"X_udot": -5.5}}, source="probe.toml")
        vehicle_from_dict({**base, "weight": 11.5 * 9.81}, source="probe.toml")
        vehicle_from_dict({**base, "buoyancy": 1.05 * weight}, source="probe.toml")  # trimmed
        load_vehicle("vt690")


@pytest.mark.parametrize(("r_g", "r_b"), [(-0.02, 0.0), (0.0, 0.03), (0.01, 0.05)])
def test_a_centre_of_gravity_above_the_centre_of_buoyancy_is_warned_of(r_g, r_b):
    """FRD, z down: a vehicle whose CG is above its CB (r_g z < r_b z) is statically
    unstable in roll and pitch, which no ROV or AUV is trimmed to be (a sign slip, z written
    up): loaded without a word. Said once, naming the file and both values; a bottom-heavy
    vehicle, one with both at the origin, and every shipped vehicle file say nothing."""
    from nnid.vehicle import PRESETS, load_vehicle, vehicle_from_dict

    base = {"name": "probe", "mass": 11.5, "inertia": [0.2, 0.2, 0.3]}
    tipped = {**base, "r_g": [0.0, 0.0, r_g], "r_b": [0.0, 0.0, r_b]}
    with pytest.warns(UserWarning) as caught:
        vehicle_from_dict(tipped, source="probe.toml")
    said = [str(w.message) for w in caught]
    assert len(said) == 1 and said[0].startswith("probe.toml: the centre of gravity is above"), said
    assert f"r_g z = {r_g:g} m," in said[0] and f"r_b z = {r_b:g} m," in said[0], said
    assert "unstable" in said[0], said
    swapped = {**base, "r_g": [0.0, 0.0, r_b], "r_b": [0.0, 0.0, r_g]}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vehicle_from_dict(swapped, source="probe.toml")  # bottom-heavy
        vehicle_from_dict(base, source="probe.toml")  # both at the origin: neutral
        for name in [*PRESETS, MINIROV, *map(str, (REPO / "configs" / "vehicles").glob("*.toml"))]:
            load_vehicle(name)


def test_a_buoyancy_whose_moment_outweighs_the_weights_is_warned_of_as_such():
    """The righting moment is z_g W − z_b B (Fossen's g(η)): with both centres at the same
    height below the origin and B > W it tips the vehicle over, though the centre of gravity
    is not above the centre of buoyancy; said as what it is, not as a CG above the CB."""
    from nnid.vehicle import vehicle_from_dict

    base = {"name": "probe", "mass": 11.5, "inertia": [0.2, 0.2, 0.3]}
    weight = 11.5 * 9.81
    light = {**base, "r_g": [0.0, 0.0, 0.02], "r_b": [0.0, 0.0, 0.02], "buoyancy": 1.01 * weight}
    with pytest.warns(UserWarning) as caught:
        vehicle_from_dict(light, source="probe.toml")
    said = [str(w.message) for w in caught]
    assert len(said) == 1, said
    assert said[0].startswith("probe.toml: the buoyancy's moment outweighs the weight's"), said
    assert "z_g W < z_b B" in said[0] and "unstable" in said[0], said


def test_a_clock_finer_than_nnid_reads_is_refused_where_it_is_set():
    """A simulated dt or a reader config's rate finer than any log nnid reads (FASTEST_STEP)
    was refused downstream as hours read as seconds ("convert it to seconds"): nothing was
    read in a wrong unit. Refused where it is set, naming the key."""
    from pydantic import ValidationError

    from nnid.config import SimulateConfig
    from nnid.datasets.column_map import ColumnMap
    from nnid.datasets.log import FASTEST_STEP

    with pytest.raises(ValidationError) as err:
        SimulateConfig(vehicle="seamor", dt=FASTEST_STEP / 2)
    assert err.value.errors()[0]["loc"] == ("dt",)
    with pytest.raises(ValidationError) as err:  # the bound itself is taken: what is left
        SimulateConfig(vehicle="seamor", dt=FASTEST_STEP)  # is the missing experiments
    assert all(e["loc"] != ("dt",) for e in err.value.errors()), err.value.errors()
    source = {"file": "nav.csv", "time": "t", "columns": {"z": "depth"}}
    with pytest.raises(ValidationError) as err:
        ColumnMap(rate=2.0 / FASTEST_STEP, sources=[source])
    assert err.value.errors()[0]["loc"] == ("rate",)
    ColumnMap(rate=1.0 / FASTEST_STEP, sources=[source])


def test_a_run_of_one_sample_in_a_scored_part_names_no_window_setting():
    """A run too short for any window (one sample) is refused before the fit naming no key:
    no savgol_window would make it fit, and the pre-fit check had named model.savgol_window."""
    from conftest import make_vehicle

    from nnid.config import FossenModelSpec
    from nnid.datasets.splits import Split
    from nnid.errors import NnidInputError
    from nnid.pipeline import check_savgol_window

    def run(n: int, name: str) -> pd.DataFrame:
        t = np.arange(n) * 0.05
        return pd.DataFrame({"t": t, "experiment": name, "u": np.sin(t), "v": 0.0, "r": 0.0,
                             "tau_X": 1.0})  # fmt: skip

    spec = FossenModelSpec(dofs=["u"], savgol_window=0.5)
    split = Split(run(200, "a"), run(1, "b"), run(30, "c"))
    with pytest.raises(NnidInputError) as err:
        check_savgol_window(spec, spec.build(make_vehicle()), split, "model")
    assert err.value.field is None, err.value.field
    assert "'b' has 1 sample" in err.value.message, err.value.message


@pytest.mark.parametrize(
    ("extra", "said"),
    [
        # an IsADirectoryError traceback
        (["--data", "FOLDER"], "is a folder: --follow reads one growing CSV file"),
        # the reader config was ignored without a word, even a missing one
        (["--columns", "nothere.toml"], "field '--columns': --follow reads a CSV in nnid's"),
    ],
)
def test_detect_follow_refuses_a_folder_and_a_reader_config(fixtures, tmp_path, extra, said):
    args = _command("detect", tmp_path, fixtures)
    if extra[0] == "--data":
        args[args.index("--data") + 1] = str(tmp_path)
    else:
        args += extra
    result = CliRunner().invoke(app, [*args, "--follow"])
    assert result.exit_code == 2 and "Traceback" not in result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and said in errors[0], result.output


@pytest.mark.parametrize(
    ("text", "said"),
    [
        ("warmup_s = " + "9" * 5000 + "\n", "digits"),  # beyond Python's integer-string limit
        ("zz = " + "[" * 5000 + "]" * 5000 + "\n", "nested too deep"),
    ],
)
def test_a_toml_file_python_cannot_parse_is_named(tmp_path, text, said):
    from nnid.errors import NnidInputError
    from nnid.validation import read_toml

    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(NnidInputError, match=said) as err:
        read_toml(path)
    assert err.value.source == str(path)


def test_a_json_file_nested_too_deep_or_a_folder_is_named(tmp_path):
    from nnid.errors import NnidInputError
    from nnid.serialization import read_json

    deep = tmp_path / "model.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(NnidInputError, match="nested too deep") as err:
        read_json(deep)
    assert err.value.source == str(deep)
    folder = tmp_path / "monitor.json"
    folder.mkdir()
    with pytest.raises(NnidInputError, match="cannot be read") as err:
        read_json(folder)
    assert err.value.source == str(folder)


@pytest.mark.parametrize(
    ("mutate", "said"),
    [
        # the first of two 'u' columns was read without a word; the whole-log reader refuses it
        pytest.param(
            lambda text: text.replace(",extra\n", ",u\n", 1),
            "the header names column 'u' twice",
            id="column named twice",
        ),
        # a blank label started a run of its own; the whole-log reader refuses it
        pytest.param(
            lambda text: "\n".join(
                line.replace(",h2,", ",,") if k == 30 else line
                for k, line in enumerate(text.split("\n"))
            ),
            "column 'experiment', row 29: empty experiment label",
            id="empty label",
        ),
        # the header's columns were said missing, not the line read as the header
        pytest.param(
            lambda text: "# logged by rov1\n" + text,
            "line 1 ('# logged by rov1') is a comment",
            id="comment line",
        ),
    ],
)
def test_detect_follow_refuses_a_column_named_twice_and_an_empty_label(
    fixtures, tmp_path, mutate, said
):
    path = tmp_path / "stream.csv"
    text = fixtures["octo_log"].assign(extra=0.0).to_csv(index=False)
    path.write_text(mutate(text))
    args = _command("detect", tmp_path, fixtures, data=path, out=tmp_path / "o")
    result = CliRunner().invoke(app, [*args, "--follow"])
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and said in errors[0] and str(path) in errors[0], result.output


@pytest.mark.parametrize(
    "variant", ["byte-order mark", "semicolons and decimal commas", "tabs", "spaces", "blank lines"]
)
def test_detect_follow_reads_a_csv_as_the_whole_log_reader_does(fixtures, tmp_path, variant):
    """A CSV that batch detect reads was refused by --follow: behind a byte-order mark, a
    semicolon or a tab the header's columns were said missing, a space after each comma
    hid all but t, and a blank line ended the watch in "has 0 fields against the header's
    20". Each is now read as the whole-log reader reads it: the same samples, watched alike."""
    from nnid.fault.follow import follow_csv
    from nnid.fault.monitor import ResidualMonitor

    log = fixtures["octo_log"]
    text = log.to_csv(index=False)
    written = {
        "byte-order mark": ("\ufeff" + text).encode(),
        "semicolons and decimal commas": log.to_csv(index=False, sep=";", decimal=",").encode(),
        "tabs": log.to_csv(index=False, sep="\t").encode(),
        "spaces": text.replace(",", ", ").encode(),
        "blank lines": text.replace("\n", "\n\n", 3).encode() + b"\n\n",
    }[variant]
    (tmp_path / "plain.csv").write_text(text)
    (tmp_path / "variant.csv").write_bytes(written)
    assert written != text.encode()
    watched = [
        follow_csv(
            ResidualMonitor.load(fixtures["monitor"]), str(tmp_path / name), 10.0,
            lambda line: None, idle_s=0.0,
        ).trace
        for name in ("plain.csv", "variant.csv")
    ]  # fmt: skip
    assert watched[1].t.size == len(log)
    np.testing.assert_array_equal(watched[1].t, watched[0].t)
    np.testing.assert_array_equal(watched[1].experiment, watched[0].experiment)
    np.testing.assert_array_equal(watched[1].values, watched[0].values)


def test_detect_follow_refuses_a_decimal_point_in_a_file_of_decimal_commas():
    # the whole-log reader reads such a column as text and refuses it: so does --follow
    from nnid.errors import NnidInputError
    from nnid.fault.follow import _numbers

    assert _numbers(["0,5", "x"], [("u", 0)], 0, "s.csv", 2, decimal=",") == {"u": 0.5}
    with pytest.raises(NnidInputError, match="decimal mark is a comma") as err:
        _numbers(["1.5", "x"], [("u", 0)], 3, "s.csv", 2, decimal=",")
    assert (err.value.field, err.value.row) == ("u", 3) and "'1.5'" in str(err.value)
    assert _numbers(["1.5", "x"], [("u", 0)], 3, "s.csv", 2) == {"u": 1.5}


@pytest.mark.parametrize("how", ["truncated", "replaced"])
def test_detect_follow_refuses_a_file_truncated_or_replaced_while_followed(tmp_path, how):
    """A followed log rotated by rename was taken as ended (its old file never grows), and one
    truncated in place read on from the old offset: each is refused at the row to come,
    naming the file."""
    from nnid.errors import NnidInputError
    from nnid.fault.follow import _rows

    path = tmp_path / "live.csv"
    path.write_text("t,u\n0.0,1\n0.1,2\n0.2,3\n")
    rows = _rows(str(path), 0.5)
    assert [next(rows) for _ in range(4)][-1] == ["0.2", "3"]
    if how == "replaced":
        path.rename(tmp_path / "live.csv.1")
        path.write_text("t,u\n0.0,1\n0.1,2\n0.2,3\n0.3,4\n")
    else:
        path.write_text("t,u\n")
    with pytest.raises(NnidInputError, match=f"was {how}") as err:
        next(rows)
    assert err.value.source == str(path) and err.value.row == 3


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")
def test_detect_follow_reads_a_named_pipe_to_its_end(tmp_path):
    """A pipe (a named one, --data /dev/stdin fed by one, <(producer)) has no size: the check
    for a truncated file asked its offset, OSError 'Illegal seek', a traceback with the
    outputs lost. It is read until its writer closes it, as before that check."""
    import threading

    from nnid.fault.follow import _rows

    # its writer closed: its last line is whole without a line end too (it was left out as
    # "a row still being written", as a regular file's is), and no idle wait (idle_s 30 s)
    for last in (b"0.1,2\n", b"0.1,2"):
        pipe = tmp_path / f"live{len(last)}.csv"
        os.mkfifo(pipe)

        def write(pipe=pipe, last=last) -> None:
            with open(pipe, "wb") as writer:  # waits for the reader to open it
                for line in (b"t,u\n", b"0.0,1\n", last):
                    writer.write(line)
                    writer.flush()

        writer = threading.Thread(target=write, daemon=True)
        writer.start()
        said = []
        try:
            start = time.perf_counter()
            rows = list(_rows(str(pipe), 30.0, say=said.append))
            assert rows == [["t", "u"], ["0.0", "1"], ["0.1", "2"]] and not said, said
            assert time.perf_counter() - start < 10.0
        finally:
            writer.join(timeout=5)


def test_detect_follow_names_data_it_cannot_read_and_says_a_cut_last_row(tmp_path, monkeypatch):
    """A followed file that cannot be read, or '-' with no standard input (a service started
    without one: sys.stdin is None), ended in a traceback: each is said against --data. A
    file whose last line has no line end when it stops growing was read as a row, though its
    writer may be half way through a number: it is left out and said."""
    import sys

    from nnid.errors import NnidInputError
    from nnid.fault import follow
    from nnid.fault.follow import _rows

    monkeypatch.setattr(sys, "stdin", None)
    with pytest.raises(NnidInputError, match="no standard input") as err:
        next(_rows("-", 0.0))
    assert err.value.field == "--data"
    path = tmp_path / "locked.csv"
    path.write_text("t,u\n0.0,1\n")
    path.chmod(0)
    if os.access(path, os.R_OK):  # root reads it anyway: the refusal open gives others

        def refused(*args, **kwargs):
            raise PermissionError(13, "Permission denied", str(path))

        monkeypatch.setattr(follow, "open", refused, raising=False)
    with pytest.raises(NnidInputError, match="cannot be read") as err:
        next(_rows(str(path), 0.0))
    assert (err.value.field, err.value.source) == ("--data", str(path))
    path.chmod(0o644)
    monkeypatch.delattr(follow, "open", raising=False)
    path.write_text("t,u\n0.0,1\n0.1,2\n0.2,3.1")  # the writer stopped inside 3.14159
    said: list[str] = []
    assert list(_rows(str(path), 0.0, None, said.append)) == [
        ["t", "u"],
        ["0.0", "1"],
        ["0.1", "2"],
    ]
    assert len(said) == 1 and said[0].startswith("row 2 left out") and "3.1" in said[0]


def test_detect_follow_names_a_row_the_csv_reader_refuses(tmp_path):
    from nnid.errors import NnidInputError
    from nnid.fault.follow import _rows

    path = tmp_path / "cr.csv"
    path.write_text("t,u\n0.0,1\n0.1,2\n0.2,\rx\n0.3,4\n")
    with pytest.raises(NnidInputError, match="is not a CSV row") as err:
        list(_rows(str(path), 0.0))
    assert err.value.source == str(path) and err.value.row == 2


@pytest.mark.parametrize(
    ("config", "old", "new", "field"),
    [
        ("hybrid.toml", "segments = [", "segments = [1e308, ", "model.segments"),
        ("seamor_narx_adam.toml", "hidden = [10]", "hidden = [2000000000]", "model.member.hidden"),
        (
            "seamor_narx_lm.toml",
            "[model]",
            '[sweep]\nrandom = { "model.member.hidden" = [[4], [8]] }\nsamples = 1000000000000\n\n'
            "[model]",
            "sweep.samples",
        ),
    ],
)
def test_sizes_beyond_any_log_are_refused_at_the_config(tmp_path, config, old, new, field):
    # each was a traceback after minutes (an overflow, a 264 GB allocation, a sweep that
    # drew 1e12 settings before its first trial)
    from nnid.config import TrainConfig, load_config
    from nnid.errors import NnidInputError

    text = (REPO / "configs" / config).read_text()
    assert old in text
    path = tmp_path / config
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(NnidInputError) as err:
        load_config(path, TrainConfig)
    assert err.value.field.startswith(field) and err.value.source == str(path)


@pytest.mark.parametrize(
    ("sweep", "field", "said"),
    [
        # "<file>: is not a known field here": no field named at all
        pytest.param('grid = { "" = [1.0, 2.0] }', "sweep.grid", "no option path", id="empty"),
        pytest.param('grid = { "model..x" = [1, 2] }', "sweep.grid", "no option path", id="dots"),
        # searched the [sweep] table itself: every trial fitted the same, one "best" chosen
        pytest.param(
            'grid = { "sweep.seeds" = [[1], [2]] }', "sweep.grid", "not searched", id="itself"
        ),
        # "field 'model.seed': is not a known field here", a key the config never wrote
        pytest.param("seeds = [0, 1]", "sweep.seeds", "model.seed", id="seed of no model"),
        # a value given twice was merged into one setting ("Best of 1 settings"), its seeds'
        # scores counted twice in the mean
        pytest.param(
            'grid = { "model.hidden" = [[4], [4]] }', 'sweep.grid."model.hidden"',
            "model.hidden lists [4] twice",
            id="grid value twice",
        ),
        pytest.param(
            'grid = { "warmup_s" = [1.0, 1.0] }', 'sweep.grid."warmup_s"',
            "warmup_s lists 1.0 twice",
            id="grid number twice",
        ),
        pytest.param(
            'random = { "warmup_s" = [1.0, 2.0, 1.0] }\nsamples = 2', 'sweep.random."warmup_s"',
            "warmup_s lists 1.0 twice", id="random choice twice",
        ),
        # the seeds were used as warm-up lengths: 0 s, 1 s, 2 s
        pytest.param(
            'seeds = [0, 1, 2]\nseed_option = "warmup_s"', "sweep.seed_option", "is no seed",
            id="seed option not a seed",
        ),
    ],
)  # fmt: skip
def test_a_sweep_path_that_names_no_option_is_said_against_the_sweep(
    fixtures, tmp_path, sweep, field, said
):
    config = tmp_path / "sweep.toml"
    config.write_text(f"{TRAIN_TEXT}\n[sweep]\n{sweep}\n")
    data = _write_log(tmp_path, "good", fixtures["demo_log"])
    args = ["sweep", str(config), "--data", str(data), "--vehicle", MINIROV, "--out",
            str(tmp_path / "o")]  # fmt: skip
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    assert f"{config}, field '{field}'" in errors[0] and said in errors[0], result.output
    assert not (tmp_path / "o").exists()


READER = str(REPO / "configs" / "readers" / "tartan_auv.toml")


def _train_with(tmp: Path, fx: dict, **given) -> list[str]:
    return _command("train", tmp, fx, out=tmp / "o", **given)


@pytest.mark.parametrize(
    ("args", "path", "what", "expected"),
    [
        # was "field 'name': is not a known field here", a key of a whole file of another kind
        pytest.param(
            lambda tmp, fx: _train_with(tmp, fx, config=MINIROV),
            MINIROV,
            "vehicle file",
            "not a 'train' config",
            id="vehicle file as config",
        ),
        # was "field 'name': is required but missing"
        pytest.param(
            lambda tmp, fx: _train_with(tmp, fx, vehicle=TRAIN),
            TRAIN,
            "'train' config",
            "not a vehicle file",
            id="config as vehicle",
        ),
        pytest.param(
            lambda tmp, fx: _train_with(tmp, fx, config=READER),
            READER,
            "reader config",
            "not a 'train' config",
            id="reader config as config",
        ),
        # was "field 'sources': is required but missing"
        pytest.param(
            lambda tmp, fx: [*_train_with(tmp, fx), "--columns", MINIROV],
            MINIROV,
            "vehicle file",
            "not a reader config",
            id="vehicle file as reader config",
        ),
        # was "field 'command': is required but missing"
        pytest.param(
            lambda tmp, fx: ["batch", TRAIN, "--out", str(tmp / "o")],
            TRAIN,
            "'train' config",
            "not a batch manifest",
            id="config as manifest",
        ),
    ],
)
def test_one_of_nnids_files_given_where_another_goes_is_named_as_what_it_is(
    fixtures, tmp_path, args, path, what, expected
):
    result = CliRunner().invoke(app, args(tmp_path, fixtures))
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {path}: this is ") and what in errors[0], errors[0]
    assert expected in errors[0] and not (tmp_path / "o").exists(), errors[0]


def test_a_sweep_stops_drawing_once_every_combination_is_drawn(monkeypatch):
    from nnid.config import SweepSpec
    from nnid.scale import sweep

    spec = SweepSpec(random={"model.hidden": [[2], [4]], "model.trainer.lr": [1e-3]}, samples=50)
    few = sweep.settings(spec)
    assert sorted(s["model.hidden"][0] for s in few) == [2, 4]
    draws = []
    real = np.random.default_rng

    class Counting:  # the generator the sweep draws from, counting its draws
        def __init__(self, seed):
            self.rng = real(seed)

        def integers(self, *args, **kwargs):
            draws.append(1)
            return self.rng.integers(*args, **kwargs)

    monkeypatch.setattr(sweep.np.random, "default_rng", Counting)
    # the same two settings, in the same order, however many draws are asked for; and the
    # drawing stops once both are drawn (it made 2 x 100000 draws before the first trial)
    assert sweep.settings(spec.model_copy(update={"samples": 100_000})) == few
    assert 0 < len(draws) < 100


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        (("thresholds", "cusum"), None, "thresholds.cusum"),  # None: the key removed
        (("thresholds", "ewma", "value"), -1.0, "thresholds.ewma.value"),  # alarmed at once
        (("thresholds", "ewma", "value"), "x", "thresholds.ewma.value"),
        (("settings", "time_constant_s"), 0, "settings.time_constant_s"),
        (("settings", "false_alarm_per_hour"), -1, "settings.false_alarm_per_hour"),
        (("calibration",), {}, "calibration.hours"),
        (
            ("measured_false_alarms",),
            {
                "alarms": -1,
                "hours": 1.0,
                "rate_per_hour": 0.0,
                "interval": [0.0, 3.7],
                "confidence": 0.95,
            },
            "measured_false_alarms.alarms",
        ),
    ],
)
def test_a_hand_edited_monitor_is_refused_naming_the_key(fixtures, tmp_path, path, value, field):
    # each was a traceback (KeyError, TypeError) or believed (a negative threshold, a negative
    # target rate printed as such)
    import json
    import shutil

    from nnid.errors import NnidInputError
    from nnid.fault.monitor import ResidualMonitor

    folder = tmp_path / "monitor"
    shutil.copytree(fixtures["monitor"], folder)
    state = json.loads((folder / "monitor.json").read_text())
    node = state
    for key in path[:-1]:
        node = node[key]
    if value is None:
        del node[path[-1]]
    else:
        node[path[-1]] = value
    (folder / "monitor.json").write_text(json.dumps(state))
    with pytest.raises(NnidInputError) as err:
        ResidualMonitor.load(folder)
    assert err.value.field == field and err.value.source == str(folder / "monitor.json")
    ResidualMonitor.load(fixtures["monitor"])  # the file it was copied from loads


def test_a_model_folder_whose_files_are_folders_is_refused(fixtures, tmp_path):
    import shutil

    from nnid.errors import NnidInputError
    from nnid.models.base import load_model

    for name in ("model.json", "tensors.pt"):
        folder = tmp_path / name.split(".")[0]
        shutil.copytree(fixtures["monitor"], folder)
        target = folder / name
        if target.exists():
            target.unlink()
        target.mkdir()
        with pytest.raises(NnidInputError, match="cannot be read") as err:
            load_model(folder)
        assert err.value.source == str(target)


@pytest.mark.parametrize("text", [b"https://example.org/tensors.pt\n", b"(empty)\n", b"Garbage"])
def test_a_tensors_file_of_text_is_refused_naming_it(fixtures, tmp_path, text):
    """Bytes that are no zip archive are read as a legacy pickle, whose unpickler failed on
    text with its internals' KeyError, IndexError or struct.error: a traceback, exit 1."""
    import shutil

    folder = tmp_path / "model"
    shutil.copytree(fixtures["monitor"], folder)
    (folder / "tensors.pt").write_bytes(text)
    args = _command("detect", tmp_path, fixtures, model=folder, out=tmp_path / "o")
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2, result.output
    assert f"error: {folder / 'tensors.pt'}: damaged" in result.output


@pytest.mark.parametrize(("text", "said"), [("u,,w", "empty name"), ("run0,run0", "run0 twice")])
def test_an_option_list_with_an_empty_or_repeated_name_is_refused(text, said):
    from nnid.errors import NnidInputError
    from nnid.runs import names

    with pytest.raises(NnidInputError, match=said) as err:
        names(text, "--validation")
    assert err.value.field == "--validation"
    assert names(" u , w ", "--dofs") == ["u", "w"] and names(None, "--dofs") == []  # not given


def test_a_sequence_fit_needs_only_its_steps_velocities(fixtures, tmp_path):
    # the early velocity check reads a sequence's DOFs, not the six of the default dofs
    log = fixtures["demo_log"].drop(columns=["u", "v"])
    data = _write_log(tmp_path, "heave only", log)
    config = tmp_path / "seq.toml"
    config.write_text(
        'kind = "train"\nwarmup_s = 2.0\n[split]\nby = "experiment"\nvalidation = ["run1"]\n'
        'test = ["run2"]\n[model]\nkind = "fossen"\ntrainer = { kind = "ls" }\n'
        '[[model.sequence]]\nexperiments = ["run0"]\ndofs = ["w"]\n'
        'unknowns = ["Z_wdot", "Z:w*abs(w)"]\n'
    )
    args = ["train", str(config), "--data", str(data), "--vehicle", MINIROV]
    done = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    assert done.exit_code == 0, done.output
    args[1] = str(tmp_path / "no_u.toml")
    Path(args[1]).write_text(config.read_text().replace('dofs = ["w"]', 'dofs = ["u", "w"]'))
    done = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out2")])
    assert done.exit_code == 2 and "field 'u'" in done.output, done.output


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        ("cut to 3", "other shapes than the monitor's 6 channels"),
        ("padded to 9", "other shapes than the monitor's 6 channels"),
        ("negative correlation time", "correlation time that is not positive"),
        ("null in whiten", "non-finite"),
    ],
)
def test_a_monitor_whose_arrays_do_not_fit_the_model_is_refused(fixtures, tmp_path, edit, said):
    """Arrays cut to 3 channels (consistent with each other) were believed: the compiled
    kernel read past them and detect said "0 alarm(s)"; 5 or 9 ended in a broadcast
    traceback in the isolation."""
    import json
    import shutil

    from nnid.errors import NnidInputError
    from nnid.fault.monitor import ResidualMonitor

    folder = tmp_path / "monitor"
    shutil.copytree(fixtures["monitor"], folder)
    state = json.loads((folder / "monitor.json").read_text())
    k = {"cut to 3": 3, "padded to 9": 9}.get(edit)
    if k is not None:
        for key in ("mu", "sigma"):
            state[key] = (state[key] + [0.0] * 9)[:k]
        for key in ("whiten", "s_inv"):
            state[key] = [(row + [0.0] * 9)[:k] for row in (state[key] + [[0.0] * 9] * 9)[:k]]
    elif edit == "negative correlation time":
        state["correlation_time"] = -2.0
    else:
        state["whiten"][0][0] = None  # read as NaN, and believed by the kernel
    (folder / "monitor.json").write_text(json.dumps(state))
    with pytest.raises(NnidInputError, match=said) as err:
        ResidualMonitor.load(folder)
    assert err.value.source == str(folder / "monitor.json")


def test_a_monitor_whose_statistic_never_rose_loads_as_it_was_saved(fixtures, tmp_path):
    # a CUSUM that never exceeds its allowance on healthy data gets the threshold 2 x 0 = 0:
    # written by nnid, so read back by it
    import json
    import shutil

    from nnid.fault.monitor import ResidualMonitor

    folder = tmp_path / "monitor"
    shutil.copytree(fixtures["monitor"], folder)
    state = json.loads((folder / "monitor.json").read_text())
    state["thresholds"]["cusum"]["value"] = 0.0
    (folder / "monitor.json").write_text(json.dumps(state))
    assert ResidualMonitor.load(folder).threshold_values[1] == 0.0


def test_a_run_the_config_leaves_out_may_be_sampled_as_it_likes(fixtures, tmp_path):
    """The sampling check reads the runs data.experiments keeps: run1's rate change refused
    the whole fit though the config left run1 out."""
    config, data = _narx_on_a_rate_change(tmp_path, fixtures["demo_log"])
    kept = NARX_TRAIN.replace(
        'kind = "train"\n', 'kind = "train"\n[data]\nexperiments = ["run0", "run2"]\n'
    )
    config.write_text(kept.replace('validation = ["run2"]', 'validation = ["run2"]\ntest = []'))
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["train", str(config), "--data", str(data), "--out", str(out)])
    assert result.exit_code == 0, result.output
    config.write_text(NARX_TRAIN)
    out = tmp_path / "out2"
    result = CliRunner().invoke(app, ["train", str(config), "--data", str(data), "--out", str(out)])
    assert result.exit_code == 2 and "rate_change.csv" in result.output
    # the row named is the file's, with runs left out before it (it was the row's position
    # among the runs kept, row 1); run1's median interval is its 100-Hz part's, so its second
    # sample, 0.05 s after the first, is the first one off
    table = pd.read_csv(data)
    first_off = int(np.flatnonzero((table["experiment"] == "run1").to_numpy())[1])
    keep = 'kind = "train"\n[data]\nexperiments = ["run1", "run2"]\n'
    config.write_text(NARX_TRAIN.replace('kind = "train"\n', keep))
    result = CliRunner().invoke(app, ["train", str(config), "--data", str(data), "--out", str(out)])
    assert result.exit_code == 2 and f"row {first_off}:" in result.output, result.output


def test_a_value_where_a_table_goes_says_it_is_a_table(tmp_path):
    """`data = "log.csv"` where a [data] table goes said "Input should be a valid dictionary
    or object to extract fields from", which says nothing of TOML."""
    from nnid.config import TrainConfig, load_config
    from nnid.errors import NnidInputError

    path = tmp_path / "c.toml"
    path.write_text(TRAIN_TEXT.replace("[split]", 'split = "a.csv"\n[x]'))
    with pytest.raises(NnidInputError, match=r"is a table \(\[split\] with its keys below it\)"):
        load_config(path, TrainConfig)


@pytest.mark.parametrize("command", ["train", "compare", "loop"])
def test_a_missing_vehicle_option_is_not_blamed_on_the_config(command, tmp_path):
    """`--vehicle` names no key of the config: the error said "<config>, field '--vehicle'"."""
    config = tmp_path / "run.toml"
    compare = 'kind = "compare"\n[[models]]\nkind = "fossen"\n'
    config.write_text({"train": TRAIN_TEXT, "compare": compare, "loop": 'kind = "loop"\n'}[command])
    data = _write_log(tmp_path, "good", _demo_log())
    args = [command, str(config), "--data", str(data), "--vehicle", str(tmp_path / "nothere.toml")]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    assert "field '--vehicle'" in errors[0] and "run.toml" not in errors[0], errors[0]


def test_one_table_where_a_list_of_tables_goes_is_named(tmp_path):
    """`[thrusters]` for `[[thrusters]]` said "Input should be a valid list", naming no field."""
    import tomllib

    from nnid.config import CompareConfig, load_config
    from nnid.errors import NnidInputError
    from nnid.vehicle import vehicle_from_dict

    data = tomllib.loads(GOOD_VEHICLE + _THRUSTER.replace("[[thrusters]]", "[thrusters]"))
    with pytest.raises(NnidInputError, match=re.escape("[[thrusters]]")) as err:
        vehicle_from_dict(data, source="probe.toml")
    assert err.value.field == "thrusters" and err.value.source == "probe.toml"
    path = tmp_path / "c.toml"
    path.write_text('kind = "compare"\n[models]\nkind = "fossen"\n')
    with pytest.raises(NnidInputError, match=re.escape("[[models]]")) as err:
        load_config(path, CompareConfig)
    assert err.value.field == "models" and err.value.source == str(path)


def test_samples_missing_in_a_run_train_predicts_are_said_against_the_log(tmp_path):
    """A run with 30 s of samples missing: train's free run refused it once fitted, naming the
    config (its with_source) for the log's column t and row."""
    log = _demo_log()
    log["t"] = log["t"].where(log.index < 100, log["t"] + 30.0)
    data = _write_log(tmp_path, "gap", log)
    args = ["train", TRAIN, "--data", str(data), "--vehicle", MINIROV]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {data}, column 't', row 100:"), errors[0]


_COMPARE_GAP = """kind = "compare"
warmup_s = 1.0
[data]
experiments = ["run1", "run2"]
[split]
by = "experiment"
train = ["run1"]
validation = ["run2"]
[[models]]
kind = "fossen"
unknowns = ["damping"]
trainer = { kind = "ls", filter_lambda = 1.0 }
"""


def test_samples_missing_in_a_run_compare_predicts_are_said_against_the_log(tmp_path):
    """Samples missing in a held-out run: compare's prediction refused it once every model
    was fitted, naming the config for the log's column t. Now the log and its row (the file's,
    with run0 left out by data.experiments), before any fit; a gap in a run only fitted is
    no error (compare never steps it)."""
    config = tmp_path / "compare.toml"
    config.write_text(_COMPARE_GAP)
    log = _demo_log()
    held = log.index[log["experiment"] == "run2"]
    log.loc[held[150] :, "t"] += 30.0  # the file's row held[150] comes 30 s after the last
    data = _write_log(tmp_path, "held_gap", log)
    args = ["compare", str(config), "--data", str(data), "--vehicle", MINIROV]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out")])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {data}, column 't', row {held[150]}:"), errors[0]
    assert "fitting" not in result.output  # said before any fit
    fitted_only = tmp_path / "compare_train_gap.toml"
    swapped = 'train = ["run2"]\nvalidation = ["run1"]'
    fitted_only.write_text(_COMPARE_GAP.replace('train = ["run1"]\nvalidation = ["run2"]', swapped))
    args = ["compare", str(fitted_only), "--data", str(data), "--vehicle", MINIROV]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "out2")])
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize(
    ("options", "field", "said"),
    [
        # "Input should be less than or equal to 0.5": a NaN is no number above it
        (["--alpha", "nan"], "--alpha", "a finite number at least 1e-12 and at most 0.5"),
        (["--alpha", "0.7"], "--alpha", "a finite number at least 1e-12 and at most 0.5"),
        # blamed "good.csv, field 'validation'", a key of no file
        (["--validation", "run0,run1,run2"], "--validation", "every experiment is held out"),
    ],
)
def test_a_loop_option_is_named_as_the_option(fixtures, tmp_path, options, field, said):
    args = [*_command("loop", tmp_path, fixtures), *options]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    assert errors[0].startswith(f"error: field '{field}': {said}"), errors[0]
    assert not fixtures["out"].exists()


@pytest.mark.parametrize("follow", [False, True])
@pytest.mark.parametrize("window", ["nan", "inf", "0.1"])
def test_a_detect_window_is_named_as_the_option(fixtures, tmp_path, window, follow):
    """--window nan was typer's box, "Input should be greater than or equal to 0.5", and
    --window inf was taken (every alarm waited for its run's end): each is now nnid's one line
    naming the option, before the model or the log is read."""
    args = [*_command("detect", tmp_path, fixtures), "--window", window]
    result = CliRunner().invoke(app, [*args, "--follow"] if follow else args)
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    said = f"error: field '--window': a finite number at least 0.5 is expected, not {window}"
    assert errors[0] == said, errors[0]
    assert not fixtures["out"].exists()


@pytest.mark.parametrize(
    ("idle", "follow", "said"),
    [
        ("-1", True, "a finite number at least 0 is expected, not -1.0"),
        ("nan", True, "a finite number at least 0 is expected, not nan"),  # never compared
        ("0", False, "applies to --follow only (drop it, or add --follow)"),  # no wait
    ],
)
def test_a_detect_idle_time_is_named_as_the_option(fixtures, tmp_path, idle, follow, said):
    """--idle-s, how long a followed file may stop growing before it has ended: a negative
    or NaN time, or one given without --follow, is one line naming the option, before the
    model or the log is read."""
    args = [*_command("detect", tmp_path, fixtures), "--idle-s", idle]
    result = CliRunner().invoke(app, [*args, "--follow"] if follow else args)
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert errors == [f"error: field '--idle-s': {said}"], result.output
    assert not fixtures["out"].exists()


@pytest.mark.parametrize(("name", "said"), [("   ", "visible character"), ("a\nb", "one line")])
def test_vehicle_name_option_is_named_as_the_option(tmp_path, name, said):
    # blamed "v1.toml, field 'name'", a file not yet written; a newline was written
    target = tmp_path / "v1.toml"
    args = ["vehicle", "--out", str(target), "--mass", "10", "--size", "0.4x0.3x0.2"]
    result = CliRunner().invoke(app, [*args, "--name", name])
    assert result.exit_code == 2, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and errors[0].startswith("error: field '--name': "), result.output
    assert said in errors[0] and "v1.toml" not in errors[0] and not target.exists()


@pytest.mark.parametrize(
    ("direction", "unit"),
    [
        # the sum of squares overflowed to inf: a direction of zeros, simulate exited 0
        ([1e300, 1e300, 0.0], [2**-0.5, 2**-0.5, 0.0]),
        # it underflowed to 0: refused as a zero vector
        ([1e-300, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ([0.0, -3.0, 4.0], [0.0, -0.6, 0.8]),
    ],
)
def test_a_thruster_direction_is_normalised_at_any_scale(direction, unit):
    from nnid.vehicle import vehicle_from_dict

    thruster = {"name": "h1", "position": [0.1, 0.0, 0.0], "direction": direction,
                "curve": {"kind": "signed_quadratic", "k": 40.0}}  # fmt: skip
    data = {"name": "probe", "mass": 11.5, "inertia": [0.16, 0.16, 0.16], "thrusters": [thruster]}
    got = vehicle_from_dict(data, source="probe.toml").thrusters[0].direction
    np.testing.assert_allclose(got, unit, rtol=1e-15, atol=1e-15)


@pytest.mark.parametrize(
    ("curve", "field"),
    [
        ({"kind": "signed_quadratic", "k": 0.0}, "thrusters.0.curve.k"),
        ({"kind": "poly", "coeffs": [0.0, 0.0, 0.0]}, "thrusters.0.curve.coeffs"),
        ({"kind": "table", "cmd": [-1.0, 1.0], "thrust": [0.0, 0.0]}, "thrusters.0.curve.thrust"),
        # docs/vehicle_file.md: a reversed propeller pushes against its direction
        ({"kind": "signed_quadratic", "k": -40.0}, None),
        ({"kind": "poly", "coeffs": [0.0, -0.5]}, None),
    ],
)
def test_a_thrust_curve_of_no_thrust_is_refused_naming_it(curve, field):
    from nnid.errors import NnidInputError
    from nnid.vehicle import vehicle_from_dict

    thruster = {"name": "h1", "position": [0.1, 0.0, 0.0], "direction": [1.0, 0.0, 0.0],
                "curve": curve}  # fmt: skip
    data = {"name": "probe", "mass": 11.5, "inertia": [0.16, 0.16, 0.16], "thrusters": [thruster]}
    if field is None:
        vehicle_from_dict(data, source="probe.toml")
        return
    with pytest.raises(NnidInputError, match="no thrust at any command") as err:
        vehicle_from_dict(data, source="probe.toml")
    assert err.value.field == field and err.value.source == "probe.toml"


@pytest.mark.parametrize(("deadband", "refused"), [(1.0, True), (0.05, False)])
def test_a_deadband_as_wide_as_every_command_is_refused(deadband, refused):
    """A thruster vehicle's deadband is in command units: one as wide as the largest command
    of its thrusters' cmd_min and cmd_max swallows every command (no thrust, ever)."""
    import tomllib

    from nnid.errors import NnidInputError
    from nnid.vehicle import vehicle_from_dict

    data = tomllib.loads(GOOD_VEHICLE + _THRUSTER)
    data["deadband"] = deadband
    if not refused:
        assert vehicle_from_dict(data, source="probe.toml").deadband == deadband
        return
    with pytest.raises(NnidInputError, match="not below the largest command") as err:
        vehicle_from_dict(data, source="probe.toml")
    assert err.value.field == "deadband" and err.value.source == "probe.toml"


def test_a_simulated_log_the_contract_refuses_is_said_against_the_config(tmp_path):
    """A noise level within its bound can still make positions no log may hold: the refusal
    named the --out file, which is not written; now the config, and the column."""
    from nnid.datasets.log import MAX_DISTANCE

    config = tmp_path / "noisy.toml"
    config.write_text(
        'kind = "simulate"\nvehicle = "seamor"\n[[experiments]]\nname = "e1"\nduration = 1.0\n'
        f'[measurement]\nkind = "mocap"\nposition_noise = {MAX_DISTANCE / 2:g}\n'
    )
    out = tmp_path / "sim.csv"
    result = CliRunner().invoke(app, ["simulate", str(config), "--out", str(out)])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {config}: the log contract refuses "), errors[0]
    assert "column 'x'" in errors[0] and str(out) not in errors[0] and not out.exists()


class _Fitted(Exception):
    """Raised in place of a fit: the run got as far as fitting a model."""


_WINDOW = "savgol_window = 4.0\n"  # 81 samples at 20 Hz: a training block's 180 hold it
_SPLIT = 'kind = "%s"\nwarmup_s = 1.0\n[split]\nby = "auto"\nfractions = [0.6, 0.2, 0.2]\n'


@pytest.mark.parametrize(
    ("command", "models", "said"),
    [
        pytest.param("train", f'[model]\nkind = "fossen"\n{_WINDOW}', "model.savgol_window",
                     id="fossen"),
        pytest.param("train", f'[model]\nkind = "hybrid"\n{_WINDOW}', "model.savgol_window",
                     id="hybrid"),
        pytest.param("train", f'[model]\nkind = "synthesis"\n{_WINDOW}', "model.savgol_window",
                     id="synthesis"),
        pytest.param("train", f'[model]\nkind = "sindy"\nmode = "control"\n{_WINDOW}',
                     "model.savgol_window", id="sindy control"),
        pytest.param("train", '[model]\nkind = "ensemble"\nseeds = [0, 1]\n[model.member]\n'
                     f'kind = "hybrid"\n{_WINDOW}', "model.member.savgol_window", id="ensemble"),
        pytest.param("compare", f'[[models]]\nkind = "fossen"\n[[models]]\nkind = "hybrid"\n'
                     f"{_WINDOW}", "models.1.savgol_window", id="compare"),
        # Caccia's residual derives them with its step-2 filter, its own key
        pytest.param("train", '[model]\nkind = "caccia"\nvelocity_window = 4.0\n',
                     "model.velocity_window", id="caccia"),
        # a window the runs hold, and a filtered damping fit that derives no acceleration: fitted
        pytest.param("train", '[model]\nkind = "hybrid"\nsavgol_window = 2.0\n', None,
                     id="hybrid, a window that fits"),
        pytest.param("train", f'[model]\nkind = "synthesis"\nfilter_lambda = 1.0\n{_WINDOW}',
                     None, id="synthesis, filtered"),
    ],
)  # fmt: skip
def test_a_savgol_window_longer_than_a_scored_run_is_refused_before_any_fit(
    fixtures, tmp_path, monkeypatch, command, models, said
):
    """A window longer than the 3-s validation blocks was refused once the model was fitted,
    as its residual was scored there (a hybrid's training of minutes, then exit 2): now before
    any fit, for every model kind whose scores derive accelerations with it."""
    from nnid import pipeline

    def fitted(*args, **kwargs):
        raise _Fitted

    monkeypatch.setattr(pipeline, "fit_model", fitted)
    config = tmp_path / "window.toml"
    config.write_text(_SPLIT % command + models)
    args = _command(command, tmp_path, fixtures, config=config, out=tmp_path / "o")
    result = CliRunner().invoke(app, args)
    if said is None:
        assert isinstance(result.exception, _Fitted), result.output
        return
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {config}, field '{said}': the validation part's ")
    assert "too few for the Savitzky-Golay window of 81 samples" in errors[0], errors[0]
    assert errors[0].endswith(f"give a shorter {said.split('.')[-1]} or a longer run"), errors[0]


def test_each_model_kind_says_where_it_derives_accelerations_with_its_window():
    """check_savgol_window asks the model (acceleration_parts), not the config's kind: the
    parts and DOFs whose accelerations its fit and scores derive with its own window and
    order; none for a filtered damping fit and a network; Caccia's residual in its one DOF
    with its step-2 filter, named by its key velocity_window (it returned none, so a window too
    long for a held-out run was refused only in scoring the fitted model, naming savgol_window,
    a key its config has not); an ensemble's members' held-out parts, named under its member,
    only where nnid train scores them."""
    from conftest import make_vehicle

    from nnid.datasets.splits import PARTS
    from nnid.models import base
    from nnid.physics.dofs import DOFS

    vehicle = make_vehicle()

    def said(kind, members_scored=False, **kw):
        derived = base.model_class(kind)(**kw).acceleration_parts(members_scored)
        if derived is None:
            return None
        return derived.parts, tuple(derived.dofs), derived.window_s, derived.order, derived.field

    fossen = said("fossen", vehicle=vehicle, dofs=["u", "r"], savgol_window=2.5, savgol_order=3)
    assert fossen == (PARTS, ("u", "r"), 2.5, 3, "savgol_window")
    steps = [{"experiments": ["a"], "dofs": ["v"], "unknowns": ["Y_vdot"]},
             {"experiments": ["b"], "dofs": ["r"], "unknowns": ["N_rdot"]}]  # fmt: skip
    assert said("fossen", vehicle=vehicle, sequence=steps)[1] == ("v", "r")  # before its fit
    assert said("hybrid", vehicle=vehicle, dofs=["w"])[:2] == (PARTS, ("w",))
    for kind in ("synthesis", "sindy"):  # τ̄ reads all six accelerations
        assert said(kind, vehicle=vehicle)[:2] == (PARTS, tuple(DOFS)), kind
        assert said(kind, vehicle=vehicle, filter_lambda=1.0) is None, kind
    control = said("sindy", vehicle=vehicle, mode="control", filter_lambda=1.0)
    assert control[:2] == (("train", "validation"), tuple(DOFS))  # its regression's targets
    caccia = said("caccia", vehicle=vehicle, dof="r", velocity_window=3.0, velocity_order=3)
    assert caccia == (PARTS, ("r",), 3.0, 3, "velocity_window")
    assert said("narx", inputs=["tau_X"], outputs=["u"]) is None
    member = base.model_class("hybrid")(vehicle=vehicle, dofs=["u"], savgol_window=3.0)
    assert said("ensemble", model=member) is None  # compare scores no member
    held_out = said("ensemble", members_scored=True, model=member)
    assert held_out == (("validation", "test"), ("u",), 3.0, 4, "member.savgol_window")


def test_a_log_with_the_accelerations_a_model_reads_is_not_judged_against_its_window():
    """Only the DOFs whose accelerations the model reads decide: a surge-only Fossen fit on a
    log that logs du derives none, so validation runs shorter than its window are no fault,
    whatever other DOFs lack; without du the window is refused, naming the part's run."""
    from conftest import make_vehicle

    from nnid.config import FossenModelSpec
    from nnid.datasets.splits import Split
    from nnid.errors import NnidInputError
    from nnid.pipeline import check_savgol_window

    def run(n: int, name: str) -> pd.DataFrame:
        t = np.arange(n) * 0.05
        return pd.DataFrame({"t": t, "experiment": name, "u": np.sin(t), "du": np.cos(t),
                             "v": 0.0, "r": 0.0, "tau_X": 1.0})  # fmt: skip

    spec = FossenModelSpec(dofs=["u"], savgol_window=4.0)  # 81 samples at 20 Hz
    model = spec.build(make_vehicle())
    split = Split(run(200, "a"), run(30, "b"), run(30, "c"))
    check_savgol_window(spec, model, split, "model")  # du logged: nothing derived
    unlogged = Split(*(split[p].drop(columns="du") for p in ("train", "validation", "test")))
    with pytest.raises(NnidInputError) as err:
        check_savgol_window(spec, model, unlogged, "model")
    assert err.value.field == "model.savgol_window"
    assert err.value.message.startswith("the validation part's experiment 'b' has 30 samples")


def test_every_character_splitlines_breaks_at_is_refused_in_a_name_and_a_run_label(tmp_path):
    """U+2028 and U+2029 (line and paragraph separators) are no control characters: a run
    labelled "dive<U+2028>1" was read, and every report line naming it split in two."""
    from nnid.datasets.readers import read_log
    from nnid.errors import NnidInputError
    from nnid.validation import one_line

    breaks = [c for c in map(chr, range(0x110000)) if len(f"a{c}b".splitlines()) > 1]
    assert {"\n", "\r", "\x85", "\u2028", "\u2029"} <= set(breaks)
    log = pd.DataFrame({"t": [0.0, 0.1, 0.0, 0.1], "u": 0.0, "tau_X": 1.0})
    for c in breaks:
        with pytest.raises(ValueError, match="one line of text"):
            one_line(f"dive{c}1")
        path = tmp_path / "log.parquet"
        log.assign(experiment=["run0", "run0", f"dive{c}1", f"dive{c}1"]).to_parquet(path)
        with pytest.raises(NnidInputError) as err:
            read_log(path)
        said = str(err.value)
        assert said.startswith(f"{path}, column 'experiment', row 2: experiment label"), said
        assert repr(f"dive{c}1") in said, said


@pytest.mark.parametrize(
    ("written", "simulation", "said"),
    [
        ("replay_autopilot = true\n", False, "it is a log file"),
        ("replay_autopilot = true\n", True, "its simulate config has no [autopilot] table"),
        ("", False, None),  # the default replays where the log was flown under one: no word
        ("replay_autopilot = false\n", False, None),
    ],
)
def test_a_written_autopilot_replay_on_a_log_flown_under_none_is_said(
    tmp_path, written, simulation, said
):
    """replay_autopilot = true on a log file was not applied, and only comparison.json's
    autopilot_replay: false showed it; the free runs compared were open loop."""
    from nnid.config import CompareConfig, SimulateConfig, load_config
    from nnid.datasets.cleaning import CleaningReport
    from nnid.pipeline import Inputs, unreplayed

    config = tmp_path / "cmp.toml"
    config.write_text(f'kind = "compare"\n{written}[[models]]\nkind = "fossen"\n')
    cfg = load_config(config, CompareConfig)
    sim = load_config(SIMULATE, SimulateConfig) if simulation else None
    assert sim is None or sim.autopilot is None
    inputs = Inputs(pd.DataFrame({"t": [0.0]}), CleaningReport(), simulation=sim)
    warned = unreplayed(cfg, inputs, None)
    if said is None:
        assert warned == []
        return
    assert len(warned) == 1 and warned[0].startswith("replay_autopilot = true, but the log")
    assert said in warned[0] and "open loop" in warned[0], warned[0]
    assert unreplayed(cfg, inputs, replay=object()) == []  # replayed: nothing to say


def _reader_config(log: pd.DataFrame, file: str) -> str:
    """A reader config mapping each column of ``log`` (in ``file``) to itself."""
    columns = "".join(f'{c} = "{c}"\n' for c in log.columns if c not in ("t", "experiment"))
    return (
        f'name = "demo"\nexperiment = "experiment"\n[[sources]]\nfile = "{file}"\n'
        f'time = "t"\n[sources.columns]\n{columns}'
    )


@pytest.mark.parametrize(
    ("old", "new", "field", "said"),
    [
        ('name = "demo"', 'name = "demo\\nlog"', "name", "one line"),
        ('name = "demo"', 'name = "demo\\u2028log"', "name", "one line"),
        ('name = "demo"', 'name = "  "', "name", "visible character"),
        ('file = "good.csv"', 'file = "good\\t.csv"', "sources.0.file", "one line"),
    ],
)
def test_a_reader_configs_name_and_file_are_one_visible_line(
    fixtures, tmp_path, old, new, field, said
):
    """A reader config's name heads the cleaning report (cleaning.md's title: "demo" and
    "log" on two lines) and its files are said in the report's lines: both were taken
    whatever they held, exit 0."""
    fixtures["demo_log"].to_csv(tmp_path / "good.csv", index=False)
    config = tmp_path / "map.toml"
    config.write_text(_reader_config(fixtures["demo_log"], "good.csv").replace(old, new))
    args = ["inspect", str(tmp_path), "--columns", str(config), "--out", str(tmp_path / "o")]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 2 and "Traceback" not in result.output, result.output
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {config}, field '{field}': "), errors[0]
    assert said in errors[0] and not (tmp_path / "o").exists(), errors[0]


def test_detect_says_a_velocity_it_derived_from_the_pose(fixtures, tmp_path):
    """A log without w: detect derived it from the pose, where the monitor had been calibrated
    on a logged w (another noise in the residual it watches), and said nothing of it."""
    import json

    data = _write_log(tmp_path, "no w", fixtures["octo_log"].drop(columns="w"))
    result = CliRunner().invoke(
        app, _command("detect", tmp_path, fixtures, data=data, out=tmp_path / "o")
    )
    assert result.exit_code == 0, result.output
    said = [line for line in result.output.splitlines() if line.startswith("derive velocities:")]
    assert len(said) == 1 and said[0].startswith("derive velocities: w from pose"), result.output
    notes = json.loads((tmp_path / "o" / "detect.json").read_text())["notes"]
    assert said[0] in notes, notes
    full = _write_log(tmp_path, "good", fixtures["octo_log"])
    kept = CliRunner().invoke(
        app, _command("detect", tmp_path, fixtures, data=full, out=tmp_path / "k")
    )
    assert kept.exit_code == 0 and "derive velocities" not in kept.output, kept.output
    assert "<h2>Notes on the log</h2>" not in (tmp_path / "k" / "report.html").read_text()


def test_detects_report_shows_the_runs_notes(fixtures, tmp_path):
    """report.html showed none of the notes detect said of the log (a velocity derived from
    the pose, rows lost, a wandering clock): they were on the console and in detect.json
    only."""
    import html
    import json

    data = _write_log(tmp_path, "no w", fixtures["octo_log"].drop(columns="w"))
    result = CliRunner().invoke(
        app, _command("detect", tmp_path, fixtures, data=data, out=tmp_path / "o")
    )
    assert result.exit_code == 0, result.output
    notes = json.loads((tmp_path / "o" / "detect.json").read_text())["notes"]
    page = (tmp_path / "o" / "report.html").read_text()
    assert notes and "<h2>Notes on the log</h2>" in page
    assert all(f"<li>{html.escape(n)}</li>" in page for n in notes), notes


@pytest.mark.parametrize("command", ["train", "loop"])
def test_a_copied_config_whose_simulation_stayed_behind_runs_on_data(
    fixtures, tmp_path, monkeypatch, command
):
    """--data replaces the data a config names (its log, simulation or campaign), which is
    then not read; a shipped config copied to another folder (seamor_ls.toml, its simulate
    file left behind) was refused for it ("field 'data.simulate': no such file or folder")
    on the very log it was given. Without --data the missing file is still named."""
    from nnid import pipeline, runs

    def fitted(*args, **kwargs):
        raise _Fitted

    monkeypatch.setattr(pipeline, "fit_model", fitted)
    monkeypatch.setattr(runs, "residual_loop_run", fitted)
    behind = "[data]\nsimulate = 'left_behind.toml'\n"
    text = (
        TRAIN_TEXT.replace("[split]", f"{behind}\n[split]")
        if command == "train"
        else (f'kind = "loop"\n{behind}')
    )
    config = tmp_path / "copied.toml"
    config.write_text(text)
    args = _command(command, tmp_path, fixtures, config=config, out=tmp_path / "o")
    result = CliRunner().invoke(app, args)
    assert isinstance(result.exception, _Fitted), result.output
    at = args.index("--data")
    result = CliRunner().invoke(app, args[:at] + args[at + 2 :])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {config}, field 'data.simulate': no such file"), errors


def test_a_fossen_fit_of_no_unknowns_says_it_estimated_nothing(fixtures, tmp_path):
    """unknowns = [] fitted nothing, exited 0 without a word, and metrics.json said
    "trainer": "ls" as though least squares had run. The model is the vehicle file as
    written: said on the console and in metrics.json, and no trainer recorded."""
    import json

    config = tmp_path / "as_written.toml"
    config.write_text(TRAIN_TEXT.replace('unknowns = ["added_mass", "damping"]', "unknowns = []"))
    args = _command("train", tmp_path, fixtures, config=config, out=tmp_path / "o")
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert "warning: the fit has no unknowns (unknowns = []): nothing is estimated" in said
    metrics = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert metrics["trainer"] is None and metrics["params"] == {}
    assert any(w.startswith("the fit has no unknowns") for w in metrics["warnings"])


def _bare_vehicle_and_log(tmp_path: Path) -> tuple[Path, Path]:
    """The demo's vehicle file with its damping tables cut off, and the demo log, written."""
    text = Path(MINIROV).read_text()
    vehicle = tmp_path / "bare.toml"
    vehicle.write_text(text[: text.index("[damping")])
    data = tmp_path / "good.parquet"
    _demo_log().to_parquet(data)
    return vehicle, data


@pytest.mark.parametrize("unknowns", ['["damping"]', '["added_mass", "damping"]'])
def test_damping_asked_of_a_vehicle_file_with_none_is_one_error(tmp_path, unknowns):
    """unknowns = ["damping"] on a vehicle file of no damping terms warned "nothing is
    estimated" and exited 0; beside added_mass, the damping asked for was dropped without a
    word. One error (exit 2) naming the config key, the vehicle file and what it needs."""
    vehicle, data = _bare_vehicle_and_log(tmp_path)
    config = tmp_path / "damping.toml"
    config.write_text(
        TRAIN_TEXT.replace('unknowns = ["added_mass", "damping"]', f"unknowns = {unknowns}")
    )
    args = [
        "train",
        str(config),
        "--data",
        str(data),
        "--vehicle",
        str(vehicle),
        "--out",
        str(tmp_path / "o"),
    ]
    result = CliRunner().invoke(app, args)
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    said = " ".join(result.output.split())
    assert said.startswith(f"error: {config}, field 'model.unknowns': 'damping' asks"), said
    assert f"vehicle file {vehicle}, which declares no damping term" in said
    assert "[damping] model" in said and "leave 'damping' out of unknowns" in said
    assert not (tmp_path / "o").exists()


def test_damping_asked_by_default_of_a_vehicle_file_with_none_is_said_not_refused(tmp_path):
    """The default unknowns (added_mass and damping) ask for damping on any vehicle: on one of
    no damping terms the added mass is estimated and the damping said not to be (it was
    dropped without a word), where written in the config it is refused (above)."""
    vehicle, data = _bare_vehicle_and_log(tmp_path)
    config = tmp_path / "default.toml"
    config.write_text(TRAIN_TEXT.replace('unknowns = ["added_mass", "damping"]\n', ""))
    assert "unknowns" not in config.read_text()
    out = tmp_path / "o"
    args = ["train", str(config), "--data", str(data), "--vehicle", str(vehicle), "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())
    assert "which declares no damping term" in said and "no damping is estimated" in said
    params = json.loads((out / "metrics.json").read_text())["params"]
    assert params and all(k.endswith("dot") for k in params), params  # added mass only


def test_damping_of_other_forces_only_is_refused_by_the_fit_itself():
    """Given in Python, a fit of the heave equation with unknowns ["damping"] on a vehicle
    that declares surge damping only is refused too, naming the vehicle by its name."""
    from nnid.errors import NnidInputError
    from nnid.models.parametric import ParametricModel
    from nnid.vehicle import load_vehicle

    veh = load_vehicle(MINIROV)
    surge = veh.model_copy(
        update={"damping": veh.damping.model_copy(update={"coefficients": {"X:u": -13.7}})}
    )
    with pytest.raises(NnidInputError) as err:
        ParametricModel(surge, ["damping"], dofs=["w"]).fit(_demo_log())
    assert err.value.field == "unknowns"
    assert (
        "vehicle 'minirov', which declares damping terms of X only, none of the Z"
        in err.value.message
    )


def test_a_hybrid_of_no_physics_unknowns_says_its_physics_is_the_file():
    """A hybrid may keep its physics as written (unknowns = []): kept, and said, its physics
    fit recorded as fitted by no trainer (it said "ls")."""
    from nnid.models.hybrid import HybridModel
    from nnid.trainers.adam import Adam
    from nnid.vehicle import load_vehicle

    log = _demo_log()
    model = HybridModel(
        load_vehicle(MINIROV), unknowns=[], dofs=["w"], trainer=Adam(max_epochs=0),
        segments=(0.5,),
    )  # fmt: skip
    with pytest.warns(UserWarning, match=r"the fit has no unknowns \(unknowns = \[\]\)"):
        model.fit(log[log["experiment"] == "run0"])
    physics = model.baseline()  # metrics.json's "baseline", model.json's physics_trainer
    assert physics.trainer_name() is None and physics.params == {}


def test_a_loop_error_names_the_log_read_through_a_reader_config(fixtures, tmp_path):
    """The loop said an error about the log it read through a reader config against the
    config's name (the cleaning report's title), as though "tartan-auv-2022" were a file."""
    log = fixtures["demo_log"].drop(columns=["phi", "theta"])
    log["p"] += 0.3 * np.cos(log["t"])  # rolling, with no roll angle to read it by
    log.to_csv(tmp_path / "nav.csv", index=False)
    config = tmp_path / "map.toml"
    config.write_text(_reader_config(log, "nav.csv").replace('"demo"', '"tartan-auv-2022"'))
    args = ["loop", "--data", str(tmp_path), "--columns", str(config), "--vehicle", MINIROV]
    result = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "o")])
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    assert errors[0].startswith(f"error: {tmp_path} (through {config}), field 'phi'"), errors
