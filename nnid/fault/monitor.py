"""The streaming residual monitor: a trained physics model's equation error, whitened by the
healthy residual covariance, watched by an EWMA (fast changes) and a χ² CUSUM (slow drifts),
with thresholds set for a target false-alarm rate per hour on healthy data.

``ResidualMonitor(model).fit(healthy_log)`` calibrates: the mean μ and covariance Σ of the
healthy residual (z = L⁻¹(r − μ), Σ = L Lᵀ over the model's DOF equations), the covariance of the
EWMA of z measured on the healthy data itself (so the residual's autocorrelation is accounted
for, not assumed away), and the two thresholds by a generalized Pareto fit to the excursion
peaks (:mod:`nnid.fault.thresholds`). ``run(log)`` processes whole logs; ``stream()`` gives a
:class:`Stream` that takes one sample at a time with identical results, through the same
compiled update (:mod:`nnid.fault.kernel`) and buffers allocated once.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field
from scipy.stats import trim_mean
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from nnid.datasets.arrays import check_commands, far_beyond_range, motion_arrays
from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.gaps import some_runs
from nnid.datasets.log import POSE, VELOCITY, check_log, rounded_clock, run_label
from nnid.datasets.preprocess import check_attitude, refuse_bursty_runs
from nnid.errors import NnidInputError
from nnid.fault import kernel
from nnid.fault.thresholds import rate_interval, rate_threshold, threshold_caveat
from nnid.models.base import (
    MODEL_FILE,
    MONITOR_FILE,
    learned_fingerprint,
    load_model,
    model_fingerprint,
)
from nnid.physics.compiled import form_args
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.thrusters import Actuation
from nnid.serialization import SCHEMA_VERSION, read_json, write_json
from nnid.threads import torch_threads_kept
from nnid.validation import MAX_FALSE_ALARMS_PER_HOUR, PositiveFloat, StrictModel, validated

#: monitor.json's key of the saved model it was calibrated for (:func:`model_fingerprint`)
FOR_MODEL = "model_fingerprint"
#: what reads a log sample by sample at one interval, as said in a refusal of stamps in bursts
#: (:func:`~nnid.datasets.preprocess.refuse_bursts`; batch and ``--follow`` alike)
MONITOR_STEPS = "the residual monitor, calibrated at one sample interval,"
#: the relative difference of sample interval a monitored log may have from the healthy record
RATE_TOLERANCE = 0.1
#: a spread of the scored intervals (:meth:`ResidualMonitor.clock_spread`) beyond which the
#: false-alarm rate is said not to hold (±10 % of jitter raised 4 alarms in a healthy minute)
CLOCK_SPREAD = 0.2
#: an interval longer than this many typical intervals has samples missing: it gets no residual.
#: One dropped sample (2×) is a gap too: across it a command that changed after one step was
#: not held, and scored, one dropped row every 2 s raised 36 false alarms an hour (thruster
#: losses among them) against a target of 0.01
GAP_INTERVALS = 1.5
#: the fewest healthy residual samples (intervals between two rows of one run) calibrated on
MIN_RESIDUALS = 100
TRACE_COLUMNS = [
    *(f"r_{f}" for f in FORCES),
    *(f"z_{f}" for f in FORCES),
    *(f"ewma_{f}" for f in FORCES),
    "T",
    "g",
]
UNCALIBRATED = (
    "this monitor is not calibrated yet: call fit(healthy_log) first, or load one with "
    "ResidualMonitor.load(dir)"
)
#: what the monitor reads, as detect and training say it (:func:`monitor_motion`)
RESIDUAL = "the monitor's residual (Fossen eq. 2: ν and the attitude)"
#: who never reads a pose column :func:`monitor_motion` leaves out, as detect says it
UNREAD_BY = f"{RESIDUAL} never reads"
_KINDS = {"poly": kernel.CURVE_POLY, "signed_quadratic": kernel.CURVE_QUADRATIC}


def physics_of(model):
    """The fitted Fossen plant a monitor watches: the model itself, or a hybrid's physics."""
    from nnid.models.parametric import FossenPlant

    if isinstance(model, FossenPlant):
        return model
    plant = model.baseline() if getattr(model, "kind", None) == "hybrid" else None
    if not isinstance(plant, FossenPlant):
        raise NnidInputError(
            f"fault detection watches the equation error of a physics model; a '{model.kind}' "
            "model has none (train one with configs/detect_fossen.toml)",
            field="model",
        )
    return plant


