"""The ``nnid batch`` manifest and the tasks it expands into (ARCHITECTURE.md, "The batch
manifest").

A manifest is TOML, paths relative to its own folder::

    command = "loop"                 # train | loop | detect | compare
    data = ["dives/*.csv"]           # paths or globs (sorted), each one task's log
    vehicle = "minirov.toml"         # a preset or a path, or a list of them
    config = "loop.toml"             # optional where the command has defaults; or a list
    pair = "product"                 # product (every log x vehicle x config) or zip
    time_unit = "s"                  # optional: the unit of every log's t (--time-unit)

A task is one run of the command on one log with one vehicle, config (and, for ``detect``, one
detection model). Its id is stable: the log's stem and a hash of the *contents* of every input
(log, vehicle file, config, reader config, detection model, and the files a config names:
:func:`named_inputs`), the command, its options and nnid's version, so editing any of them
re-runs the task.
"""

from __future__ import annotations

import glob
import hashlib
import itertools
import json
import re
import warnings
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

from pydantic import Field, ValidationInfo, field_validator

from nnid.errors import NnidInputError
from nnid.validation import (
    ALPHA_MAX,
    ALPHA_MIN,
    MIN_WINDOW_S,
    StrictModel,
    read_toml,
    refuse_other_file,
    resolve,
    validated,
)

COMMANDS = ("train", "loop", "detect", "compare")


class Options(StrictModel):
    """A manifest's ``options``: the CLI options of ``nnid loop`` and ``nnid detect``, with
    the bounds the CLI puts on them."""

    max_effects: int | None = Field(None, ge=0)
    alpha: float | None = Field(None, ge=ALPHA_MIN, le=ALPHA_MAX)
    dofs: str | list[str] | None = None
    validation: str | list[str] | None = None
    exclude: str | list[str] | None = None
    window: float | None = Field(None, ge=MIN_WINDOW_S)

    @field_validator("dofs", "validation", "exclude")
    @classmethod
    def _names(cls, value: str | list[str] | None, info: ValidationInfo):
        """The CLI's own checks of these names (a DOF that exists, no name empty or twice),
        said against the manifest before any task runs, not inside every task."""
        from nnid.runs import dofs_option, names

        if value is None:
            return value
        text = value if isinstance(value, str) else ",".join(value)
        try:
            dofs_option(text) if info.field_name == "dofs" else names(text)
        except NnidInputError as err:
            raise ValueError(err.message) from None
        return value


#: the options each command takes (train and compare take theirs from the config)
TAKES = {
    "train": (),
    "compare": (),
    "loop": ("max_effects", "alpha", "dofs", "validation", "exclude"),
    "detect": ("window",),
}

#: the input keys (besides ``data`` and ``columns``) each command reads: a key it does not
#: read would still multiply its tasks and their ids (a detector run once per vehicle file
#: it never loads)
READS = {
    "train": ("vehicle", "config"),
    "compare": ("vehicle", "config"),
    "loop": ("vehicle", "config"),
    "detect": ("model",),
}


class Manifest(StrictModel):
    """The validated manifest (paths as written; :func:`expand` resolves them)."""

    command: Literal[COMMANDS]  # type: ignore[valid-type]
    data: list[str] = Field(min_length=1)
    vehicle: list[str] = Field(default_factory=list)
    config: list[str] = Field(default_factory=list)
    model: list[str] = Field(default_factory=list)  # detect: folders of detection models
    columns: str | None = None  # one reader config for every log
    # the unit of every log's t, as each command's --time-unit (a reader config declares its
    # sources' units itself)
    time_unit: str | None = None
    pair: Literal["product", "zip"] = "product"
    options: Options = Field(default_factory=Options)  # loop: dofs, alpha...; detect: window

    @field_validator("data", "vehicle", "config", "model", mode="before")
    @classmethod
    def _listed(cls, value: Any) -> Any:
        return [value] if isinstance(value, str) else value

    @field_validator("vehicle", "config", "model")
    @classmethod
    def _read_by_command(cls, value: list[str], info: ValidationInfo) -> list[str]:
        command = info.data.get("command")
        if value and command is not None and info.field_name not in READS[command]:
            reads = ", ".join(("data", *READS[command], "columns"))
            raise ValueError(
                f"'{command}' tasks do not read a {info.field_name}: each would run once per "
                f"{info.field_name} all the same; the inputs they read: {reads}"
            )
        return value

    @field_validator("time_unit")
    @classmethod
    def _time_unit(cls, unit: str | None, info: ValidationInfo) -> str | None:
        from nnid.datasets.log import checked_time_unit

        if unit is None:
            return unit
        try:
            checked_time_unit(unit)
        except NnidInputError as err:
            raise ValueError(err.message) from None
        if info.data.get("columns"):  # refused in every task at run time, else
            raise ValueError(
                "declares the unit of logs in nnid's columns; the reader config in 'columns' "
                "declares each source's unit itself (its time_unit or time_scale)"
            )
        return unit

    @field_validator("options")
    @classmethod
    def _options_apply(cls, value: Options, info: ValidationInfo) -> Options:
        # an option the command does not take would be dropped (loop's window) or fail
        # inside every task without naming the manifest
        command = info.data.get("command")
        if command is None:  # the command itself was refused: that error is the one to give
            return value
        stray = sorted(set(value.model_fields_set) - set(TAKES[command]))
        if stray:
            takes = ", ".join(TAKES[command]) or "none (their config sets them)"
            raise ValueError(
                f"'{stray[0]}' does not apply to '{command}' tasks; the options they take: {takes}"
            )
        return value


