"""The report of ``nnid compare``: models of every family ranked on the same held-out data.

One self-contained HTML page (figures embedded, no scripts from elsewhere) and a Markdown twin
with the same tables for terminals and pull requests: the ranking with the sentence that says
which model to use (or that the data do not tell the first two apart), each held-out run's
free-run NRMSE on its own, velocity NRMSE per DOF in each prediction mode, each model's free
run overlaid on every held-out experiment (one figure per DOF), and for the models with a
force equation McCarter's Tables 5.1/5.2 for this data (J, J₀ and J/J₀, eq. 4.25), error
against complexity, the force series and the coefficients with their units.
"""

from __future__ import annotations

import html

import numpy as np
import pandas as pd

from nnid.datasets.log import run_of
from nnid.datasets.preprocess import experiment_rows
from nnid.evaluation.evaluate import diverged_columns
from nnid.physics.dofs import FORCES
from nnid.pipeline import RUNS_DECIDE
from nnid.reports.cells import missing, number, score, score_cell
from nnid.reports.figures import (
    FORCE_UNITS,
    IMAGES_CHECK,
    LONG_TICKS_LEFT_IN,
    UNITS,
    definitions,
    figure_uri,
    html_table,
    legend_outside,
    markdown_table,
    new_figure,
    page_head,
    plot_label,
    said_list,
)
from nnid.reports.loop_report import parameter_unit
from nnid.reports.stops import HEAD as STOP_HEAD
from nnid.reports.stops import TRAINING_TITLE, stage_cells
from nnid.reports.train_report import RUNS_TITLE, scored_columns

MODES = (
    ("free_run_nrmse", "Free-run velocity NRMSE"),
    ("k_step_nrmse", "{h} s-ahead velocity NRMSE"),
    ("one_step_nrmse", "One-step velocity NRMSE"),
)


def _held(row: dict, comparison: dict) -> dict:
    return row.get(comparison.get("held_out", "validation"), {})


def _total(row: dict, comparison: dict, key: str) -> str:
    part = _held(row, comparison)
    if key not in part:
        return "-"
    return score_cell(part[key], "total", diverged_columns(part, key))


def _ranked(row: dict, comparison: dict, key: str) -> str:
    """A ranking cell: the score the ranking used, over the outputs every model is scored on
    (``ranked_nrmse``); "-" where the mode was not scored or the models share no output."""
    if key not in _held(row, comparison) or not comparison.get("ranked_on"):
        return "-"
    value = row["ranked_nrmse"][key.removesuffix("_nrmse")]
    # diverged in any output, shared or its own: the ranking voided its score for it
    return score(value, diverged=bool(diverged_columns(_held(row, comparison), key)))


def _partial(comparison: dict) -> bool:
    """True where some model is scored on outputs the others are not."""
    shared = comparison.get("ranked_on", [])
    return any(set(_held(m, comparison).get("columns", [])) != set(shared)
               for m in comparison["models"])  # fmt: skip


def ranking_rows(comparison: dict) -> tuple[list[str], list[list[str]]]:
    """The ranking: one row per model, best first."""
    by_name = {m["name"]: m for m in comparison["models"]}
    head = [
        "rank",
        "model",
        "kind",
        "trainer",
        "parameters",
        "fit s",
        "free-run NRMSE",
        "k-step NRMSE",
        "one-step NRMSE",
        "scored samples",
        "J/J0",
        "validation used for",
    ]
    rows = []
    ranked = bool(comparison.get("ranked_on"))
    for k, name in enumerate(comparison["ranking"], 1):
        m = by_name[name]
        held = _held(m, comparison)
        rows.append(
            [
                str(k) if ranked else "-",
                name,
                m["kind"],
                str(m.get("trainer") or "-"),
                str(m["n_params"]),
                number(m["seconds"], 3),
                _ranked(m, comparison, "free_run_nrmse"),
                _ranked(m, comparison, "k_step_nrmse"),
                _ranked(m, comparison, "one_step_nrmse"),
                _scored(held),
                number(held.get("J_over_J0"), 3),
                m.get("validation_used_for") or "-",
            ]
        )
    return head, rows


