"""The report of ``nnid train``: parameters with uncertainty and held-out errors, for a model
of any kind, as Markdown (the twin of ``metrics.json``) and as one self-contained HTML page.
For a hybrid the page also shows the physics-only baseline on the same split, the learned
correction force against the states and inputs it depends on most, the free runs of both on a
held-out experiment, and the dominant terms of the correction named in the effect
vocabulary."""

from __future__ import annotations

import html
from collections.abc import Iterable
from typing import Any

import numpy as np
import pandas as pd

from nnid.datasets.log import TAU, VELOCITY
from nnid.datasets.preprocess import experiment_rows
from nnid.evaluation.evaluate import diverged_columns
from nnid.evaluation.persistence import REMEMBERED
from nnid.fault.thresholds import threshold_caveat
from nnid.physics.dofs import DOFS, FORCES
from nnid.reports.cells import number, score_cell, thresholds_cell
from nnid.reports.figures import (
    FORCE_UNITS,
    IMAGES_CHECK,
    LONG_TICKS_LEFT_IN,
    UNITS,
    definitions,
    figure_uri,
    html_table,
    markdown_table,
    new_figure,
    page_head,
    plot_label,
    said_list,
)
from nnid.reports.loop_report import parameter_unit
from nnid.reports.stops import HEAD as STOP_HEAD
from nnid.reports.stops import TRAINING_TITLE, stage_cells, training_stages

ERROR_KEYS = (
    ("free_run_nrmse", "free-run NRMSE"),
    ("k_step_nrmse", "k-step NRMSE"),
    ("one_step_nrmse", "one-step NRMSE"),
    ("force_rmse", "force residual RMS (N, N m)"),
)


def _rel(value, ref) -> str:
    if value is None or ref in (None, 0):
        return "-"
    return f"{(value / ref - 1) * 100:.3g} %"


def _params_table(metrics: dict) -> tuple[list[str], list[list[str]]]:
    params = metrics["params"]
    physical = any("percentile_error" in p or "vehicle_file" in p for p in params.values())
    ref = metrics.get("reference", {})
    ref_values = ref.get("values", {})
    head = (
        ["parameter", "unit", "estimate", "std. error"]
        if physical
        else ["parameter", "estimate", "std. error"]
    )
    if physical:
        head += ["percentile error", "significant (95 %)", "vehicle file", "estimate / file − 1"]
    if ref_values:
        head += [ref.get("label", "reference"), "estimate / reference − 1"]
    rows = []
    for name, p in params.items():
        row = [f"`{name}`", _estimate(p), number(p["stderr"], 2)]
        if physical:
            pe = p.get("percentile_error")
            row.insert(1, parameter_unit(name))
            row += [
                f"{number(pe, 3)} %" if pe is not None else "-",
                _significance(p),
                number(p.get("vehicle_file"), 5),
                _rel(p["value"], p.get("vehicle_file")),
            ]
        if ref_values:
            r = ref_values.get(name)
            row += [number(r, 5), _rel(p["value"], r)]
        rows.append(row)
    return head, rows


def _estimate(p: dict) -> str:
    """The estimate cell: the value, or "-" for none; for an unidentified parameter its model
    simulates at another value (the vehicle file's, ``simulated_at``) "- (simulated at X)",
    so that no one reads the model's predictions as resting on the fit alone."""
    if p["value"] is None and p.get("simulated_at") is not None:
        return f"- (simulated at {number(p['simulated_at'], 5)})"
    return number(p["value"], 5)


def _significance(p: dict) -> str:
    """The significance cell: "yes" or "no" by the 95 % test, "not measured" for a parameter
    only rows the fit left out read (not finite: no data on it at all), "not excited" for one
    the data do not excite (its model's ``not_excited_``, or a zero regressor: fitted to noise
    or not at all, its "no" is no test result), :data:`REMEMBERED` for one a recursive
    estimator's memory does not excite but earlier samples did (its value is learnt from data;
    before "not measured", which the memory alone may say of it), "collinear" for one the data
    do not separate from others (only their combination is measured), "-" where no test ran (a
    jointly trained value without s.e.)."""
    if p.get("remembered"):
        return REMEMBERED
    if p.get("measured") is False:
        return "not measured"
    if p.get("excited") is False:
        return "not excited"
    if p.get("collinear"):
        return "collinear"
    if p.get("significant") is None:
        return "-"
    return "yes" if p["significant"] else "no"


