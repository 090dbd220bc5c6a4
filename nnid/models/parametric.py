"""The Fossen model written linear in its unknown parameters (Weiss eqs 47-53, 99-108).

With the rigid body known, the equation of motion M ν̇ + C(ν)ν + D(ν)ν + g(η) = τ_eff + b is
linear in the added-mass derivatives, the damping coefficients of any basis term, the
installation coefficients η (Caccia eq. 3), a constant external force b, weight, buoyancy and
the centres of gravity and buoyancy (one of each pair of a product unknown). So

    R(θ) = M ν̇ − (τ_eff + b − C ν + τ_D − g) = R(0) + Φ θ = 0   ⇒   Φ θ = −R(0) = y,

and every regressor column is φ_k = R(e_k) − R(0), evaluated with the physics package itself:
no term is derived by hand here. Which parameters are unknown and which DOF equations are used
makes the decoupled per-DOF forms (Weiss 99-104), pitch through surge-heave coupling (105-108)
and the full coupled 6-DOF regression.

Parameter names follow the vehicle file: ``X_udot``, ``"X:u*abs(u)"``, ``eta.w.neg``,
``external_bias.u``, ``weight``, ``buoyancy``, ``r_g.z``, ``r_b.z``.
"""

from __future__ import annotations

import dataclasses
import re
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import pandas as pd
import torch
from scipy.signal import lfilter, lfilter_zi
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted

from nnid.datasets.arrays import log_arrays, nominal_forces
from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.log import (
    ACCELERATION,
    ANGLES,
    MOTION,
    POSE,
    VELOCITY,
    run_label,
    typical_step,
)
from nnid.datasets.preprocess import (
    HELD_DT,
    HELD_SHARE,
    held_at,
    savgol_noise_gain,
    step_window,
    unwrap_finite,
    velocity_sources,
    zoh_midpoint,
)
from nnid.datasets.splits import PARTS
from nnid.errors import ExcitationWarning, NnidInputError, checked_number
from nnid.evaluation.persistence import kind_sizes, motion_sizes, rounding_floors
from nnid.evaluation.prediction import (
    Replay,
    blank_initial,
    check_mode,
    check_stepped,
    mode_steps,
    predict_closed_loop,
    predict_states,
    substeps_for,
)
from nnid.models.base import (
    NETWORK_TRAINERS,
    NOT_FITTED,
    REGRESSION_TRAINERS,
    AccelerationParts,
    NnidModel,
    check_log,
    record_key,
    record_tensor,
    saved_record,
)
from nnid.physics.added_mass import mirrored_key, parse_added_mass_key, set_derivative
from nnid.physics.damping import parse_coefficient_key
from nnid.physics.damping_library import (
    ATOMS,
    canonical_term,
    evaluate_terms,
    parse_term,
    term_codes,
)
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.fossen import FossenModel, net_force_of
from nnid.physics.parts import Parts, at_file_value, relative_velocity
from nnid.physics.thrusters import force_deadband
from nnid.serialization import exact_float, read_exact_float
from nnid.trainers.history import Progress
from nnid.trainers.regression import Regression
from nnid.vehicle import Vehicle, vehicle_copy

if TYPE_CHECKING:  # at run time imported where used, as this module does elsewhere
    from nnid.trainers.least_squares import Estimate

_AXES = "xyz"


class PhysicsWarning(UserWarning):
    """An estimate that no physical vehicle can have."""


def canonical_parameter(name: str) -> str:
    """Validate a parameter name and return its canonical spelling."""
    if re.fullmatch(r"[XYZKMN]_[uvwpqr]dot", name):
        parse_added_mass_key(name)
        return name  # its mirror is the same parameter: ParametricFossen refuses the pair
    if ":" in name:
        force, term = parse_coefficient_key(name)
        return f"{force}:{term}"
    if re.fullmatch(r"eta\.[uvwpqr]\.(pos|neg)", name):
        return name
    if re.fullmatch(r"external_bias\.[uvwpqr]", name) or name in ("weight", "buoyancy"):
        return name
    if re.fullmatch(r"r_[gb]\.[xyz]", name):
        return name
    raise NnidInputError(
        f"unknown parameter '{name}'; expected an added-mass derivative ('X_udot'), a damping "
        "coefficient ('X:u*abs(u)'), 'eta.<dof>.<pos|neg>', 'external_bias.<dof>', 'weight', "
        "'buoyancy', 'r_g.<x|y|z>' or 'r_b.<x|y|z>'",
        field="unknowns",
    )


def vehicle_with(vehicle, values: dict[str, float]):
    """A copy of ``vehicle`` with parameters (names of :func:`canonical_parameter`) set to
    ``values``: an identified vehicle file. Raises ValueError where a value is not physical
    (an installation coefficient outside (0, 2])."""
    out = vehicle.model_dump()
    for name, value in values.items():
        name, value = canonical_parameter(name), float(value)
        if ":" in name:
            force, term = parse_coefficient_key(name)
            coefs = out["damping"]["coefficients"]
            key = next((k for k in coefs if parse_coefficient_key(k) == (force, term)), name)
            coefs[key] = value
        elif name.endswith("dot"):
            set_derivative(out["added_mass"], name, value)
        elif name.startswith("eta."):
            out["installation"][name[4:]] = value
        elif name.startswith("external_bias."):
            out["external_bias"][DOFS.index(name.split(".")[1])] = value
        elif name in ("weight", "buoyancy"):
            out[name] = value
        else:
            out[name[:3]][_AXES.index(name[-1])] = value
    # the curves are the given vehicle's: one of no thrust that a saved model kept is kept, so
    # that the model's vehicle can be refitted
    return vehicle_copy(vehicle, out)


def checked_dofs(dofs: object, field: str = "dofs") -> tuple[str, ...]:
    """``dofs`` as a tuple of DOF names, or the error naming ``field``: given in Python, a
    name that is no DOF failed as ``tuple.index(x)`` while the unknowns were expanded."""
    if isinstance(dofs, str | bytes) or not np.iterable(dofs):
        raise NnidInputError(f"a list of DOFs (some of u v w p q r) is expected, not {dofs!r}",
                             field=field)  # fmt: skip
    for d in dofs:
        if d not in DOFS:
            raise NnidInputError(f"'{d}' is not a DOF; expected u v w p q r", field=field)
    return tuple(dofs)


def regression_trainer(trainer: object, field: str = "trainer") -> Any:
    """A fresh copy of the trainer of a physics fit (least squares if None), or the error
    naming ``field``: a network's trainer, or something that is no trainer (given in Python,
    ``"nope"`` failed as ``'str' object has no attribute 'fit'``)."""
    from nnid.trainers.least_squares import LeastSquares

    if trainer is None:
        return LeastSquares()
    kind = getattr(trainer, "kind", type(trainer).__name__)
    if kind in NETWORK_TRAINERS:
        raise NnidInputError(
            f"the '{kind}' trainer cannot fit a Fossen model's parameters; "
            f"it is fitted by one of {', '.join(REGRESSION_TRAINERS)} (lm and adam train "
            "networks: a hybrid's, a NARX's)",
            field=field,
        )
    if not callable(getattr(trainer, "fit", None)):
        raise NnidInputError(
            f"a regression trainer is expected (LeastSquares, RecursiveLeastSquares, "
            f"GradientEstimator, UnscentedKalman: kinds {', '.join(REGRESSION_TRAINERS)}), "
            f"not {trainer!r}",
            field=field,
        )
    return clone(trainer, safe=False)


#: the rows :meth:`ParametricFossen.rounding_floors` evaluates at most: its state is one
#: constant motion, the rows differ only by pose and inputs
REFERENCE_ROWS = 256


def _parts_key(parts: Parts) -> tuple:
    """Every field of ``parts`` by value (its bytes: -0.0 and NaN as they are), in its order
    (a dict's order is its model's term order), hashable."""
    out = []
    for f in dataclasses.fields(parts):
        value = getattr(parts, f.name)
        if isinstance(value, dict):
            out.append(tuple((k, np.float64(v).tobytes()) for k, v in value.items()))
        elif value is None:
            out.append(None)
        else:
            array = np.asarray(value, dtype=np.float64)
            out.append((array.shape, array.tobytes()))
    return tuple(out)


