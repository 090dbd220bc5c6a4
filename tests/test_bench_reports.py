"""The report-rendering benchmark (``benchmarks/bench_reports.py``): its command line, one run
on tiny inputs (every row timed, no timing asserted) and how a revision's cells are said."""

from __future__ import annotations

import re
import runpy
import sys
from pathlib import Path

import pytest
from conftest import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_reports.py"


@pytest.fixture
def bench(monkeypatch):
    monkeypatch.syspath_prepend(str(SCRIPT.parent))  # its sibling module common
    return load_script(SCRIPT, monkeypatch)


@pytest.mark.parametrize(("argv", "code", "said"), [
    (["--help"], 0, "ratio REV / this tree"),
    (["--repeats", "0"], 2, "at least one timed call"),
    (["not-a-revision-anywhere"], 2, "'not-a-revision-anywhere' is not a git revision"),
])  # fmt: skip
def test_help_and_wrong_arguments_are_said(monkeypatch, capsys, argv, code, said):
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), *argv])
    monkeypatch.syspath_prepend(str(SCRIPT.parent))
    with pytest.raises(SystemExit) as stop:
        runpy.run_path(str(SCRIPT), run_name="__main__")
    assert stop.value.code == code
    out = capsys.readouterr()
    assert said in (out.out if code == 0 else out.err)


def test_a_tiny_run_times_every_row(bench, capsys, monkeypatch):
    """Every figure and page of the table is built and timed: a positive CPU time each (the
    figures not encoded as PNGs, most of their time, which this test does not measure)."""
    from nnid.reports import compare_report, loop_report, train_report

    for module in (compare_report, loop_report, train_report):
        monkeypatch.setattr(module, "figure_uri", lambda fig: "data:image/png;base64,")
    bench.main(["--tiny", "--repeats", "1"])
    out = capsys.readouterr().out
    rows = [line for line in out.splitlines() if line.startswith("| ") and "---" not in line]
    assert rows[0] == "| figure | ms now |"
    cells = dict(re.fullmatch(r"\| (.+) \| (.+) \|", line).groups() for line in rows[1:])
    assert list(cells) == list(bench.ROWS)
    assert all(float(ms) > 0 for ms in cells.values()), cells
    assert out.startswith("machine: ") and "median of 1; tiny inputs" in out


def test_a_revisions_cells_give_the_ratio_or_say_why_not(bench):
    """A revision's time over this tree's; "–" with why where its call failed there or a
    function's signature differs (called as this tree calls it, it would be another call)."""
    labels = list(bench.ROWS)
    now = {"rows": {label: {"ms": 10.0} for label in labels},
           "signatures": {p: "(a, b)" for paths in bench.ROWS.values() for p in paths}}  # fmt: skip
    rows = {label: {"ms": 25.0} for label in labels}
    rows[labels[1]] = {"why": "AttributeError: no _free_run_figure"}
    signatures = dict(now["signatures"])
    signatures["nnid.reports.loop_report:correlation_figure"] = "(analysis)"
    lines = bench.table(now, "OLD", {"rows": rows, "signatures": signatures})
    assert lines[0] == "| figure | ms now | ms at OLD | OLD / now |"
    cells = {line.split(" | ")[0][2:]: line.split(" | ")[1:] for line in lines[2:]}
    assert cells[labels[0]] == ["10.0", "25.0", "2.50 |"]
    assert cells[labels[1]] == ["10.0", "– (AttributeError: no _free_run_figure)", "– |"]
    why = "– (correlation_figure(analysis) at OLD, correlation_figure(a, b) now)"
    # the loop's page draws the correlation figure too: both rows say it
    for label in ("loop: correlation figure", "loop report page (three figures)"):
        assert cells[label] == ["10.0", why, "– |"]
