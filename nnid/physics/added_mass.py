"""Added mass: M_A from hydrodynamic derivatives, C_A(ν), and the prolate-spheroid estimate.

M_A = −[X_u̇ X_v̇ … ; …] (Weiss eq. 20; McCarter 2.23); C_A(ν) from the symmetric part of M_A
(Weiss eqs 27-28; McCarter 2.33-2.35). Prolate spheroid: McCarter eqs 2.36-2.41 (Fossen 2011 §6.4).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping

import torch
from torch import Tensor

from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.kinematics import skew

_KEY = re.compile(r"^([XYZKMN])_([uvwpqr])dot$")


def parse_added_mass_key(key: str) -> tuple[int, int]:
    """'Y_rdot' -> (row of Y, column of r). Raises ValueError on anything else."""
    m = _KEY.match(key)
    if not m:
        raise ValueError(
            f"'{key}' is not an added-mass derivative; expected '<F>_<v>dot' with F in "
            "X Y Z K M N and v in u v w p q r, e.g. 'X_udot'"
        )
    return FORCES.index(m.group(1)), DOFS.index(m.group(2))


def mirrored_key(key: str) -> str | None:
    """The derivative ``key`` equals by the symmetry of M_A (``Y_rdot`` -> ``N_vdot``), or None
    for a diagonal one."""
    i, j = parse_added_mass_key(key)
    return None if i == j else f"{FORCES[j]}_{DOFS[i]}dot"


def set_derivative(derivatives: dict[str, float], key: str, value: float) -> None:
    """Set ``key`` in ``derivatives``, and its mirror (:func:`mirrored_key`) where that is
    declared: they are one parameter of a symmetric M_A."""
    derivatives[key] = value
    twin = mirrored_key(key)
    if twin in derivatives:
        derivatives[twin] = value


def derivative(derivatives: Mapping[str, float], key: str) -> float:
    """The value of ``key`` in a symmetric M_A: its own entry, else its mirror's, else 0."""
    if key in derivatives:
        return float(derivatives[key])
    return float(derivatives.get(mirrored_key(key) or key, 0.0))


def added_mass_matrix(derivatives: Mapping[str, float], dtype=torch.float64) -> Tensor:
    """M_A = −[derivatives] as a 6x6 tensor, symmetric: an off-diagonal derivative fills its
    mirror too (X_v̇ = Y_u̇, McCarter eq. 2.33; Weiss eq. 28 reuses the upper triangle), so a
    vehicle file may give one of a pair. An asymmetric M_A makes an unforced, undamped vehicle
    gain energy (690 % in 30 s with Y_ṙ = −2 alone, where C_A reads its symmetric part).
    Absent derivatives are zero."""
    ma = torch.zeros(6, 6, dtype=dtype)
    for key, value in derivatives.items():
        i, j = parse_added_mass_key(key)
        ma[i, j] = ma[j, i] = -float(value)
    return ma


def added_mass_coriolis_matrix(added_mass: Tensor, nu: Tensor) -> Tensor:
    """C_A(ν) = [[0, −S(A₁₁ν₁ + A₁₂ν₂)], [−S(A₁₁ν₁ + A₁₂ν₂), −S(A₂₁ν₁ + A₂₂ν₂)]].

    Weiss eq. 27-28; uses the symmetric part of M_A, so C_A(ν) is skew-symmetric.
    """
    a = _momentum(added_mass, nu)
    s1, s2 = skew(a[..., 0:3]), skew(a[..., 3:6])
    zero = torch.zeros_like(s1)
    return torch.cat([torch.cat([zero, -s1], -1), torch.cat([-s1, -s2], -1)], -2)


def added_mass_coriolis_force(added_mass: Tensor, nu: Tensor) -> Tensor:
    """C_A(ν) ν without forming the matrix: [ω × a₁; v × a₁ + ω × a₂] with a = sym(M_A) ν."""
    a = _momentum(added_mass, nu)
    v, omega = nu[..., 0:3], nu[..., 3:6]
    a1, a2 = a[..., 0:3], a[..., 3:6]
    return torch.cat(
        [torch.linalg.cross(omega, a1), torch.linalg.cross(v, a1) + torch.linalg.cross(omega, a2)],
        -1,
    )


def _momentum(added_mass: Tensor, nu: Tensor) -> Tensor:
    sym = 0.5 * (added_mass + added_mass.transpose(-1, -2))
    return (sym @ nu.unsqueeze(-1)).squeeze(-1)


def prolate_spheroid_added_mass(
    length: float, diameter: float, rho: float = 1000.0, mass: float | None = None
) -> dict[str, float]:
    """Added-mass derivatives of a prolate spheroid (McCarter eqs 2.36-2.41; Lamb's k-factors).

    Semi-axes a = length/2 (x) and b = diameter/2; eccentricity e = sqrt(1 - (b/a)²). The mass
    scale is the displaced mass (4/3)πρab² unless ``mass`` is given: McCarter's Table B.3 uses
    the vehicle's mass for it. Returns the Fossen derivatives (negative); K_pdot is zero for a
    body of revolution.
    """
    a, b = 0.5 * length, 0.5 * diameter
    if not a > b > 0:
        raise ValueError("a prolate spheroid needs length > diameter > 0")
    e = math.sqrt(1.0 - (b / a) ** 2)
    log_term = math.log((1.0 + e) / (1.0 - e))
    alpha0 = 2.0 * (1.0 - e**2) / e**3 * (0.5 * log_term - e)
    beta0 = 1.0 / e**2 - (1.0 - e**2) / (2.0 * e**3) * log_term
    m = 4.0 / 3.0 * math.pi * rho * a * b**2 if mass is None else mass
    x_udot = -alpha0 / (2.0 - alpha0) * m
    y_vdot = -beta0 / (2.0 - beta0) * m
    n_rdot = (
        -0.2
        * m
        * (b**2 - a**2) ** 2
        * (alpha0 - beta0)
        / (2.0 * (b**2 - a**2) + (b**2 + a**2) * (beta0 - alpha0))
    )
    return {
        "X_udot": x_udot,
        "Y_vdot": y_vdot,
        "Z_wdot": y_vdot,
        "K_pdot": 0.0,
        "M_qdot": n_rdot,
        "N_rdot": n_rdot,
    }