def pack_actuation(vehicle, parts) -> tuple:
    """The inputs-to-force map as the kernel's arrays: thrust curves, ranges, allocation and the
    model's installation coefficients (or the identity for logs of generalized forces)."""
    act = Actuation(vehicle)
    n = len(act.channels)
    width = max([2, *(len(c.cmd) for c in act.curves), *(len(c.coeffs) for c in act.curves)])
    kinds = np.full(n, kernel.CURVE_FORCE, dtype=np.int64)
    coeffs = np.zeros((n, width))
    tab_cmd, tab_thrust = np.zeros((n, width)), np.zeros((n, width))
    n_tab = np.zeros(n, dtype=np.int64)
    lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
    for i, (thruster, curve) in enumerate(zip(act.thrusters, act.curves, strict=True)):
        if curve.kind == "table":
            kinds[i], n_tab[i] = kernel.CURVE_TABLE, len(curve.cmd)
            tab_cmd[i, : n_tab[i]], tab_thrust[i, : n_tab[i]] = curve.cmd, curve.thrust
        else:
            kinds[i] = _KINDS[curve.kind]
            # a signed quadratic's forward and reverse coefficients (Caccia eq. 6)
            reverse = curve.k if curve.k_neg is None else curve.k_neg
            values = curve.coeffs if curve.kind == "poly" else (curve.k, reverse)
            coeffs[i, : len(values)] = values
        lo[i] = -np.inf if thruster.cmd_min is None else thruster.cmd_min
        hi[i] = np.inf if thruster.cmd_max is None else thruster.cmd_max
    return (
        kinds,
        coeffs,
        tab_cmd,
        tab_thrust,
        n_tab,
        lo,
        hi,
        np.ascontiguousarray(act.matrix, dtype=np.float64),
        np.asarray(parts.eta_pos, dtype=np.float64),
        np.asarray(parts.eta_neg, dtype=np.float64),
        float(vehicle.deadband),
    )


def input_columns(channels: list[str]) -> list[str]:
    """The log columns of a monitor's input channels: ``cmd_<thruster>`` for a vehicle with
    thrusters, ``tau_X`` … ``tau_N`` for one without (the channels the kernel maps)."""
    if channels == list(FORCES):
        return [f"tau_{c}" for c in FORCES]
    return [f"cmd_{c}" for c in channels]


def monitor_motion(columns: Iterable[str]) -> list[str]:
    """The pose and velocity columns of a log with ``columns`` that the monitor's residual
    reads on every row: ν and the attitude (Fossen eq. 2: C(ν), D(ν) and the restoring g(η) of
    φ, θ; ψ turns a current), and the pose a velocity the log lacks is derived from
    (:func:`~nnid.models.parametric.equation_columns`, as a least-squares fit reads them). The
    kernel's right-hand side reads no x, y, z (:func:`nnid.physics.compiled._rhs`), whichever
    trainer fitted the plant: a UKF-fitted plant's ``motion_columns`` says every column, for
    its filter, not for this residual. A gap in one of these cuts the run; an empty cell of
    another is held (:func:`monitor_inputs`)."""
    from nnid.models.parametric import equation_columns

    return [c for c in equation_columns(columns) if c in (*POSE, *VELOCITY)]


def monitor_inputs(
    log: pd.DataFrame, plant, report: CleaningReport | None = None
) -> dict[str, np.ndarray]:
    """Time, state [N, 12] (velocities derived from the pose where the log lacks them, by the
    model's Savitzky-Golay setting) and the input channels [N, n] the kernel maps to forces.
    An empty cell of a pose column the residual does not read (:func:`monitor_motion`: a 1-Hz
    GPS x, y beside a 20-Hz DVL) takes its run's nearest sample, and stays NaN in a run with
    no sample of it, as ``--follow`` holds it (:mod:`nnid.fault.follow`): not a made-up 0 for
    the isolation to read. ``unread``: those columns of the state, which the kernel is fed
    as 0 where NaN (:func:`kernel_state`), so that it scores the row; they change no residual.
    ``report`` records the velocities derived from the pose ("derive velocities"). A run
    whose stamps come in bursts is refused (:func:`~nnid.datasets.preprocess.refuse_bursts`):
    the residual steps sample by sample at the calibrated interval."""
    from nnid.datasets.gaps import nearest_samples
    from nnid.models.parametric import prepare_motion

    log = check_log(log)  # every entry (fit, run, detect) reads the log here first
    # before check_rate, whose trimmed mean read ten stamps a burst as 1e-05 s apart, and
    # pairs 1e-05 s apart every 0.1 s as 0.05 s: that log was watched, and a difference
    # quotient over 1e-05 s alarmed at its start
    refuse_bursty_runs(log, MONITOR_STEPS)
    cols = input_columns(list(Actuation(plant.vehicle).channels))
    if plant.vehicle.thrusters:
        check_commands(log.columns, cols, plant.vehicle.name)
    missing = [c for c in cols if c not in log]
    if missing:
        raise NnidInputError(
            f"the log lacks the inputs {', '.join(missing)} of vehicle '{plant.vehicle.name}'",
            field=missing[0],
        )
    slips = far_beyond_range(log, plant.vehicle)
    if slips:  # a monitor reads them as faults: PWM against ±1 gave "external_bias.q = −9.58"
        raise NnidInputError(slips[0].message, field=slips[0].column, row=slips[0].row)
    check_attitude(log, plant.vehicle, plant.dofs_)
    log = prepare_motion(
        log,
        plant.dofs_,
        plant.savgol_window,
        plant.savgol_order,
        False,
        report,
        setting=plant.window_key,
    )
    data = motion_arrays(log)
    read = monitor_motion(log.columns)
    unread = [k for k, c in enumerate(POSE) if c in log and c not in read]
    if unread:  # NaN where a run has no sample of one: not sampled, read by no equation
        data["eta"][:, unread] = nearest_samples(log, data["eta"][:, unread])
    return {
        "t": data["t"],
        "x": np.ascontiguousarray(np.concatenate([data["eta"], data["nu"]], 1)),
        "inputs": np.ascontiguousarray(log[cols].to_numpy(np.float64)),
        "experiment": data["experiment"],
        "experiment_names": data["experiment_names"],
        "experiment_runs": data["experiment_runs"],  # per code: its piece_of, else itself
        "unread": np.array(unread, dtype=np.int64),
    }


