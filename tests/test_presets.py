"""Every preset equals its seed tables.

Expected numbers are typed from the seed texts under ../shared/seeds/ (never read back from
the preset files). "Weiss L<n>" = line n of 000_738d95e604f0f71d.txt (Weiss 2013, NPS thesis),
"Caccia L<n>" = line n of 001_f0911909a12443cd.txt (Caccia, Indiveri & Veruggio 2000),
"McCarter l.<n>" = line n of 002_2a6246727713bc4f.txt (McCarter 2014, VT thesis).
"""

from __future__ import annotations

import numpy as np
import pytest

from nnid.vehicle import PRESETS, load_vehicle

FORCES = "XYZKMN"
VELS = "uvwpqr"


@pytest.fixture(scope="module")
def presets():
    return {name: load_vehicle(name) for name in ("seamor", "vlbv300", "romeo", "vt690")}


def test_all_presets_are_listed():
    assert set(PRESETS) == {"seamor", "vlbv300", "romeo", "vt690", "bluerov2_heavy"}


# --------------------------------------------------------------------------------------------
# Seamor: Weiss Table 3 "True value" column (Weiss L986-997), Chen et al. mass/inertia (L964),
# Appendix A simulator listing z_cb = -.05 (L1405), x/y/z_cg = 0 (L1407-1409).

# Weiss Table 3, L986-997 (dots lost in extraction; the units kg, kg m^2/rad identify added mass)
SEAMOR_ADDED_MASS = {
    "X_udot": -27.08,  # Table 3 L986, kg
    "Y_vdot": -25.952,  # Table 3 L988, kg
    "Z_wdot": -68.576,  # Table 3 L990, kg
    "K_pdot": -61.683,  # Table 3 L992, kg m^2/rad
    "M_qdot": -79.411,  # Table 3 L994, kg m^2/rad (true value; the estimate -82.363 is not it)
    "N_rdot": -0.154,  # Table 3 L996, kg m^2/rad
}
SEAMOR_DAMPING = {
    "X:u*abs(u)": -61.117,  # Table 3 L987, X_u|u| kg/m
    "Y:v*abs(v)": -139.81,  # Table 3 L989, Y_v|v| kg/m
    "Z:w*abs(w)": -51.724,  # Table 3 L991, Z_w|w| kg/m
    "K:p*abs(p)": -12.0,  # Table 3 L993, K_p|p| kg m^2/rad^2
    "M:q*abs(q)": -56.61,  # Table 3 L995, M_q|q| (true value; the estimate -58.77 is not it)
    "N:r*abs(r)": -1.772,  # Table 3 L997, N_r|r| kg m^2/rad^2
}


def test_seamor_table3_added_mass(presets):
    v = presets["seamor"]
    assert set(v.added_mass) == set(SEAMOR_ADDED_MASS)
    for key, expected in SEAMOR_ADDED_MASS.items():
        assert v.added_mass[key] == pytest.approx(expected, abs=1e-12), key


def test_seamor_table3_quadratic_damping(presets):
    v = presets["seamor"]
    # Weiss eq. 45 (L545-548): purely quadratic, one term per axis
    assert set(v.damping.coefficients) == set(SEAMOR_DAMPING)
    for key, expected in SEAMOR_DAMPING.items():
        assert v.damping.coefficients[key] == pytest.approx(expected, abs=1e-12), key


def test_seamor_mass_inertia_and_centres(presets):
    v = presets["seamor"]
    assert v.mass == pytest.approx(20.4)  # Weiss L964: mass = 20.4 kg (Chen et al.)
    # Weiss L964: I_x = 0.429, I_y = I_z = 0.609 kg m^2; off-diagonals neglected (L501)
    np.testing.assert_allclose(v.inertia_matrix(), np.diag([0.429, 0.609, 0.609]), atol=1e-12)
    # Weiss App. A L1405: z_cb = -.05 (CB 5 cm above CG, z down); x_cb = y_cb = 0 (L1402-1403)
    np.testing.assert_allclose(v.r_b, [0.0, 0.0, -0.05], atol=1e-12)
    # Weiss App. A L1407-1409: x_cg = y_cg = z_cg = 0
    np.testing.assert_allclose(v.r_g, [0.0, 0.0, 0.0], atol=1e-12)
    # Neutrally buoyant, B = W = m g (Weiss L501; App. A L1383-1384, g = 9.81 L1381)
    assert v.weight == pytest.approx(20.4 * 9.81, rel=1e-9)
    assert v.buoyancy == pytest.approx(v.weight, rel=1e-12)


