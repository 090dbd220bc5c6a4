"""The compare report's text and tables, built from hand-made scores (no model is trained):
the verdict's rule, the per-run table, the force table's J0, Markdown and legend escaping,
units of outputs that are not DOFs, and why a free run was not scored."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import nnid.reports.compare_report as report
from nnid.evaluation.evaluate import evaluate
from nnid.physics.dofs import FORCES
from nnid.pipeline import rank, ranked_columns, ranked_score, summary
from nnid.reports.figures import html_table, markdown_table
from nnid.reports.train_report import _errors, _runs


def _row(name: str, free: float | None, runs: dict[str, float] | None = None, **extra) -> dict:
    """A compare row scored on u in the validation part, with per-run scores where given."""
    held: dict = {
        "columns": ["u"],
        "samples": 100,
        "free_run_nrmse": {"u": free, "total": free},
        "one_step_nrmse": {"u": 0.01, "total": 0.01},
        "diverged": {},
    }
    if runs:
        held["free_run_nrmse_per_experiment"] = {r: {"u": v, "total": v} for r, v in runs.items()}
    row = {
        "name": name,
        "kind": "fossen",
        "trainer": "ls",
        "n_params": 6,
        "seconds": 0.5,
        "validation_used_for": None,
        "train": {},
        "validation": held,
    }
    return {**row, **extra}


def _comparison(rows: list[dict]) -> dict:
    """The comparison.json run_compare writes of these rows (its ranking, verdict, summary)."""
    from nnid.pipeline import ranked_runs, run_columns, verdict

    ranking = rank(rows, "validation")
    shared = ranked_columns(rows, "validation")
    by_run = run_columns(rows, "validation", shared)
    for row in rows:
        row["ranked_nrmse"] = {
            m: ranked_score(row, "validation", f"{m}_nrmse", shared)
            for m in ("free_run", "k_step", "one_step")
        }
        row["ranked_free_run_per_experiment"] = ranked_runs(row, "validation", by_run)
    return {
        "vehicle": "v",
        "models": rows,
        "k_step_s": None,
        "warmup_s": 1.0,
        "held_out": "validation",
        "ranking": ranking,
        "ranked_on": shared,
        "ranked_on_per_experiment": by_run,
        "train": ["a"],
        "validation": ["b", "c", "d"],
        "test": [],
        "split_by": "experiment",
        "fractions": [0.6, 0.4, 0.0],
        "verdict": verdict(rows, ranking, "validation"),
        "summary": summary(rows, ranking, "validation", False),
        "warnings": [],
    }


def test_two_models_that_print_the_same_score_are_called_indistinguishable():
    """The verdict named a winner whatever the gap: "Use A ... (0.213, against 0.213 for B)".
    Scores that print the same tell the models apart no more than the reader can."""
    rows = [_row("A", 0.2131), _row("B", 0.2134)]
    text = summary(rows, rank(rows, "validation"), "validation", False)
    assert not text.startswith("Use")
    assert "A (fossen, 6 parameters) and B (fossen, 6 parameters) are indistinguishable" in text
    assert "(0.213 and 0.213)" in text
    from nnid.reports.batch_report import _compare_table
    from nnid.runs import INDISTINGUISHABLE, best_model, no_best_why

    assert best_model(_comparison(rows)) is None  # the batch table names no best either
    # and says why: "-" alone read the same as no skill, no free run or no ranking
    assert no_best_why(_comparison(rows)) == INDISTINGUISHABLE
    row = {"data": "a.csv", "status": "ok", "best": None, "no_best": INDISTINGUISHABLE}
    assert f"none: {INDISTINGUISHABLE}" in _compare_table([row])


def test_a_pooled_lead_not_held_on_two_thirds_of_the_runs_is_no_win():
    """With several held-out runs, A lower pooled but lower on only 1 of 3 runs: not a win;
    lower on 3 of 3: named, with the count."""
    from nnid.pipeline import verdict
    from nnid.runs import best_model

    runs_a = {"b": 0.10, "c": 0.40, "d": 0.41}
    runs_b = {"b": 0.30, "c": 0.35, "d": 0.36}
    rows = [_row("A", 0.20, runs_a), _row("B", 0.25, runs_b)]
    told = verdict(rows, rank(rows, "validation"), "validation")
    assert told is not None
    assert (told["lower_on_runs"], told["runs"], told["indistinguishable"]) == (1, 3, True)
    text = summary(rows, rank(rows, "validation"), "validation", False)
    assert "are indistinguishable" in text and "A lower on 1 of 3 held-out runs" in text
    rows = [_row("A", 0.20, {"b": 0.1, "c": 0.2, "d": 0.3}), _row("B", 0.25, runs_b)]
    text = summary(rows, rank(rows, "validation"), "validation", False)
    assert text.startswith("Use A") and "0.2, against 0.25 for B" in text
    assert "A lower on 3 of 3 held-out runs" in text
    assert best_model(_comparison(rows)) == "A"


def test_the_report_tables_each_held_out_runs_free_run_and_states_the_rule():
    """comparison.json held each run's free-run NRMSE and the report never read it: both
    twins now table it per model, and the definitions state the verdict's rule."""
    rows = [
        _row("A", 0.20, {"b": 0.1, "c": 0.2, "d": 0.3}),
        _row("B", 0.25, {"b": 0.3, "c": 0.35, "d": 0.36}),
    ]
    comparison = _comparison(rows)
    head, body = report.run_rows(comparison)
    assert head == ["model", "run b", "run c", "run d"]
    assert body == [["A", "0.1", "0.2", "0.3"], ["B", "0.3", "0.35", "0.36"]]
    md = report.markdown(comparison)
    assert f"## {report.RUNS_TITLE} (validation data)" in md
    assert "| A | 0.1 | 0.2 | 0.3 |" in md
    assert "fewer than two thirds of the runs" in md
    assert comparison["ranking"] == ["A", "B"]  # the order is kept