def _scored(held: dict) -> str:
    """A model's scored held-out samples, and its k-step ones where fewer (every model of a
    comparison is scored on the same: after the longest warm-up among them)."""
    n, k = held.get("samples"), held.get("k_step_scored")
    if n is None:
        return "-"
    return f"{n} (k-step {k})" if k is not None and k != n else str(n)


def column_terms(comparison: dict) -> dict[str, str]:
    """What each column of the ranking means."""
    part = comparison.get("held_out", "validation")
    k = comparison.get("k_step_s")
    shared = comparison.get("ranked_on", [])
    if not shared:
        over = (
            "; the models share no output, so these cells are empty and the per-DOF tables "
            "compare them"
        )
    elif _partial(comparison):
        over = (
            f", mean over the outputs every model is scored on ({', '.join(shared)}): the models "
            "predict different outputs, and each one's other outputs are in the per-DOF tables"
        )
    else:
        over = ", mean over the excited DOFs"
    # the per-run table is shown only where there are several runs: pointed to only then
    table = f" ({RUNS_TITLE} below says each run's)" if run_rows(comparison)[1] else ""
    return {
        "rank": "order of the held-out free-run NRMSE below (models whose free run diverged or "
        "was not scored after, by their k-step error). The sentence above names the first "
        "model for use only where the data tell it from the second: with "
        f"{RUNS_DECIDE} or more held-out runs, where the first is lower than the second on at "
        "least two thirds of the runs (each scored alone, over the outputs it excites), "
        "whatever the pooled scores; on fewer, the two are called indistinguishable when "
        "their free-run NRMSEs print the same, or, on two runs, when the first is lower on "
        f"fewer than two thirds of the runs{table}",
        "parameters": "number of fitted parameters (network weights for NARX and state-space "
        "models)",
        "fit s": "wall time of the fit in seconds",
        "free-run NRMSE": f"RMSE of the velocity simulated from the {part} run's initial state "
        f"and its inputs alone, over the standard deviation of the measured velocity{over}; "
        "'diverged' where the simulation left the physical range",
        "k-step NRMSE": (
            f"the same error for predictions {number(k, 3)} s ahead, restarted from the measured "
            "state at every sample"
            if k
            else "not computed"
        ),
        "one-step NRMSE": "the same error one sample ahead",
        "scored samples": f"the {part} samples each model's errors are over: those after the "
        f"first {number(comparison.get('warmup_s'), 3)} s of each run and after "
        f"{_warmup_text(comparison)}; in brackets the k-step count, each prediction needing "
        "k samples of its run before it",
        "J/J0": "McCarter's force error (eq. 4.25): RMS of the force residual over RMS of the "
        "force the model's fitted terms explain (the viscous force τ̄ of eq. 4.4 for damping "
        "models, the regression's target for a Fossen fit); only for models with a force "
        "equation. Each model's τ̄ is drawn with its own smoothing settings, so the ratios "
        "share a J0 only where the force table's J0 column agrees",
        "validation used for": "what the model did with the validation run while fitting "
        "(early stopping or model selection): its validation scores are then not independent",
    }


def _warmup_text(comparison: dict) -> str:
    """What the scores leave out of each run besides ``warmup_s``: the longest warm-up among
    the models (``warmup_samples``), so every model is scored on the same samples; a
    comparison.json written before it was kept scored each model after its own."""
    n = comparison.get("warmup_samples")
    if n is None:
        return (
            "the model's own initial conditions (one sample for a physics model, its longest "
            "delay for a NARX network), so a model that needs more initial samples is scored "
            "on fewer"
        )
    samples = "sample" if n == 1 else "samples"
    return (
        f"its first {n} {samples}, the longest initial conditions among the models (one "
        "sample for a physics model, its longest delay for a NARX network), so every model "
        "is scored on the same samples"
    )