@dataclass(frozen=True)
class Task:
    """One run: ``command`` on the log ``data`` (absolute paths; ``vehicle`` may be a preset
    name). ``overrides`` are dotted config paths set on top of the config (a sweep's trial)."""

    command: str
    data: str
    vehicle: str | None = None
    config: str | None = None
    model: str | None = None
    columns: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)
    time_unit: str | None = None  # the unit of the log's t (the manifest's time_unit)
    id: str = ""

    def inputs(self) -> dict[str, Any]:
        """The task's inputs as a summary row's columns."""
        skip = ("options", "overrides", "id") + (() if self.time_unit else ("time_unit",))
        row = {k: v for k, v in asdict(self).items() if k not in skip}
        row["options"] = json.dumps(self.options, sort_keys=True) if self.options else None
        row["overrides"] = json.dumps(self.overrides, sort_keys=True) if self.overrides else None
        return row


def _digest(path: str | None, h, key: str) -> None:
    """Feed ``path``'s contents (a file, or every file of a folder in sorted order) to ``h``;
    a name that is no path (a preset) is fed as its name. A file that cannot be read is
    refused against ``key``, the input that names it."""
    if not path:
        h.update(b"\0none")
        return
    p = Path(path)
    q = p
    try:
        if not p.exists():
            h.update(b"\0name:" + path.encode())
            return
        files = sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
        for q in files:
            h.update(b"\0file:" + (str(q.relative_to(p)) if p.is_dir() else "").encode())
            with open(q, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
    except OSError as exc:  # no read permission, a file gone while read: before any task runs
        raise NnidInputError(f"'{q}' cannot be read ({exc.strerror or exc})", field=key) from None


#: the keys whose string value names another input (a config's vehicle and data files, a
#: reader config's vehicle and root): what they name joins the task's hash
NAMING_KEYS = frozenset({"vehicle", "log", "columns", "simulate", "campaign", "root"})
#: the keys naming the data a task's own log replaces (read only when the task gives none)
DATA_KEYS = frozenset({"log", "simulate", "campaign", "root"})


def named_inputs(
    path: str | None, skip: frozenset[str] = frozenset(), seen: set[Path] | None = None
) -> list[Path]:
    """The files and folders a TOML input names under :data:`NAMING_KEYS` but ``skip``
    (relative to its folder, as the run reads them), and those they name in turn; a config
    that names its data (``data.log``, ``simulate``, ``campaign``) reads no reader config's
    ``root``, which is then skipped. A file that does not parse names nothing here: the run
    itself says what is wrong with it."""
    seen = set() if seen is None else seen
    p = Path(path) if path else None
    if p is None or p.suffix != ".toml" or not p.is_file() or p.resolve() in seen:
        return []
    seen.add(p.resolve())
    try:
        doc = read_toml(p)
    except NnidInputError:
        return []
    data = doc.get("data")
    if isinstance(data, dict) and any(data.get(k) for k in ("log", "simulate", "campaign")):
        skip = skip | {"root"}
    found: list[Path] = []

    def walk(node: dict) -> None:
        for key, value in node.items():
            if isinstance(value, dict):
                walk(value)
            elif key in NAMING_KEYS - skip and isinstance(value, str):
                target = resolve(p.parent, value)
                if target.exists():
                    found.append(target)
                    found.extend(named_inputs(str(target), skip, seen))

    walk(doc)
    return found


def task_id(task: Task) -> str:
    """``<log stem>-<12 hex>``: the hash of the inputs' contents, the settings and nnid's
    version (see the module docstring)."""
    from nnid import __version__

    h = hashlib.sha256()
    settings = {
        "nnid": __version__,
        "command": task.command,
        "options": task.options,
        "overrides": task.overrides,
    }
    if task.time_unit:  # only when declared: the ids of the tasks without one stay as they were
        settings["time_unit"] = task.time_unit
    h.update(json.dumps(settings, sort_keys=True, default=str).encode())
    inputs = {"data": task.data, "vehicle": task.vehicle, "config": task.config,
              "model": task.model, "columns": task.columns}  # fmt: skip
    for key, path in inputs.items():
        _digest(path, h, key)
    # what the config names (its log, vehicle, simulation): editing one re-runs the task too;
    # a task's own log replaces the config's data, which is then neither read nor hashed
    skip = DATA_KEYS if task.data else frozenset()
    for key in ("config", "vehicle", "columns"):
        for named in named_inputs(inputs[key], skip):
            _digest(str(named), h, key)
    named = task.data or task.config or "task"  # a sweep's trial may use its config's data
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(named).stem)[:40] or "task"
    return f"{stem}-{h.hexdigest()[:12]}"