def test_a_lead_on_every_run_is_named_though_the_pooled_scores_print_the_same():
    """A lower on 10 of 10 held-out runs, pooled 0.2131 against 0.2134: called
    indistinguishable, the printed tie overriding the runs. With three or more runs the runs
    decide; on two, a printed tie still stands."""
    from nnid.pipeline import verdict
    from nnid.runs import best_model

    names = [f"r{k}" for k in range(10)]
    rows = [
        _row("A", 0.2131, {r: 0.20 for r in names}),
        _row("B", 0.2134, {r: 0.21 for r in names}),
    ]
    told = verdict(rows, rank(rows, "validation"), "validation")
    assert told is not None and told["same_printed"]
    assert (told["lower_on_runs"], told["runs"], told["indistinguishable"]) == (10, 10, False)
    text = summary(rows, rank(rows, "validation"), "validation", False)
    assert text.startswith("Use A") and "A lower on 10 of 10 held-out runs" in text
    assert best_model(_comparison(rows)) == "A"
    assert "at least two thirds of the runs" in report.column_terms(_comparison(rows))["rank"]
    two = [_row("A", 0.2131, {"b": 0.2, "c": 0.2}), _row("B", 0.2134, {"b": 0.21, "c": 0.21})]
    assert verdict(two, rank(two, "validation"), "validation")["indistinguishable"]


