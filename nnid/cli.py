"""The ``nnid`` command line: parse a config, call the library, write files.

Bad input ends with one line on stderr and exit code 2; nothing else here does numerics.
"""

from __future__ import annotations

import functools
import os
import signal
import time
import warnings
from contextlib import contextmanager
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress

from nnid.errors import NnidInputError
from nnid.runs import check_out as _check_out
from nnid.runs import staged as _staged
from nnid.validation import MAX_SEED
from nnid.warning_messages import warning_messages

app = typer.Typer(
    name="nnid",
    help="Identify underwater-vehicle dynamics from logged data.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",
)
# plain text unless a print asks for markup: paths, experiment names and messages go out as
# they are ("runs[lm]/" would lose "[lm]" as a style tag), and never broken at the console's
# width (80 columns in a pipe), so a path a person copies stays whole
err = Console(stderr=True, soft_wrap=True, markup=False)
out = Console(soft_wrap=True, markup=False)


def _show_version(value: bool) -> None:
    if value:
        from nnid import __version__

        out.print(f"nnid {__version__}", highlight=False)
        raise typer.Exit()


@app.callback()
def main_options(
    version: bool = typer.Option(
        False,
        "--version",
        callback=_show_version,
        is_eager=True,
        help="Print nnid's version and exit.",
    ),
) -> None:
    """Identify underwater-vehicle dynamics from logged data."""


