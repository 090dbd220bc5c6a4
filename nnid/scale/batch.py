"""``nnid batch``: run a manifest's tasks on an engine, resume what an earlier run finished,
and write one summary (ARCHITECTURE.md, "batch and sweep").

Outputs in the batch folder: ``<task id>/`` per task (the command's own outputs and
``task.json``), ``summary.parquet`` and ``summary.csv`` (one row per task, manifest order:
inputs, ``status``, ``error``, headline scores, ``seconds``, ``worker``), ``summary.json``
(the same rows, the engine and the counts) and ``report.html``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from nnid.scale.manifest import Task
from nnid.scale.task import finished
from nnid.trainers.history import Progress, silent


@dataclass
class BatchResult:
    """The rows of a batch in task order, the engine that ran it, how many tasks an earlier
    run had finished (``reused``) and the wall time."""

    rows: list[dict[str, Any]]
    engine: str
    reused: int = 0
    seconds: float = 0.0
    slots: int = 1
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def failed(self) -> list[dict[str, Any]]:
        return [r for r in self.rows if r["status"] != "ok"]


def counts_message(ok: int, failed: int, running: int, reused: int = 0) -> str:
    """The progress line: tasks done, failed and running."""
    text = f"{ok} done, {failed} failed, {running} running"
    return text + (f" ({reused} finished earlier)" if reused else "")


def run_tasks(
    tasks: list[Task],
    out_root: str | Path,
    engine,
    progress: Progress | None = None,
    resume: bool = True,
) -> BatchResult:
    """Run ``tasks`` on ``engine`` (:mod:`nnid.scale.engines`); with ``resume`` a task whose
    folder holds a finished ``task.json`` of the same id is not run again."""
    progress = progress or silent
    start = time.perf_counter()
    out_root = Path(out_root)
    out_root.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict[str, Any]] = {}
    if resume:
        for task in tasks:
            row = finished(task, out_root)
            if row is not None:
                rows[task.id] = {**row, "reused": True}
    reused = len(rows)
    todo = [t for t in tasks if t.id not in rows]
    ok = reused
    failed = 0
    progress(ok, len(tasks), counts_message(ok, 0, min(engine.slots, len(todo)), reused))
    for row in engine.run(todo, out_root):
        row["reused"] = False
        rows[row["id"]] = row
        ok += row["status"] == "ok"
        failed += row["status"] != "ok"
        running = min(engine.slots, len(tasks) - ok - failed)  # known once the engine runs
        progress(ok + failed, len(tasks), counts_message(ok, failed, running, reused))
    ordered = [rows[t.id] for t in tasks]
    slots = engine.slots if todo else 1
    return BatchResult(ordered, engine.name, reused, time.perf_counter() - start, slots)


def summary_frame(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """One row per task; lists (warnings) joined into text so the table stays flat."""
    flat = [
        {
            k: "; ".join(map(str, v)) if isinstance(v, list) else v
            for k, v in row.items()
            if k != "traceback"
        }
        for row in rows
    ]
    frame = pd.DataFrame(flat)
    first = [c for c in ("id", "command", "data", "vehicle", "config", "status", "error")
             if c in frame]  # fmt: skip
    return frame[first + [c for c in frame if c not in first]]


def write_summary(result: BatchResult, out_root: str | Path, title: str = "nnid batch") -> None:
    """``summary.parquet``, ``summary.csv``, ``summary.json`` and ``report.html``."""
    from nnid.reports.batch_report import batch_html
    from nnid.serialization import write_json, write_text

    out_root = Path(out_root)
    frame = summary_frame(result.rows)
    # parquet needs one type per column: a score that is None in every row is all-null
    tmp = out_root / ".summary.parquet.part"
    frame.to_parquet(tmp, index=False)
    tmp.replace(out_root / "summary.parquet")
    write_text(out_root / "summary.csv", frame.to_csv(index=False))
    write_json(
        out_root / "summary.json",
        {
            "engine": result.engine,
            "slots": result.slots,
            "tasks": len(result.rows),
            "ok": len(result.rows) - len(result.failed),
            "failed": len(result.failed),
            "reused": result.reused,
            "seconds": result.seconds,
            **result.extra,
            "rows": result.rows,
        },
    )
    write_text(out_root / "report.html", batch_html(result, title))