PRIME_NOT_EXCITED = "(not excited by the data: fitted to noise, no standard error)"
#: one excited before a recursive estimator's memory only (:data:`REMEMBERED`)
PRIME_REMEMBERED = (
    "(not excited in the estimator's memory: value remembered from earlier samples, "
    "no standard error)"
)


def _prime_error(v: dict) -> str:
    """What follows a Prime-system value: its standard error, or why it has none."""
    if v.get("remembered"):
        return PRIME_REMEMBERED
    return f"± {number(v['stderr'], 2)}" if v.get("excited", True) else PRIME_NOT_EXCITED


def _prime(metrics: dict) -> tuple[str, list[tuple[str, str]]] | None:
    """The Prime-system I section (Weiss eqs 111-122) of ``metrics["nondimensional"]``: its
    title and, per coefficient, its name and "value ± s.e." (or why it has no s.e.); None
    without one. The Markdown and the HTML both write it from here."""
    nd = metrics.get("nondimensional")
    if not nd:
        return None
    title = f"Prime-system I (U = {nd['speed']} m/s, L = {nd['length']} m)"
    items = [(k, f"{number(v['value'], 5)} {_prime_error(v)}") for k, v in nd["params"].items()]
    return title, items


def train_markdown(metrics: dict) -> str:
    """Markdown for a ``metrics.json`` of any model kind."""
    lines = [
        f"# {metrics['model']} model"
        + (f" of '{metrics['vehicle']}'" if metrics.get("vehicle") else "")
        + f" ({metrics.get('trainer') or '-'})",
        "",
        f"{metrics.get('n_params', len(metrics['params']))} parameters.",
        "",
        "## Parameters",
        "",
        *markdown_table(*_params_table(metrics)),
    ]
    used = metrics.get("validation_used_for")
    for part in ("train", "validation", "test"):
        scores = metrics.get(part)
        if not scores:
            continue
        note = f"; used for {used} while fitting" if part == "validation" and used else ""
        lines += [
            "",
            f"## Errors on the {part} split ({scores.get('samples', '?')} samples scored, "
            f"the first {metrics.get('warmup_s', 0)} s of each run excluded{_k_rows(scores)}"
            f"{note})",
            "",
        ]
        for key, label in ERROR_KEYS:
            if key in scores:
                vals, went = scores[key], diverged_columns(scores, key)
                cells = ", ".join(f"{k} {score_cell(vals, k, went)}" for k in vals)
                lines.append(f"- {label}: {cells}")
        if scores.get("J") is not None:
            lines.append(f"- J = {number(scores['J'], 4)}, J/J0 = {number(scores['J_over_J0'], 3)}")
        for key in ("diverged", "k_step_diverged", "one_step_diverged"):
            if scores.get(key):
                when = ", ".join(f"{d} at t = {t:.4g} s" for d, t in scores[key].items())
                lines.append(f"- **{key.replace('_', ' ')}**: {when}")
    if metrics.get("baseline"):
        lines += [
            "",
            "## Against the physics-only baseline",
            "",
            *markdown_table(*_baseline(metrics)),
        ]
    runs = _runs(metrics)
    if runs[1]:
        lines += ["", f"## {RUNS_TITLE}", "", *markdown_table(*runs)]
    if metrics.get("detect"):
        lines += ["", f"## {MONITOR_TITLE}", "", monitor_sentence(metrics["detect"]) + "."]
    if metrics.get("members"):
        lines += [
            "",
            "## Ensemble members (free-run NRMSE of each seed alone)",
            "",
            *markdown_table(*_members(metrics)),
        ]
    training = _training(metrics)
    if training[1]:
        lines += ["", f"## {TRAINING_TITLE}", "", *markdown_table(*training)]
    if metrics.get("correction"):
        head, rows, explained = _terms(metrics)
        lines += [
            "",
            "## What the network learned",
            "",
            _learned_sentence(metrics, explained) + (":" if rows[0][0] != "-" else "."),
            "",
            *markdown_table(head, rows),
            "",
            "Network force over the physics' damping force (RMS ratio per DOF):",
            "",
            *markdown_table(*_shares(metrics)),
        ]
    if metrics.get("warnings"):
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in metrics["warnings"]]
    prime = _prime(metrics)
    if prime:
        lines += ["", f"## {prime[0]}", ""] + [f"- `{k}` = {text}" for k, text in prime[1]]
    lines += ["", f"Fitted and scored in {metrics['seconds']:.1f} s."]
    return "\n".join(lines) + "\n"