def test_each_run_is_compared_on_the_ranked_outputs_it_excites():
    """Weiss-style held-out runs each excite one of u and v: each run scored over both had no
    score, the per-run table read "not scored" everywhere and the two-thirds rule never
    applied. Each run is scored over the ranked outputs it excites, the same for both models,
    and the table names them where fewer than all."""
    from nnid.pipeline import verdict

    def weiss(name: str, surge: float, sway: float) -> dict:
        row = _row(name, (surge + sway) / 2)
        row["validation"]["columns"] = ["u", "v"]
        row["validation"]["free_run_nrmse"] = {"u": surge, "v": sway, "total": (surge + sway) / 2}
        row["validation"]["free_run_nrmse_per_experiment"] = {
            "surge": {"u": surge, "total": surge},
            "sway": {"v": sway, "total": sway},
            "both": {"u": surge, "v": sway, "total": (surge + sway) / 2},
        }
        return row

    rows = [weiss("A", 0.10, 0.30), weiss("B", 0.20, 0.35)]
    comparison = _comparison(rows)
    assert comparison["ranked_on_per_experiment"] == {
        "surge": ["u"], "sway": ["v"], "both": ["u", "v"]
    }  # fmt: skip
    assert rows[0]["ranked_free_run_per_experiment"] == {"surge": 0.1, "sway": 0.3, "both": 0.2}
    told = verdict(rows, rank(rows, "validation"), "validation")
    assert (told["lower_on_runs"], told["runs"], told["indistinguishable"]) == (3, 3, False)
    head, body = report.run_rows(comparison)
    assert head == ["model", "run surge (u)", "run sway (v)", "run both"]
    assert body[0] == ["A", "0.1", "0.3", "0.2"]


def test_the_rank_definition_points_to_the_per_run_table_only_where_it_is_shown():
    """With one held-out run there is no per-run table, and the rank definition said
    "(Free-run NRMSE of each held-out run on its own below says each run's)" all the same."""
    one = _comparison([_row("A", 0.2), _row("B", 0.3)])
    assert report.RUNS_TITLE not in report.column_terms(one)["rank"]
    assert report.RUNS_TITLE not in report.markdown(one)
    runs = {"b": 0.1, "c": 0.2}
    several = _comparison([_row("A", 0.2, runs), _row("B", 0.3, runs)])
    assert f"({report.RUNS_TITLE} below says" in report.column_terms(several)["rank"]


def test_a_score_just_above_one_is_not_printed_as_one():
    """A score of 1.0004 printed "1" beside "is above 1"; the batch table named it best."""
    rows = [_row("A", 1.0004), _row("B", 1.2)]
    text = summary(rows, rank(rows, "validation"), "validation", False)
    assert "No trained model has skill" in text and "1.0004" in text
    from nnid.runs import NO_SKILL, best_model, no_best_why

    assert best_model(_comparison(rows)) is None
    assert no_best_why(_comparison(rows)) == NO_SKILL


def test_the_summary_says_why_a_free_run_was_not_scored():
    """Every missing, non-diverged free run was said to have "no sample left after the
    warm-ups", also one of a constant output or of no output at all."""
    from nnid.evaluation.evaluate import CONSTANT, NO_OUTPUT, not_scored_key

    const = _row("C", None)
    const["validation"][not_scored_key("free_run")] = {"u": CONSTANT}
    none = _row("N", None)
    none["validation"][not_scored_key("free_run")] = {"total": NO_OUTPUT}
    rows = [_row("A", 0.2), _row("B", 0.5), const, none]
    text = summary(rows, rank(rows, "validation"), "validation", False)
    assert f"Not scored in free run (u {CONSTANT}): C." in text
    assert f"Not scored in free run ({NO_OUTPUT}): N." in text
    assert "no sample left" not in text


class _Constant:
    """A fitted model of one output ``y`` that predicts it exactly."""

    targets_ = ("y",)
    warmup_samples_ = 1
    has_force_equation = False

    def predict(self, log: pd.DataFrame, mode="free_run") -> pd.DataFrame:
        return log[["y"]].copy()


def test_evaluate_records_why_a_score_is_none():
    """A held-out output that does not vary scores None (no divisor): evaluate says why."""
    from nnid.evaluation.evaluate import CONSTANT, not_scored_key

    log = pd.DataFrame({"t": np.arange(50) * 0.1, "y": 2.0})
    out = evaluate(_Constant(), log, ("free_run",))
    assert out["free_run_nrmse"]["y"] is None
    assert out[not_scored_key("free_run")] == {"y": CONSTANT}
    log["y"] = np.sin(log["t"])
    assert not_scored_key("free_run") not in evaluate(_Constant(), log, ("free_run",))


