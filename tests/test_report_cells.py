"""The report cells every report shares (``nnid.reports.cells``): a missing number is "-", a
voided score "diverged", a score with nothing to measure "not scored", an unscored column "-",
and a count is never rounded."""

import html
import math

import numpy as np
import pytest

from nnid.reports.cells import number, score, score_cell
from nnid.reports.train_report import _members


@pytest.mark.parametrize("missing", [None, math.nan, math.inf, -math.inf, np.float32("nan")])
def test_missing_number_is_a_dash(missing):
    assert number(missing) == "-"


def test_numbers_keep_their_significant_figures_and_counts_stay_whole():
    assert number(0.0123456) == "0.0123"
    assert number(0.0123456, 5) == "0.012346"
    assert number(0.65, 3, fixed=True) == "0.650" and score(None, fixed=True) == "diverged"
    assert number(np.float32(2.5)) == "2.5"
    # a seed or an alarm count written as 1.23e+04 would read as a measured value
    assert number(12345) == "12345" and number(np.int64(7)) == "7"
    assert number(True) == "True" and number("fossen") == "fossen"


def test_a_voided_score_is_diverged_and_an_unscored_column_a_dash():
    assert score(None) == "diverged" and score(0.04567) == "0.0457"
    vals = {"u": 0.1, "v": None, "total": None}
    cells = [score_cell(vals, k, {"v": 12.5}) for k in ("u", "v", "w", "total")]
    assert cells == ["0.1", "diverged", "-", "diverged"]


def test_a_score_nothing_was_left_to_measure_is_not_called_diverged():
    """A None with no divergence behind it (a 70 s-ahead score on 60-s runs: no sample left
    after the horizon; or a constant signal) was not scored. It read "diverged"."""
    assert score(None, diverged=False) == "not scored"
    vals = {"w": None, "total": None}
    assert [score_cell(vals, k, {}) for k in ("w", "total")] == ["not scored", "not scored"]


def test_members_table_says_dash_for_a_column_a_split_does_not_score():
    # the test run does not excite w: its w is not scored, which is not a divergence
    member = {
        "seed": 3,
        "validation": {"free_run_nrmse": {"u": 0.05, "w": 0.2, "total": 0.125}},
        "test": {"free_run_nrmse": {"u": 0.07, "v": None, "total": None}, "diverged": {"v": 8.0}},
    }
    head, rows = _members({"members": [member]})
    cells = dict(zip(head, rows[0], strict=True))
    assert cells["seed"] == "3"
    assert cells["validation w"] == "0.2" and cells["test u"] == "0.07"
    assert cells["test w"] == "-"
    assert cells["test total"] == "diverged"


def test_a_parameter_never_tested_for_significance_is_not_called_insignificant():
    """A jointly trained hybrid's physics has values without standard errors: no test ran,
    so its significance is "-", not "no" (the table printed "no" for every one)."""
    from nnid.reports.train_report import _params_table

    params = {
        "Z_wdot": {"value": -1.2, "stderr": None, "vehicle_file": -1.0},
        "Z:w": {"value": -4.0, "stderr": 0.5, "vehicle_file": -5.0, "significant": False},
        "Z:w|w|": {"value": -9.0, "stderr": 0.5, "vehicle_file": -8.0, "significant": True},
    }
    head, rows = _params_table({"params": params})
    column = head.index("significant (95 %)")
    assert [r[column] for r in rows] == ["-", "no", "yes"]


def test_a_free_run_score_of_zero_keeps_its_ratio_to_the_baseline():
    """A free-run NRMSE of exactly 0.0 is a score: the ratio cell was left empty, as for a
    model whose free run was not measured (a truthiness test where ``is not None`` was
    meant)."""
    from nnid.reports.train_report import _baseline

    def part(total):
        return {"free_run_nrmse": {"w": total, "total": total}, "diverged": {}}

    metrics = {"model": "fossen", "validation": part(0.0),
               "baseline": {"model": "physics only", "validation": part(0.5)}}  # fmt: skip
    rows = _baseline(metrics)[1]
    assert rows[0][2] == "0" and rows[0][-1] == "0"
    assert rows[1][-1] == ""  # the baseline's own row has no ratio
    metrics["validation"] = {"free_run_nrmse": {"w": None, "total": None}, "diverged": {"w": 1.0}}
    rows = _baseline(metrics)[1]
    assert rows[0][2] == "diverged" and rows[0][-1] == ""  # not measured: no number


