"""A log as the arrays the physics works on: pose η, velocity ν, acceleration ν̇, the nominal
generalized force τ (from ``tau_*`` or through the vehicle's thrusters from ``cmd_*``), time
and experiment codes."""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import pandas as pd

from nnid.datasets.log import ANGLES, POSE, TAU, VELOCITY, run_of
from nnid.datasets.preprocess import first_order_lag
from nnid.errors import NnidInputError
from nnid.physics.thrusters import Actuation, apply_deadband, force_deadband


def motion_arrays(log: pd.DataFrame) -> dict[str, np.ndarray]:
    """η, ν, ν̇, time and experiment codes from a log (missing pose components are zero;
    velocities and accelerations must be present: derive them with
    :mod:`nnid.datasets.preprocess`). ``experiment_runs`` names the run of each experiment
    code: its ``piece_of`` where a gap cut a run into pieces, else its own name, so that what
    is keyed by run (a weight setting, a sequence step) finds its pieces."""
    n = len(log)
    eta = np.zeros((n, 6))
    for k, c in enumerate(POSE):
        if c in log:
            eta[:, k] = log[c].to_numpy(np.float64)
    nu = np.zeros((n, 6))
    nu_dot = np.zeros((n, 6))
    for k, c in enumerate(VELOCITY):
        if c in log:
            nu[:, k] = log[c].to_numpy(np.float64)
        if "d" + c in log:
            nu_dot[:, k] = log["d" + c].to_numpy(np.float64)
    if "experiment" in log:
        codes, names = pd.factorize(log["experiment"])
    else:
        codes, names = np.zeros(n, dtype=int), ["0"]
    run = run_of(log)
    runs = [run.get(e, e) for e in names]
    return {
        "eta": eta,
        "nu": nu,
        "nu_dot": nu_dot,
        "angles_known": np.array(all(a in log for a in ANGLES)),
        "t": log["t"].to_numpy(np.float64),
        "experiment": codes,
        "experiment_names": np.asarray(names, dtype=object),
        "experiment_runs": np.asarray(runs, dtype=object),
    }


def check_commands(columns: Iterable[str], cols: list[str], vehicle_name: str) -> None:
    """Every ``cmd_*`` column of a log (``columns``) is one of the vehicle's thrusters
    (``cols``): a thruster the vehicle file lacks would be left out of τ without a word."""
    extra = [c for c in columns if str(c).startswith("cmd_") and c not in cols]
    if extra:
        raise NnidInputError(
            f"the log's commands {', '.join(extra)} drive no thruster of vehicle "
            f"'{vehicle_name}' (its commands: {', '.join(cols) or 'none, it has no thrusters'}): "
            "add the thruster to the vehicle file, or drop the column if it is not a thruster's",
            field=extra[0],
        )


def flown_range(thruster) -> tuple[float, float]:
    """The commands a thruster flies as asked: :meth:`nnid.physics.thrusters.Actuation.thrusts`
    clips to its ``cmd_min`` and ``cmd_max`` (either one alone too), and a thrust table holds
    its end thrust past its span; ±inf where nothing bounds it."""
    low = -np.inf if thruster.cmd_min is None else float(thruster.cmd_min)
    high = np.inf if thruster.cmd_max is None else float(thruster.cmd_max)
    if getattr(thruster.curve, "kind", None) == "table":
        low, high = max(low, thruster.curve.cmd[0]), min(high, thruster.curve.cmd[-1])
    return low, high


def command_range(thruster) -> tuple[float, float] | None:
    """A thruster's command range: the commands it flies as asked (:func:`flown_range`, the
    one rule: a ±1 thruster whose table spans ±0.8 flies ±0.8), where both ends are bounded;
    else None (a curve of any command)."""
    low, high = flown_range(thruster)
    return (low, high) if np.isfinite(low) and np.isfinite(high) else None


class CommandUnitsWarning(UserWarning):
    """Thruster commands far beyond their range: a unit slip (:func:`warn_far_beyond_range`).
    Its own class so that a run that said it against the whole log can leave out the same
    warning from each fit on a part of it (whose share of samples would differ)."""


class CommandLimits(NamedTuple):
    """A thruster's command range and the bounds further beyond it than it is wide."""

    low: float
    high: float
    range_low: float
    range_high: float

    def holds(self, value: float) -> bool:
        return self.low <= value <= self.high


def command_limits(vehicle) -> dict[str, CommandLimits]:
    """``{cmd_<thruster>: CommandLimits}``: beyond ``low`` and ``high`` a command is further
    from its range (:func:`command_range`) than the range is wide."""
    out = {}
    for thruster in vehicle.thrusters:
        span = command_range(thruster)
        if span is not None:
            lo, hi = span
            out[f"cmd_{thruster.name}"] = CommandLimits(lo - (hi - lo), hi + (hi - lo), lo, hi)
    return out


