"""Prediction modes (one step, k steps, free run) and how physics models predict in each.

A physics model here is a :class:`nnid.models.parametric.Parts` (or anything with ``model()``
and ``applied()``): the log's nominal inputs pass through its installation coefficients, and
the compiled RK4 integrates from measured states. Missing state components start at zero.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from nnid.datasets.gaps import nearest_samples
from nnid.datasets.log import (
    POSE,
    TAU,
    VELOCITY,
    check_time_unit,
    check_unique_labels,
    frame_step,
    typical_step,
)
from nnid.datasets.preprocess import check_uniform, experiment_rows, first_order_lag
from nnid.errors import NnidInputError
from nnid.physics import compiled


def check_mode(mode: Any) -> str | int:
    """A prediction mode: "one_step", "free_run" or a positive number of steps."""
    if mode in ("one_step", "free_run"):
        return mode
    if isinstance(mode, (int, np.integer)) and not isinstance(mode, bool) and mode >= 1:
        return int(mode)
    raise NnidInputError(
        f"prediction mode {mode!r}: expected 'one_step', 'free_run' or a number of steps ≥ 1",
        field="mode",
    )


def mode_steps(mode: str | int) -> int:
    """Steps ahead of a mode: 1 for one step (and free run, whose first prediction is one
    step after its initial condition), k for k steps."""
    return mode if isinstance(mode, int) else 1


#: the longest RK4 step a physics model's prediction takes (s): slow logs (ROMEO's 10 Hz) are
#: sub-stepped. At 50 ms the VT 690's closed-loop free run differs from a 2.5 ms integration by
#: 1e-7 in NRMSE, so the step adds no error worth the cost of smaller ones.
MAX_STEP = 0.05


#: how far an interval may differ from its run's median before a physics prediction refuses
#: it: one 1.5 times the median has a sample missing (the fault monitor's rule), across which
#: the commands were not held (and one under half of it is no clock's jitter either); smaller
#: jitter is stepped at the median
MISSING_SAMPLE = 0.5


def check_stepped(log: pd.DataFrame) -> None:
    """Refuse a vehicle log a physics prediction would step wrongly: time not in seconds (the
    rule a log file is read with; a log handed to the Python API is checked here), or a run
    with samples missing (three blocks of 2 s dropped from a 20-Hz run were each stepped as
    one sample: free-run NRMSE 0.05-0.18 of the true model on noise-free data)."""
    if "t" not in log:
        return
    check_time_unit(log)
    what = "the prediction (one step of the run's typical interval a sample)"
    check_uniform(log, what, tolerance=MISSING_SAMPLE)


def substeps_for(log: pd.DataFrame, max_step: float = MAX_STEP) -> int:
    """RK4 sub-steps per sample so that no step exceeds ``max_step`` seconds, at the typical
    step of the log's runs (:func:`~nnid.datasets.log.frame_step`: the joins between them
    left out); 1 for a log in which no run has two samples (nothing to step)."""
    dt = frame_step(log)
    if np.isnan(dt):  # as a log of one sample was: nothing to step
        return 1
    return max(1, int(np.ceil(dt / max_step - 1e-9)))


def measured_states(log: pd.DataFrame) -> np.ndarray:
    """[N, 12] pose and velocity from the log (absent columns are zero). An empty pose cell
    (a 1-Hz GPS x y beside a 10-Hz DVL, which no fit reads and ``make_split`` leaves in)
    takes its run's last sample before it, else its first after, a piece cut at a gap
    (``piece_of``) within the run it was cut from: a simulated pose starts from where the
    vehicle was measured, not from 0 (η̇ = J(η) ν carries the offset on)."""
    x = np.zeros((len(log), 12))
    for k, c in enumerate((*POSE, *VELOCITY)):
        if c in log:
            x[:, k] = log[c].to_numpy(np.float64)
    x[:, :6] = nearest_samples(log, x[:, :6])
    return np.nan_to_num(x)  # an undefined component (w of a tumbling vehicle) starts at zero


def predict_states(
    parts,
    log: pd.DataFrame,
    tau_nominal: np.ndarray,
    mode="free_run",
    substeps: int = 1,
    lag: float = 0.0,
) -> pd.DataFrame:
    """Predicted pose and velocity columns for ``mode`` = "one_step", "free_run" or k (int).

    Row i holds the prediction of sample i; the first k samples of each experiment (k = 1 for
    one step) repeat the measurement and belong to the warm-up. With an actuator ``lag`` T
    > 0, ``tau_nominal`` is the force commanded before the lag: the force the vehicle feels is
    integrated as a state (stepped exactly, as the simulator steps it), started at each
    window from its value at that sample (:func:`~nnid.datasets.preprocess.first_order_lag`).
    Holding those sampled values instead delays the force by about half a sample, which
    biased a lag chosen by its simulated error by about dt/2.
    """
    form = parts.model(check=False, actuator_lag=lag).feature_form()
    tau = parts.applied(tau_nominal)
    x = measured_states(log)
    out = x.copy()
    if lag > 0:
        x = np.concatenate([x, felt_forces(parts, log, tau_nominal, lag)], 1)
    k = 1 if mode == "one_step" else mode
    for _, pos in experiment_rows(log):
        t = log["t"].to_numpy(np.float64)[pos]
        dt = typical_step(t, np.nan)
        if mode == "free_run":
            flown = compiled.integrate_rk4(form, x[pos[0]], tau[pos[:-1]], dt, substeps)
            out[pos] = flown[:, :12]
            continue
        if not isinstance(k, int) or k < 1:
            raise ValueError("mode is 'one_step', 'free_run' or a positive number of steps")
        n = pos.size - k
        if n <= 0:
            continue
        windows = np.stack([tau[pos[j : j + n]] for j in range(k)], 1)
        last = compiled.integrate_rk4(form, x[pos[:n]], windows, dt, substeps)[:, -1]
        out[pos[k:]] = last[:, :12]
    return pd.DataFrame(out, columns=[*POSE, *VELOCITY], index=log.index)


def felt_forces(parts, log: pd.DataFrame, tau_nominal: np.ndarray, lag: float) -> np.ndarray:
    """The force the vehicle feels at each sample behind an actuator ``lag`` T ``[N, 6]``: the
    commanded ``tau_nominal`` through ``parts``' installation, then 1/(T s + 1) per experiment
    (:func:`~nnid.datasets.preprocess.first_order_lag`, exact for forces held between
    samples, at rest on the first one): the lag state a prediction window starts from."""
    return first_order_lag(parts.applied(tau_nominal), log, lag)


def blank_initial(predicted: pd.DataFrame, log: pd.DataFrame, n: int) -> pd.DataFrame:
    """``predicted`` with the first ``n`` rows of each experiment set to NaN: the initial
    conditions a prediction starts from are not predictions."""
    if n <= 0:
        return predicted
    values = predicted.to_numpy(np.float64, copy=True)
    for _, pos in experiment_rows(log):
        values[pos[:n]] = np.nan
    return pd.DataFrame(values, columns=predicted.columns, index=predicted.index)


@dataclass
class Replay:
    """How a log was flown in closed loop, to fly a model's free run the same way: the
    simulator's PD autopilot (:class:`nnid.datasets.simulator.Autopilot`) and the open-loop
    part of the input (``tau_X … tau_N`` on the log's index); the log records their sum."""

    autopilot: Any
    open_loop: pd.DataFrame


#: a model flown in closed loop: (window starts [B] as positions in the log, dt) ->
#: step(states [B, 12], command [B, 6]) -> states one sample later; a new step per experiment,
#: so it can keep its own memory, started from the log's history at each window's start
Stepper = Callable[[np.ndarray, float], Callable[[np.ndarray, np.ndarray], np.ndarray]]

#: a whole closed-loop flight of one run: (states [B, 12], the run's open-loop input [M, 6],
#: window starts [B] in it, steps, dt, the run's positions in the log [M]) -> states
#: [B, steps + 1, 12]; a window that turns non-finite may stop there. A window steps through
#: its run's samples, which need not be contiguous rows of the log (runs A, B, A)
Flight = Callable[[np.ndarray, np.ndarray, np.ndarray, int, float, np.ndarray], np.ndarray]


def fly_closed_loop(
    log: pd.DataFrame, replay: Replay, stepper: Stepper, mode: str | int = "free_run"
) -> pd.DataFrame:
    """A model flown under ``replay``'s autopilot: each sample the commanded force is the
    open-loop input plus the autopilot's feedback on the *simulated* state, held over the
    sample (as :func:`nnid.datasets.simulator.simulate` flew the log). ``mode`` "free_run"
    flies each experiment from its first measured state; k (or "one_step", k = 1) flies k
    samples from every measured state, all windows at once. Rows not predicted keep the
    measurement (the caller blanks them)."""

    def flight(x0, tau_open, starts, steps, dt, pos):
        step = stepper(pos[starts], dt)
        states = np.full((starts.size, steps + 1, x0.shape[1]), np.nan)
        states[:, 0] = state = x0
        for j in range(steps):
            state = step(state, tau_open[starts + j] + replay.autopilot.force(state))
            states[:, j + 1] = state
            if mode == "free_run" and not np.isfinite(state).all():
                break
        return states

    return _fly(log, replay, flight, mode)


def predict_closed_loop(
    parts,
    log: pd.DataFrame,
    replay: Replay,
    mode: str | int = "free_run",
    substeps: int = 1,
    deadband: float = 0.0,
    lag: float = 0.0,
    tau_nominal: np.ndarray | None = None,
) -> pd.DataFrame:
    """A physics model (:class:`nnid.physics.parts.Parts`) flown under ``replay``'s
    autopilot as :func:`fly_closed_loop` flies a stepper, in one compiled loop
    (:func:`nnid.physics.compiled.fly_pd`; the same numbers), the commanded forces through
    the vehicle's ``deadband`` as the simulator flies them.

    With an actuator ``lag`` T > 0 the force felt is a state of the flight, stepped exactly
    as the simulator steps it, started at each window from the force felt there as the log
    was flown: :func:`felt_forces` of ``tau_nominal``, the log's commanded force (deadband
    applied, not lagged), as :func:`predict_states` starts it."""
    form = parts.model(check=False, actuator_lag=lag).feature_form()
    pilot = replay.autopilot.pilot(parts.eta_pos, parts.eta_neg)
    felt = None
    if lag > 0:
        if tau_nominal is None:
            raise ValueError("a lagged flight starts from the log's commanded tau_nominal")
        felt = felt_forces(parts, log, tau_nominal, lag)

    def flight(x0, tau_open, starts, steps, dt, pos):
        if felt is not None:  # the lag states after the 12 of pose and velocity
            x0 = np.concatenate([x0, felt[pos[starts]]], 1)
        flown = compiled.fly_pd(form, x0, tau_open, starts, steps, dt, pilot, deadband, substeps)
        return flown[0][..., :12]

    return _fly(log, replay, flight, mode)


def _fly(log: pd.DataFrame, replay: Replay, flight: Flight, mode: str | int) -> pd.DataFrame:
    """Each experiment of ``log`` flown by ``flight`` from its measured states: a free run
    from the first (NaN from its first non-finite state on), or k samples from every one."""
    # a split's rows take the whole log's open-loop inputs by label: one label, one row
    why = "the log's rows take the replay's open-loop inputs by label"
    check_unique_labels(log.index, "the log's index", why)
    check_unique_labels(replay.open_loop.index, "the index of the replay's open-loop inputs", why)
    x = measured_states(log)
    out = x.copy()
    tau_open = replay.open_loop.loc[log.index, list(TAU)].to_numpy(np.float64)
    k = mode_steps(mode)
    for _, pos in experiment_rows(log):
        dt = typical_step(log["t"].to_numpy(np.float64)[pos], np.nan)
        if mode == "free_run":
            flown = flight(x[pos[:1]], tau_open[pos], np.zeros(1, int), pos.size - 1, dt, pos)[0]
            bad = np.flatnonzero(~np.isfinite(flown).all(1))
            if bad.size:
                flown[bad[0] :] = np.nan
            out[pos[1:]] = flown[1:]
        elif pos.size > k:
            starts = np.arange(pos.size - k)  # in the run: its rows need not be contiguous
            out[pos[starts + k]] = flight(x[pos[starts]], tau_open[pos], starts, k, dt, pos)[:, -1]
    return pd.DataFrame(out, columns=[*POSE, *VELOCITY], index=log.index)