# --------------------------------------------------------------------------------------------
# vLBV300: Weiss Table 5 dimensional column (L1192-1199), mass 20.9 kg (L323, App. A L1382),
# inertias 0.5587/0.9531/0.9 (App. A L1386-1394; eqs 32-34).

VLBV_ADDED_MASS = {
    "X_udot": -13.5778,  # Table 5 L1192, kg
    "Y_vdot": -27.9347,  # Table 5 L1194, kg
    "Z_wdot": -46.3258,  # Table 5 L1196, kg
    "N_rdot": -3.1023,  # Table 5 L1198, kg m^2/rad
}
VLBV_DAMPING = {
    "X:u*abs(u)": -27.7411,  # Table 5 L1193, kg/m
    "Y:v*abs(v)": -50.6868,  # Table 5 L1195, kg/m
    "Z:w*abs(w)": -64.5970,  # Table 5 L1197, kg/m
    "N:r*abs(r)": -2.1709,  # Table 5 L1199, kg m^2/rad^2
}


def test_vlbv300_table5_dimensional_column(presets):
    v = presets["vlbv300"]
    # Table 5 has no roll/pitch rows: those coefficients must be absent, not invented
    assert set(v.added_mass) == set(VLBV_ADDED_MASS)
    assert set(v.damping.coefficients) == set(VLBV_DAMPING)
    for key, expected in VLBV_ADDED_MASS.items():
        assert v.added_mass[key] == pytest.approx(expected, abs=1e-12), key
    for key, expected in VLBV_DAMPING.items():
        assert v.damping.coefficients[key] == pytest.approx(expected, abs=1e-12), key


def test_vlbv300_mass_and_inertia(presets):
    v = presets["vlbv300"]
    assert v.mass == pytest.approx(20.9)  # Weiss L323 "weighs 20.9 kg in air"; App. A L1382
    # Weiss App. A L1386-1394: I_xx = .5587, I_yy = .9531, I_zz = .9 (products of inertia 0)
    np.testing.assert_allclose(v.inertia_matrix(), np.diag([0.5587, 0.9531, 0.9]), atol=1e-12)
    assert v.length == pytest.approx(0.625)  # Weiss L323 / L1045 characteristic length
    assert v.rho == pytest.approx(1000.0)  # Weiss L1045
    assert v.buoyancy == pytest.approx(v.weight, rel=1e-12)  # neutral (Weiss L296, L501)


def test_vlbv300_has_six_thrusters_in_weiss_order(presets):
    # Weiss L345: FS, FP, AS, AP horizontal; VS (= VR), VP (= VL) vertical
    names = [t.name for t in presets["vlbv300"].thrusters]
    assert names == ["FS", "FP", "AS", "AP", "VS", "VP"]
    for t in presets["vlbv300"].thrusters:
        # Weiss L343: PWM command range -102 .. +102
        assert (t.cmd_min, t.cmd_max) == (-102.0, 102.0)


# --------------------------------------------------------------------------------------------
# ROMEO: Caccia Tables II-IV. Caccia's drag is -k xi - k2 xi|xi| with k > 0 (eq. 2, L79), so the
# Fossen coefficient (force = coefficient * term) is -k. The preset uses: heave Table II,
# yaw Table III upper section ("Linear and quadratic yaw model"), surge Table IV forward
# technological row, installation from "horizontal all" / "vertical all" modes.


def test_romeo_mass_and_weight(presets):
    v = presets["romeo"]
    assert v.mass == pytest.approx(450.0)  # Caccia L187: "weighs about 450 kg in air"
    assert v.length == pytest.approx(1.3)  # Caccia L187: "1.3 m in length"
    assert v.g == pytest.approx(9.81)  # Caccia L75
    assert v.weight == pytest.approx(450.0 * 9.81, rel=1e-9)
    # Caccia Table II (L290): W = -13.5 N = weight - buoyancy along +z (experiment 0, positive)
    assert v.weight - v.buoyancy == pytest.approx(-13.5, abs=1e-9)