# -- tables shared by the Markdown and the HTML --------------------------------------------------


def _k_rows(scores: dict) -> str:
    """The k-step scores' own sample count, where it differs: a k-step prediction needs k
    samples of its run before it (and the model's own warm-up), so fewer are scored."""
    k = scores.get("k_step_scored")
    if k is None or k == scores.get("samples"):
        return ""
    return f"; k-step: {k} samples, as each needs k samples of its run before it"


def _baseline(metrics: dict) -> tuple[list[str], list[list[str]]]:
    """Free-run, k-step and one-step NRMSE totals of the model and its baseline per held-out
    split, and the ratio model / baseline of the free run."""
    head = ["split", "model", "free-run NRMSE", "k-step NRMSE", "one-step NRMSE", "ratio"]
    base = metrics["baseline"]
    rows = []
    for part in ("validation", "test"):
        if part not in base:
            continue
        free = metrics[part].get("free_run_nrmse", {}).get("total")
        ref = base[part].get("free_run_nrmse", {}).get("total")
        for name, scores in ((metrics["model"], metrics[part]), (base["model"], base[part])):
            rows.append(
                [
                    part,
                    name,
                    *(
                        score_cell(scores[k], "total", diverged_columns(scores, k))
                        if k in scores
                        else "-"
                        for k in ("free_run_nrmse", "k_step_nrmse", "one_step_nrmse")
                    ),
                    # a free run of 0.0 is a score: only a missing one or a zero divisor
                    # leaves the ratio out
                    number(free / ref, 3)
                    if scores is metrics[part] and free is not None and ref
                    else "",
                ]
            )
    return head, rows


#: the title of the table of each held-out run's free-run NRMSE, scored alone (this report's
#: and the compare report's)
RUNS_TITLE = "Free-run NRMSE of each held-out run on its own"


def _runs(metrics: dict) -> tuple[list[str], list[list[str]]]:
    """Each run of a held-out split of several runs, scored alone (its own std): the split's
    pooled NRMSE can hide a run that fails on an output it barely moves."""
    scored = [
        (part, run, vals)
        for part in ("validation", "test")
        for run, vals in (
            (metrics.get(part) or {}).get("free_run_nrmse_per_experiment") or {}
        ).items()
    ]
    columns = scored_columns([vals for _, _, vals in scored])
    rows = []
    for part, run, vals in scored:
        left = (metrics.get(part) or {}).get("diverged_per_experiment") or {}
        rows.append([part, run, *_dof_cells(vals, left.get(run, {}), columns)])
    return ["split", "run", *columns, "total"], rows


MONITOR_TITLE = "Residual monitor (fault detection)"


def monitor_sentence(detect: dict) -> str:
    """What a train run's ``[detect]`` calibration gave: the thresholds, the healthy time they
    were set on (and, where they do not hold the target rate, why: the monitor's caveat,
    :func:`nnid.fault.thresholds.threshold_caveat`), and the alarms on the healthy test part
    with their exact Poisson interval (or that no test part measured them)."""
    th = detect["thresholds"]
    cal = detect["calibration"]
    target = detect["settings"].get("false_alarm_per_hour")
    test = detect.get("test_false_alarms")
    stats = thresholds_cell(th)
    on = f"{60 * cal['hours']:.1f} min of healthy validation data"
    # a metrics.json without the target (none was set) has no rate to hold or to miss
    caveat = None if target is None else threshold_caveat(th, cal["hours"], test, target)
    if caveat is None:
        text = f"thresholds {stats}, set for {number(target, 3)} false alarms per hour on {on}"
    else:  # too few peaks for a rate fit, or a measured rate wholly above the target
        text = (
            f"thresholds {stats} from {on}, the target of {number(target, 3)} false alarms "
            f"per hour is not controlled: {caveat}"
        )
    if test is None:
        return text + "; no test part: the false-alarm rate was not measured"
    lo, hi = test["interval"]
    return (
        text + f"; on the healthy test part ({60 * test['hours']:.1f} min): {test['alarms']} "
        f"alarm(s), {number(test['rate_per_hour'], 3)} per hour "
        f"({100 * test['confidence']:.0f} % interval {number(lo, 3)}-{number(hi, 3)})"
    )


