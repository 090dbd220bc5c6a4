"""McCarter's viscous-model synthesis as models (ch. 4, eqs 4.4-4.27).

The residual force τ̄ = M ν̇ + C(ν)ν − g(η) − τ (eq. 4.4) is the viscous force a log shows once
the rigid body, added mass, restoring forces and actuation are taken out; a damping model
K ξ(ν) over the basis library (eq. 4.6) is fitted to it. :class:`DampingModel` is what every
such model shares: its residual is τ̄ − K ξ(ν) (McCarter's force error, so J and J₀ of eq. 4.25
come from the protocol's ``residual`` and ``force_series``), and it predicts by flying the
vehicle file with its damping replaced by K inside the Fossen simulator.
:class:`SynthesisModel` fits a named mask by least squares (eq. 4.22) or Nelder-Mead on the
costs of eqs 4.23-4.27 (:mod:`nnid.trainers.synthesis`); :class:`nnid.models.sindy.SindyDamping`
chooses the terms by sparse regression.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Literal

import numpy as np
import pandas as pd

from nnid.datasets.arrays import log_arrays
from nnid.datasets.log import ACCELERATION
from nnid.datasets.preprocess import run_spans, zoh_midpoint_inputs
from nnid.datasets.splits import PARTS
from nnid.errors import NnidInputError
from nnid.evaluation.persistence import library_floors
from nnid.models.base import AccelerationParts
from nnid.models.parametric import (
    FossenPlant,
    ParametricFossen,
    equation_columns,
    filter_settled,
    filter_signal,
    prepare_motion,
    warn_held_inputs,
    warn_simulated,
    with_simulated_at,
)
from nnid.physics.damping_library import BasisLibrary
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.parts import Parts, relative_velocity
from nnid.trainers.history import Progress
from nnid.trainers.synthesis import (
    LOSSES,
    force_error,
    mask_matrix,
    mask_term_list,
    masked_least_squares,
    nelder_mead,
)


def residual_force(
    vehicle,
    log: pd.DataFrame,
    savgol_window: float = 1.0,
    savgol_order: int = 4,
    filter_lambda: float | None = None,
    zoh_midpoint: bool = False,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """McCarter's residual force τ̄ (eq. 4.4) ``[N, 6]`` and the log's arrays (η, ν, ν̇, τ).

    Velocities and accelerations missing from the log are derived by Savitzky-Golay
    (:func:`nnid.models.parametric.prepare_motion`) and τ̄ is
    :meth:`ParametricFossen.damping_force` (the
    vehicle's declared damping is left out of it). With ``filter_lambda`` = λ it is instead the
    filtered residual F[τ̄], F(s) = λ/(s + λ), with M F[ν̇] computed as M sF(s)[ν] (the
    filtered-regressor form of :meth:`ParametricFossen.equation_residual`): no differentiated
    acceleration, and the regressors must then be filtered alike (:func:`synthesis_data`). The
    first 3/λ s of each experiment, where the filters settle, are NaN.

    ``zoh_midpoint`` takes the inputs as held over each sample (zero-order hold, as logged
    commands are) and uses at t_k the mean (τ_{k−1} + τ_k)/2 of the force held before and after
    it, which is what a smoothed or filtered acceleration at t_k sees; without it a fast
    autopilot's held force leaves a half-sample lag that biases the damping by several %.
    """
    held = zoh_midpoint and vehicle.actuator_lag == 0  # a lagged force is continuous already
    # the accelerations are cut at the steps of the inputs as logged, before their midpoint
    log = prepare_motion(
        log, DOFS, savgol_window, savgol_order, filter_lambda is None, cut_at_steps=held
    )
    if held:
        log = zoh_midpoint_inputs(log)
    data = log_arrays(log, vehicle)
    structure = ParametricFossen(vehicle, [])
    if filter_lambda is None:
        return structure.damping_force(data), data
    parts = structure.base.copy()
    parts.damping = {}
    tau_bar = structure.equation_residual(parts, data, filter_lambda)
    tau_bar[~filter_settled(data, filter_lambda)] = np.nan
    return tau_bar, data


def synthesis_data(
    vehicle,
    log: pd.DataFrame,
    library: BasisLibrary,
    savgol_window: float = 1.0,
    savgol_order: int = 4,
    filter_lambda: float | None = None,
    zoh_midpoint: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The basis terms ξ(ν_r) ``[N, n_terms]`` and τ̄ ``[N, 6]`` of a log, both through F(s)
    when ``filter_lambda`` is given, so that τ̄ = K ξ holds on either form (eq. 4.6), and the
    velocities through the water ν_r ``[N, 6]`` the terms are of (unfiltered: the motion a
    term is judged beside, :func:`~nnid.evaluation.persistence.library_floors`). ν_r = ν − ν_c
    in the vehicle file's current (:func:`~nnid.physics.parts.relative_velocity`), ν in
    still water."""
    tau_bar, data = residual_force(
        vehicle, log, savgol_window, savgol_order, filter_lambda, zoh_midpoint
    )
    # τ̄ leaves out τ_D(ν_r), what the fitted plant flies: ξ of the logged ν in a current
    # biased K (a 0.3 m/s current took X:u*abs(u) of the Seamor from −61 to −28)
    nu = relative_velocity(Parts.from_vehicle(vehicle), data)
    xi = library(nu)
    if filter_lambda is not None:
        xi = filter_signal(data, xi, filter_lambda)
        xi[~np.isfinite(tau_bar).all(1)] = np.nan
    return xi, tau_bar, nu


def restored_matrices(
    state: dict, extra: int, stderr_default: bool = False
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """The basis terms, K and its standard errors of a saved damping model, checked: terms
    that parse (:class:`BasisLibrary`), K and its standard errors ``[6, len(terms) + extra]``
    (``extra``: SINDy control mode's six force columns). A file edited by hand loaded and
    failed at the first prediction or ``describe()``; it is refused at loading."""
    terms = list(state["terms"])
    BasisLibrary(terms)  # raises ValueError on a term that is not one
    shape = (6, len(terms) + extra)
    coef = np.array(state["coef"], dtype=float)
    stderr = (
        np.array(state["stderr"], dtype=float)
        if "stderr" in state or not stderr_default
        else np.full(shape, np.nan)
    )
    for name, values in (("coef", coef), ("stderr", stderr)):
        if values.size != shape[0] * shape[1]:
            raise ValueError(f"{name} has {values.size} values, not 6 × {shape[1]}")
    return terms, coef.reshape(shape), stderr.reshape(shape)


#: the saved state's key of a damping model's unidentified coefficients (absent from files
#: saved before they were kept: a synthesis model's are told from K there,
#: :func:`older_unidentified`)
UNIDENTIFIED = "unidentified"


def older_unidentified(structure: np.ndarray, coef: np.ndarray, stderr: np.ndarray) -> np.ndarray:
    """The unidentified entries of a synthesis model's K in a file saved before they were
    kept (:data:`UNIDENTIFIED`): the entries of its ``structure`` (the mask) at exactly 0
    with no standard error. Masked least squares has always left an unidentified term so (its
    NaN estimate at 0, no standard error), and no estimate is exactly 0 (least squares on a
    column the data excite, or a Nelder-Mead search started from it), so the file tells them
    apart. What it cannot tell: a Nelder-Mead search of that time could move an unidentified
    term off 0 (no cost read it, and the search was not yet held there); such a value is
    shown as saved."""
    return structure & (coef == 0) & ~np.isfinite(stderr)


def restored_unidentified(
    state: Mapping, terms: Sequence[str], coef: np.ndarray, stderr: np.ndarray
) -> np.ndarray:
    """The unidentified entries of K ``[6, len(terms)]`` a saved damping model names under
    :data:`UNIDENTIFIED` (``"F:term"`` keys, as its params), checked: each an entry of K that
    holds 0 without a standard error, as a fit leaves one; none for an older file."""
    out = np.zeros(coef.shape, dtype=bool)
    names = state.get(UNIDENTIFIED, [])
    if not isinstance(names, list):
        raise TypeError(f"'{UNIDENTIFIED}' is not a list of coefficients: {names!r}")
    index = {f"{FORCES[f]}:{t}": (f, j) for f in range(6) for j, t in enumerate(terms)}
    for name in names:
        if name not in index:
            raise ValueError(f"'{UNIDENTIFIED}' names {name!r}, which is no entry of K")
        f, j = index[name]
        if coef[f, j] != 0 or np.isfinite(stderr[f, j]):
            raise ValueError(
                f"'{UNIDENTIFIED}' names {name!r}, which has a value {coef[f, j]!r} or a "
                "standard error: an unidentified coefficient has neither (it is simulated at 0)"
            )
        out[f, j] = True
    return out


class DampingModel(FossenPlant):
    """A viscous damping model K ξ(ν) over basis terms, fitted to McCarter's τ̄.

    Subclasses store ``vehicle``, ``savgol_window``, ``savgol_order``, ``filter_lambda`` and
    ``zoh_midpoint`` (the form of τ̄, :func:`residual_force`) and call :meth:`_set_damping`
    with the fitted terms, coefficient matrix and standard errors."""

    def motion_columns(self, columns: Iterable[str]) -> list[str]:
        """τ̄ and ξ(ν)'s columns (eq. 4.4): a regression on the Fossen equation's
        (:func:`~nnid.models.parametric.equation_columns`)."""
        return equation_columns(columns)

    def _xi_tau(self, log: pd.DataFrame, terms: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
        return self._library_data(log, terms)[:2]

    def _library_data(
        self, log: pd.DataFrame, terms: Sequence[str]
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """ξ(ν), τ̄ and ν of a log (:func:`synthesis_data`) in this model's form."""
        return synthesis_data(
            self.vehicle,
            log,
            self._basis(terms),
            self.savgol_window,
            self.savgol_order,
            self.filter_lambda,
            self.zoh_midpoint,
        )

    def _basis(self, terms: Sequence[str]) -> BasisLibrary:
        """The basis library of ``terms`` at the vehicle file's current speed u_c."""
        return BasisLibrary(terms, self.vehicle.damping.u_c or 0.0)

    def _floors(
        self, nu: np.ndarray, terms: Sequence[str], inputs: np.ndarray | None = None
    ) -> np.ndarray:
        """Each term's floor of the rounding rule on the velocities ``nu`` ``[N, 6]`` the fit
        reads, then of the ``inputs`` appended
        (:func:`~nnid.evaluation.persistence.library_floors`, angular rates over the vehicle's
        length where its file gives one, else a metre)."""
        return library_floors(nu, self._basis(terms), self.vehicle.rounding_length, inputs)

    @property
    def filtered(self) -> bool:
        """Whether the regression's rows go through F(s) = λ/(s + λ) (``filter_lambda``)."""
        return self.filter_lambda is not None

    def acceleration_parts(self, members_scored: bool = False) -> AccelerationParts | None:
        """τ̄ (:func:`residual_force`) reads all six accelerations, in every part its residual
        is scored; none in the filtered form."""
        if self.filtered:
            return None
        return AccelerationParts(PARTS, DOFS, self.savgol_window, self.savgol_order)

    def _defined(
        self, log: pd.DataFrame, theta: np.ndarray, y: np.ndarray, what: str
    ) -> np.ndarray:
        """The rows of a regression on ``log`` (``what``: "training" or "validation") where
        every feature and target is defined; none is a clear error, not an empty fit: the
        Savitzky-Golay window, or the filter's first 3/λ s, take each experiment's ends."""
        ok = np.isfinite(theta).all(1) & np.isfinite(y).all(1)
        if ok.any():
            return ok
        longest = max(run_spans(log), default=0.0)
        if self.filtered:
            field = "filter_lambda"
            settle = 3.0 / self.filter_lambda
            cause = f"the filter λ/(s + λ) settles over the first 3/λ = {settle:g} s"
            knob = "a larger filter_lambda"
        else:
            field = "savgol_window"
            cause = f"the Savitzky-Golay window ({self.savgol_window:g} s) takes its two ends"
            knob = "a shorter savgol_window"
        raise NnidInputError(
            f"the {what} data leave no sample with every term and target defined: their longest "
            f"experiment lasts {longest:.3g} s, and {cause} of each; give longer {what} "
            f"experiments or {knob}",
            field=field,
        )

    def _warn_held(self, log: pd.DataFrame, fit: str) -> None:
        """:func:`~nnid.models.parametric.warn_held_inputs` for this fit's τ̄: its
        acceleration is smoothed unless the log has every one and no filter is set."""
        if not self.zoh_midpoint:
            smoothed = self.filtered or not all(a in log for a in ACCELERATION)
            warn_held_inputs(log, fit, smoothed, self.vehicle.actuator_lag, stacklevel=5)

    def _set_damping(
        self,
        terms: Sequence[str],
        coef: np.ndarray,
        stderr: np.ndarray,
        unidentified: np.ndarray | None = None,
    ) -> None:
        """The fitted state: K ``[6, len(terms)]`` and its standard errors (NaN where none),
        the entries the fit left unidentified (``unidentified``: K holds 0 there, no
        estimate), and the plant (the vehicle file with its damping replaced by K)."""
        self.terms_ = list(terms)
        self.coef_ = np.asarray(coef, dtype=np.float64)
        self.stderr_ = np.asarray(stderr, dtype=np.float64)
        self.unidentified_ = (
            np.zeros(self.coef_.shape, dtype=bool)
            if unidentified is None
            else np.asarray(unidentified, dtype=bool)
        )
        self.parts_ = Parts.from_vehicle(self.vehicle)
        self.parts_.damping = {
            f"{FORCES[f]}:{self.terms_[j]}": float(self.coef_[f, j])
            for f, j in zip(*np.nonzero(self.coef_), strict=True)
        }
        self._set_outputs(DOFS)

    def _residual(self, log: pd.DataFrame) -> pd.DataFrame:
        """τ̄ − K ξ(ν) (McCarter's σ̃, eq. 4.20), NaN where τ̄ is undefined (filter settling)."""
        xi, tau_bar = self._xi_tau(log, self.terms_)
        return pd.DataFrame(tau_bar - xi @ self.coef_.T, columns=list(FORCES), index=log.index)

    def tau_bar(self, log: pd.DataFrame) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """McCarter's τ̄ in this model's form, and the log's arrays (:func:`residual_force`)."""
        return residual_force(
            self.vehicle,
            log,
            self.savgol_window,
            self.savgol_order,
            self.filter_lambda,
            self.zoh_midpoint,
        )

    def _force_series(self, log: pd.DataFrame) -> pd.DataFrame:
        """τ̄ (eq. 4.4): what the damping model must explain."""
        return pd.DataFrame(self.tau_bar(log)[0], columns=list(FORCES), index=log.index)

    def predict_force(self, log: pd.DataFrame) -> pd.DataFrame:
        """τ̂ = K ξ(ν) (eq. 4.6) per sample, columns X Y Z K M N, on the log's index."""
        xi, _ = self._xi_tau(log, self.terms_)
        return pd.DataFrame(xi @ self.coef_.T, columns=list(FORCES), index=log.index)

    def error(self, log: pd.DataFrame, per_force: bool = False):
        """(J, J₀) of eq. 4.25 on a log (see :func:`nnid.trainers.synthesis.force_error`)."""
        xi, tau_bar = self._xi_tau(log, self.terms_)
        return force_error(tau_bar, xi @ self.coef_.T, per_force)

    def coefficient_matrix(self) -> np.ndarray:
        """K ``[6, len(terms_)]`` (zero off the structure)."""
        return self.coef_.copy()

    def _params(self) -> dict[str, dict[str, float | None]]:
        out: dict[str, dict[str, float | None]] = {}
        for f, j in zip(*np.nonzero(self._structure() | self.unidentified_), strict=True):
            s = self.stderr_[f, j]
            out[f"{FORCES[f]}:{self.terms_[j]}"] = {
                # an unidentified coefficient's 0 is no estimate: null, and simulated_at says 0
                "value": None if self.unidentified_[f, j] else float(self.coef_[f, j]),
                "stderr": float(s) if np.isfinite(s) else None,
            }
        return with_simulated_at(out, dict.fromkeys(self._unidentified_names()))

    def _unidentified_names(self) -> list[str]:
        """The ``"F:term"`` names of the coefficients the fit left unidentified."""
        return self._entry_names(self.unidentified_)

    def _entry_names(self, entries: np.ndarray) -> list[str]:
        """The ``"F:term"`` names (those of params) of the True ``entries`` of a K-shaped mask."""
        return [f"{FORCES[f]}:{self.terms_[j]}" for f, j in zip(*np.nonzero(entries), strict=True)]

    def _structure(self) -> np.ndarray:
        """Which entries of K are parameters of the model."""
        return self.coef_ != 0

    def _state(self) -> tuple[dict, dict]:
        state = {"terms": self.terms_, "coef": self.coef_, "stderr": self.stderr_}
        return {**state, UNIDENTIFIED: self._unidentified_names()}, {}

    def _restore(self, state: dict, tensors: dict) -> None:
        terms, coef, stderr = restored_matrices(state, extra=0)
        self._set_damping(terms, coef, stderr, restored_unidentified(state, terms, coef, stderr))
        # a mask setting edited by hand: refused here, not by describe()
        stray = self.unidentified_ & ~self._structure()
        if stray.any():  # a fit leaves unidentified only terms of its structure (the mask)
            raise ValueError(
                f"'{UNIDENTIFIED}' names {self._entry_names(stray)}, which are not terms of the "
                "model"
            )


def _at_zero(_: float | None) -> str:
    """Where a damping model simulates an unidentified coefficient (:func:`warn_simulated`)."""
    return "at 0 (K replaces the vehicle file's damping wholesale, McCarter eq. 4.6)"


class SynthesisModel(DampingModel):
    """A masked viscous model K ξ(ν) fitted to McCarter's τ̄.

    ``SynthesisModel(vehicle, mask="mcfarland", method="ls")`` then ``fit(log)``; ``mask`` is a
    named model of the basis library (McCarter's M_k, eq. 4.15) or ``{force: [terms]}``;
    ``method`` is ``"ls"`` (eq. 4.22) or a Nelder-Mead cost ``"mae" | "mse" | "rms" | "mad"``
    (eqs 4.23-4.27, started from least squares). ``params`` holds ``{"F:term": {"value",
    "stderr"}}`` (standard errors from least squares only). ``filter_lambda`` and
    ``zoh_midpoint`` choose the form of τ̄ (:func:`residual_force`): Savitzky-Golay
    accelerations by default; the filtered form with the zero-order-hold midpoint is the
    unbiased choice for logs of held inputs under a fast autopilot.
    """

    kind = "synthesis"

    def __init__(
        self,
        vehicle,
        mask: str | Mapping[str, Sequence[str]] = "mcfarland",
        method: Literal["ls", "mae", "mse", "rms", "mad"] = "ls",
        savgol_window: float = 1.0,
        savgol_order: int = 4,
        filter_lambda: float | None = None,
        zoh_midpoint: bool = False,
    ) -> None:
        self.vehicle = vehicle
        self.mask = mask
        self.method = method
        self.savgol_window = savgol_window
        self.savgol_order = savgol_order
        self.filter_lambda = filter_lambda
        self.zoh_midpoint = zoh_midpoint

    def _fit(self, log: pd.DataFrame, validation, progress: Progress) -> None:
        if self.method != "ls" and self.method not in LOSSES:
            raise NnidInputError(
                f"method is 'ls' or one of {', '.join(LOSSES)}, not '{self.method}'",
                field="method",
            )
        try:
            terms = mask_term_list(self.mask)
            mask = mask_matrix(self.mask, terms)
        except ValueError as exc:  # an unknown model name or term
            raise NnidInputError(str(exc), field="mask") from None
        xi, tau_bar, nu = self._library_data(log, terms)
        ok = self._defined(log, xi, tau_bar, "training")
        self._warn_held(log, "the synthesis fit")
        # each term against itself at the log's typical motion, to its power (as SINDy's):
        # against Ξ's typical regressor, q|q| of a real pitch rate 1e-6 of the yaw rate
        # (1e-11 beside r|r|) was a zero regressor, held at 0 and warned unexcited
        floors = self._floors(nu[ok], terms)
        fit = masked_least_squares(xi, tau_bar, mask, terms, floors=floors)
        progress(1, 2 if self.method != "ls" else 1, "masked least squares")
        if self.method != "ls":
            fit = nelder_mead(xi, tau_bar, mask, self.method, start=fit)
            progress(2, 2, f"Nelder-Mead on {self.method}")
        self._set_damping(terms, fit.coefficients, fit.stderr, fit.unidentified)
        warn_simulated(dict.fromkeys(self._unidentified_names()), stacklevel=3, at=_at_zero)

    def _structure(self) -> np.ndarray:
        return mask_matrix(self.mask, self.terms_)

    def _restore(self, state: dict, tensors: dict) -> None:
        super()._restore(state, tensors)
        if UNIDENTIFIED not in state:  # an older file: its 0 was shown as an estimate
            self.unidentified_ = older_unidentified(self._structure(), self.coef_, self.stderr_)

    def trainer_name(self) -> str:
        return "masked least squares" if self.method == "ls" else f"Nelder-Mead ({self.method})"