def test_the_force_table_shows_each_models_j0():
    """Each damping model's τ̄ comes from its own smoothing settings: J/J0 of different J0
    sat side by side with no J0 to tell."""
    rows = [
        {"name": n, "kind": "synthesis", "n_params": 4,
         "train": {"J": 1.0, "J0": j0, "J_over_J0": 1.0 / j0},
         "validation": {"J": 2.0, "J0": j0 + 1, "J_over_J0": 2.0 / (j0 + 1)}}
        for n, j0 in (("a", 4.0), ("b", 9.0))
    ]  # fmt: skip
    assert report.HEAD[3] == "train J0" and report.HEAD[6] == "validation J0"
    table = report.table_rows({"models": rows})
    assert [r[3] for r in table] == ["4", "9"] and [r[6] for r in table] == ["5", "10"]


def test_a_pipe_in_a_model_name_does_not_shift_the_markdown_columns():
    lines = markdown_table(["model", "score"], [["a|b", "0.2"]])
    assert lines[-1] == r"| a\|b | 0.2 |"


def test_the_markdown_twin_has_the_coefficient_tables_with_units():
    """The HTML page tabled each damping model's coefficients; the Markdown twin did not, and
    neither gave units."""
    rows = [_row("A", 0.2), _row("B", 0.3)]
    rows[0]["coefficients"] = {"X:u*abs(u)": {"value": -61.117, "stderr": 1.5}}
    md = report.markdown(_comparison(rows))
    assert "## Coefficients" in md and "### A (1 coefficients)" in md
    assert "| `X:u*abs(u)` | N / (m/s · m/s) | -61.117 | 1.5 |" in md
    assert report.COEFFICIENT_HEAD == ["coefficient", "unit", "value", "std. error"]


def test_coefficient_names_are_not_read_as_markdown_emphasis():
    """A coefficient of two products has two '*': bare in the Markdown twin, the text
    between them was set in italics and the stars dropped. Written as code spans, as the train
    report's parameters are, in both tables (the HTML one draws them as <code>)."""
    name = "X:u*abs(u)*v*abs(v)"
    rows = [_row("A", 0.2), _row("B", 0.3)]
    rows[0]["coefficients"] = {name: {"value": -2.0, "stderr": None}, "Y:v_dot": {"value": 1.0}}
    comparison = _comparison(rows)
    md = report.markdown(comparison)
    cells = [line.split(" | ")[0].removeprefix("| ") for line in md.splitlines()]
    assert f"`{name}`" in cells and "`Y:v_dot`" in cells
    [(model, crow)] = report.coefficient_blocks(comparison)  # the HTML page's tables too
    assert model == "A" and f"<td><code>{name}</code></td>" in html_table(
        report.COEFFICIENT_HEAD, crow
    )


def test_plot_labels_escape_mathtext_and_a_leading_underscore():
    from nnid.reports.figures import plot_label

    assert plot_label("_hidden") == " _hidden"
    assert plot_label("cost $x$") == r"cost \$x\$"


def _held(t0: float = 100.0) -> pd.DataFrame:
    t = np.arange(0.0, 20.0, 0.1)
    return pd.DataFrame({"t": t0 + t, "experiment": "r", "y": np.sin(t), "u": np.cos(t)})


def test_free_run_legends_name_every_model_and_survive_mathtext(monkeypatch):
    """A model named with a leading '_' was left out of the legend, and a bad '$' pair raised
    in savefig after every fit. A diverged free run, clipped off the panel, says when it left
    in its label; an output that is not a DOF has no unit to show."""
    held = _held()
    runs = {"_hidden": held[["y", "u"]], r"cost $\frac{$ x": 2 * held[["y", "u"]]}
    comparison = {
        "held_out": "validation",
        "models": [
            {"name": "_hidden", "validation": {"diverged": {}}},
            {"name": r"cost $\frac{$ x", "validation": {"diverged": {"y": 105.0}}},
        ],
    }
    drawn = []
    real = report.figure_uri
    monkeypatch.setattr(report, "figure_uri", lambda fig: drawn.append(fig) or real(fig))
    report.free_run_figures(held, runs, ["y"], comparison)  # savefig raised on the name
    (ax,) = drawn[0].axes
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts == ["measured", " _hidden", r"cost \$\frac{\$ x (diverged at t = 5 s)"]
    assert ax.get_ylabel() == "y [unit not known]"