def _members(metrics: dict) -> tuple[list[str], list[list[str]]]:
    """An ensemble's members: free-run NRMSE per output and total per held-out split."""
    parts = [p for p in ("validation", "test") if p in metrics["members"][0]]
    cols = list(metrics["members"][0][parts[0]]["free_run_nrmse"]) if parts else []
    head = ["seed", *(f"{p} {c}" for p in parts for c in cols)]
    rows = []
    for member in metrics["members"]:
        cells = []
        for p in parts:
            vals = member[p]["free_run_nrmse"]
            went = diverged_columns(member[p], "free_run_nrmse")
            cells += [score_cell(vals, c, went) for c in cols]
        rows.append([str(member["seed"]), *cells])
    return head, rows


def _training(metrics: dict) -> tuple[list[str], list[list[str]]]:
    """Why each training stage of the model (each ensemble member) ended, in words."""
    stages = training_stages(metrics.get("describe") or {})
    members = any(s["member"] is not None for s in stages)
    head = ["stage", *STOP_HEAD]
    if members:
        return ["member", *head], [[f"seed {s['member']}", *stage_cells(s)] for s in stages]
    return head, [stage_cells(s) for s in stages]


def _terms(metrics: dict) -> tuple[list[str], list[list[str]], str]:
    expl = metrics["correction"]["explanation"]
    head = ["term", "meaning", "value", "share of the learned force"]
    rows = [
        [f"`{t['effect']}`", t["meaning"], number(t["value"], 3), f"{100 * t['share']:.1f} %"]
        for t in expl["terms"]
    ] or [["-", "no term explains a share of the learned force on its own", "-", "-"]]
    return head, rows, f"{100 * expl['explained']:.0f} %"


def _learned_sentence(metrics: dict, explained: str) -> str:
    """What the terms table is of: the learned force on the training runs, or none at all (a
    network whose training kept its zero start has nothing to explain)."""
    train = metrics["correction"]["share_of_damping_force"].get("train") or {}
    if train.get("max") == 0:
        return "The network's force is zero on the training runs: it learned nothing to explain"
    return (
        "Dominant terms of the learned force on the training runs (together they explain "
        f"{explained} of it)"
    )


def _shares(metrics: dict) -> tuple[list[str], list[list[str]]]:
    shares = metrics["correction"]["share_of_damping_force"]
    dofs = [d for d in DOFS if any(d in v for v in shares.values())]
    head = ["split", *dofs, "max"]
    rows = [
        [part, *(number(v.get(d), 2) for d in dofs), number(v.get("max"), 2)]
        for part, v in shares.items()
    ]
    return head, rows


# -- HTML ----------------------------------------------------------------------------------------


