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

import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd
import torch
from scipy.signal import lfilter, lfilter_zi

from nnid.datasets.log import ANGLES, POSE, TAU, VELOCITY
from nnid.models.damping_library import canonical_term, evaluate_terms, term_codes
from nnid.physics.added_mass import DOFS, FORCES, added_mass_matrix, parse_added_mass_key
from nnid.physics.damping import DampingTerms, parse_coefficient_key
from nnid.physics.fossen import FossenModel
from nnid.physics.thrusters import Actuation, apply_installation

_AXES = "xyz"


class PhysicsWarning(UserWarning):
    """An estimate that no physical vehicle can have."""


def canonical_parameter(name: str) -> str:
    """Validate a parameter name and return its canonical spelling."""
    if re.fullmatch(r"[XYZKMN]_[uvwpqr]dot", name):
        parse_added_mass_key(name)
        return name
    if ":" in name:
        force, term = parse_coefficient_key(name)
        return f"{force}:{term}"
    if re.fullmatch(r"eta\.[uvwpqr]\.(pos|neg)", name):
        return name
    if re.fullmatch(r"external_bias\.[uvwpqr]", name) or name in ("weight", "buoyancy"):
        return name
    if re.fullmatch(r"r_[gb]\.[xyz]", name):
        return name
    raise ValueError(
        f"unknown parameter '{name}'; expected an added-mass derivative ('X_udot'), a damping "
        "coefficient ('X:u*abs(u)'), 'eta.<dof>.<pos|neg>', 'external_bias.<dof>', 'weight', "
        "'buoyancy', 'r_g.<x|y|z>' or 'r_b.<x|y|z>'"
    )


@dataclass
class Regression:
    """Φ θ = y stacked sample-major over the chosen DOF equations."""

    phi: np.ndarray  # [N * len(dofs), P]
    y: np.ndarray  # [N * len(dofs)]
    names: list[str]
    dofs: tuple[str, ...]
    n_samples: int

    def dof_rows(self, dof: str) -> np.ndarray:
        """Row indices of one DOF's equation."""
        k = self.dofs.index(dof)
        return np.arange(self.n_samples) * len(self.dofs) + k


