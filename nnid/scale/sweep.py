"""``nnid sweep``: a search over a train config's settings and seeds (its ``[sweep]`` table,
:class:`nnid.config.SweepSpec`), each trial a train task on an engine, scored on held-out data.

A *setting* is one assignment of the searched options; a *trial* is a setting with one seed.
Settings are ranked by the mean over their seeds of the validation part's score (the split's
validation experiments; the test part, where the split has one, is reported for the chosen
setting and never used to choose). A setting with a diverged or failed seed ranks after every
setting whose seeds all gave a score, and says so: a missing score is not averaged away.

Outputs: the trial tasks' folders, ``summary.*`` (one row per trial), ``settings.csv`` (one row
per setting, ranked) and ``best.toml``, the config with the chosen setting written in (and the
``[sweep]`` table removed), ready for ``nnid train``.
"""

from __future__ import annotations

import itertools
import json
import math
import statistics
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from nnid.config import SweepSpec, TrainConfig, load_config, set_option
from nnid.errors import NnidInputError
from nnid.scale.batch import BatchResult, run_tasks
from nnid.scale.manifest import Task, with_id
from nnid.scale.status import STOPPED, not_ok_counts, trial_setting
from nnid.trainers.history import Progress, silent, stopping_score
from nnid.validation import read_toml


def settings(spec: SweepSpec) -> list[dict[str, Any]]:
    """The settings to try: the grid's combinations, each with ``samples`` random draws from
    the random choices (a local generator seeded by ``spec.seed``); duplicates kept once."""
    keys = sorted(spec.grid)
    grid = [dict(zip(keys, values, strict=True))
            for values in itertools.product(*(spec.grid[k] for k in keys))] or [{}]  # fmt: skip
    rng = np.random.default_rng(spec.seed)
    combos = math.prod(len(v) for v in spec.random.values())
    seen: dict[str, dict[str, Any]] = {}
    for _ in range(spec.samples):
        if len(seen) == combos:  # every combination drawn: more draws only repeat them
            break
        draw = {
            k: spec.random[k][int(rng.integers(len(spec.random[k])))] for k in sorted(spec.random)
        }
        seen.setdefault(json.dumps(draw, sort_keys=True), draw)
    draws = list(seen.values()) or [{}]
    out: dict[str, dict[str, Any]] = {}
    for g, d in itertools.product(grid, draws):
        setting = {**g, **d}
        out.setdefault(json.dumps(setting, sort_keys=True), setting)
    return list(out.values())


def trials(
    config: Path, data: str | None = None, vehicle: str | None = None, columns: str | None = None
) -> tuple[SweepSpec, list[Task]]:
    """The sweep of a train config and its trial tasks; every setting is validated as a
    config before any work (a bad option path is refused, naming it)."""
    from nnid.pipeline import check_paths, vehicle_for

    cfg = load_config(config, TrainConfig, command="sweep")
    if cfg.sweep is None:
        raise NnidInputError("has no [sweep] table (see docs/scale.md)", source=str(config),
                             field="sweep")  # fmt: skip
    spec = cfg.sweep
    vehicle_path = _vehicle_path(vehicle, config)
    seeds = spec.seeds or [None]
    tasks = []
    for setting in settings(spec):
        for seed in seeds:
            overrides = {**setting, **({} if seed is None else {spec.seed_option: seed})}
            try:
                load_config(config, TrainConfig, overrides)  # refused here, before any fit
            except NnidInputError as exc:
                searched = _searched_at(exc.field, setting)
                if searched is not None:  # a value the sweep tries, not one the config wrote
                    table = "grid" if searched in spec.grid else "random"
                    at = "" if exc.field == searched else f" (at {exc.field})"
                    raise NnidInputError(
                        f"the value {setting[searched]!r} it tries{at}: {exc.message}",
                        source=str(config),
                        field=f'sweep.{table}."{searched}"',
                    ) from None
                if seed is None or exc.field != spec.seed_option or spec.seed_option in setting:
                    raise
                # the seed option is the sweep's (model.seed by default), not a key written
                raise NnidInputError(
                    f"each seed is set at {spec.seed_option} (sweep.seed_option), which this "
                    f"config does not take ({exc.message}): name the config's seed in "
                    "seed_option, or drop seeds (a model without one fits the same each time)",
                    source=str(config),
                    field="sweep.seeds",
                ) from None
            # absolute paths: a trial on Ray Tune runs in its own trial folder, where a path
            # relative to this one names another file or none
            task = Task("train", str(Path(data).resolve()) if data else "",
                        vehicle_path, str(Path(config).resolve()), None,
                        str(Path(columns).resolve()) if columns else None, {},
                        overrides)  # fmt: skip
            try:
                tasks.append(with_id(task))
            except NnidInputError as err:  # a file that cannot be read: said against its option
                option = f"--{err.field}" if err.field in ("data", "vehicle", "columns") else None
                raise NnidInputError(
                    err.message, source=None if option else str(config), field=option
                ) from None
    # a file that does not exist (the log, reader config or vehicle, an option's or the
    # config's) is refused here, after the settings as `nnid train` checks it after the
    # config, not by each trial once the engine has started
    check_paths(cfg, Path(config), data, columns)
    name, key = (vehicle, "--vehicle") if vehicle else (cfg.vehicle, "vehicle")
    if name:
        vehicle_for(name, Path(config), key)
    return spec, tasks


