"""The peers benchmark's nnid Seamor rows (issue 14): fitted and scored as ``nnid train`` does.

``benchmarks/bench_peers.py`` runs for an hour and needs the ``bench`` extra for its SysIdentPy
rows; its nnid rows need neither, and a change to the pipeline's signatures once broke them
after 40 minutes of a run. This fits a small NARX config through the script's own functions and
holds its scores to the ``metrics.json`` scores of the same config.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from conftest import load_script

from nnid.config import TrainConfig, load_config
from nnid.pipeline import run_train

ROOT = Path(__file__).resolve().parents[1]

SIM = """kind = "simulate"
vehicle = "seamor"
dt = 0.1
[[experiments]]
name = "a"
signals = [{ kind = "stairs", channel = "X", levels = [20, -10, 15, 0], hold = 4.0 }]
[[experiments]]
name = "b"
signals = [{ kind = "stairs", channel = "X", levels = [-15, 10, 0], hold = 4.0 }]
[[experiments]]
name = "c"
signals = [{ kind = "stairs", channel = "X", levels = [12, -18, 0], hold = 4.0 }]
[[experiments]]
name = "d"
signals = [{ kind = "stairs", channel = "X", levels = [8, -6, 0], hold = 4.0 }]
"""

NARX = """kind = "train"
vehicle = "seamor"
warmup_s = 0.5
[data]
simulate = "sim.toml"
[split]
by = "experiment"
validation = ["b", "d"]
test = ["c"]
[model]
kind = "narx"
inputs = ["tau_X"]
outputs = ["u"]
input_delays = 2
output_delays = 2
hidden = [3]
seed = 0
[model.trainer]
kind = "lm"
max_epochs = 5
"""


def test_nnid_seamor_rows_score_as_nnid_train(tmp_path, monkeypatch) -> None:
    (tmp_path / "sim.toml").write_text(SIM)
    config = tmp_path / "narx.toml"
    config.write_text(NARX)
    bench = load_script(ROOT / "benchmarks" / "bench_peers.py", monkeypatch)
    monkeypatch.setattr(bench, "SEAMOR_CONFIG", config)
    monkeypatch.setattr(bench, "SEAMOR_NNID_CONFIGS", {"NARX (LM)": config})
    case = bench.load_case("seamor")
    assert case.notes["test_runs"] == ["c"] and case.notes["validation_runs"] == ["b", "d"]

    row = next(r for r in bench.nnid_rows(case, seeds=(0,)) if r["model"] == "NARX (LM)")

    metrics = run_train(load_config(config, TrainConfig), config).metrics
    for part, got in (("validation", row["validation"]), ("test", row["test"]["test"])):
        want = metrics[part]["free_run_nrmse"]
        assert math.isfinite(got["value"])
        assert got["value"] == pytest.approx(want["total"], rel=1e-9), part
        assert got["per"]["u"] == pytest.approx(want["u"], rel=1e-9), part
    # each validation run alone, as the line reads them (pooled scores hide a miss)
    runs = metrics["validation"]["free_run_nrmse_per_experiment"]
    assert set(row["validation"]["per_run"]) == {"b", "d"}
    for run in ("b", "d"):
        got = row["validation"]["per_run"][run]["u"]
        assert (
            got == pytest.approx(runs[run]["u"], rel=1e-9)
            and got != runs["b" if run == "d" else "d"]["u"]
        )
    assert row["fit_s"] > 0 and row["seeds"] == [0]
