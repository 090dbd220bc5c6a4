"""Prime-system I nondimensional forms and the Reynolds number (Weiss Table 4, eqs 110-123;
Fossen's Prime system I).

Scales with water density ρ, length L and speed U: mass ½ρL³, inertia ½ρL⁵, force ½ρU²L²,
moment ½ρU²L³, linear velocity U, angular velocity U/L, time L/U. A coefficient c of a term in a
force F scales as c' = c · Π(scale of each factor) / scale(F), which gives Table 4's divisors:
X_u|u|' = X_u|u| / (½ρL²), X_u' = X_u / (½ρUL²), X_u̇' = X_u̇ / (½ρL³), N_ṙ' = N_ṙ / (½ρL⁵).
(Weiss eq. 120 divides N_r|r| by ½ρL³, which is not dimensionless; the consistent divisor is
½ρL⁵, used here.)
"""

from __future__ import annotations

from nnid.physics.added_mass import parse_added_mass_key
from nnid.physics.damping import parse_coefficient_key
from nnid.physics.damping_library import ATOMS, parse_term

WATER_VISCOSITY = 1.1e-3
"""Dynamic viscosity of water, Pa s, as Weiss uses in eq. 126."""

_LINEAR_ATOMS = {"u", "v", "w", "abs(u)", "abs(v)", "abs(w)", "U", "V", "Vv", "Vw"}
_ANGULAR_ATOMS = {"p", "q", "r", "abs(p)", "abs(q)", "abs(r)"}


def _force_scale(force: str, rho: float, length: float, speed: float) -> float:
    power = 2 if force in "XYZ" else 3
    return 0.5 * rho * speed**2 * length**power


def damping_scale(key: str, rho: float, length: float, speed: float) -> float:
    """Divisor d with c' = c / d for the damping coefficient ``key`` ('X:u*abs(u)', ...)."""
    force, term = parse_coefficient_key(key)
    factor = 1.0
    for index in parse_term(term):
        atom = ATOMS[index]
        if atom in _LINEAR_ATOMS:
            factor *= speed
        elif atom in _ANGULAR_ATOMS:
            factor *= speed / length
    return _force_scale(force, rho, length, speed) / factor


def added_mass_scale(key: str, rho: float, length: float) -> float:
    """Divisor for an added-mass derivative: 'X_udot' ½ρL³, 'Y_rdot' ½ρL⁴, 'N_rdot' ½ρL⁵."""
    row, col = parse_added_mass_key(key)
    power = 3 + (row >= 3) + (col >= 3)
    return 0.5 * rho * length**power


def mass_scale(rho: float, length: float) -> float:
    """m' = m / (½ρL³) (Weiss eq. 111)."""
    return 0.5 * rho * length**3


def inertia_scale(rho: float, length: float) -> float:
    """I' = I / (½ρL⁵) (Weiss eq. 118)."""
    return 0.5 * rho * length**5


def nondimensional_coefficients(vehicle, speed: float) -> dict[str, float]:
    """The vehicle's mass, inertias, added-mass and damping coefficients in Prime-system I
    at reference speed ``speed`` (needs ``vehicle.length``)."""
    if vehicle.length is None:
        raise ValueError("the vehicle file needs 'length' for nondimensional forms")
    rho, length = vehicle.rho, vehicle.length
    out = {"mass": vehicle.mass / mass_scale(rho, length)}
    inertia = vehicle.inertia_matrix()
    for i, name in enumerate(("Ix", "Iy", "Iz")):
        out[name] = float(inertia[i, i]) / inertia_scale(rho, length)
    for key, value in vehicle.added_mass.items():
        out[key] = value / added_mass_scale(key, rho, length)
    for key, value in vehicle.damping.coefficients.items():
        out[key] = value / damping_scale(key, rho, length, speed)
    return out


def reynolds_number(
    speed: float, length: float, rho: float = 1000.0, viscosity: float = WATER_VISCOSITY
) -> float:
    """Re = ρ U L / μ (Weiss eq. 123)."""
    return rho * speed * length / viscosity