def kernel_state(x: np.ndarray, unread: np.ndarray) -> np.ndarray:
    """The state ``x`` ([12] or [N, 12]) as the kernel is fed it: a NaN in one of the
    ``unread`` columns (a pose the residual never reads, not yet sampled in its run) as 0.
    The kernel scores no row with a value that is not finite, and reads no x, y, z; the
    arrays the isolation reads keep the NaN."""
    if not unread.size or not np.isnan(x[..., unread]).any():
        return x
    out = x.copy()
    out[..., unread] = np.nan_to_num(x[..., unread])
    return out


@dataclass
class Trace:
    """What :meth:`ResidualMonitor.run` saw: per sample the residual r (force units), the
    whitened z, the EWMA, the statistics T and g, and where alarms started."""

    t: np.ndarray
    experiment: np.ndarray
    values: np.ndarray  # [N, 20] in TRACE_COLUMNS order
    alarm: np.ndarray  # [N] bool: a new alarm starts here

    def frame(self) -> pd.DataFrame:
        out = pd.DataFrame(self.values, columns=TRACE_COLUMNS)
        out.insert(0, "experiment", self.experiment)
        out.insert(0, "t", self.t)
        out["alarm"] = self.alarm
        return out


class ResidualMonitor(BaseEstimator):
    """Detect a change of a vehicle from its model's equation error (see the module docstring).

    Parameters: ``model`` a fitted nnid model with a force equation (or a hybrid, watched
    through its physics), ``false_alarm_per_hour`` the target rate (split between the EWMA and
    the CUSUM), ``time_constant_s`` of the EWMA, ``allowance`` the CUSUM's drift allowance in
    units of the residual's dimension (it grows when the whitened residual power exceeds
    (1 + allowance) times its healthy mean), ``rearm_s`` how long both statistics must stay
    below their thresholds before a new alarm can start.
    """

    def __init__(
        self,
        model,
        false_alarm_per_hour: float = 0.01,
        time_constant_s: float = 0.5,
        allowance: float = 1.0,
        rearm_s: float = 5.0,
    ) -> None:
        self.model = model
        self.false_alarm_per_hour = false_alarm_per_hour
        self.time_constant_s = time_constant_s
        self.allowance = allowance
        self.rearm_s = rearm_s

    # -- the compiled pieces --------------------------------------------------------------------
    def _setup(self) -> None:
        from nnid.models.base import NOT_FITTED

        plant = physics_of(self.model)
        check_is_fitted(plant, msg=NOT_FITTED)
        self.plant_ = plant
        model = plant.parts_.model(check=False)
        self.form_ = form_args(model.feature_form())
        if self.form_[-1] > 0:
            raise NnidInputError(
                "the monitor's model has an actuator lag; fit one without (its state would be "
                "the unmeasured thrust)",
                field="model",
            )
        self.mass_ = np.ascontiguousarray(model.mass_matrix().numpy())
        self.mask_ = np.array([d in plant.dofs_ for d in DOFS], dtype=np.float64)
        self.act_ = pack_actuation(plant.vehicle, plant.parts_)
        self.channels_ = list(Actuation(plant.vehicle).channels)

    def _buffers(self, n_channels: int) -> dict[str, np.ndarray]:
        return {
            "prev": np.zeros(13 + n_channels),
            "st": np.zeros(kernel.STATE_SIZE),
            "work": np.zeros((4, max(18, n_channels))),
            "scratch": np.zeros((4, 18)),
        }

    def _cfg(self, thresholds: tuple[float, float], interval: float) -> np.ndarray:
        cfg = np.zeros(kernel.CFG_SIZE)
        cfg[kernel.TAU] = self.time_constant_s
        cfg[kernel.DIM] = float(self.mask_.sum())
        cfg[kernel.ALLOWANCE] = self.allowance * cfg[kernel.DIM]
        cfg[kernel.H_EWMA], cfg[kernel.H_CUSUM] = thresholds
        cfg[kernel.REARM] = self.rearm_s
        cfg[kernel.MAX_DT] = GAP_INTERVALS * interval
        return cfg

    def _pass(self, data, mu, whiten, s_inv, thresholds, interval: float) -> Trace:
        """The compiled update over every row; each run of rows of one experiment starts from
        a fresh state, the experiments in parallel threads (slices of the arrays, no copies:
        the pass is memory-bound)."""
        cfg = self._cfg(thresholds, interval)
        n = data["t"].size
        codes = data["experiment"]
        starts = np.r_[0, np.flatnonzero(np.diff(codes)) + 1, n].astype(np.int64)
        with torch_threads_kept():  # a parallel launch resets torch's count
            out = kernel.run_blocks(
                starts,
                data["t"],
                kernel_state(data["x"], data.get("unread", np.zeros(0, np.int64))),
                data["inputs"],
                cfg,
                self.form_,
                self.mass_,
                self.mask_,
                self.act_,
                mu,
                whiten,
                s_inv,
                np.empty((n, 21)),
            )
        names = data["experiment_names"][codes]
        return Trace(data["t"], names, out[:, :20], out[:, 20] == 1)

    # -- calibration ----------------------------------------------------------------------------
    def fit(self, healthy: pd.DataFrame) -> ResidualMonitor:
        """Calibrate on a healthy log (one or more experiments, none with a fault)."""
        self._setup()
        data = monitor_inputs(healthy, self.plant_)
        active = self.mask_ > 0
        eye, none = np.eye(6), (math.inf, math.inf)
        interval = typical_interval(data["t"], data["experiment"])
        raw = self._pass(data, np.zeros(6), eye, np.zeros((6, 6)), none, interval).values[:, 0:6]
        raw = raw[np.isfinite(raw).all(1)]
        if raw.shape[0] < MIN_RESIDUALS:
            raise _too_few_residuals(data, raw.shape[0], interval, "experiment" in healthy)
        mu = np.where(active, raw.mean(0), 0.0)
        cov = np.cov(raw[:, active].T).reshape(int(active.sum()), -1)
        if np.any(np.diag(cov) <= 0):
            quiet = [d for d, v in zip(np.array(DOFS)[active], np.diag(cov), strict=True) if v <= 0]
            raise NnidInputError(
                f"the healthy residual has no variance in {', '.join(quiet)} (noise-free data?): "
                "the monitor cannot normalise it",
                field="data",
            )
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:  # a traceback said "Matrix is not positive definite"
            raise _dependent_dofs(cov, list(np.array(DOFS)[active])) from None
        whiten = np.zeros((6, 6))
        whiten[np.ix_(active, active)] = np.linalg.inv(chol)
        z = self._pass(data, mu, whiten, np.eye(6), none, interval).values
        ewma = z[np.isfinite(z[:, 12]), 12:18][:, active]
        s_inv = np.zeros((6, 6))
        s_inv[np.ix_(active, active)] = np.linalg.inv(np.cov(ewma.T).reshape(len(ewma.T), -1))
        self.mu_, self.whiten_, self.s_inv_ = mu, whiten, s_inv
        self.sigma_ = np.sqrt(_variances(cov, active))  # per DOF, for the isolation's weights
        trace = self._pass(data, mu, whiten, s_inv, none, interval)
        # the hours scored, not the runs' spans: the tail fit's rate above the base level is
        # over them (a logger's pause, counted, set the thresholds for a lower rate)
        hours = _scored_hours(trace, GAP_INTERVALS * interval)
        # the declustering gap: the rows in rearm_s, at the record's seconds per row
        gap = max(round(self.rearm_s / interval), 1)
        series = {name: [] for name in ("T", "g")}
        for code in np.unique(data["experiment"]):
            rows = data["experiment"] == code
            series["T"].append(trace.values[rows, 18])
            series["g"].append(trace.values[rows, 19])
        if not np.any(np.concatenate(series["g"]) > 0):  # no threshold is set over 0s alone
            raise NnidInputError(
                f"the CUSUM never rose above 0 on the healthy record: its whitened residual "
                f"power never exceeded (1 + allowance) = {1 + self.allowance:g} times its "
                f"{int(active.sum())} DOF equations, so no threshold can be set for it (one of 0 "
                "would alarm at its first rise, with a severity that is not finite); calibrate "
                "with a smaller allowance, or on a longer healthy record",
                field="allowance",
            )
        half = self.false_alarm_per_hour / 2
        self.thresholds_ = {
            "ewma": rate_threshold(series["T"], hours, half, gap),
            "cusum": rate_threshold(series["g"], hours, half, gap),
        }
        self.correlation_time_ = _correlation_time(trace.values[:, 6:12][:, active])
        self.calibration_ = {
            "hours": hours,
            "samples": int(raw.shape[0]),
            "experiments": [str(e) for e in data["experiment_names"]],
            "dt": interval,  # too: nnid before "interval" read the interval from it
            "interval": interval,
        }
        self.measured_false_alarms_: dict | None = None  # :meth:`measure_false_alarms`
        caveat = self.threshold_caveat()
        if caveat:
            warnings.warn(caveat, stacklevel=2)
        return self

    def threshold_caveat(self) -> str | None:
        """Why the thresholds do not hold the target false-alarm rate (a healthy record too
        short for the peaks-over-threshold fit; a healthy test part whose measured rate lies
        wholly above it: :func:`~nnid.fault.thresholds.threshold_caveat`), or None."""
        check_is_fitted(self, "thresholds_", msg=UNCALIBRATED)
        return threshold_caveat(
            self.thresholds_,
            self.calibration_["hours"],
            self.measured_false_alarms_,
            self.false_alarm_per_hour,
        )

    @property
    def threshold_values(self) -> tuple[float, float]:
        return self.thresholds_["ewma"]["value"], self.thresholds_["cusum"]["value"]

    # -- detection ------------------------------------------------------------------------------
    def run(self, log: pd.DataFrame) -> Trace:
        """The monitor over a whole log (each experiment from a fresh state)."""
        check_is_fitted(self, "thresholds_", msg=UNCALIBRATED)
        data = monitor_inputs(log, self.plant_)
        self.check_rate(data["t"], data["experiment"])
        return self._pass(
            data, self.mu_, self.whiten_, self.s_inv_, self.threshold_values, self.interval
        )

    @property
    def interval(self) -> float:
        """The healthy record's typical sample interval (:func:`typical_interval`; a monitor
        saved before it was stored has the median)."""
        return self.calibration_.get("interval", self.calibration_.get("dt"))

    @property
    def max_interval(self) -> float:
        """The longest interval given a residual (:data:`GAP_INTERVALS` calibrated ones): a
        longer one has samples missing."""
        return GAP_INTERVALS * self.interval

    def missing_samples(self, t: np.ndarray, experiment: np.ndarray | None = None) -> int:
        """How many intervals of ``t`` (within an experiment) are longer than
        :attr:`max_interval`: samples missing there, no residual."""
        return int(np.sum(_steps(t, experiment) > self.max_interval))

    def clock_spread(self, t: np.ndarray, experiment: np.ndarray | None = None) -> float:
        """The spread of the scored intervals (those within :attr:`max_interval`): their 10th
        to 90th percentile over the calibrated interval. The residual is a difference quotient
        whose noise grows as the interval shrinks, so the thresholds hold on a uniform clock;
        a clock alternating 0.04 / 0.06 s (spread 0.4) raised ~200 false alarms an hour."""
        steps = _steps(t, experiment)
        steps = steps[(steps > 0) & (steps <= self.max_interval)]
        if steps.size < 2:
            return 0.0
        lo, hi = np.percentile(steps, [10, 90])
        return float((hi - lo) / self.interval)

    def check_rate(self, t: np.ndarray, experiment: np.ndarray | None = None) -> None:
        """Refuse a log sampled at another rate than the healthy record: the residual is a
        difference quotient (its noise grows as 1/dt) and the EWMA's gain depends on dt, so the
        whitening and both thresholds hold at the calibration rate only (a healthy log at twice
        the rate raised 30 alarms per hour against a target of 0.01)."""
        calibrated = self.interval  # the typical interval of both records, on one rule
        dt = typical_interval(t, experiment)
        if calibrated and not abs(dt / calibrated - 1) <= RATE_TOLERANCE:
            raise NnidInputError(
                f"is sampled every {dt:.4g} s; the monitor was calibrated at {calibrated:.4g} s, "
                "and its whitening and thresholds hold at that rate only (resample the log to "
                "the calibration rate, or calibrate on a healthy log at this one)",
                field="t",
            )

    def stream(self) -> Stream:
        """A one-sample-at-a-time monitor with this calibration."""
        check_is_fitted(self, "thresholds_", msg=UNCALIBRATED)
        return Stream(self)

    def false_alarms(self, log: pd.DataFrame, confidence: float = 0.95) -> dict:
        """Alarms on a healthy log as a rate per hour with its exact Poisson interval."""
        trace = self.run(log)
        hours = _scored_hours(trace, self.max_interval)
        count = int(trace.alarm.sum())
        lo, hi = rate_interval(count, hours, confidence)
        return {
            "alarms": count,
            "hours": hours,
            "rate_per_hour": count / hours,
            "interval": [lo, hi],
            "confidence": confidence,
        }

    def measure_false_alarms(self, healthy: pd.DataFrame, confidence: float = 0.95) -> dict:
        """:meth:`false_alarms` on a healthy record the calibration never saw, kept (and saved)
        with the monitor: ``detect.json`` then gives the rate measured beside the target."""
        self.measured_false_alarms_ = self.false_alarms(healthy, confidence)
        return self.measured_false_alarms_

    # -- persistence ----------------------------------------------------------------------------
    def save(self, folder: str | Path) -> Path:
        """The monitor's model (``model.save(folder)``, which removes an earlier monitor.json),
        then ``monitor.json`` beside it (strict JSON, no code), which records the model it
        wrote (:func:`~nnid.models.base.model_fingerprint`). Fingerprinting whatever model.json
        the folder held bound this calibration to another model saved there."""
        check_is_fitted(self, "thresholds_", msg=UNCALIBRATED)
        folder = self.model.save(folder)
        path = folder / MONITOR_FILE
        write_json(
            path,
            {
                FOR_MODEL: model_fingerprint(folder),
                "settings": {
                    "false_alarm_per_hour": self.false_alarm_per_hour,
                    "time_constant_s": self.time_constant_s,
                    "allowance": self.allowance,
                    "rearm_s": self.rearm_s,
                },
                "mu": self.mu_.tolist(),
                "whiten": self.whiten_.tolist(),
                "s_inv": self.s_inv_.tolist(),
                "sigma": self.sigma_.tolist(),
                "thresholds": self.thresholds_,
                "correlation_time": self.correlation_time_,
                "calibration": self.calibration_,
                "measured_false_alarms": self.measured_false_alarms_,
            },
        )
        return path

    @classmethod
    def load(cls, folder: str | Path, model=None) -> ResidualMonitor:
        """The monitor saved in ``folder`` with its model, loaded from there unless given. The
        calibration is checked against the model.json beside it, and a given ``model``
        against that model (:func:`~nnid.models.base.learned_fingerprint`: its settings and
        what it learned, whichever nnid saved it): another model was given this calibration
        without a word."""
        folder = Path(folder)
        path = folder / MONITOR_FILE
        if not path.is_file():
            raise NnidInputError(
                "has no monitor.json: train a detection model with configs/detect_fossen.toml",
                source=str(folder),
                field="--model",
            )
        state = read_json(path)
        # a hand-edited file: its numbers are believed by the compiled kernel and the report
        if not isinstance(state, dict):
            raise NnidInputError("is not a monitor nnid wrote (no JSON object)", source=str(path))
        validated(_SavedMonitor, state, str(path))
        # the model's own errors name model.json: loaded outside the monitor's error wrapping
        given = model is not None
        model = model if given else load_model(folder)
        # a monitor saved before it recorded its model's (no key) is believed, as it was
        beside = (folder / MODEL_FILE).is_file()
        if FOR_MODEL in state and not beside:  # only a given model gets this far without one
            raise NnidInputError(
                f"has no {MODEL_FILE} beside it, and the calibration is bound to the model saved "
                f"with it (monitor.save writes both): save the monitor with its model, or load "
                "the monitor from the folder it was saved to",
                source=str(path),
            )
        held = model_fingerprint(folder) if beside else None
        if FOR_MODEL in state and state[FOR_MODEL] != held:
            raise NnidInputError(
                f"was calibrated for another model than the {MODEL_FILE} beside it (the model "
                "was saved again, or the files come from different runs): train the detection "
                "model again",
                source=str(path),
            )
        # the calibration is the saved model's: a given one must be that model
        if (
            FOR_MODEL in state
            and given
            and learned_fingerprint(model) != learned_fingerprint(load_model(folder))
        ):
            raise NnidInputError(
                f"was calibrated for the model saved beside it ({MODEL_FILE}), and the model "
                "given to load is another (its settings or what it learned differ): give the "
                "model saved there, or none to load it from the folder",
                source=str(path),
                field="model",
            )
        try:
            out = cls(model, **state["settings"])
            out._setup()
            out.mu_ = np.asarray(state["mu"], dtype=np.float64)
            out.whiten_ = np.asarray(state["whiten"], dtype=np.float64)
            out.s_inv_ = np.asarray(state["s_inv"], dtype=np.float64)
            out.sigma_ = np.asarray(state["sigma"], dtype=np.float64)
            out.thresholds_ = state["thresholds"]
            out.correlation_time_ = float(state["correlation_time"])
            out.calibration_ = state["calibration"]
            out.measured_false_alarms_ = state.get("measured_false_alarms")  # older: none
        except (KeyError, TypeError, ValueError) as exc:
            raise NnidInputError(
                f"is not a monitor nnid wrote ({type(exc).__name__}: {exc})", source=str(path)
            ) from None
        # the compiled kernel does not check bounds: a file with other shapes is refused here
        k = len(DOFS)  # one channel per DOF, whichever the model watches
        square = (out.whiten_, out.s_inv_)
        if (
            out.mu_.shape != (k,)
            or any(a.shape != (k, k) for a in square)
            or out.sigma_.shape != (k,)
        ):
            raise NnidInputError(
                f"holds arrays of other shapes than the monitor's {k} channels (one per DOF: "
                f"mu {out.mu_.shape}, whiten {out.whiten_.shape}, s_inv {out.s_inv_.shape}, "
                f"sigma {out.sigma_.shape})",
                source=str(path),
            )
        arrays = (out.mu_, out.whiten_, out.s_inv_, out.sigma_, [out.correlation_time_])
        # a zero noise level of a watched DOF: fit refuses one (noise-free data), nnid wrote none
        watched = out.sigma_[out.mask_ > 0]
        if (
            not all(np.isfinite(a).all() for a in arrays)
            or not out.correlation_time_ > 0
            or not (watched > 0).all()
        ):
            raise NnidInputError(
                "holds a non-finite number, a correlation time that is not positive, or a "
                "watched DOF's noise level (sigma) that is not: not a monitor nnid wrote",
                source=str(path),
            )
        return out


