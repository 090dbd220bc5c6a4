"""End-to-end runs of the documented workflows, for the CLI: load or simulate the data, split
it, fit, and score on held-out data. Returns data; the CLI writes files and talks to people."""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from nnid.config import (
    DataSpec,
    FossenSpec,
    LoopConfig,
    SimulateConfig,
    SindySpec,
    TrainConfig,
    load_config,
)
from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.log import VELOCITY
from nnid.datasets.readers import load_log
from nnid.datasets.simulator import simulate_config
from nnid.datasets.splits import split_log
from nnid.errors import NnidInputError
from nnid.evaluation.metrics import excited_dofs, per_dof, rmse, warmup_mask
from nnid.physics.added_mass import DOFS, FORCES

TRAINERS = ("ls", "rls", "gradient", "ukf", "caccia")


def resolve(base: Path, path: str) -> Path:
    p = Path(path)
    return p if p.is_absolute() or p.exists() else base / p


def load_data(
    cfg: TrainConfig | LoopConfig,
    config_path: Path,
    data_override: str | None = None,
    columns_override: str | None = None,
) -> tuple[pd.DataFrame, CleaningReport]:
    """The training log: ``--data`` or the config's file, or its simulation."""
    base = config_path.parent
    if cfg.data.kind == "table":
        return _load_table(cfg, base, data_override)
    if data_override or cfg.data.log:
        path = data_override or str(resolve(base, cfg.data.log))
        cols = columns_override or (
            str(resolve(base, cfg.data.columns)) if cfg.data.columns else None
        )
        log, report = load_log(path, cols)
    elif cfg.data.simulate:
        sim_path = resolve(base, cfg.data.simulate)
        sim = load_config(sim_path, SimulateConfig)
        from nnid.vehicle import load_vehicle

        log = simulate_config(sim, load_vehicle(sim.vehicle))
        report = CleaningReport(source=str(sim_path))
        report.add("simulate", f"{len(log)} samples from {sim_path}")
    else:
        raise NnidInputError("give data.log or data.simulate (or --data)", field="data")
    if cfg.data.experiments:
        log = log[log["experiment"].isin(cfg.data.experiments)].reset_index(drop=True)
    return log, report


def _load_table(
    cfg: TrainConfig | LoopConfig, base: Path, data_override: str | None
) -> tuple[pd.DataFrame, CleaningReport]:
    """A generic input-output table (``[data] kind = "table"``) checked for the columns of the
    config's input-output model."""
    from nnid.datasets.log import validate_table
    from nnid.datasets.readers import read_table

    spec = getattr(cfg, "narx", None) or getattr(cfg, "state_space", None)
    if spec is None:
        raise NnidInputError(
            'data kind = "table" is for the input-output models (narx, state_space)',
            field="data.kind",
        )
    if not (data_override or cfg.data.log):
        raise NnidInputError('data kind = "table" needs data.log (or --data)', field="data")
    path = data_override or str(resolve(base, cfg.data.log))
    log = validate_table(read_table(path), [*spec.inputs, *spec.outputs], source=path)
    report = CleaningReport(source=path)
    report.add("read", f"{len(log)} rows, a generic input-output table")
    if cfg.data.experiments:
        log = log[log["experiment"].isin(cfg.data.experiments)].reset_index(drop=True)
    return log, report


def expand_unknowns(spec: list[str], dofs: list[str], vehicle) -> list[str]:
    """Expand the ``added_mass`` / ``damping`` shortcuts for the chosen DOFs."""
    from nnid.physics.damping import DampingTerms

    out: list[str] = []
    forces = {FORCES[DOFS.index(d)] for d in dofs}
    for item in spec:
        if item == "added_mass":
            out += [f"{FORCES[DOFS.index(d)]}_{d}dot" for d in dofs]
        elif item == "damping":
            terms = DampingTerms.from_spec(vehicle.damping.model, vehicle.damping.coefficients)
            out += [k for k in terms.as_dict() if k.split(":")[0] in forces]
        else:
            out.append(item)
    return list(dict.fromkeys(out))


