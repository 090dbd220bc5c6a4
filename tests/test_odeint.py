"""Integration of sampled inputs through torchdiffeq (nnid.physics.odeint) and the feature-form
evaluator of the Fossen model (nnid.physics.form), checked against exact solutions, the
term-by-term model and the compiled kernel."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.linalg import expm

from nnid.physics import compiled
from nnid.physics.form import Field, current_body, eta_dot, ned_axes, trig
from nnid.physics.fossen import FossenModel
from nnid.physics.integrate import rk4
from nnid.physics.kinematics import kinematics_matrix, rotation_matrix
from nnid.physics.odeint import SampledInput, integrate
from nnid.vehicle import load_vehicle

# a damped oscillator ẋ = A x + B u driven by held (ZOH) inputs: exact by the matrix exponential
A = torch.tensor([[0.0, 1.0], [-4.0, -0.6]], dtype=torch.float64)
B = torch.tensor([[0.0], [1.5]], dtype=torch.float64)


def _linear(x: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
    return x @ A.T + u @ B.T


def _exact_zoh(x0: np.ndarray, u: np.ndarray, dt: float) -> np.ndarray:
    """States at the sample times under inputs held over each sample (exact discretisation)."""
    n = A.shape[0]
    big = np.zeros((n + 1, n + 1))
    big[:n, :n], big[:n, n:] = A.numpy(), B.numpy()
    phi = expm(big * dt)
    ad, bd = phi[:n, :n], phi[:n, n:]
    out = [x0]
    for k in range(u.shape[0]):
        out.append(ad @ out[-1] + bd @ u[k])
    return np.stack(out)


@pytest.fixture
def held_inputs():
    gen = np.random.default_rng(3)
    return np.repeat(gen.normal(size=(8, 1)), 5, axis=0), 0.1  # steps every 5 samples


def test_sampled_input_holds_or_interpolates():
    values = torch.tensor([[[0.0], [1.0], [3.0]], [[2.0], [2.0], [0.0]]], dtype=torch.float64)
    zoh, lin = SampledInput(values, 0.5), SampledInput(values, 0.5, "linear")
    s = torch.tensor(1.5, dtype=torch.float64)  # halfway between samples 1 and 2
    assert zoh(s).tolist() == [[1.0], [2.0]]
    assert lin(s).tolist() == [[2.0], [1.0]]
    assert zoh(torch.tensor(9.0)).tolist() == [[3.0], [0.0]]  # beyond the last: the last
    with pytest.raises(ValueError, match="hold"):
        SampledInput(values, 0.5, "cubic")


def test_fixed_step_rk4_switches_held_inputs_exactly_at_the_samples(held_inputs):
    """The perturbed grid evaluates the last stage of a step just before the sample, so a
    held input never leaks into the step before its own: the error is RK4's alone and falls
    as h⁴ with sub-steps (a leak would leave an O(h) error that sub-steps do not remove)."""
    u, dt = held_inputs
    x0 = np.array([0.3, -0.2])
    exact = _exact_zoh(x0, u, dt)
    errors = []
    for substeps in (1, 4):
        got = integrate(
            _linear,
            torch.as_tensor(x0),
            SampledInput(torch.as_tensor(u), dt),
            steps=len(u),
            substeps=substeps,
        ).numpy()
        assert got.shape == exact.shape
        errors.append(np.abs(got - exact).max())
    assert errors[0] < 1e-4
    assert errors[1] < errors[0] / 4**4 * 1.5


def test_adaptive_dopri5_with_jumps_at_the_samples_is_accurate(held_inputs):
    u, dt = held_inputs
    x0 = np.array([0.3, -0.2])
    got = integrate(
        _linear,
        torch.as_tensor(x0),
        SampledInput(torch.as_tensor(u), dt),
        steps=len(u),
        method="dopri5",
        rtol=1e-10,
        atol=1e-12,
    ).numpy()
    assert np.abs(got - _exact_zoh(x0, u, dt)).max() < 1e-8


def test_batched_segments_match_one_at_a_time_and_the_own_rk4(held_inputs):
    u, dt = held_inputs
    gen = torch.Generator().manual_seed(0)
    x0 = torch.randn(3, 2, generator=gen, dtype=torch.float64)
    inputs = torch.as_tensor(np.stack([u, -u, 2 * u]))  # [B, N, 1]
    both = integrate(_linear, x0, SampledInput(inputs, dt), steps=u.shape[0])
    for b in range(3):
        one = integrate(_linear, x0[b], SampledInput(inputs[b], dt), steps=u.shape[0])
        assert torch.equal(both[:, b], one)
    # the classic RK4 of nnid.physics.integrate: another 4th-order rule, the same answer to h⁴
    own = rk4(_linear, x0, inputs.transpose(0, 1), dt)
    assert (both - own).abs().max() < 1e-5


def test_adjoint_gradient_equals_backpropagation(held_inputs):
    """The adjoint integrates the sensitivities backwards on the same grid: the gradient of
    the continuous problem, equal to backpropagation through the steps up to RK4's error."""
    u, dt = held_inputs
    inputs = SampledInput(torch.as_tensor(u), dt)
    grads = []
    for adjoint in (False, True):
        a = A.clone().requires_grad_(True)

        def f(x, v, a=a):
            return x @ a.T + v @ B.T

        x = integrate(
            f,
            torch.tensor([0.3, -0.2], dtype=torch.float64),
            inputs,
            substeps=8,
            adjoint=adjoint,
            adjoint_params=(a,),
        )
        (x**2).sum().backward()
        grads.append(a.grad.clone())
    assert torch.allclose(grads[0], grads[1], rtol=1e-7, atol=0.0)