@dataclass
class Parts:
    """The numbers that define a plant for the regression and the simulator."""

    mass: float
    inertia: np.ndarray
    r_g: np.ndarray
    r_b: np.ndarray
    weight: float
    buoyancy: float
    added_mass: dict[str, float]
    damping: dict[str, float]
    eta_pos: np.ndarray
    eta_neg: np.ndarray
    bias: np.ndarray
    u_c: float = 0.0
    current: np.ndarray | None = None  # steady water current, NED (m/s)

    def copy(self) -> Parts:
        return Parts(
            self.mass,
            self.inertia.copy(),
            self.r_g.copy(),
            self.r_b.copy(),
            self.weight,
            self.buoyancy,
            dict(self.added_mass),
            dict(self.damping),
            self.eta_pos.copy(),
            self.eta_neg.copy(),
            self.bias.copy(),
            self.u_c,
            None if self.current is None else self.current.copy(),
        )

    @classmethod
    def from_vehicle(cls, vehicle) -> Parts:
        damping = DampingTerms.from_spec(
            vehicle.damping.model, vehicle.damping.coefficients, vehicle.damping.u_c
        ).as_dict()
        pos, neg = vehicle.installation_vectors()
        return cls(
            vehicle.mass,
            vehicle.inertia_matrix().astype(float),
            np.array(vehicle.r_g, float),
            np.array(vehicle.r_b, float),
            float(vehicle.weight),
            float(vehicle.buoyancy),
            dict(vehicle.added_mass),
            damping,
            pos,
            neg,
            np.array(vehicle.external_bias, float),
            vehicle.damping.u_c,
            np.array(vehicle.current, float),
        )

    def set(self, name: str, value: float) -> None:
        """Set one parameter by its name (see :func:`canonical_parameter`)."""
        if name.endswith("dot") and "_" in name and ":" not in name:
            self.added_mass[name] = value
        elif ":" in name:
            self.damping[name] = value
        elif name.startswith("eta."):
            _, dof, sign = name.split(".")
            (self.eta_pos if sign == "pos" else self.eta_neg)[DOFS.index(dof)] = value
        elif name.startswith("external_bias."):
            self.bias[DOFS.index(name.split(".")[1])] = value
        elif name in ("weight", "buoyancy"):
            setattr(self, name, value)
        else:
            (self.r_g if name.startswith("r_g") else self.r_b)[_AXES.index(name[-1])] = value

    def get(self, name: str) -> float:
        if name.endswith("dot") and ":" not in name:
            return float(self.added_mass.get(name, 0.0))
        if ":" in name:
            return float(self.damping.get(name, 0.0))
        if name.startswith("eta."):
            _, dof, sign = name.split(".")
            return float((self.eta_pos if sign == "pos" else self.eta_neg)[DOFS.index(dof)])
        if name.startswith("external_bias."):
            return float(self.bias[DOFS.index(name.split(".")[1])])
        if name in ("weight", "buoyancy"):
            return float(getattr(self, name))
        return float((self.r_g if name.startswith("r_g") else self.r_b)[_AXES.index(name[-1])])

    def model(self, check: bool = True) -> FossenModel:
        """The Fossen model of these parts (installation: see :meth:`applied`). ``check=False``
        skips the positive-definite test, for the unit probes of the regression."""
        terms = tuple(dict.fromkeys(parse_coefficient_key(k)[1] for k in self.damping))
        coef = torch.zeros(6, len(terms), dtype=torch.float64)
        for key, value in self.damping.items():
            force, term = parse_coefficient_key(key)
            coef[FORCES.index(force), terms.index(term)] = value
        return FossenModel(
            self.mass,
            self.inertia,
            added_mass_matrix(self.added_mass),
            DampingTerms(terms, coef, u_c=self.u_c),
            self.weight,
            self.buoyancy,
            self.r_g,
            self.r_b,
            external_bias=self.bias,
            current=(0.0, 0.0, 0.0) if self.current is None else self.current,
            check=check,
        )

    def applied(self, tau_nominal: np.ndarray) -> np.ndarray:
        """τ_eff = η(sign) τ per DOF (Caccia eq. 3)."""
        return apply_installation(tau_nominal, self.eta_pos, self.eta_neg)


def log_arrays(log: pd.DataFrame, vehicle) -> dict[str, np.ndarray]:
    """η, ν, ν̇ and nominal τ from a log (missing pose components are zero; velocities and
    accelerations must be present: derive them with :mod:`nnid.datasets.preprocess`)."""
    n = len(log)
    eta = np.zeros((n, 6))
    for k, c in enumerate(POSE):
        if c in log:
            eta[:, k] = log[c].to_numpy(np.float64)
    nu = np.zeros((n, 6))
    nu_dot = np.zeros((n, 6))
    for k, c in enumerate(VELOCITY):
        if c in log:
            nu[:, k] = log[c].to_numpy(np.float64)
        if "d" + c in log:
            nu_dot[:, k] = log["d" + c].to_numpy(np.float64)
    if all(c in log for c in TAU):
        tau = log[list(TAU)].to_numpy(np.float64)
    else:
        act = Actuation(vehicle)
        cols = [f"cmd_{c}" for c in act.channels]
        missing = [c for c in cols if c not in log]
        if missing:
            raise ValueError(f"the log has neither tau_X..tau_N nor the commands {missing}")
        tau = act.nominal(log[cols].to_numpy(np.float64))
    if "experiment" in log:
        codes, names = pd.factorize(log["experiment"])
    else:
        codes, names = np.zeros(n, dtype=int), ["0"]
    return {
        "eta": eta,
        "nu": nu,
        "nu_dot": nu_dot,
        "tau": tau,
        "angles_known": np.array(all(a in log for a in ANGLES)),
        "t": log["t"].to_numpy(np.float64),
        "experiment": codes,
        "experiment_names": np.asarray(names, dtype=object),
    }