#: a Fossen fit's parameters as metrics.json holds them: one identified, one the data do not
#: excite (ParametricFossenModel._params: no s.e., "significant" False, "excited" False)
_FOSSEN_PARAMS = {
    "Z_wdot": {"value": -19.0, "stderr": 0.17, "percentile_error": 0.9, "significant": True,
               "vehicle_file": -18.7},
    "Y:v*abs(v)": {"value": 3.0, "stderr": None, "percentile_error": None, "significant": False,
                   "excited": False, "vehicle_file": -217.0},
}  # fmt: skip


def test_the_train_parameter_table_gives_each_parameters_unit():
    """The train report's table gave no units (the fleet report's figure had them): its unit
    column is the fleet report's one function's (``parameter_unit``)."""
    from nnid.reports.loop_report import parameter_unit
    from nnid.reports.train_report import _params_table

    head, rows = _params_table({"params": _FOSSEN_PARAMS})
    cells = {r[0]: dict(zip(head, r, strict=True)) for r in rows}
    assert cells["`Z_wdot`"]["unit"] == "kg" == parameter_unit("Z_wdot")
    assert cells["`Y:v*abs(v)`"]["unit"] == "N / (m/s · m/s)"


def test_an_unexcited_parameter_is_called_not_excited_not_insignificant():
    """A parameter the data do not excite read a bare "no" (as if a test had found it
    insignificant): the fit recorded why (``not_excited_``), and the cell says it."""
    from nnid.reports.train_report import _params_table

    head, rows = _params_table({"params": _FOSSEN_PARAMS})
    column = head.index("significant (95 %)")
    assert [r[column] for r in rows] == ["yes", "not excited"]


def _train_metrics(**extra) -> dict:
    return {"model": "fossen", "params": _FOSSEN_PARAMS, "seconds": 1.0, **extra}


def test_the_train_page_shows_parameter_names_as_code_not_backticks():
    """The HTML escaped the tables' Markdown code marks: the page read `Z_wdot` with its
    backticks."""
    from nnid.reports.train_report import train_html

    page = train_html(_train_metrics())
    assert "<code>Z_wdot</code>" in page and "<code>Y:v*abs(v)</code>" in page
    assert "`" not in page.split("<h2>Parameters</h2>")[1]


def test_the_train_page_has_the_markdowns_prime_system_section():
    """report.md listed the Prime-system I coefficients; report.html left them out. Both now
    write them from the same metrics entry, with the same words."""
    from nnid.pipeline import _nondimensional
    from nnid.reports.train_report import train_html, train_markdown
    from nnid.vehicle import load_vehicle

    nd = _nondimensional(_FOSSEN_PARAMS, load_vehicle("vlbv300"), 0.5)
    metrics = _train_metrics(nondimensional=nd)
    text, page = train_markdown(metrics), train_html(metrics)
    title = f"Prime-system I (U = 0.5 m/s, L = {nd['length']} m)"
    assert f"## {title}" in text and f"<h2>{title}</h2>" in page
    values = dict(ln[3:].split("` = ", 1) for ln in text.splitlines() if ln.startswith("- `"))
    assert set(values) == {"Z_wdot'", "Y:v*abs(v)'"}
    for name, value in values.items():
        assert f"<li><code>{html.escape(name)}</code> = {html.escape(value)}</li>" in page
    assert "±" in values["Z_wdot'"] and "fitted to noise" in values["Y:v*abs(v)'"]


