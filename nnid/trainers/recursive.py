"""Recursive estimators on a :class:`Regression`: RLS with forgetting and the gradient estimator.

Both walk the rows of Φ θ = y in time order and keep θ after every sample in
``Estimate.history`` ``[n_samples, P]`` (row i is regression sample i: log sample i, or with
``filter_lambda`` the i-th sample after the filters have settled).

- :class:`RecursiveLeastSquares`: Weiss eqs 52-53 with exponential forgetting λ (memory
  1/(1 − λ) samples). The rows of one sample (one per DOF equation) are processed one by one as
  scalar updates, with the forgetting applied once per sample. With unit measurement weight this
  is exactly the block update K = P Φᵢᵀ(λI + Φᵢ P Φᵢᵀ)⁻¹ of the whole sample, without a matrix
  inverse.
- :class:`GradientEstimator`: Weiss eqs 62-65, θ̇ = −p₀ φ e = Γ φ (y − φᵀθ), discretised by
  forward Euler over the sample interval (optionally normalised). Its sensitivity to noise is
  eq 70: the disturbance d enters θ̇ directly through Γ φ d.

The inner loops are compiled with numba (machine code cached on disk).
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Sequence
from statistics import NormalDist

import numpy as np
from numba import njit
from sklearn.base import BaseEstimator

from nnid.datasets.log import log_step
from nnid.errors import NnidInputError
from nnid.evaluation.persistence import ExcitationReport, equation_rms, excitation_from_gram
from nnid.trainers.history import Progress, silent
from nnid.trainers.least_squares import (
    Estimate,
    ExcitationWarning,
    dof_sandwich,
    dof_variances,
    equation_times,
    feasible_floor,
    feasible_weights,
    read_only_where_left_out,
    rounding_scale,
    void_undetermined,
    warn_left_out,
)
from nnid.trainers.regression import Regression
from nnid.validation import shown


@njit(cache=True)
def _row_finite(phi, y, row):  # pragma: no cover - compiled
    """True when the row's target and regressors are all finite (others are skipped)."""
    if not math.isfinite(y[row]):
        return False
    for a in range(phi.shape[1]):
        if not math.isfinite(phi[row, a]):
            return False
    return True


@njit(cache=True)
def _rls(phi, y, m, lam, trace_max, theta, p_mat, history):  # pragma: no cover - compiled
    """RLS over samples of ``m`` rows (Weiss eqs 52-53 with forgetting λ), in place on θ, P."""
    n_par = phi.shape[1]
    g = np.empty(n_par)
    for i in range(history.shape[0]):
        if lam < 1.0:
            tr = 0.0
            for a in range(n_par):
                tr += p_mat[a, a]
            if tr < trace_max:  # forgetting suspended while P is large (windup guard)
                inv_lam = 1.0 / lam
                for a in range(n_par):
                    for b in range(n_par):
                        p_mat[a, b] *= inv_lam
        for k in range(m):
            row = i * m + k
            if not _row_finite(phi, y, row):
                continue
            denom = 1.0
            err = y[row]
            for a in range(n_par):
                s = 0.0
                for b in range(n_par):
                    s += p_mat[a, b] * phi[row, b]
                g[a] = s
            for a in range(n_par):
                denom += phi[row, a] * g[a]
                err -= phi[row, a] * theta[a]
            inv = 1.0 / denom
            for a in range(n_par):
                theta[a] += g[a] * inv * err
            for a in range(n_par):
                ga = g[a] * inv
                for b in range(a, n_par):
                    v = p_mat[a, b] - ga * g[b]
                    p_mat[a, b] = v
                    p_mat[b, a] = v
        for a in range(n_par):
            history[i, a] = theta[a]


@njit(cache=True)
def _gradient(phi, y, m, step, gamma, normalized, theta, history):  # pragma: no cover
    """θᵢ = θᵢ₋₁ + Δt Γ Σₖ φₖ (yₖ − φₖᵀθᵢ₋₁) over the ``m`` rows of sample i (Weiss eq 65),
    divided by 1 + Σₖ φₖᵀΓφₖ when ``normalized``."""
    n_par = phi.shape[1]
    grad = np.empty(n_par)
    for i in range(history.shape[0]):
        for a in range(n_par):
            grad[a] = 0.0
        norm = 1.0
        for k in range(m):
            row = i * m + k
            if not _row_finite(phi, y, row):
                continue
            err = y[row]
            for a in range(n_par):
                err -= phi[row, a] * theta[a]
            for a in range(n_par):
                grad[a] += phi[row, a] * err
            if normalized:
                for a in range(n_par):
                    s = 0.0
                    for b in range(n_par):
                        s += gamma[a, b] * phi[row, b]
                    norm += phi[row, a] * s
        for a in range(n_par):
            s = 0.0
            for b in range(n_par):
                s += gamma[a, b] * grad[b]
            theta[a] += step * s / norm
        for a in range(n_par):
            history[i, a] = theta[a]