def outputs(comparison: dict, key: str) -> list[str]:
    """The outputs any model is scored on in one mode's held-out scores
    (:func:`~nnid.reports.train_report.scored_columns`' order)."""
    return scored_columns(_held(m, comparison).get(key, {}) for m in comparison["models"])


def dof_rows(comparison: dict, key: str) -> tuple[list[str], list[list[str]]]:
    """One prediction mode's NRMSE per DOF of each model on the held-out data."""
    dofs = outputs(comparison, key)
    rows = []
    for name in comparison["ranking"]:
        m = next(x for x in comparison["models"] if x["name"] == name)
        vals = _held(m, comparison).get(key, {})
        cells = [score_cell(vals, d, diverged_columns(_held(m, comparison), key)) for d in dofs]
        rows.append([name, *cells, _total(m, comparison, key)])
    return ["model", *dofs, "total"], rows


HEAD = [
    "model",
    "n̄",
    "train J",
    "train J0",
    "train J/J0",
    "validation J",
    "validation J0",
    "validation J/J0",
]


def table_rows(comparison: dict) -> list[list[str]]:
    """Rows of the Table 5.1/5.2 analogue for the damping models: n̄ terms, J, J₀ and J/J₀ on
    train and validation. Each model's force series τ̄ is its own (its savgol window and order,
    filter_lambda and zoh_midpoint make it), so J0 is shown: ratios over different J0 are of
    different targets."""
    rows = []
    force = [
        m for m in comparison["models"] if m["kind"] in ("synthesis", "sindy") and "J" in m["train"]
    ]
    for m in sorted(force, key=lambda m: -m["n_params"]):
        rows.append(
            [
                m["name"],
                str(m["n_params"]),
                number(m["train"]["J"], 4),
                number(m["train"].get("J0"), 4),
                number(m["train"]["J_over_J0"], 4),
                number(m["validation"].get("J"), 4),
                number(m["validation"].get("J0"), 4),
                number(m["validation"].get("J_over_J0"), 4),
            ]
        )
    return rows


def run_rows(comparison: dict) -> tuple[list[str], list[list[str]]]:
    """Each held-out run's free-run NRMSE per model (``ranked_free_run_per_experiment``: the
    run scored alone, over the outputs the ranking shares that it excites), models in ranking
    order; a run scored over fewer than all of them names its outputs in its head. No rows
    where the held-out data are one run or the models are not ranked. The pooled score hides
    how a lead is spread: a model lower on one run and higher on the rest can rank first."""
    if not comparison.get("ranked_on"):
        return [], []
    by_name = {m["name"]: m for m in comparison["models"]}
    runs: list[str] = []
    for m in comparison["models"]:
        runs += [r for r in m.get("ranked_free_run_per_experiment") or {} if r not in runs]
    if len(runs) < 2:
        return [], []
    rows = []
    for name in comparison["ranking"]:
        m = by_name[name]
        per = m.get("ranked_free_run_per_experiment") or {}
        left = _held(m, comparison).get("diverged_per_experiment") or {}
        rows.append([name, *(score(per[r], diverged=r in left) if r in per else "-" for r in runs)])
    shared = comparison["ranked_on"]
    over = comparison.get("ranked_on_per_experiment") or {}

    def head(run: str) -> str:
        cols = over.get(run, shared)
        return f"run {run}" if cols == shared else f"run {run} ({', '.join(cols) or 'none'})"

    return ["model", *map(head, runs)], rows