def make_trainer(cfg: TrainConfig):
    """The configured trainer; with a ``sequence`` it runs each step of it (Weiss 99-108)."""
    base = _base_trainer(cfg)
    if cfg.sequence is None:
        return base
    from nnid.trainers.sequence import WEISS_STEPS, DecoupledSequence, Step

    steps = (
        WEISS_STEPS if cfg.sequence == "weiss" else [Step(**s.model_dump()) for s in cfg.sequence]
    )
    return DecoupledSequence(steps, base)


def sequence_unknowns(cfg: TrainConfig) -> tuple[list[str], list[str]] | None:
    """Unknowns and DOFs of a sequence config (the union over its steps)."""
    if cfg.sequence is None:
        return None
    from nnid.trainers.sequence import WEISS_STEPS

    steps = WEISS_STEPS if cfg.sequence == "weiss" else cfg.sequence
    unknowns = list(dict.fromkeys(n for s in steps for n in s.unknowns))
    dofs = list(dict.fromkeys(d for s in steps for d in s.dofs))
    return unknowns, dofs


def _base_trainer(cfg: TrainConfig):
    opts = dict(cfg.options)
    if cfg.trainer == "ls":
        from nnid.trainers.least_squares import LeastSquares

        return LeastSquares(**opts)
    if cfg.trainer in ("rls", "gradient"):
        from nnid.trainers import recursive

        cls = (
            recursive.RecursiveLeastSquares if cfg.trainer == "rls" else recursive.GradientEstimator
        )
        return cls(**opts)
    if cfg.trainer == "ukf":
        from nnid.trainers.ukf import UnscentedKalman

        return UnscentedKalman(**opts)
    raise NnidInputError(f"trainer '{cfg.trainer}' runs through its own config", field="trainer")


@dataclass
class TrainResult:
    model: object
    metrics: dict
    report: CleaningReport
    split: object


def make_split(log: pd.DataFrame, s) -> object:
    """The split a config asks for: named experiments (the rest trains) or fractions. A split
    with nothing to validate on is an error: scores on training data are not validation."""
    assignment = None
    if s.by == "experiment" and (s.train or s.validation or s.test):
        names = list(dict.fromkeys(log["experiment"]))
        held = set((s.validation or []) + (s.test or []))
        assignment = {
            "train": s.train or [n for n in names if n not in held],
            "validation": s.validation or [],
            "test": s.test or [],
        }
    split = split_log(log, s.by, tuple(s.fractions), assignment)
    if len(split.validation) == 0:
        raise NnidInputError(
            "the validation split is empty: hold out an experiment or a block", field="split"
        )
    return split