def _initial(theta0, n_par: int) -> np.ndarray:
    if theta0 is None:
        return np.zeros(n_par)
    theta = np.array(theta0, dtype=np.float64).reshape(-1)
    if theta.size != n_par:
        raise NnidInputError(
            f"theta0 has {theta.size} values; the regression has {n_par} unknowns",
            field="theta0",
        )
    return theta


def _residual_stats(reg: Regression, theta: np.ndarray, first: int) -> tuple[float, int, dict]:
    """σ̂² = rᵀr/(n − P) over the rows of samples ``first``…end with the final θ, the row
    count and each DOF equation's residual variance (:func:`dof_variances`, as batch least
    squares reports it: centred, over n). Only the rows the recursion used count: a row with a
    non-finite target or regressor was skipped, and counted as a zero residual it shrank σ̂²
    and swelled n (half the rows undefined: σ̂² half). NaN where no residual degree of
    freedom is left, as in :func:`~nnid.trainers.least_squares.solve_least_squares`."""
    m = len(reg.dofs)
    rows = slice(first * m, reg.n_samples * m)
    r = reg.y[rows] - reg.phi[rows] @ np.nan_to_num(theta)
    used = np.isfinite(r)
    n = int(used.sum())
    dof = n - int(np.isfinite(theta).sum())
    sigma2 = float(r[used] @ r[used] / dof) if dof > 0 else math.nan
    per_dof = dict(zip(reg.dofs, dof_variances(r.reshape(-1, m)).tolist(), strict=True))
    return sigma2, n, per_dof


