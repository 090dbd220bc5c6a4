"""The documented workflows end to end, for the CLI: load (or simulate) the data, split it, fit
through the model protocol, score with :func:`nnid.evaluation.evaluate.evaluate`. Returns
data; the CLI writes files and talks to people."""

from __future__ import annotations

import difflib
import time
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from pydantic import BaseModel

from nnid.config import (
    PHYSICS_KINDS,
    SAMPLE_KINDS,
    CacciaCampaignData,
    CompareConfig,
    SimulateConfig,
    TableData,
    TrainConfig,
    VehicleData,
    load_config,
)
from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.gaps import mask_gaps, say_unread
from nnid.datasets.log import (
    ANGLES,
    MOTION,
    VELOCITY,
    frame_step,
    input_columns,
    run_label,
    run_of,
    run_pieces,
)
from nnid.datasets.preprocess import check_acceleration_window, experiment_rows, run_spans
from nnid.datasets.splits import PARTS, Split, say_missed_fractions, split_log
from nnid.errors import NnidInputError
from nnid.evaluation.evaluate import (
    CONSTANT,
    common_warmup,
    diverged_columns,
    diverged_key,
    evaluate,
    not_scored_key,
)
from nnid.evaluation.metrics import exact_mean
from nnid.evaluation.prediction import Replay
from nnid.models.base import FIT_AND_SIMULATION, encode_setting
from nnid.physics.dofs import DOFS
from nnid.reports.cells import number
from nnid.reports.stops import training_stages
from nnid.trainers.history import Progress, silent, staged
from nnid.validation import resolve
from nnid.warning_messages import warning_messages

# -- inputs --------------------------------------------------------------------------------------


@dataclass
class Inputs:
    """What a run works on: the log, what was done to it, the model's vehicle, and the
    simulate config when the log was simulated (for an autopilot replay)."""

    log: pd.DataFrame
    report: CleaningReport
    vehicle: Any = None
    simulation: SimulateConfig | None = None
    notes: dict = field(default_factory=dict)
    #: the (window s, order) of the Savitzky-Golay derivative that gave the velocities the
    #: report says were derived from the pose ([data]'s)
    derived_with: tuple[float, int] = (1.0, 4)
    #: how an error names the vehicle's file ("vehicle file PATH", "preset 'NAME'"; None
    #: where no vehicle was named)
    vehicle_label: str | None = None
    #: the log file read (None for a simulated log) and the clock of the rows kept from it
    #: (``t`` and ``experiment``, labelled by the file's rows, in the order of ``log``'s rows):
    #: what an error found after the split names
    source: str | None = None
    clock: pd.DataFrame | None = None


def vehicle_for(name: str, config_path: Path, key: str = "vehicle"):
    """A preset by name, or a vehicle file (:func:`vehicle_source`); one that does not exist
    is said against ``key``: the config's ``vehicle``, or ``--vehicle``."""
    from nnid.vehicle import PRESETS, load_vehicle

    if name in PRESETS:
        return load_vehicle(name)
    path = Path(vehicle_source(name, config_path, key))
    if not path.exists():
        where = f" (looked for {path})" if key == "vehicle" else ""
        raise NnidInputError(
            f"{name!r} is neither a preset ({', '.join(PRESETS)}) nor an existing file{where}",
            source=str(config_path) if key == "vehicle" else None,
            field=key,
        )
    return load_vehicle(path)


def vehicle_label(name: str, config_path: Path, key: str = "vehicle") -> str:
    """How an error names the vehicle ``name`` loads: "preset 'NAME'", or "vehicle file
    PATH" (:func:`vehicle_source`)."""
    from nnid.vehicle import PRESETS

    return (
        f"preset '{name}'"
        if name in PRESETS
        else f"vehicle file {vehicle_source(name, config_path, key)}"
    )


def vehicle_source(name: str, config_path: Path, key: str = "vehicle") -> str:
    """What ``name`` loads: a preset's name, or the vehicle file's path: a config's
    ``vehicle`` relative to the config's folder (unless absolute), ``--vehicle`` (``key``)
    as given, relative to the current folder, as ``--data`` is."""
    from nnid.vehicle import PRESETS

    if name in PRESETS or key.startswith("--"):
        return name
    return str(resolve(config_path.parent, name))


def plant_for(name: str, config_path: Path, key: str = "vehicle"):
    """:func:`vehicle_for` of a vehicle to simulate: one whose M = M_RB + M_A is not positive
    definite cannot be flown, said against its file and field, not the simulate config
    (:func:`nnid.datasets.simulator.check_mass_matrix`; a fit loads such a file and refits
    its added mass)."""
    from nnid.datasets.simulator import check_mass_matrix

    veh = vehicle_for(name, config_path, key)
    try:
        check_mass_matrix(veh)
    except NnidInputError as exc:
        raise exc.with_source(vehicle_source(name, config_path, key)) from None
    return veh


def reader_config(cfg, config_path: Path, columns: str | None) -> str | None:
    """The reader config a vehicle log is read through: ``--columns``, else the config's
    ``data.columns`` (relative to the config's folder), with ``--data`` too."""
    if columns:
        return columns
    named = getattr(cfg.data, "columns", None) if cfg.data is not None else None
    return str(resolve(config_path.parent, named)) if named else None


def reader_root(columns: str | None) -> str | None:
    """The folder a reader config's ``root`` names (relative to its own folder), or None: the
    data of a run that gives no log, as the reader config documents."""
    if columns is None:
        return None
    from nnid.datasets.column_map import load_column_map

    cmap = load_column_map(columns)
    return str(cmap.resolve_root(Path(columns))) if cmap.root else None


def reader_vehicle(columns: str) -> tuple[Any, str | None]:
    """The vehicle a reader config names (its ``vehicle``, relative to its own folder) and
    its :func:`vehicle_label`, or (None, None): the vehicle of a run that names none, as the
    reader config documents."""
    from nnid.datasets.column_map import load_column_map

    name = load_column_map(columns).vehicle
    if not name:
        return None, None
    return vehicle_for(name, Path(columns)), vehicle_label(name, Path(columns))


def _check_file(path: Path, source: Path, key: str) -> None:
    if not path.exists():
        raise NnidInputError(f"no such file or folder: {path}", source=str(source), field=key)


def check_paths(cfg, config_path: Path, data: str | None, columns: str | None) -> None:
    """Every file the config names exists, before any work (one error naming the key)."""
    spec = cfg.data
    base = config_path.parent
    if data is not None:
        if not Path(data).exists():
            raise NnidInputError("no such file or folder", source=data, field="--data")
    if columns is not None and not Path(columns).exists():
        raise NnidInputError("no such reader config", source=columns, field="--columns")
    if data is None and spec is None and reader_root(columns) is None:
        raise NnidInputError(
            "no data: give a [data] section, --data LOG, or a reader config with a root",
            source=str(config_path),
            field="data",
        )
    if spec is None:
        return
    for key in ("log", "columns", "simulate", "campaign"):
        value = getattr(spec, key, None)
        # --data replaces the data the config names (its log, simulation or campaign), which
        # is then not read: a copied config whose simulate file stayed behind was refused
        if not value or (key != "columns" and data) or (key == "columns" and columns):
            continue
        _check_file(resolve(base, value), config_path, f"data.{key}")
    simulated = data is None and getattr(spec, "simulate", None)
    if simulated and (root := reader_root(reader_config(cfg, config_path, columns))):
        # the root's files were read and the simulation dropped without a word (as beside
        # data.log, which [data] refuses)
        raise NnidInputError(
            f"is not run: the reader config's root ({root}) is the log read instead; give "
            "data.simulate or a reader config with a root, not both (or --data, which "
            "replaces both)",
            source=str(config_path),
            field="data.simulate",
        )


#: the remedy a SINDy or named damping model's missing velocity has: no DOF can be left out
WHOLE_LIBRARY = "fit a Fossen model of the DOFs the log has (this model's terms read all six)"


def fitted_dofs(spec) -> list[str]:
    """The DOFs whose equations a physics model's config fits: its ``dofs``, with a
    ``sequence`` the DOFs of its steps, and for SINDy and the named damping models all six
    (their libraries read every velocity)."""
    sequence = getattr(spec, "sequence", None)
    if sequence:
        from nnid.trainers.sequence import sequence_dofs, sequence_steps

        steps = sequence if isinstance(sequence, str) else [s.model_dump() for s in sequence]
        return sequence_dofs(sequence_steps(steps))
    if spec.kind in ("sindy", "synthesis"):
        return list(DOFS)
    return list(getattr(spec, "dofs", None) or [])


