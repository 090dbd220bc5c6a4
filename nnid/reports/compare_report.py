"""The report of ``nnid compare``: McCarter's Tables 5.1/5.2 for the user's data, force series,
error against complexity with the SINDy path, coefficients, and free-run velocity errors.

One self-contained HTML page (figures embedded, no scripts from elsewhere) and a Markdown twin
with the same tables for terminals and pull requests.
"""

from __future__ import annotations

import html
import math

import numpy as np

from nnid.reports.figures import figure_uri, new_figure, page_head

FORCES = ("X", "Y", "Z", "K", "M", "N")


def _f(x, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


def table_rows(comparison: dict) -> list[list[str]]:
    """Rows of the Table 5.1/5.2 analogue: model, n̄, J and J/J0 on train and validation."""
    rows = []
    for m in sorted(comparison["models"], key=lambda m: -m["n_params"]):
        rows.append(
            [
                m["name"],
                str(m["n_params"]),
                _f(m["train"]["J"]),
                _f(m["train"]["J_over_J0"]),
                _f(m["validation"]["J"]),
                _f(m["validation"]["J_over_J0"]),
            ]
        )
    return rows


HEAD = ["model", "n̄", "train J", "train J/J0", "validation J", "validation J/J0"]
VELOCITY_TABLES = (
    ("free_run_nrmse", "Free-run velocity NRMSE on validation (inside the Fossen simulator)"),
    ("k_step_nrmse", "{h:.3g} s-ahead velocity NRMSE on validation (inside the Fossen simulator)"),
)


def velocity_rows(comparison: dict, key: str) -> tuple[list[str], list[list[str]]]:
    """Velocity NRMSE per DOF of each model (``free_run_nrmse`` or ``k_step_nrmse``); a run
    that left the physical range is "diverged"."""
    dofs: list[str] = []
    for m in comparison["models"]:
        for d in m["validation"].get(key, {}):
            if d not in dofs:
                dofs.append(d)
    rows = []
    for m in comparison["models"]:
        vals = m["validation"].get(key, {})
        cells = [_f(vals[d], 3) if vals.get(d) is not None else "diverged" for d in dofs]
        rows.append([m["name"], *cells])
    return ["model", *dofs], rows


def markdown(comparison: dict) -> str:
    """The Markdown twin: the same tables as the HTML page."""
    lines = [
        f"# Damping model comparison: {comparison.get('vehicle', '')}",
        "",
        comparison.get("summary", ""),
        "",
        "## Force error (McCarter Tables 5.1/5.2 for this data)",
        "",
        "| " + " | ".join(HEAD) + " |",
        "|" + "---|" * len(HEAD),
    ]
    lines += ["| " + " | ".join(r) + " |" for r in table_rows(comparison)]
    for key, title in VELOCITY_TABLES:
        head, rows = velocity_rows(comparison, key)
        if len(head) > 1:
            lines += [
                "",
                f"## {title.format(h=comparison.get('horizon_s', 0.0))}",
                "",
                "| " + " | ".join(head) + " |",
                "|" + "---|" * len(head),
            ]
            lines += ["| " + " | ".join(r) + " |" for r in rows]
    path = comparison.get("sindy_path") or []
    if path:
        lines += ["", "## SINDy path", "", "| threshold | terms | validation J |", "|---|---|---|"]
        lines += [
            f"| {_f(p.get('threshold'))} | {p['n_terms']} | {_f(p.get('validation_J'))} |"
            for p in path
        ]
    lines += [
        "",
        f"Training: {', '.join(comparison.get('train', []))}; validation: "
        f"{', '.join(comparison.get('validation', []))}.",
    ]
    return "\n".join(lines) + "\n"


def html_table(head: list[str], rows: list[list[str]]) -> str:
    h = "".join(f"<th>{html.escape(c)}</th>" for c in head)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows
    )
    return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"


