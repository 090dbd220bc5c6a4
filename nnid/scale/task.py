"""Run one task where it lands (this process, a local worker, a Ray worker) and return its
summary row.

A task calls the library (:mod:`nnid.runs`, the same calls as the CLI), never the CLI through
a subprocess. It writes its outputs to ``<out>/<task id>/`` atomically and, last, ``task.json``
(its row): a folder with ``task.json`` is a finished task, which a re-run skips. A task that
fails writes nothing there; its row says ``failed`` with the error, and the other tasks go on.

Every task runs with one torch, BLAS and numba thread, restored afterwards: tasks run side by
side on the cores. The engines' worker processes are also *started* with one thread per library
(:data:`nnid.scale.engines.ONE_THREAD`); results then agree across engines to the last few bits
(docs/scale.md says why not always to the bit).
"""

from __future__ import annotations

import os
import socket
import time
import traceback
import warnings
from pathlib import Path
from typing import Any

from nnid.errors import NnidInputError
from nnid.scale.manifest import Task
from nnid.trainers.history import Progress
from nnid.warning_messages import warning_messages

#: the file that marks a finished task inside its folder
TASK_FILE = "task.json"


def _run(task: Task, out_dir: Path, progress: Progress | None = None):
    """The task's command through :mod:`nnid.runs`; its Outcome."""
    from nnid import runs
    from nnid.config import CompareConfig, LoopConfig, TrainConfig, load_config

    config = Path(task.config) if task.config else None
    if task.command == "train":
        cfg = load_config(config, TrainConfig, task.overrides)
        return runs.train_run(cfg, config, out_dir, task.data or None, task.vehicle,
                              task.columns, progress, task.time_unit)  # fmt: skip
    if task.command == "compare":
        cfg = load_config(config, CompareConfig, task.overrides)
        return runs.compare_run(cfg, config, out_dir, task.data or None, task.vehicle,
                                task.columns, progress, task.time_unit)  # fmt: skip
    if task.command == "loop":
        cfg = load_config(config, LoopConfig, task.overrides) if config else LoopConfig()
        options = dict(task.options)
        for key in ("dofs", "validation", "exclude"):  # lists in TOML, text on the CLI
            if isinstance(options.get(key), list):
                options[key] = ",".join(options[key])
        return runs.loop_run(cfg, config, out_dir, task.data or None, task.vehicle,
                             task.columns, progress=progress, time_unit=task.time_unit,
                             **options)  # fmt: skip
    if task.command == "detect":
        window = task.options.get("window")
        return runs.detect_run(Path(task.model), task.data, out_dir, task.columns, window,
                               progress, task.time_unit)  # fmt: skip
    raise NnidInputError(f"unknown command '{task.command}'", field="command")


def run_task(task: Task, out_root: str | Path, progress: Progress | None = None) -> dict[str, Any]:
    """Run ``task`` and return its row: the inputs, ``status`` (``ok`` or ``failed``),
    ``error``, the headline scores, ``seconds``, ``worker`` and ``warnings``. ``progress``
    receives the fit's progress (and its trainers' per-epoch scores)."""
    from nnid.serialization import jsonable, write_json
    from nnid.threads import blas_threads, numba_threads, torch_threads

    out_dir = Path(out_root) / task.id
    row: dict[str, Any] = {"id": task.id, **task.inputs(), "status": "ok", "error": None}
    start = time.perf_counter()
    try:
        with (
            warnings.catch_warnings(record=True) as caught,
            torch_threads(1),
            blas_threads(1),  # OpenMP: torch_threads and numba_threads
            numba_threads(1),
        ):
            warnings.simplefilter("always")
            outcome = _run(task, out_dir, progress)
        row["warnings"] = list(dict.fromkeys([*outcome.warnings, *warning_messages(caught)]))
        row.update(outcome.headline)
    except NnidInputError as exc:
        row.update(status="failed", error=str(exc))
    except Exception as exc:  # a crash in one task must not stop the others
        row.update(
            status="failed",
            error=f"{type(exc).__name__}: {exc}",
            traceback=traceback.format_exc(),
        )
    row["seconds"] = time.perf_counter() - start
    row["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    if row["status"] == "ok":
        write_json(out_dir / TASK_FILE, row)
    return jsonable(row)


def finished(task: Task, out_root: str | Path) -> dict[str, Any] | None:
    """The row of a task finished by an earlier run (its ``task.json``), else None."""
    from nnid.serialization import read_json

    path = Path(out_root) / task.id / TASK_FILE
    if not path.is_file():
        return None
    try:
        row = read_json(path)
    except NnidInputError:  # a damaged marker: run the task again
        return None
    if not isinstance(row, dict):  # valid JSON, but no row: damaged too
        return None
    row.pop("schema_version", None)
    return row if row.get("status") == "ok" else None
