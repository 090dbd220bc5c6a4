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
from nnid.datasets.log import check_time_unit
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
