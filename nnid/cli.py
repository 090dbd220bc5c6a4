"""The ``nnid`` command line: parse a config, call the library, write files.

Bad input ends with one line on stderr and exit code 2; nothing else here does numerics.
"""

from __future__ import annotations

import functools
import sys
from pathlib import Path

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import Progress

from nnid.errors import NnidInputError

app = typer.Typer(
    name="nnid",
    help="Identify underwater-vehicle dynamics from logged data.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
err = Console(stderr=True)
out = Console()


def _input_errors(fn):
    """Turn bad input into one clear line and exit code 2 (no traceback)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except NnidInputError as exc:
            err.print(f"[bold red]error:[/] {escape(str(exc))}", highlight=False, soft_wrap=True)
            raise typer.Exit(2) from None

    return wrapper


@app.command()
@_input_errors
def simulate(
    config: Path = typer.Argument(..., help="TOML simulate config (see configs/)."),
    out_path: Path = typer.Option(..., "--out", help="Output log, .csv or .parquet."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; overrides the config's."
    ),
    seed: int | None = typer.Option(None, "--seed", help="Overrides the config's seed."),
) -> None:
    """Make a synthetic log from a vehicle, an excitation and optional injected effects."""
    from nnid.config import SimulateConfig, load_config
    from nnid.datasets.log import validate_log, write_log
    from nnid.datasets.simulator import simulate_config
    from nnid.vehicle import load_vehicle

    cfg = load_config(config, SimulateConfig)
    if seed is not None:
        cfg.seed = seed
    veh = load_vehicle(vehicle or cfg.vehicle)
    if out_path.suffix not in (".csv", ".parquet"):
        raise NnidInputError("output must end in .csv or .parquet", source=str(out_path))
    try:
        with Progress(console=err, transient=True) as bar:
            task = bar.add_task("simulating", total=len(cfg.all_experiments()))
            log = simulate_config(
                cfg, veh, progress=lambda done, total: bar.update(task, completed=done)
            )
    except NnidInputError as exc:
        raise exc.with_source(str(config)) from None
    validate_log(log, source=str(out_path))
    write_log(log, out_path)
    n_exp = log["experiment"].nunique() if "experiment" in log else 1
    out.print(
        f"wrote {out_path}: {len(log)} samples, {n_exp} experiments, "
        f"{log['t'].groupby(log.get('experiment', 0)).max().sum():.1f} s of '{veh.name}'"
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
) -> None:
    """Show what a log holds: columns, rate, duration, experiments, gaps, derivable signals and
    the excitation of each DOF."""
    import json

    from rich.table import Table

    from nnid.datasets.inspect import summarize
    from nnid.datasets.readers import load_log

    log, report = load_log(log_path, columns)
    info = summarize(log)
    cols = info["columns"]
    out.print(
        f"[bold]{log_path}[/]: {info['samples']} samples, {info['duration_s']:.1f} s, "
        f"{len(info['experiments'])} experiments, about {info['rate_hz']:.3g} Hz"
    )
    for group in ("pose", "velocity", "acceleration", "inputs", "other"):
        out.print(f"  {group:13s} {', '.join(cols[group]) or '-'}")
    out.print(f"  derivable     {', '.join(info['derivable']) or '-'}")
    gaps = info["gaps"]
    out.print(
        f"  gaps          {len(gaps)}"
        + (f" (longest {max(g['length_s'] for g in gaps):.3g} s)" if gaps else "")
    )
    table = Table(title="excitation per DOF")
    for head in ("DOF", "velocity std", "force std", "force active"):
        table.add_column(head)
    for dof, e in info["excitation"].items():
        table.add_row(
            dof,
            *(
                f"{e[k]:.3g}" if k in e else "-"
                for k in ("velocity_std", "force_std", "force_active_share")
            ),
        )
    out.print(table)
    for step in report.steps:
        out.print(
            f"  cleaning: {step.step}: {step.detail}"
            + (f" ({step.rows_removed} rows removed)" if step.rows_removed else "")
        )
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "summary.json").write_text(json.dumps(info, indent=2))
        report.write(out_dir)


def _vehicle_path(name: str, config: Path, resolve) -> str:
    """A preset name as it is; a path relative to the config file (or to the working folder)."""
    from nnid.vehicle import PRESETS

    return name if name in PRESETS else str(resolve(config.parent, name))


def _not_yet(name: str) -> None:
    err.print(f"nnid {name}: not implemented yet", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


@app.command()
@_input_errors
def train(
    config: Path = typer.Argument(..., help="TOML train config (see configs/)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder for model, metrics, report."),
    data: str | None = typer.Option(None, "--data", help="Log to fit; overrides the config's."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; overrides the config's."
    ),
    columns: str | None = typer.Option(
        None, "--columns", help="Reader config for a log not in nnid's format."
    ),
) -> None:
    """Fit one model on the training split and score it on held-out data: writes
    model.json (a NARX: narx.pt and narx.json), metrics.json, report.md and the cleaning
    report to --out."""
    import json

    from nnid.config import TrainConfig, load_config
    from nnid.pipeline import run_train
    from nnid.reports.train_report import train_markdown
    from nnid.validation import read_toml
    from nnid.vehicle import load_vehicle

    if read_toml(config).get("kind") == "caccia":
        from nnid.pipeline import run_caccia_train

        with err.status("Caccia two-step identification"):
            result = run_caccia_train(config, vehicle)
    elif read_toml(config).get("model") == "narx":
        from nnid.pipeline import run_narx_train

        cfg = load_config(config, TrainConfig)
        try:
            with err.status(f"training the NARX network ({cfg.trainer})"):
                result = run_narx_train(cfg, config, data, columns)
        except NnidInputError as exc:
            raise exc.with_source(str(config)) from None
    else:
        from nnid.pipeline import resolve

        cfg = load_config(config, TrainConfig)
        if not (vehicle or cfg.vehicle):
            raise NnidInputError("give a vehicle (config or --vehicle)", field="vehicle")
        veh = load_vehicle(vehicle or _vehicle_path(cfg.vehicle, config, resolve))
        try:
            with err.status(f"fitting the Fossen model ({cfg.trainer})"):
                result = run_train(cfg, config, veh, data, columns)
        except NnidInputError as exc:
            raise exc.with_source(str(config)) from None
    out_dir.mkdir(parents=True, exist_ok=True)
    if result.metrics["model"] == "narx":
        result.model.save(out_dir)  # narx.pt (state dict) + narx.json
    else:
        result.model.save(out_dir / "model.json")
    (out_dir / "metrics.json").write_text(json.dumps(result.metrics, indent=2))
    (out_dir / "report.md").write_text(train_markdown(result.metrics))
    result.report.write(out_dir)
    val = result.metrics["validation"].get("free_run_nrmse", {})
    out.print(
        f"wrote {out_dir}/: model.json, metrics.json, report.md "
        f"(validation free-run NRMSE total {val.get('total', float('nan')):.3g})"
    )


@app.command()
@_input_errors
def compare(
    config: Path = typer.Argument(..., help="TOML compare config (see configs/)."),
    out_dir: Path = typer.Option(..., "--out", help="Output folder for the report."),
    data: str | None = typer.Option(None, "--data", help="Log to use; overrides the config's."),
    vehicle: str | None = typer.Option(
        None, "--vehicle", help="Preset name or vehicle TOML; overrides the config's."
    ),
    columns: str | None = typer.Option(
        None, "--columns", help="Reader config for a log not in nnid's format."
    ),
) -> None:
    """Fit the named damping models and SINDy on the training split and compare them on the
    validation split: writes comparison.json, report.html and report.md to --out."""
    import json

    from nnid.config import CompareConfig, load_config
    from nnid.pipeline import resolve, run_compare
    from nnid.reports.compare_report import html_page, markdown
    from nnid.vehicle import load_vehicle

    cfg = load_config(config, CompareConfig)
    veh = load_vehicle(vehicle or _vehicle_path(cfg.vehicle, config, resolve))
    try:
        with Progress(console=err, transient=True) as bar:
            task = bar.add_task("fitting damping models", total=len(cfg.models) + 1)
            result = run_compare(
                cfg,
                config,
                veh,
                data,
                columns,
                progress=lambda d, n: bar.update(task, completed=d, total=n),
            )
    except NnidInputError as exc:
        raise exc.with_source(str(config)) from None
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "comparison.json").write_text(json.dumps(result.comparison, indent=2))
    (out_dir / "report.html").write_text(
        html_page(result.comparison, result.t, result.measured, result.predicted)
    )
    (out_dir / "report.md").write_text(markdown(result.comparison))
    result.report.write(out_dir)
    out.print(
        f"wrote {out_dir}/: comparison.json, report.html, report.md. "
        + result.comparison["summary"]
    )


@app.command()
def loop() -> None:
    """Residual loop: find and add missing effects (not implemented yet)."""
    _not_yet("loop")


@app.command()
def detect() -> None:
    """Fault detection from residuals (not implemented yet)."""
    _not_yet("detect")


@app.command()
def demo() -> None:
    """The main job end to end on bundled data (not implemented yet)."""
    _not_yet("demo")


def main() -> None:  # pragma: no cover - console entry
    sys.exit(app())