def _input_errors(fn):
    """Turn bad input into one clear line and exit code 2 (no traceback)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        # the application, not the library, decides how warnings reach a person: one plain
        # line each, once, after the command's own output
        _SAID.clear()
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                return fn(*args, **kwargs)
            except NnidInputError as exc:
                err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, markup=True)
                raise typer.Exit(2) from None
            finally:
                for message in warning_messages(caught):
                    if message not in _SAID:  # a run's own warnings were said with its lines
                        err.print(f"warning: {message}", highlight=False)

    return wrapper


@app.command()
@_input_errors
def simulate(
    config: Path = typer.Argument(..., help="TOML simulate config (see configs/)."),
    out_path: Path = typer.Option(..., "--out", help="Output log, .csv or .parquet."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; overrides the config's."
    ),
    seed: int | None = typer.Option(
        None,
        "--seed",
        min=0,
        max=MAX_SEED,
        help="Overrides the config's seed: the sensor noise's (experiment i draws from seed + "
        "i). A prbs or aprbs signal draws from its own 'seed' key, which --seed leaves as it "
        "is.",
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file."),
) -> None:
    """Make a synthetic log from a vehicle, an excitation and optional injected effects."""
    from nnid.config import SimulateConfig, load_config
    from nnid.datasets.log import validate_log, write_log
    from nnid.datasets.simulator import simulate_config
    from nnid.pipeline import plant_for

    cfg = load_config(config, SimulateConfig)
    if seed is not None:
        cfg.seed = seed
    # the config's vehicle file is relative to the config's folder, as for train and loop
    veh = plant_for(vehicle or cfg.vehicle, config, "--vehicle" if vehicle else "vehicle")
    if out_path.suffix not in (".csv", ".parquet"):
        raise NnidInputError("output must end in .csv or .parquet", source=str(out_path))
    if out_path.is_dir():
        raise NnidInputError("is a folder; give a file name", source=str(out_path), field="--out")
    if out_path.exists() and not force:  # a measured log of that name would be lost
        raise NnidInputError(
            "exists: give --force to replace it, or another name", source=str(out_path),
            field="--out",
        )  # fmt: skip
    _check_out(out_path.parent)
    try:
        with _bar("simulating") as progress:
            log = simulate_config(cfg, veh, progress=progress)
    except NnidInputError as exc:
        raise exc.with_source(str(config)) from None
    try:
        validate_log(log, source="the log it simulates")
    except NnidInputError as exc:  # made by the config: the --out file is not yet written
        raise NnidInputError(f"the log contract refuses {exc}", source=str(config)) from None
    write_log(log, out_path)
    n_exp = log["experiment"].nunique() if "experiment" in log else 1
    out.print(
        f"wrote {out_path}: {len(log)} samples, {n_exp} experiment{'s' * (n_exp != 1)}, "
        f"{log['t'].groupby(log.get('experiment', 0)).max().sum():.1f} s of '{veh.name}'"
    )


def _check_time_unit(unit: str | None) -> None:
    """A ``--time-unit`` nnid knows, refused before any work otherwise."""
    if unit is not None:
        from nnid.datasets.log import checked_time_unit

        checked_time_unit(unit, "--time-unit")


#: ``--time-unit`` on every command that reads a log file
TIME_UNIT_HELP = (
    "Unit of the log's t: s, ms, us or ns, converted to seconds (said in the cleaning report). "
    "Default: seconds, and a clock that steps as another unit does is refused (a 1-Hz log "
    "stepping by whole seconds reads as integer milliseconds); replaces the config's "
    "data.time_unit."
)


@app.command()
@_input_errors
def inspect(
    log_path: Path = typer.Argument(..., metavar="LOG", help="Log file or data folder."),
    columns: Path | None = typer.Option(
        None, "--columns", help="Reader config (column map TOML) for logs not in nnid's format."
    ),
    out_dir: Path | None = typer.Option(
        None, "--out", help="Also write summary.json and the cleaning report here."
    ),
    time_unit: str | None = typer.Option(None, "--time-unit", help=TIME_UNIT_HELP),
) -> None:
    """Show what a log holds: columns, rate, duration, experiments, gaps, derivable signals and
    the excitation of each DOF.

    The duration is the time sampled, the time in gaps beside it; velocities a log lacks are
    derived from its pose as train derives them (with the default [data] window), and each
    command channel's excitation is shown as a command's, not a force's."""
    from rich.table import Table

    from nnid.config import VehicleData
    from nnid.datasets.gaps import SlowChannel, say_ends
    from nnid.datasets.inspect import summarize
    from nnid.datasets.log import run_label
    from nnid.datasets.readers import load_log
    from nnid.physics.dofs import DOFS
    from nnid.serialization import write_json

    if out_dir is not None:
        _check_out(out_dir)
    _check_time_unit(time_unit)
    log, report = load_log(log_path, columns, time_unit, "--time-unit")
    # the window train uses unless a config's [data] sets another
    window, order = (VehicleData.model_fields[k].default for k in ("savgol_window", "savgol_order"))
    info = summarize(log, window, order)
    cols = info["columns"]
    pieces = sum(e["piece_of"] is not None for e in info["experiments"])
    low, high = (f(e["rate_hz"] for e in info["experiments"]) for f in (min, max))
    gap_s = info["gap_s"]
    bursty = [e for e in info["experiments"] if e["bursts"]]
    # a run in bursts counts at its rate over the run, not its median step's (~100 kHz)
    in_bursts = (
        ""
        if not bursty
        else " (stamps in bursts: the rate over the run)"
        if len(bursty) == len(info["experiments"])
        else f" ({len(bursty)} run{'s' * (len(bursty) != 1)} in bursts: at the rate over the run)"
    )
    out.print(
        f"[bold]{escape(str(log_path))}[/]: {info['samples']} samples, "
        f"{info['duration_s']:.1f} s" + (f" of data (and {gap_s:.3g} s in gaps)" if gap_s else "")
        + f", {info['runs']} experiment{'s' * (info['runs'] != 1)}"
        + (f" ({pieces} pieces: runs cut at gaps)" if pieces else "")
        + f", about {info['rate_hz']:.3g} Hz"
        + in_bursts
        + (f" (experiments from {low:.3g} to {high:.3g} Hz)" if high > 1.1 * low else ""),
        markup=True,
    )  # fmt: skip
    for group in ("pose", "velocity", "acceleration", "inputs", "other"):
        out.print(f"  {group:13s} {', '.join(cols[group]) or '-'}")
    out.print(f"  derivable     {', '.join(info['derivable']) or '-'}")
    for e in bursty:
        # its median step is one inside a burst: no rate of ~100 kHz, nor each burst's end a gap
        out.print(
            f"  clock         {run_label(e['name'])}: {e['bursts']}; its gaps are not counted "
            "and the fits refuse it (they step sample by sample at one rate): resample it "
            "onto a uniform grid first",
            highlight=False,
        )
    gaps = info["gaps"]
    out.print(
        f"  gaps          {len(gaps)}"
        + (f" (longest {max(g['length_s'] for g in gaps):.3g} s)" if gaps else "")
        + (f" (not counted in the {len(bursty)} run{'s' * (len(bursty) != 1)} in bursts)"
           if bursty else "")
    )  # fmt: skip
    for ch in info["slow"]:
        slow = SlowChannel(**{k: v for k, v in ch.items() if k not in ("filled", "ends")})
        # a rate not measured: its empty cells may be that rate, said here and not as gaps
        unmeasured = ", nor its empty cells counted as gaps (they may be its rate)"
        how = (
            "filled between its samples with the gyro where a fit needs it on every row"
            if ch["filled"]
            else f"not filled{unmeasured * (ch['rate_hz'] is None)}: bridged from the pose "
            "where it allows, else a fit that reads it takes its runs out (refused where that "
            "leaves nothing)"
        )
        ends = f"; {say_ends(ch['ends'])}" if ch["ends"] else ""
        out.print(f"  slow          {slow.describe()} ({how}){ends}", highlight=False)
    missing = info["missing"]
    if missing["count"]:
        cols = sorted({c for g in missing["gaps"] for c in g["columns"]}, key=list(log).index)
        out.print(
            f"  missing       {missing['count']} gap{'s' * (missing['count'] != 1)} in "
            f"{', '.join(cols)} "
            f"({missing['samples']} samples, {missing['seconds']:.3g} s missing, longest "
            f"{missing['longest_s']:.3g} s): bridged from the pose or masked where used"
        )
    excitation, excited = info["excitation"], info["excited"]
    posed = info["velocity_from_pose"]
    if posed.get("columns"):
        approx = "; w approximate, from the depth rate" if posed["approximate"] else ""
        out.print(
            f"  from pose     {', '.join(posed['columns'])} (as train derives them: "
            f"{posed['window_s']:g} s window, order {posed['order']}{approx})"
        )
    elif posed.get("error"):
        out.print(f"  from pose     none: {posed['error']}", highlight=False)
    moving = [d for d in DOFS if "velocity_std" in excitation.get(d, {})]
    still = [d for d in moving if d not in excited]
    absent = [d for d in DOFS if d not in moving]
    if moving:
        out.print(
            f"  excited       {', '.join(excited) or '-'}"
            + (f"; not excited: {', '.join(still)} (velocity std under 10 % of the largest "
               "linear / angular one)" if still else "")
            + (f"; no velocity: {', '.join(absent)}" if absent else "")
        )  # fmt: skip
    else:
        out.print("  excited       - (no velocity logged or derivable from the pose)")
    forces = any("force_std" in e for e in excitation.values())
    table = Table(title="excitation per DOF")
    heads = ["DOF", "velocity std", "excited"] + (["force std", "force active"] if forces else [])
    for head in heads:
        table.add_column(head)
    for dof, e in excitation.items():
        std = f"{e['velocity_std']:.3g}" if "velocity_std" in e else "-"
        if e.get("velocity_from_pose"):
            std += " (from pose)"
        row = [dof, std, "-" if "velocity_std" not in e else "yes" if dof in excited else "no"]
        if forces:
            row += [f"{e[k]:.3g}" if k in e else "-" for k in ("force_std", "force_active_share")]
        table.add_row(*row)
    if excitation:
        out.print(table)
    if info["commands"]:
        # no vehicle file here: a command is not a force until its thrusters map it
        table = Table(title="commands per channel (not forces: no vehicle file maps them)")
        for head in ("channel", "std", "active"):
            table.add_column(head)
        for name, c in info["commands"].items():
            table.add_row(name, f"{c['std']:.3g}", f"{c['active_share']:.3g}")
        out.print(table)
    for line in report.summary():
        out.print(f"  cleaning: {line}", highlight=False)
    if out_dir is not None:
        with _staged(out_dir) as stage:
            write_json(stage / "summary.json", info)
            report.write(stage)