class ParametricFossen:
    """The regression structure: a vehicle, the unknown parameters and the DOF equations used."""

    def __init__(self, vehicle, unknowns: Sequence[str], dofs: Sequence[str] = DOFS) -> None:
        self.vehicle = vehicle
        self.names = [canonical_parameter(n) for n in unknowns]
        if len(set(self.names)) != len(self.names):
            raise NnidInputError("unknown parameters must be unique", field="unknowns")
        for n in self.names:
            twin = mirrored_key(n) if n.endswith("dot") and ":" not in n else None
            if twin in self.names:
                raise NnidInputError(
                    f"'{n}' and '{twin}' are one parameter (the added-mass matrix is "
                    "symmetric): give one of them",
                    field="unknowns",
                )
        self.dofs = checked_dofs(dofs)
        if {"weight", "buoyancy"} & set(self.names):
            pair = {"weight": "r_g.", "buoyancy": "r_b."}
            for n in self.names:
                for w, r in pair.items():
                    if w in self.names and n.startswith(r):
                        raise NnidInputError(
                            f"'{w}' and '{n}' multiply each other: identify their "
                            "moment instead, or fix one of them",
                            field="unknowns",
                        )
        self.base = Parts.from_vehicle(vehicle)
        for name in self.names:  # unknowns start from zero in R(0)
            self.base.set(name, 0.0)
        self._models: dict[tuple, FossenModel] = {}  # :meth:`_model`'s, by the parts' values

    def _model(self, parts: Parts) -> FossenModel:
        """The (unchecked) model of ``parts``, made once per value of them: :meth:`_columns`
        evaluates the base and each unknown's unit at every call (``detect --follow`` every
        0.5 s of rows), and making a model cost about as much as evaluating it. Keyed by
        every field's value, so parts edited since (:meth:`restricted`'s known values) get
        a model of their own; made from a copy, which no later edit reaches."""
        key = _parts_key(parts)
        model = self._models.get(key)
        if model is None:
            if len(self._models) > 2 * len(self.names) + 2:  # not the columns' parts alone
                self._models.clear()
            model = self._models[key] = parts.copy().model(check=False)
        return model

    def parts(self, theta: Sequence[float] | dict) -> Parts:
        """The vehicle's parts with the unknowns set to ``theta``."""
        values = theta if isinstance(theta, dict) else dict(zip(self.names, theta, strict=True))
        out = self.base.copy()
        for name, value in values.items():
            out.set(name, float(value))
        return out

    def equation_residual(
        self,
        parts: Parts,
        data: dict[str, np.ndarray],
        filter_lambda: float | None = None,
        nu_dot_f: np.ndarray | None = None,
    ) -> np.ndarray:
        """R = M ν̇ − (τ_eff + b − C ν + τ_D − g) per sample ``[N, 6]``, τ_eff the installed
        force through the actuator lag (:meth:`Parts.felt`, Caccia eq. 3 before the lag).

        With ``filter_lambda`` = λ both sides pass through F(s) = λ/(s + λ) and M F[ν̇] is
        computed as M sF(s)[ν] from the velocity: the filtered-regressor form of Weiss eqs
        86-92, which needs no differentiated (noisy) acceleration. ``nu_dot_f``: sF(s)[ν] of
        this ``data`` at this λ where the caller has it (:func:`filter_signal`, derivative);
        it depends on the data alone, not on ``parts``, so a regression filters it once.
        """
        return self._residuals(parts, data, [parts.bias], filter_lambda, nu_dot_f)[0]

    def _residuals(
        self,
        parts: Parts,
        data: dict[str, np.ndarray],
        biases: Sequence[np.ndarray],
        filter_lambda: float | None = None,
        nu_dot_f: np.ndarray | None = None,
        model: FossenModel | None = None,
    ) -> list[np.ndarray]:
        """:meth:`equation_residual` of ``parts`` with its external force b set to each of
        ``biases`` [6] in turn, from one evaluation of the model: b enters R alone (neither
        M nor the other forces read it), so each R is the one its own parts give, bit for bit.
        A regression's external-force columns cost a model and its forces each otherwise.
        ``model``: that of ``parts`` (:meth:`_model`), else made here."""
        model = parts.model(check=False) if model is None else model
        with torch.no_grad():
            eta, nu = torch.as_tensor(data["eta"]), torch.as_tensor(data["nu"])
            tau = torch.as_tensor(parts.felt(data))
            terms = model.motion_terms(eta, nu)
            nets = [
                net_force_of(tau + torch.as_tensor(b, dtype=torch.float64), terms).numpy()
                for b in biases
            ]
            mass = model.mass_matrix().numpy()
        if filter_lambda is None:
            inertial = data["nu_dot"] @ mass.T
            return [inertial - net for net in nets]
        if nu_dot_f is None:
            nu_dot_f = filter_signal(data, data["nu"], filter_lambda, derivative=True)
        inertial = nu_dot_f @ mass.T
        return [inertial - filter_signal(data, net, filter_lambda) for net in nets]

    def regression(
        self,
        data: dict[str, np.ndarray],
        filter_lambda: float | None = None,
        nu_dot_f: np.ndarray | None = None,
        floor_dofs: Sequence[str] | None = None,
    ) -> Regression:
        """Φ θ = y over the chosen DOF equations; φ_k = R(e_k) − R(0), y = −R(0).

        With ``filter_lambda`` the filtered form is used (see :meth:`equation_residual`,
        which also says ``nu_dot_f``) and the first 3/λ seconds of each experiment, where the
        filters settle, are left out. ``floor_dofs``: the DOF equations the columns' rounding
        floors are sized over (:meth:`rounding_floors`), where a fit weights only those of the
        chosen ones (the residual loop's analysed DOFs); default: all the chosen ones.
        """
        rows = [DOFS.index(d) for d in self.dofs]
        keep = np.ones(data["t"].size, dtype=bool)
        if filter_lambda is not None:
            keep = filter_settled(data, filter_lambda)
            if not keep.any():  # nothing to fit (and a filter this slow is singular to discretise)
                longest = max(
                    float(np.ptp(data["t"][data["experiment"] == k]))
                    for k in np.unique(data["experiment"])
                )
                if longest <= 0.0:  # runs of one sample each: no λ helps
                    raise NnidInputError(
                        "no experiment has two samples: there is nothing to filter or fit",
                        field="experiment",
                    )
                raise NnidInputError(
                    f"the filtered regressors settle in 3/λ = {3.0 / filter_lambda:.3g} s, "
                    f"longer than every experiment (the longest lasts {longest:.3g} s): no "
                    f"sample is left to fit; give filter_lambda above {3.0 / longest:.3g} rad/s",
                    field="filter_lambda",
                )
        if filter_lambda is not None and nu_dot_f is None:  # once for R(0) and every column
            nu_dot_f = filter_signal(data, data["nu"], filter_lambda, derivative=True)
        r0, columns = self._columns(data, filter_lambda, nu_dot_f)
        cols = [col[keep][:, rows].reshape(-1) for col in columns]
        n = int(keep.sum())
        phi = np.stack(cols, 1) if cols else np.zeros((n * len(rows), 0))
        acceleration = data["nu_dot"] if nu_dot_f is None else nu_dot_f
        y = -r0[keep][:, rows].reshape(-1)

        def floors() -> np.ndarray:  # only where a solve reads them (Regression.floors)
            return self.rounding_floors(data, acceleration[keep], floor_dofs)

        return Regression(phi, y, list(self.names), self.dofs, n, floors)

    def _columns(
        self,
        data: dict[str, np.ndarray],
        filter_lambda: float | None = None,
        nu_dot_f: np.ndarray | None = None,
        names: Sequence[str] | None = None,
    ) -> tuple[np.ndarray, list[np.ndarray]]:
        """R(0) and each unknown's column R(e_k) − R(0), ``[N, 6]`` each, over all six DOF
        equations (:meth:`regression` keeps its own), of the unknowns ``names`` (default
        all, in order)."""
        names = self.names if names is None else names
        damping = self.damping_columns(data, filter_lambda) if any(":" in n for n in names) else {}
        units = {}
        for name in names:
            if name not in damping:
                units[name] = self.base.copy()
                units[name].set(name, 1.0)
        # an external force's unit differs from the base in b alone: R(0) and its R(e_k) from
        # one evaluation of the model
        forces = [n for n in units if n.startswith("external_bias.")]
        biases = [self.base.bias, *(units[n].bias for n in forces)]
        base = self._model(self.base)
        r0, *shifted = self._residuals(self.base, data, biases, filter_lambda, nu_dot_f, base)
        at_force = dict(zip(forces, shifted, strict=True))
        cols = []
        for name in names:
            if name in damping:
                cols.append(damping[name])
            elif name in at_force:
                cols.append(at_force[name] - r0)
            else:
                unit, model = units[name], self._model(units[name])
                unit_r = self._residuals(unit, data, [unit.bias], filter_lambda, nu_dot_f, model)
                cols.append(unit_r[0] - r0)
        return r0, cols

    def rounding_floors(
        self,
        data: dict[str, np.ndarray],
        nu_dot: np.ndarray,
        dofs: Sequence[str] | None = None,
    ) -> np.ndarray:
        """Each unknown's floor of the rounding rule
        (:func:`~nnid.evaluation.persistence.rounding_floors`) for this structure's regression
        on ``data``, of :meth:`reference_sizes` over the rows of ``dofs`` (default: the
        structure's DOF equations)."""
        return rounding_floors(*self.reference_sizes(data, nu_dot, dofs))

    def reference_sizes(
        self,
        data: dict[str, np.ndarray],
        nu_dot: np.ndarray,
        dofs: Sequence[str] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Each unknown's typical column size in the rows of the DOF equations ``dofs``
        (default: the structure's), of which its floor of the rounding rule is made
        (:meth:`rounding_floors`; :func:`~nnid.evaluation.persistence.motion_sizes`): its
        column at the log's typical motion ``[P]``, and with each velocity alone times
        :data:`~nnid.evaluation.persistence.POWER_PROBE` ``[6, P]``, for its least power among
        the velocities it grows with (as SINDy's library terms,
        :func:`~nnid.evaluation.persistence.library_floors`): a product is rounding where one
        of its factors is, so that u·w of a log whose w is rounding (1e-17) is of power 1 in
        w; read in the whole motion at once it was of power 2, its floor ROUNDING² × its size,
        and its 1e-17 of u² was data: M:u*w was fitted to rounding (the Munk moment's, -41.5
        on a Seamor surge/sway/yaw log), a value a later log that heaves would simulate. The
        typical motion (:func:`~nnid.evaluation.persistence.kind_sizes`, angular rates over the
        vehicle's length): ν of each kind (linear, angular) at the largest typical |ν| of that
        kind (one number for all six compared a yaw-only fit with a yaw rate of the surge
        speed, 0.49 rad/s, where the log had 2.5e-6, and called its r|r| rounding), ν̇ likewise
        of ``nu_dot`` (the accelerations the regression reads: logged, or sF(s)[ν] of the
        filtered form); each velocity's acceleration is scaled with it, as a motion of larger
        amplitude at the same frequencies has both larger: an added mass's column (its ν̇ in
        its own equation, its C_A(ν)ν in others, each a product with its velocity) is of power
        1 in its velocity, as a ν̇ alone is. A column whose motion is spread so that no velocity
        alone moves its typical size (an r_g column: its restoring part and, in each equation, a
        ν̇ or a product of another velocity) takes the floor of a column that does not grow with
        the motion, ROUNDING × the regression's largest column at that motion. Why that is no
        wrong verdict: a column with a motion part has a ν̇ part (each parameter of C(ν) is one
        of M: an added mass, r_g), of power 1, so the floor its power would give is ROUNDING ×
        its own size, and the fallback is never below it (its own size is at most the
        largest): no column of rounding is estimated. It is stricter only by the largest
        column over its own, so a real column is called rounding only where it is within
        ROUNDING of the regression's largest column at the log's typical motion, the scalar
        rule's own limit (:data:`~nnid.evaluation.persistence.ROUNDING`: ten decades in
        earnest), which the tol rule of
        :func:`~nnid.evaluation.persistence.excitation_from_gram` calls zero too unless an
        equation it is in has no column 1e6 times its size; its restoring part has no power,
        and the fallback is that part's floor in any case (r_g.z and r_g.x of a BlueROV2 Heavy
        log, mostly restoring, are themselves the largest column: the two floors are one). Row
        by row otherwise (η, the inputs), on at most :data:`REFERENCE_ROWS` rows drawn by a
        fixed local generator: the rule needs a size within decades.

        Why not the regression's own columns: a one-DOF fit whose every column is rounding
        (X:u alone on a heave-only log, u ~ 1e-17) has nothing to be compared with, and read
        X:u = -13.7 off a target of rounding as a precise estimate. Why each column at the
        motion to its power, not one size for all: the columns' units and powers differ (u|u|
        of a real surge 1e-6 of the heave is 1e-12 of the heave's w|w|, not rounding). A log at
        rest in every DOF (all of ν rounding) gives floors of rounding, and the rule then finds
        nothing: there is no motion to compare with."""
        if not self.names:
            return np.zeros(0), np.zeros((len(DOFS), 0))
        n = data["t"].size
        picked = np.arange(n)
        if n > REFERENCE_ROWS:
            picked = np.sort(np.random.default_rng(0).choice(n, REFERENCE_ROWS, replace=False))
        moved = {
            k: v[picked]
            for k, v in data.items()
            if isinstance(v, np.ndarray) and v.shape[:1] == (n,)
        }
        # the rates at the ends of the vehicle (Vehicle.rounding_length)
        length = self.vehicle.rounding_length
        nu, acc = kind_sizes(data["nu"], length), kind_sizes(nu_dot, length)
        # the rows a fit weights: a column's entries in an equation it does not fit (an added
        # mass's C_A(ν)ν beside the one DOF analysed) are no size of what it measures there
        rows = [DOFS.index(d) for d in (self.dofs if dofs is None else dofs)]

        others = [n for n in self.names if ":" not in n]

        def columns_at(scales: np.ndarray) -> list[np.ndarray]:  # each velocity with its ν̇
            # every scale's rows stacked in one evaluation (a model per unknown each): each
            # row is evaluated on its own, so each scale's columns are those it alone gives
            batch = {k: np.concatenate([v] * len(scales)) for k, v in moved.items()}
            batch["nu"] = np.repeat(scales * nu, picked.size, 0)
            batch["nu_dot"] = np.repeat(scales * acc, picked.size, 0)
            shape = (len(scales), picked.size, -1)
            cols = {}
            if others:
                at = self._columns(batch, names=others)[1]
                cols.update(zip(others, (c[:, rows].reshape(shape) for c in at), strict=True))
            # a damping column is −ξ_term in its force's row, 0 in the others
            # (damping_columns), and a size reads a column's non-zero entries alone
            # (column_sizes, which draws no rows from REFERENCE_ROWS × 6): the term's own
            # entries where its force is fitted, none where not, not spread into [N, 6]
            # columns (the loop's 630 candidates at seven scales: 54 MB a copy, the demo
            # loop's peak 150 MB higher)
            terms, xi, forces = self.damping_terms(batch)
            if terms:
                xi = np.where(np.isin(forces, rows), xi, 0.0)
                cols.update(zip(terms, np.moveaxis(xi.reshape(shape), 2, 0), strict=True))
            return [cols[n] for n in self.names]

        return motion_sizes(columns_at, len(DOFS))

    def damping_force(self, data: dict[str, np.ndarray]) -> np.ndarray:
        """McCarter's residual force τ̄ = M ν̇ + C(ν)ν + g(η) − τ (eq. 4.4, his g on the other
        side): the viscous force the log shows once everything else the model knows is taken
        out, ``[N, 6]``. Damping unknowns and declared damping are both left out of it."""
        parts = self.base.copy()
        parts.damping = {}
        return self.equation_residual(parts, data)

    def damping_columns(
        self, data: dict[str, np.ndarray], filter_lambda: float | None = None
    ) -> dict[str, np.ndarray]:
        """Columns of the damping unknowns in one evaluation of the basis library: R holds
        −τ_D = −Θ ξ(ν), so coefficient "F:term" has −ξ_term(ν) in row F and zero elsewhere
        (the same number R(e_k) − R(0) gives, without one physics call per term)."""
        names, xi, rows = self.damping_terms(data, filter_lambda)
        out = {}
        for k, (name, row) in enumerate(zip(names, rows, strict=True)):
            col = np.zeros((xi.shape[0], 6))
            col[:, row] = -xi[:, k]
            out[name] = col
        return out

    def damping_terms(
        self, data: dict[str, np.ndarray], filter_lambda: float | None = None
    ) -> tuple[list[str], np.ndarray, list[int]]:
        """The damping unknowns, their terms ξ_term(ν_r) ``[N, K]`` (filtered with
        ``filter_lambda``) from one evaluation of the basis library, and the row (force) of
        R each enters with −ξ: what :meth:`damping_columns` spreads into ``[N, 6]`` columns,
        for callers that build the ``[N, 6, K]`` block at once."""
        names = [n for n in self.names if ":" in n]
        if not names:
            return [], np.zeros((data["t"].size, 0)), []
        split = [parse_coefficient_key(n) for n in names]
        nu = relative_velocity(self.base, data)
        xi = evaluate_terms(nu, term_codes([t for _, t in split]), self.base.u_c)
        if filter_lambda is not None:
            xi = filter_signal(data, xi, filter_lambda)
        return names, xi, [FORCES.index(force) for force, _ in split]

    def restricted(
        self, unknowns: Sequence[str], dofs: Sequence[str], known: dict[str, float]
    ) -> ParametricFossen:
        """The structure of a step of a decoupled sequence: ``unknowns`` from the ``dofs``
        equations, with the ``known`` values of earlier steps plugged in (a parameter that is
        unknown again is refitted from zero)."""
        sub = ParametricFossen(self.vehicle, unknowns, dofs)
        for name, value in known.items():
            if name not in sub.names:
                sub.base.set(name, value)
        return sub

    def term_names(self) -> list[str]:
        return [canonical_term(n.split(":")[1]) for n in self.names if ":" in n]


def filter_signal(data: dict[str, np.ndarray], x: np.ndarray, lam: float, derivative: bool = False):
    """F(s) = λ/(s + λ) (or s F(s) for the derivative) per experiment, discretised by the
    bilinear transform so that the two stay consistent; started in steady state. A filter too
    fast for the sampling is refused: with c = λ dt/2 ≥ 1 the pole (1 − c)/(1 + c) is at or
    below 0, an alternating filter that amplifies the highest frequencies, not a low-pass
    (λ = 1e5 rad/s on the demo's 20-Hz log found no effect where λ = 1 finds its heave
    thrust)."""
    out = np.empty_like(x)
    zis: dict[float, np.ndarray] = {}  # the runs of a log mostly share one rate: solved once
    names = data.get("experiment_names")
    for k in np.unique(data["experiment"]):
        idx = np.flatnonzero(data["experiment"] == k)
        dt = typical_step(data["t"][idx], 1.0)
        c = lam * dt / 2.0
        where = run_label(names[k]) if names is not None else f"experiment {k}"
        if idx.size > 1 and c >= 1.0:
            raise NnidInputError(
                f"filter_lambda = {lam:g} rad/s with samples every {dt:.4g} s ({where}): "
                f"λ dt/2 = {c:.3g} ≥ 1 turns the discretised filter into an alternating "
                f"one, not a low-pass; give filter_lambda below {2.0 / dt:.3g} rad/s (a few "
                "rad/s is the usual choice)",
                field="filter_lambda",
            )
        if idx.size > 1 and (1.0 - c) / (1.0 + c) == 1.0:
            # c lost beside 1: the pole rounds to 1, a filter that never moves, whose steady
            # start is singular (a LinAlgError traceback where the regression's check of the
            # settling came after the filtering: the loop, the filtered damping models)
            raise NnidInputError(
                f"filter_lambda = {lam:g} rad/s with samples every {dt:.4g} s ({where}): "
                f"λ dt/2 = {c:.3g} is lost beside 1 in floating point, so the discretised "
                f"filter never moves (it would settle in 3/λ = {3.0 / lam:.3g} s); give a "
                "filter_lambda of a few rad/s",
                field="filter_lambda",
            )
        a = np.array([1.0 + c, -(1.0 - c)])
        b = lam * np.array([1.0, -1.0]) if derivative else np.array([c, c])
        if c not in zis:
            zis[c] = lfilter_zi(b, a)
        zi = zis[c]
        seg = x[idx]
        out[idx] = lfilter(b, a, seg, axis=0, zi=zi[:, None] * seg[:1])[0]
    return out


def settled_rows(data: dict[str, np.ndarray], seconds: float) -> np.ndarray:
    """True for the samples at least ``seconds`` after the start of their experiment."""
    keep = np.ones(data["t"].size, dtype=bool)
    for k in np.unique(data["experiment"]):
        idx = np.flatnonzero(data["experiment"] == k)
        keep[idx] = data["t"][idx] - data["t"][idx[0]] >= seconds
    return keep


def filter_settled(data: dict[str, np.ndarray], lam: float) -> np.ndarray:
    """The samples where F(s) = λ/(s + λ) has settled: 3/λ s after each experiment starts
    (a step response is then within e⁻³ ≈ 5 % of its end value)."""
    return settled_rows(data, 3.0 / lam)


#: what a Fossen fit of no unknowns says: nothing was fitted, though it ran and is scored
NOTHING_ESTIMATED = (
    "the fit has no unknowns ({}): nothing is estimated and no trainer runs; the Fossen model "
    "is the vehicle file as written (its added mass, damping and restoring as given), and its "
    "scores are those of the file's values"
)


def check_damping_group(
    spec: Sequence[str],
    dofs: Sequence[str],
    vehicle: Vehicle,
    vehicle_label: str | None = None,
    strict: bool = True,
) -> None:
    """The group ``damping`` of the unknowns ``spec`` refused where the vehicle declares no
    damping term in the forces of ``dofs``: it asks to estimate damping the model does not
    contain (a fit of ``["damping"]`` alone warned and estimated nothing). Not ``strict`` (the
    group asked by default, not by the user), a warning that it is not estimated: it was
    dropped without a word. ``vehicle_label`` names the vehicle in the message (``nnid train``
    knows its file; else its name). Not checked on loading a saved model: one fitted so
    before is read as it was."""
    if "damping" not in spec:
        return
    forces = [FORCES[DOFS.index(d)] for d in dofs]
    declared = sorted({k.split(":")[0] for k in Parts.from_vehicle(vehicle).damping})
    if set(declared) & set(forces):
        return
    where = vehicle_label or f"vehicle '{vehicle.name}'"
    has = (
        "declares no damping term"
        if not declared
        else f"declares damping terms of {', '.join(declared)} only, none of the "
        f"{', '.join(forces)} equation{'s' if len(forces) > 1 else ''} fitted"
    )
    said = (
        f"'damping' asks to estimate the damping of {where}, which {has} ([damping] model or "
        "[damping.coefficients]): there is nothing to estimate. Give the vehicle file the terms "
        '([damping] model = a named mask such as "fossen", whose coefficients left out are '
        "identified, or keys under [damping.coefficients]), or leave 'damping' out of unknowns"
    )
    if not strict:
        warnings.warn(f"{said}; no damping is estimated", UserWarning, stacklevel=3)
        return
    raise NnidInputError(said, field="unknowns")


def expand_unknowns(spec: Sequence[str], dofs: Sequence[str], vehicle) -> list[str]:
    """The unknowns of a fit with the shortcuts expanded: ``added_mass`` (the diagonal
    derivatives of ``dofs``) and ``damping`` (the vehicle's damping-model terms of their
    forces). A bare string is refused, as the config and :func:`checked_dofs` refuse one:
    given in Python, ``"damping"`` was read letter by letter ("unknown parameter 'd'")."""
    if isinstance(spec, str | bytes) or not np.iterable(spec):
        raise NnidInputError(
            "unknowns is a list of parameter names and the groups 'added_mass' and 'damping' "
            f"(e.g. [{spec!r}]), not {spec!r}",
            field="unknowns",
        )
    out: list[str] = []
    forces = {FORCES[DOFS.index(d)] for d in dofs}
    for item in spec:
        if item == "added_mass":
            out += [f"{FORCES[DOFS.index(d)]}_{d}dot" for d in dofs]
        elif item == "damping":
            out += [k for k in Parts.from_vehicle(vehicle).damping if k.split(":")[0] in forces]
        else:
            out.append(item)
    return list(dict.fromkeys(out))


def _factor_velocities(atom: int) -> tuple[int, ...]:
    """The velocity DOFs (0-5) a basis-term atom depends on: u..r and abs(u)..abs(r) one each,
    U and η all linear ones, V, Vv and Vw v and w; the unit atom none."""
    name = ATOMS[atom]
    if atom < 2 * len(DOFS):
        return (atom % len(DOFS),)
    return {"U": (0, 1, 2), "(eta-1)": (0, 1, 2), "1": ()}.get(name, (1, 2))


def unexcited_unknowns(
    names: Sequence[str],
    data: dict[str, np.ndarray],
    from_pose: tuple[Sequence[str], tuple[float, int]] | None = None,
    *,
    structure: ParametricFossen | None = None,
    dofs: Sequence[str] = (),
    filter_lambda: float | None = None,
) -> dict[str, list[str]]:
    """The unknowns whose regressor is a product with a velocity that stays within 3 times its
    measurement noise over the fit data (the noise from second differences,
    :func:`nnid.trainers.ukf.noise_level`): ``{name: [DOFs]}``.

    A diagonal added mass ``Y_vdot`` multiplies v̇ (and v in the Coriolis terms), a damping term
    ``Y:v*abs(v)`` its factors: where v only trembles at its noise, the column is noise, unit
    scaling makes it look as well conditioned as any other (Weiss eq. 95 sees no defect), and
    least squares fits it, with a small standard error, to the noise (errors in variables).
    Signal to noise only: a small but real motion is excitation. Velocities differentiated
    from the pose (Savitzky-Golay) carry smoothed, correlated noise that second differences
    put 7-8 times too low (a surge-only motion-capture run's p, q, r, pure noise, passed as
    excited): ``from_pose`` = (the velocity columns so derived, the (window s, order) of that
    derivative) adds theirs from the pose noise (:func:`pose_noise_variance`) times the
    first-derivative gain (:func:`~nnid.datasets.preprocess.savgol_noise_gain`), in quadrature
    with the differences' (which see the white share, e.g. u times the heading noise in v).

    A diagonal added mass enters the other equations through the Coriolis products of
    C_A(ν)ν (Weiss eqs 27-28), whose other factor may be the one at noise: the surge equation
    reads ``Y_vdot`` through v r alone, so with v moving and r only noise its column is signal
    times noise. Given the ``structure`` and the ``dofs`` equations it is fitted from (with
    ``filter_lambda`` as fitted), its column (:func:`still_factors`) is also judged: at noise
    when every product in it has a factor at noise. Off-diagonal added mass and non-motion
    unknowns are not judged here."""
    from nnid.trainers.ukf import noise_level

    nu = np.asarray(data["nu"], dtype=np.float64)
    noise = noise_level(data, DOFS)
    if from_pose is not None and any(d in from_pose[0] for d in DOFS):
        noise = np.hypot(noise, _pose_velocity_noise(data, *from_pose))
    spread = np.nanstd(nu, axis=0)
    # no noise estimate (too few samples): no verdict
    moving = {k for k in range(len(DOFS)) if not np.isfinite(noise[k]) or spread[k] > 3 * noise[k]}
    out: dict[str, list[str]] = {}
    for name in names:
        if ":" in name:
            factors = [_factor_velocities(a) for a in parse_term(parse_coefficient_key(name)[1])]
        else:
            try:
                i, j = parse_added_mass_key(name)
            except ValueError:
                continue
            if i != j:
                continue
            factors = [(j,)]
        still = [f for f in factors if f and not moving.intersection(f)]
        if still:
            out[name] = list(dict.fromkeys(DOFS[k] for f in still for k in f))
        elif ":" not in name and structure is not None and dofs:
            at_noise = set(range(len(DOFS))) - moving
            found = still_factors(structure, name, dofs, data, at_noise, filter_lambda)
            if found:
                out[name] = [DOFS[k] for k in found]
    return out


#: a column that zeroing the velocities at noise leaves at most this share of (RMS) is all
#: products with such a factor: the rest is the rounding of R(e_k) − R(0), ~1e-16 of R
_STILL_SHARE = 1e-6


def still_factors(
    structure: ParametricFossen,
    name: str,
    dofs: Sequence[str],
    data: dict[str, np.ndarray],
    at_noise: set[int],
    filter_lambda: float | None = None,
) -> list[int]:
    """The DOFs of ``at_noise`` (indices into :data:`DOFS`) that are factors of every product
    in the regression column of ``name`` over the ``dofs`` equations on ``data`` (the column
    of :func:`~nnid.trainers.sequence.step_reads`, φ_k = R(e_k) − R(0)), or [] where some
    product has no such factor, or the column is zero. Judged numerically, as the column is
    built: with those velocities and their accelerations set to zero the column vanishes (up to
    rounding), and each DOF named changes it when zeroed alone."""
    if not at_noise:
        return []
    sub = structure.restricted([name], dofs, {})

    def column(zeroed: set[int]) -> np.ndarray:
        cut = list(zeroed)
        moved = {k: np.array(data[k], dtype=np.float64) for k in ("nu", "nu_dot") if k in data}
        for v in moved.values():
            v[:, cut] = 0.0
        phi = sub.regression({**data, **moved}, filter_lambda).phi[:, 0]
        return np.where(np.isfinite(phi), phi, 0.0)  # rows least squares leaves out

    def rms(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean(x**2))) if x.size else 0.0

    whole = column(set())
    size = rms(whole)
    if size == 0.0 or rms(column(at_noise)) > _STILL_SHARE * size:
        return []
    return [k for k in sorted(at_noise) if rms(whole - column({k})) > _STILL_SHARE * size]


def _pose_velocity_noise(
    data: dict[str, np.ndarray], columns: Sequence[str], savgol: tuple[float, int]
) -> np.ndarray:
    """Per DOF of :data:`DOFS`: the noise σ of a velocity of ``columns`` derived from the pose
    by the Savitzky-Golay first derivative of ``savgol`` (window s, order), each experiment at
    its own rate: the pose noise through J⁻¹(η) (:func:`pose_noise_variance`, its mean over
    the samples) times that derivative's gain; 0 for the DOFs not in ``columns``."""
    t = np.asarray(data["t"], dtype=np.float64)
    experiment = np.asarray(data.get("experiment", np.zeros(t.size, dtype=int)))
    gain2 = _run_gain2(t, experiment, savgol)
    var = pose_noise_variance(data, DOFS, columns) * gain2[:, None]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a DOF not derived: all NaN
        mean = np.nanmean(var, axis=0)
    return np.sqrt(np.nan_to_num(mean, nan=0.0))