def train_html(metrics: dict, figures: dict[str, Any] | None = None) -> str:
    """The train report as one self-contained HTML page (figures embedded)."""
    figures = figures or {}
    title = f"{metrics['model']} model" + (
        f" of '{metrics['vehicle']}'" if metrics.get("vehicle") else ""
    )
    out = [page_head(title)]
    out.append(
        f"<p>Trainer: {html.escape(str(metrics.get('trainer') or '-'))}; "
        f"{metrics.get('n_params', '?')} parameters; fitted and scored in "
        f"{metrics['seconds']:.1f} s.</p>"
    )
    used = metrics.get("validation_used_for")
    if used:
        out.append(
            f"<p>The validation split was used for {html.escape(used)} while fitting: its "
            "scores are not independent of the fit"
            + (", the test split's are." if metrics.get("test") else ".")
            + "</p>"
        )
    out.append("<h2>Velocity NRMSE per split</h2>")
    out.append(html_table(*_errors(metrics)))
    out.append(
        definitions(
            {
                "NRMSE": "RMS error over the standard deviation of the measured signal, "
                "warm-up excluded (0 is perfect, 1 is as good as predicting the mean)",
                "free run": "simulated from the first measured state of each experiment "
                "with the logged inputs only",
                "one step": "one sample ahead from every measured state",
            }
        )
    )
    if metrics.get("baseline"):
        out.append("<h2>Against the physics-only baseline (same split)</h2>")
        out.append(html_table(*_baseline(metrics)))
        out.append(
            definitions({"ratio": "the model's free-run NRMSE over the baseline's (< 1: better)"})
        )
    runs = _runs(metrics)
    if runs[1]:
        out.append(f"<h2>{RUNS_TITLE}</h2>")
        out.append(html_table(*runs))
    if metrics.get("detect"):
        out.append(f"<h2>{MONITOR_TITLE}</h2>")
        out.append(f"<p>{html.escape(monitor_sentence(metrics['detect']))}.</p>")
    if metrics.get("members"):
        out.append("<h2>Ensemble members (free-run NRMSE of each seed alone)</h2>")
        out.append(html_table(*_members(metrics)))
    training = _training(metrics)
    if training[1]:
        out.append(f"<h2>{TRAINING_TITLE}</h2>")
        out.append(html_table(*training))
    if "free_run" in figures:
        out.append("<h2>Free run on a held-out experiment</h2>")
        out.append(_img(_free_run_figure(figures)))
    if metrics.get("correction"):
        head, rows, explained = _terms(metrics)
        out.append("<h2>What the network learned</h2>")
        out.append(
            "<p>The learned force at the measured states and inputs, regressed on the effect "
            "vocabulary's columns and McCarter's basis library (sparse regression). "
            f"{html.escape(_learned_sentence(metrics, explained))}.</p>"
        )
        out.append(html_table(head, rows))
        out.append(
            definitions(
                {
                    "value": "the term's size in the vocabulary's units (a damping "
                    "coefficient, a current in m/s, an installation ratio, ...)",
                    "share": "the term's part of the learned force's weighted sum of squares",
                }
            )
        )
        out.append("<h3>Network force over the physics' damping force (RMS, per DOF)</h3>")
        out.append(html_table(*_shares(metrics)))
        if "correction" in figures:
            out.append("<h3>Learned force against the states and inputs it follows most</h3>")
            log, force = figures["correction"]
            if any(force[f].abs().max() > 0 for f in FORCES):
                out.append(_img(_correction_figure(log, force)))
            else:  # a network that learned nothing has no force to plot (a figure of 0 rows)
                out.append("<p>The network's force is zero on every sample: nothing to plot.</p>")
    head, rows = _params_table(metrics)
    out.append("<h2>Parameters</h2>")
    out.append(html_table(head, rows))
    prime = _prime(metrics)
    if prime:
        out.append(f"<h2>{html.escape(prime[0])}</h2><ul>")
        out += [
            f"<li><code>{html.escape(k)}</code> = {html.escape(text)}</li>" for k, text in prime[1]
        ]
        out.append("</ul>")
    out.append(said_list(metrics.get("warnings", [])))
    out.append(IMAGES_CHECK + "</body></html>")
    return "\n".join(out)


def _img(uri: str) -> str:
    return f'<p><img src="{uri}" alt="figure"></p>'


def _errors(metrics: dict) -> tuple[list[str], list[list[str]]]:
    scored = [
        (part, label, metrics[part], key)
        for part in ("train", "validation", "test")
        for key, label in ERROR_KEYS[:3]
        if key in (metrics.get(part) or {})
    ]
    columns = scored_columns([scores[key] for _, _, scores, key in scored])
    rows = [
        [part, label, *_dof_cells(scores[key], diverged_columns(scores, key), columns)]
        for part, label, scores, key in scored
    ]
    return ["split", "mode", *columns, "total"], rows


def scored_columns(scores: Iterable[dict]) -> list[str]:
    """The columns of score tables (this report's and the compare report's): the outputs the
    scores (``{column: value, "total": ...}``) name, u v w p q r in their order, other outputs
    (a NARX's ``y``) after in first-seen order (a sorted set's order hung on the hash seed).
    Fixed to the six DOFs, the HTML left out a non-DOF output its Markdown twin showed."""
    seen: list[str] = []
    for vals in scores:
        seen += [c for c in vals if c != "total" and c not in seen]
    return sorted(seen, key=lambda c: DOFS.index(c) if c in DOFS else len(DOFS))


