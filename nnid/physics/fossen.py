"""The Fossen 6-DOF model: ν̇ = M⁻¹(τ − C(ν)ν − D(ν)ν − g(η)), η̇ = J(η)ν.

Weiss eqs 11-31; McCarter eq. 2.1. With a steady, irrotational water current the hydrodynamic
terms act on the relative velocity ν_r = ν − ν_c (Fossen 2011 eq. 10.1):

    M_RB ν̇ + C_RB(ν)ν + M_A ν̇_r + C_A(ν_r)ν_r + D(ν_r)ν_r + g(η) = τ + b,

where ν_c = [J₁(η)ᵀ v_c; 0] so that ν̇_c = [ν_c,lin × ω; 0], and b is a constant external force
(Caccia's mean disturbance). A first-order actuator lag adds the applied force as a state.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from nnid.physics.added_mass import added_mass_coriolis_force, added_mass_matrix
from nnid.physics.damping import DampingTerms
from nnid.physics.damping_library import ONE
from nnid.physics.kinematics import eta_dot, rotation_matrix
from nnid.physics.restoring import restoring_force, restoring_matrix
from nnid.physics.rigid_body import rigid_body_coriolis_force, rigid_body_mass_matrix

PAIRS = tuple((i, j) for i in range(6) for j in range(i, 6))
"""Index pairs of the 21 quadratic monomials νᵢνⱼ (i ≤ j), McCarter's C.3 order."""


def _t(x) -> Tensor:
    return x if isinstance(x, Tensor) else torch.as_tensor(np.asarray(x), dtype=torch.float64)


@dataclass(frozen=True)
class FeatureForm:
    """The model's right-hand side as numbers: ν̇ = M⁻¹(τ + b − Q_RB m(ν) − Q_A m(ν_r)
    + Θ ξ(ν_r) − G s(η) + M_A ν̇_c), with m the 21 quadratic monomials and
    s = (sin θ, cos θ sin φ, cos θ cos φ). Extracted from the torch terms by polarisation, so it
    is the same physics; compiled kernels evaluate it without Python overhead.
    """

    m_inv: np.ndarray
    q_rb: np.ndarray
    q_a: np.ndarray
    g_mat: np.ndarray
    theta: np.ndarray
    codes: np.ndarray
    added_mass: np.ndarray
    bias: np.ndarray
    current: np.ndarray
    u_c: float
    lag: float


class TorchForm(NamedTuple):
    """:class:`FeatureForm` as tensors (they may require grad); evaluated by
    :mod:`nnid.physics.form`."""

    m_inv: Tensor
    q_rb: Tensor
    q_a: Tensor
    g_mat: Tensor
    theta: Tensor
    codes: Tensor
    added_mass: Tensor
    bias: Tensor
    current: Tensor
    u_c: float


def net_force_of(tau_b: Tensor, terms: Sequence[Tensor]) -> Tensor:
    """:meth:`FossenModel.net_force` from τ + b (``tau_b``) and its other ``terms``
    (:meth:`FossenModel.motion_terms`), summed in its order: τ + b − C ν + τ_D − g
    (+ M_A ν̇_c), so that each force is the one :meth:`~FossenModel.net_force` gives, bit for
    bit."""
    out = tau_b - terms[0] + terms[1] - terms[2]
    return out + terms[3] if len(terms) > 3 else out


