"""The Fossen right-hand side in feature form, evaluated in PyTorch with few operations.

Why a second evaluator: a neural-ODE hybrid integrates the physics thousands of times per
training epoch on small batches (tens of segments × 4 RK stages × every sample), where the cost
is the number of tensor operations, not their size (~4 µs each with autograd on this project's
2-core machines). The term-by-term model (:class:`nnid.physics.fossen.FossenModel`: J(η) as a
6 × 6 matrix, C_RB and C_A from cross products, the basis library, g(η)) takes ~150 operations
per call. The feature form (:class:`nnid.physics.fossen.TorchForm`, extracted from those same
terms by polarisation; the form the compiled kernel evaluates) is

    ν̇ = M⁻¹(τ + b − Q_RB m(ν) − Q_A m(ν_r) + Θ ξ(ν_r) − G s(η) + M_A ν̇_c),   η̇ = J(η)ν,

with m the 21 quadratic monomials and s = (sin θ, cos θ sin φ, cos θ cos φ); :class:`Field`
stacks every term after τ into one feature vector z and M⁻¹ into one matrix, so ν̇ is a single
``addmm`` of [τ, z]: ~35 operations. It stays differentiable in the states, the inputs and the
form's tensors (joint training of physics parameters). Tests hold it equal to the term-by-term
model and to the compiled kernel.
"""

from __future__ import annotations

import torch
from torch import Tensor

from nnid.physics.damping_library import ONE, atoms
from nnid.physics.fossen import PAIRS, TorchForm

_I = torch.as_tensor([i for i, _ in PAIRS])
_J = torch.as_tensor([j for _, j in PAIRS])
#: atoms ν, |ν| and 1: all most damping structures need (no U, V, η of McCarter's library)
_LEAN = 12


def monomials(nu: Tensor) -> Tensor:
    """The 21 products νᵢνⱼ (i ≤ j) ``[..., 21]`` in :data:`PAIRS` order."""
    return nu[..., _I] * nu[..., _J]


def _rotate(a: Tensor, b: Tensor, s: Tensor, c: Tensor) -> tuple[Tensor, Tensor]:
    """(c a − s b, s a + c b): a plane rotation by the angle of (s, c)."""
    return c * a - s * b, s * a + c * b


def trig(eta: Tensor) -> tuple[Tensor, Tensor]:
    """(sin, cos) of the Euler angles φ θ ψ ``[..., 3]`` each: computed once per evaluation."""
    angles = eta[..., 3:6]
    return torch.sin(angles), torch.cos(angles)


def eta_dot(nu: Tensor, s: Tensor, c: Tensor, positions: bool = True) -> Tensor:
    """η̇ = J(η)ν written out (Weiss eqs 14-17) from the angles' sines ``s`` and cosines
    ``c``: R = R_z(ψ) R_y(θ) R_x(φ) applied as three plane rotations, and the Euler-rate
    transform. ``positions=False`` leaves ẋ ẏ ż at zero (they do not feed back into the
    dynamics; a fit of velocities does not need them)."""
    sf, st = s[..., 0], s[..., 1]
    cf, ct = c[..., 0], c[..., 1]
    q, r = nu[..., 4], nu[..., 5]
    a = sf * q + cf * r
    rates = torch.stack([nu[..., 3] + a * st / ct, cf * q - sf * r, a / ct], -1)
    if not positions:
        return torch.cat([torch.zeros_like(rates), rates], -1)
    u, v, w = nu[..., 0], nu[..., 1], nu[..., 2]
    v1, w1 = _rotate(v, w, sf, cf)
    w2, u2 = _rotate(w1, u, st, ct)
    x_dot, y_dot = _rotate(u2, v1, s[..., 2], c[..., 2])
    return torch.cat([torch.stack([x_dot, y_dot, w2], -1), rates], -1)


def ned_axes(s: Tensor, c: Tensor) -> Tensor:
    """The entries of R(Θ) = J₁ ``[..., 9]`` (row-major) from the angles' sines and cosines:
    column j of Rᵀ, i.e. row j of R, is NED axis j seen in the body frame, the direction a
    steady current along that axis (j = x, y) or gravity (j = z) takes in the body."""
    sf, st, sp = s.unbind(-1)
    cf, ct, cp = c.unbind(-1)
    a, b = st * sf, st * cf
    return torch.stack(
        [
            cp * ct,
            cp * a - sp * cf,
            cp * b + sp * sf,
            sp * ct,
            sp * a + cp * cf,
            sp * b - cp * sf,
            -st,
            ct * sf,
            ct * cf,
        ],
        -1,
    )


