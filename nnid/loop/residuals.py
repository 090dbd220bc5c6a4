"""Residual analysis of a fitted model on held-out data.

What the model leaves unexplained, in the two forms an engineer reads:

- the force residual per DOF, R = M ν̇ − (τ_eff + b − Cν + τ_D − g): McCarter's τ̄ (eq. 4.4)
  minus the model's damping, in N and N m;
- MATLAB ``resid``-style correlation analysis: the normalised autocorrelation of each
  residual and its cross-correlation with each input over ±25 lags, with the band a white
  residual stays inside with 99 % probability (±z/√N, z = 2.576). A residual outside its
  autocorrelation band has structure the model misses; outside a cross-correlation band it
  still depends on that input.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm


@dataclass
class Correlation:
    """Correlation analysis of one residual signal."""

    lags: np.ndarray  # [2 L + 1], -L .. L
    auto: np.ndarray  # autocorrelation at lags 0..L, [L + 1]
    cross: dict[str, np.ndarray]  # input name -> cross-correlation at lags -L..L
    band: float  # half-width of the confidence band
    n: int

    @property
    def auto_outside(self) -> float:
        """Fraction of lags 1..L whose autocorrelation leaves the band."""
        return float(np.mean(np.abs(self.auto[1:]) > self.band)) if self.auto.size > 1 else 0.0

    def cross_outside(self) -> dict[str, float]:
        """Per input, the fraction of lags whose cross-correlation leaves the band."""
        return {k: float(np.mean(np.abs(v) > self.band)) for k, v in self.cross.items()}

    def as_dict(self) -> dict:
        return {
            "band": self.band,
            "n": self.n,
            "autocorrelation_outside": self.auto_outside,
            "cross_correlation_outside": self.cross_outside(),
        }


def _segments_corr(a: np.ndarray, b: np.ndarray, segments: list[np.ndarray], lag: int) -> float:
    """Σ a[t] b[t − lag] over pairs inside one segment (experiments are not joined)."""
    total = 0.0
    for idx in segments:
        x, y = a[idx], b[idx]
        if lag >= 0:
            total += float(x[lag:] @ y[: x.size - lag]) if lag < x.size else 0.0
        else:
            total += float(x[: x.size + lag] @ y[-lag:]) if -lag < x.size else 0.0
    return total


def correlation_analysis(
    residual: np.ndarray,
    inputs: dict[str, np.ndarray],
    experiment: np.ndarray | None = None,
    max_lag: int = 25,
    confidence: float = 0.99,
) -> Correlation:
    """Autocorrelation of ``residual`` and its cross-correlation with each input (MATLAB
    ``resid``: ±``max_lag`` lags, ``confidence`` band ±z/√N). Means are removed per signal;
    lagged products never pair samples of different experiments. NaN samples are dropped."""
    residual = np.asarray(residual, dtype=np.float64)
    n = residual.size
    experiment = np.zeros(n, dtype=int) if experiment is None else np.asarray(experiment)
    ok = np.isfinite(residual)
    for v in inputs.values():
        ok &= np.isfinite(v)
    segments = [np.flatnonzero((experiment == e) & ok) for e in np.unique(experiment)]
    segments = [s for s in segments if s.size > 1]
    e = np.where(ok, residual - residual[ok].mean() if ok.any() else 0.0, 0.0)
    n_ok = int(ok.sum())
    lags = np.arange(-max_lag, max_lag + 1)
    ee = _segments_corr(e, e, segments, 0)
    auto = np.array(
        [_segments_corr(e, e, segments, k) / ee if ee > 0 else 0.0 for k in range(max_lag + 1)]
    )
    cross = {}
    for name, u in inputs.items():
        u = np.asarray(u, dtype=np.float64)
        uc = np.where(ok, u - u[ok].mean() if ok.any() else 0.0, 0.0)
        uu = _segments_corr(uc, uc, segments, 0)
        scale = np.sqrt(ee * uu)
        cross[name] = np.array(
            [_segments_corr(e, uc, segments, k) / scale if scale > 0 else 0.0 for k in lags]
        )
    band = float(norm.ppf(0.5 + confidence / 2.0) / np.sqrt(max(n_ok, 1)))
    return Correlation(lags, auto, cross, band, n_ok)
