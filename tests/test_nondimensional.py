"""Prime-system I scales (Weiss Table 4, eqs 110-126; Fossen) and the Reynolds number.

"Weiss L<n>" = line n of seed 000_738d95e604f0f71d.txt. L = 0.625 m, rho = 1000 kg/m^3
(Weiss L1045).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nnid.physics.nondimensional import (
    added_mass_scale,
    damping_scale,
    inertia_scale,
    mass_scale,
    nondimensional_coefficients,
    reynolds_number,
)
from nnid.vehicle import load_vehicle, vehicle_from_dict

RHO, L = 1000.0, 0.625  # Weiss L1045
HALF_RHO_L2 = 195.3125  # (rho/2) L^2
HALF_RHO_L3 = 122.0703125  # (rho/2) L^3
HALF_RHO_L4 = 76.2939453125  # (rho/2) L^4
HALF_RHO_L5 = 47.6837158203125  # (rho/2) L^5

SPEEDS = [0.1, 0.2915, 0.3635, 0.8630, 2.0]  # Weiss L1022, L1128-1129 steady speeds, and others


def test_table4_mass_and_inertia_divisors():
    # Weiss Table 4 (L1034-1043): mass rho/2 L^3 (eq 111), inertia rho/2 L^5 (eq 118)
    assert mass_scale(RHO, L) == pytest.approx(HALF_RHO_L3, rel=1e-12)
    assert inertia_scale(RHO, L) == pytest.approx(HALF_RHO_L5, rel=1e-12)
    # rounded constants quoted in the notes
    assert mass_scale(RHO, L) == pytest.approx(122.0703, abs=1e-4)
    assert inertia_scale(RHO, L) == pytest.approx(47.6837, abs=1e-4)


@pytest.mark.parametrize("speed", SPEEDS)
def test_quadratic_damping_divisor_is_speed_independent(speed):
    # Weiss Table 4 "Quadratic damping" rho/2 L^2 (eq 113: X_u|u|' = X_u|u| / (rho/2 L^2))
    for key in ("X:u*abs(u)", "Y:v*abs(v)", "Z:w*abs(w)"):
        assert damping_scale(key, RHO, L, speed) == pytest.approx(HALF_RHO_L2, rel=1e-12)
    assert damping_scale("X:u*abs(u)", RHO, L, speed) == pytest.approx(195.3125, abs=1e-9)


@pytest.mark.parametrize("speed", SPEEDS)
def test_linear_damping_divisor(speed):
    # Weiss Table 4 "Linear damping" rho/2 U L^2 (eq 131; eq 132's printed rho/2 L^2 is a typo)
    for key in ("X:u", "Y:v", "Z:w"):
        assert damping_scale(key, RHO, L, speed) == pytest.approx(
            0.5 * RHO * speed * L**2, rel=1e-12
        )


@pytest.mark.parametrize("speed", SPEEDS)
def test_angular_damping_divisors_follow_fossen(speed):
    # Fossen Prime-system I: N_r|r|' = N_r|r| / (rho/2 L^5) for every U. Weiss eq. 120 (L1086)
    # prints rho/2 L^3, which is not dimensionless (N_r|r| is kg m^2); see notes section 8.
    for key in ("K:p*abs(p)", "M:q*abs(q)", "N:r*abs(r)"):
        assert damping_scale(key, RHO, L, speed) == pytest.approx(HALF_RHO_L5, rel=1e-12)
    assert damping_scale("N:r*abs(r)", RHO, L, speed) != pytest.approx(HALF_RHO_L3)
    # Fossen: N_r' = N_r / (rho/2 U L^4); X_vr' = X_vr / (rho/2 L^3)
    assert damping_scale("N:r", RHO, L, speed) == pytest.approx(0.5 * RHO * speed * L**4, rel=1e-12)
    assert damping_scale("X:v*r", RHO, L, speed) == pytest.approx(HALF_RHO_L3, rel=1e-12)


def test_added_mass_divisors():
    # Weiss Table 4 / eq 112: X_udot' = X_udot / (rho/2 L^3); eq 119: N_rdot' = N_rdot/(rho/2 L^5)
    assert added_mass_scale("X_udot", RHO, L) == pytest.approx(HALF_RHO_L3, rel=1e-12)
    assert added_mass_scale("Y_vdot", RHO, L) == pytest.approx(HALF_RHO_L3, rel=1e-12)
    assert added_mass_scale("N_rdot", RHO, L) == pytest.approx(HALF_RHO_L5, rel=1e-12)
    # Fossen: cross terms force-angular, e.g. Y_rdot' = Y_rdot / (rho/2 L^4)
    assert added_mass_scale("Y_rdot", RHO, L) == pytest.approx(HALF_RHO_L4, rel=1e-12)
    assert added_mass_scale("N_vdot", RHO, L) == pytest.approx(HALF_RHO_L4, rel=1e-12)


def test_table5_dimensional_column_converted_with_table4():
    """Weiss Table 5 (L1192-1199) dimensional column divided by the Table 4 divisors.

    The printed nondimensional column is an independent estimate, not a conversion (L1096),
    so it is NOT the expectation here; the numbers are those in the notes, section 8."""
    primes = nondimensional_coefficients(load_vehicle("vlbv300"), 0.8630)
    expected = {
        "X_udot": -0.1112,  # -13.5778 / 122.0703
        "X:u*abs(u)": -0.1420,  # -27.7411 / 195.3125
        "Y_vdot": -0.2288,  # -27.9347 / 122.0703
        "Y:v*abs(v)": -0.2595,  # -50.6868 / 195.3125
        "Z_wdot": -0.3795,  # -46.3258 / 122.0703
        "Z:w*abs(w)": -0.3307,  # -64.5970 / 195.3125
        "N_rdot": -0.0651,  # -3.1023 / 47.6837
        "N:r*abs(r)": -0.0455,  # -2.1709 / 47.6837 (Fossen; Weiss eq. 120 would give -0.0178)
    }
    for key, value in expected.items():
        assert primes[key] == pytest.approx(value, abs=6e-5), key
    # mass and inertias (eqs 111, 118): m' = 20.9 / 122.0703, I_z' = 0.9 / 47.6837
    assert primes["mass"] == pytest.approx(20.9 / HALF_RHO_L3, rel=1e-12)
    assert primes["Iz"] == pytest.approx(0.9 / HALF_RHO_L5, rel=1e-12)
    assert primes["Ix"] == pytest.approx(0.5587 / HALF_RHO_L5, rel=1e-12)


def test_quadratic_primes_do_not_depend_on_reference_speed():
    v = load_vehicle("vlbv300")
    a = nondimensional_coefficients(v, 0.3635)
    b = nondimensional_coefficients(v, 0.8630)
    assert a == pytest.approx(b, rel=1e-12)


def test_nondimensional_needs_a_length():
    v = load_vehicle("vlbv300").model_copy(update={"length": None})
    with pytest.raises(ValueError, match="length"):
        nondimensional_coefficients(v, 1.0)


def test_reynolds_number_weiss_eq126():
    # Weiss eq. 126 (L1128): Re_low = 1000 * 0.3635 * 0.625 / 1.1e-3 = 2.065e5 (printed 2.06e5)
    assert reynolds_number(0.3635, 0.625) == pytest.approx(2.065e5, rel=1e-3)
    assert reynolds_number(0.3635, 0.625) == pytest.approx(1000 * 0.3635 * 0.625 / 1.1e-3)
    # Re_high at 0.8630 m/s = 4.903e5 (notes section 8)
    assert reynolds_number(0.8630, 0.625) == pytest.approx(4.903e5, rel=1e-3)
    assert reynolds_number(1.0, 1.0, rho=1015.0, viscosity=1e-3) == pytest.approx(1.015e6)


# --------------------------------------------------------------------------------------------
# Dimensional-analysis property: a result computed in primes equals the dimensional one.

_DOF = {  # force key of the quadratic coefficient, is the DOF angular?
    "X": ("X:u*abs(u)", False),
    "Y": ("Y:v*abs(v)", False),
    "Z": ("Z:w*abs(w)", False),
    "K": ("K:p*abs(p)", True),
    "M": ("M:q*abs(q)", True),
    "N": ("N:r*abs(r)", True),
}


@settings(max_examples=60, deadline=None)
@given(
    speed=st.floats(0.05, 3.0),
    force=st.floats(0.01, 200.0),
    dof=st.sampled_from("XYZKMN"),
)
def test_seamor_steady_state_speed_in_primes(speed, force, dof):
    """Steady state of Weiss eqs 99-104 (v_dot = 0): force + F_q v|v| = 0."""
    seamor = load_vehicle("seamor")
    key, angular = _DOF[dof]
    coeff = seamor.damping.coefficients[key]
    ss = math.sqrt(force / -coeff)  # dimensional steady speed (m/s or rad/s)
    primes = nondimensional_coefficients(seamor, speed)
    # force'/moment' = F / (rho/2 U^2 L^2) or / (rho/2 U^2 L^3) (Weiss Table 4, eqs 114, 121)
    f_prime = force / (0.5 * seamor.rho * speed**2 * seamor.length ** (3 if angular else 2))
    ss_prime = math.sqrt(f_prime / -primes[key])
    # u' = u / U, r' = r L / U
    scale = speed / seamor.length if angular else speed
    assert ss_prime == pytest.approx(ss / scale, rel=1e-10)


@settings(max_examples=40, deadline=None)
@given(
    speed=st.floats(0.05, 3.0),
    force=st.floats(-100.0, 100.0),
    u=st.floats(-2.0, 2.0),
    r=st.floats(-2.0, 2.0),
)
def test_seamor_accelerations_in_primes(speed, force, u, r):
    """Weiss eq 115 (surge) and eq 122 (yaw, Fossen-consistent: no L^2 in the damping term,
    see notes section 8) reproduce the dimensional eqs 99 and 104."""
    v = load_vehicle("seamor")
    p = nondimensional_coefficients(v, speed)
    rho, length = v.rho, v.length
    # eq 99: u_dot = (X_u|u| u|u| + X_prop) / (m - X_udot)
    x_uu, x_ud = v.damping.coefficients["X:u*abs(u)"], v.added_mass["X_udot"]
    udot = (x_uu * u * abs(u) + force) / (v.mass - x_ud)
    x_prop_p = force / (0.5 * rho * speed**2 * length**2)  # eq 114
    den = length * (p["mass"] - p["X_udot"])
    udot_p = p["X:u*abs(u)"] / den * u * abs(u) + speed**2 / den * x_prop_p  # eq 115
    assert udot_p == pytest.approx(udot, rel=1e-9, abs=1e-12)
    # eq 104: r_dot = (N_r|r| r|r| + N_prop) / (I_z - N_rdot)
    n_rr, n_rd = v.damping.coefficients["N:r*abs(r)"], v.added_mass["N_rdot"]
    iz = v.inertia_matrix()[2, 2]
    rdot = (n_rr * r * abs(r) + force) / (iz - n_rd)
    n_prop_p = force / (0.5 * rho * speed**2 * length**3)  # eq 121
    den = p["Iz"] - p["N_rdot"]
    rdot_p = p["N:r*abs(r)"] / den * r * abs(r) + speed**2 / (length**2 * den) * n_prop_p
    assert rdot_p == pytest.approx(rdot, rel=1e-9, abs=1e-12)


def test_linear_plus_quadratic_steady_state_in_primes():
    """Seamor with an added linear surge term (Weiss eq 127 low-speed form): the steady state
    of X_u u + X_u|u| u|u| + X = 0 in primes (X_u' = X_u / (rho/2 U L^2)) is u / U."""
    data = load_vehicle("seamor").model_dump()
    data["damping"]["coefficients"]["X:u"] = -6.8387  # Weiss App. A X_u, as a test value
    v = vehicle_from_dict(data)
    a, b = v.damping.coefficients["X:u*abs(u)"], v.damping.coefficients["X:u"]
    for speed in (0.2, 0.8630, 1.7):
        for force in (1.0, 21.532, 90.0):
            # a u^2 + b u + force = 0, u > 0 (a, b < 0)
            u = (-b - math.sqrt(b * b - 4 * a * force)) / (2 * a)
            p = nondimensional_coefficients(v, speed)
            ap, bp = p["X:u*abs(u)"], p["X:u"]
            fp = force / (0.5 * v.rho * speed**2 * v.length**2)
            up = (-bp - math.sqrt(bp * bp - 4 * ap * fp)) / (2 * ap)
            assert up == pytest.approx(u / speed, rel=1e-10)
            assert np.isfinite(up) and up > 0


def test_the_prime_system_table_gives_no_error_bar_to_a_parameter_fitted_to_noise():
    """A run without sway leaves Y_vdot fitted to noise: its prime-system value printed
    "0.16287 ± 0.0041", a 2.5 % bar on a number with the wrong sign. It is said instead."""
    from nnid.pipeline import _nondimensional
    from nnid.reports.train_report import train_markdown
    from nnid.vehicle import load_vehicle

    vehicle = load_vehicle("vlbv300")
    params = {
        "X_udot": {"value": -10.0, "stderr": 0.1},
        "Y_vdot": {"value": 3.0, "stderr": None, "significant": False, "excited": False},
    }
    nd = _nondimensional(params, vehicle, 1.0)
    assert nd["params"]["Y_vdot'"]["excited"] is False and nd["params"]["X_udot'"]["excited"]
    text = train_markdown({"model": "fossen", "params": {}, "seconds": 0.0, "nondimensional": nd})
    lines = {ln.split("`")[1]: ln for ln in text.splitlines() if ln.startswith("- `")}
    assert "±" in lines["X_udot'"] and "±" not in lines["Y_vdot'"]
    assert "fitted to noise" in lines["Y_vdot'"]