#: seconds between progress lines where no live bar can be drawn
HEARTBEAT_S = 30.0


@contextmanager
def _bar(description: str):
    """A live progress bar on stderr; yields the callback ``(done, total, message)`` that
    trainers, models and the loop call. Off a terminal (a script, a CI log, ``nohup``) a live
    bar draws nothing, and a six-minute compare looked hung: there, one plain line at most
    every :data:`HEARTBEAT_S` seconds, the first after that long."""
    if not err.is_terminal:
        start = time.monotonic()
        last = [start]

        def line(done: int, total: int | None, message: str, **scores: float) -> None:
            now = time.monotonic()
            if now - last[0] >= HEARTBEAT_S:
                last[0] = now
                count = f" ({done}/{total})" if total else ""
                err.print(f"[{now - start:.0f} s] {message or description}{count}", highlight=False)

        yield line
        return
    with Progress(console=err, transient=True) as bar:
        task = bar.add_task(description, total=None)

        def update(done: int, total: int | None, message: str, **scores: float) -> None:
            bar.update(task, completed=done, total=total, description=message or description)

        yield update


#: the warnings a command has said already (each is said once)
_SAID: set[str] = set()


def _print(outcome) -> None:
    """A run's warnings on stderr, its sentences on stdout."""
    for warning in outcome.warnings:
        if warning not in _SAID:
            _SAID.add(warning)
            err.print(f"warning: {warning}", highlight=False)
    for line in outcome.lines:
        _say(line)


