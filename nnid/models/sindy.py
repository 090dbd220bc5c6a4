"""Sparse identification of the viscous force (SINDy) over McCarter's basis library.

pysindy does the sparse regression (:class:`nnid.trainers.sindy.SparsePath`); this model supplies
the candidate functions and the targets. Two modes:

``mode="residual"`` (default)
    regress McCarter's residual force τ̄ = M ν̇ + C(ν)ν + g(η) − τ (eq. 4.4, see
    :func:`nnid.models.synthesis.residual_force`) on ξ(ν): τ̄ ≈ Θ ξ(ν), one sparse coefficient
    row per force ``X Y Z K M N``. The coefficients are the damping coefficients ``"F:term"`` of
    a vehicle file; the model predicts by flying the vehicle with that damping (a
    :class:`~nnid.models.synthesis.DampingModel`), and ``filter_lambda``/``zoh_midpoint`` choose
    the form of τ̄ as for the synthesis models.
``mode="control"``
    SINDy with control on the accelerations: ν̇ ≈ Ξ [ξ(ν), τ], the controls entering linearly
    (pysindy's convention of appending u to x before the library). Rigid-body, added-mass and
    Coriolis effects are absorbed by the coefficients (the Coriolis products are library terms);
    restoring forces are not in the library, so this mode suits trimmed, level runs. It predicts
    the velocities by integrating ν̇ = Ξ [ξ(ν), τ] (RK4, the input held over each sample; a
    vehicle file's actuator lag stepped exactly from the force commanded); its residual is the
    acceleration error.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import torch

from nnid.datasets.arrays import log_arrays, nominal_forces
from nnid.datasets.log import VELOCITY, typical_step
from nnid.datasets.preprocess import experiment_rows
from nnid.errors import NnidInputError
from nnid.evaluation.prediction import blank_initial, mode_steps
from nnid.models.base import AccelerationParts
from nnid.models.parametric import prepare_motion, warn_simulated
from nnid.models.synthesis import DampingModel, _at_zero, restored_matrices, restored_unidentified
from nnid.physics.damping_library import LIBRARY
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.integrate import rk4
from nnid.physics.parts import Parts, relative_velocity
from nnid.threads import blas_threads
from nnid.trainers.history import Progress
from nnid.trainers.sindy import MODES, BasisFeatureLibrary, SparsePath, path_j
from nnid.trainers.synthesis import masked_least_squares

ACCELERATION_OUTPUTS = tuple(f"d{d}" for d in DOFS)


class SindyDamping(DampingModel):
    """Sparse viscous-force identification with pysindy over the basis library.

    ``SindyDamping(vehicle).fit(log, validation)``: the threshold path is fitted on ``log`` and
    a model chosen on ``validation`` (without one, on the last ``holdout`` fraction of each
    experiment, then left out of the fit; ``selection="aic"`` or ``"bic"`` chooses on the
    training fit and takes no holdout: without validation data it fits the whole log, and the
    path has no validation J nor ``selected_["validation_nmse"]``): see
    :class:`nnid.trainers.sindy.SparsePath` for ``optimizer``, ``thresholds``, ``selection``,
    ``tolerance``, ``alpha``, ``per_output`` and ``seed``. ``path_`` lists every threshold
    tried, ``selected_`` the chosen entry (its ``validation_nmse`` per output: ``{"X": …}``,
    or ``{"du": …}`` in control mode), ``coefficients_`` the model as ``{"F:term": value}``
    (mode ``"control"``: ``{"du:term": value}`` and ``{"du:tau_X": value}``). Velocities and
    accelerations missing from a log are derived by Savitzky-Golay (``savgol_window`` s,
    ``savgol_order``).
    """

    kind = "sindy"

    def __init__(
        self,
        vehicle,
        optimizer: str = "stlsq",
        thresholds: Sequence[float] | None = None,
        selection: str = "validation",
        tolerance: float = 0.05,
        mode: str = "residual",
        terms: Sequence[str] | None = None,
        alpha: float = 1e-8,
        holdout: float = 0.2,
        per_output: bool = True,
        savgol_window: float = 1.0,
        savgol_order: int = 4,
        filter_lambda: float | None = None,
        zoh_midpoint: bool = False,
        seed: int = 0,
    ) -> None:
        self.vehicle = vehicle
        self.optimizer = optimizer
        self.thresholds = thresholds
        self.selection = selection
        self.tolerance = tolerance
        self.mode = mode
        self.terms = terms
        self.alpha = alpha
        self.holdout = holdout
        self.per_output = per_output
        self.savgol_window = savgol_window
        self.savgol_order = savgol_order
        self.filter_lambda = filter_lambda
        self.zoh_midpoint = zoh_midpoint
        self.seed = seed

    @property
    def seeded(self) -> bool:  # type: ignore[override]
        """Only library ensembling draws at random; STLSQ and SR3 are deterministic."""
        return self.optimizer == "ensemble"

    @property
    def validation_role(self) -> str | None:  # type: ignore[override]
        """The threshold is chosen on the validation log (with ``selection="validation"``;
        without one, on a holdout of the training log: no use of held-out data)."""
        return "model selection" if self.selection == "validation" else None

    @property
    def has_force_equation(self) -> bool:  # type: ignore[override]
        """Residual mode regresses a force; control mode an acceleration."""
        return self.mode == "residual"

    # -- data -----------------------------------------------------------------------------------
    def _terms(self) -> list[str]:
        return list(LIBRARY if self.terms is None else self.terms)

    def features(self, log: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        """Evaluated library ``[N, K]`` (with the six controls appended in control mode) and
        targets ``[N, 6]`` (τ̄, or ν̇ in control mode), row-aligned with the log (NaN where a
        value is undefined)."""
        theta, y, _ = self._regression(log)
        return theta, y

    def _regression(self, log: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`features` and the velocities ν ``[N, 6]`` the library's terms are of."""
        if self.mode == "residual":
            return self._library_data(log, self._terms())
        log = prepare_motion(log, DOFS, self.savgol_window, self.savgol_order, True)
        data = log_arrays(log, self.vehicle)
        theta = np.concatenate([self._basis(self._terms())(data["nu"]), data["tau"]], axis=1)
        return theta, data["nu_dot"], data["nu"]

    def arrays(self, log: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        """Library inputs ``x`` (ν_r, the velocity through the water the damping terms are of;
        ν and τ in control mode) and targets ``y`` (τ̄ or ν̇) of a log, rows with an undefined
        value dropped (for regressions outside the model). Not of the filtered form: its
        regressors F[ξ(ν_r)] are no function of the velocities at a sample (:meth:`features`
        gives them)."""
        if self.filtered:
            # F[τ̄] beside ξ(x) is not the regression the model fitted (F[τ̄] on F[ξ])
            raise NnidInputError(
                f"with filter_lambda = {self.filter_lambda:g} the regression's terms are "
                "filtered, F[ξ(ν_r)], no function of each sample's velocities: take the "
                "regression from features(log)",
                field="filter_lambda",
            )
        if self.mode == "residual":
            y, data = self.tau_bar(log)
            x = relative_velocity(Parts.from_vehicle(self.vehicle), data)
        else:
            log = prepare_motion(log, DOFS, self.savgol_window, self.savgol_order, True)
            data = log_arrays(log, self.vehicle)
            x, y = np.concatenate([data["nu"], data["tau"]], axis=1), data["nu_dot"]
        ok = np.isfinite(x).all(1) & np.isfinite(y).all(1)
        return x[ok], y[ok]

    def _split(self, log: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
        train, val = [], []
        for _, pos in experiment_rows(log):
            g = log.iloc[pos]
            cut = round(len(g) * (1.0 - self.holdout))
            train.append(g.iloc[:cut])
            val.append(g.iloc[cut:])
        return pd.concat(train), pd.concat(val)

    @property
    def filtered(self) -> bool:
        """Only residual mode filters; control mode regresses Savitzky-Golay accelerations."""
        return self.mode == "residual" and self.filter_lambda is not None

    def acceleration_parts(self, members_scored: bool = False) -> AccelerationParts | None:
        """Control mode's regression targets are the six accelerations, in the parts it fits
        (training, and validation for the selection); residual mode's are τ̄'s."""
        if self.mode == "control":
            parts = ("train", "validation")
            return AccelerationParts(parts, DOFS, self.savgol_window, self.savgol_order)
        return super().acceleration_parts(members_scored)

    @property
    def output_names(self) -> list[str]:
        """Names of the regression's outputs: forces, or accelerations in control mode."""
        return list(FORCES) if self.mode == "residual" else list(ACCELERATION_OUTPUTS)

    # -- fitting --------------------------------------------------------------------------------
    def _fit(self, log: pd.DataFrame, validation, progress: Progress) -> None:
        # one BLAS thread (nnid.threads says why): this fit on 6,000 rows took 8.2-12.4 s of
        # CPU with OpenBLAS's default 2 threads on 2 cores against 1.6-1.9 s with one (2 runs
        # each, load 4-7, 2026-11-30), its coefficients up to 2e-13 (relative) apart
        with blas_threads(1):
            self._sparse_fit(log, validation, progress)

    def _sparse_fit(self, log: pd.DataFrame, validation, progress: Progress) -> None:
        if self.mode not in MODES:
            raise NnidInputError(f"mode is one of {', '.join(MODES)}", field="mode")
        if validation is None and self.selection == "validation":
            log, validation = self._split(log)
        # AIC and BIC choose on the training fit: without validation data the whole log is
        # fitted (a holdout took the last `holdout` of each run from the fit and said nothing)
        theta, y, nu = self._regression(log)
        ok = self._defined(log, theta, y, "training")
        theta_v = y_v = None
        if validation is not None:
            theta_v, y_v = self.features(validation)
            ok_v = self._defined(validation, theta_v, y_v, "validation")
            theta_v, y_v = theta_v[ok_v], y_v[ok_v]
        self._warn_held(log, "the SINDy fit")
        # forces and moments (linear and angular accelerations) are each judged rounding within
        # their own kind, a kind put in the other's units by the vehicle's length where its
        # file gives one, else a metre (as the Fossen regression's rounding floors); each
        # library column against itself at the log's typical motion, to its power
        k = len(self._terms())
        floors = self._floors(nu[ok], self._terms(), theta[ok][:, k:])
        path = SparsePath(
            self.optimizer,
            self.thresholds,
            self.selection,
            self.tolerance,
            self.alpha,
            self.per_output,
            self.seed,
            self.output_names,
            self._to_linear(),
        ).fit(theta[ok], y[ok], theta_v, y_v, floors)
        progress(1, 1, f"SINDy path of {len(path.path_)} thresholds")
        self.path_ = path.path_
        self.selected_ = path.selected_
        if "validation_nmse" in self.selected_:
            self.selected_["validation_nmse"] = dict(
                zip(self.output_names, self.selected_["validation_nmse"], strict=True)
            )
        terms = self._terms()
        names = terms + (list(f"tau_{f}" for f in FORCES) if self.mode == "control" else [])
        self.feature_names_ = names
        # the debiased coefficients are the least squares of each output on its selected terms:
        # that regression's standard errors (widened for correlated residuals), with its
        # warnings when the support is collinear or a term unexcited. They are conditional on
        # the support and leave out the uncertainty of the selection itself.
        support = masked_least_squares(
            theta[ok], y[ok], path.coef_ != 0, names, self.output_names, floors
        )
        coef, unidentified = path.coef_, None
        if self.mode == "residual":
            # a selected term the debiasing finds unexcited (a zero regressor) has no estimate:
            # the sparse regression's value would be simulated without a standard error. It is
            # held at 0 and named unidentified, as the synthesis model's (McCarter eq. 4.6);
            # control mode's ν̇ model keeps no such marks, and keeps the value
            unidentified = support.unidentified & (path.coef_ != 0)
            coef = np.where(unidentified, 0.0, path.coef_)
        self.coefficients_ = {
            f"{out}:{names[j]}": float(coef[i, j])
            for i, out in enumerate(self.output_names)
            for j in np.flatnonzero(coef[i])
        }
        self._set_model(terms, coef, support.stderr, unidentified)
        if unidentified is not None:
            warn_simulated(dict.fromkeys(self._unidentified_names()), stacklevel=3, at=_at_zero)

    def _set_model(
        self,
        terms: list[str],
        coef: np.ndarray,
        stderr: np.ndarray,
        unidentified: np.ndarray | None = None,
    ) -> None:
        """The fitted state; ``unidentified`` (residual mode): the entries of K held at 0."""
        if self.mode == "residual":
            self._set_damping(terms, coef, stderr, unidentified)
            return
        self.terms_ = list(terms)
        self.coef_ = np.asarray(coef, dtype=np.float64)
        self.stderr_ = np.asarray(stderr, dtype=np.float64)
        self.dofs_ = DOFS
        self.outputs_ = list(VELOCITY)
        self.targets_ = list(VELOCITY)
        self.warmup_samples_ = 1
        self.unidentified_ = np.zeros(self.coef_.shape, dtype=bool)  # K of ν̇: none kept

    def trainer_name(self) -> str:
        return f"pysindy {self.optimizer}"

    # -- use ------------------------------------------------------------------------------------
    def selected_terms(self) -> set[str]:
        """The selected ``"F:term"`` keys."""
        return set(self.coefficients_)

    def _n_params(self) -> int:
        return int(np.count_nonzero(self.coef_))

    def _params(self) -> dict[str, dict[str, float | None]]:
        if self.mode == "residual":
            return super()._params()
        names = self.feature_names_
        out: dict[str, dict[str, float | None]] = {}
        for i, j in zip(*np.nonzero(self.coef_), strict=True):
            s = self.stderr_[i, j]
            out[f"{self.output_names[i]}:{names[j]}"] = {
                "value": float(self.coef_[i, j]),
                "stderr": float(s) if np.isfinite(s) else None,
            }
        return out

    def predict_arrays(self, x: np.ndarray) -> np.ndarray:
        """The model's output (τ_D or ν̇) ``[N, 6]`` for library inputs ``x`` ``[N, 6 (+6)]``."""
        library = BasisFeatureLibrary(self.terms_, self.vehicle.damping.u_c).fit(x)
        return np.asarray(library.transform(x)) @ self.coef_.T

    def regression_error(self, log: pd.DataFrame) -> float:
        """The path's J on a log (:func:`~nnid.trainers.sindy.path_j`): the mean normalised
        MSE of the regression's outputs that have something to explain there (an output still
        on the log, its target rounding, has no NMSE), on the regression the path scored
        (:meth:`features`: F[τ̄] on F[ξ] with ``filter_lambda``)."""
        theta, y = self.features(log)
        ok = np.isfinite(theta).all(1) & np.isfinite(y).all(1)
        return path_j(y[ok], theta[ok] @ self.coef_.T, self._to_linear())

    def _to_linear(self) -> float:
        """The factor that puts the regression's angular kind in its linear one's units (the
        rounding rule judges each target within its kind): one over the vehicle's length for
        moments (residual mode), the length for angular accelerations (control mode)."""
        length = self.vehicle.rounding_length
        return 1.0 / length if self.mode == "residual" else length

    def _accelerations(self, nu: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
        """ν̇ = Ξ [ξ(ν), τ] of control mode (torch, batched)."""
        coef = torch.as_tensor(self.coef_)
        return torch.cat([self._basis(self.terms_)(nu), tau], -1) @ coef.T

    def _state_rate(self, x: torch.Tensor, tau: torch.Tensor) -> torch.Tensor:
        """ẋ of the predicted state: ν̇ (:meth:`_accelerations`), and with an actuator lag a
        zero rate for the lagged force that follows ν (:func:`~nnid.physics.integrate.rk4`
        steps it by its exponential)."""
        if x.shape[-1] == 6:
            return self._accelerations(x, tau)
        nu, lagged = x[..., :6], x[..., 6:]
        return torch.cat([self._accelerations(nu, lagged), torch.zeros_like(lagged)], -1)

    def _predict(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        if self.mode == "residual":
            return super()._predict(log, mode)
        log = prepare_motion(log, DOFS, self.savgol_window, self.savgol_order, False)
        data = log_arrays(log, self.vehicle)
        lag = float(self.vehicle.actuator_lag)
        # with a lag the state is [ν, a], a the lagged force started from its value at the
        # sample, stepped exactly from the force commanded (as predict_states steps it):
        # holding a's samples delays the force by half a sample (free-run NRMSE 0.06-0.18 of
        # a fit on noise-free data against 0.01-0.02)
        state = data["nu"] if lag <= 0 else np.concatenate([data["nu"], data["tau"]], 1)
        drive = data["tau"] if lag <= 0 else nominal_forces(log, self.vehicle, lagged=False)
        out = np.full((len(log), 6), np.nan)
        k = mode_steps(mode)
        for _, pos in experiment_rows(log):
            dt = typical_step(log["t"].to_numpy(np.float64)[pos], np.nan)
            x = torch.as_tensor(state[pos])
            tau = torch.as_tensor(drive[pos])
            with torch.no_grad():
                if mode == "free_run":
                    run = rk4(self._state_rate, x[:1], tau[:-1, None], dt, lag=lag)
                    out[pos] = run[:, 0, :6].numpy()
                elif pos.size > k:
                    n = pos.size - k
                    windows = torch.stack([tau[j : j + n] for j in range(k)], 0)
                    run = rk4(self._state_rate, x[:n], windows, dt, lag=lag)
                    out[pos[k:]] = run[-1, :, :6].numpy()
        pred = pd.DataFrame(out, columns=list(VELOCITY), index=log.index)
        return blank_initial(pred, log, self.warmup_samples_ + k - 1)

    def _residual(self, log: pd.DataFrame) -> pd.DataFrame:
        """τ̄ − Θ ξ(ν) (residual mode), or ν̇ − Ξ [ξ(ν), τ] (control mode, columns du … dr)."""
        if self.mode == "residual":
            return super()._residual(log)
        theta, y = self.features(log)
        return pd.DataFrame(
            y - theta @ self.coef_.T, columns=list(ACCELERATION_OUTPUTS), index=log.index
        )

    def _state(self) -> tuple[dict, dict]:
        state, tensors = super()._state()
        return {
            **state,
            "coefficients": self.coefficients_,
            "path": self.path_,
            "selected": self.selected_,
            "feature_names": self.feature_names_,
        }, tensors

    def _restore(self, state: dict, tensors: dict) -> None:
        if self.mode not in MODES:  # any other value predicted as control mode
            raise ValueError(f"mode is one of {', '.join(MODES)}, not {self.mode!r}")
        extra = 0 if self.mode == "residual" else len(FORCES)
        terms, coef, stderr = restored_matrices(state, extra, stderr_default=True)
        unidentified = (
            restored_unidentified(state, terms, coef, stderr) if self.mode == "residual" else None
        )
        self._set_model(terms, coef, stderr, unidentified)
        self.coefficients_ = dict(state["coefficients"])
        self.path_ = list(state["path"])
        self.selected_ = dict(state["selected"])
        self.feature_names_ = list(state["feature_names"])