def _tables(comparison: dict) -> list[tuple[str, list[str], list[list[str]]]]:
    """(title, head, rows) of every table, in page order (HTML and Markdown share them)."""
    part = comparison.get("held_out", "validation")
    h = number(comparison.get("k_step_s"), 3)
    out = [("Ranking", *ranking_rows(comparison))]
    head, rows = run_rows(comparison)
    if rows:
        out.append((f"{RUNS_TITLE} ({part} data)", head, rows))
    for key, title in MODES:
        head, rows = dof_rows(comparison, key)
        if len(head) > 2:
            out.append((f"{title.format(h=h)} per DOF ({part} data)", head, rows))
    if table_rows(comparison):
        out.append(
            ("Force error (McCarter Tables 5.1/5.2 for this data)", HEAD, table_rows(comparison))
        )
    stages = [
        [m["name"] + ("" if s["member"] is None else f" (seed {s['member']})"), *stage_cells(s)]
        for m in comparison["models"]
        for s in m.get("training", [])
    ]
    if stages:
        out.append((TRAINING_TITLE, ["model", "stage", *STOP_HEAD], stages))
    return out


def all_warnings(comparison: dict) -> list[str]:
    """The comparison's warnings, then each model's fit warnings under its name."""
    own = [f"{m['name']}: {w}" for m in comparison["models"] for w in m.get("warnings", [])]
    return [*comparison.get("warnings", []), *own]


def markdown(comparison: dict) -> str:
    """The Markdown twin: the same tables as the HTML page."""
    lines = [
        f"# Model comparison: {comparison.get('vehicle') or ''}",
        "",
        comparison["summary"],
        "",
    ]
    lines += [_data_text(comparison), ""]
    for title, head, rows in _tables(comparison):
        lines += [f"## {title}", "", *markdown_table(head, rows), ""]
    lines += ["Columns:", ""]
    lines += [f"- **{k}**: {v}" for k, v in column_terms(comparison).items()]
    blocks = coefficient_blocks(comparison)
    if blocks:
        lines += ["", "## Coefficients"]
        for name, crow in blocks:
            lines += ["", f"### {name} ({len(crow)} coefficients)", ""]
            lines += markdown_table(COEFFICIENT_HEAD, crow)
    if all_warnings(comparison):
        lines += ["", "## Warnings", "", *(f"- {w}" for w in all_warnings(comparison))]
    return "\n".join(lines) + "\n"


def _data_text(comparison: dict) -> str:
    def runs(part: str) -> str:
        # a log without an experiment column is one run, named None in comparison.json
        names = ", ".join("the log" if n is None else str(n) for n in comparison[part])
        if comparison.get("split_by") != "block":
            return names
        share = comparison["fractions"][("train", "validation", "test").index(part)]
        return f"a block of {100 * share:.0f} % of {names}"

    text = f"Trained on {runs('train')}; validation on {runs('validation')}"
    if comparison.get("test"):
        text += f"; test on {runs('test')} (the ranking uses the test run)"
    text += f". The first {comparison['warmup_s']:g} s of every run are not scored"
    if comparison.get("warmup_samples"):  # the same samples for every model
        n = comparison["warmup_samples"]
        text += (
            f", nor its first {n} sample{'' if n == 1 else 's'} (the longest warm-up among "
            "the models, so that every model is scored on the same samples)"
        )
    if comparison.get("k_step_samples", 1) > 1:  # k-step predictions need k steps of history
        text += ", nor, for the k-step scores, a run's samples before its k-th"
    text += "."
    if comparison.get("autopilot_replay"):
        held = comparison.get("held_out", "validation")
        flown = [m["name"] for m in comparison["models"] if m.get(held, {}).get("closed_loop")]
        open_loop = [m["name"] for m in comparison["models"] if m["name"] not in flown]
        text += (
            " The log was flown under the simulator's autopilot; the free runs and k-step "
            "predictions of " + (", ".join(flown) or "no model") + " are flown under the same "
            "autopilot (its open-loop inputs replayed, its feedback computed on the model's own "
            "state), so they compare like with like with the log."
        )
        if open_loop:
            text += f" {', '.join(open_loop)} cannot fly under it and run open loop."
    return text


def unit_text(column: str) -> str:
    """An output's unit for an axis label: SI for the vehicle's velocities, else "unit not
    known" (a NARX output such as the cascaded tanks' ``y`` read "y []")."""
    return UNITS[column] if column in UNITS else "unit not known"


