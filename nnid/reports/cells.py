"""Table and sentence cells shared by every report: one way to write a number that may be
missing, and one way to write a score that may have diverged or not have been scored."""

from __future__ import annotations

import math
import numbers
from typing import Any


def missing(x: Any) -> bool:
    """True for a number that was not measured: None, NaN or ±inf (:func:`number`'s "-")."""
    return x is None or (
        isinstance(x, numbers.Real) and not isinstance(x, bool) and not math.isfinite(x)
    )


def number(x: Any, digits: int = 3, fixed: bool = False) -> str:
    """``x`` to ``digits`` significant figures (``fixed``: decimals); "-" where it is missing
    (None, NaN, ±inf). Integers are written whole (a count or a seed is never rounded); other
    objects as ``str``."""
    if x is None or isinstance(x, bool):
        return "-" if x is None else str(x)
    if isinstance(x, numbers.Integral):
        return str(int(x))
    if isinstance(x, numbers.Real):
        if missing(x):
            return "-"
        return f"{float(x):.{digits}f}" if fixed else f"{float(x):.{digits}g}"
    return str(x)


def score(x: float | None, digits: int = 3, fixed: bool = False, diverged: bool = True) -> str:
    """A score: the number, or for ``None`` "diverged" (``diverged``: the prediction left the
    data's range and was voided, as :mod:`nnid.evaluation.evaluate` reports it) or "not
    scored" (nothing to score: no samples after the warm-up and the horizon, or a constant
    signal)."""
    if x is None:
        return "diverged" if diverged else "not scored"
    return number(x, digits, fixed)


def score_cell(vals: dict, key: str, diverged: dict) -> str:
    """One score of a per-DOF dict: the number; for None "diverged" where ``diverged`` (the
    mode's ``{column: t}``, :func:`nnid.evaluation.evaluate.diverged_columns`) names the key,
    or a total with a diverged column, else "not scored"; "-" where the key was not scored at
    all (a DOF the model does not predict or the data does not excite)."""
    if key not in vals:
        return "-"
    return score(vals[key], diverged=key in diverged or (key == "total" and bool(diverged)))


def thresholds_cell(thresholds: dict) -> str:
    """A residual monitor's two thresholds, each with the method that set it: the EWMA's and
    the CUSUM's are calibrated on their own, and one may fall back where the other was fitted
    (:func:`nnid.fault.thresholds.rate_threshold`)."""
    return ", ".join(
        f"{k.upper()} {number(thresholds[k]['value'], 3)} ({thresholds[k]['method']})"
        for k in ("ewma", "cusum")
    )