def _run_gain2(
    t: np.ndarray,
    experiment: np.ndarray,
    savgol: tuple[float, int],
    gain2: Callable[[int, float], float] | None = None,
) -> np.ndarray:
    """Per sample, the squared noise gain of the Savitzky-Golay derivative of ``savgol``
    (window s, order) at its experiment's typical step (:func:`step_window`; 1 s for a run of
    one sample): the first derivative's (:func:`savgol_noise_gain`), or ``gain2(window, dt)``."""
    out = np.ones(t.size)
    for k in np.unique(experiment):
        rows = np.flatnonzero(experiment == k)
        dt, window = step_window(t[rows], *savgol, 1.0)
        out[rows] = (
            savgol_noise_gain(window, savgol[1], dt) ** 2 if gain2 is None else gain2(window, dt)
        )
    return out


def twice_differentiated_gain2(
    window: int, order: int, dt: float, filter_lambda: float | None = None
) -> float:
    """The squared noise gain of a velocity differentiated from the pose (the Savitzky-Golay
    first-derivative kernel of ``window`` samples and ``order``) and then again for its
    acceleration: by the same kernel (the gain of the convolution of the two), or with
    ``filter_lambda`` by the filtered derivative sF(s) of :func:`filter_signal` (its impulse
    response to the first kernel, run until it has decayed)."""
    from scipy.signal import savgol_coeffs

    first = savgol_coeffs(window, order, deriv=1, delta=dt)
    if filter_lambda is None:
        return float(np.sum(np.convolve(first, first) ** 2))
    c = filter_lambda * dt / 2.0
    tail = int(np.ceil(20.0 / (filter_lambda * dt)))  # e^-20 of the response left
    response = lfilter(
        filter_lambda * np.array([1.0, -1.0]),
        np.array([1.0 + c, -(1.0 - c)]),
        np.concatenate([first, np.zeros(tail)]),
    )
    return float(np.sum(response**2))