class FossenModel:
    """Fossen 6-DOF dynamics with parameters as float64 tensors (they may require grad)."""

    def __init__(
        self,
        mass,
        inertia,
        added_mass,
        damping: DampingTerms,
        weight,
        buoyancy,
        r_g=(0.0, 0.0, 0.0),
        r_b=(0.0, 0.0, 0.0),
        current=(0.0, 0.0, 0.0),
        external_bias=(0.0,) * 6,
        actuator_lag: float = 0.0,
        check: bool = True,
    ) -> None:
        self.mass = _t(mass)
        self.inertia = _t(inertia)
        if self.inertia.dim() == 1:
            self.inertia = torch.diag(self.inertia)
        self.added_mass = _t(added_mass)
        self.damping = damping
        self.weight = _t(weight)
        self.buoyancy = _t(buoyancy)
        self.r_g = _t(r_g)
        self.r_b = _t(r_b)
        self.current = _t(current)
        self.external_bias = _t(external_bias)
        self.actuator_lag = float(actuator_lag)
        mass_matrix = self.mass_matrix().detach()
        if check and not torch.linalg.eigvalsh(0.5 * (mass_matrix + mass_matrix.T)).min() > 0:
            raise ValueError(
                "M = M_RB + M_A is not positive definite; check mass, inertia and added mass "
                "(diagonal added-mass derivatives are negative in Fossen's convention)"
            )

    @classmethod
    def from_vehicle(cls, vehicle) -> FossenModel:
        """Build from a validated :class:`nnid.vehicle.Vehicle`."""
        return cls(
            mass=vehicle.mass,
            inertia=vehicle.inertia_matrix(),
            added_mass=added_mass_matrix(vehicle.added_mass),
            damping=DampingTerms.from_spec(
                vehicle.damping.model, vehicle.damping.coefficients, vehicle.damping.u_c
            ),
            weight=vehicle.weight,
            buoyancy=vehicle.buoyancy,
            r_g=vehicle.r_g,
            r_b=vehicle.r_b,
            current=vehicle.current,
            external_bias=vehicle.external_bias,
            actuator_lag=vehicle.actuator_lag,
        )

    @property
    def state_size(self) -> int:
        return 18 if self.actuator_lag > 0 else 12

    def rigid_body_mass_matrix(self) -> Tensor:
        return rigid_body_mass_matrix(self.mass, self.r_g, self.inertia)

    def mass_matrix(self) -> Tensor:
        """M = M_RB + M_A (Weiss eq. 18)."""
        return self.rigid_body_mass_matrix() + self.added_mass

    def current_body(self, eta: Tensor) -> Tensor:
        """ν_c = [J₁(η)ᵀ v_c; 0], the water velocity in the body frame."""
        rot = rotation_matrix(eta[..., 3:6])
        lin = (rot.transpose(-1, -2) @ self.current.unsqueeze(-1)).squeeze(-1)
        return torch.cat([lin, torch.zeros_like(lin)], -1)

    def coriolis_force(self, nu: Tensor, nu_r: Tensor | None = None) -> Tensor:
        """C_RB(ν)ν + C_A(ν_r)ν_r."""
        nu_r = nu if nu_r is None else nu_r
        return rigid_body_coriolis_force(
            self.mass, self.r_g, self.inertia, nu
        ) + added_mass_coriolis_force(self.added_mass, nu_r)

    def restoring_force(self, eta: Tensor) -> Tensor:
        """g(η)."""
        return restoring_force(eta, self.weight, self.buoyancy, self.r_g, self.r_b)

    def damping_force(self, nu_r: Tensor) -> Tensor:
        """τ_D(ν_r) = −D(ν_r)ν_r."""
        return self.damping.force(nu_r)

    def net_force(self, eta: Tensor, nu: Tensor, tau: Tensor) -> Tensor:
        """M ν̇: everything on the right-hand side of the equation of motion."""
        return net_force_of(tau + self.external_bias, self.motion_terms(eta, nu))

    def motion_terms(self, eta: Tensor, nu: Tensor) -> tuple[Tensor, ...]:
        """The terms of :meth:`net_force` besides τ + b, in its order: C ν, τ_D, g and, in a
        current, M_A ν̇_c. None reads b, so forces that differ in b alone (a regression's
        external-force columns) share them (:func:`net_force_of`)."""
        if not bool(torch.any(self.current != 0)) and not self.current.requires_grad:
            # still water: ν_r = ν (skips a rotation per sample on long logs)
            return self.coriolis_force(nu), self.damping_force(nu), self.restoring_force(eta)
        nu_c = self.current_body(eta)
        nu_r = nu - nu_c
        nu_c_dot = torch.cat(
            [torch.linalg.cross(nu_c[..., :3], nu[..., 3:6]), torch.zeros_like(nu[..., 3:6])], -1
        )
        return (
            self.coriolis_force(nu, nu_r),
            self.damping_force(nu_r),
            self.restoring_force(eta),
            nu_c_dot @ self.added_mass.T,
        )

    def nu_dot(self, eta: Tensor, nu: Tensor, tau: Tensor) -> Tensor:
        """ν̇ = M⁻¹ (τ + b − C ν − D ν − g)."""
        m_inv = torch.linalg.inv(self.mass_matrix())
        return self.net_force(eta, nu, tau) @ m_inv.T

    def rhs(self, x: Tensor, tau: Tensor) -> Tensor:
        """ẋ for x = [η, ν] (or [η, ν, τ_applied] with actuator lag) under commanded τ."""
        eta, nu = x[..., 0:6], x[..., 6:12]
        if self.actuator_lag > 0:
            applied = x[..., 12:18]
            lag_dot = (tau - applied) / self.actuator_lag
            return torch.cat([eta_dot(eta, nu), self.nu_dot(eta, nu, applied), lag_dot], -1)
        return torch.cat([eta_dot(eta, nu), self.nu_dot(eta, nu, tau)], -1)

    def kinetic_energy(self, nu: Tensor) -> Tensor:
        """T = ½ νᵀ M ν (M_A symmetric part), conserved without damping, forces and restoring."""
        m = self.mass_matrix()
        m = 0.5 * (m + m.T)
        return 0.5 * ((nu @ m) * nu).sum(-1)

    def form(self) -> TorchForm:
        """The right-hand side in feature form as tensors that keep their autograd graph
        (joint training of physics parameters differentiates through it); see
        :class:`FeatureForm`. Polarisation: the 21 monomial coefficients of a quadratic h(ν)
        are h(e_i) for i = j and h(e_i + e_j) − h(e_i) − h(e_j) otherwise."""
        eye = torch.eye(6, dtype=torch.float64)
        probes = torch.stack([eye[i] if i == j else eye[i] + eye[j] for i, j in PAIRS])
        diag_i = torch.as_tensor([i for i, j in PAIRS if i != j])
        diag_j = torch.as_tensor([j for i, j in PAIRS if i != j])
        mixed = torch.as_tensor([k for k, (i, j) in enumerate(PAIRS) if i != j])

        def polarise(h) -> Tensor:
            out = h(probes)  # [21, 6]
            units = h(eye)  # [6, 6]
            fix = torch.zeros_like(out).index_add(0, mixed, units[diag_i] + units[diag_j])
            return (out - fix).T

        q_rb = polarise(lambda n: rigid_body_coriolis_force(self.mass, self.r_g, self.inertia, n))
        q_a = polarise(lambda n: added_mass_coriolis_force(self.added_mass, n))
        # G in closed form, not fitted to attitudes: a fit (MKL's lstsq, then the normal
        # equations) left last-bit entries where G is zero that differed between processors,
        # and those forces moved the simulated vehicle in DOFs nothing drives
        g_mat = restoring_matrix(self.weight, self.buoyancy, self.r_g, self.r_b)
        theta = self.damping.coefficients
        codes = torch.as_tensor(self.damping.codes, dtype=torch.long).reshape(-1, 3)
        if not self.damping.terms:
            theta = torch.zeros(6, 1, dtype=torch.float64)
            codes = torch.full((1, 3), ONE, dtype=torch.long)
        return TorchForm(
            m_inv=torch.linalg.inv(self.mass_matrix()),
            q_rb=q_rb,
            q_a=q_a,
            g_mat=g_mat,
            theta=theta,
            codes=codes,
            added_mass=self.added_mass,
            bias=self.external_bias,
            current=self.current,
            u_c=self.damping.u_c,
        )

    def feature_form(self) -> FeatureForm:
        """The right-hand side as arrays for compiled kernels (see :class:`FeatureForm`)."""
        with torch.no_grad():
            form = self.form()
            return FeatureForm(
                m_inv=form.m_inv.numpy().copy(),
                q_rb=np.ascontiguousarray(form.q_rb.numpy()),
                q_a=np.ascontiguousarray(form.q_a.numpy()),
                g_mat=np.ascontiguousarray(form.g_mat.numpy()),
                theta=np.ascontiguousarray(form.theta.numpy().astype(np.float64)),
                codes=form.codes.numpy().astype(np.int64),
                added_mass=form.added_mass.numpy().copy(),
                bias=form.bias.numpy().copy(),
                current=form.current.numpy().copy(),
                u_c=form.u_c,
                lag=self.actuator_lag,
            )
