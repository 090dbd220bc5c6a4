"""Candidate effects: each name of the effect vocabulary as an object the loop can test.

A candidate knows its physical meaning, the Fossen-regression parameter that carries it (for
the effects that are linear in their parameter) or the bounds of a one-dimensional search (for
water current, actuator lag and deadband, which enter nonlinearly), how to turn an estimated
parameter change into the effect's value in the vocabulary's units, and where its signature
shows in the residual. What an effect *does* to a vehicle lives in one place,
:func:`nnid.physics.effects.apply_effect`; candidates only call it.

Linear candidates and the parameter δ they add to the model at its current values:

=================================  ==========================  ================================
effect                             parameter                   value
=================================  ==========================  ================================
``linear_damping.<dof>``           ``"X:u"`` …                 δ (N s/m, N m s/rad)
``quadratic_damping.<dof>``        ``"X:u*abs(u)"`` …          δ
``coupled_damping.<F>:<term>``     ``"<F>:<term>"``            δ
``thruster_installation.<d>.<s>``  ``eta.<d>.<s>``             (η₀ + δ)/η₀ (Caccia eq. 3)
``buoyancy_offset``                ``buoyancy``                −δ (W − B grows)
``restoring_offset.<K|M>``         ``r_g.z``                   δ (m; + is lower)
``external_bias.<dof>``            ``external_bias.<dof>``     δ (N, N m)
``added_mass.<dof>``               ``X_udot`` …                δ (kg, kg m²)
=================================  ==========================  ================================

``restoring_offset.K`` and ``.M`` are one physical change (z_g); the loop tests it once and
names it after the DOF whose residual it explains most.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from nnid.datasets.arrays import force_arrays, logged_inputs
from nnid.datasets.log import frame_step
from nnid.physics.damping import parse_coefficient_key
from nnid.physics.damping_library import LIBRARY, canonical_term
from nnid.physics.dofs import DOF_WORD, DOFS, FORCES
from nnid.physics.effects import apply_effect
from nnid.vehicle import MAX_CURRENT, MAX_LAG

_MEANING = {
    "linear_damping": "linear (skin-friction) damping in {0}, missing from the model",
    "quadratic_damping": "quadratic (form) drag in {0}, missing from the model",
    "coupled_damping": "coupled damping term {0}",
    "thruster_installation": "{0} thrust in the {1} direction differs from nominal",
    "buoyancy_offset": "weight and buoyancy differ (W − B)",
    "restoring_offset": "the centre of gravity is off its declared height (z_g; + is lower)",
    "current": "a steady water current along NED {0}",
    "external_bias": "a constant external force in {0} (tether, payload)",
    "actuator_lag": "thrusters answer commands with a first-order lag",
    "thruster_deadband": "small commands give no thrust (deadband)",
    "added_mass": "the added mass in {0} is wrong",
    "thruster_loss": "thruster {0} gives less thrust than nominal",
}


@dataclass(frozen=True)
class Candidate:
    """One effect the loop can add. ``parameter`` is set for linear-in-parameter effects;
    ``bounds`` (the effect value's search interval) for the nonlinear ones."""

    name: str
    kind: str
    parameter: str | None = None
    bounds: tuple[float, float] | None = None
    dofs: tuple[str, ...] = DOFS  # where its signature shows in the residual

    @property
    def linear(self) -> bool:
        return self.parameter is not None

    @property
    def meaning(self) -> str:
        args = self.name.split(".", 1)[1].split(".") if "." in self.name else []
        args = [DOF_WORD.get(a, a) for a in args]
        if self.kind == "thruster_installation":
            args = [DOF_WORD[self.name.split(".")[1]].capitalize(), args[1]]
            args[1] = "positive" if args[1] == "pos" else "negative"
        return _MEANING[self.kind].format(*args)

    def value(self, delta: float, vehicle) -> float:
        """The effect's value (vocabulary units) for a parameter change ``delta``."""
        if self.kind == "thruster_installation":
            return (self._eta(vehicle) + delta) / self._eta(vehicle)
        if self.kind == "buoyancy_offset":
            return -delta
        return delta

    def value_scale(self, vehicle) -> float:
        """d value / d δ, to carry a standard error over."""
        if self.kind == "thruster_installation":
            return 1.0 / self._eta(vehicle)
        return -1.0 if self.kind == "buoyancy_offset" else 1.0

    def _eta(self, vehicle) -> float:
        _, dof, sign = self.name.split(".")
        pos, neg = vehicle.installation_vectors()
        return float((pos if sign == "pos" else neg)[DOFS.index(dof)])

    def current_value(self, vehicle) -> float:
        """The effect's value the vehicle already has (nonlinear effects; 0 for current, which
        :func:`apply_effect` adds)."""
        if self.kind == "actuator_lag":
            return float(vehicle.actuator_lag)
        if self.kind == "thruster_deadband":
            return float(vehicle.deadband)
        return 0.0

    def augment(self, vehicle, value: float):
        """The vehicle with this effect added (:func:`apply_effect`)."""
        return apply_effect(vehicle, self.name, value)

    def renamed(self, name: str) -> Candidate:
        return Candidate(name, self.kind, self.parameter, self.bounds, self.dofs)


def _declared_damping(vehicle) -> set[tuple[str, str]]:
    from nnid.physics.parts import Parts

    return {parse_coefficient_key(k) for k in Parts.from_vehicle(vehicle).damping}


def candidates(vehicle, log: pd.DataFrame, coupled: bool = True) -> list[Candidate]:
    """Every effect of the vocabulary that the vehicle does not already declare and that
    the log can show (installation only in directions the inputs take; current only on axes
    the vehicle moves along). Coupled damping candidates are the library's terms outside the
    vehicle's damping structure."""
    declared = _declared_damping(vehicle)
    out: list[Candidate] = []
    for k, dof in enumerate(DOFS):
        force = FORCES[k]
        if (force, dof) not in declared:
            out.append(
                Candidate(f"linear_damping.{dof}", "linear_damping", f"{force}:{dof}", dofs=(dof,))
            )
        quad = canonical_term(f"{dof}*abs({dof})")
        if (force, quad) not in declared:
            out.append(
                Candidate(
                    f"quadratic_damping.{dof}", "quadratic_damping", f"{force}:{quad}", dofs=(dof,)
                )
            )
    diagonal = {(FORCES[k], d) for k, d in enumerate(DOFS)} | {
        (FORCES[k], canonical_term(f"{d}*abs({d})")) for k, d in enumerate(DOFS)
    }
    if coupled:
        for force in FORCES:
            for term in LIBRARY:
                term = canonical_term(term)
                if (force, term) in declared or (force, term) in diagonal:
                    continue
                if "(eta-1)" in term and vehicle.damping.u_c == 0:
                    continue  # η − 1 = −1 without a reference speed: a copy of another term
                dof = DOFS[FORCES.index(force)]
                out.append(
                    Candidate(
                        f"coupled_damping.{force}:{term}",
                        "coupled_damping",
                        f"{force}:{term}",
                        dofs=(dof,),
                    )
                )
    # a direction is there where its installation regressor is: the lagged part of the force
    # in that direction (Caccia eq. 3 before the lag), the force's own sign without a lag
    forces = force_arrays(log, vehicle)
    neg = forces.get("tau_neg", np.minimum(forces["tau"], 0.0))
    pos = forces["tau"] - neg
    for k, dof in enumerate(DOFS):
        for sign, present in (("pos", (pos[:, k] > 0).any()), ("neg", (neg[:, k] < 0).any())):
            if present:
                out.append(
                    Candidate(
                        f"thruster_installation.{dof}.{sign}",
                        "thruster_installation",
                        f"eta.{dof}.{sign}",
                        dofs=(dof,),
                    )
                )
    out.append(Candidate("buoyancy_offset", "buoyancy_offset", "buoyancy"))
    out.append(Candidate("restoring_offset.M", "restoring_offset", "r_g.z", dofs=("p", "q")))
    for dof in DOFS:
        out.append(
            Candidate(f"external_bias.{dof}", "external_bias", f"external_bias.{dof}", dofs=(dof,))
        )
        key = f"{FORCES[DOFS.index(dof)]}_{dof}dot"
        out.append(Candidate(f"added_mass.{dof}", "added_mass", key, dofs=(dof,)))
    speeds = [float(np.nanmax(np.abs(log[c]))) if c in log else 0.0 for c in "uvw"]
    top = max([*speeds, 0.0])
    for axis, speed in zip("xyz", speeds, strict=True):
        if top > 0 and speed > 0.1 * top:
            # searched only where a vehicle file may hold the value (nnid.vehicle's bounds)
            reach = min(2 * top, MAX_CURRENT)
            out.append(Candidate(f"current.{axis}", "current", bounds=(-reach, reach)))
    slowest = 100 * frame_step(log)  # 100 samples, joins left out
    lag = min(max(slowest, 0.5), MAX_LAG)
    out.append(Candidate("actuator_lag", "actuator_lag", bounds=(0.0, lag)))
    inputs, forces = logged_inputs(log, vehicle)
    width = float(np.nanmax(np.abs(inputs))) if len(log) else 0.0
    # a thruster vehicle's deadband is in command units: logged forces are past it, and the
    # search would move nothing (nominal_forces leaves them as logged)
    if width > 0 and not (forces and vehicle.thrusters):
        out.append(Candidate("thruster_deadband", "thruster_deadband", bounds=(0.0, 0.5 * width)))
    return out