class _Settings(StrictModel):
    false_alarm_per_hour: float = Field(gt=0, le=MAX_FALSE_ALARMS_PER_HOUR)
    time_constant_s: PositiveFloat
    allowance: PositiveFloat
    rearm_s: PositiveFloat


class _Threshold(BaseModel):
    """A threshold as :func:`~nnid.fault.thresholds.rate_threshold` writes it (its fit's other
    numbers pass through)."""

    model_config = ConfigDict(extra="allow", allow_inf_nan=False, strict=True)
    # 0 where the statistic never rose on healthy data, as nnid wrote it before refusing that
    # (rate_threshold's floor): its alarms' severity is not finite
    value: float = Field(ge=0)
    peaks: int = Field(ge=0)


class _Thresholds(StrictModel):
    ewma: _Threshold
    cusum: _Threshold


class _Calibration(StrictModel):
    hours: PositiveFloat
    samples: int = Field(ge=1)
    experiments: list[str]
    dt: PositiveFloat  # the interval (older monitors: the median step, log_step)
    interval: PositiveFloat | None = None  # :func:`typical_interval`; older monitors lack it


class _Measured(StrictModel):
    """:meth:`ResidualMonitor.false_alarms` as saved."""

    alarms: int = Field(ge=0)
    hours: PositiveFloat
    rate_per_hour: float = Field(ge=0)
    interval: Annotated[list[Annotated[float, Field(ge=0)]], Field(min_length=2, max_length=2)]
    confidence: float = Field(gt=0, lt=1)


