"""The basis library (McCarter App. C) and the named masks (App. D)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nnid.physics.damping import DampingTerms
from nnid.physics.damping_library import (
    LIBRARY,
    BasisLibrary,
    canonical_term,
    mask_terms,
    parse_term,
)
from nnid.physics.damping_masks import MASK_TERM_COUNTS, MASKS


def test_library_has_mccarters_132_terms_in_groups():
    """C.1-C.6: 6 + 6 + 21 + 36 + 36 + 27 = 132 distinct terms."""
    assert len(LIBRARY) == 132 == len(set(LIBRARY))
    assert LIBRARY[:6] == ("u", "v", "w", "p", "q", "r")
    assert LIBRARY[12] == "u*u" and LIBRARY[32] == "r*r"
    assert LIBRARY[33] == "u*abs(u)" and LIBRARY[68] == "r*abs(r)"
    assert LIBRARY[69] == "u*V" and LIBRARY[104] == "abs(r)*Vw"
    assert LIBRARY[105] == "u*u*(eta-1)" and LIBRARY[131] == "r*V*(eta-1)"
    assert len({parse_term(t) for t in LIBRARY}) == 132


def test_terms_evaluate_as_written():
    """V = sqrt(v²+w²), Vv = V sign(v), Vw = V sign(w), η = u_c / U (C.8-C.12)."""
    nu = np.array([2.0, -3.0, 4.0, 0.5, -0.25, 1.5])
    lib = BasisLibrary(
        ["u*abs(v)", "abs(q)*Vv", "w*Vw", "u*u*(eta-1)", "p*r", "r*V*(eta-1)"], u_c=1.0
    )
    big_v, big_u = 5.0, np.sqrt(29.0)
    expected = [
        2 * 3,
        0.25 * -big_v,
        4 * big_v,
        4 * (1 / big_u - 1),
        0.75,
        1.5 * big_v * (1 / big_u - 1),
    ]
    assert np.allclose(lib(nu), expected, rtol=1e-12)


def test_numpy_and_torch_agree_and_gradients_are_finite(rng):
    lib = BasisLibrary(u_c=1.3)
    nu = rng.normal(size=(100, 6))
    nu[0] = 0.0  # at rest: sqrt and η must stay finite
    a = lib(nu)
    t = torch.tensor(nu, requires_grad=True)
    b = lib(t)
    assert np.allclose(a, b.detach().numpy(), rtol=1e-12, atol=1e-12)
    assert np.isfinite(a).all()
    b.sum().backward()
    assert torch.isfinite(t.grad).all()


def test_canonical_spelling_and_bad_terms():
    assert canonical_term("abs(v) * u") == "u*abs(v)"
    assert canonical_term("V*abs(q)") == "abs(q)*V"
    with pytest.raises(ValueError, match="'x'"):
        parse_term("u*x")
    with pytest.raises(ValueError, match="1 to 3"):
        parse_term("u*v*w*p")


def test_masks_use_library_terms_and_mccarter_counts():
    """Term counts equal McCarter's n̄ (Tables 5.1/5.2); Weiss eq. 45 has six."""
    for name, forces in MASKS.items():
        assert set(forces) == set("XYZKMN")
        terms = mask_terms(name)
        for force_terms in terms.values():
            assert set(force_terms) <= set(LIBRARY)
        assert sum(len(v) for v in terms.values()) == MASK_TERM_COUNTS[name]
    assert MASK_TERM_COUNTS["mcfarland"] == 216
    assert mask_terms("weiss_quadratic")["M"] == ("q*abs(q)",)
    assert set(mask_terms("fossen")["X"]) == {"u", "u*abs(u)"}  # McCarter 3.41
    with pytest.raises(ValueError, match="unknown damping model"):
        mask_terms("no_such_model")


def test_damping_structure_from_mask_and_coefficients():
    d = DampingTerms.from_spec("weiss_quadratic", {"X:u*abs(u)": -61.117, "N:v*abs(r)": -3.0})
    assert d.as_dict() == {"X:u*abs(u)": -61.117, "Y:v*abs(v)": 0.0, "Z:w*abs(w)": 0.0,
                           "K:p*abs(p)": 0.0, "M:q*abs(q)": 0.0, "N:r*abs(r)": 0.0,
                           "N:v*abs(r)": -3.0}  # fmt: skip
    nu = torch.tensor([0.5, 0.2, 0.0, 0.0, 0.0, -0.4])
    force = d.force(nu)
    assert torch.allclose(force, torch.tensor([-61.117 * 0.25, 0, 0, 0, 0, -3.0 * 0.2 * 0.4]))


def test_a_velocity_at_rounding_level_has_no_sign(vehicle_factory, rng):
    """Vv = V sign(v), Vw = V sign(w): a w that is only rounding (1e-17 m/s on a vehicle that
    never heaves) gave every Vw term a full-size V with a random sign. Its sign is 0, as of an
    exact zero, in NumPy, torch and the compiled kernel; a w a sensor resolves keeps its sign."""
    from nnid.physics import compiled
    from nnid.physics.fossen import FossenModel

    nu = rng.normal(size=(200, 6))
    nu[:, 2] = 0.0
    rounding = nu.copy()
    rounding[:, 2] = 1e-17 * rng.standard_normal(200)
    lib = BasisLibrary()
    vw = [i for i, t in enumerate(lib.terms) if "Vw" in t]
    exact = lib(nu)
    assert not exact[:, vw].any()
    for got in (lib(rounding), lib(torch.tensor(rounding)).numpy()):
        assert np.array_equal(got[:, vw], exact[:, vw])
        assert np.allclose(got, exact, rtol=0, atol=1e-15)  # the w factors: rounding
    # heave without sway: a rounding v leaves Vv 0 too
    swapped = nu.copy()
    swapped[:, 2], swapped[:, 1] = nu[:, 1], 1e-17 * rng.standard_normal(200)
    vv = [i for i, t in enumerate(lib.terms) if "Vv" in t]
    assert not lib(swapped)[:, vv].any()
    # a micrometre per second is motion: Vw = ±V
    measured = nu.copy()
    measured[:, 2] = 1e-6 * np.sign(rng.standard_normal(200))
    big_v = np.hypot(nu[:, 1], measured[:, 2])
    assert np.allclose(
        lib(measured)[:, lib.index("Vw*u")], nu[:, 0] * big_v * np.sign(measured[:, 2])
    )
    # the simulator's kernel: a Vw force on a vehicle that never heaves stays off
    veh = vehicle_factory(damping={"coefficients": {"M:u*Vw": -40.0, "Z:abs(q)*Vw": -5.0}})
    form = FossenModel.from_vehicle(veh).feature_form()
    tau = np.array([20.0, 5.0, 0.0, 0.0, 0.0, 1.0])
    for x_exact in np.hstack([np.zeros((5, 6)), nu[:5] * [1, 1, 0, 0, 0, 1]]):
        x_round = x_exact.copy()
        x_round[8] = 1e-17
        # the Coriolis products of w stay rounding; -40 u V was the jump
        got, want = compiled.rhs(form, x_round, tau), compiled.rhs(form, x_exact, tau)
        assert np.allclose(got, want, rtol=0, atol=1e-12), np.abs(got - want).max()
