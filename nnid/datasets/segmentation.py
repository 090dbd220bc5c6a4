"""Transient / steady-state labels and a sampler that weighs them equally (Weiss V.B).

Weiss found that a network trained on a log that is mostly steady state misses the transients.
The rule that labels a sample *transient*, per DOF and experiment:

1. the body acceleration a_k: Savitzky-Golay derivative of the velocity (``window_s``, cubic),
   or the logged ``d<v>`` when there is no velocity column;
2. its noise level n_k: the velocity's white-noise level (robust spread of the velocity about
   its SG fit) times the filter's noise gain sqrt(Σcₖ²) (filter theory), or, for logged
   accelerations, the robust spread of their first differences / sqrt(2);
3. its manoeuvre scale s_k: the 99th percentile of |a_k|;
4. a sample is transient when any DOF with s_k > 3 n_k has |a_k| > max(rel · s_k, 3 n_k)
   (rel = 0.1 by default), and the labels are dilated by ``hold`` seconds so the tail of each
   manoeuvre counts with it.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd
from scipy.ndimage import binary_dilation
from scipy.stats import median_abs_deviation

from nnid.datasets.log import VELOCITY, run_label, typical_step
from nnid.datasets.preprocess import (
    experiment_rows,
    run_window,
    savgol_derivative,
    savgol_noise_gain,
    short_piece,
    uneven_runs,
)


def accelerations_with_noise(
    log: pd.DataFrame, window_s: float = 1.0, order: int = 3, rows: np.ndarray | None = None
) -> tuple[pd.DataFrame, dict[str, float]]:
    """Body accelerations per DOF present, and the noise level of each (see module rule),
    measured on ``rows`` (a boolean mask; all by default). An empty cell is a gap: the
    derivative and the noise are taken from the stretches between gaps (the first or last
    window of a run stopped the edge fit with a bare ValueError, elsewhere the noise went
    NaN), and a piece of a run cut at a gap shorter than the window (:func:`short_piece`)
    gets none, said in a warning."""
    acc, noise = {}, {}
    rows = np.ones(len(log), dtype=bool) if rows is None else np.asarray(rows, dtype=bool)
    t_all = log["t"].to_numpy(np.float64)
    short: dict[object, int] = {}  # the pieces shorter than the window: their samples
    for c in VELOCITY:
        if c in log:
            col, sig = np.full(len(log), np.nan), []
            values = log[c].to_numpy(np.float64)
            for name, pos in experiment_rows(log):
                v = values[pos]
                dt, w = run_window(t_all[pos], window_s, order, name)
                if short_piece(log, pos, w):
                    short[name] = len(pos)
                    continue
                col[pos] = savgol_derivative(v, dt, w, order, where=f"experiment {name!r}")
                if not rows[pos].any():
                    continue
                # the fit of each stretch between gaps (deriv 0): a log without one, as before
                fit = savgol_derivative(v, 1.0, w, order, deriv=0, where=f"experiment {name!r}")
                resid = (v - fit)[rows[pos]]
                resid = resid[np.isfinite(resid)]  # a gap, or a stretch shorter than w
                if resid.size:
                    sigma_v = median_abs_deviation(resid, scale="normal")
                    sig.append(sigma_v * savgol_noise_gain(w, order, dt))
            acc[c], noise[c] = col, float(np.median(sig)) if sig else np.nan
        elif "d" + c in log:
            a = log["d" + c].to_numpy(np.float64)
            acc[c] = a
            steps = np.diff(a)[rows[1:] & rows[:-1]]  # a step of two measured rows
            steps = steps[np.isfinite(steps)]  # not one into or out of a gap
            noise[c] = (
                float(median_abs_deviation(steps, scale="normal") / np.sqrt(2))
                if steps.size
                else np.nan
            )
    if not acc:
        raise ValueError("labelling transients needs body velocities or accelerations")
    if any(c in log for c in VELOCITY):
        uneven_runs(log, "the Savitzky-Golay derivative")
    if short:
        named = ", ".join(run_label(n) for n in list(short)[:3]) + (", …" if len(short) > 3 else "")
        warnings.warn(
            f"{sum(short.values())} samples in {len(short)} piece"
            f"{'' if len(short) == 1 else 's'} of runs cut at gaps ({named}) shorter than the "
            f"Savitzky-Golay window of {window_s:g} s that labels transients: no acceleration "
            "there, labelled steady",
            stacklevel=3,
        )
    return pd.DataFrame(acc, index=log.index), noise


def label_transients(
    log: pd.DataFrame,
    rel: float = 0.1,
    hold: float = 0.5,
    window_s: float = 1.0,
    rows: np.ndarray | None = None,
) -> pd.Series:
    """Boolean Series, True where the sample is transient (rule in the module docstring).
    ``rows`` (a boolean mask; all by default): the rows whose manoeuvre scales and noise
    levels set the thresholds, e.g. a random division's training rows; every row is labelled.
    A sample without an acceleration (a gap, a stretch or piece shorter than the window) is
    steady, and the scales and noise levels are read from the samples with one."""
    acc, noise = accelerations_with_noise(log, window_s, rows=rows)
    fit = slice(None) if rows is None else np.asarray(rows, dtype=bool)
    labels = np.zeros(len(log), dtype=bool)
    for c in acc.columns:
        a = np.abs(acc[c].to_numpy())
        known = a[fit][np.isfinite(a[fit])]  # a log without a gap: every sample, as before
        if not known.size or not np.isfinite(noise[c]):
            continue  # a DOF with no acceleration to read a scale or noise from
        scale = np.percentile(known, 99)
        if scale <= 3 * noise[c]:
            continue  # a DOF that never moves beyond its noise
        labels |= a > max(rel * scale, 3 * noise[c])
    out = np.zeros_like(labels)
    for _, pos in experiment_rows(log):
        t = log["t"].to_numpy(np.float64)[pos]
        steps = max(0, round(hold / typical_step(t, np.nan)))
        seg = labels[pos]
        out[pos] = binary_dilation(seg, iterations=steps) if steps and seg.any() else seg
    return pd.Series(out, index=log.index, name="transient")


def run_bounds(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First index and one-past-last index of each contiguous run of equal codes (the
    experiments of a log, in order)."""
    codes = np.asarray(codes)
    starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
    return starts, np.r_[starts[1:], codes.size]