def test_bad_arguments_are_refused(held_inputs):
    u, dt = held_inputs
    inputs = SampledInput(torch.as_tensor(u), dt)
    x0 = torch.zeros(2, dtype=torch.float64)
    with pytest.raises(ValueError, match="method"):
        integrate(_linear, x0, inputs, method="euler")
    with pytest.raises(ValueError, match="power of two"):
        integrate(_linear, x0, inputs, substeps=3)


# -- the feature form ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["seamor", "vt690", "romeo"])
@pytest.mark.parametrize("current", [(0.0, 0.0, 0.0), (0.2, -0.15, 0.05)])
def test_feature_form_field_equals_the_term_by_term_model_and_the_kernel(name, current):
    model = FossenModel.from_vehicle(load_vehicle(name))
    model.current = torch.tensor(current, dtype=torch.float64)
    gen = torch.Generator().manual_seed(1)
    x = torch.randn(300, 12, generator=gen, dtype=torch.float64) * 0.5
    tau = torch.randn(300, 6, generator=gen, dtype=torch.float64) * 20
    field = Field(model.form())
    got = field(x, tau)
    want = model.rhs(x, tau)
    assert torch.allclose(got, want, rtol=1e-12, atol=1e-12 * float(want.abs().max()))
    form = model.feature_form()
    kernel = np.stack(
        [compiled.rhs(form, a, b) for a, b in zip(x.numpy(), tau.numpy(), strict=True)]
    )
    assert np.allclose(got.numpy(), kernel, rtol=1e-12, atol=1e-12 * float(want.abs().max()))


def test_kinematics_written_out_equal_the_matrices():
    gen = torch.Generator().manual_seed(2)
    eta = torch.randn(200, 6, generator=gen, dtype=torch.float64)
    nu = torch.randn(200, 6, generator=gen, dtype=torch.float64)
    s, c = trig(eta)
    want = (kinematics_matrix(eta) @ nu.unsqueeze(-1)).squeeze(-1)
    assert torch.allclose(eta_dot(nu, s, c), want, atol=1e-13)
    rot = rotation_matrix(eta[:, 3:6])
    assert torch.allclose(ned_axes(s, c), rot.reshape(-1, 9), atol=1e-15)
    v_c = torch.tensor([0.3, -0.2, 0.1], dtype=torch.float64)
    assert torch.allclose(current_body(v_c, s, c), (rot.transpose(-1, -2) @ v_c), atol=1e-15)


def test_feature_form_keeps_gradients_to_physics_parameters():
    """Joint training differentiates the form with respect to the added mass and damping."""
    model = FossenModel.from_vehicle(load_vehicle("seamor"))
    ma = model.added_mass.clone().requires_grad_(True)
    model.added_mass = ma
    x = torch.full((4, 12), 0.2, dtype=torch.float64)
    Field(model.form())(x, torch.ones(4, 6, dtype=torch.float64)).sum().backward()
    assert ma.grad is not None and ma.grad.abs().sum() > 0