def test_romeo_surge_added_mass_from_identified_mass(presets):
    # Caccia L347: m_u = 890 +- 56 kg identified (includes added mass, Nomenclature L24)
    # => X_udot = -(890 - 450) = -440 kg ("about 440 kg", L349)
    assert presets["romeo"].added_mass["X_udot"] == pytest.approx(-(890.0 - 450.0), abs=1e-9)


ROMEO_DAMPING_FROM_TABLES = {
    "X:u": -46.9,  # Table IV L367, forward technological k_u+ = 46.9 Ns/m
    "X:u*abs(u)": -306.2,  # Table IV L367, k_u|u|+ = 306.2 Ns^2/m^2
    "Z:w": -44.7,  # Table II L290, k_w = 44.7 Ns/m
    "Z:w*abs(w)": -430.3,  # Table II L290, k_w|w| = 430.3 Ns^2/m^2
    "N:r": -20.5,  # Table III L334 (lin+quad model), k_r = 20.5 Nms/rad
    "N:r*abs(r)": -49.5,  # Table III L334, k_r|r| = 49.5 Nms^2/rad^2
}


def test_romeo_damping_from_tables_ii_iii_iv(presets):
    coeffs = presets["romeo"].damping.coefficients
    for key, expected in ROMEO_DAMPING_FROM_TABLES.items():
        assert coeffs[key] == pytest.approx(expected, abs=1e-12), key


def test_romeo_installation_coefficients(presets):
    inst = presets["romeo"].installation
    assert inst["w.neg"] == pytest.approx(0.56)  # Table II L290: eta_w (upward thrust)
    assert inst["w.pos"] == pytest.approx(1.0)  # eq. 20 (L261): eta_w = 1 for phi_w >= 0
    assert inst["u.pos"] == pytest.approx(0.73)  # Table IV L367: eta_u^{hull-propeller,+}
    assert inst["u.neg"] == pytest.approx(0.80)  # Table IV L374: eta_u^{hull-propeller,-}
    assert inst["r.pos"] == pytest.approx(0.60)  # Table III L334: eta_r^{hull-propeller}
    assert inst["r.neg"] == pytest.approx(0.60)  # Table III L334
    pos, neg = presets["romeo"].installation_vectors()
    # DOF order u v w p q r; undeclared DOFs default to 1 (Caccia eq. 3 reference)
    np.testing.assert_allclose(pos, [0.73, 1.0, 1.0, 1.0, 1.0, 0.60])
    np.testing.assert_allclose(neg, [0.80, 1.0, 0.56, 1.0, 1.0, 0.60])


def test_romeo_thrusters_follow_caccia_eq6(presets):
    thrusters = presets["romeo"].thrusters
    # Caccia L209: tau_H = [HFL HFR HRL HRR], tau_V = [VFL VFR VRL VRR]
    assert [t.name for t in thrusters] == ["HFL", "HFR", "HRL", "HRR", "VFL", "VFR", "VRL", "VRR"]
    for t in thrusters:
        # Caccia eq. 6 (L105) tau = c_V V|V|, c_V = 1.02 N/V^2 for positive thrust (L217)
        assert t.curve.kind == "signed_quadratic"
        assert t.curve.k == pytest.approx(1.02)


# --------------------------------------------------------------------------------------------
# VT 690: McCarter Appendix B (l.1175-1208) and McFarland coefficients, Tables E.1-E.3.


def test_vt690_appendix_b_scalars(presets):
    v = presets["vt690"]
    assert v.mass == pytest.approx(41.458)  # Table B.2 m
    assert v.length == pytest.approx(2.057)  # Table B.2 ell
    assert v.g == pytest.approx(9.80665)  # Table B.1 g
    assert v.rho == pytest.approx(1000.0)  # Table B.1 rho_f (fresh water)
    # Table B.2 displacement nabla = 41.702 kg -> B = 41.702 g
    assert v.buoyancy == pytest.approx(41.702 * 9.80665, rel=1e-6)
    assert v.weight == pytest.approx(41.458 * 9.80665, rel=1e-6)
    # Table B.2 r_G = (-0.0029, -0.0002, 0.0084) m, r_B = (0, 0, 0) (origin at CB)
    np.testing.assert_allclose(v.r_g, [-0.0029, -0.0002, 0.0084], atol=1e-12)
    np.testing.assert_allclose(v.r_b, [0.0, 0.0, 0.0], atol=1e-12)


