"""Prediction modes of physics models on a log: one step, k steps, free run.

A physics model here is a :class:`nnid.models.parametric.Parts` (or anything with ``model()``
and ``applied()``): the log's nominal inputs pass through its installation coefficients, and
the compiled RK4 integrates from measured states. Missing state components start at zero.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from nnid.datasets.log import POSE, VELOCITY
from nnid.datasets.preprocess import experiments
from nnid.physics import compiled


def measured_states(log: pd.DataFrame) -> np.ndarray:
    """[N, 12] pose and velocity from the log (absent columns are zero)."""
    x = np.zeros((len(log), 12))
    for k, c in enumerate((*POSE, *VELOCITY)):
        if c in log:
            x[:, k] = log[c].to_numpy(np.float64)
    return np.nan_to_num(x)  # an undefined component (w of a tumbling vehicle) starts at zero


def predict_states(
    parts, log: pd.DataFrame, tau_nominal: np.ndarray, mode="free_run", substeps: int = 1
) -> pd.DataFrame:
    """Predicted pose and velocity columns for ``mode`` = "one_step", "free_run" or k (int).

    Row i holds the prediction of sample i; the first k samples of each experiment (k = 1 for
    one step) repeat the measurement and belong to the warm-up.
    """
    form = parts.model(check=False).feature_form()
    tau = parts.applied(tau_nominal)
    x = measured_states(log)
    out = x.copy()
    k = 1 if mode == "one_step" else mode
    for _, idx in experiments(log):
        pos = log.index.get_indexer(idx)
        t = log["t"].to_numpy(np.float64)[pos]
        dt = float(np.median(np.diff(t)))
        if mode == "free_run":
            out[pos] = compiled.integrate_rk4(form, x[pos[0]], tau[pos[:-1]], dt, substeps)
            continue
        if not isinstance(k, int) or k < 1:
            raise ValueError("mode is 'one_step', 'free_run' or a positive number of steps")
        n = pos.size - k
        if n <= 0:
            continue
        windows = np.stack([tau[pos[j : j + n]] for j in range(k)], 1)
        last = compiled.integrate_rk4(form, x[pos[:n]], windows, dt, substeps)[:, -1]
        out[pos[k:]] = last
    return pd.DataFrame(out, columns=[*POSE, *VELOCITY], index=log.index)