def pose_noise_variance(
    data: dict[str, np.ndarray], dofs: Sequence[str], from_pose: Sequence[str]
) -> np.ndarray:
    """``[N, len(dofs)]``: per sample, the variance that the pose noise (σ of
    :func:`nnid.trainers.ukf.noise_level` on the pose columns) gives a body velocity of
    ``dofs`` derived from the pose (:func:`nnid.datasets.preprocess.derive_velocities`),
    per unit of the differentiator's gain: p q r = T_Θ⁻¹ Θ̇ (the Euler angle rates for small
    angles), u v w = J₁ᵀ ṗ with the full pose (``"u"`` in ``from_pose``), else w = ż/(cθ cφ)
    (its divisor kept at 0.5 or more, as there). NaN for a DOF not in ``from_pose``. The
    attitude's noise is read from it unwrapped (readers keep it wrapped at ±π)."""
    from nnid.datasets.log import euler_rate_matrices
    from nnid.datasets.mapping import rotation_from_euler
    from nnid.trainers.ukf import noise_level

    eta = np.asarray(data["eta"], dtype=np.float64)
    # a wrap's 2π step is no noise: unwrapped along the rows, every step within a run is the
    # angle's own (a step across a join between runs is no noise either way: the MAD drops it)
    pose = eta.copy()
    for k in range(3, 6):
        pose[:, k] = unwrap_finite(eta[:, k])
    sigma2 = noise_level({"nu": pose}, DOFS) ** 2  # x y z φ θ ψ, indexed as u v w p q r
    angles = eta[:, 3:6]
    out = np.full((eta.shape[0], len(dofs)), np.nan)
    rates = linear = None
    for k, d in enumerate(dofs):
        if d not in from_pose:
            continue
        i = DOFS.index(d)
        if i >= 3:
            rates = euler_rate_matrices(angles, inverse=True) if rates is None else rates
            out[:, k] = rates[:, i - 3, :] ** 2 @ sigma2[3:]
        elif "u" in from_pose:
            linear = rotation_from_euler(angles) if linear is None else linear
            out[:, k] = linear[:, :, i] ** 2 @ sigma2[:3]  # u = J₁ᵀ ṗ: column i of J₁
        else:
            tilt = np.abs(np.cos(angles[:, 1]) * np.cos(angles[:, 0]))
            out[:, k] = sigma2[2] / np.maximum(tilt, 0.5) ** 2
    return out


