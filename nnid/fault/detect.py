"""Detection end to end: the monitor over a log, each alarm isolated on the window after it.

The alarm records follow the ``detect.json`` contract (ARCHITECTURE.md): time, kind, thruster and
remaining efficiency, effect, severity (the peak of the larger statistic over its threshold in the
window) and confidence.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import pandas as pd

from nnid.fault.isolation import isolate
from nnid.fault.monitor import ResidualMonitor, Trace, monitor_inputs

ALARM_FIELDS = ["experiment", "t", "kind", "thruster", "efficiency", "efficiency_low",
                "efficiency_high", "effect", "value", "stderr", "severity", "confidence",
                "explained", "meaning"]  # fmt: skip


@dataclass
class DetectResult:
    trace: Trace
    alarms: list[dict]
    seconds: float


def alarm_record(
    monitor: ResidualMonitor, data: dict, trace: Trace, k: int, window_s: float
) -> dict:
    """The alarm that starts at row ``k``, isolated on [t_k, t_k + window_s]. The window starts
    at the alarm, never before: the change began at or before the alarm, and healthy samples
    before its onset would bias the size of the change toward zero."""
    t, codes = data["t"], data["experiment"]
    rows = np.flatnonzero((codes == codes[k]) & (t >= t[k]) & (t <= t[k] + window_s))
    diag = isolate(monitor, data, trace.values[:, 0:6], rows)
    h_t, h_g = monitor.threshold_values
    severity = float(
        np.nanmax(np.maximum(trace.values[rows, 18] / h_t, trace.values[rows, 19] / h_g))
    )
    interval = diag.efficiency_interval or (None, None)
    return {
        "experiment": str(trace.experiment[k]),
        "t": float(t[k]),
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
        "p_value": diag.p_value,
        "alternatives": diag.alternatives,
        "components": diag.components,
    }


def detect(monitor: ResidualMonitor, log: pd.DataFrame, window_s: float = 10.0) -> DetectResult:
    """Every alarm on ``log`` with its isolation on the ``window_s`` seconds after it."""
    start = time.perf_counter()
    data = monitor_inputs(log, monitor.plant_)
    trace = monitor.run(log)
    alarms = [
        alarm_record(monitor, data, trace, int(k), window_s) for k in np.flatnonzero(trace.alarm)
    ]
    return DetectResult(trace, alarms, time.perf_counter() - start)
