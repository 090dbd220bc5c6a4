"""Detection end to end: the monitor over a log, each alarm isolated on the window after it.

The alarm records follow the ``detect.json`` contract (ARCHITECTURE.md): time, kind, thruster and
remaining efficiency, effect, severity (the peak of the larger statistic over its threshold in the
window) and confidence.

While an isolated change persists its residual keeps the statistics above their thresholds, and
the monitor alone would not re-arm until it ends: a second fault during the first would not be
alarmed. So after an alarm whose change is isolated (a hypothesis named that leaves no more than
noise, :data:`nnid.fault.isolation.UNEXPLAINED_RATIO`), the rest of the experiment is watched
on the residual that change leaves (the fitted hypothesis taken out, fresh EWMA and CUSUM from
the end of the isolation window, the same thresholds): a new alarm there is a residual the
first change no longer explains, and is isolated on that residual. An alarm that is not
isolated (unexplained, not significant) leaves the monitor as it was.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from nnid.fault import kernel
from nnid.fault.isolation import (
    UNEXPLAINED_RATIO,
    UNEXPLAINED_SHARE,
    Diagnosis,
    isolate,
    noise_ratio,
    signature,
)
from nnid.fault.monitor import ResidualMonitor, Trace, monitor_inputs

ALARM_FIELDS = ["experiment", "t", "kind", "thruster", "efficiency", "efficiency_low",
                "efficiency_high", "effect", "value", "stderr", "severity", "confidence",
                "explained", "residual_ratio", "hypothesis", "meaning"]  # fmt: skip


@dataclass
class DetectResult:
    trace: Trace
    alarms: list[dict]
    seconds: float


def isolated_alarm(
    monitor: ResidualMonitor,
    data: dict,
    trace: Trace,
    k: int,
    window_s: float,
    residual: np.ndarray | None = None,
) -> tuple[dict, Diagnosis, np.ndarray]:
    """The alarm that starts at row ``k``, isolated on [t_k, t_k + window_s]: its record, the
    diagnosis and the rows of the window. The window starts at the alarm, never before: the
    change began at or before the alarm, and healthy samples before its onset would bias the
    size of the change toward zero. ``residual`` [N, 6]: the one to isolate (the trace's own
    by default)."""
    rows = window_rows(data, k, window_s)
    residual = trace.values[:, 0:6] if residual is None else residual
    diag = isolate(monitor, data, residual, rows)
    h_t, h_g = monitor.threshold_values
    severity = float(
        np.nanmax(np.maximum(trace.values[rows, 18] / h_t, trace.values[rows, 19] / h_g))
    )
    interval = diag.efficiency_interval or (None, None)
    name = trace.experiment[k]
    record = {
        "experiment": None if name is None else str(name),
        "t": float(data["t"][k]),
        "kind": diag.kind,
        "thruster": diag.thruster,
        "efficiency": diag.efficiency,
        "efficiency_low": interval[0],
        "efficiency_high": interval[1],
        "effect": diag.effect,
        "value": diag.value,
        "stderr": diag.stderr,
        "severity": severity,
        "confidence": diag.confidence,
        "meaning": diag.meaning,
        "explained": diag.explained,
        "residual_ratio": diag.residual_ratio,
        "hypothesis": diag.hypothesis,
        "p_value": diag.p_value,
        "alternatives": diag.alternatives,
        "components": diag.components,
    }
    return record, diag, rows


def run_names(names, codes, named: bool) -> np.ndarray:
    """The experiment of each row (``codes`` into ``names``) as the trace and the alarm records
    name it: its label, or None where the log has no experiment column (``named`` false): one
    run without a name, as :func:`nnid.datasets.preprocess.experiments` gives it, not the
    placeholder its arrays carry ("0" in batch, "" in ``--follow``)."""
    labels = np.array(names if named else [None] * len(names), dtype=object)
    return labels[np.asarray(codes, dtype=int)]


def window_rows(data: dict, k: int, window_s: float) -> np.ndarray:
    """The rows of the isolation window of an alarm at row ``k``: its experiment's on
    [t_k, t_k + window_s]."""
    t, codes = data["t"], data["experiment"]
    return np.flatnonzero((codes == codes[k]) & (t >= t[k]) & (t <= t[k] + window_s))


def explained_by_the_changes(monitor: ResidualMonitor, r: np.ndarray, left: np.ndarray) -> bool:
    """Whether an alarm on what isolated changes leave is no new change: the residual
    ``left`` [N, 6] on its window is within what a named hypothesis may leave of the model's
    residual ``r`` there (isolation's rule: the model's error grows with the first change;
    small excursions of it are not a second fault)."""
    excess = noise_ratio(monitor, r - monitor.mu_) - 1.0
    left_ratio = noise_ratio(monitor, left - monitor.mu_)
    return left_ratio <= max(UNEXPLAINED_RATIO, 1.0 + UNEXPLAINED_SHARE * excess)


class Rewatch:
    """The monitor on the residual that the isolated changes of one experiment leave (the
    module docstring), for :func:`detect` and ``detect --follow`` alike: the changes' fitted
    hypotheses, and EWMA and CUSUM started fresh at the end of the latest one's window."""

    def __init__(self, monitor: ResidualMonitor) -> None:
        self.monitor = monitor
        self.cfg = monitor._cfg(monitor.threshold_values, monitor.interval)
        self.fitted: list[tuple[str, float]] = []
        self.state = np.zeros(kernel.STATE_SIZE)
        self.t_prev = np.nan

    def restart(self, t_prev: float, fitted: list[tuple[str, float]] = ()) -> None:
        """Fresh statistics after the time ``t_prev`` (the end of an alarm's window), with the
        isolated change ``fitted`` (:attr:`Diagnosis.fitted`) also taken out."""
        self.fitted = [*self.fitted, *fitted]
        self.state[:] = 0.0
        self.t_prev = float(t_prev)

    def left(self, data: dict, rows: np.ndarray, r: np.ndarray) -> np.ndarray:
        """What the changes leave of the model's residual ``r`` [N, 6] on ``rows``: minus
        their signature (:func:`nnid.fault.isolation.signature`, linear in the changes)."""
        # where a change cannot be shown (NaN) the residual is left as it was: watched blind
        # there, a later fault would pass unsaid
        return r - np.nan_to_num(signature(self.monitor, data, rows, self.fitted))

    def step(self, ts: np.ndarray, left: np.ndarray) -> np.ndarray:
        """The statistics of the rows at times ``ts`` (after those of the last call) on the
        residual ``left``: [N, 21] as :func:`nnid.fault.kernel.run` gives them."""
        m = self.monitor
        out = kernel.watch(self.t_prev, ts, left, self.cfg, m.mu_, m.whiten_, m.s_inv_,
                           self.state, np.empty((ts.size, 21)))  # fmt: skip
        if ts.size:
            self.t_prev = float(ts[-1])
        return out


