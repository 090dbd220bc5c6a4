"""Each command's whole run as one library call: read, fit, score and write the outputs to a
folder, atomically. The CLI (one run, a person watching) and :mod:`nnid.scale` (many runs on
workers) both call these, so a task of ``nnid batch`` writes exactly what the command writes.

Every function returns an :class:`Outcome`: the sentences the CLI prints, the warnings, and a
flat ``headline`` of the run's scores for a summary table. Nothing here prints.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import uuid
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from nnid.errors import NnidInputError, checked_number
from nnid.reports.cells import score_cell
from nnid.trainers.history import Progress, silent
from nnid.validation import ALPHA_MAX, ALPHA_MIN, MIN_WINDOW_S, repeated


@dataclass
class Outcome:
    """What a run says: ``lines`` for a person, ``warnings``, and ``headline`` scores (flat,
    JSON-ready: numbers, strings, None) for one row of a summary."""

    lines: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    headline: dict[str, Any] = field(default_factory=dict)


# -- output folders ------------------------------------------------------------------------------


def check_out(out_dir: Path) -> None:
    """An output folder that can be written: refused before any work starts (a file, a place
    such as /proc, a folder without write permission)."""
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise NnidInputError("exists and is not a folder", source=str(out_dir), field="--out")
    base = next(p for p in (out_dir.absolute(), *out_dir.absolute().parents) if p.exists())
    if not base.is_dir():
        raise NnidInputError(f"{base} is not a folder", source=str(out_dir), field="--out")
    try:  # the only sure test of writability is to write
        tempfile.TemporaryDirectory(dir=base).cleanup()
    except OSError as exc:
        raise _unwritable(out_dir, exc) from None


@contextmanager
def staged(out_dir: Path, supersedes: tuple[str, ...] = ()) -> Iterator[Path]:
    """Yield a hidden folder to write the outputs into; only once every file is written are
    they moved into ``out_dir``, so a run that fails half way leaves nothing that poses as its
    result (and an earlier result in ``out_dir`` untouched). ``supersedes``: the files an
    earlier run of this command may have left that this run replaces; one it did not write is
    removed (an old ``monitor.json`` must not pair with a new model). A file where ``out_dir``
    holds a folder of that name, or a folder where it holds a file, is refused before
    anything moves: it is the user's, not an earlier result. A folder that cannot be written
    is said against ``--out``."""
    out_dir = Path(out_dir)
    where = out_dir.absolute()
    # an existing out_dir holds its stage: the folder check_out proved writable, and one file
    # system (a parent that cannot be written, a mount point, failed after the whole fit);
    # a new one is staged beside it and renamed into place whole
    home = where if where.is_dir() else where.parent
    try:
        home.mkdir(parents=True, exist_ok=True)
        # os.mkdir, not mkdtemp: the folder keeps the user's umask once it is renamed into place
        stage = home / f".{where.name}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        stage.mkdir()
    except OSError as exc:
        raise _unwritable(out_dir, exc) from None
    try:
        yield stage
        try:
            _moved_into(stage, out_dir, supersedes)
        except OSError as exc:
            raise _unwritable(out_dir, exc) from None
    finally:
        shutil.rmtree(stage, ignore_errors=True)


def _moved_into(stage: Path, out_dir: Path, supersedes: tuple[str, ...]) -> None:
    """The files of ``stage`` moved into ``out_dir`` (:func:`staged`). A new folder is the
    stage renamed, whole. Into one that exists (it may hold the user's other files, and be a
    mount point: never renamed itself), the earlier files this run replaces are moved aside
    into a hidden folder first, then the new ones in: a failure on the way moves them back,
    so the folder holds the earlier result whole, never a mix of the two (moved one by one,
    a failure half way left a new model.json beside an old metrics.json). A process killed
    between the renames cannot move them back; as every earlier file is aside before a new
    one moves in, the folder then holds some of one result's files, never of both, and the
    earlier ones lie in that hidden folder (``.<out>-…-old``)."""
    if not out_dir.exists():
        stage.rename(out_dir)
        return
    items = list(stage.iterdir())
    for item in items:
        target = out_dir / item.name
        if target.exists() and target.is_dir() != item.is_dir():
            kind = "folder" if target.is_dir() else "file"
            raise NnidInputError(
                f"{target} is a {kind} of yours where this run writes its "
                f"{'folder' if item.is_dir() else 'file'} {item.name}: move it, or choose "
                "another --out",
                field="--out",
            )
    written = {item.name for item in items}
    stale = [n for n in supersedes if n not in written and (out_dir / n).is_file()]
    earlier = [n for n in (*written, *stale) if os.path.lexists(out_dir / n)]
    aside = stage.with_name(f"{stage.name}-old")  # beside the stage: one file system
    aside.mkdir()
    moved: list[str] = []  # the earlier files moved aside
    placed: list[str] = []  # the new ones moved in
    try:
        for name in earlier:
            os.replace(out_dir / name, aside / name)
            moved.append(name)
        for item in items:
            os.replace(item, out_dir / item.name)
            placed.append(item.name)
    except BaseException:
        _moved_back(stage, out_dir, aside, placed, moved)
        raise
    shutil.rmtree(aside, ignore_errors=True)


def _moved_back(
    stage: Path, out_dir: Path, aside: Path, placed: list[str], moved: list[str]
) -> None:
    """Undo :func:`_moved_into`'s renames that were made: the new files ``placed`` back into
    the stage, the earlier ones ``moved`` aside back into ``out_dir``. One that cannot be is
    said with where the earlier result lies (the hidden folder is then kept)."""
    try:
        for name in reversed(placed):
            os.replace(out_dir / name, stage / name)
        for name in reversed(moved):
            os.replace(aside / name, out_dir / name)
        aside.rmdir()
    except OSError as exc:
        raise NnidInputError(
            f"cannot be written, and the earlier result it held could not be put back "
            f"({exc.strerror or exc}): its files are in {aside}",
            source=str(out_dir),
            field="--out",
        ) from exc


def _unwritable(out_dir: Path, exc: OSError) -> NnidInputError:
    """The error of an output folder that refused the outputs, naming ``--out``."""
    return NnidInputError(
        f"cannot be written ({exc.strerror or exc})", source=str(out_dir), field="--out"
    )


def lost_rows(report) -> list[str]:
    """The cleaning steps that bridged, masked or removed rows, a line each for the console:
    a run says what it filled in or left out, not only in its cleaning report file."""
    from nnid.datasets.gaps import GAP_STEPS

    return [f"{s.step}: {s.detail}" for s in report.steps if s.rows_removed or s.step in GAP_STEPS]


def _total(scores: dict, key: str) -> float | None:
    return scores.get(key, {}).get("total")


# -- train ---------------------------------------------------------------------------------------


def train_run(
    cfg,
    config_path: Path,
    out_dir: Path,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    progress: Progress | None = None,
    time_unit: str | None = None,
) -> Outcome:
    """``nnid train``: fit the configured model, score it on the held-out parts, write the
    model (``model.json``, ``tensors.pt``), ``metrics.json``, the reports and the cleaning
    report to ``out_dir``. ``time_unit``: ``--time-unit`` (the config's ``data.time_unit``
    otherwise)."""
    from nnid.pipeline import run_train
    from nnid.reports.train_report import monitor_sentence, train_html, train_markdown
    from nnid.serialization import write_json, write_text

    try:
        result = run_train(
            cfg, config_path, data, vehicle, columns, progress=progress, time_unit=time_unit
        )
    except NnidInputError as exc:
        raise exc.with_source(str(config_path)) from None
    from nnid.fault.monitor import MONITOR_FILE
    from nnid.models.base import MODEL_FILE, TENSOR_FILE

    with staged(out_dir, supersedes=(MODEL_FILE, TENSOR_FILE, MONITOR_FILE)) as stage:
        if result.monitor is not None:  # saves its model, then the calibration bound to it
            result.monitor.save(stage)
        else:
            result.model.save(stage)
        write_json(stage / "metrics.json", result.metrics)
        write_text(stage / "report.md", train_markdown(result.metrics))
        write_text(stage / "report.html", train_html(result.metrics, result.figures))
        result.report.write(stage)
        # what this run wrote, as written: tensors.pt and the cleaning report had gone unsaid
        files = ", ".join(sorted(item.name for item in stage.iterdir()))
    from nnid.evaluation.evaluate import diverged_columns
    from nnid.pipeline import diverged_training

    metrics = result.metrics
    held = "test" if "test" in metrics else "validation"
    free = metrics[held].get("free_run_nrmse", {})
    went = diverged_columns(metrics[held], "free_run_nrmse")
    line = f"{held} free-run NRMSE total {score_cell(free, 'total', went)}"
    used = metrics.get("validation_used_for")
    if held == "validation" and used:  # no test part: the number shown is not independent
        line += f", used for {used} while fitting"
    base_part = metrics.get("baseline", {}).get(held, {})
    base = base_part.get("free_run_nrmse", {})
    if base:
        went = diverged_columns(base_part, "free_run_nrmse")
        line += f"; physics only {score_cell(base, 'total', went)}"
    broke = diverged_training(metrics.get("describe") or {})
    if broke:  # the scores are then the stage's start: said beside them, and as a warning
        line += "; a training stage kept its start (the warning says why)"
    headline: dict[str, Any] = {
        "model": metrics["model"],
        "trainer": metrics["trainer"],
        "vehicle_name": metrics.get("vehicle"),
        "n_params": metrics["n_params"],
        "held_out": held,
        "validation_used_for": used,
        "free_run_nrmse": free.get("total"),
        "one_step_nrmse": _total(metrics[held], "one_step_nrmse"),
        "diverged": ", ".join(metrics[held].get("diverged", {})) or None,
        "training_diverged": bool(broke),
    }
    for key in ("free_run_nrmse", "one_step_nrmse", "k_step_nrmse"):  # what a sweep ranks by
        headline[f"validation_{key}"] = _total(metrics["validation"], key)
    for name, p in metrics["params"].items():
        headline[f"param:{name}"] = p.get("value")
        headline[f"stderr:{name}"] = p.get("stderr")
    said = [f"wrote {out_dir}/: {files} ({line})"]
    if result.monitor is not None:
        said.append(f"monitor: {monitor_sentence(metrics['detect'])}")
    return Outcome(
        [*lost_rows(result.report), *said],
        list(metrics["warnings"]),
        headline,
    )


# -- compare -------------------------------------------------------------------------------------


#: why a comparison names no best model (:func:`no_best_why`), as the batch table says it
NOT_RANKED = "not ranked: no output in common"
UNTRAINED = "training kept its start"
NO_FREE_RUN = "no free run measured"
NO_SKILL = "no skill (free run above 1)"
INDISTINGUISHABLE = "first two indistinguishable"


def no_best_why(comparison: dict) -> str | None:
    """Why the batch table names no best model, as the summary says it, or None where it
    names one: models that share no output are not ranked; a ranking of an untrained start,
    or on k-step or one-step scores (every free run diverged or was not scored), names none;
    nor does one where no model has skill (free run above 1: the summary said so while the
    table named a best) or where the data do not tell the first from the second
    (:func:`nnid.pipeline.verdict`). Four reasons read "-" alike in the table."""
    ranking = comparison.get("ranking", [])
    if not ranking or not comparison.get("ranked_on"):
        return NOT_RANKED
    top = next((r for r in comparison["models"] if r["name"] == ranking[0]), {})
    free = (top.get("ranked_nrmse") or {}).get("free_run")
    if top.get("training_diverged"):
        return UNTRAINED
    if free is None:
        return NO_FREE_RUN
    if free > 1.0:
        return NO_SKILL
    if (comparison.get("verdict") or {}).get("indistinguishable", False):
        return INDISTINGUISHABLE
    return None


def best_model(comparison: dict) -> str | None:
    """The model a batch table names best, as the summary names it, or None
    (:func:`no_best_why` says why)."""
    return None if no_best_why(comparison) else comparison["ranking"][0]


def compare_run(
    cfg,
    config_path: Path,
    out_dir: Path,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    progress: Progress | None = None,
    time_unit: str | None = None,
) -> Outcome:
    """``nnid compare``: fit the config's models on one split, compare them on the same
    held-out runs; ``comparison.json`` and the reports. ``time_unit``: ``--time-unit``."""
    from nnid.pipeline import run_compare
    from nnid.reports.compare_report import all_warnings, html_page, markdown
    from nnid.serialization import write_json, write_text

    try:
        result = run_compare(
            cfg, config_path, data, vehicle, columns, progress=progress, time_unit=time_unit
        )
    except NnidInputError as exc:
        raise exc.with_source(str(config_path)) from None
    with staged(out_dir) as stage:
        write_json(stage / "comparison.json", result.comparison)
        write_text(stage / "report.html", html_page(result))
        write_text(stage / "report.md", markdown(result.comparison))
        result.report.write(stage)
    comparison = result.comparison
    best = best_model(comparison)
    shared = comparison.get("ranked_on") or []
    untrained = [r["name"] for r in comparison["models"] if r.get("training_diverged")]
    headline: dict[str, Any] = {
        "best": best,
        "no_best": no_best_why(comparison),  # the four reasons read alike as "-"
        "ranked_on": ",".join(shared) or None,
        "training_diverged": ",".join(untrained) or None,
    }
    for row in comparison["models"]:
        held = row.get("test") or row.get("validation") or {}
        # side by side, the totals must be over the same outputs: those the ranking shares
        headline[f"free_run_nrmse:{row['name']}"] = (
            row["ranked_nrmse"]["free_run"] if shared else _total(held, "free_run_nrmse")
        )
    return Outcome(
        [
            *lost_rows(result.report),
            f"wrote {out_dir}/: comparison.json, report.html, report.md. " + comparison["summary"],
        ],
        all_warnings(comparison),
        headline,
    )


# -- loop ----------------------------------------------------------------------------------------

#: loop settings a config (or an option) sets: an error about one names the config
LOOP_SETTINGS = (
    "validation",
    "validation_fraction",
    "filter_lambda",
    "dofs",
    "alpha",
    "max_effects",
    "warmup_s",
    "gate_horizon_s",
    "savgol_window",
    "savgol_order",
)


def names(text: str | None, option: str = "") -> list[str]:
    """A comma-separated option as a list (empty for None); an option given with no name in it
    (``--dofs ,``) is an error, not "all", and so are an empty name and a name given twice
    (a typo, as in a config's lists)."""
    if text is None:
        return []
    given = [n.strip() for n in text.split(",")]
    out = [n for n in given if n]
    if not out:
        raise NnidInputError(
            f"names nothing ({text!r}); leave the option out for all", field=option
        )
    if len(out) < len(given):
        raise NnidInputError(f"has an empty name ({text!r})", field=option)
    twice = repeated(out)
    if twice:
        raise NnidInputError(f"names {', '.join(twice)} twice ({text!r})", field=option)
    return out


def dofs_option(text: str | None) -> tuple[str, ...] | None:
    """``--dofs u,w``: checked DOF names, or None for all logged."""
    from nnid.physics.dofs import DOFS

    given = names(text, "--dofs")
    unknown = [d for d in given if d not in DOFS]
    if unknown:
        raise NnidInputError(
            f"unknown DOF {', '.join(unknown)}; expected some of {' '.join(DOFS)}", field="--dofs"
        )
    return tuple(given) or None


def exclude_experiments(log, excluded: list[str], report):
    """The log without the named experiments (a name may be a replay group of the reader
    config, ``replays[0]``: all its copies), reported; an unknown name is an error."""
    from nnid.datasets.log import REPLAY_GROUP, run_pieces

    if not excluded:
        return log
    excluded = run_pieces(log, excluded)  # a run a gap cut into pieces: all of them
    if REPLAY_GROUP in log:
        groups = log.groupby(REPLAY_GROUP, sort=False)["experiment"].unique()
        excluded = [e for n in excluded for e in (groups[n] if n in groups else [n])]
    known = set(log["experiment"]) if "experiment" in log else set()
    unknown = [n for n in excluded if n not in known]
    if unknown:
        raise NnidInputError(
            f"experiments {', '.join(unknown)} are not in the log", field="--exclude"
        )
    keep = ~log["experiment"].isin(excluded)
    if not keep.any():
        raise NnidInputError(
            f"leaves no experiment to analyse (the log has {', '.join(sorted(map(str, known)))})",
            field="--exclude",
        )
    report.add("exclude", f"left out {', '.join(excluded)} (--exclude)", int((~keep).sum()))
    return log[keep].reset_index(drop=True)


@contextmanager
def said_on_error(messages: Sequence[str]) -> Iterator[None]:
    """Run the block; where it stops on an input error, first say ``messages``: warnings a run
    recorded for its outputs (:func:`nnid.pipeline.loaded_inputs`), which a refusal before
    they are written would otherwise lose."""
    try:
        yield
    except NnidInputError:
        for message in messages:
            warnings.warn(message, stacklevel=3)
        raise


def hybrid_model(folder: Path):
    """A saved hybrid model, or one clear error."""
    from nnid.models.base import load_model

    model = load_model(folder)
    if model.kind != "hybrid":
        raise NnidInputError(
            f"is a saved '{model.kind}' model; --hybrid takes a hybrid "
            "(nnid train configs/hybrid.toml)",
            source=str(folder),
            field="--hybrid",
        )
    return model


def loop_run(
    cfg,
    config_path: Path | None,
    out_dir: Path,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    *,
    max_effects: int | None = None,
    alpha: float | None = None,
    dofs: str | None = None,
    validation: str | None = None,
    exclude: str | None = None,
    hybrid: Path | None = None,
    progress: Progress | None = None,
    time_unit: str | None = None,
) -> Outcome:
    """``nnid loop``: the residual loop of a log and a vehicle file (a
    :class:`nnid.config.LoopConfig`; the keyword options override it as the CLI's do,
    ``time_unit`` its ``data.time_unit``)."""
    from nnid.datasets.column_map import load_column_map
    from nnid.datasets.preprocess import check_attitude
    from nnid.physics.dofs import DOFS
    from nnid.pipeline import loaded_inputs, reader_config

    if alpha is not None:  # as the config's alpha: a NaN failed typer's bound as "above 0.5"
        checked_number(alpha, "--alpha", ALPHA_MIN, strict=False, maximum=ALPHA_MAX)
    where = config_path or Path("loop.toml")
    reader = reader_config(cfg, where, columns)
    if not (vehicle or cfg.vehicle or (reader and load_column_map(reader).vehicle)):
        raise NnidInputError(
            "give a vehicle (--vehicle, the config's 'vehicle' or the reader config's)",
            field="vehicle",
        )
    if not (data or cfg.data.log or cfg.data.simulate):
        raise NnidInputError("give a log (--data or the config's data.log)", field="data")
    second = hybrid_model(hybrid) if hybrid is not None else None
    try:  # what loading said (a vehicle file's sign slip) goes into loop.json too
        inputs, loaded = loaded_inputs(cfg, where, [], data, vehicle, columns, time_unit=time_unit)
    except NnidInputError as exc:
        raise exc.with_source(str(config_path)) if config_path else exc from None
    # loop.json keeps them; a refusal before it is written says them, or nothing would
    with said_on_error(loaded):
        if second is not None and second.vehicle.name != inputs.vehicle.name:
            # its learned force is of another vehicle: read as this one's missing effect, misleading
            raise NnidInputError(
                f"was trained for vehicle '{second.vehicle.name}'; this loop runs "
                f"'{inputs.vehicle.name}'",
                source=str(hybrid),
                field="--hybrid",
            )
        left_out = names(exclude, "--exclude")
        log = exclude_experiments(inputs.log, left_out, inputs.report)
        held = names(validation, "--validation") or cfg.validation
        if held:  # said against the option or key that names them, not against the log
            key = "--validation" if validation else "validation"
            known = set(log["experiment"]) if "experiment" in log else set()
            logged = set(inputs.log["experiment"]) if "experiment" in inputs.log else set()
            for name in held:
                if name not in known:  # --exclude may name a replay group: its runs are gone too
                    why = "is left out by --exclude" if name in logged else "is not in the log"
                    raise NnidInputError(
                        f"experiment {name!r} {why}",
                        source=str(config_path) if key == "validation" and config_path else None,
                        field=key,
                    )
        fitted_dofs = dofs_option(dofs) or (tuple(cfg.dofs) if cfg.dofs else None)
        try:  # on the runs the loop keeps, as train checks the runs its config keeps
            check_attitude(log, inputs.vehicle, list(fitted_dofs or DOFS))
        except NnidInputError as exc:
            # the log file read (through its reader config), not the reader config's name
            raise exc.with_source(inputs.source or inputs.report.source or str(where)) from None
        settings = dict(
            max_effects=cfg.max_effects if max_effects is None else max_effects,
            alpha=cfg.alpha if alpha is None else alpha,
            coupled=cfg.coupled,
            filter_lambda=cfg.filter_lambda,
            savgol_window=cfg.savgol_window,
            savgol_order=cfg.savgol_order,
            warmup_s=cfg.warmup_s,
            validation=cfg.validation_fraction,
            dofs=fitted_dofs,
            validation_experiments=held,
            gate_horizon_s=cfg.gate_horizon_s,
            second_opinion=second,
        )
        source, named = data or str(config_path or ""), str(config_path or "")
        given = {"validation": validation, "alpha": alpha, "max_effects": max_effects, "dofs": dofs}
        options = {k: f"--{k.replace('_', '-')}" for k, v in given.items() if v is not None}
        return residual_loop_run(
            log, inputs.vehicle, out_dir, source, inputs.report, named, progress, loaded,
            options, **settings,
        )  # fmt: skip


def residual_loop_run(
    log,
    veh,
    out_dir: Path,
    source: str = "",
    cleaning=None,
    config: str = "",
    progress: Progress | None = None,
    said: Sequence[str] = (),
    options: Mapping[str, str] | None = None,
    **settings,
) -> Outcome:
    """The residual loop on a loaded log: ``loop.json``, the reports and the cleaning report
    written to ``out_dir`` (:class:`nnid.loop.residual_loop.ResidualLoop`); ``said``, the
    warnings of loading it, lead the loop's own; ``options``, the command-line option that
    gave a setting (``validation``: ``--validation``), is named for a fault of that setting."""
    from nnid.loop.residual_loop import ResidualLoop
    from nnid.reports.loop_report import write_loop_report

    progress = progress or silent
    try:
        fitted = ResidualLoop(veh, **settings).fit(log, progress=progress)
    except NnidInputError as exc:
        option = (options or {}).get(exc.field or "")
        if option and exc.source is None and exc.row is None:  # neither the log's nor the file's
            raise NnidInputError(exc.message, field=option) from None
        named = config if config and exc.field in LOOP_SETTINGS else source
        raise exc.with_source(named) if named else exc from None
    fitted.warnings_ = list(dict.fromkeys([*said, *fitted.warnings_]))
    progress(0, None, "writing the report")
    with staged(out_dir) as stage:
        lines = write_loop_report(fitted, stage)
        if cleaning is not None:
            cleaning.write(stage)
    result = fitted.as_dict()
    headline: dict[str, Any] = {
        "vehicle_name": result["vehicle"],
        "added": "; ".join(result["added"]) or None,
        "before_free_run_nrmse": _total(result["before"], "free_run_nrmse"),
        "after_free_run_nrmse": _total(result["after"], "free_run_nrmse"),
        "before_force_rmse": _total(result["before"], "force_rmse"),
        "after_force_rmse": _total(result["after"], "force_rmse"),
        # "after" is measured on the runs that ranked and gated the effects added
        "validation_used_for": result["validation_used_for"],
        "diverged": ", ".join(result["before"].get("diverged", {})) or None,
        "unexplained": "; ".join(f"{d}: {s}" for d, s in result["unexplained"].items()) or None,
    }
    for step in result["steps"]:
        added = step["added"]
        if added:  # the size of each added effect (an efficiency, a force, ...)
            headline[f"param:{added['effect']}"] = added["params"].get("value")
            headline[f"stderr:{added['effect']}"] = added["stderr"].get("value")
    return Outcome(
        [*lines, f"wrote {out_dir}/: loop.json, report.html, report.md"],
        list(fitted.warnings_),
        headline,
    )


# -- detect --------------------------------------------------------------------------------------


def detection_window(model_dir: Path) -> float:
    """The isolation window a detection model was trained with (metrics.json's
    ``detect.settings.window_s``, bounded as the [detect] config bounds it), else 10 s: a
    hand-edited value was read unchecked (text a traceback, a negative one no window at all)."""
    from nnid.serialization import read_json

    path = Path(model_dir) / "metrics.json"
    if not path.is_file():
        return 10.0
    keys = ("detect", "settings", "window_s")
    node = read_json(path)
    for depth, key in enumerate(keys):
        if not isinstance(node, dict):  # a table edited into a list or a number
            raise NnidInputError(
                f"a JSON object is expected, not a {type(node).__name__}",
                source=str(path),
                field=".".join(keys[:depth]) or None,
            )
        node = node.get(key, 10.0 if key == "window_s" else {})
    try:  # as the [detect] config bounds it (nnid.config.DetectSpec)
        return checked_number(node, ".".join(keys), MIN_WINDOW_S, strict=False)
    except NnidInputError as exc:
        raise exc.with_source(str(path)) from None


def check_detect_inputs(model_dir: Path, data: str, out_dir: Path, follow: bool = False) -> None:
    """A detection model folder and a log that exist, and an output folder that is not the
    model's (its report.html would be replaced): checked before the model is loaded."""
    if not Path(model_dir).is_dir():
        raise NnidInputError("no such folder", source=str(model_dir), field="--model")
    if Path(out_dir).resolve() == Path(model_dir).resolve():
        raise NnidInputError(
            f"is the --model folder {model_dir}: detect's outputs would replace the model's "
            "own (its report.html); give another --out",
            field="--out",
        )
    if data != "-" and not Path(data).exists():
        raise NnidInputError("no such file or folder", source=data, field="--data")
    if data == "-" and not follow:
        raise NnidInputError("'-' (standard input) is read with --follow", field="--data")
    if follow and Path(data).is_dir():
        raise NnidInputError(
            "is a folder: --follow reads one growing CSV file (or '-')", source=data,
            field="--data",
        )  # fmt: skip
    if follow and data.lower().endswith((".parquet", ".gz")):  # read as text: a traceback
        raise NnidInputError(
            "is not a plain-text CSV: --follow reads a growing CSV file (or '-') row by row; "
            "a whole Parquet or gzipped log is read without --follow",
            source=data,
            field="--data",
        )


def _checked_window(window: float | None) -> None:
    """Refuse a ``--window`` that is not a finite number of at least :data:`MIN_WINDOW_S`
    seconds, naming the option: typer's own bound read a NaN as "should be greater than or
    equal to 0.5", and an infinite window let every alarm wait for its run's end."""
    if window is not None:
        checked_number(window, "--window", MIN_WINDOW_S, strict=False)


def _monitor(model_dir: Path, window: float | None):
    """The saved residual monitor and the isolation window to use (``window``, else the
    model's own)."""
    from nnid.fault.monitor import ResidualMonitor

    return ResidualMonitor.load(model_dir), window or detection_window(model_dir)


def follow_run(
    model_dir: Path,
    data: str,
    out_dir: Path,
    window: float | None,
    say,
    idle_s: float | None = None,
) -> list[str]:
    """``nnid detect --follow``: watch a growing CSV (or ``-``, standard input), ``say`` each
    alarm as it happens; the outputs written when the log ends (a file: once it has not grown
    for ``idle_s`` seconds, ``--idle-s``, else :data:`nnid.fault.follow.IDLE_S`); their
    sentences returned. Where an interrupt (Ctrl-C, SIGTERM) or a refused row stops the watch,
    the outputs of the rows watched are written all the same, with why it stopped, their
    sentences said, and the exception goes on (the CLI's exit code is still 130, 143 or 2),
    also where those outputs cannot be written (that error is said). What the watch said of
    the log (a cut last row, a pose column held, intervals without samples) is in the
    outputs' notes, as batch's are."""
    from nnid.fault.follow import IDLE_S, follow_csv
    from nnid.reports.detect_report import OUTPUTS, write_detect_outputs

    _checked_window(window)
    check_detect_inputs(model_dir, data, out_dir, follow=True)
    monitor, window_s = _monitor(model_dir, window)
    notes: list[str] = []  # filled by follow_csv as it says them

    def written(result) -> list[str]:
        with staged(out_dir) as stage:
            lines = write_detect_outputs(monitor, result, stage, source=data, notes=notes)
        return [*lines, f"wrote {out_dir}/: {OUTPUTS}"]

    def stopped(result) -> None:
        # called while the interrupt or refused row goes on: a failure to write (--out refused,
        # a full disk) raised here would replace it, and its exit code (130, 143) with 2
        try:
            lines = written(result)
        except (NnidInputError, OSError) as exc:
            failed = exc if isinstance(exc, NnidInputError) else _unwritable(out_dir, exc)
            say(f"error: {failed}")
            return
        for line in lines:
            say(line)

    try:
        result = follow_csv(
            monitor, data, window_s, say, idle_s=IDLE_S if idle_s is None else idle_s,
            stopped=stopped, notes=notes,
        )  # fmt: skip
    except NnidInputError as exc:
        if exc.field == "idle_s" and exc.source is None:  # follow_csv's check: the option's
            raise NnidInputError(exc.message, field="--idle-s") from None
        raise exc.with_source(data) from None
    return written(result)


def detect_run(
    model_dir: Path,
    data: str,
    out_dir: Path,
    columns: str | None = None,
    window: float | None = None,
    progress: Progress | None = None,
    time_unit: str | None = None,
) -> Outcome:
    """``nnid detect`` on a whole log: ``alarms.csv``, ``detect.json`` and the report;
    ``time_unit`` declares the unit of its ``t`` (``--time-unit``)."""
    from nnid.datasets.gaps import fill_slow, mask_gaps, say_unread
    from nnid.datasets.readers import load_log, mapped_source
    from nnid.fault.detect import detect
    from nnid.fault.monitor import CLOCK_SPREAD, GAP_INTERVALS, UNREAD_BY, monitor_motion
    from nnid.reports.detect_report import OUTPUTS, write_detect_outputs

    _checked_window(window)
    check_detect_inputs(model_dir, data, out_dir)
    monitor, window_s = _monitor(model_dir, window)
    lines: list[str] = []
    try:
        log, report = load_log(data, columns, time_unit, "--time-unit")
        # a gap in the motion data cuts the run into segments, and the monitor restarts on
        # each (its EWMA, CUSUM and alarm from zero)
        # (an attitude logged slower than the clock is filled from the gyro first), in the
        # columns the residual reads only: a 1-Hz GPS x, y masked cut every run to nothing
        log = fill_slow(log, report)
        read = monitor_motion(log.columns)
        held = "an empty cell holds its run's last sample before (else its first after)"
        say_unread(log, read, report, UNREAD_BY, "the monitor, which reads", held)
        log = mask_gaps([log], read, report)[0]
        lines += lost_rows(report)
        runs = log["experiment"].to_numpy() if "experiment" in log else None
        missing = monitor.missing_samples(log["t"].to_numpy(), runs)
        if missing:
            lines.append(
                f"missing samples: {missing} intervals longer than {GAP_INTERVALS:g} x the "
                f"calibrated {monitor.interval:.4g} s got no residual (the monitor's statistics "
                "carry across them)"
            )
        spread = monitor.clock_spread(log["t"].to_numpy(), runs)
        if spread > CLOCK_SPREAD:
            lines.append(
                f"note: the sample intervals wander by {100 * spread:.0f} % of the calibrated "
                f"{monitor.interval:.4g} s (10th to 90th percentile): the residual's noise "
                "changes with them, and the false-alarm rate holds on a uniform clock only "
                "(resample the log to a uniform grid)"
            )
        (progress or silent)(0, None, "running the monitor")
        result = detect(monitor, log, window_s, report)
        # a velocity the log lacks, derived from its pose: the residual reads it, and its noise
        # is not that of the logged velocity the monitor was calibrated on (it went unsaid)
        lines += [f"{s.step}: {s.detail}" for s in report.steps if s.step == "derive velocities"]
    except NnidInputError as exc:
        raise exc.with_source(mapped_source(data, columns)) from None
    with staged(out_dir) as stage:
        lines += write_detect_outputs(monitor, result, stage, source=data, notes=lines)
    lines.append(f"wrote {out_dir}/: {OUTPUTS}")
    alarms = result.alarms
    headline: dict[str, Any] = {
        "alarms": len(alarms),
        "first_alarm_t": alarms[0]["t"] if alarms else None,
        "alarm_kinds": "; ".join(dict.fromkeys(a["kind"] for a in alarms)) or None,
        "effects": "; ".join(dict.fromkeys(a["effect"] for a in alarms if a.get("effect"))) or None,
        "samples": result.samples,
    }
    return Outcome(lines, [], headline)