def _say(line: str) -> None:
    """One sentence for a person on stdout (plain text, no highlighting)."""
    out.print(line, highlight=False)


@app.command()
@_input_errors
def train(
    config: Path = typer.Argument(..., help="TOML train config (see configs/)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder for model, metrics, report."),
    data: str | None = typer.Option(None, "--data", help="Log to fit; replaces the config's."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; replaces the config's."
    ),
    columns: str | None = typer.Option(
        None, "--columns", help="Reader config for a log not in nnid's format."
    ),
    time_unit: str | None = typer.Option(None, "--time-unit", help=TIME_UNIT_HELP),
) -> None:
    """Fit one model on the training split and score it on held-out data: writes the model
    (model.json, and tensors.pt for networks; load it with nnid.load_model), metrics.json,
    report.md, report.html and the cleaning report to --out."""
    from nnid.config import TrainConfig, load_config
    from nnid.runs import train_run

    _check_time_unit(time_unit)
    cfg = load_config(config, TrainConfig)
    _check_out(out_dir)
    with _bar(f"training a {cfg.model.kind} model") as progress:
        outcome = train_run(
            cfg, config, out_dir, data, vehicle, columns, progress=progress, time_unit=time_unit
        )
    _print(outcome)


@app.command()
@_input_errors
def compare(
    config: Path = typer.Argument(..., help="TOML compare config (see configs/)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder for the report."),
    data: str | None = typer.Option(None, "--data", help="Log to use; replaces the config's."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; replaces the config's."
    ),
    columns: str | None = typer.Option(
        None, "--columns", help="Reader config for a log not in nnid's format."
    ),
    time_unit: str | None = typer.Option(None, "--time-unit", help=TIME_UNIT_HELP),
) -> None:
    """Fit the config's [[models]] (any kinds) on one split and compare them on the same
    held-out experiments: writes comparison.json, report.html and report.md to --out."""
    from nnid.config import CompareConfig, load_config
    from nnid.runs import compare_run

    _check_time_unit(time_unit)
    cfg = load_config(config, CompareConfig)
    _check_out(out_dir)
    with _bar("comparing models") as progress:
        outcome = compare_run(
            cfg, config, out_dir, data, vehicle, columns, progress=progress, time_unit=time_unit
        )
    _print(outcome)