def diverged_at(comparison: dict, model: str, run: object, several: bool) -> dict[str, float]:
    """``{column: t}`` where a model's held-out free run diverged in one run (a gap's pieces
    are one: :func:`~nnid.datasets.preprocess.run_rows`): the run's own
    (``diverged_per_experiment``) where the held-out data are several runs, else the part's."""
    m = next((x for x in comparison["models"] if x["name"] == model), {})
    held = _held(m, comparison)
    if several:
        return (held.get("diverged_per_experiment") or {}).get(str(run)) or {}
    return held.get("diverged") or {}


def free_run_figures(
    held: pd.DataFrame,
    free_runs: dict[str, pd.DataFrame],
    dofs: list[str],
    comparison: dict | None = None,
) -> list[tuple[str, str]]:
    """Per held-out experiment and DOF, the measured velocity and every model's free run. A
    free run is clipped to the panel, so a model's that diverged says where in its legend
    label (from ``comparison``'s scores): a line run off the panel said nothing."""
    out = []
    t_all = held["t"].to_numpy(np.float64)
    runs = experiment_rows(held)
    # a piece a gap cut is drawn on its own (simulated from its own start), and said to
    # diverge where its run did within the piece's span (a run's pieces share its clock)
    run = run_of(held)
    several = len(set(run.values())) > 1
    for name, pos in runs:
        t = t_all[pos] - t_all[pos[0]]
        for d in dofs:
            # fixed margins: the constrained layout drew the figure twice (to place, then to
            # paint), and a legend wider than the figure squeezed the panel to a sliver
            fig, axes = new_figure(1, 1, 10.0, 3.2, fixed=True, left=LONG_TICKS_LEFT_IN)
            ax = axes[0, 0]
            y = held[d].to_numpy(np.float64)[pos]
            ax.plot(t, y, color="black", lw=1.4, label="measured")
            span = np.nanmax(y) - np.nanmin(y)
            for model, pred in free_runs.items():
                if d not in pred:
                    continue
                p = pred[d].to_numpy(np.float64)[pos]
                label = plot_label(model)
                gone = (
                    diverged_at(comparison, model, run.get(name, name), several)
                    if comparison
                    else {}
                )
                if d in gone and t_all[pos[0]] <= gone[d] <= t_all[pos[-1]]:  # the axis' clock
                    label += f" (diverged at t = {gone[d] - t_all[pos[0]]:.4g} s)"
                ax.plot(
                    t, np.clip(p, np.nanmin(y) - span, np.nanmax(y) + span), lw=0.9, label=label
                )
            ax.set_ylim(np.nanmin(y) - 0.6 * span, np.nanmax(y) + 0.6 * span)
            ax.set_xlabel("time since the start of the run [s]")
            ax.set_ylabel(f"{d} [{unit_text(d)}]")
            ax.tick_params(labelsize=8)
            legend_outside(ax, ncols=4, fontsize=7, side="below")
            label = f"{name}: {d}" if name is not None else d
            out.append((f"Free run, {label}", figure_uri(fig)))
    return out


def force_window(held: pd.DataFrame, window_s: float = 60.0) -> np.ndarray:
    """Positions of the force figure's rows: the first ``window_s`` of the first held-out run.
    Taken of every run, the runs' clocks (each from 0) drew them over each other, joined by a
    line from the end of one window back to the start of the next."""
    _, pos = experiment_rows(held)[0]
    t = held["t"].to_numpy(np.float64)[pos]
    return pos[t - t[0] <= window_s]


def measured_groups(measured: dict[str, pd.DataFrame]) -> list[tuple[list[str], pd.DataFrame]]:
    """The distinct force series τ̄ of the damping models, each with the models drawn from it
    (in first-seen order): models with the same smoothing settings share one."""
    groups: list[tuple[list[str], pd.DataFrame]] = []
    for name, series in measured.items():
        same = next((g for g in groups if g[1].equals(series)), None)
        if same is None:
            groups.append(([name], series))
        else:
            same[0].append(name)
    return groups