def force_figure(
    t: np.ndarray, measured: np.ndarray, predicted: dict[str, np.ndarray], window_s: float = 60.0
) -> str:
    """Measured and predicted force per DOF over the first ``window_s`` of validation (a
    longer stretch turns nine overlaid models into a blur)."""
    keep = t - t[0] <= window_s
    t, measured = t[keep], measured[keep]
    predicted = {k: v[keep] for k, v in predicted.items()}
    fig, axes = new_figure(6, 1, 10.0, 1.6)
    for k, ax in enumerate(axes[:, 0]):
        ax.plot(t, measured[:, k], color="black", lw=1.2, label="measured τ̄")
        for name, series in predicted.items():
            ax.plot(t, series[:, k], lw=0.8, label=name)
        ax.set_ylabel(FORCES[k])
    axes[0, 0].legend(ncol=4, fontsize=7, loc="upper right")
    axes[-1, 0].set_xlabel("t [s]")
    return figure_uri(fig)


def complexity_figure(comparison: dict) -> str:
    fig, axes = new_figure(1, 1, 7.0, 4.0)
    ax = axes[0, 0]
    for m in comparison["models"]:
        ax.scatter(m["n_params"], m["validation"]["J_over_J0"], zorder=3)
        ax.annotate(m["name"], (m["n_params"], m["validation"]["J_over_J0"]), fontsize=8)
    path = comparison.get("sindy_path") or []
    if path:
        j0 = comparison.get("validation_J0", 1.0)
        pts = sorted(
            (p["n_terms"], p["validation_J"] / j0)
            for p in path
            if p.get("validation_J") is not None
        )
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "--", color="gray", label="SINDy path")
        ax.legend()
    ax.set_xlabel("number of terms n̄")
    ax.set_ylabel("validation J / J0")
    ax.set_xscale("symlog")
    return figure_uri(fig)


def html_page(
    comparison: dict, t: np.ndarray, measured: np.ndarray, predicted: dict[str, np.ndarray]
) -> str:
    """The self-contained HTML report."""
    velocity = "".join(
        f"<h2>{html.escape(title.format(h=comparison.get('horizon_s', 0.0)))}</h2>"
        + html_table(*velocity_rows(comparison, key))
        for key, title in VELOCITY_TABLES
    )
    coef_blocks = []
    for name, coefs in comparison.get("coefficients", {}).items():
        crow = [[k, _f(v, 5)] for k, v in sorted(coefs.items())]
        coef_blocks.append(
            f"<details><summary>{html.escape(name)} ({len(crow)} coefficients)"
            f"</summary>{html_table(['coefficient', 'value'], crow)}</details>"
        )
    title = f"Damping model comparison: {comparison.get('vehicle', '')}"
    forces = force_figure(t, measured, predicted)
    return (
        page_head(title)
        + f"""<p>{html.escape(comparison.get("summary", ""))}</p>
<h2>Force error (McCarter Tables 5.1/5.2 for this data)</h2>
{html_table(HEAD, table_rows(comparison))}
<p>J is the RMS error of the viscous force (McCarter eq. 4.25), J0 the RMS of the force series;
training on {html.escape(", ".join(comparison.get("train", [])))}, validation on
{html.escape(", ".join(comparison.get("validation", [])))}.</p>
<h2>Error against complexity</h2>
<img alt="validation J/J0 against the number of terms" src="{complexity_figure(comparison)}">
<h2>Validation force series (first 60 s)</h2>
<img alt="measured and predicted viscous force per DOF" src="{forces}">
{velocity}
<h2>Coefficients</h2>
{"".join(coef_blocks)}
<script>
window.addEventListener("load", function () {{
  var ok = Array.prototype.every.call(document.images, function (i) {{
    return i.complete && i.naturalWidth > 0; }});
  document.body.setAttribute("data-images-ok", ok ? "yes" : "no");
}});
</script>
</body></html>
"""
    )
