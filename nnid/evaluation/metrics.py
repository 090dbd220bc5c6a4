"""Error measures shared by every model.

NRMSE is the RMSE over the standard deviation of the measured signal (MATLAB's fit % is
100 (1 − NRMSE)); a warm-up window (delay states, the start of a free run) is excluded from
every score. ``total`` is the mean over the DOFs that the data excites.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from nnid.datasets.preprocess import experiment_rows


def warmup_mask(log: pd.DataFrame, warmup_s: float = 0.0, warmup_samples: int = 0) -> np.ndarray:
    """True where a sample is scored: after the warm-up at the start of each experiment."""
    keep = np.ones(len(log), dtype=bool)
    t = log["t"].to_numpy(np.float64)
    for _, pos in experiment_rows(log):
        keep[pos[:warmup_samples]] = False
        keep[pos] &= t[pos] - t[pos[0]] >= warmup_s
    return keep


def exact_mean(x) -> float:
    """The mean by an exactly rounded sum (:func:`math.fsum`); NaN for no values. A score then
    depends on the values alone, not on how a reduction groups them (NumPy's grouping follows
    the array's length, layout and SIMD kernel), so runs of one task on different workers agree
    wherever their predictions do. Scores reduce 10³-10⁵ samples: well under a millisecond."""
    values = np.asarray(x, dtype=np.float64).ravel()
    return math.fsum(values) / values.size if values.size else float("nan")


def exact_std(x) -> float:
    """The population standard deviation through :func:`exact_mean`."""
    values = np.asarray(x, dtype=np.float64).ravel()
    return math.sqrt(exact_mean((values - exact_mean(values)) ** 2)) if values.size else 0.0


def nrmse(measured: np.ndarray, predicted: np.ndarray) -> float:
    """RMSE / std(measured) over the measured samples; NaN where the measured signal does not
    vary, or where the prediction is not finite at a measured sample (a diverged prediction
    is not scored: over its finite part alone it read as a skilful one)."""
    measured, predicted = np.asarray(measured, float), np.asarray(predicted, float)
    ok = np.isfinite(measured)
    measured, predicted = measured[ok], predicted[ok]
    if not np.isfinite(predicted).all():
        return float("nan")
    std = exact_std(measured)
    if std == 0 or measured.size == 0:
        return float("nan")
    return math.sqrt(exact_mean((predicted - measured) ** 2)) / std


def rmse(measured: np.ndarray, predicted: np.ndarray) -> float:
    """RMS of predicted − measured over the measured samples; NaN for none, or where the
    prediction is not finite at a measured sample (as :func:`nrmse`: dropped, a diverged
    prediction read as a skilful one over its finite part)."""
    measured, predicted = np.asarray(measured, float), np.asarray(predicted, float)
    ok = np.isfinite(measured)
    measured, predicted = measured[ok], predicted[ok]
    if not np.isfinite(predicted).all() or measured.size == 0:
        return float("nan")
    return math.sqrt(exact_mean((predicted - measured) ** 2))


def per_dof(
    measured: pd.DataFrame,
    predicted: pd.DataFrame,
    columns: list[str],
    mask: np.ndarray,
    metric=nrmse,
) -> dict[str, float]:
    """The metric per column over the scored samples, and ``total``: their mean, NaN where a
    column has no score (as :func:`nnid.evaluation.evaluate.score_prediction`'s ``total``
    is None: a mean over the other columns would hide it)."""
    out = {c: metric(measured[c].to_numpy()[mask], predicted[c].to_numpy()[mask]) for c in columns}
    values = list(out.values())
    out["total"] = exact_mean(values) if values and all(np.isfinite(values)) else float("nan")
    return out