def relative_velocity(parts: Parts, data: dict[str, np.ndarray]) -> np.ndarray:
    """ν_r = ν − ν_c(η), the velocity through the water that damping acts on (Fossen 2011
    eq. 10.1); ν itself in still water."""
    if parts.current is None or not np.any(parts.current):
        return data["nu"]
    with torch.no_grad():
        nu_c = parts.model(check=False).current_body(torch.as_tensor(data["eta"])).numpy()
    return data["nu"] - nu_c


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
            out["added_mass"][name] = value
        elif name.startswith("eta."):
            out["installation"][name[4:]] = value
        elif name.startswith("external_bias."):
            out["external_bias"][DOFS.index(name.split(".")[1])] = value
        elif name in ("weight", "buoyancy"):
            out[name] = value
        else:
            out[name[:3]][_AXES.index(name[-1])] = value
    return type(vehicle).model_validate(out)


class ParametricFossen:
    """The regression structure: a vehicle, the unknown parameters and the DOF equations used."""

    def __init__(self, vehicle, unknowns: Sequence[str], dofs: Sequence[str] = DOFS) -> None:
        self.vehicle = vehicle
        self.names = [canonical_parameter(n) for n in unknowns]
        if len(set(self.names)) != len(self.names):
            raise ValueError("unknown parameters must be unique")
        self.dofs = tuple(dofs)
        for d in self.dofs:
            if d not in DOFS:
                raise ValueError(f"'{d}' is not a DOF; expected u v w p q r")
        if {"weight", "buoyancy"} & set(self.names):
            pair = {"weight": "r_g.", "buoyancy": "r_b."}
            for n in self.names:
                for w, r in pair.items():
                    if w in self.names and n.startswith(r):
                        raise ValueError(
                            f"'{w}' and '{n}' multiply each other: identify their "
                            "moment instead, or fix one of them"
                        )
        self.base = Parts.from_vehicle(vehicle)
        for name in self.names:  # unknowns start from zero in R(0)
            self.base.set(name, 0.0)

    def parts(self, theta: Sequence[float] | dict) -> Parts:
        """The vehicle's parts with the unknowns set to ``theta``."""
        values = theta if isinstance(theta, dict) else dict(zip(self.names, theta, strict=True))
        out = self.base.copy()
        for name, value in values.items():
            out.set(name, float(value))
        return out

    def equation_residual(
        self, parts: Parts, data: dict[str, np.ndarray], filter_lambda: float | None = None
    ) -> np.ndarray:
        """R = M ν̇ − (τ_eff + b − C ν + τ_D − g) per sample ``[N, 6]``.

        With ``filter_lambda`` = λ both sides pass through F(s) = λ/(s + λ) and M F[ν̇] is
        computed as M sF(s)[ν] from the velocity: the filtered-regressor form of Weiss eqs
        86-92, which needs no differentiated (noisy) acceleration.
        """
        model = parts.model(check=False)
        with torch.no_grad():
            eta, nu = torch.as_tensor(data["eta"]), torch.as_tensor(data["nu"])
            tau = torch.as_tensor(parts.applied(data["tau"]))
            net = model.net_force(eta, nu, tau).numpy()
            mass = model.mass_matrix().numpy()
        if filter_lambda is None:
            return data["nu_dot"] @ mass.T - net
        nu_dot_f = filter_signal(data, data["nu"], filter_lambda, derivative=True)
        return nu_dot_f @ mass.T - filter_signal(data, net, filter_lambda)

    def regression(
        self, data: dict[str, np.ndarray], filter_lambda: float | None = None
    ) -> Regression:
        """Φ θ = y over the chosen DOF equations; φ_k = R(e_k) − R(0), y = −R(0).

        With ``filter_lambda`` the filtered form is used (see :meth:`equation_residual`) and
        the first 3/λ seconds of each experiment, where the filters settle, are left out.
        """
        rows = [DOFS.index(d) for d in self.dofs]
        r0 = self.equation_residual(self.base, data, filter_lambda)
        keep = np.ones(r0.shape[0], dtype=bool)
        if filter_lambda is not None:
            keep = settled_rows(data, 3.0 / filter_lambda)
        damping = self.damping_columns(data, filter_lambda)
        cols = []
        for name in self.names:
            if name in damping:
                col = damping[name]
            else:
                unit = self.base.copy()
                unit.set(name, 1.0)
                col = self.equation_residual(unit, data, filter_lambda) - r0
            cols.append(col[keep][:, rows].reshape(-1))
        n = int(keep.sum())
        phi = np.stack(cols, 1) if cols else np.zeros((n * len(rows), 0))
        return Regression(phi, -r0[keep][:, rows].reshape(-1), list(self.names), self.dofs, n)

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
        names = [n for n in self.names if ":" in n]
        if not names:
            return {}
        split = [parse_coefficient_key(n) for n in names]
        nu = relative_velocity(self.base, data)
        xi = evaluate_terms(nu, term_codes([t for _, t in split]), self.base.u_c)
        if filter_lambda is not None:
            xi = filter_signal(data, xi, filter_lambda)
        out = {}
        for k, (name, (force, _)) in enumerate(zip(names, split, strict=True)):
            col = np.zeros((xi.shape[0], 6))
            col[:, FORCES.index(force)] = -xi[:, k]
            out[name] = col
        return out

    def term_names(self) -> list[str]:
        return [canonical_term(n.split(":")[1]) for n in self.names if ":" in n]


