"""Thruster allocation, thrust curves and installation coefficients against the seeds.

"Weiss L<n>" = line n of seed 000 (Weiss 2013), "Caccia L<n>" = line n of seed 001 (Caccia et
al. 2000). Sign-corrected Weiss eqs 7 and 9 are derived in docs/seed_notes/weiss.md section 2.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from nnid.physics.thrusters import Actuation, ThrustCurve, apply_installation
from nnid.vehicle import load_vehicle

X, Y, Z, K, M, N = range(6)

# Weiss L325: aft pair 45 deg, forward pair 35 deg from centerline, verticals 18 deg
ALPHA_F = math.radians(35.0)
ALPHA_R = math.radians(45.0)
BETA = math.radians(18.0)
# Weiss eq. 10 (L375): Thrust = 0.006736 PWM^2 - 0.03366 PWM + 0.0684
WEISS_EQ10 = (0.0684, -0.03366, 0.006736)


@pytest.fixture(scope="module")
def vlbv():
    return load_vehicle("vlbv300")


@pytest.fixture(scope="module")
def romeo():
    return load_vehicle("romeo")


def _lever_arms(vehicle):
    """LH1, LH2, LV (Weiss L365). The seed gives no numbers, so they are read from the preset;
    the layout they imply (horizontal thrusters at (+-LH2, +-LH1, 0), verticals at (0, +-LV, 0))
    is checked here, since eqs 8 (M = 0) and 7 (K from the verticals only) require it."""
    pos = {t.name: np.asarray(t.position) for t in vehicle.thrusters}
    lh2, lh1 = pos["FS"][0], pos["FS"][1]
    lv = pos["VS"][1]
    np.testing.assert_allclose(pos["FS"], [lh2, lh1, 0.0])
    np.testing.assert_allclose(pos["FP"], [lh2, -lh1, 0.0])
    np.testing.assert_allclose(pos["AS"], [-lh2, lh1, 0.0])
    np.testing.assert_allclose(pos["AP"], [-lh2, -lh1, 0.0])
    np.testing.assert_allclose(pos["VS"], [0.0, lv, 0.0])
    np.testing.assert_allclose(pos["VP"], [0.0, -lv, 0.0])
    return lh1, lh2, lv


def _weiss_tau(fs, fp, as_, ap, vr, vl, lh1, lh2, lv):
    """Weiss eqs 4-9 (L347-363), with eq 7 and eq 9 as corrected in the notes."""
    cf, sf = math.cos(ALPHA_F), math.sin(ALPHA_F)
    cr, sr = math.cos(ALPHA_R), math.sin(ALPHA_R)
    cb, sb = math.cos(BETA), math.sin(BETA)
    x = (ap * cr - fp * cf) + (as_ * cr - fs * cf)  # eq 4
    y = (fs * sf + as_ * sr) - (fp * sf + ap * sr) - (vl - vr) * sb  # eq 5
    z = (vl + vr) * cb  # eq 6
    k = (vr - vl) * lv * cb  # eq 7 [FIX]: printed (VL + VR) s(beta) LV is impossible
    m = 0.0 * fs  # eq 8
    n = ((ap * cr - fp * cf) - (as_ * cr - fs * cf)) * lh1 + (  # eq 9 [FIX]: port - starboard
        (ap * sr - fp * sf) - (as_ * sr - fs * sf)
    ) * lh2
    return np.stack(np.broadcast_arrays(x, y, z, k, m, n), -1)


def test_vlbv300_allocation_matrix_from_angles(vlbv):
    lh1, lh2, lv = _lever_arms(vlbv)
    cf, sf = math.cos(ALPHA_F), math.sin(ALPHA_F)
    cr, sr = math.cos(ALPHA_R), math.sin(ALPHA_R)
    cb, sb = math.cos(BETA), math.sin(BETA)
    nf = lh1 * cf + lh2 * sf
    nr = lh1 * cr + lh2 * sr
    # columns FS FP AS AP VS(=VR) VP(=VL); coefficient of each thrust in eqs 4-9 (corrected)
    expected = np.array(
        [
            [-cf, -cf, cr, cr, 0.0, 0.0],  # eq 4
            [sf, -sf, sr, -sr, sb, -sb],  # eq 5
            [0.0, 0.0, 0.0, 0.0, cb, cb],  # eq 6
            [0.0, 0.0, 0.0, 0.0, lv * cb, -lv * cb],  # eq 7 (corrected)
            [0.0, 0.0, 0.0, 0.0, 0.0, 0.0],  # eq 8
            [nf, -nf, -nr, nr, 0.0, 0.0],  # eq 9 (corrected)
        ]
    )
    matrix = Actuation(vlbv).matrix
    assert matrix.shape == (6, 6)
    np.testing.assert_allclose(matrix, expected, rtol=0, atol=1e-9)


def test_vlbv300_allocation_matches_equation_form(vlbv):
    """tau = B f equals eqs 4-9 written term by term, for random thrusts."""
    lh1, lh2, lv = _lever_arms(vlbv)
    rng = np.random.default_rng(0)
    f = rng.uniform(-20.0, 20.0, size=(50, 6))
    tau = f @ Actuation(vlbv).matrix.T
    fs, fp, as_, ap, vs, vp = f.T
    np.testing.assert_allclose(
        tau, _weiss_tau(fs, fp, as_, ap, vs, vp, lh1, lh2, lv), rtol=0, atol=1e-9
    )


def test_vlbv300_aft_only_surge_has_no_yaw(vlbv):
    # Weiss's surge experiments: aft pair only (L1018). With AP = AS = T, eq 4 gives
    # X = 2 T cos(alpha_r) and the corrected eq 9 gives N = 0 (the printed eq 9 would not).
    b = Actuation(vlbv).matrix
    tau = b @ np.array([0.0, 0.0, 1.0, 1.0, 0.0, 0.0])
    np.testing.assert_allclose(tau, [2 * math.cos(ALPHA_R), 0, 0, 0, 0, 0], atol=1e-12)
    # equal verticals: pure heave 2 cos(beta) (eqs 5-7)
    tau = b @ np.array([0.0, 0.0, 0.0, 0.0, 1.0, 1.0])
    np.testing.assert_allclose(tau, [0, 0, 2 * math.cos(BETA), 0, 0, 0], atol=1e-12)


def test_vlbv300_pwm50_aft_pair_surge_force(vlbv):
    # Weiss L1096/L1180: surge at PWM 50 on the aft pair. eq 10 at 50: 15.2254 N per thruster,
    # so X = 2 * 15.2254 * cos 45 deg = 21.532 N (notes section 8)
    act = Actuation(vlbv)
    cmd = np.array([[0.0, 0.0, 50.0, 50.0, 0.0, 0.0]])
    tau = act.nominal(cmd)[0]
    assert tau[X] == pytest.approx(2 * 15.2254 * math.cos(ALPHA_R), rel=1e-9)
    np.testing.assert_allclose(tau[1:], 0.0, atol=1e-9)
    # no installation coefficients or deadband on vlbv300: applied == nominal
    np.testing.assert_allclose(act.applied(cmd), act.nominal(cmd), atol=1e-12)


def test_vlbv300_command_saturates_at_pwm_102(vlbv):
    # Weiss L343: PWM range -102..+102 -> a larger command gives the thrust at 102
    act = Actuation(vlbv)
    f102 = 0.006736 * 102**2 - 0.03366 * 102 + 0.0684  # eq 10 at 102 = 66.7164 N
    tau = act.nominal(np.array([[0, 0, 0, 0, 150.0, 150.0], [0, 0, 0, 0, -150.0, -150.0]]))
    assert tau[0, Z] == pytest.approx(2 * f102 * math.cos(BETA), rel=1e-9)
    assert tau[1, Z] == pytest.approx(-2 * f102 * math.cos(BETA), rel=1e-9)


# --------------------------------------------------------------------------------------------
# Caccia's B_H and B_V (L203, L207): phi_H = [X/cos a, Y/sin a, N/b] = B_H tau_H,
# phi_V = [K/c, M/d, Z] = B_V tau_V; horizontal decoupled from vertical (L201).

B_H = np.array([[1, 1, -1, -1], [1, -1, 1, -1], [1, -1, -1, 1]], dtype=float)  # Caccia L203
B_V = np.array([[-1, 1, -1, 1], [-1, -1, 1, 1], [1, 1, 1, 1]], dtype=float)  # Caccia L207


def test_romeo_reproduces_caccia_bh_bv(romeo):
    b = Actuation(romeo).matrix  # columns HFL HFR HRL HRR VFL VFR VRL VRR
    assert b.shape == (6, 8)
    h, v = slice(0, 4), slice(4, 8)
    bh = b[[X, Y, N], h]
    bv = b[[K, M, Z], v]
    # normalise each row by its (common) magnitude: cos a, sin a, b and c, d, 1
    scale_h = np.abs(bh).max(axis=1, keepdims=True)
    scale_v = np.abs(bv).max(axis=1, keepdims=True)
    np.testing.assert_allclose(np.abs(bh), np.broadcast_to(scale_h, bh.shape), rtol=1e-12)
    np.testing.assert_allclose(np.abs(bv), np.broadcast_to(scale_v, bv.shape), rtol=1e-12)
    np.testing.assert_allclose(bh / scale_h, B_H, atol=1e-12)
    np.testing.assert_allclose(bv / scale_v, B_V, atol=1e-12)
    # Horizontal thrusters parallel to the diagonals of the 1.3 x 0.9 m section (L187):
    # cos a = 1.3/sqrt(2.5), sin a = 0.9/sqrt(2.5)
    assert scale_h[0, 0] == pytest.approx(1.3 / math.sqrt(2.5), abs=1e-6)
    assert scale_h[1, 0] == pytest.approx(0.9 / math.sqrt(2.5), abs=1e-6)
    assert scale_v[2, 0] == pytest.approx(1.0, abs=1e-12)  # phi_V row 3 is Z itself
    # off-diagonal blocks vanish (L201): horizontal thrusters give no K, M, Z; vertical no X, Y, N
    np.testing.assert_allclose(b[[Z, K, M], h], 0.0, atol=1e-12)
    np.testing.assert_allclose(b[[X, Y, N], v], 0.0, atol=1e-12)


def test_romeo_pseudo_inverse_is_bt_over_4():
    # Caccia L211 with P = I and Table I "horizontal all"/"vertical all": B# = B^T / 4
    np.testing.assert_allclose(B_H @ B_H.T, 4 * np.eye(3))
    np.testing.assert_allclose(B_V @ B_V.T, 4 * np.eye(3))


# --------------------------------------------------------------------------------------------
# Thrust curves


def test_poly_curve_is_odd_symmetric():
    curve = ThrustCurve(kind="poly", coeffs=WEISS_EQ10)
    cmd = np.linspace(0.5, 102.0, 57)
    np.testing.assert_allclose(curve(-cmd), -curve(cmd), rtol=0, atol=1e-12)
    assert curve(np.array([0.0]))[0] == 0.0  # sign(0) = 0: no thrust at zero command


def test_weiss_eq10_at_pwm_50_gives_15_2254(vlbv):
    # Weiss eq. 10 (L375) tabulated in the notes: 10 -> 0.4054, 20 -> 2.0896, 30 -> 5.1210,
    # 40 -> 9.4996, 50 -> 15.2254, 60 -> 22.2984 N
    pwm = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0])
    expected = np.array([0.4054, 2.0896, 5.1210, 9.4996, 15.2254, 22.2984])
    for curve in Actuation(vlbv).curves:  # all six vlbv300 thrusters use eq. 10
        np.testing.assert_allclose(curve(pwm), expected, atol=1e-9)
        np.testing.assert_allclose(curve(-pwm), -expected, atol=1e-9)
        assert curve(np.array([50.0]))[0] == pytest.approx(15.2254, abs=1e-9)


def test_signed_quadratic_is_caccia_eq6():
    # Caccia eq. 6 (L105): tau = c_V V|V|, c_V = 1.02 N/V^2 (L217)
    curve = ThrustCurve(kind="signed_quadratic", k=1.02)
    volts = np.array([-10.0, -3.5, -1.0, 0.0, 0.5, 2.0, 7.25])
    np.testing.assert_allclose(curve(volts), 1.02 * volts * np.abs(volts), rtol=1e-15)
    np.testing.assert_allclose(curve(-volts), -curve(volts), atol=1e-15)
    assert curve(np.array([4.0]))[0] == pytest.approx(16.32)


def _romeo_reverse(romeo, k_neg):
    """The romeo preset with Caccia's reverse c_V as every thruster's ``k_neg`` (L217)."""
    from nnid.vehicle import vehicle_from_dict

    data = romeo.model_dump(mode="json")
    for thruster in data["thrusters"]:
        thruster["curve"]["k_neg"] = k_neg
    return vehicle_from_dict(data, "romeo with k_neg")


def test_signed_quadratic_reverse_coefficient_is_caccia_eq6(romeo):
    """Caccia eq. 6 with L217's two coefficients: c_V = 1.02 N/V² for positive thrust, 1.09
    for negative, given in the vehicle file as k and k_neg: the thrust at −V is −1.09 V², at
    +V 1.02 V²; through the allocation a vertical-all heave command of −V gives
    Z = −4 · 1.09 V² (the four verticals push along +z). Without k_neg the curve is eq. 6's
    symmetric one (the preset, so Caccia's Table II analogue, unchanged)."""
    volts = np.array([-10.0, -3.5, -1.0, 0.0, 0.5, 2.0, 7.25])
    asym = _romeo_reverse(romeo, 1.09)
    (curve, *_) = Actuation(asym).curves
    np.testing.assert_allclose(
        curve(volts), np.where(volts >= 0, 1.02, 1.09) * volts * np.abs(volts), rtol=1e-15
    )
    assert curve(np.array([-4.0]))[0] == pytest.approx(-1.09 * 16.0)
    assert curve(np.array([4.0]))[0] == pytest.approx(1.02 * 16.0)
    act = Actuation(asym)
    vertical = np.array([t.name.startswith("V") for t in asym.thrusters])
    cmd = np.where(vertical, -3.0, 0.0)[None, :]
    assert act.nominal(cmd)[0, 2] == pytest.approx(-4 * 1.09 * 9.0)
    (plain, *_) = Actuation(romeo).curves
    np.testing.assert_array_equal(plain(-volts), -plain(volts))


def test_a_reverse_coefficient_against_k_is_refused(romeo):
    """k_neg is a magnitude like k: −1.09 (the thrust's sign written in) would push the same
    way at either command; refused naming the curve."""
    from nnid.errors import NnidInputError

    with pytest.raises(NnidInputError, match=r"k_neg = -1\.09 must have the sign of k") as err:
        _romeo_reverse(romeo, -1.09)
    assert "thrusters.0.curve" in str(err.value)


def test_table_curve_interpolates_asymmetric_map():
    # Caccia L217: c_V = 1.02 N/V^2 for positive thrust, 1.09 N/V^2 for negative thrust
    volts = np.arange(-10.0, 10.5, 1.0)
    thrust = np.where(volts >= 0, 1.02, 1.09) * volts * np.abs(volts)
    curve = ThrustCurve(kind="table", cmd=tuple(volts), thrust=tuple(thrust))
    np.testing.assert_allclose(curve(volts), thrust, atol=1e-12)  # exact at the nodes
    # linear between nodes
    assert curve(np.array([2.5]))[0] == pytest.approx(0.5 * (1.02 * 4 + 1.02 * 9))
    assert curve(np.array([-2.5]))[0] == pytest.approx(-0.5 * (1.09 * 4 + 1.09 * 9))
    # asymmetric: reverse thrust is larger in magnitude
    assert curve(np.array([-5.0]))[0] == pytest.approx(-1.09 * 25)
    assert curve(np.array([5.0]))[0] == pytest.approx(1.02 * 25)
    assert abs(curve(np.array([-5.0]))[0]) > abs(curve(np.array([5.0]))[0])


def test_unknown_curve_kind_raises():
    with pytest.raises(ValueError, match="unknown thrust curve kind"):
        ThrustCurve(kind="cubic")(np.array([1.0]))


# --------------------------------------------------------------------------------------------
# Installation coefficients, Caccia eq. 3 (L85): effective = eta+ nominal for nominal >= 0,
# eta- nominal for nominal < 0, per DOF.


def test_apply_installation_numpy_per_dof():
    eta_pos = np.array([0.73, 1.0, 1.0, 1.0, 1.0, 0.60])
    eta_neg = np.array([0.80, 1.0, 0.56, 1.0, 1.0, 0.60])
    tau = np.array([[10.0, -3.0, -5.0, 2.0, -1.0, 4.0], [-10.0, 3.0, 5.0, -2.0, 1.0, -4.0]])
    out = apply_installation(tau, eta_pos, eta_neg)
    expected = np.array(
        [
            [0.73 * 10, -3.0, 0.56 * -5, 2.0, -1.0, 0.60 * 4],
            [0.80 * -10, 3.0, 5.0, -2.0, 1.0, 0.60 * -4],
        ]
    )
    np.testing.assert_allclose(out, expected, rtol=1e-15)
    assert isinstance(out, np.ndarray)


def test_apply_installation_torch_matches_numpy():
    eta_pos = np.array([0.73, 1.0, 1.0, 1.0, 1.0, 0.60])
    eta_neg = np.array([0.80, 1.0, 0.56, 1.0, 1.0, 0.60])
    tau = np.random.default_rng(1).normal(size=(20, 6))
    out_t = apply_installation(
        torch.tensor(tau), torch.tensor(eta_pos), torch.tensor(eta_neg)
    ).numpy()
    np.testing.assert_allclose(out_t, apply_installation(tau, eta_pos, eta_neg), rtol=1e-15)


def test_romeo_upward_heave_is_056_of_nominal(romeo):
    # Caccia Table II (L290): eta_w = 0.56 for upward thrust (phi_w < 0, NED z down) in
    # "vertical all" mode; downward eta_w = 1 (eq. 20, L261)
    act = Actuation(romeo)
    up = np.array([[0, 0, 0, 0, -3.0, -3.0, -3.0, -3.0]])  # all verticals reversed
    down = -up
    nom_up, app_up = act.nominal(up)[0], act.applied(up)[0]
    nom_down, app_down = act.nominal(down)[0], act.applied(down)[0]
    # nominal: 4 thrusters x 1.02 V|V| (eq. 6), pure heave
    assert nom_up[Z] == pytest.approx(-4 * 1.02 * 9.0)
    assert nom_down[Z] == pytest.approx(4 * 1.02 * 9.0)
    assert app_up[Z] == pytest.approx(0.56 * nom_up[Z], rel=1e-12)
    assert app_down[Z] == pytest.approx(1.0 * nom_down[Z], rel=1e-12)
    np.testing.assert_allclose(app_up[[X, Y, K, M, N]], 0.0, atol=1e-12)


def test_romeo_horizontal_all_surge_and_yaw(romeo):
    # Table I "horizontal all" (L231): tau = B_H^T [X, Y, N] / 4 -> surge-only command
    act = Actuation(romeo)
    surge = np.array([[1.0, 1.0, -1.0, -1.0, 0, 0, 0, 0]])  # B_H row 1: forward surge
    nom, app = act.nominal(surge)[0], act.applied(surge)[0]
    assert nom[X] > 0
    np.testing.assert_allclose(nom[[Y, Z, K, M, N]], 0.0, atol=1e-9)
    assert app[X] == pytest.approx(0.73 * nom[X], rel=1e-12)  # Table IV L367 eta_u^{h-p,+}
    nom_b, app_b = act.nominal(-surge)[0], act.applied(-surge)[0]
    assert app_b[X] == pytest.approx(0.80 * nom_b[X], rel=1e-12)  # Table IV L374 eta_u^{h-p,-}
    yaw = np.array([[1.0, -1.0, -1.0, 1.0, 0, 0, 0, 0]])  # B_H row 3: clockwise yaw
    nom, app = act.nominal(yaw)[0], act.applied(yaw)[0]
    assert nom[N] > 0
    np.testing.assert_allclose(nom[[X, Y, Z, K, M]], 0.0, atol=1e-9)
    assert app[N] == pytest.approx(0.60 * nom[N], rel=1e-12)  # Table III L334
