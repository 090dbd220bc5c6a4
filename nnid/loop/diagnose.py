"""Diagnosis: which missing effect explains the residual, how sure we are, and the loop.

For the model at its current fit (the baseline first: the vehicle file with its damping
structure re-identified), every candidate effect is added in turn and the model refitted by
weighted least squares; the candidate is scored by

- the drop of the *training* weighted residual sum of squares, tested with an F-test whose
  degrees of freedom are shrunk by the residual's integrated autocorrelation time (smoothed
  and filtered logs have far fewer independent samples than rows), at ``alpha`` divided by
  the number of candidates tested (Bonferroni: hundreds of coupled terms are tried; one the
  data do not excite, or whose column lies in the span of the fit's, is named, not tested);
- Caccia's percentile error of the new parameter, 100 σ/|θ| ≤ 51 % (Caccia eq. 12, L135);
- the drop of the *held-out* force residual, total and in the DOF it explains most: a
  candidate must improve held-out error by at least ``min_improvement``, not only fit noise.

Linear-in-parameter candidates are screened all at once: adding column φ to a regression
whose residual e is orthogonal to the baseline columns Φ_b gives, in closed form (Frisch-Waugh),
θ = −φᵀWe / (φᵀWφ − bᵀA⁻¹b) with A = Φ_bᵀWΦ_b, b = Φ_bᵀWφ, and the refitted baseline moves by
−A⁻¹b θ. Current, actuator lag and deadband enter nonlinearly: their value is found by a
bounded one-dimensional search with the baseline refitted at each step (variable projection).
The best admissible candidate is added, the model refitted, and the search repeated until
nothing significant is left. pysindy's STLSQ over all linear candidates at once gives a second
opinion.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.optimize import minimize_scalar
from scipy.stats import f as f_dist

from nnid.datasets.arrays import force_arrays, log_arrays, nominal_forces
from nnid.datasets.log import VELOCITY
from nnid.datasets.preprocess import excited_dofs, zoh_midpoint
from nnid.evaluation.evaluate import score_split
from nnid.evaluation.metrics import exact_mean, rmse, warmup_mask
from nnid.evaluation.persistence import (
    column_sizes,
    equation_rms,
    gram_ranks,
    measured_columns,
    rounding_floors,
)
from nnid.evaluation.prediction import mode_steps, predict_states
from nnid.loop.effects import Candidate
from nnid.models.parametric import (
    ParametricFossen,
    filter_settled,
    filter_signal,
    vehicle_with,
)
from nnid.physics.dofs import DOFS
from nnid.physics.parts import Parts
from nnid.trainers.least_squares import (
    ExcitationWarning,
    correlation_time,
    dof_variances,
    feasible_floor,
    feasible_weights,
    rounding_scale,
    solve_regression,
)
from nnid.trainers.regression import Regression
from nnid.trainers.sindy import compress

_CHUNK = 64


@dataclass
class Fit:
    """The model at one step of the loop: the vehicle with every fitted value written in."""

    vehicle: object
    unknowns: list[str]
    theta: np.ndarray
    stderr: np.ndarray
    phi: np.ndarray  # [N, 6, P] training columns of the unknowns
    phi_val: np.ndarray  # [N_val, 6, P]
    e: np.ndarray  # [N, 6] training equation residual
    e_val: np.ndarray  # [N_val, 6]
    rss: float  # weighted training residual sum of squares


@dataclass
class Scored:
    """A candidate after its refit: the row of the candidate table."""

    candidate: Candidate
    value: float
    stderr: float
    p_value: float
    f_stat: float
    improvement: float  # held-out weighted force residual, fraction removed
    dof_improvement: dict[str, float]
    percentile_error: float
    admissible: bool = False
    reason: str = ""
    refit: dict[str, float] = field(default_factory=dict)  # baseline unknowns after the refit
    gate: tuple[float | None, float | None] | None = None  # held-out simulation NRMSE before/after
    # for :func:`rescore`: the F-test's pieces and how to rebuild the training residual
    drss: float = 0.0
    sigma2: float = 1.0
    delta: float = 0.0  # parameter change θ
    shift: np.ndarray | None = None  # A⁻¹ b: how the fit's unknowns move with θ
    residual: np.ndarray | None = None  # training residual after (nonlinear candidates)
    aliases: list[str] = field(default_factory=list)  # the same column on this log
    # where a 1-D search's best value lies at the edge of its range (or the search ran out of
    # evaluations): the size is a bound there, not a measurement, and is said so
    edge: str = ""
    # False: the data do not excite its column (CandidateExcitation): nothing measured
    excited: bool = True
    # False: its column lies in the span of the fit's (:func:`identifiable`): nothing measured
    identifiable: bool = True
    # False: its column is not finite on the fit's rows (:data:`NOT_FINITE`): nothing measured
    finite: bool = True
    # why its s.e. was not measured (a 1-D search's, :func:`_linearised_stderr`), said in its
    # verdict; "" where it was, or where nothing of it was
    unmeasured: str = ""

    @property
    def name(self) -> str:
        return self.candidate.name

    @property
    def scored(self) -> bool:
        """Whether anything of the candidate was measured: excited, identifiable and finite."""
        return self.excited and self.identifiable and self.finite

    def as_dict(self) -> dict:
        return {
            "effect": self.name,
            "meaning": self.candidate.meaning,
            "params": {"value": self.value},
            # at a search's edge the linearised s.e. measures nothing of the true size
            "stderr": {
                "value": self.stderr if np.isfinite(self.stderr) and not self.edge else None
            },
            "significance": self.p_value,
            "f_statistic": self.f_stat,
            "percentile_error": self.percentile_error
            if np.isfinite(self.percentile_error) and not self.edge
            else None,
            "edge": self.edge or None,
            "improvement": self.improvement,
            "improvement_per_dof": self.dof_improvement,
            "gate_nrmse": None
            if self.gate is None
            else {"before": self.gate[0], "after": self.gate[1]},
            "admissible": self.admissible,
            "reason": self.reason,
            "same_column_as": self.aliases,
        }


@dataclass
class Step:
    """One pass of the loop: the ranked candidates and what was added."""

    ranked: list[Scored]
    added: Scored | None
    sindy: list[str]
    fit: Fit | None = None  # the refitted model with ``added`` in it
    # the candidates tested (scored, and 1-D searches that found no better fit): the
    # Bonferroni correction's count
    tested: int = 0
    # the 1-D searches that ran and found no better fit: tested, with nothing to rank
    no_better_fit: list[str] = field(default_factory=list)


class Workspace:
    """Training and held-out arrays of a log, and the per-DOF weights of the loop's fits."""

    def __init__(
        self,
        train: pd.DataFrame,
        val: pd.DataFrame,
        vehicle,
        filter_lambda: float | None = 1.0,
        zoh_midpoint: bool = True,
        dofs: tuple[str, ...] = DOFS,
    ) -> None:
        self.train, self.val = train, val
        self.dofs = tuple(dofs)
        self.mask = np.array([d in self.dofs for d in DOFS], dtype=float)
        self.filter_lambda = filter_lambda
        self.zoh_midpoint = zoh_midpoint
        self.data = log_arrays(train, vehicle)
        self.data_val = log_arrays(val, vehicle)
        self.weights: np.ndarray | None = None
        self.variance_floor: np.ndarray | None = None  # per DOF, set with the weights
        self.tau_corr = 1.0
        self._cache: dict[tuple, dict[str, np.ndarray]] = {}
        self._sizes: dict[tuple, dict[str, tuple[float, float]]] = {}
        self._tau: dict[tuple, dict[str, np.ndarray]] = {}
        # held-out simulations of one fit, by (id(vehicle), mode): the loop's gate and its
        # before/after scores simulate the same models (:meth:`ResidualLoop._velocity_scores`)
        self.simulations: dict[tuple, tuple] = {}
        self._nu_dot_f: dict[str, np.ndarray] = {}

    def arrays(self, vehicle, part: str = "train") -> dict[str, np.ndarray]:
        """The arrays with the nominal forces recomputed for ``vehicle`` (its lag, deadband;
        a lag's negative part too, :func:`~nnid.datasets.arrays.force_arrays`)."""
        log, data = (self.train, self.data) if part == "train" else (self.val, self.data_val)
        key = (part, vehicle.actuator_lag, vehicle.deadband)
        if key not in self._tau:  # the searches refit many times at one lag and deadband
            forces = force_arrays(log, vehicle)
            if self.zoh_midpoint and vehicle.actuator_lag == 0:
                # a held input steps at each sample; a lagged force is continuous, seen as it is
                forces["tau"] = zoh_midpoint(forces["tau"], log)
            self._tau[key] = forces
        # the lagged negative part of another lag (the workspace's vehicle's) must not stay
        motion = {k: v for k, v in data.items() if k != "tau_neg"}
        return {**motion, **self._tau[key]}

    def columns(self, vehicle, names: list[str], part: str) -> np.ndarray:
        """Regressor columns [N, 6, P] of parameters at ``vehicle``, cached: a column of a
        parameter the model is affine in depends only on the data, the current, the lag and
        the deadband, so later passes reuse it."""
        key = (part, tuple(vehicle.current), vehicle.actuator_lag, vehicle.deadband)
        cache = self._cache.setdefault(key, {})
        missing = [n for n in names if n not in cache]
        if missing:
            data = self.arrays(vehicle, part)
            cols, _ = _columns(vehicle, missing, data, self.filter_lambda, self.nu_dot_f(part))
            cache.update({n: cols[:, :, k] for k, n in enumerate(missing)})
        return np.stack([cache[n] for n in names], 2)

    def reference_sizes(self, vehicle, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """The training columns' sizes of parameters at ``vehicle`` over the analysed DOF
        equations, at the log's typical motion ``[P]`` and with each velocity scaled
        ``[6, P]``, of which their rounding
        floors are made (:meth:`ParametricFossen.reference_sizes`), cached as :meth:`columns`
        caches the columns: a column of a parameter the model is affine in depends only on
        the data, the current, the lag and the deadband. Damping terms are sized together
        (one basis evaluation), the rest apart from them (a model each, which would otherwise
        carry hundreds of damping terms)."""
        key = (tuple(vehicle.current), vehicle.actuator_lag, vehicle.deadband)
        cache = self._sizes.setdefault(key, {})
        missing = [n for n in dict.fromkeys(names) if n not in cache]
        for damping in (True, False):
            part = [n for n in missing if (":" in n) == damping]
            if part:
                structure = ParametricFossen(vehicle, part)
                with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
                    one, probe = structure.reference_sizes(
                        self.arrays(vehicle), self.accelerations(), _fitted_dofs(self)
                    )
                cache.update({n: (one[k], probe[:, k]) for k, n in enumerate(part)})
        one = np.array([cache[n][0] for n in names], dtype=float)
        probe = np.array([cache[n][1] for n in names], dtype=float).reshape(len(names), -1)
        return one, probe.T

    def nu_dot_f(self, part: str) -> np.ndarray | None:
        """sF(s)[ν] of a part at the workspace's λ (None unfiltered), filtered once: it
        depends on the measured velocities alone, and every regression of the loop (each
        candidate's column, each step of a 1-D search) needs it
        (:meth:`ParametricFossen.equation_residual`)."""
        if self.filter_lambda is None:
            return None
        if part not in self._nu_dot_f:
            data = self.data if part == "train" else self.data_val
            self._nu_dot_f[part] = filter_signal(
                data, data["nu"], self.filter_lambda, derivative=True
            )
        return self._nu_dot_f[part]

    def accelerations(self) -> np.ndarray:
        """ν̇ as the training regression reads it, on its rows: sF(s)[ν] of the filtered form,
        else the logged (or derived) ν̇; the columns' rounding floors are sized at it
        (:meth:`ParametricFossen.reference_sizes`)."""
        acc = self.data["nu_dot"] if self.filter_lambda is None else self.nu_dot_f("train")
        return acc[self.settled(self.data)]

    def settled(self, data: dict[str, np.ndarray]) -> np.ndarray:
        """The rows the regression keeps: all, or those after the filters settle."""
        if self.filter_lambda is None:
            return np.ones(data["t"].size, dtype=bool)
        return filter_settled(data, self.filter_lambda)


def _columns(
    vehicle,
    names: list[str],
    data: dict,
    filter_lambda: float | None,
    nu_dot_f: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(Φ [N, 6, P], R(0) [N, 6]) of the unknowns ``names`` at ``vehicle``; ``nu_dot_f`` as
    :meth:`ParametricFossen.equation_residual` takes it (:meth:`Workspace.nu_dot_f`)."""
    reg = _regression(vehicle, names, data, filter_lambda, nu_dot_f)
    n = reg.n_samples
    return reg.phi.reshape(n, 6, len(names)), -reg.y.reshape(n, 6)


def _regression(
    vehicle,
    names: list[str],
    data: dict,
    filter_lambda: float | None,
    nu_dot_f: np.ndarray | None = None,
    floor_dofs: tuple[str, ...] | None = None,
) -> Regression:
    """The six DOF equations' regression of the unknowns ``names`` at ``vehicle``, stacked
    sample-major (:meth:`ParametricFossen.regression`; ``nu_dot_f`` as :func:`_columns`), its
    rounding floors sized over the equations ``floor_dofs`` (default: all six)."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):  # rows of NaN (gaps)
        structure = ParametricFossen(vehicle, names)
        return structure.regression(data, filter_lambda, nu_dot_f, floor_dofs)


def _fitted_dofs(ws: Workspace) -> tuple[str, ...]:
    """The DOF equations the loop's fits weight (weight > 0): the analysed ones."""
    return tuple(d for d, m in zip(DOFS, ws.mask, strict=True) if m > 0)


def _unread_zeroed(cols: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``cols`` [N, 6, K] with its NaN or infinite entries in the DOF equations of weight 0
    (``w`` [6]) set to 0, a copy only where there are any: no fit reads those equations, but
    a weighted sum over all six reads 0 · NaN = NaN, and a column NaN only where the loop does
    not look (a velocity the log lacks, in another DOF's row) measured nothing."""
    idle = np.flatnonzero(w == 0)
    unread = cols[:, idle, :]
    bad = ~np.isfinite(unread)
    if not bad.any():
        return cols  # the same array: every sum bit for bit as before
    out = cols.copy()
    out[:, idle, :] = np.where(bad, 0.0, unread)
    return out


def _wss(x: np.ndarray, w: np.ndarray) -> float:
    """Σ_d w_d Σ_n x[n, d]² over finite samples."""
    return float(np.nansum(x**2 * w))


def refit(ws: Workspace, vehicle, unknowns: list[str], held_out: bool = True) -> Fit:
    """Weighted least squares of ``unknowns`` at ``vehicle``, with the workspace's weights:
    set by the first (baseline) fit, 1/σ̂²_dof of its ordinary-least-squares residual (floored,
    :func:`_set_weights`), and renewed by :func:`reweight` as each effect is added. Without
    ``held_out`` the held-out arrays are left empty (for searches that need only the RSS)."""
    # its columns are judged by the equations it fits, as a trainer's fit of those DOFs judges
    # them: an added mass's C_A(ν)ν rows in the other five set its floor 1e-10 below its ν̇
    # row's, and a heave-only fit estimated Z_wdot off a heave of rounding (1e-12 of the surge)
    reg = _regression(
        vehicle, unknowns, ws.arrays(vehicle), ws.filter_lambda, ws.nu_dot_f("train"),
        _fitted_dofs(ws),
    )  # fmt: skip
    n, p = reg.n_samples, len(unknowns)
    phi = reg.phi.reshape(n, 6, p)
    if held_out:
        data_v = ws.arrays(vehicle, "val")
        phi_v, r0_v = _columns(vehicle, unknowns, data_v, ws.filter_lambda, ws.nu_dot_f("val"))
    else:
        phi_v, r0_v = np.zeros((0, 6, p)), np.zeros((0, 6))
    a_mat, y = reg.phi, reg.y
    # what the data excite is judged as the least-squares trainer judges it (solve_regression):
    # within each DOF equation, each column against its own rounding floor. Compared with all
    # six equations' columns at once, a yaw term 1e-8 of a surge one, measured by the N rows,
    # was a zero regressor: dropped, its s.e. NaN
    if ws.weights is None:  # DOF equations the log does not measure get weight zero
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ExcitationWarning)
            est = solve_regression(reg, np.tile(ws.mask, n))
        _set_weights(ws, (a_mat @ np.nan_to_num(est.theta) - y).reshape(n, 6), y.reshape(n, 6))
    w_rows = np.tile(ws.weights, n)
    # six DOF equations weighted apart (rows sample-major): each one's share of the RSS is
    # floored on its own, at the variance its weight was floored at
    est = solve_regression(reg, w_rows, equations=6, variance_floor=ws.variance_floor)
    theta = np.nan_to_num(est.theta)
    e = (a_mat @ theta - y).reshape(n, 6)
    # rows by count, not -1: a vehicle file with no coefficient to refit has p = 0 columns
    e_val = (phi_v.reshape(phi_v.shape[0] * 6, p) @ theta + r0_v.reshape(-1)).reshape(-1, 6)
    fitted = vehicle_with(vehicle, dict(zip(unknowns, theta, strict=True)))
    return Fit(fitted, list(unknowns), theta, est.stderr, phi, phi_v, e, e_val, _wss(e, ws.weights))


def reweight(ws: Workspace, fit: Fit) -> Fit:
    """The fit again with the weights renewed from its own residual, 1/σ̂²_dof (one step of
    feasible weighted least squares). The baseline's weights are kept no longer than the
    baseline: where it misses an effect (a restoring moment), its roll and pitch residual is
    thousands of times the final one, and those equations, weighted down by it, would leave
    the effect's parameter to the noisy surge and sway rows (r_g.z 1 mm off at 1σ, which the
    unexplained-structure test then blamed on an effect outside the vocabulary)."""
    # the targets the fit was made to, Φθ − e: to rounding, which is all their floor reads
    _set_weights(ws, fit.e, fit.phi @ fit.theta - fit.e)
    return refit(ws, fit.vehicle, fit.unknowns)


def _set_weights(ws: Workspace, e: np.ndarray, y: np.ndarray) -> None:
    """Feasible weights of the residual ``e`` [N, 6] of the targets ``y`` [N, 6]: 1/σ̂²_dof,
    each σ̂² at least its :func:`feasible_floor` (kept in ``ws.variance_floor``, at which the
    fits floor each equation's RSS share): beside a DOF equation of exact data, weighted 3e26
    by its rounding, a noisy one's s.e. read 1e7 for 0.03. DOF equations the log does not
    measure get weight zero, and neither their residual nor their targets set a floor."""
    measured = ws.mask > 0
    var = np.where(measured, dof_variances(e), np.nan)
    ws.variance_floor = feasible_floor(var, np.where(measured, y, np.nan).reshape(-1), 6)
    ws.weights = ws.mask * feasible_weights(var, ws.variance_floor)


#: training runs below which :func:`run_stderr` gives nothing (its variance rests on them)
MIN_RUNS = 4


def run_stderr(ws: Workspace, fit: Fit) -> np.ndarray | None:
    """The run-clustered (sandwich) standard errors of the fit's unknowns: A⁻¹ (Σ_r g_r g_rᵀ)
    A⁻¹ · G/(G − 1), g_r the weighted score Σ φᵀ W e of training run r, A = Σ φᵀ W φ. On
    measured logs what differs run to run (ballast, a tether, contact) moves an estimate
    further than one residual's correlation time says: holding out other NTNU runs moved an
    added effect by 4-5 of its s.e. None with fewer than :data:`MIN_RUNS` training runs."""
    runs = ws.data["experiment"][ws.settled(ws.data)]
    groups = np.unique(runs)
    if groups.size < MIN_RUNS or runs.size != fit.phi.shape[0] or not fit.unknowns:
        return None
    phi, e = np.nan_to_num(fit.phi), np.nan_to_num(fit.e)
    a_inv = np.linalg.pinv(np.einsum("nkp,k,nkq->pq", phi, ws.weights, phi), hermitian=True)
    scores = np.einsum("nkp,k,nk->np", phi, ws.weights, e)
    g = np.stack([scores[runs == r].sum(0) for r in groups])
    cov = a_inv @ (g.T @ g) @ a_inv * groups.size / (groups.size - 1)
    return np.sqrt(np.maximum(np.diag(cov), 0.0))


def residual_correlation_time(e: np.ndarray, dofs: tuple[str, ...] = DOFS) -> float:
    """The correlation time of the analysed DOFs' residual columns of ``e`` [N, 6] (lags up to
    2000 samples): how many rows one independent sample is worth."""
    return correlation_time(e[:, [DOFS.index(d) for d in dofs]], max_lag=2000)


def screen(
    ws: Workspace,
    fit: Fit,
    cands: list[Candidate],
    cols: np.ndarray,
    cols_val: np.ndarray,
    excited: np.ndarray | None = None,
) -> list[Scored]:
    """Score linear candidates whose columns at the current fit are ``cols`` [N, 6, K] (and
    ``cols_val``): the exact joint refit of each with the fit's unknowns, in closed form.
    ``excited`` [K] (:meth:`CandidateExcitation.excited`; None: every column not zero): a
    candidate the data do not excite is said :data:`NOT_EXCITED`, and one whose column lies in
    the span of the fit's (:func:`identifiable`) :data:`NOT_IDENTIFIABLE`, and one whose
    column is not finite on the fit's rows :data:`NOT_FINITE`, each with nothing measured (no
    value, s.e., p-value or held-out gain). Every candidate comes back, scored or named."""
    w = ws.weights
    n, n_dof, p = fit.phi.shape
    # judged on the rows the refit reads: a column NaN only in an equation of weight 0 is not
    # NOT_FINITE (the refit leaves those entries out)
    cols, cols_val = _unread_zeroed(cols, w), _unread_zeroed(cols_val, w)
    # the weighted sums over samples and DOFs as matrix products on rows (n, d): BLAS, where
    # a three-operand einsum loops over every index (a sixth of a loop's time); p may be 0
    phi = fit.phi.reshape(n * n_dof, p)
    c = cols.reshape(n * n_dof, cols.shape[2])
    w_rows = np.tile(w, n)
    w_phi = phi * w_rows[:, None]
    a_mat = w_phi.T @ phi
    a_inv = np.linalg.pinv(a_mat, hermitian=True)
    s = (w_rows * np.nan_to_num(fit.e).reshape(-1)) @ c
    b = w_phi.T @ c
    q = w_rows @ (c * c)
    bb = a_inv @ b
    denom = q - np.einsum("pk,pk->k", b, bb)
    ok = denom > 1e-9 * np.maximum(q, 1e-300)
    if excited is None:  # a zero column is the zero-regressor rule's at least
        excited = q != 0
    # the augmented regression judged as the refit would judge it: a column in the span of
    # the fit's (Z:w*V beside Z:w*abs(w) of a heave run) scored p 0.9 and a value of 1.9e5
    judged = np.isfinite(denom) & excited
    beside = np.ones(len(cands), dtype=bool)
    if judged.any():
        beside[judged] = identifiable(a_mat, b[:, judged], q[judged], n * len(ws.dofs))
    denom = np.where(ok, denom, np.inf)
    theta = -s / denom
    drss = s**2 / denom
    rows = n * len(ws.dofs)
    sigma2 = np.maximum(fit.rss - drss, 1e-300) / max(rows - p - 1, 1)
    f_stat = drss / (sigma2 * ws.tau_corr)
    n_eff = max(rows / ws.tau_corr - p - 1, 1.0)
    p_val = f_dist.sf(f_stat, 1, n_eff)
    se = np.sqrt(sigma2 * ws.tau_corr / denom)
    # held-out residual after the joint refit: e_v + θ (c_v − Φ_b,v A⁻¹ b)
    delta = cols_val - fit.phi_val @ bb
    e_new = np.nan_to_num(fit.e_val)[:, :, None] + theta[None, None, :] * delta
    before = np.nansum(fit.e_val**2, axis=0)  # [6]
    after = np.sum(e_new**2, axis=0)  # [6, K]
    total = 1.0 - (w @ after) / float(w @ before)
    per_dof = 1.0 - after / np.where(before > 0, before, np.inf)[:, None]
    out = []
    nothing = float("nan")
    for k, cand in enumerate(cands):
        if not excited[k] or (judged[k] and not (beside[k] and ok[k])):
            alone = not excited[k]  # unexcited: never judged beside
            out.append(
                Scored(cand, nothing, nothing, nothing, nothing, nothing, {}, nothing,
                       reason=NOT_EXCITED if alone else NOT_IDENTIFIABLE,
                       excited=not alone, identifiable=alone)
            )  # fmt: skip
            continue
        if not judged[k]:
            # excited, but its sums over the fit's rows are not finite: nothing to judge it by.
            # Named, not dropped: a dropped candidate was neither in loop.json nor the report,
            # and a 1-D search whose pre-screen came back empty counted as tested
            out.append(
                Scored(cand, nothing, nothing, nothing, nothing, nothing, {}, nothing,
                       reason=NOT_FINITE, finite=False)
            )  # fmt: skip
            continue
        scale = cand.value_scale(fit.vehicle)
        value = cand.value(float(theta[k]), fit.vehicle)
        err = float(se[k] * abs(scale))
        refit_values = dict(zip(fit.unknowns, fit.theta - bb[:, k] * theta[k], strict=True))
        out.append(
            Scored(
                cand,
                value,
                err,
                float(p_val[k]),
                float(f_stat[k]),
                float(total[k]),
                {d: float(per_dof[i, k]) for i, d in enumerate(DOFS) if d in ws.dofs},
                float(100 * se[k] / abs(theta[k])) if theta[k] != 0 else float("inf"),
                refit=refit_values,
                drss=float(drss[k]),
                sigma2=float(sigma2[k]),
                delta=float(theta[k]),
                shift=bb[:, k].copy(),
            )
        )
    return out


def damping_block(ws: Workspace, vehicle, cands: list[Candidate], data: dict) -> np.ndarray:
    """Columns [N, 6, K] of damping candidates, built by the regression's own one-shot
    damping columns (−ξ_term(ν_r) in row F) and cut to its rows."""
    structure = ParametricFossen(vehicle, [c.parameter for c in cands])
    _, xi, rows = structure.damping_terms(data, ws.filter_lambda)
    xi = xi[ws.settled(data)]
    # filled in place: stacking K columns [N, 6] along a new last axis (a strided copy of
    # mostly zeros) and cutting the rows after took two thirds of this function's time
    block = np.zeros((xi.shape[0], 6, xi.shape[1]))
    block[:, rows, np.arange(xi.shape[1])] = -xi
    return block


def screen_linear(ws: Workspace, fit: Fit, cands: list[Candidate]) -> list[Scored]:
    """All linear candidates, damping ones from one basis evaluation, in chunks."""
    data, data_val = ws.arrays(fit.vehicle), ws.arrays(fit.vehicle, "val")
    damping = [c for c in cands if ":" in c.parameter]
    other = [c for c in cands if ":" not in c.parameter]
    excitation = CandidateExcitation(ws, fit, cands)
    out: list[Scored] = []
    for start in range(0, len(damping), _CHUNK):
        chunk = damping[start : start + _CHUNK]
        cols = damping_block(ws, fit.vehicle, chunk, data)
        cols_v = damping_block(ws, fit.vehicle, chunk, data_val)
        out += screen(ws, fit, chunk, cols, cols_v, excitation.excited(chunk, cols))
    if other:
        names = [c.parameter for c in other]
        cols = ws.columns(fit.vehicle, names, "train")
        cols_v = ws.columns(fit.vehicle, names, "val")
        out += screen(ws, fit, other, cols, cols_v, excitation.excited(other, cols))
    mark_aliases([s for s in out if s.scored])
    return out


#: why a 1-D search's s.e. was not measured where its range leaves no step about its value
#: (:func:`_linearised_stderr`)
NO_LINEARISED_STEP = "no step within the range searched to linearise its column over"
#: the verdict on a candidate whose column the data do not excite, in the refit's words
NOT_EXCITED = "not excited by this data (zero regressor): nothing of it is measured"
#: the verdict on a candidate whose column lies in the span of the fit's regressors
NOT_IDENTIFIABLE = (
    "not identifiable beside the model (its column lies in the span of the fitted "
    "regressors): nothing of it is measured"
)
#: the verdict on a candidate whose column (or its sums with the fit's) is NaN or infinite on
#: the rows the fit reads: the closed-form screen has nothing to judge it by
NOT_FINITE = (
    "not finite on the fit's rows (its column is NaN or infinite where the fit reads the "
    "data): nothing of it is measured"
)


def identifiable(a_mat: np.ndarray, b: np.ndarray, q: np.ndarray, n: int) -> np.ndarray:
    """Whether each candidate adds a direction to the fit's regression ``[K]``: the rank of
    the weighted Gram matrix with its column, [[A, b_k], [b_kᵀ, q_k]], above the fit's own
    (A ``[P, P]``, b ``[P, K]``, q ``[K]``; ``n`` rows), by the refit's rank rule
    (:func:`~nnid.evaluation.persistence.excitation_from_gram`: near-null directions of the
    unit-RMS-scaled matrix do not count), all candidates' matrices in one call
    (:func:`~nnid.evaluation.persistence.gram_ranks`). Only the rank is read: the columns were
    judged excited before (:class:`CandidateExcitation`, the fit's own refit), so every column
    passes its size rules here (unit sizes)."""
    p = a_mat.shape[0]
    gram = np.zeros((q.size, p + 1, p + 1))
    gram[:, :p, :p] = a_mat
    gram[:, :p, p] = gram[:, p, :p] = b.T
    gram[:, p, p] = q
    return gram_ranks(gram, n) > gram_ranks(a_mat[None], n)[0]


class CandidateExcitation:
    """Which linear candidates the data excite, each judged as the refit of the fit's unknowns
    with it would judge it (:func:`~nnid.trainers.least_squares.solve_regression`: within each
    analysed DOF equation beside the other columns, and against its own rounding floor sized
    over those equations; :func:`~nnid.evaluation.persistence.measured_columns`). What the
    check reads of the fit's own columns is made once a pass, each column's floor once a fit
    (:meth:`Workspace.reference_sizes`); :meth:`excited` judges a block of candidates. The
    closed-form screen has no such rule of its own: on a heave run whose surge is 1e-13 of it
    (rounding), analysed in heave, it scored Z:u = -2.2e8 ± 3.2e8 (p = 0.49) and Z:u|u| =
    -2.8e21 as if measured, where the refit leaves both out."""

    def __init__(self, ws: Workspace, fit: Fit, cands: list[Candidate]) -> None:
        n, _, p = fit.phi.shape
        self.ws, self.vehicle = ws, fit.vehicle
        self.phi = fit.phi.reshape(n * 6, p)
        # the rows the refit reads: finite, of an analysed DOF equation (weight > 0)
        self.rows = (np.tile(ws.weights, n) > 0) & np.isfinite(fit.e).reshape(-1)
        self.rows &= np.isfinite(self.phi).all(1)
        self.equations = np.flatnonzero(ws.weights > 0)  # the analysed DOF equations
        self._baseline(self.rows)
        # every candidate sized here at once (one damping basis evaluation for all of them)
        names = [*fit.unknowns, *(c.parameter for c in cands)]
        one, probe = ws.reference_sizes(fit.vehicle, names)
        self.sizes = (one[:p], probe[:, :p])

    def _baseline(self, rows: np.ndarray) -> None:
        """The fit's columns' RMS, typical size and RMS per DOF equation over ``rows``."""
        self.raw, self.size = rounding_scale(self.phi[rows])
        self.by_equation = equation_rms(self.phi, 6, rows)

    def _by_equation(self, cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """:func:`~nnid.evaluation.persistence.equation_rms` of ``cols`` [N, 6, K] over
        ``rows``, read in the analysed equations only (0 in the others, which no row keeps):
        beside three of six, the mask over all six cost more than the rest of the check."""
        k, eqs = cols.shape[2], self.equations
        block = cols if eqs.size == 6 else cols[:, eqs, :]
        out = np.zeros((6, k))
        kept = rows.reshape(-1, 6)[:, eqs].reshape(-1)
        out[eqs] = equation_rms(block.reshape(-1, k), eqs.size, kept)
        return out

    def excited(self, cands: list[Candidate], cols: np.ndarray) -> np.ndarray:
        """Whether each of ``cands`` (columns ``cols`` [N, 6, K] at the fit) is excited."""
        k = cols.shape[2]
        col = cols.reshape(-1, k)
        rows = self.rows
        c_eq = self._by_equation(cols, rows)
        if not np.isfinite(c_eq).all():  # the refit leaves out a candidate's NaN rows
            rows = rows & np.isfinite(col).all(1)
            self._baseline(rows)
            c_eq = self._by_equation(cols, rows)
        # each column's RMS over the rows, from its RMS in each equation and their counts
        count = rows.reshape(-1, 6).sum(0)
        c_raw = np.sqrt(count @ c_eq**2 / max(count.sum(), 1))

        def joined(base: np.ndarray, own: np.ndarray) -> np.ndarray:
            """The fit's ``base`` [..., P] with each candidate's ``own`` [..., K] as its last
            column: [K, ..., P + 1], a regression per candidate."""
            own = np.moveaxis(own, -1, 0)[..., None]
            return np.concatenate([np.broadcast_to(base, (k, *base.shape)), own], -1)

        one, probe = self.ws.reference_sizes(self.vehicle, [c.parameter for c in cands])
        floors = rounding_floors(joined(self.sizes[0], one), joined(self.sizes[1], probe))
        raw = joined(self.raw, c_raw)
        by_equation = joined(self.by_equation, c_eq)

        def verdict(reference: np.ndarray) -> np.ndarray:
            return measured_columns(raw, reference, floors, by_equation)[:, -1] & (c_raw > 0)

        # the typical size of the regression with a candidate in it is at least the fit's own,
        # and the verdict only falls as it grows: a candidate's own size (a median over its
        # rows) is needed only where the two ends disagree
        out = verdict(np.full(k, self.size))
        need = (out != verdict(np.full(k, np.inf))) | (self.size == 0)
        if need.any():
            reference = np.full(k, self.size)
            reference[need] = np.maximum(self.size, column_sizes(col[rows][:, need]))
            out[need] = verdict(reference)[need]
        if rows is not self.rows:
            self._baseline(self.rows)
        return out


#: relative agreement of two candidates' F-test sums and held-out gains that marks their
#: columns as one up to scale: a coincidence of both is far rarer than this
ALIAS_RTOL = 1e-8


def mark_aliases(scored: list[Scored]) -> None:
    """Fill each candidate's ``aliases`` with the others whose column on this log is the same
    up to scale (without u and v, V = |w| and Vw = w, so Z:abs(w)*V and Z:w*Vw are both w²): such
    candidates have the same F-test sum and held-out gain, and the data cannot tell them
    apart, so the one the loop names is one of several."""
    order = sorted(range(len(scored)), key=lambda i: scored[i].drss)
    for pos, i in enumerate(order):
        for j in order[pos + 1 :]:
            a, b = scored[i], scored[j]
            if not np.isclose(b.drss, a.drss, rtol=ALIAS_RTOL, atol=0.0):
                break
            if np.isclose(a.improvement, b.improvement, rtol=ALIAS_RTOL, atol=1e-12):
                a.aliases.append(b.name)
                b.aliases.append(a.name)


def sensitivity(ws: Workspace, vehicle, cand: Candidate, a: float, b: float) -> list[np.ndarray]:
    """dR/dv of the effect between values ``a`` and ``b`` with everything else held:
    columns [N, 6, 1] on the training and held-out parts."""
    cols = []
    for part in ("train", "val"):
        r = []
        for v in (a, b):
            veh = cand.augment(vehicle, v)
            data = ws.arrays(veh, part)
            _, r0 = _columns(veh, [], data, ws.filter_lambda, ws.nu_dot_f(part))
            r.append(r0)
        cols.append(((r[1] - r[0]) / (b - a))[:, :, None])
    return cols


def search_nonlinear(
    ws: Workspace, fit: Fit, cand: Candidate, prescreen_p: float = 1e-3
) -> Scored | None:
    """Bounded 1-D search of the effect value with the fit's unknowns refitted at each step;
    its standard error from the linearised column at the optimum (variable projection). None
    only where the search ran and found no better fit (a candidate tested), an optimum whose
    refit the vehicle refuses among them.

    The search is run only if the effect, linearised at its current value, already explains a
    significant part of the residual (``prescreen_p``); otherwise the linearised score is
    returned: the search costs dozens of refits, the pre-screen two residual evaluations."""
    lo, hi = cand.bounds
    v0 = cand.current_value(fit.vehicle)
    h = 0.02 * (hi - lo)
    a, b = (v0 - h / 2, v0 + h / 2) if lo < v0 - h / 2 else (v0, v0 + h)
    (pre,) = screen(ws, fit, [cand], *sensitivity(ws, fit.vehicle, cand, a, b))
    if not pre.scored:  # its linearised column measures nothing: named, not searched
        return pre
    if pre.p_value > prescreen_p:
        pre.value = v0 + (pre.value if np.isfinite(pre.value) else 0.0)
        return pre

    def model_at(value: float):
        return cand.augment(fit.vehicle, value)

    def rss(value: float) -> float:
        try:
            return refit(ws, model_at(value), fit.unknowns, held_out=False).rss
        except ValueError:
            return np.inf

    # a value the vehicle refuses (an installation coefficient ≤ 0 near a bound) scores inf:
    # Brent's parabola through it is NaN, and the method then takes a golden-section step
    with np.errstate(invalid="ignore"):
        res = minimize_scalar(
            rss,
            bounds=(lo, hi),
            method="bounded",
            options={"xatol": 1e-3 * (hi - lo), "maxiter": 30},
        )
    value = float(res.x)
    tol = 2e-3 * (hi - lo)  # twice the search's xatol
    edge = (
        f"the search ran out of its {res.nfev} evaluations"
        if not res.success
        else f"the {'upper' if value > (lo + hi) / 2 else 'lower'} edge of the range searched "
        f"({lo:.4g} to {hi:.4g})"
        # a bound of 0 (no lag, no deadband) is no effect, not a bound on one
        if hi - value <= tol or (lo < 0 and value - lo <= tol)
        else ""
    )
    try:
        best = refit(ws, model_at(value), fit.unknowns)
    except ValueError:
        # the vehicle refuses the optimum or its refit (out of the physical range), as it does
        # each value the search scores inf: no better fit found there, and said so, no crash
        return None
    if not best.rss < fit.rss:
        return None
    se, unmeasured = _linearised_stderr(ws, fit, best, cand, value)
    # the exact numbers of the refit at the optimum: measured whatever its s.e.
    drss = fit.rss - best.rss
    rows = best.e.shape[0] * len(ws.dofs)
    sigma2 = best.rss / max(rows - len(best.unknowns) - 1, 1)
    f_stat = drss / (sigma2 * ws.tau_corr)
    n_eff = max(rows / ws.tau_corr - len(best.unknowns) - 1, 1.0)
    before = np.nansum(fit.e_val**2, axis=0)
    after = np.nansum(best.e_val**2, axis=0)
    w = ws.weights
    return Scored(
        cand,
        value,
        se,
        float(f_dist.sf(f_stat, 1, n_eff)),
        float(f_stat),
        float(1.0 - (w @ after) / (w @ before)),
        {
            d: float(1.0 - after[i] / before[i]) if before[i] > 0 else 0.0
            for i, d in enumerate(DOFS)
            if d in ws.dofs
        },
        float(100 * se / abs(value)) if value != 0 else float("inf"),
        refit=dict(zip(best.unknowns, best.theta, strict=True)),
        drss=float(drss),
        sigma2=float(sigma2),
        residual=best.e,
        edge=edge,
        unmeasured=unmeasured,
    )


def refused_step(name: str, refused: float, value: float) -> str:
    """Why a 1-D search's s.e. was not measured where the vehicle refuses the effect ``name``
    at ``refused``, an end of the step about the optimum ``value`` that its column is
    linearised over (:func:`_linearised_stderr`): the optimum lies at the edge of the values
    the vehicle takes."""
    return (
        f"the vehicle refuses {name} = {refused:.4g}, an end of the step about {value:.4g} to "
        "linearise its column over (the optimum lies at the edge of the values it takes)"
    )


def _linearised_stderr(
    ws: Workspace, fit: Fit, best: Fit, cand: Candidate, value: float
) -> tuple[float, str]:
    """The standard error of a 1-D search's ``value`` (``best``: the refit there) from the
    effect's column linearised at it (variable projection), over a step of 1e-3 of the range
    kept inside it, and why none was measured ("" where one was). NaN (not measured) where
    that column measures nothing (its verdict: :data:`NOT_EXCITED`, :data:`NOT_IDENTIFIABLE`,
    :data:`NOT_FINITE`), or where no such step exists: a range narrower than about 1e-13 of
    its distance from 0 (or one that underflows) leaves value ± step rounded to ``value``.
    The vocabulary's ranges all hold 0 (:func:`~nnid.loop.effects.candidates`: ±reach, 0 to
    a lag or half a width), so a step is 1e-3 of at least ``|value|`` there; a Candidate
    built with such a range was searched and its better fit measured all the same. NaN too
    where the vehicle refuses an end of that step (:func:`refused_step`)."""
    lo, hi = cand.bounds  # type: ignore[misc]
    h = 1e-3 * (hi - lo)
    lo_v, hi_v = max(value - h, lo), min(value + h, hi)
    if not hi_v > lo_v:
        return float("nan"), NO_LINEARISED_STEP
    fitted = vehicle_with(fit.vehicle, dict(zip(best.unknowns, best.theta, strict=True)))
    for v in (lo_v, hi_v):
        # an optimum at the edge of the values the vehicle takes (a current it declares, plus
        # the effect's, at its bound) leaves a step end it refuses: a crash, the fit found lost
        try:
            cand.augment(fitted, v)
        except ValueError:
            return float("nan"), refused_step(cand.name, v, value)
    (at,) = screen(ws, best, [cand], *sensitivity(ws, fitted, cand, lo_v, hi_v))
    if not at.scored:
        # its verdict less "nothing of it is measured", which the caller says of the s.e.
        verdict = at.reason.removesuffix(": nothing of it is measured")
        return float("nan"), f"its column linearised at {value:.4g} is {verdict}"
    return at.stderr, ""


def rescore(ws: Workspace, fit: Fit, scored: list[Scored]) -> None:
    """Redo the F-test of ``scored`` with the autocorrelation time of each candidate's own
    residual (the model *with* the effect): the baseline's residual, dominated by a missing
    effect, is correlated over whole experiments, and its autocorrelation time would make
    every test of that very effect look insignificant."""
    scored = [s for s in scored if s.scored]  # nothing of the others is measured
    linear = [s for s in scored if s.candidate.linear]
    cols: dict[str, np.ndarray] = {}
    if linear:
        data = ws.arrays(fit.vehicle)
        damping = [s.candidate for s in linear if ":" in s.candidate.parameter]
        other = [s.candidate for s in linear if ":" not in s.candidate.parameter]
        if damping:
            block = damping_block(ws, fit.vehicle, damping, data)
            cols.update({c.name: block[:, :, k] for k, c in enumerate(damping)})
        if other:
            block = ws.columns(fit.vehicle, [c.parameter for c in other], "train")
            cols.update({c.name: block[:, :, k] for k, c in enumerate(other)})
    n, _, p = fit.phi.shape
    rows = n * len(ws.dofs)
    for s in scored:
        if s.residual is not None:
            e_new = s.residual
        elif s.candidate.name in cols:
            col = cols[s.candidate.name] - fit.phi @ s.shift
            e_new = np.nan_to_num(fit.e) + s.delta * col
        else:
            continue
        tau = residual_correlation_time(e_new, ws.dofs)
        s.f_stat = s.drss / (s.sigma2 * tau)
        s.p_value = float(f_dist.sf(s.f_stat, 1, max(rows / tau - p - 1, 1.0)))
        s.stderr *= float(np.sqrt(tau / ws.tau_corr))
        s.percentile_error *= float(np.sqrt(tau / ws.tau_corr))


def sindy_opinion(
    ws: Workspace,
    fit: Fit,
    scored: list[Scored],
    share: float = 0.05,
    top: int = 40,
    ridge: float = 0.1,
) -> list[str]:
    """pysindy STLSQ over the strongest linear candidates at once (columns made orthogonal to
    the fit's unknowns and scaled to unit weighted norm): the effects it keeps. The threshold
    asks a term to explain ``share`` of the weighted training residual on its own."""
    import pysindy as ps

    linear = (s for s in scored if s.candidate.linear and s.scored)
    lin = sorted(linear, key=lambda s: -s.improvement)[:top]
    if not lin:
        return []
    data = ws.arrays(fit.vehicle)
    damping = [s.candidate for s in lin if ":" in s.candidate.parameter]
    other = [s.candidate for s in lin if ":" not in s.candidate.parameter]
    blocks, order = [], []
    if damping:
        blocks.append(damping_block(ws, fit.vehicle, damping, data))
        order += damping
    if other:
        blocks.append(ws.columns(fit.vehicle, [c.parameter for c in other], "train"))
        order += other
    cols = _unread_zeroed(np.concatenate(blocks, 2), ws.weights)  # as :func:`screen` reads it
    sw = np.sqrt(ws.weights)
    n, _, p = fit.phi.shape
    x = (cols * sw[None, :, None]).reshape(n * 6, -1)
    base = (fit.phi * sw[None, :, None]).reshape(n * 6, p)
    target = -(np.nan_to_num(fit.e) * sw).reshape(-1)
    x = x - base @ np.linalg.lstsq(base, x, rcond=None)[0]
    norms = np.linalg.norm(x, axis=0)
    x = x / np.where(norms > 0, norms, 1.0)
    # ‖Rξ − b‖² differs from ‖xξ − y‖²/N by a constant: the same solutions, k rows not N
    r, b, _ = compress(x, target[:, None])
    threshold = np.sqrt(share) * np.linalg.norm(target)
    # a ridge of 0.1 (on unit-norm columns) keeps near-copies of one column (the library
    # holds many: w|w|, w V, |w| Vw, ...) from surviving as huge opposite coefficients
    opt = ps.STLSQ(threshold=threshold, alpha=ridge / target.size, max_iter=20)
    with warnings.catch_warnings():
        # "eliminated all coefficients" is an answer, not a fault
        warnings.filterwarnings("ignore", message=".*eliminated all coefficients.*")
        opt.fit(r, b)
    coef = np.ravel(opt.coef_)
    return [c.name for c, v in zip(order, coef, strict=True) if v != 0]


def simulation_forces(log: pd.DataFrame, vehicle, dofs: tuple[str, ...]) -> np.ndarray:
    """The nominal forces a simulation for the analysed ``dofs`` is driven by: the forces of
    the other DOFs are removed, since their velocities are not analysed (often not measured)
    and the vehicle file need not predict them (with B = W and the centres on one vertical,
    nothing else drives them, and the rotational equations are exact). Before the actuator
    lag, which the simulation integrates."""
    tau = nominal_forces(log, vehicle, lagged=False)
    tau[:, [k for k, d in enumerate(DOFS) if d not in dofs]] = 0.0
    return tau


def predict(vehicle, log: pd.DataFrame, mode, dofs: tuple[str, ...] = DOFS) -> pd.DataFrame:
    """Predicted states of ``vehicle`` on ``log`` (:func:`predict_states`, forces of the DOFs
    outside ``dofs`` removed)."""
    with np.errstate(all="ignore"):
        tau = simulation_forces(log, vehicle, dofs)
        parts = Parts.from_vehicle(vehicle)
        return predict_states(parts, log, tau, mode, lag=vehicle.actuator_lag)


def velocity_scores(
    vehicle, log: pd.DataFrame, mode, warmup_s: float, dofs: tuple[str, ...] = DOFS
) -> tuple[dict[str, float | None], dict[str, float]]:
    """Velocity NRMSE per excited DOF of ``dofs`` for a prediction ``mode`` ("free_run",
    "one_step" or k steps) and the mean ``total``, scored by the one rule of
    :func:`nnid.evaluation.evaluate.score_split`: None where the prediction diverged (not
    finite, or far outside the measured range), listed with the time it left. The first k
    samples of each run (1 for one step and free run) repeat the measurement
    (:func:`predict_states`) and are never scored, whatever ``warmup_s``: a 5 s-ahead score
    after a 2 s warm-up counted 3 s of each run's own measurement as perfect predictions."""
    pred = predict(vehicle, log, mode, dofs)
    present = [c for c in VELOCITY if c in log and c in dofs]
    nrmse_, _, diverged, _, _ = score_split(
        log, pred, excited_dofs(log, present), warmup_mask(log, warmup_s, mode_steps(mode)),
        lambda run: excited_dofs(run, present),
    )  # fmt: skip
    return nrmse_, diverged


def force_residual(ws: Workspace, vehicle, part: str = "val") -> np.ndarray:
    """R = M ν̇ − (τ_eff + b − Cν + τ_D − g) per sample ``[N, 6]`` with Savitzky-Golay
    accelerations, unfiltered: McCarter's τ̄ (eq. 4.4) minus the model's damping."""
    data = ws.arrays(vehicle, part)
    _, r0 = _columns(vehicle, [], data, None)
    return r0


def force_rmse(r: np.ndarray, tau: np.ndarray, dofs: tuple[str, ...]) -> dict[str, float]:
    """Force residual RMS per DOF of ``dofs`` (N, N m) for the residual ``r`` of the input
    forces ``tau``; ``total``: the mean over the DOFs with an input of the RMS divided by the
    RMS of that input force (forces and moments differ in units, so only the ratios can be
    averaged). A DOF's two RMS over one set of rows, those where its residual and its force
    are finite, as :func:`nnid.evaluation.evaluate.force_scores` takes J and J₀: over
    different rows the ratio would not be one of errors."""
    out, rel = {}, []
    for i, d in enumerate(DOFS):
        if d not in dofs:
            continue
        rows = np.isfinite(r[:, i]) & np.isfinite(tau[:, i])
        out[d] = rmse(np.zeros(rows.sum()), r[rows, i])
        if np.any(tau[rows, i]):  # on the rows the ratio reads: elsewhere it divides by 0
            rel.append(out[d] / rmse(np.zeros(rows.sum()), tau[rows, i]))
    out["total"] = exact_mean(rel) if rel else float("nan")
    return out


__all__ = [
    "CandidateExcitation",
    "Fit",
    "Scored",
    "Step",
    "Workspace",
    "damping_block",
    "force_residual",
    "force_rmse",
    "identifiable",
    "predict",
    "refit",
    "rescore",
    "residual_correlation_time",
    "screen",
    "screen_linear",
    "search_nonlinear",
    "sensitivity",
    "sindy_opinion",
    "velocity_scores",
]