def test_vt690_inertia_tensor_with_products(presets):
    # Table B.2 I_0 (matrix of McCarter eq. 2.18, off-diagonals already carry Fossen's minus)
    expected = np.array(
        [
            [0.1707, -0.0033, 0.1407],
            [-0.0033, 10.3659, -0.0000],
            [0.1407, -0.0000, 10.3508],
        ]
    )
    np.testing.assert_allclose(presets["vt690"].inertia_matrix(), expected, atol=1e-12)


def test_vt690_added_mass_table_b3(presets):
    # Table B.3 (l.1206): diag(M_A) = [-0.6673, -40.1654, -40.1654, 0, -8.0212, -8.0212];
    # McCarter's M_A is the matrix of derivatives (negative), i.e. Fossen's X_udot etc.
    expected = {
        "X_udot": -0.6673,
        "Y_vdot": -40.1654,
        "Z_wdot": -40.1654,
        "M_qdot": -8.0212,
        "N_rdot": -8.0212,
    }
    am = presets["vt690"].added_mass
    for key, value in expected.items():
        assert am[key] == pytest.approx(value, abs=1e-12), key
    assert am.get("K_pdot", 0.0) == 0.0  # Table B.3 row 4 is zero
    # Table B.3 is diagonal
    assert all(k[0] == "XYZKMN"[VELS.index(k[2])] for k in am)


# McFarland coefficients (McCarter Tables E.1-E.3; E-table "F_{a b}" = F_{a|b|}, key "F:a*abs(b)")
MCFARLAND_SAMPLE = {
    "X:u*abs(u)": -4.797,  # Table E.2 l.1478
    "X:w*abs(w)": 166.415,  # Table E.2 l.1482
    "X:q*abs(r)": -132.503,  # Table E.2 l.1473
    "Y:v*abs(v)": -17.556,  # Table E.3 l.1497
    "Y:r*abs(r)": 292.750,  # Table E.3 l.1492
    "Y:r*abs(u)": 127.465,  # Table E.3 l.1493
    "Z:w*abs(w)": -214.787,  # Table E.3 l.1511
    "Z:q*abs(q)": -739.176,  # Table E.3 l.1502
    "Z:u*abs(r)": 0.161,  # Table E.3 l.1506
    "K:p*abs(p)": 0.421,  # Table E.1 l.1430 (positive as printed)
    "K:w*abs(q)": -10.894,  # Table E.1 l.1440
    "K:u*abs(u)": -0.028,  # Table E.1 l.1437
    "M:q*abs(q)": -452.630,  # Table E.1 l.1444
    "M:w*abs(q)": 382.573,  # Table E.1 l.1452
    "N:r*abs(r)": -172.973,  # Table E.2 l.1463
    "N:v*abs(u)": 40.731,  # Table E.2 l.1468
}


def test_vt690_mcfarland_sample_coefficients(presets):
    coeffs = presets["vt690"].damping.coefficients
    assert {k[0] for k in MCFARLAND_SAMPLE} == set(FORCES)  # spread over all six forces
    for key, expected in MCFARLAND_SAMPLE.items():
        assert coeffs[key] == pytest.approx(expected, abs=1e-12), key


def test_vt690_mcfarland_has_all_216_terms(presets):
    damping = presets["vt690"].damping
    assert damping.model == "mcfarland"
    # McCarter Tables 5.1/5.2 (l.1050-1074): McFarland n = 216 = 6 forces x 36 a|b| terms
    # (eq. 3.34, Appendix C.4)
    assert len(damping.coefficients) == 216
    expected_keys = {f"{f}:{a}*abs({b})" for f in FORCES for a in VELS for b in VELS}
    assert set(damping.coefficients) == expected_keys