def force_figure(
    measured: dict[str, pd.DataFrame] | pd.DataFrame,
    forces: dict[str, pd.DataFrame],
    held: pd.DataFrame,
    window_s: float = 60.0,
) -> str:
    """Measured and predicted viscous force per DOF over the first ``window_s`` of the first
    held-out run (:func:`force_window`; a longer stretch turns many overlaid models into a
    blur), on the run's clock as the free-run figures. Each model is drawn beside its own τ̄
    (``measured``, per model): where the models' smoothing settings differ there is one black
    line per distinct τ̄, each in its own dash, named with its models. One DataFrame is one τ̄
    for every model."""
    if isinstance(measured, pd.DataFrame):
        measured = dict.fromkeys(forces, measured)
    keep = force_window(held, window_s)
    t = held["t"].to_numpy(np.float64)[keep]
    t = t - t[0]
    groups = measured_groups(measured)
    dashes = ["-", "--", ":", "-."]
    # fixed margins: the constrained layout drew the figure twice (to place, then to paint)
    fig, axes = new_figure(6, 1, 10.0, 1.7, fixed=True, left=LONG_TICKS_LEFT_IN)
    for k, ax in enumerate(axes[:, 0]):
        f = FORCES[k]
        for j, (names, series) in enumerate(groups):
            label = "measured τ̄" if len(groups) == 1 else f"τ̄ of {', '.join(names)}"
            ax.plot(t, series[f].to_numpy()[keep], color="black", lw=1.2,
                    ls=dashes[j % len(dashes)], label=plot_label(label))  # fmt: skip
        for name, series in forces.items():
            ax.plot(t, series[f].to_numpy()[keep], lw=0.8, label=plot_label(name))
        ax.set_ylabel(f"{f} [{FORCE_UNITS[f]}]")
        ax.tick_params(labelsize=8)
    legend_outside(axes[0, 0], ncols=5, fontsize=7)
    axes[-1, 0].set_xlabel("time since the start of the run [s]")
    return figure_uri(fig)


def complexity_figure(comparison: dict) -> str:
    """Validation J/J₀ against the number of terms, with the SINDy path. The path's points
    are √ of the mean per-output normalised MSE, not J/J₀ (√ of the pooled one): the axis says
    both, as on the VT690 log they differ by about 13 %. Each model's point and path in one
    colour, named in the legend above the panel."""
    # fixed margins: the constrained layout drew the figure twice (to place, then to paint).
    # The models are named in the legend, not beside their points: a name there ran past the
    # panel's right edge, which the constrained layout's crop only made room for by shrinking
    # the panel, and a legend above is measured to fit (legend_outside)
    fig, axes = new_figure(1, 1, 7.0, 4.0, fixed=True, left=LONG_TICKS_LEFT_IN)
    ax = axes[0, 0]
    drawn = 0
    for m in comparison["models"]:
        ratio = m["validation"].get("J_over_J0")
        # a NaN read in memory (a J over an output whose held-out target is zero) is as
        # unmeasured as JSON's null: no point, no legend entry (cells.missing, one rule)
        if missing(ratio) or m["kind"] not in ("synthesis", "sindy"):
            continue
        color = f"C{drawn % 10}"
        drawn += 1
        ax.scatter(m["n_params"], ratio, zorder=3, color=color, label=plot_label(m["name"]))
        j0 = m["validation"].get("J0")
        pts = sorted(
            (p["n_terms"], float(np.sqrt(p["validation_J"])))
            for p in m.get("sindy_path") or []
            if not missing(p.get("validation_J"))
        )
        if pts and not missing(j0) and j0:
            ax.plot(
                [p[0] for p in pts],
                [p[1] for p in pts],
                "--",
                color=color,
                label=plot_label(f"{m['name']} path (√ of normalised MSE)"),
            )
    ax.set_xlabel("number of terms n̄")
    ax.set_ylabel("validation error: points J / J0, path √ mean NMSE")
    ax.set_xscale("symlog")
    entries = len(ax.get_legend_handles_labels()[1])
    if entries:  # one row where it fits: a column read down split a model from its path
        legend_outside(ax, ncols=entries, fontsize=8)
    return figure_uri(fig)