def _searched_at(field: str | None, setting: dict[str, Any]) -> str | None:
    """The option path of ``setting`` an error's ``field`` is at (the path, or a key within
    its value), or None."""
    if not field:
        return None
    return next((k for k in setting if field == k or field.startswith(k + ".")), None)


def _vehicle_path(vehicle: str | None, config: Path) -> str | None:
    """``--vehicle`` as the trial reads it, made absolute: a preset's name as it is, else the
    file (relative to the current folder, as ``nnid train`` reads it:
    :func:`nnid.pipeline.vehicle_source`)."""
    from nnid.pipeline import vehicle_source
    from nnid.vehicle import PRESETS

    if not vehicle or vehicle in PRESETS:
        return vehicle
    return str(Path(vehicle_source(vehicle, Path(config), "--vehicle")).resolve())


@dataclass
class Ranked:
    """One setting's scores over its seeds."""

    setting: dict[str, Any]
    scores: list[float | None]
    rows: list[dict]

    @property
    def complete(self) -> bool:
        return all(s is not None for s in self.scores)

    @property
    def mean(self) -> float | None:
        finite = [s for s in self.scores if s is not None]
        return statistics.fmean(finite) if finite else None


def rank(spec: SweepSpec, tasks: list[Task], rows: list[dict]) -> list[Ranked]:
    """Settings best first: complete ones by their mean validation score, then the ones with a
    missing score (diverged or failed seeds) by the mean of what they have. A trial whose
    training kept its start (``training_diverged``) has no score: its numbers are of the
    model before training, not of the setting."""
    groups: dict[str, Ranked] = {}
    for task, row in zip(tasks, rows, strict=True):
        setting, _ = trial_setting(task.overrides, spec.seed_option, bool(spec.seeds))
        key = json.dumps(setting, sort_keys=True)
        trained = row["status"] == "ok" and not row.get("training_diverged")
        score = row.get(f"validation_{spec.metric}") if trained else None
        score = None if score is None or not math.isfinite(score) else score
        groups.setdefault(key, Ranked(setting, [], [])).scores.append(score)
        groups[key].rows.append(row)
    return sorted(
        groups.values(),
        key=lambda r: (not r.complete, r.mean is None, r.mean if r.mean is not None else 0.0),
    )


def best_config_text(config: Path, setting: dict[str, Any]) -> str:
    """The config with ``setting`` written in and its ``[sweep]`` table removed."""
    import tomli_w

    data = read_toml(config)
    data.pop("sweep", None)
    for option, value in setting.items():
        set_option(data, option, value, str(config))
    return f"# chosen by nnid sweep from {Path(config).name}\n" + tomli_w.dumps(data)


def run_sweep(
    config: Path,
    out_dir: Path,
    engine,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    progress: Progress | None = None,
) -> tuple[BatchResult, list[Ranked]]:
    """Run every trial on ``engine``, rank the settings, write ``settings.csv`` and
    ``best.toml`` beside the batch summary (:func:`nnid.scale.batch.write_summary`)."""
    from nnid.scale.batch import write_summary

    spec, tasks = trials(config, data, vehicle, columns)
    result = run_tasks(tasks, out_dir, engine, progress=progress)
    ranked = _write_sweep(spec, config, tasks, result, Path(out_dir))
    write_summary(result, out_dir, title="nnid sweep")
    return result, ranked