def run_train(
    cfg: TrainConfig,
    config_path: Path,
    vehicle,
    data_override: str | None = None,
    columns_override: str | None = None,
) -> TrainResult:
    """Fit the configured model on the training split; score it on the validation split."""
    from nnid.models.parametric import ParametricModel

    start = time.perf_counter()
    log, report = load_data(cfg, config_path, data_override, columns_override)
    split = make_split(log, cfg.split)
    unknowns = expand_unknowns(cfg.fossen.unknowns, cfg.fossen.dofs, vehicle)
    dofs = cfg.fossen.dofs
    if cfg.sequence is not None:
        unknowns, dofs = sequence_unknowns(cfg)
    model = ParametricModel(
        vehicle, unknowns, dofs, make_trainer(cfg), cfg.savgol_window, cfg.savgol_order
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.fit(split.train)
    for step in model.report_.steps:
        report.add(step.step, "training split: " + step.detail, step.rows_removed, step.columns)
    metrics = {
        "model": "fossen",
        "trainer": cfg.trainer,
        "vehicle": vehicle.name,
        "params": _params(model, cfg),
        "train": _scores(model, split.train, cfg, free_run=False),
        "validation": _scores(model, split.validation, cfg, free_run=True),
        "warnings": [str(w.message) for w in caught],
        "split": split.record,
        "warmup_s": cfg.warmup_s,
    }
    if cfg.reference:
        metrics["reference"] = {"label": cfg.reference_label, "values": cfg.reference}
    if cfg.nondimensional_speed:
        metrics["nondimensional"] = _nondimensional(model, vehicle, cfg.nondimensional_speed)
    metrics["seconds"] = time.perf_counter() - start
    return TrainResult(model, metrics, report, split)


def _params(model, cfg: TrainConfig) -> dict:
    """Estimates with standard error, percentile error, significance, and the value the
    vehicle file declares for the parameter (the truth of a simulation, a prior otherwise)."""
    from nnid.models.parametric import Parts

    declared = Parts.from_vehicle(model.vehicle)
    est = model.estimate_
    out = {}
    for name, v, s, pe in zip(est.names, est.theta, est.stderr, est.percentile_error, strict=True):
        out[name] = {
            "value": float(v) if np.isfinite(v) else None,
            "stderr": float(s) if np.isfinite(s) else None,
            "percentile_error": float(pe) if np.isfinite(pe) else None,
            "significant": bool(np.isfinite(pe) and pe <= 100 / 1.96),
            "vehicle_file": declared.get(name),
        }
    return out


def _scores(model, log: pd.DataFrame, cfg: TrainConfig, free_run: bool) -> dict:
    # derived velocities/accelerations are computed once; later calls find them in the log
    prepared, _ = model.prepare(log)
    dofs = [d for d in excited_dofs(prepared, list(VELOCITY)) if d in model.dofs]
    mask = warmup_mask(prepared, cfg.warmup_s, warmup_samples=1)
    one = model.predict(prepared, "one_step")
    out = {"one_step_nrmse": per_dof(prepared, one, dofs, mask)}
    if free_run:
        free = model.predict(prepared, "free_run")
        out["free_run_nrmse"] = per_dof(prepared, free, dofs, mask)
    resid = model.residual(prepared)
    forces = [FORCES[DOFS.index(d)] for d in dofs]
    out["force_rmse"] = {
        d: rmse(np.zeros(mask.sum()), resid[f].to_numpy()[mask])
        for d, f in zip(dofs, forces, strict=True)
    }
    out["samples"] = int(mask.sum())
    return out


def _nondimensional(model, vehicle, speed: float) -> dict:
    from nnid.physics.nondimensional import added_mass_scale, damping_scale

    out = {"speed": speed, "length": vehicle.length, "params": {}}
    for name, entry in model.params.items():
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
        }
    return out


def run_caccia_train(config_path: Path, vehicle_override: str | None = None) -> TrainResult:
    """``nnid train`` for a Caccia config: both steps, then a held-out check.

    The validation run is a fresh PRBS heave (or other DOF) experiment that neither step saw:
    the identified one-DOF model (drag, installation, inertia; restoring of the first weight
    setting) is flown against it in free run and one step ahead.
    """
    from nnid.datasets.excitation import PRBS
    from nnid.datasets.simulator import simulate
    from nnid.models.parametric import ParametricModel
    from nnid.trainers.caccia import force_to_commands, load_caccia_config, run_caccia
    from nnid.trainers.least_squares import Estimate
    from nnid.vehicle import load_vehicle

    start = time.perf_counter()
    cfg, campaign = load_caccia_config(config_path)
    vehicle = load_vehicle(vehicle_override or cfg.vehicle)
    run = run_caccia(config_path, vehicle)
    est = run.estimate
    dof = cfg.dof
    fossen = [n for n in est.names if n not in ("weight_minus_buoyancy", "delta_weight")]
    idx = [est.names.index(n) for n in fossen]
    model = ParametricModel(vehicle, fossen, [dof])
    from nnid.models.parametric import ParametricFossen

    model.structure_ = ParametricFossen(vehicle, fossen, [dof])
    model.estimate_ = Estimate(
        fossen, est.theta[idx], est.cov[np.ix_(idx, idx)], est.sigma2, est.n_obs
    )
    model.parts_ = model.structure_.parts(np.nan_to_num(model.estimate_.theta))
    if dof == "w" and "weight_minus_buoyancy" in est.names:
        wb = float(est.theta[est.names.index("weight_minus_buoyancy")])
        model.parts_.buoyancy = model.parts_.weight - wb
    # held out: a PRBS on the identified DOF, fresh noise, from the campaign's plant
    t = np.arange(0.0, 120.0, campaign.dt)
    rms_force = float(np.std(run.steady_log.filter(like="cmd_").to_numpy())) or 1.0
    amp = 0.6 * max(abs(cfg.sinusoid.offset), cfg.sinusoid.amplitude, rms_force)
    force = PRBS(channel="X", amplitude=amp, hold=8.0, duration=t[-1] + campaign.dt, seed=5)(t)
    inputs = force_to_commands(vehicle, dof, force)
    effects = [(e.name, e.value) for e in campaign.effects]
    val_log = simulate(
        vehicle,
        inputs,
        campaign.dt,
        substeps=campaign.substeps,
        effects=effects,
        measurement=campaign.measurement,
        seed=campaign.seed + 999,
        experiment="validation_prbs",
    )
    model.savgol_window = cfg.velocity_window
    train_cfg = TrainConfig(
        vehicle=vehicle.name,
        data=DataSpec(log="-"),
        warmup_s=5.0,
        fossen=FossenSpec(dofs=[dof], unknowns=fossen),
    )
    metrics = {
        "model": "fossen",
        "trainer": "caccia",
        "vehicle": vehicle.name,
        "params": {},
        "train": {"steady_state_sigma": est.dof_sigma2},
        "validation": _scores(model, val_log, train_cfg, free_run=True),
        "warnings": [],
        "split": {"train": ["campaign", "d-optimal sinusoid"], "validation": ["validation_prbs"]},
        "warmup_s": 5.0,
        "design": {
            "omega_opt": run.design.frequency(),
            "offset": run.design.offset,
            "amplitude": run.design.amplitude,
        },
    }
    from nnid.models.parametric import Parts

    declared = Parts.from_vehicle(vehicle)
    for name, v, s, pe in zip(est.names, est.theta, est.stderr, est.percentile_error, strict=True):
        metrics["params"][name] = {
            "value": float(v),
            "stderr": float(s),
            "percentile_error": float(pe),
            "significant": bool(pe <= 100 / 1.96),
            "vehicle_file": declared.get(name) if name in fossen else None,
        }
    metrics["seconds"] = time.perf_counter() - start
    report = CleaningReport(source=str(config_path))
    report.add(
        "simulate",
        f"campaign {len(run.steady_log)} samples, sinusoid "
        f"{len(run.sinusoid_log)}, validation {len(val_log)}",
    )
    return TrainResult(model, metrics, report, None)