class _SavedMonitor(BaseModel):
    """The numbers of ``monitor.json`` that detection believes, checked on loading."""

    model_config = ConfigDict(extra="allow", strict=True)
    schema_version: int = Field(ge=1, le=SCHEMA_VERSION)  # as model.json's is checked
    settings: _Settings
    thresholds: _Thresholds
    calibration: _Calibration
    measured_false_alarms: _Measured | None = None  # older monitors, or no test part


class Stream:
    """One sample at a time: ``update(t, x, inputs)`` with the state x = (η, ν) [12] and the
    input channels held from t; returns 1 when an alarm starts, 0 otherwise, −1 while there is
    no residual. ``values`` holds the last sample's r, z, EWMA, T and g (TRACE_COLUMNS). Every
    buffer is allocated here, none per sample."""

    def __init__(self, monitor: ResidualMonitor) -> None:
        m = monitor
        self._buf = m._buffers(len(m.channels_))
        self._cfg = m._cfg(m.threshold_values, m.interval)
        self._fixed = (m.form_, m.mass_, m.mask_, m.act_, m.mu_, m.whiten_, m.s_inv_)
        self._n = len(m.channels_)
        self.values = np.full(20, np.nan)

    def update(self, t: float, x: np.ndarray, inputs: np.ndarray) -> int:
        # the compiled update does not check bounds: the shapes are checked here, once a call
        if x.ndim != 1 or x.size != 12 or inputs.size != self._n or x.dtype != np.float64:
            raise NnidInputError(
                f"update(t, x, inputs) takes x as 12 float64 values (η then ν) and "
                f"{self._n} inputs; got x {x.shape} {x.dtype}, inputs {inputs.shape}"
            )
        form, mass, mask, act, mu, whiten, s_inv = self._fixed
        b = self._buf
        return kernel.update(t, x, inputs, b["prev"], b["st"], self._cfg, form, mass, mask, act,
                             mu, whiten, s_inv, self.values, b["work"], b["scratch"])  # fmt: skip

    def reset(self) -> None:
        """Forget the past (a new experiment)."""
        for buf in self._buf.values():
            buf.fill(0.0)
        self.values.fill(np.nan)


