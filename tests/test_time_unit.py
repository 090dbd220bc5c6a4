"""A declared time unit (``--time-unit``, ``[data] time_unit``, ``load_log(time_unit=)``): a log
whose clock the unit guess cannot read right (a 1-Hz logger stepping by whole seconds looks like
integer milliseconds) had no way through; a declared unit is converted to seconds, said in the
cleaning report, and not guessed at."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from nnid.cli import app
from nnid.config import LoopConfig, load_config
from nnid.datasets.log import FASTEST_STEP, check_time_unit
from nnid.datasets.readers import load_log
from nnid.errors import NnidInputError
from nnid.pipeline import load_inputs

COLUMNS = "z phi theta psi u v w p q r tau_X tau_Y tau_Z tau_K tau_M tau_N".split()


def _write(path: Path, t: np.ndarray) -> Path:
    """A log of the contract's columns (a 1-Hz plateau logger's, as Caccia's) on clock ``t``."""
    rng = np.random.default_rng(0)
    df = pd.DataFrame({c: rng.normal(0.0, 0.05, t.size) for c in COLUMNS})
    df.insert(0, "experiment", "plateau")
    df.insert(0, "t", t)
    df.to_csv(path, index=False)
    return path


def test_a_whole_second_log_is_refused_naming_the_declaration_and_read_when_declared(tmp_path):
    """t = 0, 1, 2, … s (a 1-Hz logger) was refused as milliseconds with no way through."""
    log = _write(tmp_path / "hz1.csv", np.arange(200))
    refused = CliRunner().invoke(app, ["inspect", str(log)])
    assert refused.exit_code == 2
    said = " ".join(refused.output.split())
    assert "looks like milliseconds" in said and "--time-unit" in said
    assert "[data] time_unit" in said
    read = CliRunner().invoke(app, ["inspect", str(log), "--time-unit", "s"])
    assert read.exit_code == 0, read.output
    assert "about 1 Hz" in read.output and "199.0 s" in read.output
    assert "t read as seconds, as declared" in " ".join(read.output.split())


def test_a_config_declares_integer_milliseconds_converted_and_said(tmp_path):
    """[data] time_unit = "ms": t divided by 1000, said in the cleaning report."""
    _write(tmp_path / "ms.csv", np.arange(100) * 20)  # 50 Hz in integer milliseconds
    path = tmp_path / "loop.toml"
    path.write_text('kind = "loop"\n[data]\nlog = "ms.csv"\ntime_unit = "ms"\n')
    inputs = load_inputs(load_config(path, LoopConfig), path, [])
    np.testing.assert_allclose(inputs.log["t"].to_numpy()[:3], [0.0, 0.02, 0.04])
    details = [s.detail for s in inputs.report.steps]
    assert "t read as milliseconds, as declared: divided by 1000" in details
    # the option replaces the config's key: declared seconds, 20-s steps are read as such
    as_s = load_inputs(load_config(path, LoopConfig), path, [], time_unit="s")
    assert as_s.log["t"].iloc[1] == 20


def test_an_unknown_time_unit_is_refused_naming_the_option_or_key(tmp_path):
    log = _write(tmp_path / "a.csv", np.arange(50) * 0.1)
    bad = CliRunner().invoke(app, ["inspect", str(log), "--time-unit", "min"])
    assert bad.exit_code == 2
    said = " ".join(bad.output.split())
    assert "'--time-unit'" in said and "'min'" in said and "s, ms, us, ns" in said
    path = tmp_path / "loop.toml"
    path.write_text('kind = "loop"\n[data]\nlog = "a.csv"\ntime_unit = "minutes"\n')
    with pytest.raises(NnidInputError) as err:
        load_config(path, LoopConfig)
    assert err.value.field == "data.time_unit" and "'ms'" in str(err.value)


def test_a_reader_config_keeps_its_time_scale_as_the_one_declaration(tmp_path):
    """A reader config scales each source's stamps (time_scale): a second declaration of the
    same clock would scale it twice, and is refused naming the option."""
    log = _write(tmp_path / "a.csv", np.arange(50) * 0.1)
    cmap = tmp_path / "map.toml"
    cmap.write_text('name = "m"\n[[sources]]\nfile = "a.csv"\ntime = "t"\n')
    with pytest.raises(NnidInputError, match="time_scale") as err:
        load_log(log, cmap, "ms", "--time-unit")
    assert err.value.field == "--time-unit"


def test_a_declared_log_is_not_guessed_at_again_by_its_slices():
    """A prediction checks the clock of the log it is given (check_stepped): a declared log's
    parts are not refused there either."""
    from nnid.datasets.log import declare_time_unit

    n = 40
    df = pd.DataFrame({"t": np.arange(n), "u": np.zeros(n), "tau_X": np.ones(n)})
    with pytest.raises(NnidInputError, match="time_unit"):
        check_time_unit(df)
    declared, said = declare_time_unit(df, "s")
    assert said.startswith("t read as seconds") and declared["t"].equals(df["t"])
    check_time_unit(declared.iloc[10:30].reset_index(drop=True))
    check_time_unit(declared[["t", "u"]].copy())