def test_a_train_report_imports_neither_matplotlib_nor_the_residual_loop(monkeypatch):
    """Every report module imports ``nnid.reports.figures`` for its tables, and that module
    imported matplotlib: 0.6 s of CPU in every ``nnid train`` of a model with no figure (all
    but a hybrid); the train report imports the loop report's ``parameter_unit``, and that
    module imported the residual loop (pysindy with it, 0.13 s) for one constant. Each is
    imported where it is used: with neither importable, fresh copies of every report module
    load, and a Fossen model's pages are written."""
    import importlib.util
    import sys

    import nnid.reports

    loaded = [m for m in sys.modules if m.split(".")[0] == "matplotlib"]
    for name in {"matplotlib", "nnid.loop.residual_loop", *loaded}:  # their imports now fail
        monkeypatch.setitem(sys.modules, name, None)
    with pytest.raises(ImportError):
        import matplotlib.figure  # noqa: F401

    copies = {}
    folder = nnid.reports.__path__[0]
    for name in ("figures", "batch_report", "compare_report", "detect_report", "loop_report",
                 "train_report"):  # fmt: skip
        spec = importlib.util.spec_from_file_location(f"_copy_{name}", f"{folder}/{name}.py")
        copies[name] = importlib.util.module_from_spec(spec)
        monkeypatch.setitem(sys.modules, spec.name, copies[name])
        spec.loader.exec_module(copies[name])
    metrics = _train_metrics()
    page = copies["train_report"].train_html(metrics)
    assert "<code>Z_wdot</code>" in page and "Z_wdot" in copies["train_report"].train_markdown(
        metrics
    )
    assert copies["figures"].html_table(["a"], [["`b`"]]) == (
        "<table><thead><tr><th>a</th></tr></thead><tbody><tr><td><code>b</code></td></tr>"
        "</tbody></table>"
    )


def _hybrid_figure_data(forces: str, scale: float, n: int = 2000):
    """A held-out log and a learned force (``forces``, each of size ``scale``, a feature's
    too) as the train report draws them."""
    import pandas as pd

    from nnid.datasets.log import TAU, VELOCITY

    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.05
    log = pd.DataFrame({"t": t, "experiment": "run0"})
    for k, c in enumerate([*VELOCITY, *TAU, "phi", "theta", "psi"]):
        log[c] = scale * np.sin(t / (3 + k)) + 0.1 * scale * rng.standard_normal(n)
    force = pd.DataFrame({f: 0.0 for f in "XYZKMN"}, index=log.index)
    for k, f in enumerate(forces):
        force[f] = scale * (log[VELOCITY[k]] / scale) ** 2 + 0.1 * scale * rng.standard_normal(n)
    return log, force


def _drawn(monkeypatch, draw):
    """The figure ``draw`` builds (its data URI checked)."""
    from nnid.reports import train_report

    built = []
    real = train_report.figure_uri
    monkeypatch.setattr(train_report, "figure_uri", lambda fig: built.append(fig) or real(fig))
    assert draw().startswith("data:image/png;base64,")
    (fig,) = built
    return fig


@pytest.mark.parametrize(("forces", "scale"), [("XN", 1.0), ("Y", 3e-4), ("K", 1e6)])
def test_the_hybrid_correction_figure_has_fixed_margins_a_y_axis_a_row_and_labels_inside(
    monkeypatch, forces, scale
):
    """The hybrid's six-DOF correction grid (24 panels) took 2-4 s a report under the
    constrained layout: fixed margins and one y axis per row. Each row still says which force
    it plots, each panel its feature and |r|; the force's tick labels are on the row's first
    panel only; every label lies inside the figure and out of the other panels, from forces
    and features of 3e-4 to 1e6 (the row layout is the same for one row as for six)."""
    from conftest import assert_labels_inside

    from nnid.reports.figures import FORCE_UNITS
    from nnid.reports.train_report import _correction_figure

    log, force = _hybrid_figure_data(forces, scale)
    fig = _drawn(monkeypatch, lambda: _correction_figure(log, force))
    assert_labels_inside(fig)
    grid = np.array(fig.axes).reshape(len(forces), 4)
    for row, f in zip(grid, forces, strict=True):
        assert row[0].get_ylabel() == f"learned {f} [{FORCE_UNITS[f]}]"
        assert [ax.get_ylabel() for ax in row[1:]] == ["", "", ""]
        assert all(ax.get_visible() and ax.get_xlabel() for ax in row)
        assert all(ax.get_title().startswith("|r| = ") for ax in row)
        shown = [[t for t in ax.get_yticklabels() if t.get_visible() and t.get_text()]
                 for ax in row]  # fmt: skip
        assert shown[0] and not any(shown[1:])
        assert all(ax.get_ylim() == row[0].get_ylim() for ax in row)
    if scale < 1:  # a tick label on every panel's edge, eight characters long, still fits
        for ax in fig.axes:
            ax.set_xlim(-1e-4, 1e-4)
        assert_labels_inside(fig)
        assert fig.axes[0].get_xticklabels()[0].get_text() == "−0.00010"


