"""``nnid detect`` outputs: alarms.csv, detect.json and report.html (residual traces with the
thresholds and alarms, and the isolation evidence of each alarm)."""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np
import pandas as pd

from nnid.fault.detect import ALARM_FIELDS, DetectResult, alarm_row
from nnid.fault.follow import (
    describe_alarm,
    efficiency_interval,
    explained_share,
    seen_again,
    unjudged_line,
    value_pm,
    withdrawn_line,
)
from nnid.physics.dofs import DOFS, FORCES
from nnid.reports.cells import missing, number, thresholds_cell
from nnid.reports.figures import (
    FORCE_UNITS,
    IMAGES_CHECK,
    definitions,
    figure_uri,
    html_table,
    new_figure,
    page_head,
    said_list,
)
from nnid.serialization import write_json, write_text


def detect_json(monitor, result: DetectResult, notes: list[str] | None = None) -> dict:
    """The ``detect.json`` contract: alarms, thresholds, the false-alarm rate the thresholds
    were set for, and whether the calibration controls it (``false_alarm_rate_controlled``:
    false, with the reason in ``false_alarm_caveat``, when the healthy record was too short
    for the rate fit and the thresholds are twice its largest value: then the rate is a
    target that was neither achieved by a fit nor measured; or when the healthy test part
    measured a rate whose interval lies wholly above the target). ``false_alarms_measured``: the
    alarms on the healthy test part at training, with the rate's exact interval; null where
    the training split had no test part (the rate was never measured). The contract's
    ``false_alarm_rate_per_hour`` is the target; ``target_false_alarm_rate_per_hour`` says so
    by its name, and ``measured_false_alarm_rate_per_hour`` is the rate the healthy test part
    measured (null where nothing measured it). ``notes``: what the run said of the log before
    the alarms (rows lost, samples missing, a wandering clock). ``withdrawn``: the alarms
    ``--follow`` announced that ``alarms`` does not hold, and why (empty in batch, which
    announces none: :attr:`~nnid.fault.detect.DetectResult.withdrawn`). ``dismissed``: the
    alarms batch judged within what isolated changes may leave, with their reading beside the
    changes and why (:attr:`~nnid.fault.detect.DetectResult.dismissed`; empty with
    ``--follow``, which says them in ``withdrawn``). ``unjudged``: per experiment, the rows at
    its end that were not judged, how many, the seconds they cover, each stretch of them
    where judged rows lie between, and why (:func:`~nnid.fault.detect.unjudged_tail`; batch
    and ``--follow`` alike). ``samples``: the rows watched, those a long ``--follow`` forgot
    too. ``stopped``: why ``--follow`` stopped before its input ended (an interrupt, a refused
    row; also the first of the notes), null where the input ended."""
    h_t, h_g = monitor.threshold_values
    caveat = monitor.threshold_caveat()
    measured = monitor.measured_false_alarms_
    return {
        "alarms": result.alarms,
        "withdrawn": result.withdrawn,
        "dismissed": result.dismissed,
        "unjudged": result.unjudged,
        "threshold": {
            "ewma": h_t,
            "cusum": h_g,
            "ewma_fit": monitor.thresholds_["ewma"],
            "cusum_fit": monitor.thresholds_["cusum"],
        },
        "false_alarm_rate_per_hour": monitor.false_alarm_per_hour,  # the contract's: a target
        "target_false_alarm_rate_per_hour": monitor.false_alarm_per_hour,
        "measured_false_alarm_rate_per_hour": (
            None if measured is None else measured["rate_per_hour"]
        ),
        "false_alarm_rate_controlled": caveat is None,
        "false_alarm_caveat": caveat,
        "false_alarms_measured": monitor.measured_false_alarms_,
        "calibration": monitor.calibration_,
        "samples": result.samples,
        "seconds": result.seconds,
        "stopped": result.stopped,
        "notes": _notes(result, notes),
    }


def _notes(result: DetectResult, notes: list[str] | None) -> list[str]:
    """What the run said of the log, led by why the watch stopped before its end."""
    return [*([result.stopped] if result.stopped else []), *(notes or [])]


#: the files of a detect run, as the CLI lists them
OUTPUTS = "alarms.csv, detect.json, report.html"