@app.command()
@_input_errors
def loop(
    config: Path | None = typer.Argument(
        None, help="Optional TOML loop config (data, vehicle, DOFs, held-out runs, settings)."
    ),
    data: str | None = typer.Option(None, "--data", help="The log; overrides the config's."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; overrides the config's."
    ),
    out_dir: Path = typer.Option(..., "--out", help="Output folder for loop.json and reports."),
    columns: str | None = typer.Option(
        None, "--columns", help="Reader config for a log not in nnid's format."
    ),
    max_effects: int | None = typer.Option(
        None,
        "--max-effects",
        min=0,
        help="Add at most this many effects; default: the config's max_effects, else 3.",
    ),
    alpha: float | None = typer.Option(
        None,
        "--alpha",
        help="Family-wise significance of the F-test, 1e-12 to 0.5; default: the config's "
        "alpha, else 0.01.",
    ),
    dofs: str | None = typer.Option(
        None, "--dofs", help="DOFs to analyse, comma-separated (e.g. p,q,r); default: all logged."
    ),
    validation: str | None = typer.Option(
        None,
        "--validation",
        help="Experiments held out, comma-separated; default: the config's validation, else "
        "the last 30 % (validation_fraction).",
    ),
    exclude: str | None = typer.Option(
        None, "--exclude", help="Experiments left out (e.g. replays), comma-separated."
    ),
    hybrid: Path | None = typer.Option(
        None,
        "--hybrid",
        help="Folder of a trained hybrid (nnid train configs/hybrid.toml) of this vehicle: "
        "its learned force, named in the effect vocabulary, as a second opinion.",
    ),
    time_unit: str | None = typer.Option(None, "--time-unit", help=TIME_UNIT_HELP),
) -> None:
    """Residual loop: fit the vehicle file to the log, find the effect the residual points to,
    add it, refit, repeat; writes loop.json, report.html and report.md to --out, with the
    held-out errors before and after ("no significant effect" when there is none)."""
    from nnid.config import LoopConfig, load_config
    from nnid.runs import loop_run

    _check_time_unit(time_unit)
    cfg = load_config(config, LoopConfig) if config else LoopConfig()
    _check_out(out_dir)
    with _bar("residual loop") as progress:
        outcome = loop_run(
            cfg, config, out_dir, data, vehicle, columns,
            max_effects=max_effects, alpha=alpha, dofs=dofs, validation=validation,
            exclude=exclude, hybrid=hybrid, progress=progress, time_unit=time_unit,
        )  # fmt: skip
    _print(outcome)


@app.command()
@_input_errors
def detect(
    model_dir: Path = typer.Option(
        ..., "--model", help="Folder of a detection model (nnid train configs/detect_fossen.toml)."
    ),
    data: str = typer.Option(..., "--data", help="The log to watch; '-' reads CSV from stdin."),
    out_dir: Path = typer.Option(
        ..., "--out", help="Output folder: alarms.csv, detect.json, report."
    ),
    columns: str | None = typer.Option(
        None, "--columns", help="Reader config for a log not in nnid's format (not with --follow)."
    ),
    follow: bool = typer.Option(
        False, "--follow", help="Read a growing CSV (or stdin) and print each alarm as it happens."
    ),
    # bounded in nnid.runs, as --alpha: typer's min=0.5 read a NaN as under 0.5, passed inf
    window: float | None = typer.Option(
        None,
        "--window",
        help="Seconds after an alarm used to isolate it, 0.5 or more; default the detection "
        "model's ([detect] window_s when it was trained, 10 s if it saved none).",
    ),
    time_unit: str | None = typer.Option(None, "--time-unit", help=TIME_UNIT_HELP),
    # bounded in nnid.runs, as --window
    idle_s: float | None = typer.Option(
        None,
        "--idle-s",
        help="With --follow: seconds the file may stop growing before its log is taken as "
        "ended (0 or more, default 3); standard input is read until it closes.",
    ),
) -> None:
    """Fault detection: watch a log with a calibrated residual monitor; each alarm says whether a
    thruster lost thrust (which one, its remaining efficiency), an external force appeared, or
    the vehicle changed (the effect, e.g. buoyancy_offset, with its size)."""
    from nnid.runs import detect_run, follow_run

    _check_time_unit(time_unit)
    _check_out(out_dir)
    if follow and columns is not None:  # a stream is read as nnid's CSV, row by row
        raise NnidInputError(
            "--follow reads a CSV in nnid's columns; a reader config applies to a whole log "
            "(drop --follow)",
            field="--columns",
        )
    if follow and time_unit is not None:  # a stream's rows are read as they come, in seconds
        raise NnidInputError(
            "--follow reads a CSV whose t is in seconds, row by row (drop --follow to declare "
            "a whole log's time unit)",
            field="--time-unit",
        )
    if idle_s is not None and not follow:  # a whole log is read at once: it never waits
        raise NnidInputError(
            "applies to --follow only (drop it, or add --follow)", field="--idle-s"
        )
    if follow:
        for line in follow_run(model_dir, data, out_dir, window, _say, idle_s):
            _say(line)
        return
    with _bar("detecting") as progress:
        outcome = detect_run(
            model_dir, data, out_dir, columns, window, progress=progress, time_unit=time_unit
        )
    _print(outcome)