def current_body(current: Tensor, s: Tensor, c: Tensor) -> Tensor:
    """ν_c,lin = J₁(η)ᵀ v_c ``[..., 3]``: the NED current in the body frame (``s``, ``c``: the
    angles' sines and cosines)."""
    x, y = _rotate(current[0], current[1], -s[..., 2], c[..., 2])
    z, x = _rotate(current[2], x, -s[..., 1], c[..., 1])
    y, z = _rotate(y, z, -s[..., 0], c[..., 0])
    return torch.stack([x, y, z], -1)


class Field:
    """ẋ = f(x, τ) of a :class:`TorchForm`, with the constant matrices stacked once.

    ``accelerations(force, z)`` is M⁻¹(force + everything else on the right-hand side, ``z``
    from :meth:`features`): ``force`` is τ, or τ plus a learned force (a hybrid's
    correction)."""

    def __init__(self, form: TorchForm, positions: bool = True) -> None:
        self.form = form
        self.positions = positions
        self.still = not bool(torch.any(form.current != 0)) and not form.current.requires_grad
        codes = form.codes
        used = set(codes.unique().tolist()) - {ONE}
        self.lean = all(k < _LEAN for k in used)
        self.codes = torch.where(codes == ONE, _LEAN, codes) if self.lean else codes
        m_inv = form.m_inv
        blocks = [m_inv]  # τ (+ learned force)
        if self.still:
            blocks.append(-(form.q_rb + form.q_a))
        else:
            blocks += [-form.q_rb, -form.q_a, form.added_mass[:, 0:3]]
        blocks += [form.theta, -form.g_mat]
        # M⁻¹ applied to every block but the first (already M⁻¹)
        self.weight = torch.cat([blocks[0], m_inv @ torch.cat(blocks[1:], 1)], 1).T.contiguous()
        self.bias = form.bias @ m_inv.T

    def basis(self, nu_r: Tensor) -> Tensor:
        """ξ(ν_r) ``[..., K]``: the damping structure's terms."""
        if self.lean:
            a = torch.cat([nu_r, nu_r.abs(), torch.ones_like(nu_r[..., :1])], -1)
        else:
            a = atoms(nu_r, self.form.u_c)
        return a[..., self.codes].prod(-1)

    def features(self, nu: Tensor, s: Tensor, c: Tensor) -> tuple[Tensor, Tensor]:
        """(z, ν_r): every right-hand-side term after the force, as one vector per sample."""
        restoring = torch.stack([s[..., 1], c[..., 1] * s[..., 0], c[..., 1] * c[..., 0]], -1)
        if self.still:
            return torch.cat([monomials(nu), self.basis(nu), restoring], -1), nu
        cur = current_body(self.form.current, s, c)
        nu_r = torch.cat([nu[..., 0:3] - cur, nu[..., 3:6]], -1)
        nu_c_dot = torch.linalg.cross(cur, nu[..., 3:6])
        parts = [monomials(nu), monomials(nu_r), nu_c_dot, self.basis(nu_r), restoring]
        return torch.cat(parts, -1), nu_r

    def accelerations(self, force: Tensor, z: Tensor) -> Tensor:
        """ν̇ = M⁻¹(force + the terms ``z``) in one matrix product."""
        lead = z.shape[:-1]
        flat = torch.cat([force, z], -1).reshape(-1, self.weight.shape[0])
        return torch.addmm(self.bias, flat, self.weight).reshape(*lead, 6)

    def __call__(self, x: Tensor, tau: Tensor) -> Tensor:
        nu = x[..., 6:12]
        s, c = trig(x)
        z, _ = self.features(nu, s, c)
        return torch.cat([eta_dot(nu, s, c, self.positions), self.accelerations(tau, z)], -1)


def rhs(form: TorchForm, x: Tensor, tau: Tensor) -> Tensor:
    """ẋ for x = [η, ν] under applied forces ``tau`` (build a :class:`Field` once instead when
    the form is evaluated many times)."""
    return Field(form)(x, tau)
