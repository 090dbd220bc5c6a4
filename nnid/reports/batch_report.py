"""The fleet at a glance: the ``report.html`` of ``nnid batch`` and ``nnid sweep``.

Per vehicle, in manifest order of the logs (date-named logs read as a time line): the
identified parameters with their standard errors, the effects the loop added, the alarms; and
every failed task with its error. Numbers come from the task rows (``summary.json``).
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import Any

import numpy as np

from nnid.reports.figures import definitions, figure_uri, html_table, new_figure, page_head

#: at most this many parameters are drawn per vehicle (the ones most tasks identified)
MAX_PARAMS = 12


def _f(x: Any, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}" if isinstance(x, float) else str(x)


def _log(row: dict) -> str:
    return Path(str(row.get("data", ""))).name


def _vehicle(row: dict) -> str:
    return str(row.get("vehicle_name") or Path(str(row.get("vehicle") or "-")).stem)


def _unit(name: str) -> str:
    """The unit of an effect's size; vehicle-file parameters are in SI (their key says
    which)."""
    from nnid.reports.loop_report import unit

    try:
        return unit(name)
    except (KeyError, ValueError):
        return "SI"


def parameter_figure(rows: list[dict]) -> str | None:
    """Each identified parameter over the vehicle's logs, ± one standard error; None when
    the tasks identified none."""
    names: dict[str, int] = {}
    for row in rows:
        for key, value in row.items():
            if key.startswith("param:") and value is not None:
                names[key[6:]] = names.get(key[6:], 0) + 1
    chosen = sorted(names, key=lambda n: -names[n])[:MAX_PARAMS]
    if not chosen:
        return None
    cols = min(3, len(chosen))
    n_rows = -(-len(chosen) // cols)
    fig, axes = new_figure(n_rows, cols, width=10.0, height=2.4)
    x = np.arange(len(rows))
    labels = [_log(r) for r in rows]
    for ax, name in zip(axes.flat, chosen, strict=False):
        value = np.array([r.get(f"param:{name}") for r in rows], dtype=float)
        se = np.array([r.get(f"stderr:{name}") for r in rows], dtype=float)
        ax.errorbar(x, value, yerr=np.where(np.isfinite(se), se, 0.0), fmt="o-", ms=3,
                    capsize=2, lw=1)  # fmt: skip
        ax.set_title(name, fontsize=9)
        ax.set_ylabel(_unit(name), fontsize=8)
        ax.set_xticks(x, labels, rotation=45, ha="right", fontsize=7)
        ax.tick_params(axis="y", labelsize=7)
    for ax in list(axes.flat)[len(chosen) :]:
        ax.set_visible(False)
    return figure_uri(fig)


def _failed(result) -> list[str]:
    if not result.failed:
        return []
    rows = [[r["id"], _log(r), str(r.get("error") or "")] for r in result.failed]
    return ["<h2>Failed tasks</h2>", html_table(["task", "log", "error"], rows)]


def _loop_table(rows: list[dict]) -> str:
    body = [
        [_log(r), r["status"], str(r.get("added") or "none") if r["status"] == "ok" else "-",
         _f(r.get("before_free_run_nrmse")), _f(r.get("after_free_run_nrmse")),
         str(r.get("diverged") or ""), str(r.get("unexplained") or "")]
        for r in rows
    ]  # fmt: skip
    head = ["log", "status", "effects added", "NRMSE before", "NRMSE after", "diverged",
            "unexplained"]  # fmt: skip
    return html_table(head, body) + definitions(
        {
            "effects added": "the effects the residual loop found significant and added",
            "NRMSE before/after": "held-out free-run velocity NRMSE (total over the excited "
            "DOFs) of the vehicle file refitted, and with the effects added; '-' where it "
            "was not measured (a diverged free run is never averaged)",
            "diverged": "DOFs whose baseline free run left the physical range",
            "unexplained": "structure the effect vocabulary does not explain",
        }
    )


def _train_table(rows: list[dict]) -> str:
    body = [
        [_log(r), r["status"], str(r.get("model") or ""), str(r.get("held_out") or ""),
         _f(r.get("free_run_nrmse")), _f(r.get("one_step_nrmse"))]
        for r in rows
    ]  # fmt: skip
    return html_table(
        ["log", "status", "model", "held out", "free-run NRMSE", "one-step NRMSE"], body
    ) + definitions(
        {
            "held out": "the part scored (test where the split has one, else validation)",
            "free-run NRMSE": "total over the excited DOFs; '-' where the free run diverged",
        }
    )


def _detect_table(rows: list[dict]) -> str:
    body = [
        [_log(r), r["status"], _f(r.get("alarms")), _f(r.get("first_alarm_t")),
         str(r.get("alarm_kinds") or ""), str(r.get("effects") or "")]
        for r in rows
    ]  # fmt: skip
    return html_table(["log", "status", "alarms", "first alarm [s]", "kinds", "effects"], body)


def _compare_table(rows: list[dict]) -> str:
    body = [[_log(r), r["status"], str(r.get("best") or "-")] for r in rows]
    return html_table(["log", "status", "best model (held-out free run)"], body)


TABLES = {"loop": _loop_table, "train": _train_table, "detect": _detect_table,
          "compare": _compare_table}  # fmt: skip


def _sweep(extra: dict) -> list[str]:
    sweep = extra.get("sweep")
    if not sweep:
        return []
    best = sweep.get("best")
    out = ["<h2>Sweep</h2>", f"<p>{html.escape(sweep.get('summary', ''))}</p>"]
    if best:
        out.append(
            html_table(["option", "value"], [[k, str(v)] for k, v in best["settings"].items()])
        )
    return out


def batch_html(result, title: str = "nnid batch") -> str:
    """The page: counts, failed tasks, and per vehicle the tables and parameter figures."""
    rows = result.rows
    out = [page_head(title)]
    out.append(
        f"<p>{len(rows)} tasks on the {html.escape(result.engine)} engine "
        f"({result.slots} at once): {len(rows) - len(result.failed)} ok, "
        f"{len(result.failed)} failed, {result.reused} finished by an earlier run; "
        f"{result.seconds:.1f} s wall time.</p>"
    )
    out += _sweep(result.extra)
    out += _failed(result)
    by_vehicle: dict[str, list[dict]] = {}
    for row in rows:
        by_vehicle.setdefault(_vehicle(row), []).append(row)
    for name, group in by_vehicle.items():
        out.append(f"<h2>Vehicle {html.escape(name)}</h2>")
        for command in dict.fromkeys(r["command"] for r in group):
            part = [r for r in group if r["command"] == command]
            out.append(f"<h3>{html.escape(command)}</h3>")
            out.append(TABLES[command](part))
            ok = [r for r in part if r["status"] == "ok"]
            uri = parameter_figure(ok) if ok else None
            if uri:
                out.append(
                    "<p>Identified values over the logs (manifest order), bars ± one standard "
                    "error; loop tasks show the size of each effect they added.</p>"
                    f'<img src="{uri}" alt="parameters of {html.escape(name)}">'
                )
    out.append("</body></html>")
    return "\n".join(out)