@app.command()
@_input_errors
def vehicle(
    out_path: Path = typer.Option(..., "--out", help="The vehicle file to write (.toml)."),
    preset: str | None = typer.Option(
        None, "--preset", help="Start from a preset (e.g. bluerov2_heavy), with its citations."
    ),
    mass: float | None = typer.Option(None, "--mass", help="Mass in air, kg."),
    size: str | None = typer.Option(
        None, "--size", help="LENGTHxWIDTHxHEIGHT in m, e.g. 0.46x0.58x0.25."
    ),
    layout: str | None = typer.Option(
        None, "--layout", help="Thrusters: heavy8 (BlueROV2 Heavy, the default) or none."
    ),
    name: str | None = typer.Option(None, "--name", help="Vehicle name; default the file's stem."),
) -> None:
    """Write a starter vehicle file for your own ROV: a preset's, or one estimated from its mass,
    size and thruster layout (every estimate marked; the identification refits them)."""
    from nnid.vehicle import vehicle_from_dict, vehicle_name
    from nnid.vehicle_starter import preset_text, starter_text

    if out_path.suffix != ".toml":
        raise NnidInputError(
            "the vehicle file must end in .toml", source=str(out_path), field="--out"
        )
    if out_path.exists():
        raise NnidInputError("exists: choose another name (nothing is overwritten)",
                             source=str(out_path), field="--out")  # fmt: skip
    _check_out(out_path.parent)
    if (preset is None) == (mass is None and size is None):
        raise NnidInputError("give either --preset or --mass and --size", field="--preset")
    if preset is not None:
        given = [o for o, v in (("--name", name), ("--layout", layout)) if v is not None]
        if given:  # the preset's own name and thrusters would be written without a word
            raise NnidInputError(
                f"{' and '.join(given)} apply to a starter file (--mass and --size), not to "
                "a preset, which is written as it is: rename it in the file",
                field=given[0],
            )
        text = preset_text(preset)
    else:
        if mass is None or size is None:
            raise NnidInputError(
                "give both --mass and --size", field="--mass" if mass is None else "--size"
            )
        try:
            dims = tuple(float(x) for x in size.lower().split("x"))
        except ValueError:
            dims = ()
        if len(dims) != 3:
            raise NnidInputError(f"'{size}': expected LENGTHxWIDTHxHEIGHT in m", field="--size")
        if name is not None:  # said against the option, not the file it would be written to
            try:
                vehicle_name(name)
            except ValueError as exc:
                raise NnidInputError(f"{exc} (got {name!r})", field="--name") from None
        text = starter_text(name or out_path.stem, mass, dims, layout or "heavy8")
    import tomllib

    vehicle_from_dict(tomllib.loads(text), source=str(out_path))  # what is written loads back
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(text, encoding="utf-8")  # as nnid reads it, whatever the locale's
    out.print(
        f"wrote {out_path}: edit what it marks ASSUMED or ESTIMATE (docs/vehicle_file.md)",
        highlight=False,
    )


