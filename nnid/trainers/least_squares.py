"""Batch least squares with uncertainty (Caccia eqs 11-12; Weiss eqs 47-53).

θ̂ = (ΦᵀWΦ)⁻¹ΦᵀWy, cov(θ̂) = σ̂² (ΦᵀWΦ)⁻¹ with σ̂² = rᵀWr / (n − p) (Caccia eq. 12), standard
deviations, and Caccia's percentile error 100 σ̂/|θ̂|: above 51.02 % (= 100/1.96) a parameter is
insignificant at 95 % (a two-sided z-test of θ = 0). Weighted least squares takes row weights;
``feasible`` weights each DOF's equation by the inverse of its residual variance from a first
ordinary fit, so forces (N) and moments (N m) are combined on equal statistical footing;
``none`` over several DOF equations keeps the ordinary estimate and takes its covariance from
each equation's own residual variance (a sandwich, :func:`dof_sandwich`). Rank-deficient or
unexcited regressions warn and name the parameters (Weiss eqs 95-98).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from sklearn.base import BaseEstimator

from nnid.errors import ExcitationWarning as ExcitationWarning  # raised here, long imported here
from nnid.errors import NnidInputError
from nnid.evaluation.persistence import (
    ExcitationReport,
    changed_verdicts,
    equation_rms,
    excitation_from_gram,
    typical_size,
)
from nnid.serialization import json_float
from nnid.trainers.history import Progress, silent
from nnid.trainers.regression import Regression

INSIGNIFICANT_PERCENT = 100.0 / 1.96  # 51.02 %, Caccia (L279)
EPS = float(np.finfo(np.float64).eps)
#: a residual variance below this share of its target's mean square is rounding, not noise
#: (:func:`rounding_floor`): the three-term RSS of exact data is a few ulps of yᵀy
ROUNDING_SHARE = 4 * EPS


def significant(percentile_error: float | np.ndarray) -> bool | np.ndarray:
    """Caccia's rule (L279): a parameter whose percentile error 100 σ̂/|θ̂| is at most 51.02 %
    (= 100/1.96) is significant at 95 % (a two-sided z-test of θ = 0); NaN is not."""
    return np.asarray(percentile_error) <= INSIGNIFICANT_PERCENT


@dataclass
class Estimate:
    names: list[str]
    theta: np.ndarray
    cov: np.ndarray
    sigma2: float
    n_obs: int
    excitation: ExcitationReport | None = None
    dof_sigma2: dict[str, float] = field(default_factory=dict)
    history: np.ndarray | None = None  # θ after each sample [n_samples, P] (recursive trainers)

    @property
    def stderr(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.cov), 0.0, None))

    @property
    def percentile_error(self) -> np.ndarray:
        """100 σ̂_θ / |θ̂| (Caccia L135)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return 100.0 * self.stderr / np.abs(self.theta)

    @property
    def significant(self) -> np.ndarray:
        return significant(self.percentile_error)

    def as_state(self) -> dict:
        """The estimate's scalars as JSON-ready data (NaN becomes null on writing; see
        :meth:`from_state`). Not ``history``: a series per sample is no scalar, and its model
        saves it with its tensors (``tensors.pt``), given back to :meth:`from_state`."""
        return {
            "names": list(self.names),
            "theta": self.theta,
            "cov": self.cov,
            "sigma2": self.sigma2,
            "n_obs": self.n_obs,
            "dof_sigma2": self.dof_sigma2,
            # what the fit found unexcited or collinear: the reports name them from it
            "excitation": None if self.excitation is None else self.excitation.as_state(),
        }

    @classmethod
    def from_state(cls, state: dict, history: np.ndarray | None = None) -> Estimate:
        """Inverse of :meth:`as_state` after a JSON round trip (null is NaN again), with the
        θ per sample ``history`` saved apart (checked: [samples, P]). Files saved before the
        excitation report was kept have none: None."""
        names = list(state["names"])
        excitation = state.get("excitation")
        if history is not None:
            history = np.asarray(history, dtype=np.float64)
            if history.ndim != 2 or history.shape[1] != len(names):
                raise ValueError(f"the estimate's history is not [samples, {len(names)}]")
        return cls(
            names,
            np.array(state["theta"], dtype=float),
            np.array(state["cov"], dtype=float).reshape(len(names), len(names)),
            json_float(state["sigma2"]),
            int(state["n_obs"]),
            None if excitation is None else ExcitationReport.from_state(excitation),
            dof_sigma2={k: json_float(v) for k, v in state["dof_sigma2"].items()},
            history=history,
        )

    def as_dict(self) -> dict[str, dict[str, float | bool | None]]:
        """``{name: {"value": θ, "stderr": σ, "percentile_error": 100 σ/|θ| (%),
        "significant": bool}}``; a number that is not finite (an unidentified parameter) is
        None. A parameter the excitation check (Weiss eqs 93-98) found unexcited also has
        ``"excited": False`` (and ``"measured": False`` where only rows left out read it:
        :attr:`ExcitationReport.not_measured`; ``"remembered": True`` where a recursive
        estimator learnt its value before its memory: :attr:`ExcitationReport.remembered`), one
        it found collinear ``"collinear": True``: its "not significant" is no test result, and
        the reports say why."""
        out: dict[str, dict[str, float | bool | None]] = {
            n: {
                "value": _finite(v),
                "stderr": _finite(s),
                "percentile_error": _finite(pe),
                "significant": bool(ok),
            }
            for n, v, s, pe, ok in zip(
                self.names,
                self.theta,
                self.stderr,
                self.percentile_error,
                self.significant,
                strict=True,
            )
        }
        report = self.excitation
        for name in [] if report is None else report.unexcited:
            if name in out:  # a combined estimate (Caccia's) may carry a part's report
                out[name]["excited"] = False
        for name in [] if report is None else report.not_measured:
            if name in out:  # only rows left out read it: no data on it, not unexcited data
                out[name]["measured"] = False
        for name in [] if report is None else report.remembered:
            if name in out:  # unexcited in the memory only: its value is learnt from data
                out[name]["remembered"] = True
        for name in [] if report is None else report.collinear:
            if name in out:
                out[name]["collinear"] = True
        return out