def load_inputs(
    cfg: TrainConfig | CompareConfig,
    config_path: Path,
    models: list,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    time_unit: str | None = None,
) -> Inputs:
    """The log of a train or compare run (``--data``/``--columns`` replace the config's file,
    ``--vehicle`` its vehicle, ``--time-unit`` its ``data.time_unit``), with velocities
    derived and noise added where asked."""
    check_paths(cfg, config_path, data, columns)
    models = [m.fitted for m in models]  # an ensemble needs the data its members need
    spec = cfg.data if cfg.data is not None else VehicleData()
    base = config_path.parent
    physics = any(m.kind in PHYSICS_KINDS for m in models)
    name, key = (vehicle, "--vehicle") if vehicle else (cfg.vehicle, "vehicle")
    veh = vehicle_for(name, config_path, key) if name else None
    veh_label = vehicle_label(name, config_path, key) if name else None
    reader = reader_config(cfg, config_path, columns)
    if veh is None and reader is not None:
        veh, veh_label = reader_vehicle(reader)
    simulated = data is None and bool(getattr(spec, "simulate", None))
    if physics and veh is None and not simulated:  # said before any data is read
        raise NnidInputError(
            "a physics model needs a vehicle: the config's 'vehicle' or --vehicle",
            source=str(config_path),
            field="vehicle",
        )
    sim, source = None, None  # source: the log file read, which errors about it name
    # the declared unit of the log's t: the option's, else the config's
    unit, unit_key = (
        (time_unit, "--time-unit")
        if time_unit
        else (getattr(spec, "time_unit", None), "data.time_unit")
    )
    if isinstance(spec, TableData):
        _nothing_to_declare(unit, unit_key, config_path, "a generic table")
        if physics:
            raise NnidInputError(
                'data kind = "table" is for the input-output models (narx, state_space)',
                source=str(config_path),
                field="data.kind",
            )
        path = data or (str(resolve(base, spec.log)) if spec.log else None)
        if path is None:
            raise NnidInputError("give data.log (or --data)", source=str(config_path), field="data")
        inputs = Inputs(*_read_table(path, models))
        source = path
    elif isinstance(spec, CacciaCampaignData) and data is None:
        _nothing_to_declare(unit, unit_key, config_path, "a simulated campaign")
        sim, log, report = _caccia_campaign(spec, config_path, models, veh)
        inputs = Inputs(log, report, veh, sim)
    elif path := (
        data
        or (str(resolve(base, spec.log)) if getattr(spec, "log", None) else None)
        or reader_root(reader)  # read only when the run gives no log
    ):
        from nnid.datasets.readers import load_log, mapped_source

        inputs = Inputs(*load_log(path, reader, unit, unit_key), veh)
        source = mapped_source(path, reader)
        if veh is not None and (physics or not models):  # physics fits, and the loop's log
            from nnid.datasets.arrays import (
                check_forces_match_commands,
                far_beyond_range,
                warn_far_beyond_range,
            )

            check_forces_match_commands(inputs.log, veh)
            slips = far_beyond_range(inputs.log, veh)
            if slips and getattr(cfg, "detect", None) is not None:  # before the fit, not after
                raise NnidInputError(
                    f"{slips[0].message} ([detect] calibrates a monitor, which reads them as "
                    "faults)",
                    source=source,
                    field=slips[0].column,
                    row=slips[0].row,
                )
            warn_far_beyond_range(inputs.log, veh, slips)
        if physics and veh is not None:  # the inputs the vehicle reads, said against the log
            from nnid.datasets.arrays import logged_inputs
            from nnid.datasets.preprocess import check_velocities

            try:
                logged_inputs(inputs.log, veh)
                for m in models:  # the velocities the fit needs, said against the log
                    if m.kind in ("sindy", "synthesis"):
                        check_velocities(inputs.log.columns, fitted_dofs(m), WHOLE_LIBRARY)
                    elif m.kind in PHYSICS_KINDS:
                        check_velocities(inputs.log.columns, fitted_dofs(m))
            except NnidInputError as err:
                raise err.with_source(source) from None
    elif getattr(spec, "simulate", None):
        from nnid.datasets.simulator import simulate_config

        _nothing_to_declare(unit, unit_key, config_path, "simulated")
        sim_path = resolve(base, spec.simulate)
        sim = load_config(sim_path, SimulateConfig)
        plant = plant_for(sim.vehicle, sim_path)
        report = CleaningReport(source=str(sim_path))
        log = simulate_config(sim, plant)
        report.add("simulate", f"{len(log)} samples from {sim_path}")
        inputs = Inputs(log, report, veh or plant, sim)
        veh_label = veh_label or vehicle_label(sim.vehicle, sim_path)
    else:
        raise NnidInputError(
            "give data.log, data.simulate (or --data)", source=str(config_path), field="data"
        )
    # a run a gap cut into pieces is named as logged: its name stands for all its pieces
    wanted = run_pieces(inputs.log, spec.experiments) if spec.experiments else []
    if spec.experiments:
        runs = run_of(inputs.log)
        missing = [e for e in wanted if e not in runs]
        if missing:
            have = sorted(map(str, dict.fromkeys(runs.values())))
            said = have if len(have) <= 8 else [*have[:8], f"… {len(have)} in all"]
            # a config that names its runs fits only logs holding them (the shipped Seamor
            # ones): the way to another log was left unsaid
            raise NnidInputError(
                f"experiments {missing} are not in the log (it has {said}): for this log, "
                "name its runs in data.experiments and [split] (or remove them)",
                source=str(config_path),
                field="data.experiments",
            )
    kept = inputs.log  # its index: the rows as read, which errors about the file name
    if spec.experiments:
        kept = inputs.log[inputs.log["experiment"].isin(wanted)]
        inputs.log = kept.reset_index(drop=True)
        inputs.report.add("experiments", f"kept {', '.join(spec.experiments)}")
    if source is not None:  # the runs kept: one left out may be sampled as it likes
        _check_sampling(kept, models, source, every_part_predicted=cfg.kind == "train")
        inputs.source = source
        inputs.clock = kept[[c for c in ("t", "experiment") if c in kept]]
        # a model with no dofs fits every DOF the data excites: any of them may read the angle
        fitted = [d for m in models if m.kind in PHYSICS_KINDS for d in fitted_dofs(m) or DOFS]
        if fitted and inputs.vehicle is not None:
            from nnid.datasets.preprocess import check_attitude

            try:
                check_attitude(inputs.log, inputs.vehicle, list(dict.fromkeys(fitted)))
            except NnidInputError as err:
                raise err.with_source(source) from None
    inputs.log = _prepare(inputs.log, spec, inputs.report)
    inputs.derived_with = (float(spec.savgol_window), int(spec.savgol_order))
    inputs.vehicle_label = veh_label if inputs.vehicle is not None else None
    return inputs


def _nothing_to_declare(unit: str | None, key: str, config_path: Path, data: str) -> None:
    """A declared time unit where the run reads no vehicle log file: refused, not dropped
    without a word."""
    if unit is not None:
        raise NnidInputError(
            f"declares the time unit of a vehicle log file, and this run's data is {data}",
            source=None if key.startswith("--") else str(config_path),
            field=key,
        )