def typical_interval(t: np.ndarray, experiment: np.ndarray | None = None) -> float:
    """The sample interval of a record, seconds per row, read from its intervals within each
    experiment: a coarsely rounded clock's rate (:func:`~nnid.datasets.log.rounded_clock`:
    120 Hz stamped in ms is 8.333 ms, where the trimmed mean of its 8, 8, 9-ms steps read
    8.29), else their 10 %-trimmed mean, which ignores a few holes. Each use of it is seconds
    per row: the longest interval scored (:attr:`ResidualMonitor.max_interval`), the rate
    check, the rows of ``rearm_s`` the thresholds decluster over, the rows of a window. So it
    is not :func:`~nnid.datasets.log.log_step`'s median (the step a derivative takes; the same
    on other clocks): on a clock alternating 0.04 and 0.06 s (20 Hz) the median is 0.04 or
    0.06 by one sample more or less, 20 % off its rate; the declustering read it (83 rows
    where 5 s holds 100), and the rate check (10 %) and the scored limit (1.5 times 0.04 s is
    the 0.06-s intervals themselves) cannot."""
    t = np.asarray(t, dtype=np.float64)
    within = None if experiment is None else _within(experiment)
    rounded = rounded_clock(t, within)
    if rounded is not None:
        return rounded[0]
    steps = _steps(t, experiment)
    return float(trim_mean(steps, 0.1)) if steps.size else math.nan