def _dof_cells(vals: dict, diverged: dict, columns: list[str]) -> list[str]:
    """One cell per column and the total (:func:`score_cell`)."""
    return [score_cell(vals, d, diverged) for d in (*columns, "total")]


def _free_run_figure(figures: dict) -> str:
    held, _ = figures["correction"]
    hybrid, physics = figures["free_run"], figures["baseline_free_run"]
    name, pos = experiment_rows(held)[0]
    cols = [c for c in VELOCITY if c in held and hybrid[c].notna().any()]
    # fixed margins: the constrained layout drew the figure twice (to place, then to paint)
    fig, axes = new_figure(len(cols), 1, 9.0, 1.8, fixed=True, left=LONG_TICKS_LEFT_IN)
    t = held["t"].to_numpy()[pos]
    for ax, c in zip(axes[:, 0], cols, strict=True):
        # the predictions are row-aligned with the held-out log (predict answers on its index)
        ax.plot(t, held[c].to_numpy()[pos], color="0.6", lw=1.2, label="measured")
        ax.plot(t, physics[c].to_numpy()[pos], color="tab:orange", lw=0.9, label="physics only")
        ax.plot(t, hybrid[c].to_numpy()[pos], color="tab:blue", lw=0.9, label="hybrid")
        ax.set_ylabel(f"{c} [{UNITS[c]}]")
    # the user's run name, as matplotlib draws it: a '$' pair was parsed as mathtext, and a
    # bad one ('$\foo$') raised in savefig after the whole fit
    axes[0, 0].set_title(
        f"experiment {plot_label(str(name))}" if name is not None else "held-out data"
    )
    axes[0, 0].legend(loc="upper right", fontsize=8, ncols=3)
    axes[-1, 0].set_xlabel("t [s]")
    return figure_uri(fig)


#: what the correction may depend on, with the unit of each
_FEATURES = {
    **{c: UNITS[c] for c in VELOCITY},
    **{c: FORCE_UNITS[c[4:]] for c in TAU},
    "phi": "rad",
    "theta": "rad",
    "psi": "rad",
}


def _correction_figure(log: pd.DataFrame, force: pd.DataFrame, per_dof: int = 4) -> str:
    """One row per corrected DOF: the learned force against the ``per_dof`` features it
    correlates with most (scatter of up to 3000 samples)."""
    cols = [f for f in FORCES if force[f].abs().max() > 0]
    feats = [c for c in _FEATURES if c in log and log[c].std() > 0]
    pick = np.unique(np.linspace(0, len(log) - 1, min(len(log), 3000)).round().astype(int))
    # fixed margins and one y axis per row (every panel of a row plots the same force): the
    # constrained layout measured every label of 24 panels, then the crop drew them again.
    # Room right of each panel for half an x tick label (``−0.00010``) on its edge; between
    # rows for the tick labels, the feature and the next row's |r|
    fig, axes = new_figure(
        len(cols), per_dof, 11.0, 2.2, fixed=True, left=LONG_TICKS_LEFT_IN, right=0.4,
        hspace=0.55, wspace=0.3, sharey="row",
    )  # fmt: skip
    for row, f in zip(axes, cols, strict=True):
        y = force[f].to_numpy()
        corr = {c: abs(np.corrcoef(log[c].to_numpy(), y)[0, 1]) for c in feats}
        best = sorted(feats, key=lambda c: -np.nan_to_num(corr[c]))[:per_dof]
        for ax, c in zip(row, best, strict=False):
            ax.scatter(log[c].to_numpy()[pick], y[pick], s=2, alpha=0.4, color="tab:blue")
            ax.set_xlabel(f"{c} [{_FEATURES[c]}]")
            # y given: matplotlib no longer measures the panel's tick labels for a title
            # over axes with none on top (a tenth of the figure's time); the y axis's offset
            # text, the one label up there, is at the left, clear of a centred title
            ax.set_title(f"|r| = {corr[c]:.2f}", fontsize=8, y=1.0)
        row[0].set_ylabel(f"learned {f} [{FORCE_UNITS[f]}]")
        for ax in row[len(best) :]:
            ax.set_visible(False)
    return figure_uri(fig)