def _without_damping(vehicle):
    """The vehicle with its declared damping removed: every compared model starts from none."""
    out = vehicle.model_copy(deep=True)
    out.damping.model = None
    out.damping.coefficients = {}
    return out


@dataclass
class CompareResult:
    comparison: dict
    t: np.ndarray
    measured: np.ndarray
    predicted: dict
    report: CleaningReport


def run_compare(
    cfg,
    config_path: Path,
    vehicle,
    data_override: str | None = None,
    columns_override: str | None = None,
    progress=None,
) -> CompareResult:
    """Fit each named damping model (masked least squares, McCarter eq. 4.20) and SINDy on the
    training split, and score them on the validation split: force error J and J/J0 (eq. 4.25)
    and the velocity error of each model flown inside the Fossen simulator."""
    from nnid.models.damping_library import LIBRARY, BasisLibrary
    from nnid.models.parametric import ParametricFossen, ParametricModel
    from nnid.trainers.synthesis import (
        force_error,
        mask_matrix,
        masked_least_squares,
        synthesis_data,
    )

    start = time.perf_counter()
    log, report = load_data(cfg, config_path, data_override, columns_override)
    split = make_split(log, cfg.split)
    bare = _without_damping(vehicle)
    library = BasisLibrary(LIBRARY, vehicle.damping.u_c or 0.0)
    form = {
        "savgol_window": cfg.savgol_window,
        "savgol_order": cfg.savgol_order,
        "filter_lambda": cfg.filter_lambda,
        "zoh_midpoint": cfg.zoh_midpoint,
    }
    xi_train, tau_train = synthesis_data(bare, split.train, library, **form)
    xi_val, tau_val = synthesis_data(bare, split.validation, library, **form)
    probe = ParametricModel(bare, [], DOFS, None, cfg.savgol_window, cfg.savgol_order)
    val_log, val_data = probe.prepare(split.validation)
    mask_val = warmup_mask(val_log, cfg.warmup_s, warmup_samples=1)
    base = ParametricFossen(bare, []).base
    _, j0_train = force_error(tau_train, 0 * tau_train)
    _, j0_val = force_error(tau_val[mask_val], 0 * tau_val[mask_val])
    dt = float(np.median(np.diff(val_log["t"].to_numpy())))
    horizon = max(1, round(cfg.horizon_s / dt))
    dofs = excited_dofs(val_log, list(VELOCITY))
    rows, predicted, coefficients = [], {}, {}
    total = len(cfg.models) + bool(cfg.sindy)

    def add(name: str, coef: np.ndarray, n_params: int) -> None:
        """Score one fitted coefficient matrix K [6, 132] over the library."""
        parts = base.copy()
        nonzero = zip(*np.nonzero(coef), strict=True)
        parts.damping = {f"{FORCES[f]}:{LIBRARY[j]}": float(coef[f, j]) for f, j in nonzero}
        j_train, _ = force_error(tau_train, xi_train @ coef.T)
        j_val, _ = force_error(tau_val[mask_val], (xi_val @ coef.T)[mask_val])
        velocity = _velocity_scores(parts, val_log, val_data, dofs, mask_val, horizon)
        rows.append(
            {
                "name": name,
                "n_params": int(n_params),
                "train": {"J": j_train, "J_over_J0": j_train / j0_train},
                "validation": {"J": j_val, "J_over_J0": j_val / j0_val, **velocity},
            }
        )
        predicted[name] = xi_val @ coef.T
        coefficients[name] = parts.damping
        if progress:
            progress(len(rows), total)

    for name in cfg.models:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # aliased terms (u > 0) warn: McCarter Table E.10
            fit = masked_least_squares(xi_train, tau_train, mask_matrix(name, LIBRARY), LIBRARY)
        add(name, fit.coefficients, int(fit.mask.sum()))
    sindy_path = []
    spec = SindySpec() if cfg.sindy is True else cfg.sindy
    if spec:
        from nnid.trainers.sindy import SindyDamping

        sindy = SindyDamping(
            bare,
            optimizer=spec.optimizer,
            thresholds=spec.thresholds,
            selection=spec.selection,
            tolerance=spec.tolerance,
        )
        ok_t = np.isfinite(xi_train).all(1) & np.isfinite(tau_train).all(1)
        ok_v = mask_val & np.isfinite(xi_val).all(1) & np.isfinite(tau_val).all(1)
        sindy.fit_features(xi_train[ok_t], tau_train[ok_t], xi_val[ok_v], tau_val[ok_v], LIBRARY)
        add("sindy", sindy.coef_, sindy.n_params)
        j0 = j0_val**2  # the path's J is a mean-square ratio per force; report RMS like J
        sindy_path = [
            {**p, "validation_J": float(np.sqrt(p["validation_J"] * j0))} for p in sindy.path_
        ]
    best = min(rows, key=lambda r: r["validation"]["J"])
    comparison = {
        "vehicle": vehicle.name,
        "models": rows,
        "sindy_path": sindy_path,
        "coefficients": coefficients,
        "train": [e["experiment"] for e in split.record["parts"]["train"]],
        "validation": [e["experiment"] for e in split.record["parts"]["validation"]],
        "train_J0": j0_train,
        "validation_J0": j0_val,
        "warmup_s": cfg.warmup_s,
        "horizon_s": horizon * dt,
        "summary": (
            f"Lowest validation force error: {best['name']} ({best['n_params']} terms, "
            f"J/J0 = {best['validation']['J_over_J0']:.3g})."
        ),
        "seconds": time.perf_counter() - start,
    }
    return CompareResult(comparison, val_log["t"].to_numpy(), tau_val, predicted, report)