def _steps(t: np.ndarray, experiment: np.ndarray | None = None) -> np.ndarray:
    """The sample intervals of ``t`` within each experiment (none across a boundary)."""
    steps = np.diff(np.asarray(t, dtype=np.float64))
    return steps if experiment is None else steps[_within(experiment)]


def _within(experiment: np.ndarray) -> np.ndarray:
    """Which steps of a log join two rows of one experiment (``experiment``: each row's)."""
    runs = np.asarray(experiment)
    return runs[1:] == runs[:-1]


def _too_few_residuals(data: dict, count: int, interval: float, named: bool) -> NnidInputError:
    """The refusal of a healthy log (:func:`monitor_inputs`, ``named``: it has an experiment
    column) that gave ``count`` < :data:`MIN_RESIDUALS` residual samples, with why: a residual
    is an interval between two rows of one run, so its runs' rows, or where rows were enough,
    the intervals scored none (samples missing, or a value missing at either end)."""
    codes = data["experiment"]
    names = [run_label(None)] if not named else [str(n) for n in data["experiment_names"]]
    rows = np.bincount(codes, minlength=len(names))
    pairs = int(_within(codes).sum())
    said = [f"{n} row{'s' * (n != 1)}" for n in rows.tolist()]
    if len(names) > 1 and len(set(said)) == 1:  # one count for all: said once
        runs = f"{some_runs(names)} of {said[0]} each give"
    else:
        runs = f"{some_runs(names, said)} give{'s' * (len(names) == 1)}"
    why = (
        f"the healthy log gives {count} residual samples; the monitor needs at least "
        f"{MIN_RESIDUALS} to calibrate. A residual is the difference quotient over two "
        f"consecutive rows of one experiment, so a run of n rows gives at most n - 1: here "
        f"{runs} at most {pairs}"
    )
    if pairs < MIN_RESIDUALS:
        fix = f"runs with at least {MIN_RESIDUALS} such intervals together"
    else:
        long = int(np.sum(_steps(data["t"], codes) > GAP_INTERVALS * interval))
        why += (
            f", and {pairs - count} of those intervals gave none: {long} longer than "
            f"{GAP_INTERVALS * interval:.4g} s (samples missing), {pairs - count - long} with a "
            "value missing (NaN) at either end"
        )
        fix = "runs with fewer gaps"
    return NnidInputError(f"{why}; calibrate on a healthy log of {fix}", field="data")


