"""The short report of ``nnid train``: parameters with uncertainty and held-out errors, for a
model of any kind (the Markdown twin of ``metrics.json``)."""

from __future__ import annotations

import math

from nnid.reports.figures import markdown_table

ERROR_KEYS = (
    ("free_run_nrmse", "free-run NRMSE"),
    ("k_step_nrmse", "k-step NRMSE"),
    ("one_step_nrmse", "one-step NRMSE"),
    ("force_rmse", "force residual RMS (N, N m)"),
)


def _fmt(x, digits: int = 5) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


def _rel(value, ref) -> str:
    if value is None or ref in (None, 0):
        return "-"
    return f"{(value / ref - 1) * 100:.3g} %"


def _params_table(metrics: dict) -> list[str]:
    params = metrics["params"]
    physical = any("percentile_error" in p or "vehicle_file" in p for p in params.values())
    ref = metrics.get("reference", {})
    ref_values = ref.get("values", {})
    head = ["parameter", "estimate", "std. error"]
    if physical:
        head += ["percentile error", "significant (95 %)", "vehicle file", "estimate / file − 1"]
    if ref_values:
        head += [ref.get("label", "reference"), "estimate / reference − 1"]
    rows = []
    for name, p in params.items():
        row = [f"`{name}`", _fmt(p["value"]), _fmt(p["stderr"], 2)]
        if physical:
            pe = p.get("percentile_error")
            row += [
                f"{_fmt(pe, 3)} %" if pe is not None else "-",
                "yes" if p.get("significant") else "no",
                _fmt(p.get("vehicle_file")),
                _rel(p["value"], p.get("vehicle_file")),
            ]
        if ref_values:
            r = ref_values.get(name)
            row += [_fmt(r), _rel(p["value"], r)]
        rows.append(row)
    return markdown_table(head, rows)


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
        *_params_table(metrics),
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
            f"the first {metrics.get('warmup_s', 0)} s of each run excluded{note})",
            "",
        ]
        for key, label in ERROR_KEYS:
            if key in scores:
                vals = scores[key]
                cells = ", ".join(
                    f"{k} {_fmt(v, 3) if v is not None else 'diverged'}" for k, v in vals.items()
                )
                lines.append(f"- {label}: {cells}")
        if scores.get("J") is not None:
            lines.append(f"- J = {_fmt(scores['J'], 4)}, J/J0 = {_fmt(scores['J_over_J0'], 3)}")
        for key in ("diverged", "k_step_diverged", "one_step_diverged"):
            if scores.get(key):
                when = ", ".join(f"{d} at t = {t:.4g} s" for d, t in scores[key].items())
                lines.append(f"- **{key.replace('_', ' ')}**: {when}")
    if metrics.get("warnings"):
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in metrics["warnings"]]
    nd = metrics.get("nondimensional")
    if nd:
        lines += ["", f"## Prime-system I (U = {nd['speed']} m/s, L = {nd['length']} m)", ""]
        lines += [
            f"- `{k}` = {_fmt(v['value'])} ± {_fmt(v['stderr'], 2)}"
            for k, v in nd["params"].items()
        ]
    lines += ["", f"Fitted and scored in {metrics['seconds']:.1f} s."]
    return "\n".join(lines) + "\n"
