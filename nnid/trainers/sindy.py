"""Sparse identification of the viscous force (SINDy) over McCarter's basis library.

pysindy does the sparse regression; nnid supplies the candidate functions. Two modes:

``mode="residual"`` (default)
    regress McCarter's residual force τ̄ = M ν̇ + C(ν)ν + g(η) − τ (eq. 4.4, see
    :meth:`nnid.models.parametric.ParametricFossen.damping_force`) on ξ(ν): τ̄ ≈ Θ ξ(ν), one
    sparse coefficient row per force ``X Y Z K M N``. The coefficients are the damping
    coefficients ``"F:term"`` of a vehicle file.
``mode="control"``
    SINDy with control on the accelerations: ν̇ ≈ Ξ [ξ(ν), τ], the controls entering linearly
    (pysindy's convention of appending u to x before the library). Rigid-body, added-mass and
    Coriolis effects are absorbed by the coefficients (the Coriolis products are library terms);
    restoring forces are not in the library, so this mode suits trimmed, level runs.

The regression is compressed before it reaches pysindy. With the columns of Θ scaled to unit
RMS and each output to unit RMS, G = ΘᵀΘ/N = V Λ Vᵀ and R = Λ^½ Vᵀ, b = Λ^-½ VᵀΘᵀy/N satisfy
‖R ξ − b‖² = ‖Θ ξ − y‖²/N − const for every ξ, so pysindy's optimizers (STLSQ, SR3, library
ensembling) solve exactly the full problem on a K × K system: the fit costs one Gram product
whatever the log length. A threshold is therefore dimensionless: a term is dropped when a
unit-RMS change of it moves the force by less than ``threshold`` times the force's RMS.

The sparsity level is chosen along a path of thresholds by validation error (the sparsest model
whose validation J is within ``tolerance`` of the best), or by AIC / BIC on the training fit.
J is the mean over outputs of the normalised mean squared error MSE_F / mean(y_F²).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
import pysindy as ps
from pysindy.feature_library.base import BaseFeatureLibrary, x_sequence_or_item
from pysindy.utils import AxesArray, comprehend_axes
from sklearn.base import BaseEstimator

from nnid.errors import NnidInputError
from nnid.evaluation.persistence import (
    ROUNDING,
    kind_sizes,
    rounding_columns,
    typical_size,
)
from nnid.physics.damping_library import BasisLibrary, evaluate_terms
from nnid.physics.dofs import DOFS

OPTIMIZERS = ("stlsq", "sr3", "ensemble")
#: the validation NMSE from which an output counts as unexplained: that of predicting zero
UNEXPLAINED = 1.0
SELECTIONS = ("validation", "aic", "bic")
MODES = ("residual", "control")
_EIG_FLOOR = 1e-13  # relative eigenvalue floor of the compressed Gram


class SindyWarning(UserWarning):
    """A selected SINDy model that does not explain an output on held-out data."""


class BasisFeatureLibrary(BaseFeatureLibrary):
    """nnid's basis library as a pysindy feature library.

    The first six inputs are the body velocities ``u v w p q r``; they give the basis terms,
    evaluated by nnid's vectorised :func:`~nnid.physics.damping_library.evaluate_terms`. Any
    further inputs (the controls pysindy appends in SINDy with control) pass through linearly.
    Feature names are the canonical term names, then the control names.
    """

    def __init__(self, terms: Sequence[str] | None = None, u_c: float = 0.0) -> None:
        self.terms = terms
        self.u_c = u_c

    @property
    def basis(self) -> BasisLibrary:
        """The underlying nnid library (canonical term names and codes)."""
        return BasisLibrary(self.terms, self.u_c)

    @x_sequence_or_item
    def fit(self, x_full, y=None) -> BasisFeatureLibrary:
        """Record the input and output sizes."""
        n = x_full[0].shape[x_full[0].ax_coord]
        if n < 6:
            raise ValueError(f"the basis library needs the six velocities; got {n} inputs")
        self._basis = self.basis
        self.n_features_in_ = n
        self.n_output_features_ = len(self._basis) + n - 6
        return self

    @x_sequence_or_item
    def transform(self, x_full):
        """``[..., 6 + n_u]`` -> ``[..., K + n_u]``: basis terms of ν, then the controls."""
        out = []
        for x in x_full:
            arr = np.asarray(x, dtype=np.float64)
            if arr.shape[-1] != self.n_features_in_:
                raise ValueError("x shape does not match training shape")
            xp = evaluate_terms(arr[..., :6], self._basis.codes, self.u_c)
            if arr.shape[-1] > 6:
                xp = np.concatenate([xp, arr[..., 6:]], axis=-1)
            out.append(AxesArray(xp, comprehend_axes(xp)))
        return out

    def get_feature_names(self, input_features: Sequence[str] | None = None) -> list[str]:
        """Canonical term names (``u*abs(u)`` …), then the names of the extra inputs."""
        n = getattr(self, "n_features_in_", 6)
        if input_features is None:
            input_features = [*DOFS, *(f"u{k}" for k in range(n - 6))]
        return [*self.basis.terms, *list(input_features)[6:n]]


def make_optimizer(
    kind: str,
    threshold: float,
    alpha: float = 1e-8,
    max_iter: int = 20,
    n_models: int = 10,
    n_candidates_to_drop: int = 5,
    seed: int = 0,
) -> ps.optimizers.BaseOptimizer | LibraryEnsemble:
    """A pysindy optimizer whose hard threshold on (scaled) coefficients is ``threshold``.

    ``sr3`` uses the L0 regulariser with weight λ = threshold²/2 (its proximal step zeroes
    coefficients below √(2λν) = threshold at ν = 1); ``ensemble`` is library ensembling of STLSQ
    (:class:`LibraryEnsemble`: ``n_models`` fits each without ``n_candidates_to_drop``
    candidate terms drawn by ``seed``, median coefficients). pysindy's own unbiasing is
    off: :func:`debias` refits each support by a minimum-norm least squares, which stays stable
    on the rank-deficient compressed system (the library has exactly collinear terms, e.g.
    every ``(eta-1)`` term when u_c = 0).
    """
    if kind == "stlsq":
        return ps.STLSQ(threshold=threshold, alpha=alpha, max_iter=max_iter, unbias=False)
    if kind == "sr3":
        return ps.SR3(
            reg_weight_lam=threshold**2 / 2,
            regularizer="L0",
            relax_coeff_nu=1.0,
            max_iter=max(max_iter, 100),
            unbias=False,
        )
    if kind == "ensemble":
        return LibraryEnsemble(
            ps.STLSQ(threshold=threshold, alpha=alpha, max_iter=max_iter, unbias=False),
            n_models=n_models,
            n_candidates_to_drop=n_candidates_to_drop,
            seed=seed,
        )
    raise ValueError(f"unknown optimizer '{kind}'; expected one of {', '.join(OPTIMIZERS)}")


def compress(theta: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """``(R, b, c)`` with ‖R ξ − b‖² + c = ‖Θ ξ − y‖²/N summed over outputs (``R`` ``[r, K]``,
    ``b`` ``[r, m]``), from one eigendecomposition of the Gram matrix."""
    n = theta.shape[0]
    gram = theta.T @ theta / n
    rhs = theta.T @ y / n
    lam, vec = np.linalg.eigh(gram)
    keep = lam > _EIG_FLOOR * max(lam.max(), 1e-300)
    lam, vec = lam[keep], vec[:, keep]
    root = np.sqrt(lam)
    r = root[:, None] * vec.T
    b = (vec.T @ rhs) / root[:, None]
    c = float(np.sum(y * y) / n - np.sum(b * b))
    return r, b, c


def debias(r: np.ndarray, b: np.ndarray, coef: np.ndarray) -> np.ndarray:
    """Least squares refit of each output on the support the optimizer chose ``[m, K]``."""
    out = np.zeros_like(coef)
    for i in range(coef.shape[0]):
        support = np.flatnonzero(coef[i])
        if support.size:
            rs = r[:, support]
            sol = np.linalg.pinv(rs.T @ rs, rcond=1e-12, hermitian=True) @ (rs.T @ b[:, i])
            out[i, support] = np.where(sol == 0.0, 1e-300, sol)  # keep the support
    return out


def _rounding_outputs(
    y: np.ndarray, to_linear: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Which outputs of targets ``y`` ``[N, m]`` are rounding, not data ``[m]``: the rounding
    rule (:func:`~nnid.evaluation.persistence.rounding_columns`) of each target against the
    typical size of the regression's targets, not of its regressors (other units); with
    ``to_linear``, of six DOFs' targets, against its own kind's
    (:func:`~nnid.evaluation.persistence.kind_sizes`: a moment beside moments, not forces). A
    target that is not finite is not idle: zeroed, it would hide bad input behind a zero row.
    Also each target's RMS over that size ``[m]``, the number the rule compares with
    :data:`~nnid.evaluation.persistence.ROUNDING` (0 for a target zero throughout)."""
    rms = np.sqrt(np.mean(y * y, axis=0))
    reference = typical_size(y) if to_linear is None else kind_sizes(y, to_linear)
    with np.errstate(divide="ignore", invalid="ignore"):  # a size of 0: every target is 0
        ratio = np.where(rms == 0, 0.0, rms / reference)
    return np.isfinite(rms) & rounding_columns(rms, reference), ratio


