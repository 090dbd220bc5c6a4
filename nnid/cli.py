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


def _not_yet(name: str) -> None:
    err.print(f"nnid {name}: not implemented yet", highlight=False, soft_wrap=True)
    raise typer.Exit(2)


@app.command()
def train(config: Path = typer.Argument(...)) -> None:
    """Fit one model (not implemented yet)."""
    _not_yet("train")


@app.command()
def compare(config: Path = typer.Argument(...)) -> None:
    """Fit several models and write a comparison report (not implemented yet)."""
    _not_yet("compare")


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