def _write_sweep(
    spec: SweepSpec, config: Path, tasks: list[Task], result: BatchResult, out_dir: Path
) -> list[Ranked]:
    """Rank the settings; write ``settings.csv`` and ``best.toml``; the sweep's record in
    ``result.extra``."""
    from nnid.serialization import write_text

    ranked = rank(spec, tasks, result.rows)
    table = pd.DataFrame(
        [
            {
                **{f"option:{k}": v for k, v in r.setting.items()},
                f"validation_{spec.metric}_mean": r.mean,
                "seeds_scored": sum(s is not None for s in r.scores),
                "seeds": len(r.scores),
                "seeds_training_diverged": sum(bool(x.get("training_diverged")) for x in r.rows),
                "scores": json.dumps(r.scores),
                "test_free_run_nrmse": json.dumps([_test_score(row) for row in r.rows]),
            }
            for r in ranked
        ]
    )
    write_text(Path(out_dir) / "settings.csv", table.to_csv(index=False))
    best = ranked[0]
    if best.mean is not None:
        write_text(Path(out_dir) / "best.toml", best_config_text(config, best.setting))
    result.extra["sweep"] = {
        "metric": f"validation {spec.metric} (total), mean over seeds",
        "seed_option": spec.seed_option,
        # a seed searched in a grid is a setting of its own: the page labels trials as ranked
        "seeds": list(spec.seeds),
        "settings": len(ranked),
        "trials": len(tasks),
        "best": {"settings": best.setting, "mean": best.mean, "scores": best.scores},
        "summary": _summary(spec, ranked),
    }
    return ranked


def _test_score(row: dict) -> float | None:
    """The trial's test free-run NRMSE (reported, never used to choose); None without a test
    part."""
    return row.get("free_run_nrmse") if row.get("held_out") == "test" else None


def _summary(spec: SweepSpec, ranked: list[Ranked]) -> str:
    best = ranked[0]
    if best.mean is None:
        rows = [row for r in ranked for row in r.rows]
        failed, stopped = not_ok_counts(rows)  # a trial ASHA stopped did not fail
        kept = sum(row["status"] == "ok" and bool(row.get("training_diverged")) for row in rows)
        rest = len(rows) - failed - stopped - kept
        said = [
            f"{failed} failed" if failed else "",
            f"{stopped} stopped early by ASHA" if stopped else "",
            f"{kept} kept an untrained start (training diverged)" if kept else "",
            f"{rest} {'has' if rest == 1 else 'have'} no validation {spec.metric} (diverged, "
            "or nothing scored: each "
            "trial's warnings say which)"
            if rest
            else "",
        ]
        return (
            f"No setting gave a validation {spec.metric}. Of {len(rows)} trials: "
            + "; ".join(x for x in said if x)
            + "."
        )
    scored = sum(s is not None for s in best.scores)
    if len(best.scores) == 1:
        over = "(one seed: "
    elif scored < len(best.scores):  # "mean of 2 seeds: no score, 6.34" was one seed's
        over = f"(mean of the {scored} of {len(best.scores)} seeds with a score: "
    else:
        over = f"(mean of {len(best.scores)} seeds: "
    text = (
        f"Best of {len(ranked)} settings: {json.dumps(best.setting)} with validation "
        f"{spec.metric} {best.mean:.4g} "
        + over
        + ", ".join("no score" if s is None else f"{s:.4g}" for s in best.scores)
        + ")."
    )
    if spec.metric.endswith("nrmse") and best.mean > 1.0:
        text += (
            " That is above 1: this setting predicts the validation runs worse than their "
            "mean, and best.toml holds it all the same."
        )
    if not best.complete:
        text += " Every setting had a seed without a score; this one is ranked on the rest."
    if spec.metric != "free_run_nrmse":  # a short-horizon rank can pick a model that diverges
        ran = [r for r in best.rows if r.get("status") == "ok"]
        gone = sum(r.get("validation_free_run_nrmse") is None for r in ran)
        if gone:
            text += (
                f" Its validation free run diverged in {gone} of {len(ran)} seeds: a "
                f"{spec.metric} ranking does not say how a setting simulates."
            )
    return text


# -- Ray Tune ------------------------------------------------------------------------------------