def _velocity_scores(parts, val_log, val_data, dofs, mask_val, horizon) -> dict:
    """Free-run and k-step velocity NRMSE of a plant; a run that leaves the physical range
    has diverged: no number (None)."""
    from nnid.evaluation.prediction import predict_states

    scores = {}
    for mode, key in (("free_run", "free_run_nrmse"), (horizon, "k_step_nrmse")):
        with np.errstate(all="ignore"):
            pred = predict_states(parts, val_log, val_data["tau"], mode)
            vals = per_dof(val_log, pred, dofs, mask_val)
        scores[key] = {k: (v if np.isfinite(v) and v < 1e3 else None) for k, v in vals.items()}
    return scores


def _io_trainer(name: str, epochs: int, lr: float, jacobian: str):
    """The trainer of an input-output model: ``"lm"`` (trainlm defaults, Jacobians by
    ``jacobian``: "samples" for one-step residuals, "forward" for simulated ones) or
    ``"adam"``."""
    if name == "lm":
        from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

        return LevenbergMarquardt(max_epochs=epochs, jacobian=jacobian)
    from nnid.trainers.adam import Adam

    return Adam(lr=lr, max_epochs=epochs)


def _fit_io_model(model, split) -> list[str]:
    """Fit on the training split, early-stop on the validation split; the warnings raised."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        model.fit(split.train, validation_log=split.validation)
    return [str(w.message) for w in caught]


def _bounds_spec(bounds: str | list | None):
    """A config's ``output_bounds`` for the models: TOML has no null, so "open" stands for None."""
    if isinstance(bounds, list):
        return [[None if v == "open" else v for v in pair] for pair in bounds]
    return bounds