def _of_run(held: pd.DataFrame) -> str:
    """The heading's " of run <name>" where the held-out data has several runs (the force
    figure's is the first), else nothing."""
    runs = experiment_rows(held)
    return f" of run {runs[0][0]}" if len(runs) > 1 else ""


COEFFICIENT_HEAD = ["coefficient", "unit", "value", "std. error"]


def coefficient_rows(coefs: dict) -> list[list[str]]:
    """A damping model's coefficients with their SI units and standard errors ("-" where the
    fit gives none: a Nelder-Mead cost has no least-squares covariance). Names as code spans,
    as the train report's (the HTML table draws them as ``<code>``): bare, the '*' of two
    products (``X:u*abs(u)*v*abs(v)``) set the Markdown twin's text between them in italics."""
    return [
        [f"`{k}`", parameter_unit(k), number(v["value"], 5), number(v.get("stderr"), 2)]
        for k, v in sorted(coefs.items())
    ]


def coefficient_blocks(comparison: dict) -> list[tuple[str, list[list[str]]]]:
    """(model name, :func:`coefficient_rows`) of each model with coefficients: the HTML page
    and the Markdown twin both write them from here."""
    return [
        (m["name"], coefficient_rows(m["coefficients"]))
        for m in comparison["models"]
        if m.get("coefficients")
    ]


def html_page(result) -> str:
    """The self-contained HTML report of a :class:`nnid.pipeline.CompareResult`."""
    comparison = result.comparison
    title = f"Model comparison: {comparison.get('vehicle') or ''}"
    tables = _tables(comparison)
    parts = [
        page_head(title),
        f"<p><b>{html.escape(comparison['summary'])}</b></p>",
        f"<p>{html.escape(_data_text(comparison))}</p>",
    ]
    title0, head0, rows0 = tables[0]
    parts += [f"<h2>{html.escape(title0)}</h2>", html_table(head0, rows0)]
    parts += [definitions(column_terms(comparison))]
    for t, head, rows in tables[1:]:
        parts += [f"<h2>{html.escape(t)}</h2>", html_table(head, rows)]
    held = result.held_out
    dofs = outputs(comparison, "free_run_nrmse")
    figures = free_run_figures(held, result.free_runs, [d for d in dofs if d in held], comparison)
    parts.append("<h2>Free runs on the held-out data</h2>")
    parts += [
        f"<h3>{html.escape(name)}</h3><img alt='{html.escape(name)}' src='{uri}'>"
        for name, uri in figures
    ]
    if result.forces:
        parts += [
            "<h2>Force error against complexity</h2>",
            f"<img alt='validation J/J0 against the number of terms' "
            f"src='{complexity_figure(comparison)}'>",
            f"<h2>Held-out force series (first 60 s{_of_run(held)})</h2>",
            f"<img alt='measured and predicted viscous force per DOF' "
            f"src='{force_figure(result.measured_force, result.forces, held)}'>",
            "<p>J is the RMS error of the viscous force (McCarter eq. 4.25), J0 the RMS of the "
            "force series τ̄ the damping model must explain (eq. 4.4); each model's τ̄ is drawn "
            "with its own smoothing settings, and each model is drawn beside its own. Time is "
            "since the start of the run, as in the free-run figures.</p>",
        ]
    coef_blocks = [
        f"<details><summary>{html.escape(name)} ({len(crow)} coefficients)"
        f"</summary>{html_table(COEFFICIENT_HEAD, crow)}</details>"
        for name, crow in coefficient_blocks(comparison)
    ]
    if coef_blocks:
        parts += ["<h2>Coefficients</h2>", *coef_blocks]
    parts.append(said_list(all_warnings(comparison)))
    parts += [IMAGES_CHECK, "</body></html>\n"]
    return "\n".join(parts)