def write_detect_outputs(
    monitor, result: DetectResult, out_dir: Path, source: str = "", notes: list[str] | None = None
) -> list[str]:
    """Write the three outputs (:data:`OUTPUTS`) to ``out_dir``; return the lines the CLI
    prints about the alarms (the caller says where it wrote: ``out_dir`` may be a staging
    folder)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    rows = [alarm_row(a) for a in result.alarms]
    write_text(out_dir / "alarms.csv", pd.DataFrame(rows, columns=ALARM_FIELDS).to_csv(index=False))
    write_json(out_dir / "detect.json", detect_json(monitor, result, notes))
    write_text(out_dir / "report.html", detect_html(monitor, result, source, notes))
    hours = monitor.calibration_["hours"]
    lines = [
        *([f"note: {result.stopped}"] if result.stopped else []),
        f"{len(result.alarms)} alarm(s) in {result.samples} samples "
        f"(target false-alarm rate {monitor.false_alarm_per_hour:g} per hour, calibrated on "
        f"{60 * hours:.1f} min of healthy data; {measured_rate(monitor)})",  # 0.5, not "0 min"
        *(describe_alarm(a) for a in result.alarms),
        *(withdrawn_line(w) for w in result.withdrawn),
        *(unjudged_line(u) for u in result.unjudged),
    ]
    caveat = monitor.threshold_caveat()
    if caveat:
        lines.append(f"note: {caveat}")
    return lines


def measured_rate(monitor) -> str:
    """What the healthy test part measured of the false-alarm rate at training, or that
    nothing did."""
    m = monitor.measured_false_alarms_
    if m is None:
        return (
            "the rate was not measured with this monitor (no healthy test part at training, "
            "or a monitor.json from before nnid recorded it)"
        )
    lo, hi = m["interval"]
    return (
        f"measured at training: {m['alarms']} alarm(s) in {60 * m['hours']:.1f} min of healthy "
        f"test data, {m['rate_per_hour']:.3g} per hour ({100 * m['confidence']:.0f} % interval "
        f"{lo:.3g}-{hi:.3g})"
    )


def _explains(a: dict) -> str:
    """What share of the whitened residual after the alarm its hypothesis explains."""
    share = explained_share(a)
    if share is None:
        return "its share of the whitened residual after the alarm was not measured"
    return f"explains {share} of the whitened residual after the alarm"


def detect_html(
    monitor, result: DetectResult, source: str = "", notes: list[str] | None = None
) -> str:
    """The detect report as one self-contained page; ``notes``: what the run said of the log
    (:func:`detect_json`'s), which qualify the alarms."""
    trace = result.trace
    h_t, h_g = monitor.threshold_values
    out = [page_head("fault detection" + (f": {source}" if source else ""))]
    cal = monitor.calibration_
    out.append(
        f"<p>Residual monitor of a '{html.escape(monitor.plant_.kind)}' model of "
        f"'{html.escape(monitor.plant_.vehicle.name)}', calibrated on "
        f"{60 * cal['hours']:.1f} min of healthy data ({cal['samples']} samples); thresholds "
        f"{html.escape(thresholds_cell(monitor.thresholds_))} for a target of "
        f"{monitor.false_alarm_per_hour:g} false alarms per hour. "
        f"{len(result.alarms)} alarm(s) in {result.samples} samples. False-alarm rate "
        f"{html.escape(measured_rate(monitor))}.</p>"
    )
    caveat = monitor.threshold_caveat()
    if caveat:
        out.append(f"<p><b>Note</b>: {html.escape(caveat)}.</p>")
    out.append(said_list(_notes(result, notes), "Notes on the log"))
    if result.alarms:
        out.append("<h2>Alarms</h2>")
        head = ["experiment", "t [s]", "kind", "thruster", "efficiency (95 %)", "effect",
                "value ± s.e.", "severity", "confidence"]  # fmt: skip
        body = []
        for a in result.alarms:
            eff = (
                f"{a['efficiency']:.2f} ({efficiency_interval(a)})"
                if a["efficiency"] is not None
                else "-"
            )
            val = value_pm(a)
            run = "-" if a["experiment"] is None else a["experiment"]  # a log of one run
            body.append([run, f"{a['t']:.2f}", a["kind"], a["thruster"] or "-", eff,
                         a["effect"] or "-", val, f"{a['severity']:.2f}",
                         number(a["confidence"], 2, fixed=True)])  # fmt: skip
        # only where an alarm was not isolated: a column of "-" on every other page is noise
        repeats = any(a.get("repeats") is not None for a in result.alarms)
        if repeats:
            head.append("seen again")
            for row, a in zip(body, result.alarms, strict=True):
                row.append(number(seen_again(a)))  # "-": an isolated alarm counts none
        out.append(html_table(head, body))
        out.append("<ul>" + "".join(f"<li>{html.escape(describe_alarm(a))}</li>"
                                    for a in result.alarms) + "</ul>")  # fmt: skip
        terms = {
            "efficiency": "the thruster's thrust as a fraction of nominal: what is "
            "left of it for a thruster_loss, above 1 or below 0 for a thruster that "
            "gives more or pushes against its command (a model_change)",
            "effect": "the change named in nnid's effect vocabulary",
            "severity": "peak of the monitor statistic over its threshold after the alarm",
            "confidence": "posterior weight of the named hypothesis and of those the "
            "data cannot tell from it; - where none is named (none explains the change "
            "significantly, or the best leaves more than twice the healthy noise power: "
            "unexplained by the hypotheses; the fitted hypothesis' posterior is then the "
            "first of its evidence below), or the alarm was not judged (too few samples in its "
            "window: no hypothesis was fitted)",
        }
        if repeats:
            terms["seen again"] = (
                "for an alarm not isolated, how many later alarms on the statistics restarted "
                "after its window were not isolated either, taken as its change persisting "
                "(no record of their own), and the latest; - for an isolated alarm, after "
                "which a later alarm is judged as a new change"
            )
        out.append(definitions(terms))
        out.append("<h2>Isolation evidence</h2>")
        for a in result.alarms:
            rows = [[h["hypothesis"], f"{h['posterior']:.3g}"] for h in a.get("alternatives", [])]
            # no confidence: none named, and the fitted hypothesis heads the list (isolation's
            # _none_named), or none was fitted and the list is empty
            which = "hypotheses fitted" if missing(a["confidence"]) else "next hypotheses"
            out.append(
                f"<p>t = {a['t']:.2f} s: {html.escape(a['meaning'])} ({_explains(a)}); the "
                f"{which}:</p>"
            )
            out.append(html_table(["hypothesis", "posterior"], rows))
    else:
        out.append("<p><b>No alarm</b>: the residual stayed within its healthy range.</p>")
    if result.withdrawn:
        items = "".join(f"<li>{html.escape(withdrawn_line(w))}</li>" for w in result.withdrawn)
        out.append(f"<h2>Announced and withdrawn</h2><ul>{items}</ul>")
    if result.unjudged:
        items = "".join(f"<li>{html.escape(unjudged_line(u))}</li>" for u in result.unjudged)
        out.append(f"<h2>Not judged at a run's end</h2><ul>{items}</ul>")
    out.append("<h2>Residual and statistics</h2>")
    if result.dropped and trace.t.size:  # a long --follow keeps its latest rows only
        out.append(
            f"<p>The traces show the last {trace.t.size} of the {result.samples} rows watched, "
            f"from t = {trace.t[0]:.2f} s (row {result.dropped}); the alarms are those of all "
            "the rows.</p>"
        )
    figure = _figure(monitor, trace, h_t, h_g, result.dropped)
    out.append(f'<img alt="residual traces" src="{figure_uri(figure)}">')
    out.append(IMAGES_CHECK + "</body></html>")
    return "\n".join(out)


def _figure(monitor, trace, h_t: float, h_g: float, first: int = 0):
    """The statistics and residuals of ``trace``, against t for one run, else against the
    row, the trace's first being row ``first``."""
    dofs = [f for f, d in zip(FORCES, DOFS, strict=True) if d in monitor.plant_.dofs_]
    fig, axes = new_figure(len(dofs) + 1, 1, height=1.6)
    x = np.arange(trace.t.size) + first
    t = trace.t if trace.experiment.size and len(set(trace.experiment)) == 1 else x
    label = "t [s]" if t is trace.t else "sample"
    ax = axes[0, 0]
    ax.plot(t, trace.values[:, 18] / h_t, lw=0.8, label="EWMA statistic / threshold")
    ax.plot(t, trace.values[:, 19] / h_g, lw=0.8, label="CUSUM / threshold")
    ax.axhline(1.0, color="k", ls="--", lw=0.8)
    ax.set_ylabel("statistic / threshold")
    ax.legend(loc="upper left", fontsize=7)
    for k in np.flatnonzero(trace.alarm):
        for row in axes[:, 0]:
            row.axvline(t[k], color="tab:red", lw=1.0)
    for i, force in enumerate(dofs):
        ax = axes[i + 1, 0]
        ax.plot(t, trace.values[:, FORCES.index(force)], lw=0.6)
        ax.set_ylabel(f"r_{force} [{FORCE_UNITS[force]}]")
    axes[-1, 0].set_xlabel(label)
    return fig