def _finite(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None


def read_only_where_left_out(phi: np.ndarray, kept: np.ndarray, names: Sequence[str]) -> list[str]:
    """The parameters ``names`` whose regressor column of ``phi`` reads them (finite and
    non-zero) only in the rows not ``kept``: left out as not finite, they are not measured,
    rather than unexcited (a zero regressor, Weiss eq. 95). A NaN entry is no evidence that a
    row reads it: a filter's settling rows are NaN in every column (:func:`synthesis_data`),
    and a term zero on every other row read "not measured" there. A column with no finite
    entry at all is not measured either: nothing shows it zero.

    The price: a column NaN in exactly the rows that would read it and 0 on every other row is
    "zero regressor" here, not "not measured" (the case at :func:`solve_least_squares`'s
    left-out rows). Its cause there, a NaN known multiplying a whole equation, is refused
    before any regression since 9accf6c (a sequence raises where a step's equations do not
    contain a parameter, ``step_contains``); what is left needs the data's own NaN (a masked
    gap) to cover every row where the signal is non-zero, and then the kept rows, measured at
    0, do show the term unexcited."""
    read = np.isfinite(phi) & (phi != 0)
    unknown = ~np.isfinite(phi).any(0)
    return [
        nm
        for j, nm in enumerate(names)
        if (read[~kept, j].any() or unknown[j]) and not read[kept, j].any()
    ]


def warn_left_out(
    phi: np.ndarray, finite: np.ndarray, names: Sequence[str], stacklevel: int = 3
) -> list[str]:
    """The parameters only the rows not ``finite`` read (:func:`read_only_where_left_out`),
    said in an :class:`ExcitationWarning` with the count of rows left out where there are
    any: one wording for batch least squares and the recursive estimators, which skip the
    same rows. Masked gaps and accelerations cut at held steps are such rows, said where they
    are made; what is said here is a parameter only the left-out rows read: a NaN known of a
    sequence step once dropped a whole equation, and its unknowns read "zero regressor".
    ``stacklevel``: as :func:`warnings.warn`'s, counted from the caller of this function."""
    left_out = read_only_where_left_out(phi, finite, list(names))
    if left_out:
        warnings.warn(
            f"{int((~finite).sum())} of {finite.size} rows of the regression are left out: "
            "their target or regressor is not finite (a dropout, an undefined signal or "
            f"value); only they read {', '.join(left_out)}",
            ExcitationWarning,
            stacklevel=stacklevel,
        )
    return left_out


def rounding_scale(fitted: np.ndarray, reference: float = 0.0) -> tuple[np.ndarray, float]:
    """What the rounding rule (:data:`~nnid.evaluation.persistence.ROUNDING`) of
    :func:`excitation_from_gram` compares: each column's RMS over the ``fitted`` rows
    ``[N, P]`` (finite, those the fit reads), unweighted, and the reference it is compared
    with where a column has no floor of its own
    (:meth:`~nnid.trainers.regression.Regression.floors`), ``reference`` (the typical size of
    the regression this one is a block of) or the rows' own
    :func:`~nnid.evaluation.persistence.typical_size` where larger. Unweighted because a fit
    that weights each equation by 1/σ̂² (feasible weighting, the recursive fit's memory check)
    scales an equation of rounding up by ~1e34, and its column then looked as large as any."""
    raw = np.sqrt(np.einsum("ij,ij->j", fitted, fitted) / max(fitted.shape[0], 1))
    return raw, max(reference, typical_size(fitted))


def solve_least_squares(
    phi: np.ndarray,
    y: np.ndarray,
    weights: np.ndarray | None = None,
    names: list[str] | None = None,
    check: bool = True,
    reference: float = 0.0,
    floors: np.ndarray | None = None,
    equations: int = 1,
    variance_floor: np.ndarray | None = None,
    stacked: int = 1,
) -> Estimate:
    """Weighted least squares with covariance, through the normal equations of the
    column-scaled regressor (fast on long logs; the excitation check guards conditioning).
    Unexcited parameters get NaN and a warning that names them; collinear ones (the data do
    not separate them: the excitation check's near-null directions) keep the pseudo-inverse's
    value, a warning, and no standard error (NaN), since only their combination is measured.
    ``reference``: the typical regressor size of the whole regression ``phi`` is a block of
    (:func:`~nnid.evaluation.persistence.typical_size`), against which a column of rounding is
    zero (:func:`excitation_from_gram`); ``phi``'s own, where larger. ``floors``: each
    column's own floor of that rule, where not NaN
    (:func:`~nnid.evaluation.persistence.rounding_floors`). ``stacked``: the DOF equations
    ``phi``'s rows stack (row i is equation i mod ``stacked``: :class:`Regression`'s
    layout), within each of which the check compares a column with the others
    (:func:`excitation_from_gram`'s ``by_equation``); 1: with all of ``phi``'s columns.

    σ̂² = rᵀWr/(n − p) (Caccia eq. 12), n the rows of weight > 0 (``n_obs``: a weight 0
    switches a row off), rᵀWr at least 4·eps of yᵀWy (the rounding of exact data). Of several
    ``equations`` weighted apart (row i is equation i mod ``equations``: feasible weighting's
    second pass) each equation's share is floored on its own
    (:func:`_equations_rss`): at ``variance_floor`` (a variance per equation, weighted as its
    rows are) where given, else at its :func:`rounding_floor`."""
    names = names or [f"theta{k}" for k in range(phi.shape[1])]
    for m in (equations, stacked):
        if phi.shape[0] % m:
            raise ValueError(f"{phi.shape[0]} rows are no whole number of {m} equations")
    equation = np.arange(phi.shape[0]) % equations
    if equations > 1 and variance_floor is None:
        variance_floor = rounding_floor(np.asarray(y, dtype=np.float64), equations)
    finite = np.isfinite(y) & np.isfinite(phi).all(1)
    # each DOF equation's column sizes, of the rows fitted (finite, weight > 0), read from the
    # sample-major layout before the rows are cut from it
    by_equation = (
        equation_rms(
            phi, stacked, finite if weights is None else finite & (np.asarray(weights) > 0)
        )
        if check and stacked > 1
        else None
    )
    left_out: list[str] = []
    if not finite.all():  # rows with an undefined signal (e.g. w of a tumbling vehicle)
        left_out = warn_left_out(phi, finite, names)
        phi, y, equation = phi[finite], y[finite], equation[finite]
        weights = None if weights is None else np.asarray(weights)[finite]
    n, p = phi.shape
    if weights is None:
        gram, rhs, yy = phi.T @ phi, phi.T @ y, float(y @ y)
    else:
        w = np.asarray(weights, dtype=np.float64)
        pw = phi * w[:, None]
        gram, rhs, yy = pw.T @ phi, pw.T @ y, float((y * w) @ y)
    # over the rows of weight > 0: a weight 0 switches an equation off (a DOF the log does not
    # measure), and a column is not to be called excited by equations that are not fitted, nor
    # are they observations: counted in n − p (the loop's --dofs p,q,r weights three of six
    # equations 0), σ̂² was half and every s.e. √2 too small
    rows = np.ones(n, dtype=bool) if weights is None else np.asarray(weights) > 0
    fitted = int(rows.sum())
    raw, reference = rounding_scale(phi[rows], reference)
    report = (
        excitation_from_gram(
            gram,
            fitted,
            names,
            left_out=left_out,
            column_rms=raw,
            reference=reference,
            floors=floors,
            by_equation=by_equation,
        )
        if check
        else None
    )
    live = np.ones(p, dtype=bool)
    if report is not None and report.warnings:
        warnings.warn("; ".join(report.warnings), ExcitationWarning, stacklevel=2)
        live = np.array([nm not in report.unexcited for nm in names])
    g = gram[np.ix_(live, live)]
    inv = scaled_pinv(g)
    theta = np.full(p, np.nan)
    theta[live] = inv @ rhs[live]
    # rᵀWr = yᵀWy − 2θᵀΦᵀWy + θᵀΦᵀWΦθ, three terms of size yᵀWy: below a few ulps of it the
    # difference is rounding, so one equation's RSS is floored there (on exact data σ̂ = 0
    # made a parameter of 1e-15 "significant")
    rss = yy - 2 * theta[live] @ rhs[live] + theta[live] @ g @ theta[live]
    if equations == 1:
        rss = max(rss, ROUNDING_SHARE * yy)
    else:  # each equation's share, floored on its own (feasible weighting's second pass)
        below = np.asarray(variance_floor, dtype=np.float64)[equation]
        wts = np.ones(n) if weights is None else w
        rss = _equations_rss(rss, yy, y - phi[:, live] @ theta[live], wts, below, equation)
    dof = fitted - int(live.sum())
    if dof > 0:
        sigma2 = float(rss / dof)
    else:  # as many rows as parameters: the fit passes through them, σ̂ is not measured
        sigma2 = np.nan
        warnings.warn(
            f"{fitted} rows for {int(live.sum())} parameters: no residual degrees of freedom, so "
            "the fit passes through every row and its standard errors are not measured; give "
            "more rows than parameters (more plateaus, a longer log)",
            ExcitationWarning,
            stacklevel=2,
        )
    cov = np.full((p, p), np.nan)
    cov[np.ix_(live, live)] = sigma2 * inv
    return Estimate(names, theta, void_undetermined(cov, names, report), sigma2, fitted, report)


def scaled_pinv(gram: np.ndarray) -> np.ndarray:
    """The pseudo-inverse of a Gram matrix ΦᵀWΦ through its column-scaled form (columns of
    N and of N m, or of 1e-3 and 1e3, no longer set its conditioning)."""
    scale = np.sqrt(np.diag(gram))
    scale[scale == 0] = 1.0
    return np.linalg.pinv(gram / np.outer(scale, scale), hermitian=True) / np.outer(scale, scale)


def solve_regression(
    reg: Regression,
    weights: np.ndarray | None = None,
    reference: float = 0.0,
    equations: int = 1,
    variance_floor: np.ndarray | None = None,
) -> Estimate:
    """:func:`solve_least_squares` of ``reg`` under nnid's one rule of what a stacked
    regression excites: each column compared with the others within each DOF equation ``reg``
    stacks (a column small in N beside N m columns of another equation is not unexcited for
    it), and rounding below its own floor (:meth:`Regression.floors`). ``weights``,
    ``reference``, ``equations`` and ``variance_floor`` as :func:`solve_least_squares` takes
    them; the least-squares trainer and the residual loop's fits solve through it."""
    return solve_least_squares(
        reg.phi,
        reg.y,
        weights,
        reg.names,
        reference=reference,
        floors=reg.floors(),
        equations=equations,
        variance_floor=variance_floor,
        stacked=len(reg.dofs),
    )


def _equations_rss(
    rss: float, yy: float, r: np.ndarray, w: np.ndarray, below: np.ndarray, equation: np.ndarray
) -> float:
    """rᵀWr of several equations weighted apart, each equation's share (rows ``equation``,
    residual ``r``, weights ``w``) at least its rows' variance floor ``below``, weighted as
    they are: one equation's floor, or the rounding of its weighted targets, no longer swamps
    another's residual. ``rss``: the three-term rᵀWr, kept where it resolves the sum (above
    √eps of yᵀWy, whose few ulps are its rounding), so that a noisy fit's σ̂² is the one it
    was; below that, the residual's own shares. The three terms have the scale of the
    heaviest equation: beside one of exact data weighted 1e25 (yᵀWy 1e34), a noisy
    equation's s.e. came out 1e7, not 0.03."""
    share = np.bincount(equation, weights=w * r * r)
    floor = np.bincount(equation, weights=w * below, minlength=share.size)
    if rss > np.sqrt(EPS) * yy:
        return float(rss + np.fmax(floor - share, 0.0).sum())
    return float(np.fmax(share, floor).sum())


def void_undetermined(
    cov: np.ndarray, names: list[str], report: ExcitationReport | None
) -> np.ndarray:
    """``cov`` with NaN in the rows and columns of the parameters ``report`` names unexcited
    or collinear: a parameter of a collinear group is not determined on its own, and the
    pseudo-inverse's covariance, which leaves out the undetermined direction, would give it a
    precise-looking standard error."""
    if report is None:
        return cov
    bad = set(report.unexcited) | set(report.collinear)
    tied = np.array([nm in bad for nm in names], dtype=bool)
    cov = cov.copy()
    cov[tied, :] = np.nan
    cov[:, tied] = np.nan
    return cov


class LeastSquares(BaseEstimator):
    """Batch (weighted) least squares on a :class:`Regression`.

    ``weighting="feasible"`` (default) reweights each DOF equation by 1/σ̂²_dof from a first
    ordinary fit; ``"none"`` is ordinary least squares. ``filter_lambda`` (rad/s) uses the
    filtered-regressor form (Weiss eqs 86-92) instead of differentiated accelerations.
    ``correlated`` (default) widens the covariance by the residuals' integrated
    autocorrelation time, each DOF equation's variance by its own (:func:`equation_times`):
    filtered and smoothed logs have far fewer independent samples than rows, and the textbook
    formula would report uncertainties that are too small.
    """

    kind = "ls"

    def __init__(
        self,
        weighting: str = "feasible",
        filter_lambda: float | None = None,
        correlated: bool = True,
    ) -> None:
        self.weighting = weighting
        self.filter_lambda = filter_lambda
        self.correlated = correlated

    def fit(self, structure, data: dict, progress: Progress | None = None) -> Estimate:
        """Build the regression (filtered if ``filter_lambda``) and solve it."""
        est = self.solve(structure.regression(data, self.filter_lambda))
        (progress or silent)(1, 1, "least squares")
        return est

    def solve(self, reg: Regression, reference: float = 0.0) -> Estimate:
        """Solve ``reg``; ``reference``: the typical regressor size of the regression it is a
        block of (:func:`solve_least_squares`), or ``reg``'s own where larger; a column with a
        floor of its own (:meth:`Regression.floors`) is judged by that instead."""
        if self.weighting not in ("feasible", "none"):
            raise NnidInputError("weighting is 'feasible' or 'none'", field="weighting")
        m = len(reg.dofs)
        est = solve_regression(reg, reference=reference)
        dof_sigma2 = self._dof_variances(reg, est.theta)
        if self.weighting == "feasible" and m > 1:
            var = np.array([dof_sigma2[d] for d in reg.dofs])
            ok = np.isfinite(reg.y) & np.isfinite(reg.phi).all(1)
            floor = feasible_floor(var, np.where(ok, reg.y, np.nan), m)
            # rows are sample-major (Regression.dof_rows): equation k is every m-th row from k
            w = np.tile(feasible_weights(var, floor), reg.n_samples)
            first = est.excitation
            # its left-out rows and residual degrees of freedom are the first pass's (the
            # weights change neither which rows are finite nor which columns are zero): said
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", ExcitationWarning)
                est = solve_regression(
                    reg, w, reference=reference, equations=m, variance_floor=floor
                )
            # but its verdict may differ: 1/σ̂² beside an equation of exact data (~1e18) left
            # a pair separable only in the other equation collinear, and dropped it unsaid
            changed = (
                changed_verdicts(first, est.excitation)
                if first is not None and est.excitation is not None
                else []
            )
            if changed:
                warnings.warn(
                    "the weighted pass (each DOF equation weighted by 1/σ̂² of the ordinary "
                    "fit's residual, whose estimate is the one given) differs from the ordinary "
                    "fit's excitation check: " + "; ".join(changed),
                    ExcitationWarning,
                    stacklevel=2,
                )
            dof_sigma2 = self._dof_variances(reg, est.theta)
        est.dof_sigma2 = dof_sigma2
        times = equation_times(reg.residuals(est.theta)) if self.correlated else np.ones(m)
        if self.weighting == "none" and len(reg.dofs) > 1 and np.isfinite(est.sigma2):
            # ordinary least squares of several DOF equations: σ̂² (ΦᵀΦ)⁻¹ pools forces (N) and
            # moments (N m) into one variance, which on a surge-yaw log made the yaw
            # parameters' s.e. 20x their spread; each equation's own variance instead (none
            # where no residual degree of freedom is left: the fit passes through every row)
            live = np.isfinite(est.theta)
            cov = np.full_like(est.cov, np.nan)
            cov[np.ix_(live, live)] = dof_sandwich(
                reg.phi[:, live],
                reg.y - reg.phi[:, live] @ est.theta[live],
                len(reg.dofs),
                reg.y,
                times,
            )
            est.cov = void_undetermined(cov, reg.names, est.excitation)
        elif self.weighting == "feasible" and m > 1:
            est.cov = widen_by_equation(
                est.cov, reg.phi, np.where(ok, w, 0.0), m, times, est.theta, est.sigma2
            )
        else:  # one equation, or a pooled σ̂² of several with no variance of their own
            est.cov = est.cov * float(np.mean(times))
        return est

    @staticmethod
    def _dof_variances(reg: Regression, theta: np.ndarray) -> dict[str, float]:
        return dict(zip(reg.dofs, dof_variances(reg.residuals(theta)).tolist(), strict=True))


def dof_variances(residuals: Sequence[np.ndarray] | np.ndarray, centred: bool = True) -> np.ndarray:
    """The variance of each DOF equation's residual (finite samples; the columns of a 2-D
    array, or one series per equation). Centred (default) for the first pass of the feasible
    weighting, whose second pass weights each equation by 1/σ̂² so that forces (N) and moments
    (N m) count on equal statistical footing: a missing effect that biases one equation's
    residual is not taken for noise there. ``centred=False``: the mean square rᵀr/n, Caccia
    eq. 12's σ̂² (before its n/(n − p)), for a covariance: a constant force the model lacks is
    error in θ̂ as much as noise is, and the centred variance made the s.e. too small by
    √(1 + c²/σₑ²). NaN for an equation without a finite sample."""
    series = residuals.T if isinstance(residuals, np.ndarray) and residuals.ndim == 2 else residuals
    # finite, not merely not NaN: nanvar read a ±inf (an inf regressor's row) as a sample, and
    # the equation's NaN variance then took feasible weighting's heaviest weight
    finite = [r[np.isfinite(r)] for r in (np.asarray(s, dtype=np.float64) for s in series)]
    spread = np.var if centred else (lambda r: np.mean(r * r))
    return np.asarray([float(spread(r)) if r.size else np.nan for r in finite])


def rounding_floor(y: np.ndarray, m: int = 1) -> np.ndarray:
    """The variance below which each of ``m`` interleaved equations' (row i is equation
    i mod m) residual is rounding, not noise: 4·eps of the mean square of its finite targets
    ``y`` (0 where it has none). The floor :func:`solve_least_squares` puts on its RSS and
    :func:`dof_sandwich` on each equation's variance (Caccia eq. 12 on exact data)."""
    known = np.isfinite(y).reshape(-1, m)
    square = np.where(known, y.reshape(-1, m), 0.0) ** 2
    return ROUNDING_SHARE * square.sum(0) / np.maximum(known.sum(0), 1)


def feasible_floor(var: np.ndarray, y: np.ndarray, m: int) -> np.ndarray:
    """The variance below which feasible weighting does not take an equation's σ̂² ``var``
    [m] at its word, each of the ``m`` interleaved equations' (``y``: their targets, NaN
    where a row is not fitted): its :func:`rounding_floor` (a residual below it is rounding,
    and 1/rounding gave an equation of exact data a weight of 1e25, made of noise), and √eps
    of the largest σ̂², so that the weights' spread stays within 1/√eps (6.7e7). An equation
    whose residual is exactly 0 (its target 0 too) got 1/1e-300, and the Gram overflowed.
    Beyond 1/√eps a lighter equation keeps less than half its digits in a Gram entry it
    shares with the heaviest, and the normal equations, whose forward error is about eps
    times the spread, fitted neither: beside an equation of noise 1e-7 (spread 1e14), a pair
    only the other equation separates came back with a + b 0.4 % off where the first says it
    to 1e-8, and σ̂² 7e9 for every parameter. The price: a precise equation more than 1/√eps
    above the others is weighted 1/√eps, and its parameters' s.e. are the larger, safe side
    (the RSS counts it at its floor, :func:`solve_least_squares`)."""
    largest = float(np.nanmax(var)) if np.isfinite(var).any() else 0.0
    return np.fmax(rounding_floor(y, m), np.sqrt(EPS) * largest)


def feasible_weights(var: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """Feasible weighting's weight of each DOF equation, 1/σ̂² (its residual variance
    ``var`` from the ordinary fit, :func:`dof_variances`, at least ``floor``:
    :func:`feasible_floor`); 1 where both are 0 or unknown (every equation exact and of zero
    target: any weight fits them)."""
    v = np.fmax(var, floor)
    good = np.isfinite(v) & (v > 0)
    return np.where(good, 1.0 / np.where(good, v, 1.0), 1.0)


def dof_sandwich(
    phi: np.ndarray,
    r: np.ndarray,
    m: int,
    y: np.ndarray | None = None,
    times: np.ndarray | None = None,
) -> np.ndarray:
    """Covariance of the *unweighted* least squares of ``m`` interleaved DOF equations (row
    i is equation i mod m): the sandwich (ΦᵀΦ)⁻¹ Φᵀ Σ Φ (ΦᵀΦ)⁻¹ with Σ each equation's own
    residual mean square (:func:`dof_variances`, uncentred, times n/(n − p)), since forces (N)
    and moments (N m) do not share one σ̂² (Caccia eq. 12 per equation), each times its own
    correlation time ``times`` [m] where given (Σ_k = τ_k σ_k²). Rows with a non-finite
    residual or regressor count as absent. Given the targets ``y``, each variance is floored at
    a few ulps of its equation's mean square, as :func:`solve_least_squares` floors the RSS: on
    exact data the residual is rounding, and a parameter of 1e-16 read as significant."""
    ok = np.isfinite(r) & np.isfinite(phi).all(1)
    var = dof_variances(np.where(ok, r, np.nan).reshape(-1, m), centred=False)
    if y is not None:
        var = np.fmax(var, rounding_floor(np.where(ok, y, np.nan), m))
    if times is not None:
        var = var * np.asarray(times, dtype=np.float64)
    phi = np.where(ok[:, None], phi, 0.0)
    n = int(ok.sum())
    spread = np.tile(np.where(var > 0, var, 0.0), r.size // m) * ok * n / max(n - phi.shape[1], 1)
    bread = np.linalg.pinv(phi.T @ phi, hermitian=True)
    return bread @ ((phi * spread[:, None]).T @ phi) @ bread


def autocorrelation_time(r: np.ndarray, max_lag: int = 5000) -> float | None:
    """Integrated autocorrelation time 1 + 2 Σ ρ_k of one residual series (summed until ρ
    first drops below 0.05; NaNs dropped): how many samples one independent sample is worth.
    None for a series too short or all zero."""
    return pooled_autocorrelation_time([r], max_lag)


def pooled_autocorrelation_time(
    pieces: Sequence[np.ndarray], max_lag: int = 5000, about_zero: bool = False
) -> float | None:
    """:func:`autocorrelation_time` of a series cut into ``pieces`` (one per experiment): each
    about its own mean, as one series alone is, its lag products summed within it and pooled
    over the pieces, so a jump between experiments is no correlation (two runs whose offsets
    had opposite signs read 2.7 times the τ of the same runs with offsets of one sign);
    ``about_zero``: each about zero instead, for a series the model says is zero-mean. None
    for fewer than 3 finite values or all zero."""
    kept = []
    for r in pieces:
        r = np.asarray(r, dtype=np.float64)
        r = r[np.isfinite(r)]
        if r.size:
            # a series the model says is zero-mean (a filter's innovations) is read about
            # zero: a run's offset is then the model's error, correlated over the whole run
            kept.append(r if about_zero else r - r.mean())
    n = sum(r.size for r in kept)
    if n < 3 or not any(np.any(r) for r in kept):
        return None
    acf = np.zeros(min(max(r.size for r in kept), max_lag))
    for r in kept:
        spec = np.fft.rfft(r, 2 * r.size)
        lags = min(r.size, max_lag)
        acf[:lags] += np.fft.irfft(spec * np.conj(spec))[:lags]
    acf = acf / acf[0]
    below = np.flatnonzero(acf < 0.05)
    cut = below[0] if below.size else acf.size
    return 1.0 + 2.0 * float(np.sum(acf[1:cut]))


def equation_times(
    residuals: np.ndarray | Sequence[np.ndarray],
    max_lag: int = 5000,
    starts: np.ndarray | None = None,
    about_zero: bool = False,
) -> np.ndarray:
    """:func:`autocorrelation_time` of each DOF equation's residual series (the columns of a
    2-D array, or one series per equation), each at least 1 (1 where not measured): each
    equation's own shrink of its effective sample size. One mean over the equations widened a
    white equation's parameters for another's correlated residual, and the correlated one's
    too little. ``starts``: the rows of a 2-D array where a new experiment begins; each
    series is then cut there and pooled (:func:`pooled_autocorrelation_time`, as is
    ``about_zero``)."""
    times = _series_times(residuals, max_lag, starts, about_zero)
    return np.asarray([1.0 if t is None else max(t, 1.0) for t in times])


def _series_times(
    residuals: np.ndarray | Sequence[np.ndarray],
    max_lag: int,
    starts: np.ndarray | None = None,
    about_zero: bool = False,
) -> list[float | None]:
    """:func:`autocorrelation_time` of each residual series: the columns of a 2-D array, or a
    sequence of series (one per DOF equation); cut at ``starts`` where given."""
    series = residuals.T if isinstance(residuals, np.ndarray) and residuals.ndim == 2 else residuals
    cuts = [] if starts is None else np.asarray(starts, dtype=int)
    return [
        pooled_autocorrelation_time(
            np.split(np.asarray(r, dtype=np.float64), cuts), max_lag, about_zero
        )
        for r in series
    ]


def widen_by_equation(
    cov: np.ndarray,
    phi: np.ndarray,
    w: np.ndarray,
    m: int,
    times: np.ndarray,
    theta: np.ndarray,
    sigma2: float,
) -> np.ndarray:
    """The covariance ``cov`` = σ̂² (ΦᵀWΦ)⁺ of a least squares of ``m`` interleaved
    equations weighted ``w`` (row i is equation i mod m; feasible weighting's 1/σ̂_k²; ``theta``
    its estimate, NaN where not fitted; ``sigma2`` its σ̂²), with each equation's residual
    variance σ̂²/w_k widened by its own correlation time τ_k: the sandwich
    σ̂² A⁺ ΦᵀWTΦ A⁺, A = ΦᵀWΦ and T each row's τ_k, over every fitted parameter (a collinear
    one ``cov`` voided was fitted too: left out, the rest's block was no sandwich), then voided
    again where ``cov`` is; τ·cov where the τ_k are equal."""
    times = np.asarray(times, dtype=np.float64)
    if np.all(times == times[0]):
        return cov * float(times[0])
    live = np.isfinite(theta)
    rows = np.isfinite(phi[:, live]).all(1) & (w > 0)
    p, wr = phi[rows][:, live], w[rows]
    tau = np.tile(times, phi.shape[0] // m)[rows]
    inv = scaled_pinv((p * wr[:, None]).T @ p)
    wide = sigma2 * inv @ ((p * (wr * tau)[:, None]).T @ p) @ inv
    out = np.full_like(cov, np.nan)
    out[np.ix_(live, live)] = 0.5 * (wide + wide.T)
    voided = ~np.isfinite(np.diag(cov))
    out[voided, :] = np.nan
    out[:, voided] = np.nan
    return out


def correlation_time(residuals: np.ndarray | Sequence[np.ndarray], max_lag: int = 5000) -> float:
    """:func:`autocorrelation_time` of each residual series (the columns of a 2-D array, or a
    sequence of series: one per DOF equation), averaged (at least 1): the factor by which
    correlated samples shrink the effective sample size."""
    taus = [t for t in _series_times(residuals, max_lag) if t is not None]
    return max(float(np.mean(taus)), 1.0) if taus else 1.0