def run_narx_train(
    cfg: TrainConfig,
    config_path: Path,
    data_override: str | None = None,
    columns_override: str | None = None,
) -> TrainResult:
    """``model = "narx"``: fit a NARX network (Weiss IV.A.2, V.B) with Levenberg-Marquardt or
    Adam on the training split, early-stop on the validation split, and score one-step and
    free-run NRMSE on validation (and test, when the split holds one), delay states and
    ``warmup_s`` excluded. Missing velocity outputs are derived from the pose."""
    from nnid.models.narx import NarxModel

    spec = cfg.narx
    if spec is None:
        raise NnidInputError("model = 'narx' needs a [narx] table", field="narx")
    if cfg.trainer not in ("lm", "adam"):
        raise NnidInputError("a NARX trains with trainer = 'lm' or 'adam'", field="trainer")
    start = time.perf_counter()
    log, report = load_data(cfg, config_path, data_override, columns_override)
    if any(c not in log for c in spec.outputs) and all(a in log for a in ("phi", "theta", "psi")):
        from nnid.datasets.preprocess import derive_velocities

        log = derive_velocities(log, cfg.savgol_window, cfg.savgol_order, report)
    if spec.noise > 0:
        rng = np.random.default_rng(spec.seed)
        log = log.copy()
        for c in spec.inputs + spec.outputs:
            if c in log:
                log[c] = log[c] + rng.normal(0.0, spec.noise * float(log[c].std()), len(log))
        report.add(
            "noise", f"white noise of {spec.noise:g} × std added to {spec.inputs + spec.outputs}"
        )
    split = make_split(log, cfg.split)
    trainer = _io_trainer(cfg.trainer, spec.epochs, spec.lr, jacobian="samples")
    model = NarxModel(
        spec.inputs,
        spec.outputs,
        spec.input_delays,
        spec.output_delays,
        hidden=spec.hidden,
        trainer=trainer,
        balanced=spec.balanced,
        seed=spec.seed,
        multi_step=spec.multi_step,
        simulation_epochs=spec.simulation_epochs,
        simulation_window=spec.simulation_window,
        lm_samples=spec.lm_samples,
        simulation_lr=spec.simulation_lr,
        simulation_trainer=spec.simulation_trainer,
        simulation_max_fail=spec.simulation_max_fail,
        simulation_l2=spec.simulation_l2,
        delta=spec.delta,
        output_transform=spec.output_transform,
        output_bounds=_bounds_spec(spec.output_bounds),
    )
    caught = _fit_io_model(model, split)
    metrics = {
        "model": "narx",
        "trainer": cfg.trainer,
        "vehicle": cfg.vehicle or None,
        "params": {
            "n_params": {"value": float(model.n_params), "stderr": None},
            **{
                f"layer_{i}_size": {"value": float(n), "stderr": None}
                for i, n in enumerate(model.layer_sizes())
            },
        },
        "network": {
            "layers": model.layer_sizes(),
            "n_params": model.n_params,
            "inputs": model.inputs,
            "outputs": model.outputs,
            "input_delays": model.input_delays,
            "output_delays": model.output_delays,
            "note": (
                "a network has no physical parameters: 'params' lists its size (weights and "
                "biases, and the layer sizes: regressor, hidden tanh nodes, linear outputs); "
                "the weights are in narx.pt"
            ),
        },
        "balanced": model.balanced,
        "transient_share_of_training_draws": model.transient_share_,
        "simulation_finetune": model.finetune_,
        "train": _io_scores(model, split.train, cfg, free_run=False),
        "validation": _io_scores(model, split.validation, cfg),
        "warnings": caught,
        "split": split.record,
        "warmup_s": cfg.warmup_s,
        "warmup_samples": model.warmup,
    }
    if len(split.test):
        metrics["test"] = _io_scores(model, split.test, cfg)
    metrics["seconds"] = time.perf_counter() - start
    return TrainResult(model, metrics, report, split)