@app.command()
@_input_errors
def batch(
    manifest: Path = typer.Argument(..., help="TOML manifest: command, data, vehicle, config."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder: one folder per task, summary."),
    address: str | None = typer.Option(
        None,
        "--address",
        help="Ray: 'auto' (this machine's cluster), 'local' (a new one here) or an address; "
        "default local processes.",
    ),
    workers: int | None = typer.Option(
        None,
        "--workers",
        min=1,
        help="Local worker processes (or the CPUs of --address local); default one per core.",
    ),
) -> None:
    """Run many train/loop/detect/compare tasks (logs x vehicles x configs) and write one
    summary: summary.parquet, summary.csv, summary.json and report.html. Tasks finished by an
    earlier run into the same --out are not run again; a failed task is a 'failed' row and the
    others go on (exit code 1 when any failed)."""
    from nnid.scale.batch import run_tasks, write_summary
    from nnid.scale.engines import engine_for
    from nnid.scale.manifest import expand

    tasks = expand(manifest)
    _check_out(out_dir)
    engine = engine_for(address, workers)
    with _bar(f"{len(tasks)} {tasks[0].command} tasks") as progress:
        result = run_tasks(tasks, out_dir, engine, progress=progress)
    write_summary(result, out_dir)
    failed = result.failed
    out.print(
        f"{len(tasks)} tasks on the {result.engine} engine: {len(tasks) - len(failed)} ok "
        f"({result.reused} finished earlier), {len(failed)} failed, {result.seconds:.1f} s; "
        f"wrote {out_dir}/summary.csv, summary.parquet, summary.json, report.html",
        highlight=False,
    )
    for row in failed:
        err.print(f"failed: {row['id']} ({row['data']}): {row['error']}", highlight=False)
    if failed:
        raise typer.Exit(1)


@app.command()
@_input_errors
def sweep(
    config: Path = typer.Argument(..., help="TOML train config with a [sweep] table."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder: trials, settings, best.toml."),
    data: str | None = typer.Option(None, "--data", help="Log to fit; replaces the config's."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; replaces the config's."
    ),
    columns: str | None = typer.Option(
        None, "--columns", help="Reader config for a log not in nnid's format."
    ),
    address: str | None = typer.Option(
        None,
        "--address",
        help="Ray: 'auto' (this machine's cluster), 'local' (a new one here) or an address; "
        "default local processes.",
    ),
    workers: int | None = typer.Option(
        None,
        "--workers",
        min=1,
        help="Local worker processes (or the CPUs of --address local); default one per core.",
    ),
) -> None:
    """Search a train config's settings and seeds ([sweep]: grid, random draws, seeds), each
    trial scored on the validation experiments: writes settings.csv (ranked), best.toml (the
    chosen setting as a ready config), summary.* (one row per trial) and report.html. If no
    setting got a score (every trial diverged, failed or was stopped), best.toml is not written
    and the command exits 1."""
    from nnid.scale.engines import LocalEngine, engine_for, environment
    from nnid.scale.status import not_ok_message
    from nnid.scale.sweep import run_sweep, run_sweep_tune, trials

    _, tasks = trials(config, data, vehicle, columns)  # a bad [sweep] is refused before work
    _check_out(out_dir)
    with _bar(f"{len(tasks)} trials") as progress:
        if address is None:
            engine = LocalEngine(workers)
            result, ranked = run_sweep(config, out_dir, engine, data, vehicle, columns, progress)
        else:
            engine_for(address, workers, tune=True)  # Ray Tune installed, or one clear error
            # Tune's own console tables would interleave with the progress bar: the
            # command's outputs are its report and this summary. Only while Tune runs (a
            # caller of the app, a test through CliRunner, keeps its environment), and not
            # over a value the person set
            quiet = {} if "RAY_AIR_NEW_OUTPUT" in os.environ else {"RAY_AIR_NEW_OUTPUT": "0"}
            with environment(quiet):
                result, ranked = run_sweep_tune(
                    config, out_dir, address, data, vehicle, columns, progress, workers
                )
    out.print(result.extra["sweep"]["summary"], highlight=False)
    written = "settings.csv, best.toml" if ranked[0].mean is not None else "settings.csv"
    out.print(
        f"wrote {out_dir}/: {written}, summary.csv, report.html (trials: "
        f"{not_ok_message(result.rows)})",
        highlight=False,
    )
    for row in result.failed:  # a trial ASHA stopped is said as stopped, not as failed
        err.print(f"{row['status']}: {row['id']}: {row['error']}", highlight=False)
    if ranked[0].mean is None:
        raise typer.Exit(1)


DEMO_LOG = "demo_minirov_heave.parquet"


@app.command()
@_input_errors
def demo(
    out_dir: Path = typer.Option(Path("nnid-demo"), "--out", help="Output folder."),
) -> None:
    """The main job end to end on bundled data: the residual loop on a simulated log of the
    'minirov' vehicle whose upward heave thrust is weaker than its vehicle file says (an
    undeclared effect, injected on purpose). The log's card is datasets/demo_minirov_heave.md
    in nnid's source repository (not installed with the package)."""
    from importlib import resources

    from nnid.datasets.readers import load_log
    from nnid.runs import residual_loop_run
    from nnid.vehicle import load_vehicle

    _check_out(out_dir)
    root = resources.files("nnid.demo_data")
    with resources.as_file(root.joinpath(DEMO_LOG)) as path:
        log, _ = load_log(str(path))
    with resources.as_file(root.joinpath("minirov.toml")) as path:
        veh = load_vehicle(path)
    out.print(
        "nnid demo: residual loop on a bundled SIMULATED log (vehicle 'minirov', an effect "
        "injected that its vehicle file does not declare)",
        highlight=False,
    )
    with _bar("residual loop") as progress:
        outcome = residual_loop_run(log, veh, out_dir, progress=progress)
    _print(outcome)
    out.print(f"open {out_dir.resolve() / 'report.html'}", highlight=False)


def _exit_on_sigterm(signum: int, frame) -> None:
    raise SystemExit(128 + signum)


def main() -> None:
    """The ``nnid`` console entry: the app, with SIGTERM unwinding like Ctrl-C.

    A SIGTERM's default kills only this process: an ensemble's worker processes (joblib's
    loky) would go on training as orphans for minutes. Raised as SystemExit, it unwinds the
    fit and the executor's shutdown ends them (``nnid batch``'s local pool cancels its queue
    and ends its workers the same way; a Ray driver has Ray's own handler). Only where
    SIGTERM still has its default (a parent that set it to be ignored keeps it so), and only
    here, in the application's entry: the library leaves signals alone."""
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, _exit_on_sigterm)
    try:
        code = app(standalone_mode=False)
    except typer.TyperException as exc:
        raise SystemExit(_usage_error(exc)) from None
    except typer.Abort:
        err.print("aborted", highlight=False)
        raise SystemExit(1) from None
    # not standalone, typer returns an Exit's code (``_input_errors``' 2, Ctrl-C's 130)
    raise SystemExit(code if isinstance(code, int) else 0)


def _usage_error(exc: typer.TyperException) -> int:
    """Say a command-line parse error (an unknown option, a value of the wrong type) in one
    line, as ``_input_errors`` says bad input, not in typer's five-line box; its exit code.

    ``typer.TyperException`` is the public base of typer's parse errors (typer vendors click
    privately, so click's own classes are not the ones raised)."""
    message = exc.format_message()
    ctx = getattr(exc, "ctx", None)
    # a bare ``nnid`` has printed its help already and carries no message to add
    if message and type(exc).__name__ != "NoArgsIsHelpError":
        hint = f" (see '{ctx.command_path} --help')" if ctx is not None else ""
        err.print(
            f"[bold red]error:[/] {escape(message)}{escape(hint)}", highlight=False, markup=True
        )
    return exc.exit_code


if __name__ == "__main__":  # `python -m nnid.cli` ran nothing and exited 0
    main()