def nmse(y: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """Per-output normalised MSE: mean((y − ŷ)²) / mean(y²). NaN where a target is zero
    throughout, whatever the prediction: there is nothing to normalise an error by, so no share
    of it is measured (a floor of 1e-300 made an error an NMSE of ~1e299, and a zero error
    was 0, a perfect score that nothing measured), as :func:`~nnid.evaluation.metrics.nrmse`
    of a flat signal."""
    ms = np.mean(y * y, axis=0)
    err = np.mean((y - pred) ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ms > 0, err / ms, np.nan)


def _j(err: np.ndarray, outputs: np.ndarray) -> float:
    """J, the mean NMSE over ``outputs`` [m] (those with something to explain); NaN where
    none is, or where one of them is not measured (:func:`nmse`)."""
    return float(err[outputs].mean()) if outputs.any() else float("nan")


def path_j(y: np.ndarray, pred: np.ndarray, to_linear: float | None = None) -> float:
    """J of predictions ``pred`` of targets ``y`` ``[N, m]`` as the path scores it
    (:func:`_j`): the mean NMSE over the outputs whose target is not rounding
    (:func:`_rounding_outputs`: one zero throughout, still on the log, is one of those); NaN
    where none has anything to explain."""
    return _j(nmse(y, pred), ~_rounding_outputs(y, to_linear)[0])


def _least(val: np.ndarray) -> np.ndarray:
    """The smallest of each column of ``val`` ``[T, m]`` over its rows, NaN where no row is
    measured (np.nanmin's answer, without its warning of an all-NaN column)."""
    least = np.min(np.where(np.isnan(val), np.inf, val), axis=0)
    return np.where(np.isnan(val).all(axis=0), np.nan, least)


class LibraryEnsemble:
    """Library ensembling of a pysindy optimizer (pysindy's ``EnsembleOptimizer`` with
    ``library_ensemble=True``): ``n_models`` fits of ``opt``, each on the library without
    ``n_candidates_to_drop`` candidate terms drawn at random, and the median of their
    coefficients (a dropped term's is zero) as ``coef_``.

    Written here because pysindy's draws from NumPy's global generator and takes none of its
    own: reseeding the global one around its fit rewound or corrupted another thread's random
    stream. The draws come from a local ``RandomState(seed)``, the same draws pysindy made from
    the global generator seeded so, so the ensemble's numbers are those it gave."""

    def __init__(self, opt, n_models: int = 10, n_candidates_to_drop: int = 5, seed: int = 0):
        if n_models < 1 or n_candidates_to_drop < 1:
            raise ValueError("a library ensemble fits at least one model, each without a term")
        self.opt = opt
        self.n_models = n_models
        self.n_candidates_to_drop = n_candidates_to_drop
        self.seed = seed

    def fit(self, x: np.ndarray, y: np.ndarray) -> LibraryEnsemble:
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        if y.ndim == 1:
            y = y[:, None]
        n = x.shape[1]
        drop = self.n_candidates_to_drop
        if drop > n:  # as pysindy's ensemble says it
            warnings.warn(
                f"n_candidates_to_drop ({drop}) exceeds the library's {n} terms: every model "
                "is fitted on the whole library",
                stacklevel=2,
            )
            drop = 0
        rng = np.random.RandomState(self.seed)
        coefs = []
        for _ in range(self.n_models):
            keep = np.sort(rng.choice(range(n), n - drop, replace=False))
            self.opt.fit(x[:, keep], y)
            coef = np.zeros((y.shape[1], n))
            coef[:, keep] = np.asarray(self.opt.coef_).reshape(y.shape[1], -1)
            coefs.append(coef)
        self.coef_ = np.median(coefs, axis=0)
        return self


class SparsePath(BaseEstimator):
    """The SINDy path: pysindy's optimizer at each threshold on the compressed regression
    (module docstring), each support debiased, and a model chosen along the path.

    ``fit(theta, y, theta_val, y_val)`` on evaluated features ``theta`` ``[N, K]`` and targets
    ``y`` ``[N, m]``: ``path_`` lists every threshold tried (``threshold``, ``n_terms``,
    ``train_J``, ``validation_J``, ``aic``, ``bic``), ``selected_`` the chosen entry (with
    validation data also ``validation_nmse``, each output's normalised MSE) and ``coef_``
    ``[m, K]`` its coefficients. ``excluded_`` ``[K]``: the columns of ``theta`` that are
    rounding, not data (:func:`~nnid.evaluation.persistence.rounding_columns`: u·w of a log
    that never heaves, w ~ 1e-17), each against its own floor in ``fit``'s ``floors`` where
    given (:func:`~nnid.evaluation.persistence.library_floors`: a term at the log's typical
    motion, to its power, so that q|q| of a real pitch rate 1e-6 of the yaw rate is data),
    else against :func:`~nnid.evaluation.persistence.typical_size` of ``theta``; they are zero
    to the path, never selected, their coefficients exactly 0.
    ``idle_outputs_`` ``[m]``: the outputs whose target is rounding against the typical size
    of the targets (the Munk moments' 1e-17 in K and M of that log); their target is zero, as
    if exactly so: they keep no terms, and where the held-out target is rounding too their
    validation NMSE is that of a zero target (not measured: NaN), not called unexplained nor
    named. ``to_linear``: where the six outputs are a six-DOF quantity's (X Y Z K M N, or ν̇),
    the factor that puts the angular kind in the linear one's units (one over the vehicle's
    length for moments, the length for angular accelerations); each target is then judged
    within its own kind (:func:`~nnid.evaluation.persistence.kind_sizes`), as a moment in N·m
    beside forces in N is no rounding for being small; None: the outputs are one kind. An
    output whose held-out target is zero throughout has no validation NMSE, whether the model
    predicts zero there or not (NaN, :func:`nmse`): one fitted in training is said, with its
    prediction's RMS there, keeps no terms under ``per_output`` (nothing measured speaks for
    them), and a J that includes it is NaN too (the shared selection chooses by the outputs
    that are measured).
    ``selection`` is "validation" (the sparsest model whose validation J is within
    ``tolerance`` of the best; with ``per_output`` each output picks its own row, greedily
    sparsest while the mean validation J of the outputs the path explains stays within
    ``tolerance`` of the best, so ``selected_`` may mix thresholds; the zero row is every
    output's candidate too, and an output it is within ``tolerance`` of keeps no terms),
    "aic" or "bic". J is the mean over outputs of the normalised MSE. Outputs the
    selected model does not explain on the validation data (NMSE ≥ 1, that of no model) are
    named in a :class:`SindyWarning`; ``output_names`` names them. An idle output whose
    held-out target is not rounding has the NMSE of its zero prediction (1): it is named in a
    warning of its own, which says it was idle in training.
    """

    def __init__(
        self,
        optimizer: str = "stlsq",
        thresholds: Sequence[float] | None = None,
        selection: str = "validation",
        tolerance: float = 0.05,
        alpha: float = 1e-8,
        per_output: bool = True,
        seed: int = 0,
        output_names: Sequence[str] | None = None,
        to_linear: float | None = None,
    ) -> None:
        self.optimizer = optimizer
        self.thresholds = thresholds
        self.selection = selection
        self.tolerance = tolerance
        self.alpha = alpha
        self.per_output = per_output
        self.seed = seed
        self.output_names = output_names
        self.to_linear = to_linear

    def fit(
        self,
        theta: np.ndarray,
        y: np.ndarray,
        theta_val: np.ndarray | None = None,
        y_val: np.ndarray | None = None,
        floors: np.ndarray | None = None,
    ) -> SparsePath:
        """The path and the selection (class docstring); ``floors`` ``[K]``: each column's
        floor of the rounding rule (:func:`~nnid.evaluation.persistence.library_floors`), where
        NaN or None the scalar rule's."""
        if self.optimizer not in OPTIMIZERS:
            raise NnidInputError(f"optimizer is one of {', '.join(OPTIMIZERS)}", field="optimizer")
        if self.selection not in SELECTIONS:
            raise NnidInputError(f"selection is one of {', '.join(SELECTIONS)}", field="selection")
        if theta_val is None and self.selection == "validation":
            raise NnidInputError("selection='validation' needs validation data", field="selection")
        if self.to_linear is not None and not (np.isfinite(self.to_linear) and self.to_linear > 0):
            raise NnidInputError(
                f"to_linear is a finite factor > 0 (a length or one over it), got {self.to_linear}",
                field="to_linear",
            )
        if self.to_linear is not None and y.shape[1] != 6:
            raise NnidInputError(
                f"to_linear judges six DOFs' targets by kind; y has {y.shape[1]} outputs",
                field="to_linear",
            )
        if floors is not None and np.shape(floors) != theta.shape[1:]:
            raise NnidInputError(
                f"floors has shape {np.shape(floors)}; one per column of theta, "
                f"({theta.shape[1]},), is expected",
                field="floors",
            )
        thresholds = (
            np.logspace(-3, 0, 41)
            if self.thresholds is None
            else np.asarray(self.thresholds, dtype=float)
        )
        n = theta.shape[0]
        col = np.sqrt(np.mean(theta * theta, axis=0))
        # a column of rounding is zero, as the excitation check says it: scaled to unit RMS it
        # was a full-size column of noise, and the path selected u·w of a log that never
        # heaved (w ~ 1e-17) to fit the Munk moments' rounding in M and K. Each against its
        # own floor where given: against one size for all, q|q| of a real pitch rate 1e-6 of
        # the yaw rate (1e-11 beside u|u|) was rounding, and M was warned unexplained
        self.excluded_ = rounding_columns(col, typical_size(theta), floors)
        col[self.excluded_] = 1.0
        # a target of rounding is zero too: scaled to unit RMS, the Munk moments' rounding in K
        # and M (w ~ 1e-17) had real columns fitted to it, and it was warned unexplained
        self.idle_outputs_, self._idle_ratio = _rounding_outputs(y, self.to_linear)
        y = np.where(self.idle_outputs_, 0.0, y)
        if y_val is not None:  # an idle output's prediction is 0: nothing to explain where
            # its held-out target is rounding too; where it is not, scored (and warned) as is
            idle_val, _ = _rounding_outputs(y_val, self.to_linear)
            y_val = np.where(self.idle_outputs_ & idle_val, 0.0, y_val)
        # J over the outputs with something to explain: an idle one has no NMSE (a zero
        # target), and averaged in as NaN it made every J of a log with a still DOF unmeasured
        fitted = ~self.idle_outputs_
        scored = fitted if y_val is None else ~(self.idle_outputs_ & idle_val)
        out = np.sqrt(np.mean(y * y, axis=0))
        out[out == 0] = 1.0
        scaled_theta = theta / col
        scaled_theta[:, self.excluded_] = 0.0  # as the same log's with those columns exactly 0
        r, b, _ = compress(scaled_theta, y / out)
        path = []
        coefs = []
        val_out = []
        ms_y = np.maximum(np.mean(y * y, axis=0), 1e-300)
        for thr in thresholds:
            opt = make_optimizer(self.optimizer, float(thr), self.alpha, seed=self.seed)
            with warnings.catch_warnings():
                # "all coefficients eliminated" at large thresholds is an answer, not a fault
                warnings.filterwarnings("ignore", message=".*eliminated all coefficients.*")
                opt.fit(r, b)
            chosen = np.array(opt.coef_, dtype=np.float64).reshape(y.shape[1], -1)
            chosen[:, self.excluded_] = 0.0  # exactly: eigh may leave last bits in R's column
            scaled = debias(r, b, chosen)
            coef = scaled * out[:, None] / col[None, :]  # [m, K]
            pred = theta @ coef.T
            train_err = nmse(y, pred)
            k = int(np.count_nonzero(coef))
            # the likelihood reads each output's MSE, of an output with a zero target too
            # (idle), which has no NMSE: there its MSE is its prediction's (0: it keeps no terms)
            mse = np.where(np.isnan(train_err), np.mean(pred * pred, axis=0), train_err * ms_y)
            log_mse = float(np.sum(n * np.log(np.maximum(mse, 1e-300))))
            entry = {
                "threshold": float(thr),
                "n_terms": k,
                "train_J": _j(train_err, fitted),
                "validation_J": (
                    _j(nmse(y_val, theta_val @ coef.T), scored)
                    if theta_val is not None
                    else float("nan")
                ),
                "aic": log_mse + 2.0 * k,
                "bic": log_mse + k * float(np.log(n * y.shape[1])),
            }
            path.append(entry)
            coefs.append(coef)
            if theta_val is not None:
                val_out.append(nmse(y_val, theta_val @ coef.T))
        self.path_ = path
        best = self._select(path, val_out)
        self.selected_ = dict(path[best])
        self.coef_ = coefs[best]
        val_nmse = val_out[best] if theta_val is not None else None
        path_best = _least(np.array(val_out)) if theta_val is not None else None
        if self.per_output and self.selection == "validation":
            # the zero row is every output's candidate too: a regression that predicts held-out
            # data worse than no model at all must not keep its terms because the threshold
            # path never reached zero (cancelling coefficients of noise outgrow any threshold)
            coefs.append(np.zeros_like(coefs[0]))
            val_out.append(nmse(y_val, np.zeros_like(y_val)))
            self.coef_ = self._select_per_output(np.array(coefs), np.array(val_out))
            val_nmse = nmse(y_val, theta_val @ self.coef_.T)
            self.selected_ = {
                "threshold": None,
                "n_terms": int(np.count_nonzero(self.coef_)),
                "train_J": _j(nmse(y, theta @ self.coef_.T), fitted),
                "validation_J": _j(val_nmse, scored),
            }
        if val_nmse is not None:
            # the mean J can hide one output the library cannot explain: each output's own
            self.selected_["validation_nmse"] = [float(v) for v in val_nmse]
            self._warn_unexplained(val_nmse, path_best)
            error = np.sqrt(np.mean((y_val - theta_val @ self.coef_.T) ** 2, axis=0))
            self._warn_unmeasured(val_nmse, error)
        return self

    def _names(self, m: int) -> list[str]:
        return list(self.output_names or [f"output {i}" for i in range(m)])

    def _warn_unmeasured(self, selected: np.ndarray, error: np.ndarray) -> None:
        """Say which outputs fitted in training have no validation NMSE (NaN: the held-out
        target is zero throughout), with the RMS of the selected model's prediction there (0
        where it keeps no terms). An idle output (``idle_outputs_``) is not named: fitted to
        nothing and scored on nothing, it has nothing to explain."""
        names = self._names(len(selected))
        unmeasured = [
            f"{names[i]} (held-out target zero, the model's prediction RMS {error[i]:.3g})"
            for i in np.flatnonzero(np.isnan(selected) & ~self.idle_outputs_)
        ]
        if unmeasured:
            warnings.warn(
                f"the validation data do not measure the SINDy model's NMSE of "
                f"{', '.join(unmeasured)}: an error beside a zero target is no share of it "
                "(NaN); give validation data in which those outputs act",
                SindyWarning,
                stacklevel=3,
            )

    def _warn_unexplained(self, selected: np.ndarray, best: np.ndarray) -> None:
        """Say which outputs the selected model does not explain on the validation data
        (normalised MSE ≥ 1, that of predicting zero), with the best each reached on the path.
        An idle output (``idle_outputs_``) among them was never fitted: it is said apart, with
        why (its training target's RMS over its kind's typical size, the number the rounding
        rule compared with its floor), as no path or library could have explained it."""
        names = self._names(len(best))
        unexplained = selected >= UNEXPLAINED
        idle = [
            f"{names[i]} (validation NMSE {selected[i]:.3g}, training target "
            + (
                f"RMS {self._idle_ratio[i]:.3g} of its kind's typical size)"
                if self._idle_ratio[i] > 0
                else "zero throughout)"
            )
            for i in np.flatnonzero(unexplained & self.idle_outputs_)
        ]
        if idle:  # its training target was zeroed as rounding: "best on the path" and "the
            # library lacks it" would send the user to the thresholds and terms for nothing
            warnings.warn(
                f"the SINDy model fits nothing of {', '.join(idle)}: each was idle in "
                f"training, its target rounding there (at most the rounding floor {ROUNDING:g} "
                "of its kind's typical size), so it keeps no terms, while its held-out target "
                "is not rounding; give training data in which it acts",
                SindyWarning,
                stacklevel=3,
            )
        poor = [
            f"{names[i]} (validation NMSE {selected[i]:.3g}, best on the path {best[i]:.3g})"
            for i in np.flatnonzero(unexplained & ~self.idle_outputs_)
        ]
        if not poor:
            return
        if self.per_output and self.selection == "validation":
            why = (
                "those outputs keep no terms; the training data do not excite what they need, "
                "or the library lacks it"
            )
        else:
            why = "their terms are kept by a threshold or criterion shared with the other outputs"
            if not self.per_output:
                why += " (per_output=True selects each output on its own)"
        warnings.warn(
            f"the selected SINDy model explains nothing of {', '.join(poor)} on the validation "
            f"data (an NMSE of 1 is that of no model): {why}",
            SindyWarning,
            stacklevel=3,
        )

    def _select_per_output(self, coefs: np.ndarray, val: np.ndarray) -> np.ndarray:
        """Rows per output (the outputs are separate regressions; J is their mean). An output
        whose zero row (the last) is within ``tolerance`` of its best explains nothing: it keeps
        no terms and has no share in the budget, where its error (noise, or rounding that
        differs by CPU) loosened every other output's selection. The others start from their
        best validation rows and, while their mean stays within ``tolerance`` of that best,
        greedily take the sparser row that costs the least J per term saved."""
        zero = val.shape[0] - 1
        best = _least(val)
        k = np.count_nonzero(coefs, axis=2)  # [T, m]
        # an output whose held-out target is zero has no NMSE on any row: nothing measured
        # speaks for its terms, and it keeps none (as when the zero row scored it 0)
        pick = {
            i: int(np.nanargmin(val[:, i]))
            for i in range(coefs.shape[1])
            if np.isfinite(best[i]) and not val[zero, i] <= (1.0 + self.tolerance) * best[i]
        }
        m = len(pick)
        if not pick:
            return np.zeros_like(coefs[zero])
        budget = (1.0 + self.tolerance) * float(np.mean([val[j, i] for i, j in pick.items()]))
        while True:
            total = float(np.mean([val[j, i] for i, j in pick.items()]))
            choice, best_rate = None, np.inf
            for i in pick:
                for j in range(val.shape[0]):
                    saved = k[pick[i], i] - k[j, i]
                    extra = (val[j, i] - val[pick[i], i]) / m
                    if saved > 0 and total + extra <= budget and extra / saved < best_rate:
                        choice, best_rate = (i, j), extra / saved
            if choice is None:
                break
            pick[choice[0]] = choice[1]
        return np.stack([coefs[pick.get(i, zero), i] for i in range(coefs.shape[1])])

    def _select(self, path: list[dict], val_out: list[np.ndarray]) -> int:
        """The row of the shared selection: by AIC or BIC, or the sparsest within
        ``tolerance`` of the best validation J among the rows whose J is measured; where none
        is (an output with a zero held-out target, whose NMSE no row measures), J over the
        outputs measured on every row."""
        if self.selection in ("aic", "bic"):
            return int(np.argmin([p[self.selection] for p in path]))
        val = np.array([p["validation_J"] for p in path])
        if np.isnan(val).all():
            per = np.array(val_out)
            common = ~np.isnan(per).any(axis=0)
            val = per[:, common].mean(axis=1) if common.any() else np.zeros(len(path))
        ok = np.flatnonzero(val <= (1.0 + self.tolerance) * np.nanmin(val))
        return int(min(ok, key=lambda i: (path[i]["n_terms"], val[i])))
