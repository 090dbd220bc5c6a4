"""Table and sentence cells shared by every report: one way to write a number that may be
missing, and one way to write a score that may have diverged."""

from __future__ import annotations

import math
import numbers
from typing import Any


def number(x: Any, digits: int = 3, fixed: bool = False) -> str:
    """``x`` to ``digits`` significant figures (``fixed``: decimals); "-" where it is missing
    (None, NaN, ±inf). Integers are written whole (a count or a seed is never rounded); other
    objects as ``str``."""
    if x is None or isinstance(x, bool):
        return "-" if x is None else str(x)
    if isinstance(x, numbers.Integral):
        return str(int(x))
    if isinstance(x, numbers.Real):
        if not math.isfinite(x):
            return "-"
        return f"{float(x):.{digits}f}" if fixed else f"{float(x):.{digits}g}"
    return str(x)


def score(x: float | None, digits: int = 3, fixed: bool = False) -> str:
    """A score that was computed: the number, or "diverged" where the free run left the
    data's range and was voided (``None``, as :mod:`nnid.evaluate` reports it)."""
    return "diverged" if x is None else number(x, digits, fixed)


def score_cell(vals: dict, key: str) -> str:
    """One score of a per-DOF dict: the number, "diverged" (a key scored None), or "-" where
    the key was not scored (a DOF the model does not predict or the data does not excite)."""
    return score(vals[key]) if key in vals else "-"
