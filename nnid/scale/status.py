"""How a batch's or sweep's tasks ended, in words: a module of its own so that the fan-out
(:mod:`nnid.scale.batch`, :mod:`nnid.scale.sweep`) and the reports that read its rows
(:mod:`nnid.reports.batch_report`) share it without importing each other."""

from __future__ import annotations

from typing import Any

#: the status of a sweep's trial that Ray Tune's ASHA stopped early (by design, not a failure)
STOPPED = "stopped"


def not_ok_message(rows: list[dict[str, Any]]) -> str:
    """The rows that are not ``ok`` in words: "N failed", and "M stopped early by ASHA" where
    a sweep's scheduler stopped trials (a trial stopped by design did not fail)."""
    stopped = sum(r["status"] == STOPPED for r in rows)
    failed = sum(r["status"] not in ("ok", STOPPED) for r in rows)
    return f"{failed} failed" + (f", {stopped} stopped early by ASHA" if stopped else "")