def filter_signal(data: dict[str, np.ndarray], x: np.ndarray, lam: float, derivative: bool = False):
    """F(s) = λ/(s + λ) (or s F(s) for the derivative) per experiment, discretised by the
    bilinear transform so that the two stay consistent; started in steady state."""
    out = np.empty_like(x)
    for k in np.unique(data["experiment"]):
        idx = np.flatnonzero(data["experiment"] == k)
        dt = float(np.median(np.diff(data["t"][idx]))) if idx.size > 1 else 1.0
        c = lam * dt / 2.0
        a = np.array([1.0 + c, -(1.0 - c)])
        b = lam * np.array([1.0, -1.0]) if derivative else np.array([c, c])
        zi = lfilter_zi(b, a)
        seg = x[idx]
        out[idx] = lfilter(b, a, seg, axis=0, zi=zi[:, None] * seg[:1])[0]
    return out


def settled_rows(data: dict[str, np.ndarray], seconds: float) -> np.ndarray:
    keep = np.ones(data["t"].size, dtype=bool)
    for k in np.unique(data["experiment"]):
        idx = np.flatnonzero(data["experiment"] == k)
        keep[idx] = data["t"][idx] - data["t"][idx[0]] >= seconds
    return keep


class ParametricModel:
    """The parametric Fossen model as an estimator (scikit-learn style).

    ``ParametricModel(vehicle, unknowns, trainer=LeastSquares())`` then ``fit(log)``: the
    trainer estimates the unknowns from the log; ``params`` holds value and standard error,
    ``predict(log, mode)`` simulates one step, k steps or free run, ``residual(log)`` is the
    force residual per DOF (McCarter eq. 4.4 minus the model), ``save``/``load`` use JSON.
    Velocities (and accelerations, unless the trainer filters) are derived from pose by
    Savitzky-Golay when the log lacks them; the cleaning report is ``report_``.
    """

    def __init__(
        self,
        vehicle,
        unknowns: Sequence[str],
        dofs: Sequence[str] = DOFS,
        trainer=None,
        savgol_window: float = 1.0,
        savgol_order: int = 4,
    ) -> None:
        self.vehicle = vehicle
        self.unknowns = list(unknowns)
        self.dofs = tuple(dofs)
        self.trainer = trainer
        self.savgol_window = savgol_window
        self.savgol_order = savgol_order

    # -- data ---------------------------------------------------------------------------------
    def prepare(self, log: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
        """The log with derived velocities/accelerations where missing, and its arrays."""
        from nnid.datasets.cleaning import CleaningReport
        from nnid.datasets.preprocess import derive_accelerations, derive_velocities

        report = CleaningReport(source="fit data")
        needs_acc = getattr(self.trainer, "filter_lambda", None) is None
        if any(d not in log for d in self.dofs) and all(a in log for a in ANGLES):
            log = derive_velocities(log, self.savgol_window, self.savgol_order, report)
        if needs_acc and any("d" + d not in log for d in self.dofs):
            log = derive_accelerations(log, self.savgol_window, self.savgol_order, report)
        self.report_ = report
        return log, log_arrays(log, self.vehicle)

    # -- estimator protocol ---------------------------------------------------------------------
    def fit(self, log: pd.DataFrame) -> ParametricModel:
        from nnid.trainers.least_squares import LeastSquares

        trainer = self.trainer if self.trainer is not None else LeastSquares()
        self.structure_ = ParametricFossen(self.vehicle, self.unknowns, self.dofs)
        _, data = self.prepare(log)
        self.estimate_ = trainer.fit(self.structure_, data)
        self.parts_ = self.structure_.parts(np.nan_to_num(self.estimate_.theta))
        mass = self.parts_.model(check=False).mass_matrix().numpy()
        if np.linalg.eigvalsh(0.5 * (mass + mass.T)).min() <= 0:
            import warnings

            warnings.warn(
                "the identified mass matrix M = M_RB + M_A is not positive definite (an added "
                "mass outweighs the rigid body): the data do not determine the inertia, and "
                "simulations of this model are meaningless",
                PhysicsWarning,
                stacklevel=2,
            )
        return self

    @property
    def params(self) -> dict[str, dict[str, float | None]]:
        return self.estimate_.as_dict()

    def predict(self, log: pd.DataFrame, mode="free_run") -> pd.DataFrame:
        from nnid.evaluation.prediction import predict_states

        log, data = self.prepare(log)
        return predict_states(self.parts_, log, data["tau"], mode)

    def residual(self, log: pd.DataFrame) -> pd.DataFrame:
        """R(θ̂) = M ν̇ − (τ_eff + b − Cν + τ_D − g): the force the model leaves unexplained."""
        log, data = self.prepare(log)
        if not all("d" + d in log for d in self.dofs):
            from nnid.datasets.preprocess import derive_accelerations

            data["nu_dot"] = log_arrays(
                derive_accelerations(log, self.savgol_window, self.savgol_order), self.vehicle
            )["nu_dot"]
        r = self.structure_.equation_residual(self.parts_, data)
        return pd.DataFrame(r, columns=list(FORCES), index=log.index)

    def describe(self) -> str:
        lines = [
            f"Fossen model of '{self.vehicle.name}', {len(self.unknowns)} parameters "
            f"identified from the {', '.join(self.dofs)} equations:"
        ]
        est = self.estimate_
        for name, v, s, pe in zip(
            est.names, est.theta, est.stderr, est.percentile_error, strict=True
        ):
            flag = "" if pe <= 100 / 1.96 else "  (insignificant at 95 %)"
            lines.append(f"  {name:>14s} = {v:.6g} ± {s:.2g}{flag}")
        return "\n".join(lines)

    # -- persistence ----------------------------------------------------------------------------
    def save(self, path) -> None:
        import json
        from pathlib import Path

        est = self.estimate_
        payload = {
            "kind": "fossen",
            "vehicle": self.vehicle.model_dump(),
            "unknowns": self.unknowns,
            "dofs": list(self.dofs),
            "savgol": [self.savgol_window, self.savgol_order],
            "theta": [None if not np.isfinite(v) else float(v) for v in est.theta],
            "cov": np.where(np.isfinite(est.cov), est.cov, 0.0).tolist(),
            "sigma2": est.sigma2,
            "n_obs": est.n_obs,
        }
        Path(path).write_text(json.dumps(payload, indent=1))

    @classmethod
    def load(cls, path) -> ParametricModel:
        """Rebuild from JSON (no code is executed)."""
        import json
        from pathlib import Path

        from nnid.trainers.least_squares import Estimate
        from nnid.vehicle import vehicle_from_dict

        payload = json.loads(Path(path).read_text())
        if payload.get("kind") != "fossen":
            raise ValueError(f"{path} is not a saved Fossen model")
        model = cls(
            vehicle_from_dict(payload["vehicle"], str(path)),
            payload["unknowns"],
            payload["dofs"],
            None,
            *payload["savgol"],
        )
        theta = np.array([np.nan if v is None else v for v in payload["theta"]], dtype=float)
        model.structure_ = ParametricFossen(model.vehicle, model.unknowns, model.dofs)
        model.estimate_ = Estimate(
            model.structure_.names,
            theta,
            np.array(payload["cov"]),
            payload["sigma2"],
            payload["n_obs"],
        )
        model.parts_ = model.structure_.parts(np.nan_to_num(theta))
        return model