def _mapped(tmp_path: Path, source: str = "", rate: str = "") -> Path:
    """A 1-Hz log whose stamps step by whole seconds, read through a reader config whose one
    source adds the ``source`` lines (a time_unit, a time_scale) after its time column."""
    _write(tmp_path / "nav.csv", np.arange(60))
    cmap = tmp_path / "map.toml"
    columns = "".join(f'{c} = "{c}"\n' for c in COLUMNS)
    cmap.write_text(
        f'name = "m"\n{rate}[[sources]]\nfile = "nav.csv"\ntime = "t"\n{source}'
        f"[sources.columns]\n{columns}"
    )
    return cmap


def test_a_reader_config_source_declares_its_time_unit(tmp_path):
    """time_scale = 1.0 is the default and declares nothing, and --time-unit is refused beside
    a reader config: a 1-Hz source stepping by whole seconds had no way through. A source's
    time_unit declares it (converted as --time-unit converts, said, not guessed at)."""
    with pytest.raises(NnidInputError, match="time_unit") as err:
        load_log(tmp_path, _mapped(tmp_path))
    assert err.value.field == "sources.0.time_scale" and err.value.source.endswith("map.toml")
    for rate in ("", "rate = 1.0\n"):  # the grid at 1 Hz, from the source or from rate
        log, report = load_log(tmp_path, _mapped(tmp_path, 'time_unit = "s"\n', rate))
        np.testing.assert_array_equal(log["t"].to_numpy()[:3], [0.0, 1.0, 2.0])
        said = [s.detail for s in report.steps if s.step == "time unit"]
        assert any("nav.csv: t read as seconds, as declared" in d for d in said)
        check_time_unit(log.iloc[5:40])  # the log's slices are not guessed at later either
    log, _ = load_log(tmp_path, _mapped(tmp_path, 'time_unit = "ms"\n'))
    assert log["t"].iloc[1] == pytest.approx(0.001)


@pytest.mark.parametrize(
    ("lines", "field", "words"),
    [
        ('time_unit = "min"\n', "sources.0.time_unit", "s, ms, us, ns"),
        ('time_unit = "ms"\ntime_scale = 0.001\n', "sources.0", "give one"),
        ('time_unit = "s"\nrow_clock = 1.0\n', "sources.0", "row_clock"),
    ],
)
def test_a_reader_config_time_unit_is_checked_naming_the_file_and_key(
    tmp_path, lines, field, words
):
    with pytest.raises(NnidInputError, match=words) as err:
        load_log(tmp_path, _mapped(tmp_path, lines))
    assert err.value.field == field and err.value.source.endswith("map.toml")


def test_a_partly_declared_reader_config_is_refused_naming_the_reader_config(tmp_path):
    """One source declared, a second (commands held, whose steps are not judged) not: the 1-Hz
    log is refused at its grid naming the sources' time_unit, not --time-unit (refused here)."""
    cmap = _mapped(tmp_path, 'time_unit = "s"\n')
    pd.read_csv(tmp_path / "nav.csv").rename(columns={"tau_X": "thrust"}).to_csv(
        tmp_path / "cmd.csv", index=False
    )
    body = cmap.read_text().replace('tau_X = "tau_X"\n', "")
    body += '[[sources]]\nfile = "cmd.csv"\ntime = "t"\nmethod = "hold"\n'
    body += '[sources.columns]\ntau_X = "thrust"\n'
    cmap.write_text(body)
    with pytest.raises(NnidInputError, match="every source's time_unit") as err:
        load_log(tmp_path, cmap)
    assert err.value.source.endswith("map.toml") and "--time-unit" not in err.value.message
    cmap.write_text(body.replace('method = "hold"', 'method = "hold"\ntime_unit = "s"'))
    assert load_log(tmp_path, cmap)[0]["t"].iloc[-1] == 59.0


