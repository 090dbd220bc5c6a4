"""The fleet at a glance: the ``report.html`` of ``nnid batch`` and ``nnid sweep``.

Per vehicle file, in manifest order of the logs (date-named logs read as a time line, one
line per config): the identified parameters with their standard errors, the effects the loop
added, the alarms; and every failed task with its error. Numbers come from the task rows
(``summary.json``).
"""

from __future__ import annotations

import html
import json
from pathlib import Path

import numpy as np

from nnid.reports.cells import number, score
from nnid.reports.figures import definitions, figure_uri, html_table, new_figure, page_head
from nnid.reports.loop_report import parameter_unit as _unit
from nnid.scale.status import STOPPED, not_ok_message, trial_setting

#: at most this many parameters are drawn per vehicle (the ones most tasks identified)
MAX_PARAMS = 12


def _log(row: dict) -> str:
    return Path(str(row.get("data", ""))).name


def _vehicle(row: dict) -> str:
    return str(row.get("vehicle_name") or Path(str(row.get("vehicle") or "-")).stem)


def _section(row: dict) -> str:
    """The vehicle a row's section is keyed by: the file (or preset) the task named, as two
    files may share a vehicle's name; the name where the task named none (its config's)."""
    return str(row.get("vehicle") or _vehicle(row))


def _configs(rows: list[dict]) -> dict[str | None, str]:
    """Each config of ``rows`` (manifest order) and its label: the file's name, or its path
    where two share a name."""
    paths = list(dict.fromkeys(r.get("config") for r in rows))
    names = [Path(p).name if p else "no config" for p in paths]
    unique = len(set(names)) == len(names)
    return {p: n if unique else str(p or n) for p, n in zip(paths, names, strict=True)}