def run_state_space_train(
    cfg: TrainConfig,
    config_path: Path,
    data_override: str | None = None,
    columns_override: str | None = None,
) -> TrainResult:
    """``model = "state_space"``: fit a continuous-time neural state-space model on the
    simulation error of the training split (Levenberg-Marquardt or Adam, staged windows),
    early-stop on the validation split, and score free-run NRMSE on validation (and test), each
    run's initial state estimated on its first ``warmup`` samples, which are not scored."""
    from nnid.models.neural_state_space import NeuralStateSpace

    spec = cfg.state_space
    if spec is None:
        raise NnidInputError(
            "model = 'state_space' needs a [state_space] table", field="state_space"
        )
    if cfg.trainer not in ("lm", "adam"):
        raise NnidInputError(
            "a state-space model trains with trainer = 'lm' or 'adam'", field="trainer"
        )
    start = time.perf_counter()
    log, report = load_data(cfg, config_path, data_override, columns_override)
    split = make_split(log, cfg.split)
    trainer = _io_trainer(cfg.trainer, spec.epochs, spec.lr, jacobian="forward")
    model = NeuralStateSpace(
        spec.inputs,
        spec.outputs,
        hidden_states=spec.hidden_states,
        hidden=spec.hidden,
        structure=spec.structure,
        substeps=spec.substeps,
        warmup=spec.warmup,
        windows=[w or None for w in spec.windows],
        trainer=trainer,
        output_bounds=_bounds_spec(spec.output_bounds),
        continuity=spec.continuity,
        seed=spec.seed,
    )
    caught = _fit_io_model(model, split)
    metrics = {
        "model": "state_space",
        "trainer": cfg.trainer,
        "vehicle": cfg.vehicle or None,
        "params": {"n_params": {"value": float(model.n_params), "stderr": None}},
        "network": {
            "n_params": model.n_params,
            "states": model.n_x,
            "hidden_states": model.hidden_states,
            "hidden_units_per_derivative": model.hidden,
            "structure": model.structure,
            "inputs": model.inputs,
            "outputs": model.outputs,
            "note": (
                "a network has no physical parameters: 'params' lists its size; the weights "
                "are in nss.pt"
            ),
        },
        "stages": [
            {"window": w, "epochs": h.epochs if hasattr(h, "epochs") else len(h.train)}
            for w, h in zip(model.windows, model.history_, strict=True)
        ],
        "train": _io_scores(model, split.train, cfg, one_step=False),
        "validation": _io_scores(model, split.validation, cfg, one_step=False),
        "warnings": caught,
        "split": split.record,
        "warmup_s": cfg.warmup_s,
        "warmup_samples": model.warmup,
    }
    if len(split.test):
        metrics["test"] = _io_scores(model, split.test, cfg, one_step=False)
    metrics["seconds"] = time.perf_counter() - start
    return TrainResult(model, metrics, report, split)


def _io_scores(
    model, log: pd.DataFrame, cfg: TrainConfig, free_run: bool = True, one_step: bool = True
) -> dict:
    """One-step and/or free-run NRMSE per output of an input-output model (NARX, neural
    state space); its warm-up samples and ``warmup_s`` excluded."""
    mask = warmup_mask(log, cfg.warmup_s, warmup_samples=model.warmup)
    cols = model.outputs
    vel = [c for c in cols if c in VELOCITY]
    if vel:  # vehicle outputs: score the excited DOFs only; generic outputs: all of them
        cols = [c for c in excited_dofs(log, vel)] + [c for c in cols if c not in VELOCITY]
    out: dict = {"samples": int(mask.sum())}
    if one_step:
        out["one_step_nrmse"] = per_dof(log, model.predict(log, "one_step"), cols, mask)
    if free_run:
        free = model.predict(log, "free_run")
        out["free_run_nrmse"] = per_dof(log, free, cols, mask)
        out["free_run_rmse"] = per_dof(log, free, cols, mask, metric=rmse)
    return out