class BalancedSampler:
    """Draws training samples (window ends) so that transient and steady-state samples carry
    equal total weight; any trainer can use it. Deterministic for a seed.

    ``window`` is the history a sample needs (NARX delays): the first ``window − 1`` samples of
    each experiment are not eligible. With ``balance=False`` every eligible sample weighs the
    same (the raw log).
    """

    def __init__(
        self,
        labels: pd.Series | np.ndarray,
        experiment: np.ndarray | None = None,
        window: int = 1,
        balance: bool = True,
        seed: int = 0,
    ) -> None:
        self.labels = np.asarray(labels, dtype=bool)
        n = self.labels.size
        experiment = np.zeros(n) if experiment is None else np.asarray(experiment)
        eligible = np.ones(n, dtype=bool)
        starts, _ = run_bounds(experiment)
        for s in starts:
            eligible[s : s + window - 1] = False
        self.eligible = eligible
        self.balance = balance
        self.seed = seed

    def weights(self) -> np.ndarray:
        """Per-sample probability; transient and steady each sum to 0.5 when both exist."""
        w = self.eligible.astype(float)
        if self.balance:
            trans, steady = self.eligible & self.labels, self.eligible & ~self.labels
            if trans.any() and steady.any():
                w[trans] = 0.5 / trans.sum()
                w[steady] = 0.5 / steady.sum()
        return w / w.sum()

    def sample(self, n: int, epoch: int = 0) -> np.ndarray:
        """``n`` sample indices drawn with replacement (a new, reproducible draw per epoch)."""
        rng = np.random.default_rng([self.seed, epoch])
        return rng.choice(self.labels.size, size=n, replace=True, p=self.weights())

    def transient_share(self, indices: np.ndarray | None = None) -> float:
        """Share of transient samples among ``indices`` (or among eligible samples)."""
        idx = np.flatnonzero(self.eligible) if indices is None else np.asarray(indices)
        return float(self.labels[idx].mean())
