"""The numbers that define one plant: rigid body, added mass, damping, restoring terms,
installation coefficients, a constant force and a water current (Fossen 2011 ch. 6-10).

:class:`Parts` is the editable form of a vehicle file that regressions, simulations and the
residual loop share: ``set``/``get`` by parameter name (``X_udot``, ``"X:u*abs(u)"``,
``eta.w.neg``, ``external_bias.u``, ``weight``, ``buoyancy``, ``r_g.z``, ``r_b.z``), and
``model()`` builds the one Fossen implementation (:class:`nnid.physics.fossen.FossenModel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from nnid.physics.added_mass import added_mass_matrix, derivative, mirrored_key, set_derivative
from nnid.physics.damping import DampingTerms, parse_coefficient_key
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.fossen import FossenModel
from nnid.physics.thrusters import apply_installation

_AXES = "xyz"

#: Caccia's mean heave disturbance W − B (Caccia eq. 20), estimated where the file has W and B
WEIGHT_MINUS_BUOYANCY = "weight_minus_buoyancy"


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
            set_derivative(self.added_mass, name, value)
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
        """The value of one parameter by its name; KeyError for a name that is not one."""
        if name.endswith("dot") and ":" not in name:
            return derivative(self.added_mass, name)
        if ":" in name:
            return float(self.damping.get(name, 0.0))
        if name.startswith("eta."):
            _, dof, sign = name.split(".")
            return float((self.eta_pos if sign == "pos" else self.eta_neg)[DOFS.index(dof)])
        if name.startswith("external_bias."):
            return float(self.bias[DOFS.index(name.split(".")[1])])
        if name in ("weight", "buoyancy"):
            return float(getattr(self, name))
        if name[:4] in ("r_g.", "r_b.") and len(name) == 5 and name[-1] in _AXES:
            return float((self.r_g if name.startswith("r_g") else self.r_b)[_AXES.index(name[-1])])
        raise KeyError(f"'{name}' is not a parameter of a vehicle file")

    def declared(self, name: str) -> float | None:
        """The value of parameter ``name`` as these parts declare it (those of a vehicle file:
        :meth:`from_vehicle`), or None where they declare no such term: an added-mass
        derivative (nor its mirror) or a damping coefficient left out, which :meth:`get`
        and the model read as 0. Also Caccia's ``weight_minus_buoyancy`` (eq. 20, heave): W − B
        of these parts, the offset a heave model flies (no parameter :meth:`get` reads: the
        file declares W and B). KeyError for a name that is not a parameter."""
        if name == WEIGHT_MINUS_BUOYANCY:
            return float(self.weight - self.buoyancy)
        if name.endswith("dot") and ":" not in name:
            if name not in self.added_mass and mirrored_key(name) not in self.added_mass:
                return None
        elif ":" in name and name not in self.damping:
            return None
        return self.get(name)

    def model(self, check: bool = True, actuator_lag: float = 0.0) -> FossenModel:
        """The Fossen model of these parts (installation: see :meth:`applied`), with the
        applied force a state behind an ``actuator_lag`` > 0. ``check=False`` skips the
        positive-definite test, for the unit probes of the regression."""
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
            actuator_lag=actuator_lag,
            check=check,
        )

    def applied(self, tau_nominal: np.ndarray) -> np.ndarray:
        """τ_eff = η(sign) τ per DOF (Caccia eq. 3)."""
        return apply_installation(tau_nominal, self.eta_pos, self.eta_neg)

    def felt(self, data: dict[str, np.ndarray]) -> np.ndarray:
        """The force the vehicle feels at the samples of log arrays
        (:func:`~nnid.datasets.arrays.log_arrays`): the nominal force through the installation
        (Caccia eq. 3) and then the vehicle's actuator lag, L[η(sign τ) τ], from the lagged
        parts ``tau`` and ``tau_neg`` a lagged vehicle's arrays hold; η(sign) τ of ``tau``
        without a lag."""
        return apply_installation(data["tau"], self.eta_pos, self.eta_neg, data.get("tau_neg"))


def at_file_value(value: float | None) -> str:
    """How every message says a parameter is taken at the vehicle file's value
    (:meth:`Parts.declared`): "at the vehicle file's value V", or "at 0 (the vehicle file has
    no such term)" for None, which the file's own model reads as 0."""
    if value is None:
        return "at 0 (the vehicle file has no such term)"
    return f"at the vehicle file's value {value:.6g}"


def relative_velocity(parts: Parts, data: dict[str, np.ndarray]) -> np.ndarray:
    """ν_r = ν − ν_c(η), the velocity through the water that damping acts on (Fossen 2011
    eq. 10.1); ν itself in still water."""
    if parts.current is None or not np.any(parts.current):
        return data["nu"]
    with torch.no_grad():
        nu_c = parts.model(check=False).current_body(torch.as_tensor(data["eta"])).numpy()
    return data["nu"] - nu_c
