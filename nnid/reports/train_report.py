"""The short report of ``nnid train``: parameters with uncertainty and held-out errors."""

from __future__ import annotations

import math


def _fmt(x, digits: int = 5) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:.{digits}g}"


def _rel(value, ref) -> str:
    if value is None or ref in (None, 0):
        return "-"
    return f"{(value / ref - 1) * 100:.3g} %"


def train_markdown(metrics: dict) -> str:
    """Markdown for a metrics.json of a Fossen fit."""
    ref = metrics.get("reference", {})
    ref_values = ref.get("values", {})
    lines = [
        f"# {metrics['model']} model of '{metrics.get('vehicle', '?')}' ({metrics['trainer']})",
        "",
        "## Parameters",
        "",
    ]
    head = (
        "| parameter | estimate | std. error | percentile error | significant (95 %) | "
        "vehicle file | estimate / file − 1 |"
    )
    sep = "|---|---|---|---|---|---|---|"
    if ref_values:
        head += f" {ref.get('label', 'reference')} | estimate / reference − 1 |"
        sep += "---|---|"
    lines += [head, sep]
    for name, p in metrics["params"].items():
        pe = p.get("percentile_error")
        row = (
            f"| `{name}` | {_fmt(p['value'])} | {_fmt(p['stderr'], 2)} | "
            f"{_fmt(pe, 3)}{' %' if pe is not None else ''} | "
            f"{'yes' if p.get('significant') else 'no'} | {_fmt(p.get('vehicle_file'))} | "
            f"{_rel(p['value'], p.get('vehicle_file'))} |"
        )
        if ref_values:
            r = ref_values.get(name)
            row += f" {_fmt(r)} | {_rel(p['value'], r)} |"
        lines.append(row)
    for part in ("train", "validation"):
        scores = metrics.get(part, {})
        if not any(k in scores for k in ("free_run_nrmse", "one_step_nrmse", "force_rmse")):
            continue
        lines += [
            "",
            f"## Errors on the {part} split ({scores.get('samples', '?')} samples, "
            f"first {metrics.get('warmup_s', 0)} s of each run excluded)",
            "",
        ]
        for key in ("free_run_nrmse", "one_step_nrmse", "force_rmse"):
            if key in scores:
                vals = scores[key]
                lines.append(f"- {key}: " + ", ".join(f"{k} {_fmt(v, 3)}" for k, v in vals.items()))
    if metrics.get("warnings"):
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in metrics["warnings"]]
    nd = metrics.get("nondimensional")
    if nd:
        lines += ["", f"## Prime-system I (U = {nd['speed']} m/s, L = {nd['length']} m)", ""]
        lines += [
            f"- `{k}` = {_fmt(v['value'])} ± {_fmt(v['stderr'], 2)}"
            for k, v in nd["params"].items()
        ]
    lines += ["", f"Fitted in {metrics['seconds']:.1f} s."]
    return "\n".join(lines) + "\n"