def test_a_free_run_that_diverged_in_a_gap_piece_says_so_on_that_piece_at_its_time(monkeypatch):
    """A gap cut run a into two pieces, each drawn on its own from its own start: the run's
    free run diverged at t = 20 s of its clock, in the second piece (from 15 s). That piece's
    legend says so at 5 s, its own clock; the first piece's and run b's say nothing."""
    from nnid.datasets.log import PIECE_OF

    t = np.arange(0.0, 10.0, 0.1)
    pieces = [("a#1", "a", t), ("a#2", "a", t + 15.0), ("b", None, t)]
    held = pd.concat(
        [pd.DataFrame({"t": tt, "experiment": e, PIECE_OF: r, "y": np.sin(tt)})
         for e, r, tt in pieces],
        ignore_index=True,
    )  # fmt: skip
    comparison = {
        "held_out": "validation",
        "models": [{"name": "m", "validation": {"diverged": {"y": 20.0},
                                                "diverged_per_experiment": {"a": {"y": 20.0}}}}],
    }  # fmt: skip
    drawn = []
    monkeypatch.setattr(report, "figure_uri", lambda fig: drawn.append(fig) or "data:")
    figures = report.free_run_figures(held, {"m": held[["y"]]}, ["y"], comparison)
    assert [name for name, _ in figures] == [
        "Free run, a#1: y",
        "Free run, a#2: y",
        "Free run, b: y",
    ]
    labels = [[t.get_text() for t in fig.axes[0].get_legend().get_texts()] for fig in drawn]
    assert labels == [
        ["measured", "m"],
        ["measured", "m (diverged at t = 5 s)"],
        ["measured", "m"],
    ]


def test_each_model_is_drawn_against_its_own_force_series_on_the_runs_clock(monkeypatch):
    """The force figure drew every model against the last model's τ̄, on the log's absolute
    clock where the free-run figures use time since the run's start."""
    held = _held()
    one = pd.DataFrame({f: np.sin(held["t"]) for f in FORCES}, index=held.index)
    measured = {"a": one, "b": 2 * one, "c": one}
    drawn = []
    monkeypatch.setattr(report, "figure_uri", lambda fig: drawn.append(fig) or "data:")
    report.force_figure(measured, {n: 0.9 * s for n, s in measured.items()}, held)
    ax = drawn[0].axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert texts[:2] == ["τ̄ of a, c", "τ̄ of b"]
    assert ax.lines[1].get_ydata()[5] == pytest.approx(2 * one["X"].iloc[5])
    assert ax.lines[0].get_xdata()[0] == 0.0
    assert drawn[0].axes[-1].get_xlabel() == "time since the start of the run [s]"


def test_outputs_keep_first_seen_order_after_the_dofs():
    comparison = {
        "held_out": "validation",
        "models": [
            {"validation": {"free_run_nrmse": {"z2": 0.1, "r": 0.1, "total": 0.1}}},
            {"validation": {"free_run_nrmse": {"a1": 0.1, "u": 0.1, "total": 0.1}}},
        ],
    }
    assert report.outputs(comparison, "free_run_nrmse") == ["u", "r", "z2", "a1"]


def test_the_train_reports_html_tables_show_an_output_that_is_not_a_dof():
    """The HTML error tables had the six DOFs as columns whatever was scored: a NARX's ``y``
    was in the Markdown twin and not in the HTML."""
    scores = {"free_run_nrmse": {"y": 0.3, "total": 0.3}, "diverged": {}}
    per = {"a": {"y": 0.2, "total": 0.2}, "b": {"y": 0.4, "total": 0.4}}
    metrics = {"validation": {**scores, "free_run_nrmse_per_experiment": per}}
    head, rows = _errors(metrics)
    assert head == ["split", "mode", "y", "total"] and rows[0][2:] == ["0.3", "0.3"]
    head, rows = _runs(metrics)
    assert head == ["split", "run", "y", "total"] and rows[1] == ["validation", "b", "0.4", "0.4"]