def test_the_hybrid_free_run_figure_has_fixed_margins_and_its_labels_inside(monkeypatch):
    """The train report's free runs of the hybrid and its physics (six panels) are drawn once,
    with fixed margins: labels of a DOF barely moving still fit."""
    from conftest import assert_labels_inside

    from nnid.datasets.log import VELOCITY
    from nnid.reports.train_report import _free_run_figure

    log, force = _hybrid_figure_data("XYZKMN", 3e-4)
    velocity = log[list(VELOCITY)]
    figures = {"correction": (log, force), "free_run": 1.1 * velocity,
               "baseline_free_run": 0.9 * velocity}  # fmt: skip
    fig = _drawn(monkeypatch, lambda: _free_run_figure(figures))
    assert_labels_inside(fig)
    assert [ax.get_ylabel() for ax in fig.axes] == [f"{c} [m/s]" for c in "uvw"] + [
        f"{c} [rad/s]" for c in "pqr"
    ]
    assert fig.axes[0].get_title() == "experiment run0" and fig.axes[-1].get_xlabel() == "t [s]"
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == [
        "measured", "physics only", "hybrid"
    ]  # fmt: skip


def test_the_hybrid_free_run_figure_survives_a_run_named_with_mathtext(monkeypatch):
    """The figure is titled with the held-out run's name: a name with a bad '$' pair
    ('$\\foo$') raised in savefig once the whole fit was done, as the compare report's
    legends did (:func:`~nnid.reports.figures.plot_label`)."""
    import pandas as pd

    from nnid.reports.train_report import _free_run_figure

    t = np.arange(0.0, 2.0, 0.1)
    held = pd.DataFrame({"t": t, "experiment": r"fit $\foo$", "u": np.sin(t), "w": np.cos(t)})
    free = held[["u", "w"]]
    figures = {"correction": (held, None), "free_run": free, "baseline_free_run": 0.5 * free}
    fig = _drawn(monkeypatch, lambda: _free_run_figure(figures))  # savefig raised on the name
    assert fig.axes[0].get_title() == r"experiment fit \$\foo\$"


def test_the_train_report_does_not_say_set_for_a_rate_the_test_part_measured_above_it():
    """Thresholds fitted for both statistics, but the healthy test part's false-alarm rate
    (5 in 6 min) lies wholly above the 0.01-per-hour target: the sentence said the thresholds
    were "set for" the target (the monitor's caveat, and detect.json, said not controlled)."""
    from nnid.fault.thresholds import rate_interval
    from nnid.reports.train_report import monitor_sentence

    fit = {"value": 3.0, "method": "generalized Pareto, peaks over threshold", "peaks": 25}
    lo, hi = rate_interval(5, 0.1)
    measured = {"alarms": 5, "hours": 0.1, "rate_per_hour": 50.0, "interval": [lo, hi],
                "confidence": 0.95}  # fmt: skip
    detect = {
        "settings": {"false_alarm_per_hour": 0.01},
        "thresholds": {"ewma": fit, "cusum": fit},
        "calibration": {"hours": 0.1},
        "test_false_alarms": measured,
    }
    sentence = monitor_sentence(detect)
    assert "set for" not in sentence, sentence
    assert "the target of 0.01 false alarms per hour is not controlled" in sentence
    assert f"interval {lo:.3g}-{hi:.3g}), above the target of 0.01 per hour" in sentence
    # a measured interval that reaches the target leaves the thresholds set for it
    lo, hi = rate_interval(0, 0.1)
    quiet = {**measured, "alarms": 0, "rate_per_hour": 0.0, "interval": [lo, hi]}
    assert "set for 0.01 false alarms per hour" in monitor_sentence(
        {**detect, "test_false_alarms": quiet}
    )
