"""How a batch's or sweep's tasks ended, in words: a module of its own so that the fan-out
(:mod:`nnid.scale.batch`, :mod:`nnid.scale.sweep`) and the reports that read its rows
(:mod:`nnid.reports.batch_report`) share it without importing each other."""

from __future__ import annotations

from typing import Any

#: the status of a sweep's trial that Ray Tune's ASHA stopped early (by design, not a failure)
STOPPED = "stopped"


def not_ok_counts(rows: list[dict[str, Any]]) -> tuple[int, int]:
    """(failed, stopped): the rows that are neither ``ok`` nor stopped, and the trials a
    sweep's scheduler stopped early (by design, not a failure)."""
    stopped = sum(r["status"] == STOPPED for r in rows)
    failed = sum(r["status"] not in ("ok", STOPPED) for r in rows)
    return failed, stopped


def not_ok_message(rows: list[dict[str, Any]]) -> str:
    """The rows that are not ``ok`` in words (:func:`not_ok_counts`): "N failed", and "M
    stopped early by ASHA" where a sweep's scheduler stopped trials."""
    failed, stopped = not_ok_counts(rows)
    return f"{failed} failed" + (f", {stopped} stopped early by ASHA" if stopped else "")


def trial_setting(
    overrides: dict[str, Any], seed_option: str, seeds_swept: bool
) -> tuple[dict[str, Any], Any]:
    """(setting, seed) of a sweep's trial from its option ``overrides``: the seed at
    ``seed_option`` is the trial's seed, and is left out of its setting only where the sweep's
    ``seeds`` set it (then the setting's seeds are averaged); searched in a grid (``seeds``
    empty), each seed is a setting of its own, ranked alone, so it stays in the setting that
    names it."""
    seed = overrides.get(seed_option)
    setting = {k: v for k, v in overrides.items() if k != seed_option or not seeds_swept}
    return setting, seed
