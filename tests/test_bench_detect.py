"""The fault-detection benchmark (``benchmarks/bench_detect.py``): it runs for minutes, so its
arguments are read here, and one mode (``second``) run on tiny data."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import pytest
from conftest import load_script

from nnid.fault.isolation import allowed_over
from nnid.vehicle import load_vehicle

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_detect.py"


@pytest.mark.parametrize(("argv", "code", "said"), [
    (["--help"], 0, "speed,scenarios,ended,second,follow"),
    (["fast"], 2, "invalid choice: 'fast'"),
    (["speed", "HEAD~1"], 2, "speed takes no revision"),
    (["second", "HEAD~1"], 2, "second takes no revision"),
])  # fmt: skip
def test_help_lists_the_modes_and_a_wrong_one_is_named(monkeypatch, capsys, argv, code, said):
    """``--help`` was a KeyError traceback ('--help' looked up as a mode), and so was a mode
    that is none."""
    monkeypatch.setattr(sys, "argv", [str(SCRIPT), *argv])
    monkeypatch.syspath_prepend(str(SCRIPT.parent))  # its sibling module common
    with pytest.raises(SystemExit) as stop:
        runpy.run_path(str(SCRIPT), run_name="__main__")
    assert stop.value.code == code
    out = capsys.readouterr()
    assert said in (out.out if code == 0 else out.err)


def test_the_modes_read_their_arguments_as_before(monkeypatch):
    """``follow REV`` and the ``follow --json`` of its subprocess on another revision still
    parse (follow reads them from sys.argv itself); no argument is ``speed``."""
    monkeypatch.syspath_prepend(str(SCRIPT.parent))  # its sibling module common
    bench = load_script(SCRIPT, monkeypatch)
    ap = bench.parser()
    assert ap.parse_args([]).mode == "speed"
    assert vars(ap.parse_args(["follow", "HEAD~1"])) == {"mode": "follow", "rev": "HEAD~1",
                                                          "json": False}  # fmt: skip
    assert ap.parse_args(["follow", "--json"]).json is True
    assert set(bench.MODES) == {"speed", "scenarios", "ended", "second", "follow"}
    assert ap.parse_args(["second"]).mode == "second"


def _tables(out: str) -> list[list[list[str]]]:
    """The Markdown tables of ``out``, each its body rows' cells (header and rule left out)."""
    tables, rows = [], None
    for line in [*out.splitlines(), ""]:
        if line.startswith("|"):
            rows = [] if rows is None else rows
            rows.append([c.strip() for c in line.strip("|").split("|")])
        elif rows is not None:
            tables.append(rows[2:])
            rows = None
    return tables


# a monitor of 200 s says its fit is weak: expected here, only the tables are read
@pytest.mark.filterwarnings("ignore:the fitted damping", "ignore:the healthy record")
def test_second_prints_both_tables_on_tiny_data(monkeypatch, capsys):
    """``second`` with a monitor fitted on 200 s, one seed, a snag then a 10 N ballast, and
    two single changes: a row for each, counts within the runs made, and a beside-reading only
    where an alarm was dismissed, with the level the library judged it against (``allowed_over``
    of some of the six DOF equations), never a value not measured."""
    monkeypatch.syspath_prepend(str(SCRIPT.parent))  # its sibling module common
    bench = load_script(SCRIPT, monkeypatch)
    mon = bench.trained(load_vehicle(bench.VEHICLE), 40.0)
    snag = "snag -10 N + 1 N m yaw"
    kinds = ["h1 stopped", "payload 2 kg, 4 N lift (W-B +15.6 N)"]
    bench.second(mon, seeds=[2], single_seeds=[1], firsts={snag: bench.FIRSTS[snag]},
                 ballasts=(10.0,), singles={k: bench.SINGLES[k] for k in kinds}, run_s=47.0,
                 single_s=60.0)  # fmt: skip
    second, single = _tables(capsys.readouterr().out)
    assert [row[:3] for row in second] == [[snag, "10 N", "1"]]
    first_alarmed, isolated, other = (int(second[0][i]) for i in (3, 4, 7))
    assert 0 <= first_alarmed <= 1 and 0 <= isolated <= 1 and other >= 0
    assert (second[0][5] == "-") == (isolated == 0) == (second[0][6] == "-")
    assert [row[:2] for row in single] == [[k, "1"] for k in kinds]
    levels = {f"{allowed_over(n, 6):.2f}" for n in range(1, 7)}
    read = 0
    for _, _, at, later, dismissed, reading, level in single:
        assert 0 <= int(at) <= 1 and int(later) >= 0 and int(dismissed) >= 0
        if reading == "-":
            assert level == "-"
            continue
        read += 1
        assert int(dismissed) >= 1 and level in levels and float(reading) > 0
    assert read >= 1  # the payload's unclaimed mass left a dismissed window
