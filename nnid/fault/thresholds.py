"""Thresholds for a target false-alarm rate, from healthy data, and the measured rate.

A monitor statistic is autocorrelated, so a per-sample quantile says little about alarms per
hour. An alarm is an *excursion* of the statistic above its threshold; the rate of excursions
above a high threshold is extrapolated from the healthy record by peaks over threshold: the
peaks of the declustered excursions above a base level u follow a generalized Pareto
distribution (Pickands-Balkema-de Haan), so the rate above h > u is λ_u · P(peak − u > h − u).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.stats import chi2, genpareto

MIN_PEAKS = 20


def excursion_peaks(series: np.ndarray, level: float, gap: int) -> np.ndarray:
    """Peak of each excursion of ``series`` above ``level``; excursions closer than ``gap``
    samples are one (an alarm does not re-arm in between). NaN samples are below."""
    above = np.nan_to_num(series, nan=-np.inf) > level
    idx = np.flatnonzero(above)
    if idx.size == 0:
        return np.zeros(0)
    breaks = np.flatnonzero(np.diff(idx) > gap)
    starts = np.r_[idx[0], idx[breaks + 1]]
    ends = np.r_[idx[breaks], idx[-1]]
    return np.array([np.nanmax(series[a : b + 1]) for a, b in zip(starts, ends, strict=True)])


def rate_threshold(
    series: Sequence[np.ndarray],
    hours: float,
    rate_per_hour: float,
    gap: int,
    base_quantile: float = 0.95,
) -> dict:
    """The level a statistic crosses ``rate_per_hour`` times per hour on healthy ``series``
    (one array per experiment, ``hours`` in all): a generalized Pareto fit to the declustered
    excursion peaks above the ``base_quantile`` level. With fewer than 20 peaks the fit is not
    made: the threshold is twice the largest healthy value and ``"method"`` says so. The shape
    is kept ≥ 0 (exponential or heavier tail). The threshold is at least the smallest positive
    healthy value: a statistic at 0 most of the time (a CUSUM within its allowance) has a base
    level of 0, and a target at or above its rate of leaving 0 set a threshold of 0, every rise
    an alarm whose severity (its peak over the threshold) was infinite. Raised from 0 to that
    value, the healthy rate above it can only fall: it stays at or below the target. A
    ValueError where no healthy value is finite, or none is above 0."""
    values = np.concatenate([s[np.isfinite(s)] for s in series]) if series else np.zeros(0)
    if values.size == 0:
        raise ValueError("no finite healthy values to calibrate on")
    positive = values[values > 0]
    if positive.size == 0:
        raise ValueError("the healthy values never rise above 0: no threshold is set over them")
    floor = float(positive.min())
    level = float(np.quantile(values, base_quantile))
    peaks = np.concatenate([excursion_peaks(s, level, gap) for s in series])
    top = float(values.max())
    out = {"base_level": level, "peaks": int(peaks.size), "healthy_max": top}
    if peaks.size < MIN_PEAKS:
        return {**out, "value": 2.0 * top, "method": "2 x healthy maximum (too few peaks)"}
    shape, _, scale = genpareto.fit(peaks - level, floc=0.0)
    if shape < 0:
        # a quadratic form of Gaussian residuals has an exponential tail (shape 0); a bounded
        # tail fitted to a short healthy record would put the threshold at the largest value
        # seen, and every longer record beats it
        shape, scale = 0.0, float(np.mean(peaks - level))
    rate_u = peaks.size / hours
    if rate_per_hour >= rate_u:
        value = level
    else:
        value = level + float(genpareto.isf(rate_per_hour / rate_u, shape, 0.0, scale))
    if not np.isfinite(value):
        value = 2.0 * top
    return {
        **out,
        "value": float(max(value, level, floor)),
        "method": "generalized Pareto, peaks over threshold",
        "shape": float(shape),
        "scale": float(scale),
        "rate_above_base_per_hour": rate_u,
    }


def rate_caveat(thresholds: dict, hours: float, rate_per_hour: float) -> str | None:
    """Why thresholds from :func:`rate_threshold` (``{"ewma": ..., "cusum": ...}``, set on
    ``hours`` of healthy data) do not hold the target ``rate_per_hour``: a statistic with
    fewer than :data:`MIN_PEAKS` peaks got no rate fit. None where both were fitted. Read
    from the thresholds alone, so a saved ``metrics.json`` says it as the monitor does."""
    few = {k: v["peaks"] for k, v in thresholds.items() if v["peaks"] < MIN_PEAKS}
    if not few:
        return None
    counts = " and ".join(f"{n} {k.upper()}" for k, n in few.items())
    return (
        f"the healthy record ({60 * hours:.1f} min) gives {counts} excursion peak(s), fewer "
        f"than the {MIN_PEAKS} a rate fit needs: those thresholds are twice the largest healthy "
        f"value, and the false-alarm rate of {rate_per_hour:g} per hour is not controlled "
        "(calibrate on a longer healthy record)"
    )


def measured_caveat(measured: dict | None, rate_per_hour: float) -> str | None:
    """Why a healthy record the calibration never saw says the target ``rate_per_hour`` is not
    held: ``measured`` (:meth:`~nnid.fault.monitor.ResidualMonitor.false_alarms`) has its
    rate's exact interval wholly above the target. None where nothing measured it, or its
    interval reaches the target (a fitted tail said controlled beside 1 alarm in 20 s, 180 per
    hour with an interval of 4.6-1000, against a target of 0.01)."""
    if measured is None or not measured["interval"][0] > rate_per_hour:
        return None
    lo, hi = measured["interval"]
    return (
        f"the healthy test part measured {measured['alarms']} false alarm(s) in "
        f"{60 * measured['hours']:.1f} min, {measured['rate_per_hour']:.3g} per hour "
        f"({100 * measured['confidence']:.0f} % interval {lo:.3g}-{hi:.3g}), above the target "
        f"of {rate_per_hour:g} per hour: the thresholds do not hold it (calibrate on a longer or "
        "more varied healthy record)"
    )


def threshold_caveat(
    thresholds: dict, hours: float, measured: dict | None, rate_per_hour: float
) -> str | None:
    """Why thresholds set on ``hours`` of healthy data do not hold the target
    ``rate_per_hour``: too few peaks for a rate fit (:func:`rate_caveat`), a healthy record
    the calibration never saw whose rate lies wholly above it (``measured``:
    :func:`measured_caveat`), both joined; None where neither. The one reading of the monitor
    (:meth:`~nnid.fault.monitor.ResidualMonitor.threshold_caveat`) and of a saved
    ``metrics.json``."""
    said = [rate_caveat(thresholds, hours, rate_per_hour), measured_caveat(measured, rate_per_hour)]
    return "; ".join(c for c in said if c) or None


def rate_interval(count: int, hours: float, confidence: float = 0.95) -> tuple[float, float]:
    """Exact (Garwood) interval of a Poisson rate per hour from ``count`` events."""
    a = 1.0 - confidence
    lo = 0.0 if count == 0 else chi2.ppf(a / 2, 2 * count) / 2
    hi = chi2.ppf(1 - a / 2, 2 * count + 2) / 2
    return float(lo / hours), float(hi / hours)