def test_a_batch_manifest_declares_the_time_unit_of_every_log(tmp_path, monkeypatch):
    """nnid batch had no way to declare a unit: a 1-Hz log stepping by whole seconds failed
    in every task. The manifest's time_unit is each task's --time-unit (the loop itself is
    stood in for: the task runs everything up to it, the log's loading among it)."""
    from nnid import runs
    from nnid.scale.batch import run_tasks
    from nnid.scale.engines import SerialEngine
    from nnid.scale.manifest import expand

    def loop_on(log, *args, **kwargs):
        return runs.Outcome(headline={"t_end": float(log["t"].max()), "samples": len(log)})

    monkeypatch.setattr(runs, "residual_loop_run", loop_on)
    demo = Path(__file__).resolve().parents[1] / "nnid" / "demo_data"
    log = pd.read_parquet(demo / "demo_minirov_heave.parquet")
    log = log[log["experiment"].isin(log["experiment"].unique()[:2])].groupby("experiment")
    log = log.head(100)
    log.assign(t=(log["t"] * 20).round()).to_csv(tmp_path / "hz1.csv", index=False)  # 1 Hz
    head = f'command = "loop"\nvehicle = "{demo / "minirov.toml"}"\ndata = "hz1.csv"\n'
    manifest = tmp_path / "fleet.toml"
    manifest.write_text(head)
    (undeclared,) = expand(manifest)
    (row,) = run_tasks([undeclared], tmp_path / "a", SerialEngine()).rows
    assert row["status"] == "failed" and "looks like milliseconds" in row["error"]
    assert "a batch manifest's time_unit" in " ".join(row["error"].split())
    manifest.write_text(head + 'time_unit = "s"\n')
    (declared,) = expand(manifest)
    assert declared.time_unit == "s" and declared.id != undeclared.id
    (row,) = run_tasks([declared], tmp_path / "b", SerialEngine()).rows
    assert row["status"] == "ok", row["error"]
    assert row["time_unit"] == "s" and (row["t_end"], row["samples"]) == (99.0, 200)


@pytest.mark.parametrize(
    ("line", "words"),
    [('time_unit = "sec"', "s, ms, us, ns"), ('columns = "map.toml"\ntime_unit = "s"', "reader")],
)
def test_a_batch_manifest_time_unit_is_checked_before_any_task(tmp_path, line, words):
    """An unknown unit, or one beside a reader config (which declares its sources' own), is
    one error naming the manifest and its key (exit 2), not a failure in every task."""
    _write(tmp_path / "a.csv", np.arange(50) * 0.1)
    (tmp_path / "map.toml").write_text('name = "m"\n[[sources]]\nfile = "a.csv"\ntime = "t"\n')
    manifest = tmp_path / "fleet.toml"
    manifest.write_text(f'command = "loop"\nvehicle = "seamor"\ndata = "a.csv"\n{line}\n')
    res = CliRunner().invoke(app, ["batch", str(manifest), "--out", str(tmp_path / "out")])
    said = " ".join(res.output.split())
    assert res.exit_code == 2 and "fleet.toml" in said and "'time_unit'" in said
    assert words in said and not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    ("command", "config", "runner"),
    [
        ("train", "fossen_ls.toml", "train_run"),
        ("compare", "vt690_compare.toml", "compare_run"),
        ("detect", None, "detect_run"),
    ],
)
def test_every_batch_command_gets_the_manifests_time_unit(monkeypatch, command, config, runner):
    """train, compare and detect tasks pass the manifest's unit on as their --time-unit."""
    import inspect

    from nnid import runs
    from nnid.scale.manifest import Task
    from nnid.scale.task import _run

    real = getattr(runs, runner)
    got = {}
    monkeypatch.setattr(
        runs, runner, lambda *a, **k: got.update(inspect.signature(real).bind(*a, **k).arguments)
    )
    configs = Path(__file__).resolve().parents[1] / "configs"
    task = Task(command, "log.csv", config=config and str(configs / config), model="det",
                time_unit="ms")  # fmt: skip
    _run(task, Path("out"))
    assert got["time_unit"] == "ms"


def test_the_reader_config_example_in_the_column_map_docstring_parses():
    """The module docstring's example [[sources]] set time_unit = "s" and row_clock = 20.0
    together, which the source's own check refuses (one clock declaration): the example is
    read as a reader config, its row_clock an alternative left commented out."""
    import re
    import tomllib

    from nnid.datasets import column_map

    (example,) = re.findall(r"```toml\n(.*?)```", column_map.__doc__ or "", re.S)
    (source,) = column_map.ColumnMap.model_validate(tomllib.loads(example)).sources
    assert source.time_unit == "s" and source.row_clock is None


def _said(result) -> str:
    """The one error line of a refused run, its wrapping undone."""
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert result.exit_code == 2 and len(errors) == 1, result.output
    return " ".join(result.output.split())