def _dependent_dofs(cov: np.ndarray, dofs: list[str]) -> NnidInputError:
    """The refusal of a healthy residual whose covariance ``cov`` over the watched ``dofs`` is
    singular (each DOF's variance positive, :meth:`ResidualMonitor.fit` checked that): some
    DOF equations are a fixed combination of others, and no whitening exists. Named: the DOFs
    with a share in a direction of (near) zero variance of their correlation matrix."""
    scale = np.sqrt(np.diag(cov))
    values, vectors = np.linalg.eigh(cov / np.outer(scale, scale))
    # below this share of the largest, a direction is no variance: cholesky failed on it
    null = values <= max(1e-10 * values.max(), values.min())
    share = np.abs(vectors[:, null]).max(1)
    named = [d for d, w in zip(dofs, share, strict=True) if w > 1e-3]
    return NnidInputError(
        f"the healthy residual is linearly dependent across the DOF equations "
        f"{', '.join(named)}: one is a fixed combination of the others, and the monitor cannot "
        "whiten it (a vehicle held still while its thrusters moved together leaves that); "
        "calibrate on a healthy log where they vary independently",
        field="data",
    )


def held_seconds(
    t: np.ndarray,
    max_step: float,
    experiment: np.ndarray | None = None,
    scored: np.ndarray | None = None,
) -> float:
    """The seconds over which rows at times ``t`` hold samples: the sum of their intervals
    within each experiment, less those longer than ``max_step`` (samples missing there: the
    monitor's :attr:`~ResidualMonitor.max_interval`, past which it scores no interval) and,
    where ``scored`` (per row: whether the interval ending there gave a residual) is given,
    those that gave none (a value missing at either end). The time a rate per hour is over:
    a logger's pause, scored by no residual, is no healthy hour without an alarm."""
    steps = np.diff(np.asarray(t, dtype=float))
    keep = steps <= max_step
    if experiment is not None:
        keep &= _within(experiment)
    if scored is not None:
        keep &= np.asarray(scored, dtype=bool)[1:]
    return float(steps[keep].sum())


def _scored_hours(trace: Trace, max_step: float) -> float:
    """The hours a monitor's ``trace`` scored (:func:`held_seconds` of the intervals that gave
    a residual, those with a statistic T), never 0 (a rate is divided by them)."""
    scored = np.isfinite(trace.values[:, TRACE_COLUMNS.index("T")])
    seconds = held_seconds(trace.t, max_step, trace.experiment, scored)
    return max(seconds, 1e-9) / 3600.0


def _variances(cov: np.ndarray, active: np.ndarray) -> np.ndarray:
    out = np.zeros(6)
    out[active] = np.diag(cov)
    return out


def _correlation_time(z: np.ndarray) -> float:
    from nnid.trainers.least_squares import correlation_time

    z = z[np.isfinite(z).all(1)]
    return float(correlation_time(z, max_lag=200)) if len(z) > 10 else 1.0