def _tune_trial(params: dict, tasks: list[Task], out_root: str, metric: str) -> None:
    """One trial inside Ray Tune: the train task, its trainers' per-epoch validation objective
    reported to Tune (ASHA's rungs), then the best of them once more as the trial ends.

    ASHA compares trials at equal report counts, so every report must measure the same thing:
    a stage that names its measure (:func:`nnid.trainers.history.staged`) is reported only
    when that is the sweep's ``metric`` (a NARX's one-step epochs are not, under a free-run
    metric: trials would be compared one-step against free run where their stages switch at
    different epochs); a model that names none has one measure and is reported."""
    from ray import tune

    from nnid.scale.task import run_task

    task = tasks[params["trial"]]
    reported: list[float] = []

    def report(done: int, total: int | None, message: str, **scores: float) -> None:
        named = any(k.startswith("validation_") for k in scores)
        value = scores.get(f"validation_{metric}") if named else scores.get("validation")
        if value is not None:  # a diverged free run is the worst score, not a skipped one
            reported.append(stopping_score(value))
            tune.report({"objective": reported[-1]})

    row = run_task(task, out_root, progress=report)
    # the kept epoch is the best one (the trainers restore it), not the last
    tune.report({"objective": min(reported, default=math.inf), "finished": 1.0,
                 "error": row["error"] or ""})  # fmt: skip


def run_sweep_tune(
    config: Path,
    out_dir: Path,
    address: str | None,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    progress: Progress | None = None,
    num_cpus: int | None = None,
) -> tuple[BatchResult, list[Ranked]]:
    """:func:`run_sweep` on Ray Tune, one CPU per trial, with ASHA early stopping
    (``[sweep] early_stopping``): a stopped trial is a ``stopped`` row that says at which
    epoch, and its setting is ranked on the seeds that finished. A trial an earlier run into
    ``out_dir`` finished is not run again (as :func:`run_sweep`). The trials' workers start
    with :data:`~nnid.scale.engines.ONE_THREAD` when this function starts Ray; a Ray the
    caller started keeps the caller's ``runtime_env`` (give it
    ``runtime_env={"env_vars": ONE_THREAD}`` for the same)."""
    from nnid.scale.batch import write_summary
    from nnid.scale.task import finished

    spec, tasks = trials(config, data, vehicle, columns)
    if spec.early_stopping:
        _check_rungs(config, spec, tasks)
    out_dir = Path(out_dir).absolute()
    out_dir.mkdir(parents=True, exist_ok=True)
    # as on local processes (run_tasks), a trial an earlier run finished is reused and never
    # given to Tune: Tune ran every trial again, and one that failed now was said ok from the
    # earlier run's task.json
    earlier = {t.id: row for t in tasks if (row := finished(t, out_dir)) is not None}
    todo = [t for t in tasks if t.id not in earlier]
    ran, cpus, seconds = (
        _run_tune(spec, tasks, todo, out_dir, address, num_cpus, progress) if todo else ({}, 1, 0.0)
    )
    rows = [{**earlier[t.id], "reused": True} if t.id in earlier else ran[t.id] for t in tasks]
    batch = BatchResult(rows, "ray tune" + (" (ASHA)" if spec.early_stopping else ""),
                        len(earlier), seconds, cpus)  # fmt: skip
    ranked = _write_sweep(spec, config, tasks, batch, out_dir)
    now = [r for r in rows if not r.get("reused")]
    batch.extra["sweep"]["early_stopping"] = {
        "scheduler": "ASHA" if spec.early_stopping else None,
        "stopped": not_ok_counts(rows)[1],
        "epochs_run": sum(r.get("epochs") or 0 for r in now),
    }
    if spec.early_stopping and now and all((r.get("epochs") or 0) <= 1 for r in now):
        batch.extra["sweep"]["summary"] += (
            f" ASHA compared no trials: no training stage reported a per-epoch validation "
            f"{spec.metric} (a least-squares or SINDy fit has no epochs), so every trial ran "
            "to its end."
        )
    write_summary(batch, out_dir, title="nnid sweep")
    return batch, ranked