# --------------------------------------------------------------------------------------------
# BlueROV2 Heavy: von Benzon et al. 2022 (nnid/presets/bluerov2_heavy.toml)
def test_bluerov2_heavy_allocation_is_von_benzons_matrix():
    """The 6 x 8 allocation from the preset's thruster geometry equals the paper's T."""
    import torch

    from nnid.physics.thrusters import allocation_matrix

    veh = load_vehicle("bluerov2_heavy")
    pos = torch.tensor([t.position for t in veh.thrusters], dtype=torch.float64)
    direction = torch.tensor([t.direction for t in veh.thrusters], dtype=torch.float64)
    b = allocation_matrix(pos, direction).numpy()
    c, h, a = 0.7071, 0.06, 0.1888
    paper = np.array([
        [c, c, -c, -c, 0, 0, 0, 0],
        [-c, c, -c, c, 0, 0, 0, 0],
        [0, 0, 0, 0, -1, 1, 1, -1],
        [h, -h, h, -h, -0.218, -0.218, 0.218, 0.218],
        [h, h, -h, -h, 0.12, -0.12, 0.12, -0.12],
        [-a, a, a, -a, 0, 0, 0, 0],
    ])  # fmt: skip
    np.testing.assert_allclose(b, paper, atol=1e-3)
    assert np.linalg.matrix_rank(b) == 6  # every DOF can be actuated


def test_bluerov2_heavy_full_ascent_reaches_the_analytic_steady_speed():
    """Full ascent on the four vertical T200s (two pushing with 51.48 N, two reversed with 39.91
    N: no roll or pitch moment) against von Benzon's heave damping and the 0.985 N by which the
    weight exceeds the buoyancy: 190 w² + 33 |w| = 2 (51.48 + 39.91) − (W − B)."""
    from nnid.datasets.simulator import simulate

    veh = load_vehicle("bluerov2_heavy")
    cmd = np.zeros((400, 8))
    cmd[:, [4, 7]], cmd[:, [5, 6]] = 1.0, -1.0  # t5, t8 thrust up; t6, t7 are mounted reversed
    log = simulate(veh, cmd, 0.05)
    lift = 2 * (51.48 + 39.91) - (veh.weight - veh.buoyancy)
    steady = (-33.0 + np.sqrt(33.0**2 + 4 * 190.0 * lift)) / (2 * 190.0)
    assert -log["w"].iloc[-1] == pytest.approx(steady, rel=1e-3)
    for dof in ("u", "v", "p", "q", "r"):
        assert abs(log[dof].iloc[-1]) < 1e-9, dof


def _fields(model) -> set[str]:
    """Every key a pydantic model of the vehicle file accepts, nested models included."""
    import typing

    from pydantic import BaseModel

    keys = set()
    for name, field in model.model_fields.items():
        keys.add(name)
        for arg in [field.annotation, *typing.get_args(field.annotation)]:
            for inner in [arg, *typing.get_args(arg)]:
                if isinstance(inner, type) and issubclass(inner, BaseModel):
                    keys |= _fields(inner)
    return keys


def test_every_key_of_the_vehicle_file_is_documented():
    """docs/vehicle_file.md names (as `key`) every key the loader accepts, and an example of
    each thrust-curve kind that loads."""
    import re
    import tomllib
    from pathlib import Path

    from nnid.vehicle import PolyCurve, SignedQuadraticCurve, TableCurve, Thruster, Vehicle

    text = (Path(__file__).parents[1] / "docs" / "vehicle_file.md").read_text()
    documented = set(re.findall(r"`([a-z_]+)`", text))
    keys = _fields(Vehicle) | _fields(Thruster) | {"coeffs", "k", "cmd", "thrust", "kind"}
    assert keys - documented == set()
    curves = re.findall(r"```toml\n(curve = .*?)\n```", text)
    kinds = {tomllib.loads(c)["curve"]["kind"] for c in curves}
    assert kinds == {"poly", "signed_quadratic", "table"}
    for c in curves:
        model = {"poly": PolyCurve, "signed_quadratic": SignedQuadraticCurve, "table": TableCurve}
        model[tomllib.loads(c)["curve"]["kind"]].model_validate(tomllib.loads(c)["curve"])


