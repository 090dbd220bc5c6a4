"""Physical effects by their canonical names (ARCHITECTURE.md, effect vocabulary).

An effect changes a vehicle: the simulator injects effects that the vehicle file does not
declare, and the residual loop adds the ones it finds. ``apply_effect`` is the one place that
says what each name means physically:

- ``thruster_installation.<dof>.<pos|neg>``: installation coefficient η of that direction is
  multiplied by ``value`` (Caccia eq. 3; 0.56 for ROMEO's upward heave thrust, Table II).
- ``linear_damping.<dof>`` / ``quadratic_damping.<dof>``: adds ``value`` to ``X:u`` /
  ``X:u*abs(u)`` (and likewise per DOF); drag is negative.
- ``coupled_damping.<F>:<term>``: adds ``value`` to that coefficient of the basis library.
- ``buoyancy_offset``: W − B grows by ``value`` newtons (buoyancy lowered by it).
- ``restoring_offset.<K|M>``: the centre of gravity sits ``value`` metres lower (z_g += value)
  than declared; it shows in roll (K) and pitch (M) restoring moments.
- ``current.<x|y|z>``: steady water current of ``value`` m/s along that NED axis.
- ``external_bias.<dof>``: a constant body-frame force (N) or moment (N m).
- ``actuator_lag``: first-order actuator time constant ``value`` seconds.
- ``thruster_deadband``: commands (or forces) with magnitude up to ``value`` give nothing.
- ``added_mass.<dof>``: adds ``value`` (kg or kg m², negative = more added mass) to the
  diagonal derivative, e.g. ``X_udot``.
"""

from __future__ import annotations

import re

from nnid.errors import NnidInputError
from nnid.physics.damping import parse_coefficient_key
from nnid.physics.dofs import DOFS, FORCES
from nnid.validation import validated

_D = "[uvwpqr]"
EFFECT_PATTERNS = {
    "linear_damping": rf"linear_damping\.({_D})",
    "quadratic_damping": rf"quadratic_damping\.({_D})",
    "coupled_damping": r"coupled_damping\.([XYZKMN]:.+)",
    "thruster_installation": rf"thruster_installation\.({_D})\.(pos|neg)",
    "buoyancy_offset": r"buoyancy_offset",
    "restoring_offset": r"restoring_offset\.([KM])",
    "current": r"current\.([xyz])",
    "external_bias": rf"external_bias\.({_D})",
    "actuator_lag": r"actuator_lag",
    "thruster_deadband": r"thruster_deadband",
    "added_mass": rf"added_mass\.({_D})",
}


def parse_effect(name: str) -> tuple[str, tuple[str, ...]]:
    """'thruster_installation.w.neg' -> ('thruster_installation', ('w', 'neg'))."""
    for kind, pattern in EFFECT_PATTERNS.items():
        m = re.fullmatch(pattern, name)
        if m:
            if kind == "coupled_damping":
                parse_coefficient_key(m.group(1))
            return kind, m.groups()
    raise ValueError(
        f"unknown effect '{name}'; expected one of: "
        + ", ".join(
            p.replace("\\", "").replace(f"({_D})", "<dof>") for p in EFFECT_PATTERNS.values()
        )
    )


def apply_effect(vehicle, name: str, value: float):
    """A copy of ``vehicle`` (a :class:`nnid.vehicle.Vehicle`) with the effect added."""
    kind, args = parse_effect(name)
    out = vehicle.model_copy(deep=True)
    value = float(value)
    if kind in ("linear_damping", "quadratic_damping", "coupled_damping"):
        if kind == "coupled_damping":
            force, term = parse_coefficient_key(args[0])
        else:
            dof = args[0]
            force = FORCES[DOFS.index(dof)]
            term = dof if kind == "linear_damping" else f"{dof}*abs({dof})"
        key = next(
            (k for k in out.damping.coefficients if parse_coefficient_key(k) == (force, term)),
            f"{force}:{term}",
        )
        out.damping.coefficients[key] = out.damping.coefficients.get(key, 0.0) + value
    elif kind == "thruster_installation":
        key = f"{args[0]}.{args[1]}"
        out.installation[key] = out.installation.get(key, 1.0) * value
    elif kind == "buoyancy_offset":
        out.buoyancy = out.buoyancy - value
    elif kind == "restoring_offset":
        out.r_g[2] += value
    elif kind == "current":
        out.current["xyz".index(args[0])] += value
    elif kind == "external_bias":
        out.external_bias[DOFS.index(args[0])] += value
    elif kind == "actuator_lag":
        out.actuator_lag = value
    elif kind == "thruster_deadband":
        out.deadband = value
    elif kind == "added_mass":
        dof = args[0]
        key = f"{FORCES[DOFS.index(dof)]}_{dof}dot"
        out.added_mass[key] = out.added_mass.get(key, 0.0) + value
    try:
        return validated(type(vehicle), out.model_dump(), "")
    except NnidInputError as exc:  # an effect too large for a physical vehicle, said as such
        raise NnidInputError(
            f"effect {name} = {value:g} leaves no valid vehicle: "
            + (f"'{exc.field}' " if exc.field else "")
            + exc.message,
        ) from None