def parameter_figure(rows: list[dict]) -> str | None:
    """Each identified parameter over the vehicle's logs, ± one standard error, one line per
    config (a log x config product on one line drew configs as a time line); None when the
    tasks identified none."""
    names: dict[str, int] = {}
    for row in rows:  # identified values: those with a standard error (not a network's sizes)
        for key, value in row.items():
            if key.startswith("param:") and value is not None:
                se = row.get(f"stderr:{key[6:]}")
                if se is not None and np.isfinite(se):
                    names[key[6:]] = names.get(key[6:], 0) + 1
    chosen = sorted(names, key=lambda n: -names[n])[:MAX_PARAMS]
    if not chosen:
        return None
    cols = min(3, len(chosen))
    n_rows = -(-len(chosen) // cols)
    fig, axes = new_figure(n_rows, cols, width=10.0, height=2.4)
    logs = list(dict.fromkeys(r.get("data") for r in rows))  # the time line: logs in order
    configs = _configs(rows)
    labels = [Path(str(log)).name for log in logs]
    for ax, name in zip(axes.flat, chosen, strict=False):
        hollow = False
        for config, label in configs.items():
            part = [r for r in rows if r.get("config") == config]
            x = np.array([logs.index(r.get("data")) for r in part])
            value = np.array([r.get(f"param:{name}") for r in part], dtype=float)
            se = np.array([r.get(f"stderr:{name}") for r in part], dtype=float)
            known = np.isfinite(se)
            line = ax.plot(x, value, "-", lw=1, label=label if len(configs) > 1 else None)[0]
            ax.errorbar(x[known], value[known], yerr=se[known], fmt="o", ms=3, capsize=2,
                        color=line.get_color())  # fmt: skip
            if (~known & np.isfinite(value)).any():  # a zero-width bar would read as exact
                ax.plot(x[~known], value[~known], "o", mfc="none", ms=4, color=line.get_color(),
                        label=None if hollow else "no standard error")  # fmt: skip
                hollow = True
        if hollow or len(configs) > 1:
            ax.legend(fontsize=6)
        ax.set_title(name, fontsize=9)
        ax.set_ylabel(_unit(name), fontsize=8)
        ax.set_xticks(range(len(logs)), labels, rotation=45, ha="right", fontsize=7)
        ax.tick_params(axis="y", labelsize=7)
    for ax in list(axes.flat)[len(chosen) :]:
        ax.set_visible(False)
    return figure_uri(fig)


def _failed(result) -> list[str]:
    if not result.failed:
        return []
    rows = [[r["id"], _log(r), str(r.get("error") or "")] for r in result.failed]
    stopped = any(r["status"] == STOPPED for r in result.failed)
    title = "Failed or stopped tasks" if stopped else "Failed tasks"
    return [f"<h2>{title}</h2>", html_table(["task", "log", "error"], rows)]


def _loop_table(rows: list[dict]) -> str:
    body = [
        [_log(r), r["status"], str(r.get("added") or "none") if r["status"] == "ok" else "-",
         number(r.get("before_free_run_nrmse")), number(r.get("after_free_run_nrmse")),
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
            "was not measured (a diverged free run is never averaged). The held-out runs also "
            "ranked the candidates and chose the effects added: 'after' is not an independent "
            "test of them",
            "diverged": "DOFs whose baseline free run left the physical range",
            "unexplained": "structure the effect vocabulary does not explain",
        }
    )


def _held_out(row: dict) -> str:
    held, used = str(row.get("held_out") or ""), row.get("validation_used_for")
    return f"{held} (used for {used})" if held == "validation" and used else held


#: a row whose training kept its start: its numbers are the untrained model's
KEPT_START = "kept its start (training diverged)"


def _free_run(row: dict, digits: int = 3) -> str:
    """A task's held-out free-run NRMSE: the number, "diverged" where the row names the DOFs
    that diverged, "not scored" where none did; "-" for a task that scored nothing (failed)."""
    if "free_run_nrmse" not in row:
        return "-"
    return score(row["free_run_nrmse"], digits, diverged=bool(row.get("diverged")))


def _train_table(rows: list[dict]) -> str:
    body = [
        [_log(r), r["status"], str(r.get("model") or ""), _held_out(r),
         _free_run(r), number(r.get("one_step_nrmse")),
         KEPT_START if r.get("training_diverged") else ""]
        for r in rows
    ]  # fmt: skip
    return html_table(
        ["log", "status", "model", "held out", "free-run NRMSE", "one-step NRMSE", "training"],
        body,
    ) + definitions(
        {
            "held out": "the part scored (test where the split has one, else validation, "
            "and then what the fit used it for: its score is not independent)",
            "free-run NRMSE": "total over the excited DOFs; 'diverged' where the free run "
            "left the physical range, 'not scored' where no sample was left to score",
            "one-step NRMSE": "the same total one sample ahead; '-' where it was not measured "
            "(diverged, or no sample left to score)",
            "training": f"'{KEPT_START}' where a training stage ended on a non-finite loss or "
            "a validation that never measured a free run: the scores are of the model before "
            "that stage",
        }
    )


def _detect_table(rows: list[dict]) -> str:
    body = [
        [_log(r), r["status"], number(r.get("alarms")), number(r.get("first_alarm_t")),
         str(r.get("alarm_kinds") or ""), str(r.get("effects") or "")]
        for r in rows
    ]  # fmt: skip
    return html_table(["log", "status", "alarms", "first alarm [s]", "kinds", "effects"], body)


def _best(row: dict) -> str:
    """A compare task's best model, or why it names none (``no_best``, :func:`nnid.runs.
    no_best_why`): "-" alone said the same of a tie, no skill, no free run and no ranking."""
    if row.get("best"):
        return str(row["best"])
    return f"none: {row['no_best']}" if row.get("no_best") else "-"


def _compare_table(rows: list[dict]) -> str:
    body = [[_log(r), r["status"], _best(r), str(r.get("training_diverged") or "")] for r in rows]
    head = ["log", "status", "best model (held-out free run)", f"training {KEPT_START}"]
    return html_table(head, body)


TABLES = {"loop": _loop_table, "train": _train_table, "detect": _detect_table,
          "compare": _compare_table}  # fmt: skip


def _sweep(result) -> list[str]:
    """The sweep's verdict, every trial, and the validation score of each setting's seeds."""
    sweep = result.extra["sweep"]
    out = ["<h2>Sweep</h2>", f"<p>{html.escape(sweep.get('summary', ''))}</p>"]
    metric = sweep["metric"].split()[1]  # "validation free_run_nrmse (total), ..."
    body, scores = [], {}
    # labelled as the sweep ranked them: a seed searched in a grid (no ``seeds``) is a setting
    # of its own, not one of several seeds under one label (a record without "seeds", built
    # by hand, reads its seed as the sweep's)
    seed_option = sweep.get("seed_option", "model.seed")
    swept = bool(sweep.get("seeds", True))
    for row in result.rows:
        overrides = json.loads(row.get("overrides") or "{}")
        setting, seed = trial_setting(overrides, seed_option, swept)
        label = ", ".join(f"{k} = {v}" for k, v in setting.items()) or "as configured"
        value = row.get(f"validation_{metric}") if row["status"] == "ok" else None
        # a diverged test free run is said, not a "-" that reads as "no test part"
        test = _free_run(row, 4) if row.get("held_out") == "test" else "-"
        note = str(row.get("error") or "")
        untrained = row["status"] == "ok" and row.get("training_diverged")
        if untrained:  # the sweep ranks it unscored
            note = f"{KEPT_START}: its score is the untrained model's, not ranked"
        elif row["status"] == "ok" and value is None and not note:  # a "-" said, not left bare
            note = f"no validation {metric}: diverged, or nothing scored (the run's warnings)"
        scores.setdefault(label, []).append(None if untrained else value)
        body.append([label, number(seed), row["status"], number(value, 4), test, note])
    head = ["setting", "seed", "status", f"validation {metric}", "test free-run NRMSE", "note"]
    out.append(html_table(head, body))
    out.append(definitions({
        f"validation {metric}": "total over the excited outputs on the validation part: what "
        "the settings are ranked by (mean over seeds)",
        "test free-run NRMSE": "reported, never used to choose; 'diverged' where the test "
        "free run left the physical range, 'not scored' where no sample was left to score, "
        "'-' without a test part",
    }))  # fmt: skip
    fig, axes = new_figure(1, 1, width=8.0, height=3.2)
    ax = axes[0, 0]
    for i, values in enumerate(scores.values()):
        finite = [v for v in values if v is not None]
        ax.plot([i] * len(finite), finite, "o", alpha=0.7)
        if len(finite) < len(values):
            ax.annotate(f"{len(values) - len(finite)} without a score", (i, ax.get_ylim()[1]),
                        fontsize=7, ha="center", va="top")  # fmt: skip
    ax.set_xticks(range(len(scores)), list(scores), rotation=20, ha="right", fontsize=8)
    ax.set_ylabel(f"validation {metric} (-)")
    out.append(f'<img src="{figure_uri(fig)}" alt="validation score per setting">')
    return out


def batch_html(result, title: str = "nnid batch") -> str:
    """The page: counts, failed tasks, and per vehicle the tables and parameter figures."""
    rows = result.rows
    out = [page_head(title)]
    out.append(
        f"<p>{len(rows)} tasks on the {html.escape(result.engine)} engine "
        f"({result.slots} at once): {len(rows) - len(result.failed)} ok, "
        f"{not_ok_message(rows)}, {result.reused} finished by an earlier run; "
        f"{result.seconds:.1f} s wall time.</p>"
    )
    out += _failed(result)
    if "sweep" in result.extra:
        out += _sweep(result)
        out.append("</body></html>")
        return "\n".join(out)
    by_vehicle: dict[str, list[dict]] = {}
    for row in rows:
        by_vehicle.setdefault(_section(row), []).append(row)
    for key, group in by_vehicle.items():
        name = next((_vehicle(r) for r in group if r.get("vehicle_name")), _vehicle(group[0]))
        shown = "" if key == name else f" <small>({html.escape(key)})</small>"
        out.append(f"<h2>Vehicle {html.escape(name)}{shown}</h2>")
        for command in dict.fromkeys(r["command"] for r in group):
            part = [r for r in group if r["command"] == command]
            out.append(f"<h3>{html.escape(command)}</h3>")
            configs = _configs(part)
            for config, label in configs.items():  # a table per config: one log, one row
                if len(configs) > 1:
                    out.append(f"<h4>config {html.escape(label)}</h4>")
                out.append(TABLES[command]([r for r in part if r.get("config") == config]))
            ok = [r for r in part if r["status"] == "ok"]
            uri = parameter_figure(ok) if ok else None
            if uri:
                out.append(
                    "<p>Identified values over the logs (manifest order), bars ± one standard "
                    "error, hollow marks a value without one (not determined on its own); loop "
                    "tasks show the size of each effect they added.</p>"
                    f'<img src="{uri}" alt="parameters of {html.escape(name)}">'
                )
    out.append("</body></html>")
    return "\n".join(out)