def detect(monitor: ResidualMonitor, log: pd.DataFrame, window_s: float = 10.0) -> DetectResult:
    """Every alarm on ``log`` with its isolation on the ``window_s`` seconds after it; after an
    isolated change, the monitor watches what that change leaves (the module docstring). The
    trace keeps the model's residual r; its statistics and alarms are those watched."""
    start = time.perf_counter()
    data = monitor_inputs(log, monitor.plant_)
    trace = monitor.run(log)
    values, alarm = trace.values.copy(), trace.alarm.copy()
    residual = trace.values[:, 0:6].copy()  # the residual watched, re-referenced per change
    names = run_names(data["experiment_names"], data["experiment"], "experiment" in log)
    watched = Trace(trace.t, names, values, alarm)
    t, codes = data["t"], data["experiment"]
    rewatch: dict[int, Rewatch] = {}  # per experiment
    alarms, pos = [], 0
    changed = np.zeros(t.size, dtype=bool)  # rows watched on a re-referenced residual
    while (ks := np.flatnonzero(alarm[pos:])).size:
        k = pos + int(ks[0])
        if changed[k]:
            rows = window_rows(data, k, window_s)
            if explained_by_the_changes(monitor, trace.values[rows, 0:6], residual[rows]):
                alarm[k] = False  # dismissed: no record, so no mark in the trace either
                _rewatch(rewatch[int(codes[k])], data, residual, values, alarm, rows, changed)
                pos = int(rows[-1]) + 1
                continue
        record, diag, rows = isolated_alarm(monitor, data, watched, k, window_s, residual)
        alarms.append(record)
        pos = k + 1
        if diag.isolated:
            w = rewatch.setdefault(int(codes[k]), Rewatch(monitor))
            _rewatch(w, data, residual, values, alarm, rows, changed, diag.fitted)
            pos = int(rows[-1]) + 1
    return DetectResult(watched, alarms, time.perf_counter() - start)


def _rest(data: dict, rows: np.ndarray) -> np.ndarray:
    """The rows of the experiment after ``rows``."""
    codes = data["experiment"]
    k = int(rows[-1])
    return np.arange(k + 1, int(np.flatnonzero(codes == codes[k])[-1]) + 1)


def _rewatch(w: Rewatch, data, residual, values, alarm, rows, changed, fitted=()) -> None:
    """Watch ``residual`` from fresh statistics on the rest of the experiment after ``rows``
    (the window of an alarm: no new alarm within it); values and alarms rewritten there.
    ``fitted``: a change just isolated, taken out of the model's residual there first."""
    rest = _rest(data, rows)
    alarm[rows[0] + 1 : rows[-1] + 1] = False
    changed[rest] = True
    w.restart(data["t"][rows[-1]], fitted)
    if fitted:  # values' first six columns are still the model's residual r
        residual[rest] = w.left(data, rest, values[rest, 0:6])
    if rest.size:
        out = w.step(data["t"][rest], residual[rest])
        values[rest, 6:20] = out[:, 6:20]
        alarm[rest] = out[:, 20] == 1