def with_id(task: Task) -> Task:
    """The task with its id set."""
    return Task(**{**asdict(task), "id": task_id(task)})


def _paths(patterns: list[str], base: Path, key: str, source: str) -> list[str]:
    """Each pattern resolved against ``base``: a glob's matches (sorted), or the one path,
    which must exist."""
    out: list[str] = []
    for pattern in patterns:
        if not pattern.strip():  # it would resolve to the manifest's own folder
            raise NnidInputError("is empty: name a file or a pattern", source=source, field=key)
        full = pattern if Path(pattern).is_absolute() else str(base / pattern)
        if glob.has_magic(pattern):
            found = sorted(glob.glob(full, recursive=True))
            if not found:
                raise NnidInputError(f"'{pattern}' matches no file", source=source, field=key)
            ours = [f for f in found if _written_by_nnid(Path(f))]
            if ours:  # a "**" reaches into earlier runs' outputs: their tables are no logs
                warnings.warn(
                    f"{source}: {key} '{pattern}' also matches {len(ours)} table(s) nnid wrote "
                    f"(e.g. {ours[0]}): left out",
                    stacklevel=3,
                )
                found = [f for f in found if f not in ours]
                if not found:
                    raise NnidInputError(
                        f"'{pattern}' matches only tables nnid wrote",
                        source=source,
                        field=key,
                    )
            out += [str(Path(f).resolve()) for f in found]
        elif Path(full).exists():
            out.append(str(Path(full).resolve()))
        else:
            raise NnidInputError(f"'{pattern}': no such file or folder", source=source, field=key)
    folders = [p for p in out if key in FILE_KEYS and Path(p).is_dir()]
    if folders:  # else every task fails on it at run time (exit 1), after the check passed
        raise NnidInputError(
            f"'{folders[0]}' is a folder; each {key} is a TOML file", source=source, field=key
        )
    return out


#: the keys whose every item is a file (a log may be a folder of bags, a model is a folder)
FILE_KEYS = ("config", "vehicle", "columns")


#: the tables nnid writes (a batch's or sweep's summary and settings, detect's alarms), and
#: the records beside them that mark a folder as a run's
RUN_TABLES = ("summary.csv", "summary.parquet", "settings.csv", "alarms.csv")
RUN_FILES = ("summary.json", "metrics.json", "comparison.json", "loop.json", "detect.json")


def _written_by_nnid(path: Path) -> bool:
    """Whether ``path`` is a table nnid wrote: one of :data:`RUN_TABLES` beside a
    :data:`RUN_FILES` record. Any other file, in any folder, is the user's."""
    path = path.resolve()
    return path.name in RUN_TABLES and any((path.parent / n).is_file() for n in RUN_FILES)


def _vehicles(names: list[str], base: Path, source: str) -> list[str]:
    from nnid.vehicle import PRESETS

    return [n if n in PRESETS else _paths([n], base, "vehicle", source)[0] for n in names]


