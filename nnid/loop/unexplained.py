"""Structure left in the held-out residual that no effect of the vocabulary explains.

After the loop's last pass the held-out force residual of each analysed DOF is tested for what
a residual made of measurement noise cannot show:

- **autocorrelation beyond the differentiation window.** The accelerations are Savitzky-Golay
  derivatives over ``window`` samples, so white measurement noise leaves a moving-average
  residual of order q = window − 1 and no correlation at longer lags. Beyond q each sample
  autocorrelation has Bartlett's variance (1 + 2 Σ_{j≤q} ρ_j²)/N (Box & Jenkins, MA(q) test);
- **cross-correlation with the inputs and with input × velocity products** at lags up to
  ±``max_lag_s``, with Bartlett's variance for two autocorrelated series, Σ_j ρ_xx(j) ρ_yy(j)/N.

Both bands are Bonferroni-corrected at ``alpha`` over every lag and signal tested, and a
correlation must also reach ``min_corr`` in size (16 % of the residual variance at 0.4), and a
cross-correlation must lie outside the derivative's half window: on simulated logs with no
missing effect, the parameter error of the fit itself leaves correlations up to 0.35 at long
lags and 0.45 within the half window (2 of 40 logs at a floor of 0.25), while a tether's tug, a
ballast change and a distorted thrust curve leave 0.5 to 0.8. Last, the correlated part must
be material: at least ``min_share`` (2 %) of the RMS force that drives the DOF. A well-fitted
DOF with a quiet sensor (yaw on a gyro) shows the fit's own percent-level bias as structure
far above its noise, yet worth a fraction of a percent of its force.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.signal import correlate, savgol_coeffs
from scipy.stats import norm


@dataclass
class Correlate:
    """One signal the residual correlates with beyond its band."""

    signal: str  # "own past", an input ("tau_Z") or a product ("tau_Z*u")
    lag_s: float
    correlation: float
    band: float


def _centred_segments(x: np.ndarray, groups: list[np.ndarray]) -> list[np.ndarray]:
    mean = np.mean(np.concatenate([x[g] for g in groups]))
    return [x[g] - mean for g in groups]


def _xcorr(a: list[np.ndarray], b: list[np.ndarray], max_lag: int) -> np.ndarray:
    """Σ a[t] b[t − k] / sqrt(Σa² Σb²) for k = −max_lag..max_lag, summed over the segments
    (pairs never span two segments)."""
    total = np.zeros(2 * max_lag + 1)
    for x, y in zip(a, b, strict=True):
        full = correlate(x, y, mode="full", method="fft")  # lag k at index len(y) − 1 + k
        mid = y.size - 1
        lo, hi = max(mid - max_lag, 0), min(mid + max_lag, full.size - 1)
        total[lo - mid + max_lag : hi - mid + max_lag + 1] += full[lo : hi + 1]
    scale = np.sqrt(sum(float(x @ x) for x in a) * sum(float(y @ y) for y in b))
    return total / scale if scale > 0 else total


def unexplained_structure(
    residual: np.ndarray,
    inputs: dict[str, np.ndarray],
    velocities: dict[str, np.ndarray],
    experiment: np.ndarray,
    dt: float,
    window: int,
    order: int = 4,
    alpha: float = 0.01,
    min_corr: float = 0.4,
    max_lag_s: float = 5.0,
    top: int = 3,
    force_rms: float | None = None,
    min_share: float = 0.02,
    memo: dict | None = None,
) -> list[Correlate]:
    """The strongest correlates of one DOF's held-out ``residual`` outside their bands
    (module docstring), strongest first; empty when the residual is consistent with noise.
    ``force_rms``: the RMS of the force that drives this DOF; a correlate whose share of the
    residual, |ρ| · RMS(residual), is below ``min_share`` of it is immaterial. ``memo``: a
    dict shared by the calls for the DOFs of one residual (the same inputs, velocities,
    experiments, ``dt``, ``window`` and ``max_lag_s``), which then centre and autocorrelate
    each signal once for all DOFs whose finite samples are the same."""
    ok = np.isfinite(residual)
    for v in (*inputs.values(), *velocities.values()):
        ok &= np.isfinite(v)
    groups = [np.flatnonzero((experiment == e) & ok) for e in dict.fromkeys(experiment)]
    groups = [g for g in groups if g.size > window]
    n = sum(g.size for g in groups)
    if n < 4 * window:
        return []
    q = window - 1
    max_lag = min(max(round(max_lag_s / dt), q + 1), n // 4)
    e = _centred_segments(residual, groups)
    auto = _xcorr(e, e, max_lag)[max_lag:]  # lags 0..max_lag
    signals = dict(inputs)
    for name, u in inputs.items():
        for dof, nu in velocities.items():
            signals[f"{name}*{dof}"] = u * nu
    lags_auto = np.arange(q + 1, max_lag + 1)
    tests = lags_auto.size + len(signals) * (2 * max_lag + 1)
    z = float(norm.isf(alpha / (2 * max(tests, 1))))
    found: list[Correlate] = []
    # the noise-only residual's autocorrelation: that of the SG derivative kernel, so the
    # bands are those of the null hypothesis, not widened by the structure under test
    rho0 = np.zeros(max_lag + 1)
    if window > 1:
        c = savgol_coeffs(window, min(order, window - 1), deriv=1)
        full = np.correlate(c, c, mode="full")[c.size - 1 :]
        rho0[: min(full.size, max_lag + 1)] = (full / full[0])[: max_lag + 1]
    else:
        rho0[0] = 1.0
    if lags_auto.size:
        band = z * np.sqrt((1 + 2 * np.sum(rho0[1 : q + 1] ** 2)) / n)
        k = lags_auto[np.argmax(np.abs(auto[lags_auto]))]
        if abs(auto[k]) > max(band, min_corr):
            found.append(Correlate("own past", float(k * dt), float(auto[k]), float(band)))
    samples = ok.tobytes()  # a signal's centred segments depend on the samples kept
    for name, s in signals.items():
        key = (name, samples, max_lag)
        if memo is not None and key in memo:
            x, sx = memo[key]
        else:
            x = _centred_segments(s, groups)
            sx = _xcorr(x, x, max_lag) if any(np.any(xi) for xi in x) else None
            if memo is not None:
                memo[key] = (x, sx)
        if sx is None:  # a signal that is zero wherever the residual is scored
            continue
        rho = _xcorr(e, x, max_lag)
        # Bartlett: Σ_j ρ_ee(j) ρ_xx(j) over j = −max_lag..max_lag (both even in j)
        var = (rho0[0] * sx[max_lag] + 2 * np.sum(rho0[1:] * sx[max_lag + 1 :])) / n
        band = z * np.sqrt(max(var, 1.0 / n))
        # within the derivative's half window a parameter error of the fit itself correlates
        # the residual with the inputs (a held-out regime the training part excited less):
        # structure, but not evidence of a missing effect
        rho[max_lag - q // 2 : max_lag + q // 2 + 1] = 0.0
        k = int(np.argmax(np.abs(rho)))
        if abs(rho[k]) > max(band, min_corr):
            found.append(Correlate(name, float((k - max_lag) * dt), float(rho[k]), float(band)))
    if force_rms:
        size = float(np.sqrt(sum(float(x @ x) for x in e) / n))
        found = [c for c in found if abs(c.correlation) * size >= min_share * force_rms]
    found.sort(key=lambda c: -abs(c.correlation))
    return found[:top]


def describe(dof_word: str, found: list[Correlate], stopped_at_limit: bool = False) -> str:
    """The verdict in words, naming the strongest correlates; ``stopped_at_limit``: the loop
    stopped at its ``max_effects`` before testing the rest of the vocabulary, so what remains
    may be in it."""
    parts = []
    for c in found:
        what = (
            f"its own past {c.lag_s:.2g} s earlier"
            if c.signal == "own past"
            else f"{c.signal.replace('*', ' × ')} at a lag of {c.lag_s:.2g} s"
        )
        parts.append(f"{what} (correlation {c.correlation:.2f}, band ±{c.band:.2f})")
    what = (
        "an effect remains (the loop stopped at max_effects: the rest of the vocabulary was "
        "not tested)"
        if stopped_at_limit
        else "an effect outside the vocabulary remains"
    )
    return f"{what} in the held-out {dof_word} residual: it correlates with {'; '.join(parts)}"


def as_records(found: list[Correlate]) -> list[dict]:
    return [asdict(c) for c in found]
