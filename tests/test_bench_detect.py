"""The fault-detection benchmark's command line (``benchmarks/bench_detect.py``): it runs for
minutes, so only its arguments are read here, never a mode run."""

from __future__ import annotations

import runpy
import sys
from pathlib import Path

import pytest
from conftest import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_detect.py"


@pytest.mark.parametrize(("argv", "code", "said"), [
    (["--help"], 0, "speed,scenarios,ended,follow"),
    (["fast"], 2, "invalid choice: 'fast'"),
    (["speed", "HEAD~1"], 2, "speed takes no revision"),
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
    assert set(bench.MODES) == {"speed", "scenarios", "ended", "follow"}