def loaded_inputs(*args, **kwargs) -> tuple[Inputs, list[str]]:
    """:func:`load_inputs` and the warnings it raised about the data, each once: they belong
    in the run's record (``metrics.json``, ``comparison.json``, the reports), not only on the
    console, and no fit need raise them again."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        error: NnidInputError | None = None
        try:
            inputs = load_inputs(*args, **kwargs)
        except NnidInputError as exc:
            error = exc
    if error is not None:  # no record to keep them in: said before the error, as they were
        for w in caught:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        raise error
    return inputs, warning_messages(caught)


def _check_sampling(
    log: pd.DataFrame, models: list, path: str, every_part_predicted: bool = False
) -> None:
    """No run whose stamps come in bursts, for any model (the loop's too): each is fitted,
    simulated and scored at its run's typical step (:func:`~nnid.datasets.log.typical_step`),
    one inside a burst (an IMU's samples 10 µs apart, every 10 ms); uniform sampling, said
    against the log before any fit, where a model counts time in samples (the input-output
    models check it again themselves, naming the config); and, where
    ``every_part_predicted`` (train scores the free run of its training part too), no
    samples missing where a physics model's prediction steps (its own check, which said the
    config, not the log, once the fit was done)."""
    from nnid.datasets.preprocess import check_uniform, refuse_bursty_runs
    from nnid.evaluation.prediction import check_stepped

    counting = [m.kind for m in models if m.kind in SAMPLE_KINDS]
    stepped = every_part_predicted and any(m.kind in PHYSICS_KINDS for m in models)
    if "t" in log:
        try:
            # before check_uniform, which read a burst's gap as samples missing
            refuse_bursty_runs(log, FIT_AND_SIMULATION)
            if counting:
                check_uniform(log, f"the {counting[0]} model")
            if stepped:
                check_stepped(log)
        except NnidInputError as err:
            raise err.with_source(path) from None


def check_held_stepped(inputs: Inputs, split: Split, models: list) -> None:
    """No samples missing where a physics model's prediction steps the held-out parts of a
    comparison (validation and test: training is only fitted), said against the log file and
    its row before any fit (the prediction's own check, after the fits, named the config)."""
    from nnid.evaluation.prediction import check_stepped

    clock = inputs.clock
    if clock is None or "t" not in clock or not any(m.kind in PHYSICS_KINDS for m in models):
        return
    runs = clock["experiment"].to_numpy() if "experiment" in clock else None
    held = []
    for part in ("validation", "test"):  # the record's rows count within each experiment
        for entry in split.record["parts"][part]:
            pos = (
                np.arange(len(clock))
                if runs is None
                else np.flatnonzero(runs == entry["experiment"])
            )
            a, b = entry.get("rows", (0, len(pos)))
            held.append(pos[a:b])
    if not held:
        return
    try:
        check_stepped(clock.iloc[np.unique(np.concatenate(held))])
    except NnidInputError as err:
        raise err.with_source(inputs.source) from None


def _read_table(path: str, models: list) -> tuple[pd.DataFrame, CleaningReport]:
    from nnid.datasets.log import validate_table
    from nnid.datasets.readers import read_table

    needed = list(dict.fromkeys(c for m in models for c in [*m.inputs, *m.outputs]))
    log = validate_table(read_table(path), needed, source=path)
    report = CleaningReport(source=path)
    report.add("read", f"{len(log)} rows, a generic input-output table")
    return log, report


def _caccia_campaign(spec: CacciaCampaignData, config_path: Path, models: list, vehicle):
    from nnid.trainers.caccia import caccia_campaign

    model = next((m for m in models if m.kind == "caccia"), None)
    if model is None:
        raise NnidInputError(
            'data kind = "caccia_campaign" designs its sinusoid with a caccia model\'s settings',
            source=str(config_path),
            field="data.kind",
        )
    if vehicle is None:
        raise NnidInputError("give a vehicle", source=str(config_path), field="vehicle")
    path = resolve(config_path.parent, spec.campaign)
    campaign = load_config(path, SimulateConfig)
    if spec.campaign_seed is not None:
        campaign = campaign.model_copy(update={"seed": spec.campaign_seed})
    if campaign.vehicle != vehicle.name:
        raise NnidInputError(
            f"the campaign flies '{campaign.vehicle}', the config names '{vehicle.name}'",
            source=str(config_path),
            field="data.campaign",
        )
    trainer = model.build(vehicle).trainer()
    log, design = caccia_campaign(campaign, vehicle, trainer, spec.sinusoid, spec.validation)
    report = CleaningReport(source=str(path))
    report.add(
        "simulate",
        f"Caccia campaign: {len(log)} samples; d-optimal sinusoid designed from step 1: "
        f"ω = {design.frequency():.4g} rad/s, offset {design.offset:g} N, amplitude "
        f"{design.amplitude:g} N",
    )
    return campaign, log, report


def _prepare(log: pd.DataFrame, spec, report: CleaningReport) -> pd.DataFrame:
    """An attitude logged slower than the clock filled from the gyro between its samples
    (:func:`nnid.datasets.gaps.fill_slow`), velocities derived from the pose where the log
    lacks them (every model is fitted and scored on the same measured velocities), then light
    white noise (``spec.noise``), each step reported."""
    from nnid.datasets.gaps import bridge_from_pose, fill_slow
    from nnid.datasets.measurement import relative_noise
    from nnid.datasets.preprocess import derive_velocities

    log = fill_slow(log, report)
    try:
        if any(c not in log for c in VELOCITY) and all(a in log for a in ANGLES):
            log = derive_velocities(log, spec.savgol_window, spec.savgol_order, report)
        log = bridge_from_pose(log, spec.savgol_window, spec.savgol_order, report=report)
    except NnidInputError as exc:  # a window the config's [data] chose
        raise exc.within("data", type(spec).model_fields) from None
    if spec.noise > 0:
        absent = [c for c in spec.noise_columns or [] if c not in log]
        if absent:  # no noise at all, with the report saying it was added
            raise NnidInputError(
                f"noise_columns names {', '.join(absent)}, which the log does not have "
                f"(it has {', '.join(map(str, log.columns))})",
                field="data.noise_columns",
            )
        noisy = spec.noise_columns or [*input_columns(log), *VELOCITY]
        cols = [c for c in noisy if c in log]
        log = log.copy()
        rng = np.random.default_rng(spec.noise_seed)
        relative_noise(log, {c: c for c in cols}, spec.noise, rng)
        report.add("noise", f"white noise of {spec.noise:g} × std added to {', '.join(cols)}")
    return log


def make_split(
    log: pd.DataFrame,
    s,
    source: str = "",
    report: CleaningReport | None = None,
    warmup_s: float = 0.0,
    log_source: str | None = None,
    read: Sequence[str] | None = None,
    unread_said: tuple[str, str, str] | None = None,
) -> Split:
    """The split a config asks for: named experiments (the rest trains) or fractions. A split
    with nothing to validate on is an error: scores on training data are not validation; so
    is one whose held-out runs are all no longer than the scores' warm-up ``warmup_s``.
    Motion gaps are masked in each part after the split, so they never move it
    (:func:`nnid.datasets.gaps.mask_gaps`, reported in ``report``), in the motion columns
    the models ``read`` (:func:`read_motion`; None: every one); a run in which one of them is
    logged slower than the clock is taken out whole and said, and the log refused, naming
    ``log_source``, only where that empties a part that had rows. Empty cells of a motion column no
    model reads stay, said in ``report`` (``unread_said``: who reads none, what the rows stay
    in, what an empty pose cell takes; :func:`~nnid.datasets.gaps.say_unread`): a 1-Hz GPS x y
    beside a 10-Hz DVL refused a Fossen fit that never reads them."""
    assignment = None
    # what the config alone shows (named parts only by experiment, not beside fractions, not
    # overlapping; fractions summing to 1) its SplitSpec refused
    named = [p for p in PARTS if getattr(s, p) is not None]  # test = [] says: no test part
    if s.by == "experiment" and named:
        if "experiment" not in log:
            raise NnidInputError(
                "the log has no 'experiment' column to split by", source=source, field="split"
            )
        names = list(dict.fromkeys(log["experiment"]))
        # a run a gap cut into pieces is named as logged: all its pieces
        validation, test = run_pieces(log, s.validation or []), run_pieces(log, s.test or [])
        held = set(validation + test)
        assignment = {
            "train": run_pieces(log, s.train or []) or [n for n in names if n not in held],
            "validation": validation,
            "test": test,
        }
        unused = [n for n in names if n not in {*assignment["train"], *held}]
        if unused:  # a run in no part: said, never dropped in silence
            said = f"experiments {', '.join(map(str, unused))} are in no part of the split"
            warnings.warn(f"{said} (split.train names the training runs): not used", stacklevel=2)
            if report is not None:
                report.add("split", f"{said}: not used", int(log["experiment"].isin(unused).sum()))
    try:
        if s.by == "auto":
            split = _auto_split(log, tuple(s.fractions))
        else:
            split = split_log(log, s.by, tuple(s.fractions), assignment)
    except NnidInputError as exc:
        raise NnidInputError(exc.message, source=source, field=f"split.{exc.field}") from None
    say_missed_fractions(split)
    if report is not None and split.record.get("missed"):
        report.add("split", split.record["missed"])
    motion = [c for c in MOTION if c in log and (read is None or c in read)]
    say_unread(log, motion, report, *(unread_said or ()))
    try:
        parts = mask_gaps(
            [split.train, split.validation, split.test],
            motion,
            report,
            ("training", "validation", "test"),
        )
    except NnidInputError as exc:  # a slow channel: said against the log (``log_source``)
        raise exc.with_source(log_source) if log_source else exc from None
    split = Split(*parts, split.record)
    if len(split.train) == 0:
        raise NnidInputError("the training split is empty", source=source, field="split")
    if len(split.validation) == 0:
        raise NnidInputError(
            "the validation split is empty: hold out an experiment or a block",
            source=source,
            field="split",
        )
    for part, name in (
        (split.train, "training"),
        (split.validation, "validation"),
        (split.test, "test"),
    ):
        for exp, pos in experiment_rows(part):
            if len(pos) < 2:  # no sample period: nothing to fit or score on it
                raise NnidInputError(
                    f"the {name} split holds a single sample of "
                    f"{run_label(exp)}: each piece needs at "
                    "least two; the log is too short for these fractions, so give a longer log "
                    "or other fractions",
                    source=source,
                    field="split",
                )
        spans = run_spans(part)
        if name != "training" and spans and max(spans) <= warmup_s:
            # every scored run would be all warm-up: no score, not a "diverged" one
            raise NnidInputError(
                f"the longest {name} run is {max(spans):.3g} s, no longer than the warm-up "
                f"({warmup_s:g} s): nothing would be scored; give a shorter warmup_s, or a "
                "longer log or split",
                source=source,
                field="warmup_s",
            )
    return split


def read_motion(models, log: pd.DataFrame, replay: Replay | None = None) -> list[str]:
    """The motion columns of ``log`` that a fit or a score of any of ``models`` reads on every
    row (:meth:`nnid.models.base.NnidModel.motion_columns`): those :func:`make_split` masks
    gaps in. Every one under an autopilot ``replay``: its feedback acts on the flown pose,
    which starts from the measured one (η_ref − η, a position included)."""
    if replay is not None:
        return [c for c in MOTION if c in log]
    read = {c for m in models for c in m.motion_columns(log.columns)}
    return [c for c in MOTION if c in read]


def _auto_split(log: pd.DataFrame, fractions: tuple[float, float, float]) -> Split:
    """Whole experiments when each part with a fraction gets one, else blocks."""
    n = log["experiment"].nunique() if "experiment" in log else 1
    if n >= 2:
        split = split_log(log, "experiment", fractions)
        if all(len(split[p]) for p, f in zip(PARTS, fractions, strict=True) if f):
            split.record["requested"] = "auto"
            return split
    split = split_log(log, "block", fractions)
    split.record["requested"] = "auto"
    return split


# -- fit and score -------------------------------------------------------------------------------

#: models whose force series is McCarter's τ̄ (eq. 4.4): their forces share one plot and table
DAMPING_KINDS = ("synthesis", "sindy")


def build_model(spec, inputs: Inputs, warmup_s: float):
    """The model of a config section; an ensemble scores its members' validation free runs
    with the run's ``warmup_s``, as every score of the run is (one number per member, not
    one in ``describe`` and another in ``members``), and a model with a Fossen fit (a Fossen
    model's, a hybrid's) learns which velocities the inputs' report derived from the pose and
    with which window (:func:`_prepare`: their noise is the pose's, smoothed)."""
    model = spec.build(inputs.vehicle)
    if model.kind == "ensemble":
        model.set_params(warmup_s=warmup_s)
    steps = inputs.report.steps
    derived = tuple(
        dict.fromkeys(c for s in steps if s.step == "derive velocities" for c in s.columns)
    )
    for key in [k for k in model.get_params(deep=True) if k.endswith("pose_velocities")]:
        # an ensemble's members too (model__pose_velocities)
        model.set_params(
            **{key: derived, key[: -len("velocities")] + "savgol": inputs.derived_with}
        )
    return model


def fit_model(
    model, split: Split, progress: Progress, section: str, spec, replay: Replay | None = None
) -> list[str]:
    """Fit on the training split (validation for early stopping or selection); the warnings
    raised, each once. The model's own refusals are named where the config sets the field:
    under ``section`` (``model``, ``models.2``) when it is a key of the config table ``spec``.
    An ensemble is given the run's ``replay``: it scores its members' validation free runs
    (and drops diverged ones) as the run's scores fly them."""
    extra = {"replay": replay} if model.kind == "ensemble" else {}
    with warnings.catch_warnings(record=True) as caught, named_in(section, spec):
        warnings.simplefilter("always")
        model.fit(split.train, split.validation, progress=progress, **extra)
    return _fit_warnings(caught)


@contextmanager
def named_in(section: str, spec) -> Iterator[None]:
    """A model's refusals (in its fit, or in scoring it: a ``savgol_window`` longer than a
    held-out run) named where the config sets the field: under ``section`` (``model``,
    ``models.2``) when it is a key of the config table ``spec`` or of a table below it
    (:func:`config_named`)."""
    try:
        yield
    except NnidInputError as exc:
        raise config_named(exc, section, spec) from None


#: the tables below a model's table whose keys a model's refusal names bare: its trainers'
#: (``filter_lambda`` of ``[model.trainer]``) and an ensemble's member's
_PARTS = ("trainer", "physics_trainer", "member")


def config_named(exc: NnidInputError, section: str, spec: Any) -> NnidInputError:
    """``exc`` with its field named where the config table ``spec`` (under ``section``) sets
    it: a key of the table, else of the one table below it that has it (a trainer's
    ``filter_lambda`` is ``model.trainer.filter_lambda``, not a key of ``[model]``); else
    as it was, where no table or two have it."""
    named = exc.within(section, type(spec).model_fields)
    if named is not exc:
        return named
    below = [(f"{section}.{key}", getattr(spec, key, None)) for key in _PARTS]
    found = [config_named(exc, at, part) for at, part in below if isinstance(part, BaseModel)]
    found = [f for f in found if f is not exc]
    return found[0] if len(found) == 1 else exc


def check_savgol_window(
    spec, model, split: Split, section: str, members_scored: bool = False
) -> None:
    """A model's ``savgol_window`` no longer than any run of the parts whose accelerations it
    derives with it, where they lack one it reads (the model's
    :meth:`~nnid.models.base.NnidModel.acceleration_parts`; ``members_scored``: an ensemble's
    members are scored on the held-out parts, as train's scores are), said before its fit. Its
    own refusal came once it was fitted, in scoring it (minutes of a hybrid's training). Named
    as :func:`named_in` names it (an ensemble's: under its member)."""
    derived = model.acceleration_parts(members_scored)
    if derived is None:
        return
    names = dict(zip(PARTS, ("training", "validation", "test"), strict=True))
    with named_in(section, spec):
        for part in derived.parts:
            log = split[part]
            if len(log) and any("d" + d not in log for d in derived.dofs):
                # named by the model's key that sets the window (Caccia's velocity_window)
                key = derived.field.rsplit(".", 1)[-1]
                try:
                    check_acceleration_window(
                        log, derived.window_s, derived.order, names[part], key
                    )
                except NnidInputError as exc:  # an ensemble's under its member; a run of
                    # one sample names no setting (none would make it fit)
                    field = derived.field if exc.field else None
                    raise NnidInputError(exc.message, field=field) from None


def check_damping_unknowns(spec, inputs: Inputs, section: str) -> None:
    """A Fossen fit's unknowns (a Fossen model's, a hybrid's, an ensemble member's) whose
    group ``damping`` names no damping term of the vehicle, refused before the fit where the
    config writes them (:func:`~nnid.models.parametric.check_damping_group`), naming the
    vehicle's file and, as :func:`named_in` names it, the config key that asks for it. The
    default unknowns ask for damping on any vehicle: there the fit says it estimates none."""
    from nnid.models.parametric import check_damping_group

    fitted = spec.fitted
    unknowns = getattr(fitted, "unknowns", None)
    if unknowns is None or getattr(fitted, "sequence", None) or inputs.vehicle is None:
        return
    if "unknowns" not in fitted.model_fields_set:
        return
    with named_in(section, spec):
        check_damping_group(unknowns, fitted.dofs, inputs.vehicle, inputs.vehicle_label)


def _fit_warnings(caught) -> list[str]:
    """The messages of warnings caught in a fit, each once; the commands' units were said
    against the whole log as it was loaded (load_inputs), not again per part."""
    from nnid.datasets.arrays import CommandUnitsWarning

    return warning_messages(w for w in caught if not issubclass(w.category, CommandUnitsWarning))


def k_steps(log: pd.DataFrame, seconds: float | None) -> int | None:
    """Samples in ``seconds`` at the typical step of the log's runs
    (:func:`~nnid.datasets.log.frame_step`: the joins between them left out)."""
    if seconds is None:
        return None
    dt = frame_step(log)
    return max(1, round(seconds / dt))


def k_step_seconds(log: pd.DataFrame, k: int | None) -> float | None:
    """The horizon ``k`` samples ahead are in ``log``'s seconds (its typical step,
    :func:`~nnid.datasets.log.frame_step`): what a k-step score of that log predicted, which
    a k_step_s rounded to samples (0.25 s at 10 Hz: 2 samples, 0.2 s), or a part sampled at
    another rate than the one k was taken from, is not. None without k or a step."""
    if not k or len(log) < 2:
        return None
    dt = frame_step(log)
    return k * dt if np.isfinite(dt) else None


def diverged_training(description: dict) -> list[str]:
    """The warnings for training stages that kept their start: those that ended on a
    non-finite loss, and those whose every validation free run diverged, the start's included
    (early stopping measured nothing to keep). Either way the scores are of the model before
    the stage (a hybrid's network untrained, its force zero), which a report, a batch row or
    the loop must not read as a trained one."""
    stages = training_stages(description)
    said = []
    for stop, what in (
        ("non-finite loss", "training diverged in {} (the loss became non-finite)"),
        ("validation diverged", "every validation free run diverged in {}, its start's too, "
         "so early stopping measured nothing"),
    ):  # fmt: skip
        broke = [s["stage"] for s in stages if s["stop"] == stop]
        if broke:
            said.append(
                what.format(", ".join(dict.fromkeys(broke)))
                + ": that stage kept its start, so the scores are those of the model before it"
            )
    return said


def without_skill(part: str, scores: dict) -> list[str]:
    """The warning for a free run whose total NRMSE on ``part`` is above 1: the model
    simulates those data no better than their mean (BlueROV1's held-out 1.02 went unsaid)."""
    total = (scores.get("free_run_nrmse") or {}).get("total")
    if total is None or total <= 1.0:
        return []
    return [
        f"the {part} free-run NRMSE is {total:.3g}, above 1: the model simulates the {part} "
        "data no better than their mean"
    ]


def unscored_k_step(
    part: str, log: pd.DataFrame, scores: dict, cfg, model, warmup_samples: int | None = None
) -> list[str]:
    """The warning for a held-out part none of whose k-step predictions was scored, with the
    horizon that would score one: a prediction k samples ahead is scored from the run's
    sample w + k − 1 on (w the model's own warm-up samples, or a comparison's longer common
    ``warmup_samples``; :func:`nnid.evaluation.evaluate.evaluate`), so the longest run of n
    samples scores k up to n − w (the report says "not scored"; this says why)."""
    if scores.get("k_step_scored") != 0 or not len(log):
        return []
    longest = max(len(pos) for _, pos in experiment_rows(log))
    own = max(int(model.warmup_samples_), int(warmup_samples or 0))
    whose = (
        "the model's own warm-up"
        if own == model.warmup_samples_
        else "the comparison's warm-up, the longest of its models'"
    )
    if longest <= own or len(log) < 2:
        advice = f"no k_step_s would: its runs are no longer than {whose}"
    else:
        dt = frame_step(log)
        advice = f"a k_step_s of at most {(longest - own) * dt:.4g} s would score it"
    return [
        f"k_step_s = {cfg.k_step_s:g} s: no {part} run is long enough for a k-step prediction "
        f"(the longest has {longest} samples, {own} of them {whose}), so the "
        f"{part} part's k-step error was not scored; {advice}"
    ]


def score(
    model,
    log: pd.DataFrame,
    cfg,
    k: int | None,
    replay: Replay | None = None,
    predictions: dict | None = None,
    at: tuple[str, Any] | None = None,
    warmup_samples: int | None = None,
) -> dict:
    """The scores of one split (one-step, k-step when asked, free run); the model's refusals
    named under ``at``, (section, config table), as :func:`named_in` names them;
    ``warmup_samples``: :func:`~nnid.evaluation.evaluate.evaluate`'s (a comparison's common
    warm-up)."""
    modes = ("one_step", "k_step", "free_run") if k else ("one_step", "free_run")
    with np.errstate(all="ignore"), named_in(*at) if at else nullcontext():
        out = evaluate(model, log, modes, k, cfg.warmup_s, replay, predictions, warmup_samples)
    if k:  # beside its samples ("k_step"): the horizon scored, in this part's seconds
        out["k_step_s"] = k_step_seconds(log, k)
    return out


def replay_of(inputs: Inputs, log: pd.DataFrame) -> Replay | None:
    """The autopilot replay of a log simulated under the simulator's autopilot: the
    open-loop inputs of its experiments regenerated from the simulate config."""
    sim = inputs.simulation
    if sim is None or sim.autopilot is None:
        return None
    from nnid.datasets.simulator import open_loop_inputs

    return Replay(sim.autopilot, open_loop_inputs(sim, log))


def unreplayed(cfg: CompareConfig, inputs: Inputs, replay: Replay | None) -> list[str]:
    """The warning that a compare config's ``replay_autopilot = true``, written, replays
    nothing on this log (``replay`` None), else none. The replay regenerates the autopilot's
    open-loop inputs from the simulate config that flew the log, which a log file has not; the
    key is said, not refused, as a config runs on any log (``--data``), flown under an
    autopilot or not, and the default (true, unwritten) replays where there is one."""
    if replay is not None or not cfg.replay_autopilot:
        return []
    if "replay_autopilot" not in cfg.model_fields_set:
        return []
    lacks = (
        "its simulate config has no [autopilot] table"
        if inputs.simulation is not None
        else "it is a log file, not a [data] simulate config run here, whose autopilot the "
        "replay regenerates"
    )
    return [
        f"replay_autopilot = true, but the log was flown under no autopilot to replay ({lacks}): "
        "every model's free run and k-step predictions are driven by the logged inputs, open loop"
    ]


@dataclass
class TrainResult:
    model: Any
    metrics: dict
    report: CleaningReport
    split: Split
    figures: dict = field(default_factory=dict)  # data of the report's figures
    monitor: Any = None  # the calibrated fault monitor of a config with [detect]


def run_train(
    cfg: TrainConfig,
    config_path: Path,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    progress: Progress | None = None,
    time_unit: str | None = None,
) -> TrainResult:
    """Fit the configured model on the training split; score it on every split."""
    start = time.perf_counter()
    source = str(config_path)
    inputs, loaded = loaded_inputs(
        cfg, config_path, [cfg.model], data, vehicle, columns, time_unit=time_unit
    )
    if cfg.detect is not None:
        check_detect_window(cfg.detect.window_s, inputs.log, source)
    model = build_model(cfg.model, inputs, cfg.warmup_s)
    named = None  # the names the fit will estimate, where the settings give them
    if cfg.reference:
        with named_in("model", cfg.model):  # a bad setting they come from, as the fit says it
            named = model.parameter_names()
    if named is not None:  # before the fit, which may take hours
        check_reference(cfg.reference, named, source)
    replay = replay_of(inputs, inputs.log)
    read, said = read_motion([model], inputs.log, replay), None
    if cfg.detect is not None:  # and what the monitor it calibrates reads
        read, said = _monitored_motion(read, inputs.log)
    split = make_split(
        inputs.log, cfg.split, source, inputs.report, cfg.warmup_s, inputs.source, read, said
    )
    check_savgol_window(cfg.model, model, split, "model", members_scored=True)
    check_damping_unknowns(cfg.model, inputs, "model")
    caught = fit_model(model, split, progress or silent, "model", cfg.model, replay)
    if cfg.reference and named is None:  # only the fit names them
        check_reference(cfg.reference, list(model.params), source)
    if hasattr(model, "report_"):
        for step in model.report_.steps:
            inputs.report.add(step.step, "training split: " + step.detail, step.rows_removed)
    k = k_steps(split.validation, cfg.k_step_s)
    description = model.describe()
    at = ("model", cfg.model)
    metrics: dict[str, Any] = {
        "model": model.kind,
        "trainer": model.trainer_name(),
        "vehicle": getattr(inputs.vehicle, "name", None),
        "params": _params(model, inputs.vehicle),
        "n_params": model.n_params,
        "settings": encode_setting(model.get_params(deep=False)),
        "train": score(model, split.train, cfg, k, replay, at=at),
        "validation": score(model, split.validation, cfg, k, replay, at=at),
        "validation_used_for": model.validation_use,
        "describe": {key: v for key, v in description.items() if key != "params"},
        "warnings": list(dict.fromkeys([*loaded, *caught])),
        "split": split.record,
        "warmup_s": cfg.warmup_s,
        # the horizon as asked; the one scored is k_step_samples, taken at the validation
        # part's step, and each part's k_step_s (those samples in its own seconds)
        "k_step_s": cfg.k_step_s,
        "k_step_samples": k,
    }
    parts = [p for p in ("validation", "test") if len(split[p])]
    if "test" in parts:
        metrics["test"] = score(model, split.test, cfg, k, replay, at=at)
    for p in parts:
        metrics["warnings"] += unscored_k_step(p, split[p], metrics[p], cfg, model)
        metrics["warnings"] += without_skill(p, metrics[p])
    went = metrics["train"].get("diverged") or {}
    if went:  # unstable on the data it was fitted on: the held-out scores are not the story
        first = min(went.values())
        metrics["warnings"].append(
            f"the free run on the training data diverged ({', '.join(went)} from t = "
            f"{first:.3g} s): the model is unstable on the data it was fitted on"
        )
    metrics["warnings"] += diverged_training(description)
    base = model.baseline()
    if base is not None:
        metrics["baseline"] = {
            "model": base.kind,
            "trainer": base.trainer_name(),
            "n_params": base.n_params,
            **{p: score(base, split[p], cfg, k, replay, at=at) for p in parts},
        }
    if model.kind == "ensemble":  # the spread behind the combined prediction, per member
        metrics["members"] = [
            {"seed": seed, **{p: score(member, split[p], cfg, k, replay) for p in parts}}
            for seed, member in zip(model.member_seeds_, model.members_, strict=True)
        ]
    figures: dict[str, Any] = {}
    if model.kind == "hybrid":
        metrics["correction"] = _correction(model, split, parts, figures)
    if cfg.reference:
        metrics["reference"] = {"label": cfg.reference_label, "values": cfg.reference}
    if cfg.nondimensional_speed:
        metrics["nondimensional"] = _nondimensional(
            model.params, inputs.vehicle, cfg.nondimensional_speed
        )
    monitor = None
    if cfg.detect is not None:
        monitor, metrics["detect"], said = _calibrate_monitor(model, split, cfg.detect)
        metrics["warnings"] = list(dict.fromkeys([*metrics["warnings"], *said]))
    metrics["seconds"] = time.perf_counter() - start
    return TrainResult(model, metrics, inputs.report, split, figures, monitor)


def check_reference(reference: dict[str, float], fitted: Sequence[str], source: str) -> None:
    """Each key of a train config's ``[reference]`` table a parameter the model fitted
    (``fitted``), or the error naming the key and the closest fitted name: a typo
    (``Z_wdott``) was kept in metrics.json and compared with nothing."""
    for key in reference:
        if key in fitted:
            continue
        close = difflib.get_close_matches(key, fitted, n=1)
        hint = (
            f"did you mean {close[0]!r}?"
            if close
            else f"it fitted {', '.join(fitted)}"
            if fitted
            else "this model has no named parameters"
        )
        raise NnidInputError(
            f"{key!r} names no parameter the model fitted, so it would be compared with "
            f"nothing; {hint}",
            source=source,
            field=f"reference.{key}",
        )


def check_detect_window(window_s: float, log: pd.DataFrame, source: str) -> None:
    """``[detect] window_s`` within the longest run of the healthy log it is set beside: the
    isolation window is the data after an alarm in its own run that its isolation reads, and
    no alarm is raised inside it (:func:`nnid.fault.detect.detect`), so one longer than every
    run reaches each run's end and leaves it watched only up to its first alarm (1e308 s was
    taken; so was a window longer than each run, measured against all of them together)."""
    longest = max(run_spans(log))
    if window_s > longest:
        raise NnidInputError(
            f"{window_s:g} s is longer than the longest run of the log ({longest:.4g} s): the "
            "isolation window after an alarm is some seconds of the alarm's own run (several "
            "manoeuvres), and no new alarm is raised inside it, so one past the end of every run "
            "would leave each run watched only up to its first alarm",
            source=source,
            field="detect.window_s",
        )


def _monitored_motion(
    read: Sequence[str], log: pd.DataFrame
) -> tuple[list[str], tuple[str, str, str]]:
    """The motion columns masked for a config with [detect]: those its model reads (``read``,
    :func:`read_motion`) and those the monitor's residual reads on every row
    (:func:`~nnid.fault.monitor.monitor_motion`: ν and the attitude, Fossen eq. 2), and how
    an unread one is said (:func:`~nnid.datasets.gaps.say_unread`). Every column was masked,
    so a 1-Hz GPS x, y beside a 20-Hz DVL refused the training; the calibration holds an
    empty pose cell as detect does (:func:`~nnid.fault.monitor.monitor_inputs`)."""
    from nnid.fault.monitor import RESIDUAL, monitor_motion

    watched = {*read, *monitor_motion(log.columns)}
    said = (
        f"neither the model of this run nor {RESIDUAL} reads",
        "the fit, the scores and the monitor's calibration, which read",
        "a simulated pose starts from, and the monitor holds, its run's last sample before "
        "(else its first after)",
    )
    return [c for c in MOTION if c in watched], said


def _calibrate_monitor(model, split: Split, spec) -> tuple[Any, dict, list[str]]:
    """A residual monitor calibrated on the validation part, its false alarms measured on the
    test part (when the split has one), and the warnings of calibrating it (a target rate the
    thresholds do not control): kept in ``metrics.json`` and its reports, not only said on
    the console."""
    from nnid.fault.monitor import ResidualMonitor

    if len(split.validation) == 0:
        raise NnidInputError(
            "[detect] calibrates on the validation part: give the split a validation fraction",
            field="split.fractions",
        )
    settings = spec.model_dump(exclude={"window_s"})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        monitor = ResidualMonitor(model, **settings).fit(split.validation)
    out: dict[str, Any] = {
        "settings": spec.model_dump(),
        "thresholds": monitor.thresholds_,
        "calibration": monitor.calibration_,
    }
    if len(split.test):
        out["test_false_alarms"] = monitor.measure_false_alarms(split.test)
    return monitor, out, _fit_warnings(caught)


def _correction(model, split: Split, parts: list[str], figures: dict) -> dict:
    """What a hybrid's network learned: its force against the physics' damping force on each
    split, and its dominant terms named in the effect vocabulary (on the training split)."""
    from nnid.loop.explain import explain

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        explanation = explain(model, split.train)
    # kept in metrics.json beside the terms they qualify, not dropped and not printed twice
    explanation.notes.extend(warning_messages(caught))
    held = split[parts[-1]]
    figures["correction"] = (held, model.correction(held))
    figures["baseline_free_run"] = model.baseline().predict(held)
    figures["free_run"] = model.predict(held)
    return {
        "share_of_damping_force": {p: model.correction_share(split[p]) for p in ("train", *parts)},
        "explanation": explanation.as_dict(),
    }


def _params(model, vehicle) -> dict:
    """The model's parameters, with the value the vehicle file declares for each (the truth of
    a simulation, a prior otherwise) where it names one."""
    from nnid.physics.parts import Parts

    params = model.params
    if vehicle is None or model.kind not in PHYSICS_KINDS:
        return params
    declared = Parts.from_vehicle(vehicle)
    out = {}
    for name, entry in params.items():
        try:
            file_value: float | None = declared.get(name)
        except KeyError:  # an estimate with no vehicle-file value (Caccia's W − B)
            file_value = None
        out[name] = {**entry, "vehicle_file": file_value}
    return out


def _nondimensional(params: dict, vehicle, speed: float) -> dict:
    """Prime-system I forms of the added masses and damping coefficients (Weiss eqs 111-122)."""
    from nnid.physics.nondimensional import added_mass_scale, damping_scale

    out: dict[str, Any] = {"speed": speed, "length": vehicle.length, "params": {}}
    for name, entry in params.items():
        if entry["value"] is None:
            continue
        if name.endswith("dot") and ":" not in name:
            scale = added_mass_scale(name, vehicle.rho, vehicle.length)
        elif ":" in name:
            scale = damping_scale(name, vehicle.rho, vehicle.length, speed)
        else:
            continue
        se = entry["stderr"]
        out["params"][name + "'"] = {
            "value": entry["value"] / scale,
            "stderr": None if se is None else se / scale,
            "excited": entry.get("excited", True),
            # learnt before a recursive estimator's memory: not fitted to noise
            **({"remembered": True} if entry.get("remembered") else {}),
        }
    return out


# -- compare -------------------------------------------------------------------------------------


@dataclass
class CompareResult:
    comparison: dict
    held_out: pd.DataFrame
    free_runs: dict[str, pd.DataFrame]
    forces: dict[str, pd.DataFrame]
    #: each damping model's own force series τ̄ on the held-out data: a model's smoothing
    #: settings (savgol_window, savgol_order, filter_lambda, zoh_midpoint) make its own, so one
    #: series for all drew every model against the last model's τ̄
    measured_force: dict[str, pd.DataFrame]
    report: CleaningReport


def run_compare(
    cfg: CompareConfig,
    config_path: Path,
    data: str | None = None,
    vehicle: str | None = None,
    columns: str | None = None,
    progress: Progress | None = None,
    time_unit: str | None = None,
) -> CompareResult:
    """Fit every ``[[models]]`` entry on the training split and score them all on the same
    held-out experiments (the test split when there is one, else validation): one-step,
    k-step and free-run NRMSE per DOF, J and J/J₀ for models with a force equation, parameter
    count and fit seconds. Ranked by held-out free-run NRMSE (models whose free run diverged
    last, by their k-step error)."""
    start = time.perf_counter()
    report = progress or silent
    source = str(config_path)
    inputs, said = loaded_inputs(
        cfg, config_path, list(cfg.models), data, vehicle, columns, time_unit=time_unit
    )
    models = [build_model(spec, inputs, cfg.warmup_s) for spec in cfg.models]
    replay = replay_of(inputs, inputs.log) if cfg.replay_autopilot else None
    said = [*said, *unreplayed(cfg, inputs, replay)]
    read = read_motion(models, inputs.log, replay)
    split = make_split(
        inputs.log, cfg.split, source, inputs.report, cfg.warmup_s, inputs.source, read
    )
    check_held_stepped(inputs, split, [m.fitted for m in cfg.models])
    for i, (spec, model) in enumerate(zip(cfg.models, models, strict=True)):
        check_savgol_window(spec, model, split, f"models.{i}")
        check_damping_unknowns(spec, inputs, f"models.{i}")
    held_name = "test" if len(split.test) else "validation"
    held = split[held_name]
    k = k_steps(held, cfg.k_step_s)
    fits = []
    for i, (spec, model) in enumerate(zip(cfg.models, models, strict=True)):
        name = spec.label()
        report(i, len(cfg.models), f"fitting {name}")
        t0 = time.perf_counter()
        caught = fit_model(model, split, staged(progress, name), f"models.{i}", spec, replay)
        fits.append((caught, time.perf_counter() - t0))
    # every model scored after the longest warm-up of them all: each after its own scored a
    # NARX of 4 delays on fewer samples per run than a physics model, a ranking of errors
    # over different samples
    initial = common_warmup(models)
    rows, free_runs, forces, measured_force = [], {}, {}, {}
    for i, (spec, model, (caught, seconds)) in enumerate(
        zip(cfg.models, models, fits, strict=True)
    ):
        name = spec.label()
        description = model.describe()
        row: dict[str, Any] = {
            "name": name,
            "kind": model.kind,
            "trainer": model.trainer_name(),
            "n_params": model.n_params,
            "seconds": seconds,
            "validation_used_for": model.validation_use,
            # its own initial samples per run; it is scored after the comparison's
            # warmup_samples, the longest of them
            "warmup_samples": int(model.warmup_samples_),
            "warnings": caught,
            # how each stage ended: a model whose fit stalled or ran out of epochs is not
            # ranked as if it had converged without the page saying so
            "training": training_stages(description),
        }
        if model.has_force_equation:
            with named_in(f"models.{i}", spec):
                train_force = evaluate(model, split.train, (), None, cfg.warmup_s)
            row["train"] = {
                "J": train_force["J"],
                "J0": train_force["J0"],
                "J_over_J0": train_force["J_over_J0"],
            }
        else:
            row["train"] = {}
        predicted: dict[str, pd.DataFrame] = {}
        row["validation"] = score(
            model,
            split.validation,
            cfg,
            k,
            replay,
            predicted if held_name == "validation" else None,
            at=(f"models.{i}", spec),
            warmup_samples=initial,
        )
        if held_name == "test":
            row["test"] = score(
                model, held, cfg, k, replay, predicted, (f"models.{i}", spec), initial
            )
        row["warnings"] += unscored_k_step(held_name, held, row[held_name], cfg, model, initial)
        kept_start = diverged_training(description)
        row["warnings"] += kept_start
        row["training_diverged"] = bool(kept_start)  # ranked after every trained model
        rows.append(row)
        free_runs[name] = predicted["free_run"]
        with np.errstate(all="ignore"):
            if model.kind in DAMPING_KINDS and model.has_force_equation:
                resid, series = model.residual(held), model.force_series(held)
                forces[name] = series - resid
                measured_force[name] = series
        for key, value in _coefficients(model).items():
            row[key] = value
    report(len(cfg.models), len(cfg.models), "scoring done")
    ranking = rank(rows, held_name)
    shared = ranked_columns(rows, held_name)
    by_run = run_columns(rows, held_name, shared)
    for row in rows:
        row["ranked_nrmse"] = {
            mode: ranked_score(row, held_name, f"{mode}_nrmse", shared)
            for mode in ("free_run", "k_step", "one_step")
        }
        # each held-out run's free run over its shared outputs: the spread the verdict reads
        row["ranked_free_run_per_experiment"] = ranked_runs(row, held_name, by_run)
    comparison = {
        "vehicle": getattr(inputs.vehicle, "name", None),
        "models": rows,
        "k_step_s": k_step_seconds(held, k),
        "k_step_samples": k,
        "warmup_s": cfg.warmup_s,
        # the initial samples of each run no model is scored on: the longest warm-up among
        # the models (their own under each row's warmup_samples), so all share their samples
        "warmup_samples": initial,
        "held_out": held_name,
        "ranking": ranking,
        # the outputs the ranking's scores average (ranked_nrmse); none shared: not ranked
        "ranked_on": shared,
        # each held-out run's of them (a run exciting u alone is compared on u)
        "ranked_on_per_experiment": by_run,
        "train": [e["experiment"] for e in split.record["parts"]["train"]],
        "validation": [e["experiment"] for e in split.record["parts"]["validation"]],
        "test": [e["experiment"] for e in split.record["parts"]["test"]],
        # "block": each part a block of every run above (fractions), not whole runs
        "split_by": split.record["by"],
        "fractions": split.record["fractions"],
        "autopilot_replay": replay is not None,
        # whether the data tell the first two apart (summary's rule), with its counts
        "verdict": verdict(rows, ranking, held_name),
        "summary": summary(rows, ranking, held_name, replay is not None)
        + _masked_note(inputs.report, rows, ranking, held_name, len(held)),
        "warnings": said,
        "seconds": time.perf_counter() - start,
    }
    return CompareResult(comparison, held, free_runs, forces, measured_force, inputs.report)


def _masked_note(report, rows: list[dict], ranking: list[str], part: str, n: int) -> str:
    """Where gaps in the motion data were masked, the sentence that says so beside the
    ranking: each free run restarts after a gap, so on a log of dense gaps the free-run scores
    are of runs a few seconds long, over a part of the held-out samples (a gappy log scored
    0.096 where the clean one scored 0.114, over 145 of ~1200 samples, and compare did not
    say it)."""
    from nnid.datasets.gaps import MASK_STEP

    masked = [s for s in (report.steps if report is not None else []) if s.step == MASK_STEP]
    if not masked or not ranking:
        return ""
    best = next(r for r in rows if r["name"] == ranking[0])
    scored = best.get(part, {}).get("samples")
    counted = (
        f"; {scored} of the {n} {part} samples left are scored (the rest warm the pieces up)"
        if scored is not None
        else ""
    )
    return f" The log's gaps: {masked[0].detail}{counted}."


def _coefficients(model) -> dict:
    """Extra per-model material of damping models: coefficients, and SINDy's path."""
    out: dict[str, Any] = {}
    if model.kind in ("synthesis", "sindy") and getattr(model, "mode", "residual") == "residual":
        # with their standard errors, as metrics.json's params: the value alone dropped them
        out["coefficients"] = {
            k: {"value": v["value"], "stderr": v.get("stderr")} for k, v in model.params.items()
        }
    if model.kind == "sindy":
        out["sindy_path"] = model.path_
    return out


def ranked_columns(rows: list[dict], part: str) -> list[str]:
    """The outputs every model is scored on in ``part``, in the first model's order: a total
    over other outputs than another model's is not comparable with it (a NARX of w alone
    against a Fossen model's six DOFs). A model scored on nothing (its outputs not in the
    log) does not empty the set: it ranks last."""
    scored = [s for s in (row.get(part, {}).get("columns", []) for row in rows) if s]
    return [c for c in scored[0] if all(c in s for s in scored[1:])] if scored else []


def ranked_score(row: dict, part: str, key: str, columns: list[str]) -> float | None:
    """A model's NRMSE of one mode over ``columns`` (:func:`ranked_columns`): its own
    ``total`` where it is scored on exactly those, else their mean; None where one was not
    measured, or none is shared, or the model diverged in any output, shared or its own (a
    free run that left for 1e6 m/s in r is no simulation of the log, whatever its u)."""
    scores = row.get(part, {}).get(key)
    if not scores or not columns or diverged_columns(row[part], key):
        return None
    if set(row[part].get("columns", [])) == set(columns):
        return scores.get("total")
    vals = [scores.get(c) for c in columns]
    return exact_mean(vals) if all(v is not None for v in vals) else None


def rank(rows: list[dict], part: str) -> list[str]:
    """Names best first: held-out free-run NRMSE over the outputs every model is scored on
    (:func:`ranked_columns`); a model whose free run diverged (or was not scored) after every
    model whose free run was measured, ordered by its k-step NRMSE; a model whose training
    kept its start (``training_diverged``: its scores are the untrained model's) after every
    trained one. Models that share no output are not ranked: their order is the config's."""
    columns = ranked_columns(rows, part)
    if not columns:
        return [r["name"] for r in rows]

    def key(row: dict) -> tuple:
        free = ranked_score(row, part, "free_run_nrmse", columns)
        k = ranked_score(row, part, "k_step_nrmse", columns)
        one = ranked_score(row, part, "one_step_nrmse", columns)
        untrained = bool(row.get("training_diverged"))
        if free is not None:
            return (untrained, 0, free)
        if k is not None:
            return (untrained, 1, k)
        return (untrained, 2, one if one is not None else np.inf)

    return [r["name"] for r in sorted(rows, key=key)]


def run_columns(rows: list[dict], part: str, columns: list[str]) -> dict[str, list[str]]:
    """Each held-out run's outputs the models are compared on: those of ``columns``
    (:func:`ranked_columns`) that every model scored in that run, the same for all. A run
    that does not excite every ranked output (Weiss's surge and sway runs, each moving one
    of u and v) is compared on those it does: over all of them it had no score, and its
    lead counted for nothing. Empty where the held-out data are one run."""
    scored: dict[str, list[set]] = {}
    for row in rows:
        for run, vals in (row.get(part, {}).get("free_run_nrmse_per_experiment") or {}).items():
            scored.setdefault(run, []).append(set(vals) - {"total"})
    return {run: [c for c in columns if all(c in s for s in sets)] for run, sets in scored.items()}


def ranked_runs(row: dict, part: str, by_run: dict[str, list[str]]) -> dict[str, float | None]:
    """Each held-out run's free-run NRMSE of a model scored on its own
    (``free_run_nrmse_per_experiment``), over the run's outputs of ``by_run``
    (:func:`run_columns`) as :func:`ranked_score` takes the pooled one: None where the
    model diverged in that run, or the run has no output every model scored. Empty where
    the held-out data are one run."""
    held = row.get(part, {})
    left = held.get("diverged_per_experiment") or {}
    out = {}
    for run, vals in (held.get("free_run_nrmse_per_experiment") or {}).items():
        own = {
            "columns": [c for c in vals if c != "total"],
            "free_run_nrmse": vals,
            diverged_key("free_run"): left.get(run, {}),
        }
        out[run] = ranked_score({part: own}, part, "free_run_nrmse", by_run.get(run, []))
    return out


#: the fewest held-out runs on which the count of runs a model is lower on decides the
#: verdict alone (:func:`verdict`): on fewer, two printed scores that read the same do too
RUNS_DECIDE = 3


def verdict(rows: list[dict], ranking: list[str], part: str) -> dict | None:
    """Whether the data tell the first two trained models with a measured free run apart.
    With :data:`RUNS_DECIDE` or more held-out runs both are measured on, the runs decide: the
    first is named where it is lower than the second on at least two thirds of them
    (``lower_on_runs`` of ``runs``), else the two are *indistinguishable*, whatever the
    pooled scores (a pooled 0.2131 against 0.2134 is no tie when the first is lower on 10 of
    10 runs, and a pooled lead a hair wide is no win when the other model does better on as
    many runs). On fewer runs they are indistinguishable when their free-run NRMSEs print the
    same (3 significant figures, as the ranking shows them), or, on two runs, when the first
    is not lower on both. Each run is scored over its own outputs (:func:`run_columns`).
    None where there are not two such models."""
    columns = ranked_columns(rows, part)
    by_name = {r["name"]: r for r in rows}
    measured = [
        n
        for n in ranking
        if not by_name[n].get("training_diverged")
        and ranked_score(by_name[n], part, "free_run_nrmse", columns) is not None
    ]
    if not columns or len(measured) < 2 or measured[0] != ranking[0]:
        return None
    first, second = (by_name[n] for n in measured[:2])
    a = ranked_score(first, part, "free_run_nrmse", columns)
    b = ranked_score(second, part, "free_run_nrmse", columns)
    by_run = run_columns(rows, part, columns)
    runs_a, runs_b = ranked_runs(first, part, by_run), ranked_runs(second, part, by_run)
    both = [r for r in runs_a if runs_a[r] is not None and runs_b.get(r) is not None]
    lower = sum(runs_a[r] < runs_b[r] for r in both)
    same = number(a, 3) == number(b, 3)
    split = len(both) >= 2 and 3 * lower < 2 * len(both)
    return {
        "first": first["name"],
        "second": second["name"],
        "first_free_run": a,
        "second_free_run": b,
        "runs": len(both),
        "lower_on_runs": lower,
        "same_printed": same,
        "indistinguishable": split if len(both) >= RUNS_DECIDE else same or split,
    }


def above_one(x: float) -> str:
    """``x`` to 3 significant figures, or as many more as it takes not to print 1 where it is
    not 1: a sentence that says a score "is above 1" printed 1.0004 as "1"."""
    text = number(x, 3)
    for digits in range(4, 18):
        if x == 1.0 or float(text) != 1.0:
            break
        text = number(x, digits)
    return text


def unscored_reasons(rows: list[dict], names: list[str], part: str) -> dict[str, list[str]]:
    """``{why: [model, ...]}`` of models whose free run is missing without a divergence, from
    evaluate's ``free_run_not_scored``: no sample after the warm-ups, no output scored, or an
    output constant on the held-out data."""
    columns = ranked_columns(rows, part)
    out: dict[str, list[str]] = {}
    for row in (r for r in rows if r["name"] in names):
        why = row.get(part, {}).get(not_scored_key("free_run")) or {}
        reasons = [why["total"]] if "total" in why else []
        reasons += [f"{c} {why[c]}" if why[c] == CONSTANT else why[c] for c in columns if c in why]
        out.setdefault(reasons[0] if reasons else "not measured", []).append(row["name"])
    return out


def summary(rows: list[dict], ranking: list[str], part: str, replay: bool) -> str:
    """One sentence: which model to use and why. The first model is named for use only where
    the data tell it from the second (:func:`verdict`); else the sentence says the two are
    indistinguishable and why."""
    columns = ranked_columns(rows, part)
    if not columns:
        scored = "; ".join(
            f"{r['name']}: {', '.join(r.get(part, {}).get('columns', [])) or 'none'}" for r in rows
        )
        return (
            f"These models are scored on no output in common on the {part} data ({scored}): "
            "they are not ranked; compare them output by output."
        )
    by_name = {r["name"]: r for r in rows}
    shared = any(set(r.get(part, {}).get("columns", [])) != set(columns) for r in rows)
    over = f" over the outputs every model is scored on ({', '.join(columns)})" if shared else ""

    def total(row: dict, key: str) -> float | None:
        return ranked_score(row, part, key, columns)

    best = by_name[ranking[0]]
    untrained = [n for n in ranking if by_name[n].get("training_diverged")]
    notes = (
        f" Training kept its start, so these scores are of the untrained model (ranked after "
        f"the trained ones): {', '.join(untrained)}."
        if untrained
        else ""
    )
    # ranked on the validation part that some fits stopped or selected on: said beside the
    # verdict, not only in a table column (the model to use was named on it without a word)
    fitted_on = {n: by_name[n].get("validation_used_for") for n in ranking}
    used = [f"{n} ({u})" for n, u in fitted_on.items() if u and part == "validation"]
    if used:
        notes += (
            f" The fits of {', '.join(used)} used the validation data: their scores on it are "
            "not independent of the fit (a test part would rank every model on data no fit saw)."
        )
    if best.get("training_diverged"):  # every model: none is recommended on its start
        return (
            f"No model finished training: every one kept its start ({', '.join(untrained)}), "
            f"so no score on the {part} data is of a trained model; see the warnings."
        )
    free = total(best, "free_run_nrmse")
    loop = " flown under the log's autopilot" if replay else ""
    missing = [n for n in ranking if total(by_name[n], "free_run_nrmse") is None]
    # a None free run diverged, or had nothing left to score (a run shorter than the warm-up)
    diverged = [n for n in missing if diverged_columns(by_name[n].get(part, {}), "free_run_nrmse")]
    unscored = [n for n in missing if n not in diverged]
    if free is None:
        k = total(best, "k_step_nrmse")
        one = total(best, "one_step_nrmse")
        # the best is trained: so is every model this sentence speaks of, where an untrained
        # one (ranked after) has a free run of its start (it said "Every free run diverged"
        # of a comparison where the untrained model's was scored)
        trained = " of a trained model" if untrained else ""
        if unscored:
            said = ([f"diverged: {', '.join(diverged)}"] if diverged else []) + [
                f"not scored, {why}: {', '.join(names)}"
                for why, names in unscored_reasons(rows, unscored, part).items()
            ]
            lead = (
                f"No free run{trained}{loop} was scored on the {part} data{over} "
                f"({'; '.join(said)})"
            )
            conclusion = "how these models simulate this log was not measured"
        else:
            lead = f"Every free run{trained}{loop} diverged on the {part} data{over}"
            conclusion = f"none of these {'trained ' if untrained else ''}models simulates this log"
        if k is None and one is None:  # nothing was measured: no model is ranked first
            return f"{lead}, and no other error was measured: {conclusion}.{notes}"
        what = f"k-step NRMSE ({k:.3g})" if k is not None else f"one-step NRMSE ({one:.3g})"
        return (
            f"{lead}; {best['name']} ({best['kind']}, {best['n_params']} parameters) has the "
            f"lowest {what}: {conclusion}.{notes}"
        )
    others = [
        by_name[n]
        for n in ranking[1:]
        if total(by_name[n], "free_run_nrmse") is not None and n not in untrained
    ]
    told = verdict(rows, ranking, part)
    runs = (
        f"; {best['name']} lower on {told['lower_on_runs']} of {told['runs']} held-out runs"
        if told and told["runs"] >= 2
        else ""
    )
    if free > 1.0:  # below the mean's own error nothing is recommended (train says it too)
        sentence = (
            f"No trained model has skill on the {part} data: the lowest trained free-run "
            f"NRMSE{loop}{over}, {best['name']}'s ({best['kind']}, {best['n_params']} "
            f"parameters: {above_one(free)}"
        )
    elif told and told["indistinguishable"]:
        nxt = by_name[told["second"]]
        sentence = (
            f"{best['name']} ({best['kind']}, {best['n_params']} parameters) and {nxt['name']} "
            f"({nxt['kind']}, {nxt['n_params']} parameters) are indistinguishable on the "
            f"free-run NRMSE{loop} on the {part} data{over} ({number(free, 3)} and "
            f"{number(told['second_free_run'], 3)}{runs}): the data do not say which of the "
            "two to use."
        )
    else:
        sentence = (
            f"Use {best['name']} ({best['kind']}, {best['n_params']} parameters): the lowest "
            f"free-run NRMSE{loop} on the {part} data{over} ({number(free, 3)}"
        )
    if free > 1.0 or not (told and told["indistinguishable"]):
        if others:
            nxt = others[0]
            sentence += f", against {number(total(nxt, 'free_run_nrmse'), 3)} for {nxt['name']}"
        sentence += runs
        sentence += (
            "), is above 1: no trained model it scored predicts these data better than their mean."
            if free > 1.0
            else ")."
        )
    if diverged:
        sentence += f" Diverged in free run: {', '.join(diverged)}."
    for why, names in unscored_reasons(rows, unscored, part).items():
        sentence += f" Not scored in free run ({why}): {', '.join(names)}."
    return sentence + notes