def beyond_range_message(
    column: str, value: float, limits: CommandLimits, share: float | None = None
) -> str:
    """What is said of ``column`` reaching ``value`` beyond its :func:`command_limits`."""
    where = f" in {share:.0%} of the samples" if share is not None else ""
    return (
        f"{column} reaches {value:.4g}, far beyond thruster {column[4:]}'s range "
        f"[{limits.range_low:g}, {limits.range_high:g}]{where}; the thrust curve saturates it "
        "at the bound: are the commands in the vehicle file's units (not PWM microseconds "
        "against ±1)?"
    )


@dataclass
class CommandSlip:
    """A thruster command beyond its :func:`command_limits`: the column, the first such row
    (the log's integer index label, the file's row for a log as read; else None) and what to
    say."""

    column: str
    row: int | None
    message: str


def far_beyond_range(log: pd.DataFrame, vehicle) -> list[CommandSlip]:
    """Each thruster command beyond its :func:`command_limits`. The thrust curve saturates a
    command at its bound, by design; one that far out is a unit slip (PWM microseconds
    against ±1), and saturating it would fly the log at full thrust without a word."""
    slips = []
    for col, limits in command_limits(vehicle).items():
        if col not in log:
            continue
        values = log[col].to_numpy(np.float64)
        beyond = (values > limits.high) | (values < limits.low)
        if beyond.any():
            worst = values[beyond][np.argmax(np.abs(values[beyond]))]
            label = log.index[int(np.argmax(beyond))]
            row = int(label) if isinstance(label, (int, np.integer)) else None
            slips.append(
                CommandSlip(col, row, beyond_range_message(col, worst, limits, beyond.mean()))
            )
    return slips


def warn_far_beyond_range(
    log: pd.DataFrame, vehicle, slips: list[CommandSlip] | None = None
) -> None:
    """Warn of each command :func:`far_beyond_range` finds (``slips``: found already)."""
    for slip in far_beyond_range(log, vehicle) if slips is None else slips:
        warnings.warn(slip.message, CommandUnitsWarning, stacklevel=3)


class CommandSaturationWarning(UserWarning):
    """Thruster commands beyond the range the thruster flies (:func:`warn_clipped`): the log
    records the commands asked, the vehicle flew them at the range's bound."""


def _span(low: float, high: float) -> str:
    if np.isfinite(low) and np.isfinite(high):
        return f"within [{low:g}, {high:g}]"
    return f"at most {high:g}" if np.isfinite(high) else f"at least {low:g}"


def warn_clipped(
    inputs: np.ndarray, vehicle, experiment: str | None = None, said_units: Iterable[str] = ()
) -> None:
    """Warn, with the share of samples per thruster, where the commands ``inputs`` ``[N, n]``
    (the vehicle's thrusters in order) go beyond :func:`flown_range`: a PRBS of ±1.5 on a ±1
    thruster was flown at ±1 throughout and logged at ±1.5 without a word. ``said_units``:
    the ``cmd_<thruster>`` columns already warned of as a unit slip
    (:func:`warn_far_beyond_range`), left out: one slip, one warning."""
    said, skip = [], set(said_units)
    for k, thruster in enumerate(vehicle.thrusters):
        if f"cmd_{thruster.name}" in skip:
            continue
        low, high = flown_range(thruster)
        asked = inputs[:, k]
        beyond = (asked < low) | (asked > high)
        if beyond.any():
            said.append(
                f"{thruster.name} in {100 * beyond.mean():.3g}% of the samples (asked "
                f"{asked.min():g} to {asked.max():g}, flown {_span(low, high)})"
            )
    if said:
        where = f"experiment {experiment!r}: " if experiment else ""
        warnings.warn(
            f"{where}thruster commands beyond the thruster's range were flown at its bound: "
            + "; ".join(said)
            + ". The log records the commands asked, not the thrust flown: keep the signals "
            "within the range (cmd_min, cmd_max, a thrust table's span) to fly what is logged",
            CommandSaturationWarning,
            stacklevel=3,
        )