def test_starter_vehicle_files_load_and_scale(tmp_path):
    """`nnid vehicle`: a preset's file and an estimate from mass and size, both loading back;
    the estimate's inertia is the cuboid's and its thrusters the Heavy layout scaled."""
    from typer.testing import CliRunner

    from nnid.cli import app
    from nnid.physics.rigid_body import cuboid_inertia

    runner = CliRunner()
    res = runner.invoke(
        app, ["vehicle", "--preset", "bluerov2_heavy", "--out", str(tmp_path / "h.toml")]
    )
    assert res.exit_code == 0, res.output
    assert load_vehicle(tmp_path / "h.toml") == load_vehicle("bluerov2_heavy")
    out = tmp_path / "mine.toml"
    res = runner.invoke(
        app, ["vehicle", "--mass", "20", "--size", "0.914x1.15x0.508", "--out", str(out)]
    )
    assert res.exit_code == 0, res.output
    mine, ref = load_vehicle(out), load_vehicle("bluerov2_heavy")
    assert mine.name == "mine" and mine.mass == 20
    np.testing.assert_allclose(mine.inertia, cuboid_inertia(20, 0.914, 1.15, 0.508), rtol=1e-3)
    np.testing.assert_allclose(
        mine.thrusters[0].position, 2 * np.array(ref.thrusters[0].position), rtol=1e-3
    )
    # twice the size: four times the frontal area, four times the quadratic surge drag
    assert mine.damping.coefficients["X:u*abs(u)"] == pytest.approx(4 * -141.0, rel=1e-3)
    for args, option in [
        (["--mass", "20"], "--size"),
        (["--mass", "20", "--size", "1x2"], "--size"),
        (["--mass", "-3", "--size", "1x1x1"], "--mass"),
        (["--preset", "nautilus"], "--preset"),
        # written as the preset, name and thrusters and all, without a word
        (["--preset", "bluerov2_heavy", "--name", "myrov"], "--name"),
        (["--preset", "bluerov2_heavy", "--layout", "none"], "--layout"),
        (["--mass", "20", "--size", "1x1x1", "--layout", "quad"], "--layout"),
        # named as the file's 'length', which was not written yet
        (["--mass", "20", "--size", "nanx0.58x0.25"], "--size"),
        # grams: 2500 kg in a 9-litre box, written as a neutral vehicle
        (["--mass", "2500", "--size", "0.3x0.2x0.15"], "--mass': a neutral vehicle of 2500 kg"),
    ]:
        res = runner.invoke(app, ["vehicle", *args, "--out", str(tmp_path / "bad.toml")])
        assert res.exit_code == 2 and option in res.output, res.output
        assert not (tmp_path / "bad.toml").exists()
    res = runner.invoke(app, ["vehicle", "--preset", "seamor", "--out", str(out)])
    assert res.exit_code == 2 and "exists" in res.output  # nothing is overwritten
    # a name with TOML's special characters is written escaped and reads back as given
    for k, name in enumerate(['a"b', "a\\b", "my ROV é"]):
        named = tmp_path / f"named{k}.toml"
        args = ["vehicle", "--mass", "20", "--size", "1x1x0.5", "--name", name, "--out", str(named)]
        assert runner.invoke(app, args).exit_code == 0
        assert load_vehicle(named).name == name
    # a line break or another control character is refused, naming the option: written
    # escaped, it read back, but split every one-line error that names the vehicle in two
    for k, name in enumerate(["a\nb", "x\x7fy"]):
        named = tmp_path / f"control{k}.toml"
        args = ["vehicle", "--mass", "20", "--size", "1x1x0.5", "--name", name, "--out", str(named)]
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and "field '--name': a name is one line" in res.output
        assert not named.exists()


def test_starter_vehicle_file_is_neutral_at_its_measured_mass():
    """The starter file says its buoyancy is ASSUMED neutral and its mass is measured: written
    to 4 digits, 1234.5 kg came back with W - B = 0.45 N and 11.123456 kg as 11.1235 kg."""
    import tomllib

    from nnid.vehicle import vehicle_from_dict
    from nnid.vehicle_starter import starter_text

    for mass, size in [(1234.5, (3.0, 2.0, 1.0)), (11.123456, (0.457, 0.575, 0.254))]:
        veh = vehicle_from_dict(tomllib.loads(starter_text("x", mass, size)), source="x.toml")
        assert veh.mass == mass
        assert veh.buoyancy == pytest.approx(veh.weight, rel=1e-12, abs=0)