def acceleration_noise_share(
    data: dict[str, np.ndarray],
    dofs: Sequence[str],
    savgol: tuple[float, int] | None,
    filter_lambda: float | None = None,
    from_pose: tuple[Sequence[str], tuple[float, int]] | None = None,
) -> dict[str, float]:
    """Per DOF of ``dofs``: the share ρ = σ²_e / var(a) of the variance of the acceleration
    regressor a that is measurement noise e (errors in variables): the velocity noise of
    :func:`nnid.trainers.ukf.noise_level` (second differences) times the noise gain of the
    differentiator: the Savitzky-Golay derivative (``savgol`` = (window s, order)) that made
    ``nu_dot``, or with ``filter_lambda`` the filtered derivative sF(s) of Weiss eqs 86-92
    (white noise gain λ²/(1 + λ dt/2) of its bilinear discretisation); ``savgol`` None: the
    logged accelerations' own noise (gain 1). Least squares then shrinks the fitted inertia
    M_jj = m − F_jdot by the factor 1 − ρ. Velocities that were themselves differentiated from
    the pose carry smoothed noise that differences underestimate (ρ came out 10³ times too
    small): ``from_pose`` = (the velocity columns so derived, the (window s, order) of that
    derivative) takes theirs from the pose noise instead (:func:`pose_noise_variance`), times
    the gain of the two derivatives in turn (:func:`twice_differentiated_gain2`). With
    ``savgol``, ``data["nu_dot_gain2"]`` where present is each sample's squared gain of the
    derivative that made it (:func:`~nnid.datasets.preprocess.acceleration_gain2`: cut at the
    steps of held inputs, ``zoh_midpoint``), whose short pieces the full window's gain
    under-states many times."""
    from nnid.trainers.ukf import noise_level

    idx = [DOFS.index(d) for d in dofs]
    if filter_lambda is not None:
        keep = filter_settled(data, filter_lambda)
        acc = filter_signal(data, data["nu"], filter_lambda, derivative=True)[:, idx]
    else:
        keep = np.ones(data["t"].size, dtype=bool)
        acc = np.asarray(data["nu_dot"], dtype=np.float64)[:, idx]
    logged = savgol is None and filter_lambda is None  # the accelerations as logged
    pose_columns, pose_savgol = from_pose if from_pose is not None and not logged else ((), None)
    posed = np.array([d in pose_columns for d in dofs], dtype=bool)
    sigma = noise_level({"nu": data["nu_dot"] if logged else data["nu"]}, dofs)
    t, experiment = data["t"], data["experiment"]
    if filter_lambda is not None:
        gain2 = np.zeros(t.size)
        for k in np.unique(experiment):
            rows = np.flatnonzero(experiment == k)
            dt = typical_step(t[rows], 1.0)
            gain2[rows] = filter_lambda**2 / (1.0 + filter_lambda * dt / 2.0)
    elif savgol is not None and "nu_dot_gain2" in data:
        gain2 = np.asarray(data["nu_dot_gain2"], dtype=np.float64)
    elif savgol is not None:
        gain2 = _run_gain2(t, experiment, savgol)
    else:
        gain2 = np.ones(t.size)
    if posed.any():
        order = pose_savgol[1]
        pose_gain2 = _run_gain2(
            t,
            experiment,
            pose_savgol,
            lambda window, dt: twice_differentiated_gain2(window, order, dt, filter_lambda),
        )
    noise2 = sigma**2 * float(np.nanmean(gain2[keep]))  # NaN: a sample with no derivative
    if posed.any():
        pose2 = pose_noise_variance(data, dofs, pose_columns) * pose_gain2[:, None]
        noise2[posed] = np.nanmean(pose2[keep][:, posed], axis=0)
    spread2 = np.nanvar(acc[keep], axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        share = np.where(spread2 > 0, noise2 / spread2, np.inf)
    return {d: float(r) for d, r in zip(dofs, share, strict=True)}


ATTENUATION_LIMIT = 0.10
"""The expected errors-in-variables bias of an added mass, as a fraction of its value, above
which :func:`attenuated_unknowns` names it (when the standard error does not cover it either):
well-excited logs show 1.5-5 % (docs/reference.md), weak excitation 20-40 %."""


def attenuated_unknowns(
    names: Sequence[str],
    dofs: Sequence[str],
    data: dict[str, np.ndarray],
    inertia: np.ndarray,
    estimate: dict[str, tuple[float, float]],
    savgol: tuple[float, int] | None,
    filter_lambda: float | None = None,
    from_pose: tuple[Sequence[str], tuple[float, int]] | None = None,
) -> dict[str, tuple[float, float]]:
    """The diagonal added masses of ``names`` fitted from their own DOF's equation (in
    ``dofs``) whose expected errors-in-variables bias exceeds :data:`ATTENUATION_LIMIT` of their
    value and 2 standard errors, or whose acceleration is all noise (ρ ≥ 1: bias inf):
    ``{name: (ρ, bias)}``. ``inertia`` is the diagonal of the
    fitted M = M_RB + M_A, ``estimate`` ``{name: (θ̂, s.e.)}``. Least squares shrinks the
    fitted inertia M̂ by the noise share ρ of :func:`acceleration_noise_share`, so F_jdot comes
    out high (a negative added mass too small) by about M̂ ρ / (1 − ρ): an estimate, not a
    correction (on simulated surge logs with Savitzky-Golay accelerations it accounted for the
    error within 5 %; with filtered regressors it overstated it by up to a half). ``from_pose``:
    the velocities derived from the pose, as :func:`acceleration_noise_share` reads it."""
    todo = {}
    for name in names:
        try:
            i, j = parse_added_mass_key(name)
        except ValueError:
            continue
        if i == j and DOFS[j] in dofs and name in estimate:
            todo[name] = DOFS[j]
    if not todo:
        return {}
    share = acceleration_noise_share(
        data, list(dict.fromkeys(todo.values())), savgol, filter_lambda, from_pose
    )
    out = {}
    for name, dof in todo.items():
        rho, (theta, se) = share[dof], estimate[name]
        if rho >= 1:  # the acceleration is noise: the added mass is not identified at all
            out[name] = (rho, np.inf)
            continue
        bias = inertia[DOFS.index(dof)] * rho / (1.0 - rho)
        if bias > ATTENUATION_LIMIT * abs(theta - bias) and not bias <= 2 * se:
            out[name] = (rho, float(bias))
    return out


def _is_ukf(trainer) -> bool:
    """Whether ``trainer`` (or a sequence's steps' trainer) is the unscented Kalman filter,
    which integrates the model with the inputs held and regresses on no acceleration."""
    return getattr(getattr(trainer, "trainer", trainer), "kind", "") == "ukf"


def warn_held_inputs(
    log: pd.DataFrame, fit: str, smoothed: bool, actuator_lag: float, stacklevel: int = 4
) -> None:
    """Warn (:class:`~nnid.trainers.least_squares.ExcitationWarning`) when ``fit`` regresses
    a ``smoothed`` acceleration (Savitzky-Golay or the filter F(s)) on inputs that look held
    (:func:`~nnid.datasets.preprocess.held_inputs`) at a sample time of at least
    :data:`~nnid.datasets.preprocess.HELD_DT` without
    ``zoh_midpoint``; the caller checks that setting. An acceleration logged at the sample
    sees the force of that sample, and a lagged force is continuous: neither is warned of."""
    if not smoothed or actuator_lag > 0:
        return
    held, dt = held_at(log)
    if not held or not dt >= HELD_DT:  # NaN: no sample interval
        return
    from nnid.trainers.least_squares import ExcitationWarning

    warnings.warn(
        f"{fit}: the inputs {', '.join(held)} are held between samples (at least "
        f"{100 * HELD_SHARE:.0f} % of their samples repeat the one before) at Δt = {dt:.3g} s, "
        "and the fit reads the force at a sample as the one held after it, while the smoothed "
        "acceleration there sees the forces held before and after it: a half-sample delay the "
        "fit takes for inertia (about Δt/(2T) of m − F_ν̇, T the velocity time constant; on "
        "a simulated Seamor log of held steps N_ṙ came out 19 % too large at 20 Hz, 7 % at "
        "50 Hz, and within 3 % with the setting). Set zoh_midpoint = true in [model] if the "
        "commands are held between samples (a thruster controller's, a simulator's)",
        ExcitationWarning,
        stacklevel=stacklevel,  # the caller of the model's fit
    )


def _inner_trainer(model: Any) -> Any:
    """The trainer that fitted ``model``'s parameters (its ``trainer_``; a sequence's
    ``trainer``, which fitted its last step), or None where it has none."""
    trainer = getattr(model, "trainer_", None)
    return getattr(trainer, "trainer", trainer)


#: the record names (:func:`~nnid.models.base.record_key`) of a fit's per-sample series: a
#: trainer's ``history_`` series by name, and the estimate's θ path where it is not the
#: trainer's ``theta`` (RLS and the gradient estimator keep no ``history_``; the UKF's θ path is
#: its ``theta``, saved once)
TRAINER_HISTORY = "trainer_history"
ESTIMATE_HISTORY = "estimate.history"


def saved_records(model: Any) -> tuple[dict, dict[str, torch.Tensor]]:
    """A fitted model's per-sample series as saved: their names for ``model.json``
    (``trainer_history``: the series of its trainer's ``history_``, or null where it has none;
    ``history``: the record holding the estimate's θ path, or null) and the series as float64
    tensors for ``tensors.pt``. A model loaded from a file that kept no trainer has none, and
    is saved so again."""
    state: dict = {}
    records: dict[str, np.ndarray] = {}  # record name -> series
    series = getattr(_inner_trainer(model), "history_", None) or {}
    if hasattr(model, "trainer_"):
        state[TRAINER_HISTORY] = list(series) if series else None
        records.update({f"{TRAINER_HISTORY}.{k}": v for k, v in series.items()})
    path = model.estimate_.history
    if path is None:
        state["history"] = None
    elif np.array_equal(path, series.get("theta", np.empty(0)), equal_nan=True):
        state["history"] = f"{TRAINER_HISTORY}.theta"  # the UKF's: the same numbers, once
    else:
        state["history"] = ESTIMATE_HISTORY
        records[ESTIMATE_HISTORY] = path
    return state, {record_key(k): record_tensor(v) for k, v in records.items()}


def restored_estimate_history(name: object, tensors: dict) -> np.ndarray | None:
    """The estimate's θ path as :func:`saved_records` saved it: the record ``name`` names, or
    None (null; absent from older files)."""
    if name is None:
        return None
    if name not in (ESTIMATE_HISTORY, f"{TRAINER_HISTORY}.theta"):
        raise ValueError(f"'history' names no θ path: {name!r}")
    return saved_record(tensors, str(name))


def restored_trainer_history(names: object, tensors: dict) -> dict[str, np.ndarray]:
    """A trainer's per-sample ``history_`` as :func:`saved_records` saved it (the UKF's
    ``t``, ``theta``, ``theta_std``, ``nu``, ``innovation``), checked: the series named, each
    in ``tensors.pt``, of one length. A file edited by hand is refused at loading."""
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise TypeError("'trainer_history' is not a list of series names")
    out = {n: saved_record(tensors, f"{TRAINER_HISTORY}.{n}") for n in names}
    if len({v.shape[:1] for v in out.values()}) > 1:
        raise ValueError("'trainer_history' holds series of different lengths")
    return out


def restored_attenuation(value: object, names: Sequence[str]) -> dict[str, tuple[float, float]]:
    """:func:`attenuated_unknowns`' verdict as saved, checked: ``{name: [ρ, bias]}`` over
    fitted unknowns, the numbers as :func:`~nnid.serialization.exact_float` writes them. Null
    is inf: files saved before the tag wrote the only non-finite number it holds (an
    acceleration that is all noise: bias inf) so. A file edited by hand is refused at loading."""
    if not isinstance(value, dict):
        raise TypeError("'attenuated' is not a mapping")
    out = {}
    for name, pair in value.items():
        if name not in names:
            raise ValueError(f"'attenuated' names {name!r}, which is not a fitted unknown")
        if not (isinstance(pair, list) and len(pair) == 2):
            raise TypeError(f"'attenuated' {name!r} is not [rho, bias]")
        what = f"'attenuated' {name!r}"
        rho, bias = (np.inf if v is None else read_exact_float(v, what) for v in pair)
        out[name] = (rho, bias)
    return out


def simulated_values(
    vehicle, names: Sequence[str], theta: np.ndarray
) -> tuple[dict[str, float], dict[str, float | None]]:
    """The values a fitted Fossen model simulates with (Fossen eq. 2.1 with the estimate
    plugged in): each estimate of ``theta``, and for a parameter the fit left unidentified
    (NaN) the vehicle file's value (:meth:`Parts.declared`), as a later step of Weiss's
    sequence reads it, or 0 where the file has no such term: the file's own model has none
    there, and 0 is that. Also the file's value of each unidentified one (None: no such term,
    simulated at 0), to be said (:func:`warn_simulated`)."""
    declared = Parts.from_vehicle(vehicle)
    values: dict[str, float] = {}
    from_file: dict[str, float | None] = {}
    for name, value in zip(names, theta, strict=True):
        if np.isfinite(value):
            values[name] = float(value)
        else:
            from_file[name] = declared.declared(name)
            values[name] = 0.0 if from_file[name] is None else float(from_file[name])
    return values, from_file


def warn_simulated(
    from_file: Mapping[str, float | None],
    stacklevel: int,
    at: Callable[[float | None], str] = at_file_value,
) -> None:
    """Say the values a fitted model simulates its unidentified parameters at
    (:func:`simulated_values`): its predictions rest on them, and they are no estimates.
    ``at`` says where each is taken (by default the vehicle file's value, or 0)."""
    if not from_file:
        return
    # at 0 (the old nan_to_num) an unidentified added mass or damping term vanished from
    # every simulation, unsaid, where the sequence's later steps read the file's
    said = ", ".join(f"{n} {at(v)}" for n, v in from_file.items())
    warnings.warn(
        "the fit left parameters unidentified (NaN in the estimate, without a standard "
        "error); the model simulates them at values that are not estimates, and its "
        f"predictions rest on those: {said}",
        ExcitationWarning,
        stacklevel=stacklevel + 1,
    )


def with_simulated_at(
    params: dict[str, dict[str, Any]], from_file: Mapping[str, float | None]
) -> dict[str, dict[str, Any]]:
    """``params`` with ``simulated_at`` beside each unidentified parameter: not an estimate,
    the value its model simulates it at (None in ``from_file``: at 0)."""
    for name, value in from_file.items():
        params[name] = {**params[name], "simulated_at": 0.0 if value is None else value}
    return params


#: the saved state's key of :func:`simulated_values`' ``from_file`` (absent from files saved
#: before a model simulated an unidentified parameter at the vehicle file's value)
FROM_FILE = "from_file"


def saved_from_file(from_file: Mapping[str, float | None]) -> dict[str, Any]:
    """``from_file`` as a model's saved state holds it (:func:`restored_simulated` reads it)."""
    return {n: None if v is None else exact_float(v) for n, v in from_file.items()}


def restored_simulated(
    state: Mapping[str, Any],
    vehicle,
    names: Sequence[str],
    theta: np.ndarray,
    nan_before: Mapping[str, str] | None = None,
) -> tuple[dict[str, float], dict[str, float | None]]:
    """:func:`simulated_values` of a saved model, as it was fitted and saved: the values of its
    state's ``from_file``, whatever the vehicle file says now, checked (one entry for each
    parameter the estimate leaves NaN and no other, a finite number or null: a file edited by
    hand is refused at loading). A file saved before the key simulated those parameters at 0
    (np.nan_to_num), and its metrics and plots are of that model: they stay at 0 (None in
    ``from_file``), and a warning says so. Those of ``nan_before`` (each with what 0 means)
    were not zeroed but left NaN (Caccia's W − B: a NaN buoyancy, every prediction NaN): at 0
    now, the warning says the model no longer predicts as it was saved."""
    values, from_file = simulated_values(vehicle, names, theta)
    nan_before = nan_before or {}
    if FROM_FILE not in state:
        from_file = dict.fromkeys(from_file)
        values.update(dict.fromkeys(from_file, 0.0))
        zeroed = [n for n in from_file if n not in nan_before]
        said = [
            f"it simulates {n} at 0 ({nan_before[n]}), where the saved model predicted NaN"
            for n in from_file
            if n in nan_before
        ]
        if zeroed:
            said.insert(0, "it simulates them at 0, as it did when it was fitted and saved: "
                        + ", ".join(zeroed))  # fmt: skip
        if said:
            warnings.warn(
                "the saved model predates simulating an unidentified parameter at the vehicle "
                f"file's value (it has no 'from_file'): {'; '.join(said)}",
                ExcitationWarning,
                stacklevel=2,
            )
        return values, from_file
    saved = state[FROM_FILE]
    if not isinstance(saved, dict):
        raise TypeError(f"'{FROM_FILE}' is not a mapping: {saved!r}")
    for name in saved:
        if name not in names:
            raise ValueError(f"'{FROM_FILE}' names {name!r}, which is not a fitted unknown")
        if name not in from_file:
            raise ValueError(
                f"'{FROM_FILE}' names {name!r}, whose estimate is a number: only an "
                "unidentified (NaN) one is simulated at another value"
            )
    lacking = [n for n in from_file if n not in saved]
    if lacking:
        raise ValueError(
            f"'{FROM_FILE}' lacks {lacking}, which the estimate leaves unidentified (NaN)"
        )
    for name, value in saved.items():
        number = None if value is None else read_exact_float(value, f"'{FROM_FILE}' {name!r}")
        if number is not None and not np.isfinite(number):
            raise ValueError(f"'{FROM_FILE}' {name!r} is {number}, not a number to simulate")
        from_file[name] = number
        values[name] = 0.0 if number is None else number
    return values, from_file


#: the motion columns the Fossen equation of motion reads on a row (Weiss eq. 11): ν, ν̇ and the
#: attitude of g(η) and J(η). No position enters it (a submerged vehicle's g(η) depends on
#: φ and θ alone, :func:`nnid.physics.restoring.restoring_force`): x y z are only the start
#: of a simulated pose, which no score reads (the targets are velocities)
EQUATION_COLUMNS = (*VELOCITY, *ACCELERATION, *ANGLES)


def equation_columns(columns: Iterable[str], from_pose: Iterable[str] = ()) -> list[str]:
    """The motion columns of a log with ``columns`` that a regression on the Fossen equation
    (:data:`EQUATION_COLUMNS`) reads on every row, and the pose columns each velocity derived
    from the pose is made of (``from_pose``, and each the log lacks that its pose gives:
    :func:`prepare_motion` derives it; the pose's noise is then read for its noise as well):
    :func:`~nnid.datasets.preprocess.velocity_sources`, so p q r derived from the attitude
    leave a 1-Hz GPS's x, y unread, unmasked."""
    present = set(columns)
    sources = velocity_sources(present)
    derived = {*from_pose, *(v for v in VELOCITY if v not in present)}
    read = {*EQUATION_COLUMNS, *(c for v in derived for c in sources.get(v, ()))}
    return [c for c in MOTION if c in present and c in read]


def prepare_motion(
    log: pd.DataFrame,
    dofs: Sequence[str],
    savgol_window: float,
    savgol_order: int,
    accelerations: bool,
    report: CleaningReport | None = None,
    cut_at_steps: bool = False,
    setting: str = "savgol_window",
) -> pd.DataFrame:
    """The log with the velocities of ``dofs`` derived from the pose where it lacks them, and
    (``accelerations``) their accelerations, both by Savitzky-Golay, the accelerations not
    across the steps of held inputs with ``cut_at_steps``
    (:func:`~nnid.datasets.preprocess.derive_accelerations`); each step reported. ``setting``:
    the model's key that sets ``savgol_window``, named where the window is widened or refused."""
    from nnid.datasets.preprocess import (
        check_velocities,
        derive_accelerations,
        derive_velocities,
    )

    check_velocities(log.columns, dofs)
    derived = any(d not in log for d in dofs) and all(a in log for a in ANGLES)
    if derived:
        log = derive_velocities(log, savgol_window, savgol_order, report, setting=setting)
    if accelerations and any("d" + d not in log for d in dofs):
        # derive_velocities has warned of the log's uneven runs: not said a second time
        log = derive_accelerations(
            log,
            savgol_window,
            savgol_order,
            report,
            cut_at_steps,
            setting=setting,
            warn_uneven=not derived,
        )
    return log


class FossenPlant(NnidModel):
    """A model whose fitted state is one Fossen plant (``parts_``): it predicts by simulating
    that plant (compiled RK4 from the measured state, in steps of at most
    :data:`~nnid.evaluation.prediction.MAX_STEP`: one step, k steps or free run, or in closed
    loop under the autopilot a log was flown with), and its residual is the Fossen
    equation error R = M ν̇ − (τ_eff + b − C ν + τ_D − g) of the fitted DOFs (Weiss eq. 11).

    Subclasses store ``vehicle``, ``savgol_window`` and ``savgol_order`` and set ``parts_``,
    ``structure_`` (a :class:`ParametricFossen` whose base has the fitted terms at zero) and
    ``dofs_`` in ``_fit``."""

    has_force_equation = True
    #: the settings key that sets ``savgol_window``, named where that window is refused
    #: (Caccia's is its step-2 ``velocity_window``)
    window_key: ClassVar[str] = "savgol_window"

    def _data(
        self, log: pd.DataFrame, accelerations: bool, report: CleaningReport | None = None
    ) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
        log = prepare_motion(
            log,
            self._equation_dofs(),
            self.savgol_window,
            self.savgol_order,
            accelerations,
            report,
            self._held(),
            self.window_key,
        )
        return log, log_arrays(log, self.vehicle)

    def _equation_dofs(self) -> Sequence[str]:
        """The DOFs whose velocities and accelerations :meth:`_data` derives where a log lacks
        them: the fitted DOFs, or before a fit sets them the DOFs asked for. Those outside them
        may be absent from the log and are then taken as zero (e.g. an attitude-only
        protocol)."""
        return getattr(self, "dofs_", None) or getattr(self, "dofs", DOFS)

    def acceleration_parts(self, members_scored: bool = False) -> AccelerationParts | None:
        """The residual, the Fossen equation error of :meth:`_equation_dofs`, derives their
        accelerations where a part lacks one, and it is scored in every part."""
        dofs = tuple(self._equation_dofs())
        return AccelerationParts(
            PARTS, dofs, self.savgol_window, self.savgol_order, self.window_key
        )

    def _held(self) -> bool:
        """Whether the inputs are taken as held between samples (``zoh_midpoint``): the force
        is then the midpoint at a sample, and a derived acceleration is not smoothed across
        its steps. A held input steps at each sample; a lagged force is continuous, seen as
        it is (the loop's rule: the midpoint of a 0.3-s lag's samples gave X_udot -3.7 for
        -6.4)."""
        return getattr(self, "zoh_midpoint", False) and self.vehicle.actuator_lag == 0

    def _equation_data(
        self, log: pd.DataFrame, accelerations: bool, report: CleaningReport | None = None
    ) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
        """:meth:`_data` for the equation of motion (regression, residual): with the
        ``zoh_midpoint`` setting, the force at t_k is the mean of the forces held before and
        after it, which a smoothed or filtered acceleration at t_k sees (simulations keep the
        held forces)."""
        log, data = self._data(log, accelerations, report)
        if self._held():
            data = {**data, "tau": zoh_midpoint(data["tau"], log)}
        return log, data

    def _set_outputs(self, dofs: Sequence[str]) -> None:
        self.dofs_ = tuple(dofs)
        self.outputs_ = [*POSE, *VELOCITY]
        self.targets_ = list(self.dofs_)
        self.warmup_samples_ = 1

    def _predict(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        log, data = self._data(log, accelerations=False)
        check_stepped(log)
        lag = self.vehicle.actuator_lag
        # the lag is integrated (exactly) from the commanded force, not held at its samples
        tau = nominal_forces(log, self.vehicle, lagged=False) if lag > 0 else data["tau"]
        pred = predict_states(self.parts_, log, tau, mode, substeps_for(log), lag)
        return blank_initial(pred, log, self.warmup_samples_ + mode_steps(mode) - 1)

    def closed_loop(
        self, log: pd.DataFrame, replay: Replay, mode: str | int = "free_run"
    ) -> pd.DataFrame:
        """The prediction flown under ``replay``'s autopilot (its open-loop inputs plus the
        autopilot's feedback on the simulated state), as the log was flown: free run, or k
        steps ahead from every measured state. Behind the vehicle's actuator lag the force
        felt is flown as a state, each window's started from the log's commands
        (:func:`~nnid.evaluation.prediction.predict_closed_loop`)."""
        check_is_fitted(self, msg=NOT_FITTED)
        mode = check_mode(mode)
        log, _ = self._data(check_log(log), accelerations=False)
        check_stepped(log)
        deadband = force_deadband(self.vehicle)  # the autopilot commands forces
        lag = self.vehicle.actuator_lag
        # a lag's windows start from the force felt as the log was flown: its commands, unlagged
        tau = nominal_forces(log, self.vehicle, lagged=False) if lag > 0 else None
        pred = predict_closed_loop(
            self.parts_, log, replay, mode, substeps_for(log), deadband, lag, tau
        )
        return blank_initial(pred, log, self.warmup_samples_ + mode_steps(mode) - 1)

    def _forces(self) -> list[str]:
        return [FORCES[DOFS.index(d)] for d in self.dofs_]

    def _equation(self, log: pd.DataFrame, parts: Parts) -> pd.DataFrame:
        log, data = self._equation_data(log, accelerations=True)
        r = self.structure_.equation_residual(parts, data)
        cols = self._forces()
        return pd.DataFrame(r[:, [FORCES.index(f) for f in cols]], columns=cols, index=log.index)

    def _residual(self, log: pd.DataFrame) -> pd.DataFrame:
        """R(θ̂): the force the fitted model leaves unexplained, per fitted DOF equation."""
        return self._equation(log, self.parts_)

    def _force_series(self, log: pd.DataFrame) -> pd.DataFrame:
        """R(0): the force the fitted terms explain (the regression's target, −y)."""
        return self._equation(log, self.structure_.base)

    def _check_signs(self) -> None:
        """Warn of fitted diagonal added masses and damping of the sign that adds energy, as the
        vehicle loader warns of the file's (:func:`nnid.vehicle.sign_slips`): a fit on run0
        alone gave Z:w*abs(w) = +1565, said only as a diverged free run."""
        from nnid.vehicle import sign_slips

        theta = self.estimate_.theta
        fitted = {n: float(v) for n, v in zip(self.estimate_.names, theta, strict=True)}
        try:
            vehicle = vehicle_with(self.vehicle, {n: v for n, v in fitted.items() if v == v})
        except ValueError:  # an installation coefficient out of its range: said elsewhere
            return
        declared = set(sign_slips(self.vehicle))
        for slip in sign_slips(vehicle):
            if slip not in declared:
                warnings.warn(
                    f"the fitted {slip}: the data do not determine it (weak or one-sided "
                    "excitation), and a free run of this model can gain energy",
                    PhysicsWarning,
                    stacklevel=3,
                )

    def _check_mass(self) -> None:
        """Warn of a fitted mass matrix no vehicle has: the rigid body first, as a vehicle
        file's is checked (:func:`nnid.vehicle.check_rigid_body`; a fitted r_g can break
        M_RB, and the added mass was blamed for it), then M = M_RB + M_A."""
        from nnid.vehicle import check_rigid_body

        parts = self.parts_
        fitted = [n for n in self.estimate_.names if n.startswith("r_g.")]
        try:
            check_rigid_body(parts.mass, parts.r_g, parts.inertia, fitted)
        except NnidInputError as exc:  # a warning: the fit stands, its r_g is said
            warnings.warn(exc.message, PhysicsWarning, stacklevel=3)
            return
        mass = parts.model(check=False).mass_matrix().numpy()
        if np.linalg.eigvalsh(0.5 * (mass + mass.T)).min() <= 0:
            warnings.warn(
                "the identified mass matrix M = M_RB + M_A is not positive definite (an added "
                "mass outweighs the rigid body): the data do not determine the inertia, and "
                "simulations of this model are meaningless",
                PhysicsWarning,
                stacklevel=3,
            )


class ParametricModel(FossenPlant):
    """The parametric Fossen model as an estimator (Weiss eqs 47-53, 99-108).

    ``ParametricModel(vehicle, unknowns, dofs, trainer=LeastSquares())`` then ``fit(log)``: the
    trainer (least squares, RLS, the gradient estimator or the UKF) estimates the ``unknowns``
    from the ``dofs`` equations; ``unknowns`` may use the shortcuts ``added_mass`` and
    ``damping`` (:func:`expand_unknowns`). ``sequence`` ("weiss" or a list of steps with
    ``experiments``, ``dofs`` and ``unknowns``) runs Weiss's decoupled sequence (eqs 99-108)
    with that trainer; the unknowns and DOFs are then the union of its steps'. Velocities (and
    accelerations, unless the trainer filters) are derived from the pose by Savitzky-Golay
    (``savgol_window`` s, ``savgol_order``) where the log lacks them; what was derived is in
    ``report_``. ``zoh_midpoint`` regresses on the mean of consecutive inputs, the force a
    smoothed acceleration at a sample sees when commands are held between samples (without it
    a 20 Hz log of held commands biases the added mass by ~20 %). ``pose_velocities``: the
    velocity columns of the logs that were derived from the pose before the fit, with the
    (window s, order) ``pose_savgol`` of that derivative (None: this model's); ``nnid train``
    sets both from its cleaning report and its ``[data]``. Their noise is the pose's,
    smoothed, as for those the model derives itself (the excitation checks). ``params`` holds each
    estimate with its standard error, Caccia's percentile error and the 51.02 % significance
    flag.
    """

    kind = "fossen"

    def __init__(
        self,
        vehicle,
        unknowns: Sequence[str] = ("added_mass", "damping"),
        dofs: Sequence[str] = DOFS,
        trainer=None,
        sequence: str | Sequence | None = None,
        savgol_window: float = 1.0,
        savgol_order: int = 4,
        zoh_midpoint: bool = False,
        pose_velocities: Sequence[str] = (),
        pose_savgol: tuple[float, int] | None = None,
    ) -> None:
        self.vehicle = vehicle
        self.unknowns = unknowns
        self.dofs = dofs
        self.trainer = trainer
        self.sequence = sequence
        self.savgol_window = savgol_window
        self.savgol_order = savgol_order
        self.zoh_midpoint = zoh_midpoint
        self.pose_velocities = pose_velocities
        self.pose_savgol = pose_savgol

    def motion_columns(self, columns: Iterable[str]) -> list[str]:
        """A regression's columns (:func:`equation_columns`; those of the pose a velocity
        was derived from too, ``pose_velocities``); with a trainer of any kind but ls, rls or
        gradient (the UKF), every motion column: the UKF propagates the whole measured state
        η, ν (Weiss eq. 80), a position too."""
        if getattr(self.trainer, "kind", "ls") not in ("ls", "rls", "gradient"):
            return super().motion_columns(columns)
        return equation_columns(columns, self.pose_velocities)

    def _trainer(self) -> Any:
        """A fresh trainer of this model's settings: ``trainer`` (least squares if None),
        stepped through ``sequence`` where one is given."""
        from nnid.trainers.sequence import DecoupledSequence, sequence_steps

        trainer = regression_trainer(self.trainer)
        if self.sequence is not None:
            return DecoupledSequence(sequence_steps(self.sequence), trainer)
        return trainer

    def _equation_dofs(self) -> Sequence[str]:
        """As :meth:`FossenPlant._equation_dofs`; before a fit with a ``sequence``, the DOFs of
        its steps, which the fit takes instead of ``dofs``."""
        if getattr(self, "dofs_", None) or self.sequence is None:
            return super()._equation_dofs()
        from nnid.trainers.sequence import sequence_dofs, sequence_steps

        return sequence_dofs(sequence_steps(self.sequence))

    def _settings(self) -> tuple[list[str], list[str], ParametricFossen]:
        """The DOFs, the unknowns and the regression structure the settings give, each
        checked (by ``fit``, and on load: a hand-edited model.json loaded a DOF 'x', an unknown
        'bogus' or a window "1" without a word, and detect ran on it)."""
        from nnid.trainers.sequence import sequence_dofs, sequence_steps

        checked_number(self.savgol_window, "savgol_window")
        # as the config bounds it: a Savitzky-Golay polynomial of order 2 to 8
        checked_number(self.savgol_order, "savgol_order", 2, strict=False, integer=True, maximum=8)
        if not isinstance(self.zoh_midpoint, bool | np.bool_):
            raise NnidInputError(
                f"true or false is expected, not {self.zoh_midpoint!r}", field="zoh_midpoint"
            )
        if self.sequence is not None:
            steps = sequence_steps(self.sequence)
            unknowns = list(dict.fromkeys(n for s in steps for n in s.unknowns))
            dofs = sequence_dofs(steps)
        else:
            dofs = list(checked_dofs(self.dofs))
            unknowns = expand_unknowns(self.unknowns, dofs, self.vehicle)
        try:
            return dofs, unknowns, ParametricFossen(self.vehicle, unknowns, dofs)
        except NnidInputError as exc:  # with a sequence, the unknowns are its steps'
            if self.sequence is None or exc.field != "unknowns":
                raise
            raise NnidInputError(f"a step's unknowns: {exc.message}", field="sequence") from None

    def parameter_names(self) -> list[str]:
        """The regression's parameters, as :meth:`_settings` gives them (the estimate's names)."""
        return list(self._settings()[2].names)

    def _fit(self, log: pd.DataFrame, validation, progress: Progress) -> None:
        trainer = self._trainer()
        dofs, unknowns, self.structure_ = self._settings()
        if self.sequence is None:  # a sequence's steps name their unknowns one by one
            # refused where it leaves nothing to estimate; beside what is estimated, said
            check_damping_group(self.unknowns, dofs, self.vehicle, strict=not unknowns)
        self._set_outputs(dofs)
        self.report_ = CleaningReport(source="fit data")
        needs_acc = getattr(trainer, "filter_lambda", None) is None
        prepared, data = self._equation_data(log, accelerations=needs_acc, report=self.report_)
        if unknowns:
            self.estimate_ = trainer.fit(self.structure_, data, progress=progress)
        else:  # no trainer runs (a UKF cannot, on no parameters): said, and trainer_name() None
            from nnid.trainers.least_squares import LeastSquares

            # unknowns = [] (a group naming nothing is refused above)
            given = f"unknowns = {list(self.unknowns)}"
            warnings.warn(NOTHING_ESTIMATED.format(given), UserWarning, stacklevel=3)
            # a regression of no columns: the equation error of the file's values, measured
            lam = getattr(trainer, "filter_lambda", None)
            self.estimate_ = LeastSquares(filter_lambda=lam).fit(self.structure_, data, progress)
        self.trainer_ = trainer
        values, self.from_file_ = simulated_values(
            self.vehicle, self.estimate_.names, self.estimate_.theta
        )
        self.parts_ = self.structure_.parts(values)
        warn_simulated(self.from_file_, stacklevel=3)
        steps = self._step_data(data, dofs, unknowns)
        by_step = self._not_excited(steps, getattr(trainer, "filter_lambda", None))
        self.not_excited_ = self._last_verdicts(steps, by_step)
        self.estimate_ = self._noise_judged(self.estimate_)  # as saved, and as its table says
        if self.not_excited_:
            from nnid.trainers.least_squares import ExcitationWarning

            dofs_left = sorted({d for ds in self.not_excited_.values() for d in ds}, key=DOFS.index)
            # a sequence's log may move v in one run and not in the step that fits Y_vdot:
            # "the fit data" would then name data that do excite it
            where = "the fit data do not excite"
            if self.sequence is not None:
                judged = [
                    ", ".join(n for n in found if n in self.not_excited_) for found in by_step
                ]
                where = (
                    "the runs of the sequence steps that fit them ("
                    + ", ".join(f"step {k + 1}: {n}" for k, n in enumerate(judged) if n)
                    + ") do not excite"
                )
            warnings.warn(
                f"{where} {', '.join(dofs_left)} (their velocities stay "
                "within 3 times their noise): these unknowns are fitted to noise, not "
                "identified, and reported as not significant, without standard errors (theirs "
                "would not hold): "
                f"{', '.join(self.not_excited_)}",
                ExcitationWarning,
                stacklevel=3,
            )
        rested = self._rested_on_noise(
            steps,
            by_step,
            getattr(trainer, "filter_lambda", None),
            getattr(trainer, "unidentified_", None),
        )
        if rested:
            from nnid.trainers.least_squares import ExcitationWarning

            warnings.warn(
                "later sequence steps take as known values that an earlier step fitted to "
                "noise (their velocities stay within 3 times their noise in its runs), and their "
                "estimates rest on them; their standard errors do not include that error: "
                + "; ".join(rested),
                ExcitationWarning,
                stacklevel=3,
            )
        if not self.zoh_midpoint and not _is_ukf(trainer):
            # the UKF integrates the model with the inputs held: it reads them as they are
            smoothed = not needs_acc or self._derived_accelerations()
            warn_held_inputs(log, "the Fossen fit", smoothed, self.vehicle.actuator_lag)
        self.attenuated_ = self._attenuated(trainer, unknowns, dofs, data, prepared)
        if self.attenuated_:
            from nnid.trainers.least_squares import ExcitationWarning

            fitted = dict(zip(self.estimate_.names, self.estimate_.theta, strict=True))
            said = "; ".join(
                f"{n} = {fitted[n]:.3g} is not identified (the noise is "
                f"{100 * rho:.0f} % of the {DOFS[parse_added_mass_key(n)[1]]} acceleration's "
                "variance)"
                if not np.isfinite(bias)
                else f"{n} = {fitted[n]:.3g} is about {bias:.3g} too high, near "
                f"{fitted[n] - bias:.3g} ({100 * bias / abs(fitted[n] - bias):.0f} %; noise "
                f"{100 * rho:.0f} % of the {DOFS[parse_added_mass_key(n)[1]]} acceleration's "
                "variance)"
                for n, (rho, bias) in self.attenuated_.items()
            )
            warnings.warn(
                "the accelerations are weakly excited against the noise of their derivative "
                "(errors in variables): least squares shrinks the fitted inertia m − F_jdot, "
                f"and these added masses are biased by more than {100 * ATTENUATION_LIMIT:.0f} % "
                f"and 2 standard errors, which their standard errors do not include: {said}; "
                "excite the accelerations more (larger or faster input changes)",
                ExcitationWarning,
                stacklevel=3,
            )
        self._check_mass()
        self._check_signs()

    def trainer_name(self) -> str | None:
        """As :meth:`NnidModel.trainer_name`; None where the fit estimated nothing (no
        unknowns: the vehicle file as written, which no trainer fitted)."""
        estimate = getattr(self, "estimate_", None)
        if estimate is not None and not estimate.names:
            return None
        return super().trainer_name()

    def _from_pose(self) -> tuple[list[str], tuple[float, int]] | None:
        """The velocity columns the fit derived from the pose (its report's "derive
        velocities") and the (window s, order) of that derivative, or None: their noise is
        the pose's, smoothed (:func:`unexcited_unknowns`, :func:`attenuated_unknowns`)."""
        if self.pose_velocities:  # derived before the fit (nnid train), with their window
            window = self.pose_savgol or (self.savgol_window, self.savgol_order)
            return list(self.pose_velocities), (float(window[0]), int(window[1]))
        posed = [c for s in self.report_.steps if s.step == "derive velocities" for c in s.columns]
        return (posed, (self.savgol_window, self.savgol_order)) if posed else None

    def _derived_accelerations(self) -> bool:
        """Whether the fit's accelerations were derived from the log (Savitzky-Golay), as its
        cleaning report records, rather than logged."""
        return any(s.step == "derive accelerations" for s in self.report_.steps)

    def _step_data(
        self, data: dict[str, np.ndarray], dofs: list[str], unknowns: list[str]
    ) -> list[tuple[Any, dict[str, np.ndarray]]]:
        """The fit's steps, each with the rows of its experiments and the unknowns whose
        values it gives the estimate: a sequence's (Weiss eqs 99-108; a refit that could not
        identify an earlier step's value gives none: the trainer's ``kept_``), else one step of
        every unknown on all of ``data``."""
        from nnid.trainers.sequence import Step, _subset, sequence_steps

        if self.sequence is None:
            return [(Step([], dofs, unknowns), data)]
        steps = sequence_steps(self.sequence)
        kept = getattr(self.trainer_, "kept_", None) or [[] for _ in steps]
        return [
            (
                Step(
                    s.experiments,
                    s.dofs,
                    [u for u in s.unknowns if canonical_parameter(u) not in old],
                ),
                _subset(data, s.experiments),
            )
            for s, old in zip(steps, kept, strict=True)
        ]

    def _not_excited(
        self, steps: list[tuple[Any, dict[str, np.ndarray]]], filter_lambda: float | None = None
    ) -> list[dict[str, list[str]]]:
        """:func:`unexcited_unknowns` of each step's unknowns on its own experiments, from the
        step's equations (fitted with ``filter_lambda``). On the whole log of a sequence a sway
        run moved v, while the surge step fitted Y_vdot, which its equation reads through v r
        only, to v's noise (a regressor of noise times noise, which Weiss eq. 95 does not
        see): its s.e. 258 % of it, and no check named it."""
        from_pose = self._from_pose()
        return [
            unexcited_unknowns(
                [canonical_parameter(n) for n in step.unknowns],
                subset,
                from_pose,
                structure=self.structure_,
                dofs=step.dofs,
                filter_lambda=filter_lambda,
            )
            for step, subset in steps
        ]

    def _last_verdicts(
        self, steps: list[tuple[Any, dict[str, np.ndarray]]], by_step: list[dict[str, list[str]]]
    ) -> dict[str, list[str]]:
        """Each parameter's verdict of :meth:`_not_excited` from the last step that fits it,
        whose value it keeps, in the estimate's order."""
        out: dict[str, list[str]] = {}
        for (step, _), found in zip(steps, by_step, strict=True):
            for name in step.unknowns:
                out.pop(canonical_parameter(name), None)
            out.update(found)
        return {n: out[n] for n in self.estimate_.names if n in out}

    def _rested_on_noise(
        self,
        steps: list[tuple[Any, dict[str, np.ndarray]]],
        by_step: list[dict[str, list[str]]],
        filter_lambda: float | None,
        unidentified: list[list[str]] | None = None,
    ) -> list[str]:
        """Each later step of a sequence that takes as known a value an earlier step fitted to
        noise (:meth:`_not_excited`) and whose estimates rest on it (the unknowns its equations
        read it beside, or joined to those through an equation, on the later step's runs:
        :func:`~nnid.trainers.sequence.resting_on`), said as "step j (dofs) takes NAME from
        step k, for" those. A value a step left NaN (``unidentified``, per step) is not taken:
        the later steps read the vehicle file's, as the sequence says."""
        from nnid.trainers.sequence import resting_on, step_label

        said = []
        source: dict[str, int] = {}  # the step whose value a parameter holds so far
        for j, (step, subset) in enumerate(steps):
            names = [canonical_parameter(n) for n in step.unknowns]
            for name, k in source.items():
                if name in names or name not in by_step[k]:
                    continue
                rest = resting_on(self.structure_, name, step, subset, filter_lambda, names)
                if rest:  # read only where no unknown is: no estimate of the step moves with it
                    said.append(
                        f"{step_label(j, step)} takes {name} from step {k + 1}, "
                        f"for {', '.join(rest)}"
                    )
            source.update(dict.fromkeys(names, j))
            for name in [] if unidentified is None else unidentified[j]:
                source.pop(name, None)
        return said

    def _attenuated(
        self,
        trainer,
        unknowns: list[str],
        dofs: list[str],
        data: dict[str, np.ndarray],
        log: pd.DataFrame,
    ) -> dict[str, tuple[float, float]]:
        """:func:`attenuated_unknowns` of the fit, step by step for a sequence (each on its
        experiments, :meth:`_step_data`; a later step's verdict replaces an earlier one's), not
        judged for the UKF, which regresses on no acceleration. ``log``: the fit's, as its
        accelerations were derived from it (their noise gain where they were cut at held
        steps)."""
        from nnid.datasets.preprocess import acceleration_gain2

        if _is_ukf(trainer):
            return {}
        derived = self._derived_accelerations()
        savgol = (self.savgol_window, self.savgol_order) if derived else None
        if derived and self._held():  # cut at the steps: each piece's own gain
            gain2 = acceleration_gain2(log, self.savgol_window, self.savgol_order, True)
            data = {**data, "nu_dot_gain2": gain2}
        from_pose = self._from_pose()
        lam = getattr(trainer, "filter_lambda", None)
        inertia = np.diag(self.parts_.model(check=False).mass_matrix().numpy())
        est = self.estimate_
        values = dict(zip(est.names, zip(est.theta, est.stderr, strict=True), strict=True))
        values = {
            n: v for n, v in values.items() if np.isfinite(v[0]) and n not in self.not_excited_
        }
        out: dict[str, tuple[float, float]] = {}
        for step, subset in self._step_data(data, dofs, unknowns):
            for name in step.unknowns:
                out.pop(name, None)
            out.update(
                attenuated_unknowns(
                    step.unknowns, step.dofs, subset, inertia, values, savgol, lam, from_pose
                )
            )
        return out

    def _noise_judged(self, est: Estimate) -> Estimate:
        """``est`` whose excitation report says of the parameters the model's own check of
        the fit data judged fitted to noise (``not_excited_``) what the table says: not a
        recursive estimator's "remembered", which that check overrides (whatever earlier
        samples excited, the run's motion is noise). Its saved report and warnings said
        remembered beside a table that said fitted to noise."""
        report = est.excitation
        if report is None or not set(report.remembered) & set(self.not_excited_):
            return est
        kept = [n for n in report.remembered if n not in self.not_excited_]
        return dataclasses.replace(est, excitation=report.with_remembered(kept))

    def _params(self) -> dict[str, dict[str, float | None]]:
        params = self._noise_judged(self.estimate_).as_dict()
        # fitted to noise: no verdict of significance, and no standard error, whose noise
        # model does not hold there (unexcited_unknowns); every report then shows none
        for name in self.not_excited_:
            params[name] = {
                **params[name],
                "stderr": None,
                "percentile_error": None,
                "significant": False,
                "excited": False,
            }
        # not an estimate: the value the model simulates it at, said beside the missing one
        return with_simulated_at(params, self.from_file_)

    def describe(self) -> dict:
        return {**super().describe(), "vehicle": self.vehicle.name, "dofs": list(self.dofs_)}

    def _state(self) -> tuple[dict, dict]:
        state = {"dofs": list(self.dofs_), **self.estimate_.as_state()}
        # what the fit derived and judged, as the fitted model holds it: a loaded model lacked
        # report_ and attenuated_ (its warnings' grounds) that the fitted one had
        fit = {
            "report": self.report_.to_dict(),
            "attenuated": {n: [exact_float(v) for v in p] for n, p in self.attenuated_.items()},
        }
        # and what it recorded per sample (the UKF's history_, a recursive θ path): a loaded
        # model had no trainer_ at all; series, not scalars, so tensors (none: no tensors.pt)
        records, tensors = saved_records(self)
        # the unidentified parameters it simulates at the vehicle file's values (None: at 0)
        fit[FROM_FILE] = saved_from_file(self.from_file_)
        return {**state, "not_excited": dict(self.not_excited_), **fit, **records}, tensors

    def _restore(self, state: dict, tensors: dict) -> None:
        from nnid.trainers.least_squares import Estimate

        self._trainer()  # the trainer setting checked, as the settings below
        dofs = self._settings()[0]
        if list(state["dofs"]) != dofs:  # predicted on the state's, refitted on the settings'
            raise NnidInputError(
                f"{dofs} are not the DOFs the model was fitted on (state.dofs: "
                f"{list(state['dofs'])})",
                field="dofs",
            )
        self._set_outputs(state["dofs"])
        path = restored_estimate_history(state.get("history"), tensors)
        self.estimate_ = Estimate.from_state(state, path)
        self.not_excited_ = {k: list(v) for k, v in state.get("not_excited", {}).items()}
        self.estimate_ = self._noise_judged(self.estimate_)  # files saved before it was
        if "report" in state:  # absent from older files: the run folder's cleaning report
            self.report_ = CleaningReport.from_dict(state["report"])
            self.attenuated_ = restored_attenuation(state["attenuated"], self.estimate_.names)
        self.structure_ = ParametricFossen(self.vehicle, self.estimate_.names, self.dofs_)
        # what the fit simulated, whatever the vehicle file says now
        values, self.from_file_ = restored_simulated(
            state, self.vehicle, self.estimate_.names, self.estimate_.theta
        )
        self.parts_ = self.structure_.parts(values)
        if TRAINER_HISTORY in state:  # absent from older files: no trainer_, as before
            self.trainer_ = self._trainer()
            if state[TRAINER_HISTORY] is not None:
                history = restored_trainer_history(state[TRAINER_HISTORY], tensors)
                _inner_trainer(self).history_ = history