def _memory_excitation(
    reg: Regression, theta: np.ndarray, first: int
) -> tuple[ExcitationReport, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The excitation check of the rows of samples ``first``…end, each DOF equation weighted
    by 1/(its residual variance at ``theta``) so that forces and moments compare, its columns
    of rounding judged unweighted against the regression's floors (:meth:`Regression.floors`)
    or its own columns (:func:`rounding_scale`), as batch least squares judges them; also the
    used-row mask, the regressor and target with the unused rows zeroed, and the residual."""
    m = len(reg.dofs)
    rows = slice(first * m, reg.n_samples * m)
    phi, y = reg.phi[rows], reg.y[rows]
    r = y - phi @ np.nan_to_num(theta)
    ok = np.isfinite(r) & np.isfinite(phi).all(1)
    var = dof_variances(np.where(ok, r, np.nan).reshape(-1, m))
    # batch least squares' feasible weights (floored where σ̂² is rounding, spread within
    # 1/√eps): beside an equation of exact data, weighted 1e26 by its rounding, a noisy one
    # that alone separates a pair fell below the check's tolerance, and the pair read collinear
    floor = feasible_floor(var, np.where(ok, y, np.nan), m)
    w = np.tile(feasible_weights(var, floor), r.size // m) * ok
    # a parameter only the skipped rows read is not measured there, not a zero regressor
    left_out = read_only_where_left_out(phi, ok, list(reg.names))
    phi, y = np.where(ok[:, None], phi, 0.0), np.where(ok, y, 0.0)
    gram = (phi * w[:, None]).T @ phi
    # the same rows as the Gram: the memory is a window of them, not λᵏ-weighted, so the
    # unweighted RMS forgets as the Gram does. Weighted alone, an equation of rounding (X of a
    # heave-only log, σ̂² ~ 1e-34) made its column as large as any: X:u read -1.9e-26, a value
    raw, reference = rounding_scale(phi[ok])
    report = excitation_from_gram(
        gram,
        int(ok.sum()),
        list(reg.names),
        left_out=left_out,
        column_rms=raw,
        reference=reference,
        floors=reg.floors(),
        # each DOF equation's columns compared with each other, as batch least squares
        # compares them (the window's rows are sample-major from sample ``first``)
        by_equation=equation_rms(phi, m, ok) if m > 1 else None,
    )
    return report, ok, phi, y, r


def window_covariance(
    reg: Regression, theta: np.ndarray, first: int
) -> tuple[np.ndarray, np.ndarray, ExcitationReport]:
    """The covariance of ``theta`` over the samples ``first``…end (the estimator's memory):
    without forgetting the recursion's estimate is the *unweighted* least squares, so its
    covariance is the sandwich (ΦᵀΦ)⁻¹ Φᵀ Σ Φ (ΦᵀΦ)⁻¹ with Σ each DOF equation's own residual
    variance (forces in N and moments in N m do not share one), widened by the residuals'
    correlation time. With forgetting λ < 1 the estimate weighs the past by λᵏ, whose
    effective memory is about (1 + λ)/(1 − λ) samples, twice this window: these s.e. are then
    conservative by about √2 (a Monte Carlo gave 1.4-1.75 times the spread). σ̂² P of the
    recursion pools the equations' variances and takes every row as independent: too small
    for forces, too large for moments (3-24x on a minirov log); the covariance of the per-DOF
    *weighted* estimator, given before, is not this estimate's (over 16 Seamor logs, 0.5 of the
    spread of N_rdot; now 1.8). Also returns the window's unweighted least-squares fit, against
    which θ is judged settled, and the window's excitation report."""
    m = len(reg.dofs)
    rows = slice(first * m, reg.n_samples * m)
    report, ok, phi, y, r = _memory_excitation(reg, theta, first)
    r = np.where(ok, r, 0.0)
    # each equation's residual variance widened by its own correlation time
    times = equation_times([r[k::m] for k in range(m)])
    # with the targets: each equation's variance floored at its rounding, as batch least
    # squares floors it (on exact data a parameter of 1e-16 read significant)
    cov = dof_sandwich(
        reg.phi[rows],
        reg.y[rows] - reg.phi[rows] @ np.nan_to_num(theta),
        m,
        reg.y[rows],
        times=times,
    )
    # the window's own least-squares fit, unweighted as the recursion is
    fit = np.linalg.lstsq(phi, y, rcond=None)[0]
    return void_undetermined(cov, list(reg.names), report), fit, report


def _warn_memory_excitation(
    report: ExcitationReport, never: list[str], window: int, consequence: str
) -> None:
    """Say which parameters the memory's excitation check flagged and ``consequence``, what
    that costs them (RLS: no standard error; the gradient estimator, which gives none: values
    theta0's along what was not excited), and what became of the values of its unexcited
    ones: those earlier samples excited are said remembered by the report's own words
    (:meth:`ExcitationReport.with_remembered`). Only an unexcited parameter can have never
    left theta0: the note on it would misdescribe a warning about collinear ones."""
    if not report.warnings:
        return
    notes = []
    if never:
        one = len(never) == 1
        notes.append(
            f"the value of {', '.join(never)} is not given: no sample of the run excited "
            + ("it, and it" if one else "them, and they")
            + " never left theta0"
        )
    warnings.warn(
        f"over the estimator's memory (the last {window} samples): "
        + "; ".join(report.warnings)
        + f": {consequence}"
        + (f" ({'; '.join(notes)})" if notes else ""),
        ExcitationWarning,
        stacklevel=3,
    )


def _warn_skipped(reg: Regression) -> None:
    """The recursions skip a row whose target or regressor is not finite (:func:`_row_finite`):
    said in batch least squares' words where a parameter only such rows read (the same rows
    it leaves out), as a warning at the caller of the estimator's ``solve``."""
    finite = np.isfinite(reg.y) & np.isfinite(reg.phi).all(1)
    if not finite.all():
        warn_left_out(reg.phi, finite, list(reg.names), stacklevel=4)


def _chunks(n: int, parts: int = 20) -> list[tuple[int, int]]:
    """Sample ranges for progress reports: the compiled loops run range by range, carrying
    their state, so the result is the same as one pass."""
    edges = np.unique(np.linspace(0, n, parts + 1).astype(int))
    return list(itertools.pairwise(int(e) for e in edges))


#: the chance that a run whose parameters are constant is said still moving by
#: :func:`still_moving` with standard errors, over all its parameters together
STEADY_FALSE_ALARM = 0.01


def moving_threshold(count: int, alpha: float = STEADY_FALSE_ALARM) -> float:
    """The standard errors a change must exceed in :func:`still_moving`: the two-sided normal
    quantile at ``alpha`` shared among ``count`` parameters (Bonferroni), 3.29 for ten at 1 %.
    """
    return NormalDist().inv_cdf(1.0 - alpha / (2.0 * max(count, 1)))


def still_moving(
    history: np.ndarray,
    names: list[str],
    tail: float = 0.1,
    rel: float = 0.05,
    stderr: np.ndarray | None = None,
) -> list[str]:
    """The parameters whose estimate changed by more than ``rel`` of its final size over the
    last ``tail`` of the samples: a recursive law that has not converged by the data's end.
    With ``stderr``, a change within :func:`moving_threshold` standard errors (over the
    parameters that have one) is noise, not movement: a parameter whose truth is 0 ends near 0,
    and any change is a large part of it.

    Why not two: with forgetting whose memory is shorter than the tail, the two ends are
    estimates from different data, and their difference has a spread of about the window's
    s.e. (0.89 of it at λ = 0.99, 0.69 at 0.95: the window s.e. is conservative, √2 for a
    λ-weighted estimate). Two s.e. was a 5 % test per parameter, and 24 % of steady runs of ten
    parameters (λ = 0.99, 300 seeds) were said moving and lost their s.e.; at the Bonferroni
    threshold a steady run is said moving with chance at most ``STEADY_FALSE_ALARM`` (measured:
    0 of 300 at λ = 0.99 and 0.95). Without forgetting the ends share most of their data and
    the test is more conservative still."""
    n = history.shape[0]
    if n < 10:
        return []
    last, earlier = history[-1], history[int((1.0 - tail) * (n - 1))]
    change = np.abs(last - earlier)
    floor = np.abs(last) * rel
    if stderr is not None:
        z = moving_threshold(int(np.isfinite(stderr).sum()))
        floor = np.maximum(floor, z * np.nan_to_num(stderr, nan=0.0))
    return [nm for nm, d, f in zip(names, change, floor, strict=True) if d > max(f, 1e-12)]


class RecursiveLeastSquares(BaseEstimator):
    """Recursive least squares with exponential forgetting (Weiss eqs 52-53).

    Per sample: P ← P/λ, then for each DOF row φ of the sample K = Pφ/(1 + φᵀPφ),
    θ ← θ + K(y − φᵀθ), P ← P − Kφᵀ P. ``forgetting`` λ ∈ (0, 1] weights a sample k samples old
    by λᵏ: the memory is 1/(1 − λ) samples (λ = 1: ordinary RLS, converging to batch least
    squares). ``p0`` is the initial P = p₀ I (large: an uninformative start at ``theta0``,
    default zero). Forgetting is suspended while trace(P) ≥ n_par·p₀ (the trace of the initial
    P, n_par the number of parameters), so directions the data stops exciting do not wind
    up. ``filter_lambda`` (rad/s) uses the filtered regressors of Weiss eqs 85-92. The
    covariance is that of unweighted least squares at the final θ over the last window of
    ⌈1/(1 − λ)⌉ samples (the whole run for λ = 1, where it is the recursion's own estimator;
    conservative for λ < 1): :func:`window_covariance`; the recursion's own P is
    ``p_matrix_``. A parameter no sample excites is NaN, as in batch least squares (the
    recursion never moves it from ``theta0``), in ``history`` too; rows with a non-finite
    value are skipped and not counted in σ̂² or ``n_obs``, and a parameter only they read is
    said as batch least squares says it (:func:`warn_left_out`).

    At λ = 1 the estimate is ridge least squares with penalty I/p₀ toward ``theta0``, i.e.
    :class:`LeastSquares` with ``weighting="none"`` (every row weighted 1) as p₀ → ∞, not the
    default feasible weighting, which weights each DOF equation by 1/σ̂² of its residual: on
    several DOF equations the two differ, and RLS is the less precise (Gauss-Markov).
    """

    kind = "rls"

    def __init__(
        self,
        forgetting: float = 1.0,
        p0: float = 1e6,
        filter_lambda: float | None = None,
        theta0: np.ndarray | None = None,
    ) -> None:
        self.forgetting = forgetting
        self.p0 = p0
        self.filter_lambda = filter_lambda
        self.theta0 = theta0

    @property
    def memory(self) -> float:
        """Effective memory 1/(1 − λ) in samples (infinite for λ = 1)."""
        return math.inf if self.forgetting == 1.0 else 1.0 / (1.0 - self.forgetting)

    def fit(self, structure, data: dict, progress: Progress | None = None) -> Estimate:
        """Build the regression (filtered if ``filter_lambda``) and run RLS over it."""
        return self.solve(structure.regression(data, self.filter_lambda), progress)

    def solve(self, reg: Regression, progress: Progress | None = None) -> Estimate:
        if not 0.0 < self.forgetting <= 1.0:
            raise NnidInputError("forgetting must be in (0, 1]", field="forgetting")
        if self.p0 <= 0:
            raise NnidInputError("p0 must be positive", field="p0")
        report = progress or silent
        n_par = len(reg.names)
        m = len(reg.dofs)
        phi = np.ascontiguousarray(reg.phi, dtype=np.float64)
        y = np.ascontiguousarray(reg.y, dtype=np.float64)
        theta = _initial(self.theta0, n_par)
        p_mat = np.eye(n_par) * float(self.p0)
        history = np.empty((reg.n_samples, n_par))
        for a, b in _chunks(reg.n_samples):
            lam, trace_max = float(self.forgetting), n_par * float(self.p0)
            _rls(
                phi[a * m : b * m], y[a * m : b * m], m, lam, trace_max, theta, p_mat, history[a:b]
            )
            report(int(b), reg.n_samples, "recursive least squares")
        window = reg.n_samples if self.forgetting == 1.0 else math.ceil(self.memory)
        first = max(reg.n_samples - window, 0)
        _warn_skipped(reg)
        self.p_matrix_ = p_mat  # the recursion's own P, for its checks (not a covariance)
        cov, fit, report = window_covariance(reg, theta, first)
        # a parameter no sample of the run excited kept its start theta0: no estimate at all
        # (batch least squares gives NaN), where one unexcited only in the memory window is
        # remembered from earlier data and kept
        run = report if first == 0 else _memory_excitation(reg, theta, 0)[0]
        never = run.unexcited
        # said so wherever the verdict goes (the table, the Prime system, the warnings): "zero
        # regressor", read as "fitted to noise", is false of a value learnt from excited data;
        # but one collinear over the run was learnt only in a combination: said collinear
        report = report.with_remembered(
            [nm for nm in report.unexcited if nm not in never], collinear=run.collinear
        )
        _warn_memory_excitation(
            report, never, reg.n_samples - first, "their standard errors are not given"
        )
        # and not in its path either: theta0 held there is no estimate at any sample
        theta[np.isin(reg.names, never)] = np.nan
        history[:, np.isin(reg.names, never)] = np.nan
        sigma2, n_obs, per_dof = _residual_stats(reg, theta, first)
        # a window covariance around a θ the recursion has not settled on is no uncertainty:
        # still moving beyond its noise at the end, or ended far from its memory's fit
        se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        moving = still_moving(history, list(reg.names), stderr=se)
        z = moving_threshold(int(np.isfinite(se).sum()))
        unsettled = [
            nm
            for nm, d, e, v in zip(reg.names, np.abs(theta - fit), se, theta, strict=True)
            if nm in moving or (np.isfinite(e) and d > max(3.0 * e, 0.05 * abs(v)))
        ]
        if unsettled:
            converging = self.forgetting == 1.0
            warnings.warn(
                "recursive least squares "
                + ("has not converged" if converging else "is still moving (tracking a change?)")
                + f": {', '.join(unsettled)} still moved beyond 5 % and {z:.3g} standard errors "
                "over the last tenth of the data (a bound a run of constant parameters crosses "
                f"with chance under {STEADY_FALSE_ALARM:.0%} over all of them), or ended beyond "
                "5 % and three standard errors from the least-squares fit of its memory; these "
                "values are where the data ended, not estimates ("
                + ("a larger p0, or a longer log" if converging else "a longer memory")
                + "), and they get no standard error",
                UserWarning,
                stacklevel=2,
            )
        tied = np.isin(reg.names, unsettled)
        cov[tied, :] = np.nan
        cov[:, tied] = np.nan
        return Estimate(
            list(reg.names),
            theta,
            cov,
            sigma2,
            n_obs,
            # the memory's verdicts, which void the s.e. above: kept, as batch least squares
            # keeps its own, so that the reports say why (none was: "zero regressor" was said
            # once, in a warning, and the tables read a value of rounding as unidentified noise)
            excitation=report,
            dof_sigma2=per_dof,
            history=history,
        )


#: what a row of a gain matrix given from Python may be
_ROW = list | tuple | np.ndarray


def _rows(gain: object) -> bool:
    """Whether ``gain`` is given as a matrix: a 2-D array, or a list of rows (which may be
    ragged, or mixed with numbers: numpy's own error named neither)."""
    if isinstance(gain, np.ndarray):
        return gain.ndim == 2
    return isinstance(gain, list | tuple) and any(isinstance(row, _ROW) for row in gain)


def gain_matrix_problem(gain: Sequence[Sequence[float]] | np.ndarray) -> str | None:
    """What makes ``gain`` (its rows) no gain matrix Γ of the gradient law, or None: Γ is
    square, symmetric and positive definite, as the law descends the squared error only
    then (a negative definite one climbs it). The check of a config's ``gain`` too."""
    n = len(gain)
    if any(not isinstance(row, _ROW) or len(row) != n for row in gain):
        return f"a gain matrix is square: {n} rows, so {n} numbers in each"
    g = np.array(gain, dtype=np.float64)
    if not np.allclose(g, g.T, rtol=1e-9, atol=0.0):
        return "a gain matrix is symmetric (gain[i][j] = gain[j][i])"
    if n == 0 or np.linalg.eigvalsh(g).min() <= 0:
        return "a gain matrix is positive definite (all its eigenvalues above 0)"
    return None


def gain_problem(
    gain: float | Sequence[float] | Sequence[Sequence[float]] | np.ndarray,
) -> str | None:
    """What makes ``gain`` no gain Γ of the gradient law (Weiss eqs 62-65), or None: a matrix
    as :func:`gain_matrix_problem` says; a scalar p₀, or each number of a vector (diagonal Γ),
    finite and above 0, as the law descends the squared error only then (a negative gain
    climbs it, 0 never moves θ). The check of a config's ``gain`` and of one from Python."""
    if _rows(gain):
        return gain_matrix_problem(gain)  # type: ignore[arg-type]
    g = np.asarray(gain, dtype=np.float64)
    flat = g.reshape(-1)
    bad = flat[~(np.isfinite(flat) & (flat > 0))]
    if not bad.size:
        return None  # its shape is the estimator's to check: it knows the parameters
    if g.ndim == 0:  # the value itself is shown beside the message (a config's "got")
        return "a gain is a finite number above 0"
    return (
        "each number of a gain vector (Γ's diagonal) is a finite number above 0, "
        f"not {shown(bad[0])}"
    )


class GradientEstimator(BaseEstimator):
    """The gradient estimator of Weiss eqs 62-65: θ̇ = −p₀ ∂(eᵀe)/∂θ ∝ Γ φ (y − φᵀθ).

    ``gain`` is Γ: a scalar p₀ or a vector (diagonal Γ) above 0, or a symmetric positive
    definite matrix (:func:`gain_problem`). The law is discretised by forward Euler over the sample
    interval Δt (from the log's ``t`` in :meth:`fit`, else ``dt``, else 1: a gain per sample);
    it is stable while Δt Γ ΦᵢᵀΦᵢ stays below 2. With
    ``normalized`` the step is divided by 1 + Σ φᵀΓφ (normalised gradient), which bounds it.
    There is no covariance: ``cov`` is NaN and σ̂² comes from the final θ over the whole run.
    The whole run is its memory: the excitation check RLS makes over its memory
    (:func:`_memory_excitation`) is made over the run, kept as ``excitation`` and warned
    (:class:`ExcitationWarning`); a parameter no sample excites never left ``theta0`` and is
    NaN (value and ``history``), as in RLS and batch least squares. Rows with a non-finite
    value are skipped, and a parameter only they read is said (:func:`warn_left_out`).
    """

    kind = "gradient"

    def __init__(
        self,
        gain: float | np.ndarray = 1.0,
        normalized: bool = False,
        filter_lambda: float | None = None,
        theta0: np.ndarray | None = None,
        dt: float | None = None,
    ) -> None:
        self.gain = gain
        self.normalized = normalized
        self.filter_lambda = filter_lambda
        self.theta0 = theta0
        self.dt = dt

    def _gamma(self, n_par: int) -> np.ndarray:
        # checked as a config's gain is: a ragged matrix had failed in numpy's own words, and
        # a gain of 0 or below ran (θ stood still, or climbed the squared error)
        if problem := gain_problem(self.gain):
            scalar = not _rows(self.gain) and np.ndim(self.gain) == 0  # as a config says it
            got = f" (got {shown(self.gain)})" if scalar else ""
            raise NnidInputError(problem + got, field="gain")
        g = np.asarray(self.gain, dtype=np.float64)
        if g.ndim == 0:
            return np.eye(n_par) * float(g)
        if g.ndim == 1 and g.size == n_par:
            return np.diag(g)
        if g.shape == (n_par, n_par):
            return np.ascontiguousarray(g)
        raise NnidInputError(
            f"gain must be a scalar, [{n_par}] or [{n_par}, {n_par}]", field="gain"
        )

    def fit(self, structure, data: dict, progress: Progress | None = None) -> Estimate:
        """Build the regression and run the gradient law with Δt from the log's time stamps."""
        t = np.asarray(data["t"], dtype=np.float64)
        # the step of its runs, the joins between them left out; None (one gain per sample,
        # :meth:`solve`) where no run has two samples
        step = log_step(t, data.get("experiment"))
        dt = self.dt or (None if np.isnan(step) else step)
        return self.solve(structure.regression(data, self.filter_lambda), dt, progress)

    def solve(
        self, reg: Regression, dt: float | None = None, progress: Progress | None = None
    ) -> Estimate:
        report = progress or silent
        n_par = len(reg.names)
        m = len(reg.dofs)
        step = float(dt or self.dt or 1.0)
        theta = _initial(self.theta0, n_par)
        history = np.empty((reg.n_samples, n_par))
        phi = np.ascontiguousarray(reg.phi, dtype=np.float64)
        y = np.ascontiguousarray(reg.y, dtype=np.float64)
        gamma = self._gamma(n_par)
        for a, b in _chunks(reg.n_samples):
            _gradient(
                phi[a * m : b * m],
                y[a * m : b * m],
                m,
                step,
                gamma,
                bool(self.normalized),
                theta,
                history[a:b],
            )
            report(int(b), reg.n_samples, "gradient estimator")
        _warn_skipped(reg)
        diverged = not np.isfinite(theta).all()
        # persistence of excitation over the run, RLS's memory check with the run as memory:
        # an unexcited parameter kept theta0 and was reported as a value, unsaid. Judged at
        # θ = 0 where the law diverged (the check's equation weights need finite residuals)
        judged = np.zeros(n_par) if diverged else theta
        excitation = _memory_excitation(reg, judged, 0)[0]
        never = excitation.unexcited
        # it gives no standard errors: what the check costs its values is said instead
        _warn_memory_excitation(
            excitation,
            never,
            reg.n_samples,
            "along what the run did not excite, their values are theta0's, not the data's",
        )
        theta[np.isin(reg.names, never)] = np.nan
        history[:, np.isin(reg.names, never)] = np.nan
        if diverged:
            warnings.warn(
                "the gradient estimator diverged: lower the gain or use normalized=True",
                RuntimeWarning,
                stacklevel=2,
            )
        moving = still_moving(history, list(reg.names))
        if moving:
            warnings.warn(
                "the gradient estimator has not converged: "
                + ", ".join(moving)
                + " still moved by more than 5 % over the last tenth of the data; these values "
                "are where the data ended, not estimates (a larger gain, normalized=True, or "
                "a longer log)",
                UserWarning,
                stacklevel=2,
            )
        # said, not left to a column of None: every other estimator gives an uncertainty
        warnings.warn(
            "the gradient estimator gives no standard errors (its law has no covariance): "
            "its parameters are reported without uncertainty and none is judged significant; "
            "fit with ls or rls for standard errors",
            UserWarning,
            stacklevel=2,
        )
        sigma2, n_obs, per_dof = _residual_stats(reg, theta, 0)
        return Estimate(
            list(reg.names),
            theta,
            np.full((n_par, n_par), np.nan),
            sigma2,
            n_obs,
            excitation=excitation,
            dof_sigma2=per_dof,
            history=history,
        )