def load_manifest(path: str | Path) -> Manifest:
    """Read and validate a manifest; one NnidInputError naming the file and the key."""
    data = read_toml(path)
    refuse_other_file(data, "manifest", "a batch manifest", str(path))
    return validated(Manifest, data, str(path))


def expand(path: str | Path) -> list[Task]:
    """The manifest's tasks in a stable order, with their ids; every path is checked before
    any work (a missing file or a glob that matches nothing is refused, naming the key).
    Identical tasks (same id) are kept once; one kept once though its paths differ (a log of
    the same name and contents in another folder) is said, naming both."""
    source = str(path)
    spec = load_manifest(path)
    base = Path(path).resolve().parent
    logs = _paths(spec.data, base, "data", source)
    vehicles = _vehicles(spec.vehicle, base, source)
    configs = _paths(spec.config, base, "config", source)
    models = _paths(spec.model, base, "model", source)
    columns = _paths([spec.columns], base, "columns", source)[0] if spec.columns else None
    needs = {"train": ("config",), "compare": ("config",), "detect": ("model",), "loop": ()}
    for key in needs[spec.command]:
        if not {"config": configs, "model": models}[key]:
            raise NnidInputError(f"'{spec.command}' tasks need a {key}", source=source, field=key)
    if spec.command == "loop" and not (vehicles or configs):
        raise NnidInputError("'loop' tasks need a vehicle (or a config that names one)",
                             source=source, field="vehicle")  # fmt: skip
    _of_kind(configs, "config", spec.command, source)
    _of_kind([v for v in vehicles if Path(v).is_file()], "vehicle", spec.command, source)
    axes = [logs, vehicles or [None], configs or [None], models or [None]]
    if spec.pair == "zip":
        longest = max(len(a) for a in axes)
        uneven = [
            k
            for k, a in zip(("data", "vehicle", "config", "model"), axes, strict=True)
            if len(a) not in (1, longest)
        ]
        if uneven:
            raise NnidInputError(
                f"pair = 'zip' needs lists of one length (or of one item); {uneven[0]} has "
                f"{len(axes[['data', 'vehicle', 'config', 'model'].index(uneven[0])])}, "
                f"another {longest}",
                source=source,
                field=uneven[0],
            )
        combos = zip(*(a * longest if len(a) == 1 else a for a in axes), strict=True)
    else:
        combos = itertools.product(*axes)
    tasks: dict[str, Task] = {}
    for log, veh, cfg, model in combos:
        options = spec.options.model_dump(exclude_unset=True)
        try:
            task = with_id(
                Task(spec.command, log, veh, cfg, model, columns, options, time_unit=spec.time_unit)
            )
        except NnidInputError as err:  # an input that cannot be read, named against its key
            raise err.with_source(source) from None
        first = tasks.setdefault(task.id, task)
        if first != task:  # other paths, one id: a copy of the same name and contents
            _say_merged(first, task, source)
    return list(tasks.values())


def _of_kind(paths: list[str], key: str, command: str, source: str) -> None:
    """Each file of ``key`` (``config``, ``vehicle``) of the kind it names: one of nnid's other
    files, or a config of another command, failed in every task at run time (exit 1) after
    the manifest's check passed. A file that does not parse is left to its task to say."""
    what = f"a '{command}' config" if key == "config" else "a vehicle file"
    for path in paths:
        try:
            data = read_toml(path)
        except NnidInputError:
            continue
        try:
            refuse_other_file(data, key, what, path)
        except NnidInputError as err:
            raise NnidInputError(f"'{path}': {err.message}", source=source, field=key) from None
        kind = data.get("kind")
        if key == "config" and isinstance(kind, str) and kind != command:
            raise NnidInputError(
                f"'{path}' has kind = '{kind}': '{command}' tasks need {what}",
                source=source,
                field=key,
            )


def _say_merged(first: Task, task: Task, source: str) -> None:
    """Warn that ``task`` is run as ``first``: its id is the same (the same log name, the
    same contents of every input) while its paths differ, so it is no task of its own and
    its paths would be named nowhere."""
    differ = [
        f"{key} {getattr(task, key)} (as {getattr(first, key)})"
        for key in ("data", "vehicle", "config", "model")
        if getattr(task, key) != getattr(first, key)
    ]
    warnings.warn(
        f"{source}: {'; '.join(differ)}: inputs of the same contents (and a log of the same "
        f"name) are the same task {first.id}, run once; rename or change one to run both",
        stacklevel=3,
    )