def logged_inputs(log: pd.DataFrame, vehicle) -> tuple[np.ndarray, bool]:
    """The log's inputs and whether they are forces: ``tau_X`` … ``tau_N`` when all six are
    there, else the thruster commands ``cmd_<thruster>`` of the vehicle (ARCHITECTURE.md, the
    log). A vehicle without thrusters has no commands, so its logs need the six forces. Raises
    :class:`NnidInputError` naming the missing columns and the forces the log has."""
    if all(c in log for c in TAU):
        # the forces drive the model; a command no thruster takes would be read by nothing
        check_commands(log.columns, [f"cmd_{t.name}" for t in vehicle.thrusters], vehicle.name)
        return log[list(TAU)].to_numpy(np.float64), True
    # a log's columns, not a setting: no config field to name
    if not vehicle.thrusters:
        raise NnidInputError(
            f"the log lacks the input columns {', '.join(c for c in TAU if c not in log)}: "
            f"vehicle '{vehicle.name}' has no thrusters, so all six generalized forces "
            "tau_X … tau_N are needed"
        )
    cols = [f"cmd_{c}" for c in Actuation(vehicle).channels]
    check_commands(log.columns, cols, vehicle.name)
    missing = [c for c in cols if c not in log]
    if missing:
        present = [c for c in TAU if c in log]
        raise NnidInputError(
            "the log has neither the six generalized forces tau_X … tau_N"
            + (f" (only {', '.join(present)})" if present else "")
            + f" nor the commands {', '.join(missing)} of vehicle '{vehicle.name}'"
        )
    warn_far_beyond_range(log, vehicle)
    return log[cols].to_numpy(np.float64), False


def check_forces_match_commands(log: pd.DataFrame, vehicle) -> None:
    """Warn where a log holds both the six forces and every thruster's command and the two
    disagree (beyond a tenth of the forces' spread in a DOF): :func:`logged_inputs` reads the
    forces and leaves the commands unread, so the user should know which to trust. Said once
    against the whole log (the pipeline calls it as it loads one), not by every fit."""
    cols = [f"cmd_{t.name}" for t in vehicle.thrusters]
    if not cols or not all(c in log for c in (*TAU, *cols)):
        return
    tau = log[list(TAU)].to_numpy(np.float64)
    nominal = Actuation(vehicle).nominal(log[cols].to_numpy(np.float64), deadband=True)
    ok = np.isfinite(tau).all(1) & np.isfinite(nominal).all(1)
    if not ok.any():
        return
    spread = np.maximum(tau[ok].std(0), nominal[ok].std(0))
    rms = np.sqrt(np.mean((tau[ok] - nominal[ok]) ** 2, 0))
    off = [f for f, r, s in zip(TAU, rms, spread, strict=True) if s > 0 and r > 0.1 * s]
    if off:
        warnings.warn(
            f"the log's forces {', '.join(off)} differ from what its thruster commands give "
            f"through vehicle '{vehicle.name}' (beyond a tenth of their spread): the forces "
            "are read and the commands are not; drop the column you do not trust",
            stacklevel=2,
        )


def nominal_forces(log: pd.DataFrame, vehicle, lagged: bool = True) -> np.ndarray:
    """The nominal generalized force the vehicle receives ``[N, 6]``: deadband on the inputs,
    thrust curves and allocation, then (``lagged``) the first-order actuator lag of the vehicle
    at the sample times (exact for inputs held between samples); installation coefficients
    are left to the model (they act before the lag: :func:`force_arrays`)."""
    inputs, forces = logged_inputs(log, vehicle)
    if forces:  # a new array, not pandas' read-only view: the loop zeroes DOFs in it
        tau = apply_deadband(inputs, force_deadband(vehicle))
    else:
        tau = Actuation(vehicle).nominal(inputs, deadband=True)
    return first_order_lag(tau, log, vehicle.actuator_lag) if lagged else tau


def force_arrays(log: pd.DataFrame, vehicle) -> dict[str, np.ndarray]:
    """The nominal force through the vehicle's actuator lag L, ``{"tau": L[τ]}``
    (:func:`nominal_forces`), and with a lag its negative part ``"tau_neg"`` = L[min(τ, 0)]:
    installation coefficients act on the force commanded, before the lag (Caccia eq. 3, as the
    simulator applies them), and L is linear, so the force felt is η⁺ L[τ⁺] + η⁻ L[τ⁻] with
    L[τ⁺] = L[τ] − L[τ⁻] (:meth:`nnid.physics.parts.Parts.felt`), and an installation
    coefficient's regressor is its direction's lagged part. Without a lag there is no
    ``tau_neg``: η(sign τ) τ is exact."""
    tau = nominal_forces(log, vehicle, lagged=False)
    lag = vehicle.actuator_lag
    out = {"tau": first_order_lag(tau, log, lag)}
    if lag > 0:
        out["tau_neg"] = first_order_lag(np.minimum(tau, 0.0), log, lag)
    return out


def log_arrays(log: pd.DataFrame, vehicle) -> dict[str, np.ndarray]:
    """:func:`motion_arrays` and the nominal τ (from ``tau_*`` or through the vehicle's
    thrusters from ``cmd_*``, :func:`logged_inputs`), with the vehicle file's deadband and
    actuator lag (:func:`force_arrays`): a model of a vehicle whose file declares them is
    fitted on the force that vehicle receives. A lagged vehicle's arrays hold ``tau_neg`` as
    well; whoever replaces ``tau`` replaces both."""
    return {**motion_arrays(log), **force_arrays(log, vehicle)}