def test_starter_centres_are_the_presets_scaled_and_lie_inside_the_hull():
    """A fixed r_g of 2 cm put the centre of gravity of a 1-cm-tall vehicle 1.5 cm below its
    bottom (and warned of it when the file loaded back). The starter cites the Heavy, whose
    CG is its origin and whose CB lies 1 cm above it [vB22]; it wrote r_g = 2 cm and r_b = 0,
    twice the Heavy's restoring lever. At the Heavy's size it has the Heavy's centres (and
    restoring moments), at another the lever z_g − z_b scaled with the height."""
    import tomllib

    from nnid.vehicle import vehicle_from_dict
    from nnid.vehicle_starter import starter_text

    heavy = load_vehicle("bluerov2_heavy")
    lever = heavy.r_g[2] - heavy.r_b[2]
    assert lever == pytest.approx(0.01)  # the preset's 1 cm [vB22]
    for size in [(0.01, 0.01, 0.01), (0.457, 0.575, 0.254), (0.914, 1.15, 0.508)]:
        mass = heavy.mass * (size[2] / 0.254) ** 3  # the Heavy's density
        veh = vehicle_from_dict(tomllib.loads(starter_text("x", mass, size)), source="x.toml")
        for centre in (veh.r_g, veh.r_b):
            assert all(abs(c) < s / 2 for c, s in zip(centre, size, strict=True))
        assert veh.r_g[2] - veh.r_b[2] == pytest.approx(lever * size[2] / 0.254, rel=1e-3)
    text = starter_text("x", heavy.mass, (0.457, 0.575, 0.254))
    veh = vehicle_from_dict(tomllib.loads(text), source="x.toml")
    np.testing.assert_allclose([*veh.r_g, *veh.r_b], [*heavy.r_g, *heavy.r_b], atol=1e-12)
    assert "inertia = " in text and "about the origin" in text.split("inertia = ")[1][:120]


def test_starter_marks_every_value_it_did_not_measure():
    """docs/vehicle_file.md: every estimate is marked ESTIMATE or ASSUMED; r_b (the centre of
    buoyancy put at the origin) was written bare, as if measured."""
    from nnid.vehicle_starter import starter_text

    text = starter_text("x", 11.5, (0.457, 0.575, 0.254))
    top = [line for line in text.split("\n[")[0].splitlines() if "=" in line[:20]]
    measured = ("name", "description", "rho", "length", "mass")
    marked = [line for line in top if "ASSUMED" in line or "ESTIMATE" in line]
    unmarked = [line for line in top if line.split("=")[0].strip() not in measured]
    unmarked = [line for line in unmarked if line not in marked]
    assert {line.split("=")[0].strip() for line in top} >= {"buoyancy", "inertia", "r_g", "r_b"}
    assert unmarked == []


def test_a_starter_vehicle_named_beyond_the_bmp_is_written_and_loads(tmp_path):
    """JSON escaped a name's emoji as a surrogate pair, which TOML refuses: `nnid vehicle
    --name "ROV 🚀"` ended in a traceback."""
    from typer.testing import CliRunner

    from nnid.cli import app

    out = tmp_path / "rov.toml"
    args = ["vehicle", "--mass", "12", "--size", "0.5x0.4x0.3", "--name", "ROV 🚀"]
    res = CliRunner().invoke(app, [*args, "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert load_vehicle(out).name == "ROV 🚀"
    # a lone surrogate (argv bytes that were not UTF-8) is refused before any file is written
    bad = tmp_path / "bad.toml"
    args[-1] = "ROV \udcff"
    res = CliRunner().invoke(app, [*args, "--out", str(bad)])
    assert res.exit_code == 2 and "--name" in res.output and not bad.exists(), res.output


def test_a_saved_vehicle_keeps_its_thruster_directions_bit_for_bit():
    """A direction is normalised when read; a saved model's vehicle was normalised again on
    loading, which moves the last bit of a third of them ([1, 1, 0]: 0.7071067811865475, then
    ...76), and the loaded model's allocation, so its predictions, differed from the saved."""
    from nnid.vehicle import saved_vehicle, vehicle_from_dict

    data = load_vehicle("bluerov2_heavy").model_dump(mode="json")
    data["thrusters"][0]["direction"] = [1.0, 1.0, 0.0]
    first = vehicle_from_dict(data)
    assert first.thrusters[0].direction == [0.7071067811865475, 0.7071067811865475, 0.0]
    again = saved_vehicle(first.model_dump(mode="json"))
    assert [t.direction for t in again.thrusters] == [t.direction for t in first.thrusters]
    # a hand-edited saved model's direction that is no unit vector is still normalised
    edited = saved_vehicle(data)
    assert edited.thrusters[0].direction == first.thrusters[0].direction