def test_a_clock_too_fine_for_its_unit_is_named_not_blamed_on_a_window(tmp_path):
    """Only steps too large were checked for another unit: a log in hours read as seconds
    was refused as a warmup_s or savgol_window too long, and seconds declared as
    milliseconds too. The median step is said against t, with the unit assumed and the
    units that give a step a vehicle's log takes."""
    step = 0.05  # 20 Hz
    hours = _write(tmp_path / "hours.csv", np.arange(400) * step / 3600)
    said = _said(CliRunner().invoke(app, ["inspect", str(hours)]))
    assert f"{hours}, field 't': time, read as seconds" in said
    assert f"{3600 / step:.0f} Hz" in said and "hours (a step of 0.05 s, 20 Hz)" in said
    assert "multiply by 3600" in said and "savgol_window" not in said
    seconds = _write(tmp_path / "seconds.csv", np.arange(400) * step)
    args = ["loop", "--data", str(seconds), "--vehicle", "seamor", "--time-unit", "ms"]
    said = _said(CliRunner().invoke(app, [*args, "--out", str(tmp_path / "o")]))
    assert f"{seconds}, field 't': time, declared in milliseconds, steps by 0.05 ms" in said
    assert "seconds (a step of 0.05 s, 20 Hz)" in said and "--time-unit" in said
    assert "savgol_window" not in said and not (tmp_path / "o").exists()
    # a 1-kHz logger's clock, the fastest the unit guess reads, and the demo log pass
    check_time_unit(pd.DataFrame({"t": np.arange(50) * 1e-3}))
    demo = Path(__file__).resolve().parents[1] / "nnid" / "demo_data"
    check_time_unit(pd.read_parquet(demo / "demo_minirov_heave.parquet"))


def test_a_reader_config_source_too_fine_for_its_unit_is_named(tmp_path):
    """A source declared in milliseconds whose stamps are seconds, or stamped in hours:
    said against the source's time_unit or time_scale, before a grid of tens of kHz."""
    cmap = _mapped(tmp_path, 'time_unit = "ms"\n')
    _write(tmp_path / "nav.csv", np.arange(60) * 0.1)  # 10 Hz in seconds
    with pytest.raises(NnidInputError, match="declared in milliseconds") as err:
        load_log(tmp_path, cmap)
    assert err.value.field == "sources.0.time_unit" and err.value.source.endswith("map.toml")
    assert 'time_unit = "s"' in err.value.message
    cmap = _mapped(tmp_path)
    _write(tmp_path / "nav.csv", np.arange(60) * 0.1 / 3600)  # 10 Hz in hours
    with pytest.raises(NnidInputError, match=r"hours \(a step of 0.1 s, 10 Hz\)") as err:
        load_log(tmp_path, cmap)
    assert err.value.field == "sources.0.time_scale" and "3600 for hours" in err.value.message


def test_stamps_that_come_in_bursts_are_no_clock_too_fine(tmp_path):
    """An IMU delivering ten samples in one burst every 10 ms: nine steps in ten are 10 us,
    and its clock was refused as hours read as seconds ("set its time_scale to 3600"),
    though it samples at 1 kHz over the run. A unit slip scales every step and the span
    with them: the mean step tells the two apart. A reader config's rate reads it; without
    one the median step, a burst's, is no time base, and rate is asked for."""
    bursty = (np.arange(60)[:, None] * 0.01 + np.arange(10)[None, :] * 1e-5).ravel()
    check_time_unit(pd.DataFrame({"t": bursty}))
    with pytest.raises(NnidInputError, match="faster than any"):  # in hours: every step
        check_time_unit(pd.DataFrame({"t": bursty / 3600}))
    cmap = _mapped(tmp_path, rate="rate = 100.0\n")
    _write(tmp_path / "nav.csv", 1.7e9 + bursty)
    log, _ = load_log(tmp_path, cmap)
    assert len(log) == 60 and np.allclose(np.diff(log["t"]), 0.01)
    cmap = _mapped(tmp_path)
    _write(tmp_path / "nav.csv", 1.7e9 + bursty)
    with pytest.raises(NnidInputError, match=r"bursts.*give rate") as err:
        load_log(tmp_path, cmap)
    assert err.value.field == "rate" and "hours" not in err.value.message


def test_a_unit_slip_with_a_pause_in_its_run_is_still_too_fine_a_clock():
    """Hours read as seconds: a minute at 10 Hz with a 10-min stop in it. The stop's one
    step (0.17 "s") pulls the run's plain mean step to 0.3 ms, and a burst rule on that mean
    took the slip for stamps that come in bursts; every other step is 2.8e-5 "s"."""
    t = np.arange(600) * 0.1
    t[300:] += 600.0
    assert np.diff(t / 3600).mean() > FASTEST_STEP
    with pytest.raises(NnidInputError, match="faster than any"):
        check_time_unit(pd.DataFrame({"t": t / 3600}))
    check_time_unit(pd.DataFrame({"t": t}))
    # twenty 5-s runs at 10 Hz, 2-min pauses between them, no experiment column: nine pauses
    # in a thousand steps (more than the longest 1 %) took the slip for bursts
    runs = (np.arange(20)[:, None] * 125.0 + np.arange(50)[None, :] * 0.1).ravel()
    with pytest.raises(NnidInputError, match="faster than any"):
        check_time_unit(pd.DataFrame({"t": runs / 3600}))