def _run_tune(
    spec: SweepSpec,
    tasks: list[Task],
    todo: list[Task],
    out_dir: Path,
    address: str | None,
    num_cpus: int | None,
    progress: Progress | None,
) -> tuple[dict[str, dict[str, Any]], int, float]:
    """Run the trials ``todo`` (of the sweep's ``tasks``) on Ray Tune: their rows by task id,
    the cluster's CPUs and the seconds from Ray's start to the last row."""
    import threading
    import time

    import ray
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler, FIFOScheduler

    from nnid.scale.engines import ONE_THREAD, ray_session
    from nnid.scale.task import finished

    # Tune starts its trials' workers itself, with no runtime_env of ours: the job of a Ray
    # started here gives them the one-thread environment the batch engines' workers start
    # with (Ray sets only OMP_NUM_THREADS; numba, OpenBLAS and MKL took every core)
    with ray_session(ray, address, num_cpus, runtime_env={"env_vars": ONE_THREAD}):
        start = time.perf_counter()  # the wall time leaves Ray's start out (docs/scale.md)
        scheduler = (
            ASHAScheduler(
                time_attr="training_iteration",
                max_t=1_000_000,  # trials end by themselves (their own epochs and early stop)
                grace_period=spec.grace_epochs,
                reduction_factor=spec.reduction_factor,
            )
            if spec.early_stopping
            else FIFOScheduler()
        )
        trainable = tune.with_resources(
            tune.with_parameters(
                _tune_trial, tasks=todo, out_root=str(out_dir), metric=spec.metric
            ),
            {"cpu": 1},
        )
        tuner = tune.Tuner(
            trainable,
            param_space={"trial": tune.grid_search(list(range(len(todo))))},
            # a trial reuses a finished one's actor: a fresh actor is a process that imports
            # torch and nnid again (8-10 s a trial of a small NARX sweep beside a busy core,
            # 1.5 s warm). A trial ASHA stopped waits in its report and ends there when its
            # actor is reset
            tune_config=tune.TuneConfig(
                metric="objective", mode="min", scheduler=scheduler, reuse_actors=True
            ),
            run_config=tune.RunConfig(storage_path=str(out_dir / ".tune"), name="sweep", verbose=0),
        )
        cpus = int(ray.cluster_resources().get("CPU", 1))
        box: dict[str, Any] = {}

        def fit() -> None:
            # Tune's own failure is raised again here: a thread that dies of it printed its
            # traceback and left a KeyError 'grid' behind
            try:
                box["grid"] = tuner.fit()
            except BaseException as exc:
                box["error"] = exc

        thread = threading.Thread(target=fit)
        thread.start()
        while thread.is_alive():  # progress: the trials whose outputs are written
            done = sum(finished(t, out_dir) is not None for t in tasks)
            (progress or silent)(done, len(tasks), f"{done} of {len(tasks)} trials finished")
            thread.join(1.0)
        if "error" in box:
            raise box["error"]
        ran = [(todo[r.config["trial"]], r) for r in box["grid"]]
        rows = {task.id: _tune_row(task, r, out_dir, spec.metric) for task, r in ran}
        seconds = time.perf_counter() - start
    return rows, cpus, seconds


def _check_rungs(config: Path, spec: SweepSpec, tasks: list[Task]) -> None:
    """Refuse ASHA where no trial scores the sweep's metric per epoch: it would compare
    nothing, and every trial would run to its end (said before the work, not after it)."""
    measures = [
        getattr(load_config(config, TrainConfig, t.overrides).model, "epoch_measures", None)
        for t in tasks
    ]
    if all(m is not None and spec.metric not in m() for m in measures):
        raise NnidInputError(
            f"early stopping (ASHA, on --address) compares trials by their per-epoch validation "
            f"{spec.metric}, and no trial's model scores it per epoch (a NARX scores the free "
            "run per epoch only in a simulation stage, model.simulation_epochs > 0): set "
            "metric to a measure the model trains on, add that stage, or early_stopping = false",
            source=str(config),
            field="sweep.early_stopping",
        )


def _tune_row(task: Task, result, out_dir: Path, metric: str) -> dict[str, Any]:
    """A Tune trial's row: the task's own row when it finished (in this run: a trial an
    earlier run finished is not given to Tune), else why not. ``epochs`` counts the reports
    ASHA saw (the epochs that measured ``metric``, and the last)."""
    from nnid.scale.engines import failed_row
    from nnid.scale.task import finished

    metrics = result.metrics or {}
    epochs = metrics.get("training_iteration")
    row = finished(task, out_dir)
    if row is not None:
        return {**row, "epochs": epochs, "reused": False}
    if result.error is not None:
        return {**failed_row(task, str(result.error).strip().splitlines()[0]), "epochs": epochs}
    if not metrics.get("finished"):
        row = failed_row(
            task,
            f"stopped early by ASHA after {epochs} epochs of its validation {metric} "
            f"(objective {metrics.get('objective', float('nan')):.4g})",
        )
        return {**row, "status": STOPPED, "epochs": epochs}
    return {**failed_row(task, metrics.get("error") or "the fit failed"), "epochs": epochs}
