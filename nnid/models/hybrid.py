"""Neural-ODE hybrid: the Fossen model keeps its terms, a small network learns what it misses.

Force level (default; its output is a force in newtons and newton metres, so it can be read)::

    M ν̇ = τ_eff + b − C(ν)ν − D(ν_r)ν_r − g(η) + f_θ(ν_r, τ, η, τ history),    η̇ = J(η)ν

Acceleration level (``level="acceleration"``, the form of Skulstad et al. on RV Gunnerus):
ν̇ = M⁻¹(τ_eff + b − C(ν)ν − D(ν_r)ν_r − g(η)) + a_θ(…). The Fossen terms are nnid's one
implementation (:class:`nnid.physics.fossen.FossenModel`, Weiss eqs 11-31), built from a
parametric least-squares fit of the same training data (:class:`ParametricModel`); with
``physics="joint"`` its hydrodynamic parameters (added mass, damping) train with the network
under a Gaussian prior of relative width ``prior`` around that fit.

The network sees the velocity through the water ν_r, the nominal inputs τ, the attitude as
the NED axes seen in the body frame (the entries of R(Θ): an undeclared steady current acts
along ν_c = Rᵀ v_c and gravity along Rᵀ e_z, so effects of either are simple functions of
these, where Euler angles would need products of their sines and cosines) and an input
memory: τ − F_T τ for first-order filters F_T(s) = 1/(T s + 1) of the time constants
``memory`` (an actuator that lags its command shows as a force that depends on how the
command moved, which the instantaneous τ cannot say). Its last layer starts at zero, so the
untrained hybrid *is* the parametric fit, and its force is scaled per DOF by the RMS input
force of the training data (:func:`input_scale`: at least a hundredth of the largest of its
unit group). Integration goes through torchdiffeq (:mod:`nnid.physics.odeint`);
training is multiple shooting (:class:`nnid.trainers.neural_ode.MultipleShooting`) with a
penalty on the network's force so it stays small where the physics suffices, and early
stopping on held-out free runs.

A vehicle file's actuator lag T enters as :func:`nnid.evaluation.prediction.predict_states`
takes it: τ_eff is the force the physics feels, which follows the applied force commanded
(:func:`nnid.datasets.arrays.nominal_forces` unlagged, through the installation) through
1/(T s + 1), exact between samples from its value at each window's first sample; so the
untrained hybrid predicts what its :class:`ParametricModel` predicts. The network's channels
stay the lagged force's samples. Holding τ_eff's samples instead (as before) delayed the force
by about half a sample: 0.18 std of free-run difference from the fit it started from.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import pandas as pd
import torch
from sklearn.utils.validation import check_is_fitted
from torch import Tensor, nn
from torch.func import functional_call

from nnid.datasets.arrays import nominal_forces
from nnid.datasets.log import POSE, VELOCITY, check_time_unit, frame_step
from nnid.datasets.preprocess import check_uniform, experiment_rows, first_order_lag
from nnid.datasets.segmentation import label_transients
from nnid.errors import NnidInputError, checked_number
from nnid.evaluation.prediction import (
    MAX_STEP,
    Replay,
    blank_initial,
    check_mode,
    felt_forces,
    fly_closed_loop,
    measured_states,
    mode_steps,
)
from nnid.models.base import NOT_FITTED, check_log
from nnid.models.hybrid_kernel import NetArrays, free_run
from nnid.models.io_model import seeded_linear
from nnid.models.parametric import (
    FossenPlant,
    ParametricModel,
    checked_dofs,
    regression_trainer,
)
from nnid.physics.added_mass import parse_added_mass_key
from nnid.physics.damping import DampingTerms, parse_coefficient_key
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.form import Field, ned_axes, trig
from nnid.physics.form import eta_dot as form_eta_dot
from nnid.physics.fossen import FeatureForm, FossenModel
from nnid.physics.odeint import LAGGED, METHODS, SampledInput, integrate
from nnid.physics.parts import Parts
from nnid.physics.thrusters import apply_deadband, force_deadband
from nnid.threads import torch_threads
from nnid.trainers.history import (
    Progress,
    history_state,
    restored_history,
    scored_validation,
    staged,
)
from nnid.trainers.neural_ode import Batch, MultipleShooting, Run
from nnid.validation import MAX_WIDTH, adjoint_solver

DTYPE = torch.float64
#: state features of the network: ν_r (scaled), then the 9 entries of R(Θ)
_STATE_FEATURES = 15
#: rows of predictions integrated at once (k-step windows of long logs)
_CHUNK = 4096
#: the compiled kernel's rule for each fixed-step method (torchdiffeq's rk4 is the 3/8 rule)
_RULES = {"rk4": "3/8", "nnid_rk4": "classic"}
#: tensors.pt prefix of the physics fit's tensors, apart from the network's state dict
_BASELINE = "baseline."


class HybridPhysics(nn.Module):
    """The Fossen model of fitted parts, with (``joint``) relative changes δ of its
    hydrodynamic parameters as trainable weights: θ = θ_fit + s δ with s = |θ_fit| (or the
    largest |θ| of its kind where the fit is zero), so δ = 0.1 is a 10 % change."""

    def __init__(self, parts: Parts, joint: Sequence[str] = ()) -> None:
        super().__init__()
        base = parts.model(check=False)
        self.terms = base.damping.terms
        self.u_c = base.damping.u_c
        for name, value in (
            ("mass", base.mass),
            ("inertia", base.inertia),
            ("added_mass", base.added_mass),
            ("coefficients", base.damping.coefficients),
            ("mask", base.damping.mask),
            ("weight", base.weight),
            ("buoyancy", base.buoyancy),
            ("r_g", base.r_g),
            ("r_b", base.r_b),
            ("current", base.current),
            ("bias", base.external_bias),
        ):
            self.register_buffer(name, value.detach().clone())
        self.joint = list(joint)
        am = [n for n in self.joint if ":" not in n]
        dm = [n for n in self.joint if ":" in n]
        idx_a = [parse_added_mass_key(n) for n in am]
        idx_d = [(FORCES.index(f), self.terms.index(t)) for f, t in map(parse_coefficient_key, dm)]
        self.register_buffer("rows_a", torch.tensor([i for i, _ in idx_a], dtype=torch.long))
        self.register_buffer("cols_a", torch.tensor([j for _, j in idx_a], dtype=torch.long))
        self.register_buffer("rows_d", torch.tensor([i for i, _ in idx_d], dtype=torch.long))
        self.register_buffer("cols_d", torch.tensor([j for _, j in idx_d], dtype=torch.long))
        fit_a = -self.added_mass[self.rows_a, self.cols_a]  # derivatives: M_A = −[X_udot …]
        fit_d = self.coefficients[self.rows_d, self.cols_d]
        self.register_buffer("scale_a", _scale(fit_a))
        self.register_buffer("scale_d", _scale(fit_d))
        self.delta = nn.Parameter(torch.zeros(len(self.joint), dtype=DTYPE))
        self.delta.requires_grad_(bool(self.joint))
        self._fields: dict[bool, Field] = {}
        self._form: FeatureForm | None = None

    def values(self) -> dict[str, float]:
        """The jointly trained parameters at their current values (vehicle-file names)."""
        n_a = self.rows_a.numel()
        with torch.no_grad():
            a = -self.added_mass[self.rows_a, self.cols_a] + self.scale_a * self.delta[:n_a]
            d = self.coefficients[self.rows_d, self.cols_d] + self.scale_d * self.delta[n_a:]
        return dict(zip(self.joint, [*a.tolist(), *d.tolist()], strict=True))

    def fossen(self, delta: Tensor | None = None) -> FossenModel:
        """The Fossen model at the current parameters (or at the changes ``delta``)."""
        delta = self.delta if delta is None else delta
        n_a = self.rows_a.numel()
        # an off-diagonal derivative moves its mirror too: M_A stays symmetric (McCarter
        # eq. 2.33), as the vehicle file the trained values are saved in holds it
        off = self.rows_a != self.cols_a
        shift = -self.scale_a * delta[:n_a]
        added_mass = self.added_mass.index_put(
            (
                torch.cat([self.rows_a, self.cols_a[off]]),
                torch.cat([self.cols_a, self.rows_a[off]]),
            ),
            torch.cat([shift, shift[off]]),
            accumulate=True,
        )
        coefficients = self.coefficients.index_put(
            (self.rows_d, self.cols_d), self.scale_d * delta[n_a:], accumulate=True
        )
        return FossenModel(
            self.mass,
            self.inertia,
            added_mass,
            DampingTerms(self.terms, coefficients, self.mask, self.u_c),
            self.weight,
            self.buoyancy,
            self.r_g,
            self.r_b,
            current=self.current,
            external_bias=self.bias,
            check=False,
        )

    def field(self, positions: bool = True) -> Field:
        """The right-hand side at the current parameters (:class:`nnid.physics.form.Field`;
        built once while the physics is frozen)."""
        if self.joint:
            return Field(self.fossen().form(), positions)
        if positions not in self._fields:
            with torch.no_grad():
                self._fields[positions] = Field(self.fossen().form(), positions)
        return self._fields[positions]

    def feature_form(self, delta: Tensor | None = None) -> FeatureForm:
        """The physics at the current parameters (or at ``delta``) as arrays for the compiled
        kernel (built once while the physics is frozen)."""
        if self.joint:
            return self.fossen(delta).feature_form()
        if self._form is None:
            self._form = self.fossen().feature_form()
        return self._form

    def forget(self) -> None:
        """Drop the cached right-hand sides (after the parameters were loaded anew)."""
        self._fields.clear()
        self._form = None


def _scale(fit: Tensor) -> Tensor:
    """|θ_fit|, with zeros replaced by the largest |θ| of the group (or 1)."""
    if fit.numel() == 0:
        return fit.abs()
    top = float(fit.abs().max())
    return torch.where(fit.abs() > 0, fit.abs(), torch.full_like(fit, top if top > 0 else 1.0))


#: the smallest input scale of a DOF, relative to the largest RMS force (or moment) of its unit
#: group: a DOF whose τ is round-off (1e-13 N) was scaled by it, its input channel O(1) noise
#: and its correction scaled to nothing
INPUT_FLOOR = 1e-2


def input_scale(tau: np.ndarray) -> np.ndarray:
    """Per DOF, the RMS of the training forces ``tau`` ``[N, 6]`` (X … N), at least
    :data:`INPUT_FLOOR` times the largest of its group (forces in N, moments in N m: the
    scales of DOFs not actuated, or barely, in a unit); 1 in a group nothing actuates."""
    rms = np.sqrt(np.mean(tau**2, 0))
    scale = np.ones(6)
    for group in (slice(0, 3), slice(3, 6)):
        top = rms[group].max()
        if top > 0:
            scale[group] = np.maximum(rms[group], INPUT_FLOOR * top)
    return scale


class CorrectionNet(nn.Module):
    """f_θ: a tanh MLP from the features to one output per DOF, zero where the DOF is not
    corrected; outputs scaled per DOF by ``out_scale`` (units of force or acceleration). The
    last layer starts at zero: the untrained network adds nothing."""

    def __init__(
        self,
        n_in: int,
        hidden: Sequence[int],
        dofs: Sequence[bool],
        generator: torch.Generator,
    ) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        prev = n_in
        for h in hidden:
            layers += [seeded_linear(prev, int(h), generator).to(DTYPE), nn.Tanh()]
            prev = int(h)
        last = nn.utils.skip_init(nn.Linear, prev, 6, dtype=DTYPE)  # no global-RNG draw
        nn.init.zeros_(last.weight)
        nn.init.zeros_(last.bias)
        self.layers = nn.Sequential(*layers, last)
        self.register_buffer("out_scale", torch.ones(6, dtype=DTYPE))
        self.register_buffer("dof_mask", torch.as_tensor(list(dofs), dtype=DTYPE))
        self.register_buffer("nu_scale", torch.ones(6, dtype=DTYPE))

    def forward(self, features: Tensor) -> Tensor:
        return self.layers(features) * (self.out_scale * self.dof_mask)


class HybridDynamics(nn.Module):
    """The hybrid's vector field and its integration: ``forward(x0, inputs, dt)`` gives the
    states ``[L + 1, B, 12]`` (η, ν) from ``x0`` ``[B, 12]`` under held inputs ``[B, L, m]``
    (the applied forces τ_eff, then the network's input channels). With an actuator ``lag``
    T > 0 the first six are the force commanded and six more at the end the lagged force at
    each sample: the field reads, as τ_eff, the lag exact between samples from those
    (:class:`nnid.physics.odeint.SampledInput`'s ``lag``; the compiled kernel and nnid_rk4
    step it from the first one)."""

    def __init__(
        self,
        physics: HybridPhysics,
        net: CorrectionNet,
        level: str,
        method: str,
        adjoint: bool,
        lag: float = 0.0,
    ) -> None:
        super().__init__()
        self.physics = physics
        self.net = net
        self.level = level
        self.method = method
        self.adjoint = adjoint
        self.lag = float(lag)

    def channels(self, inputs: Tensor) -> Tensor:
        """The network's input channels of held inputs (without τ_eff and the lag's columns)."""
        return inputs[..., 6 : inputs.shape[-1] - (LAGGED if self.lag > 0 else 0)]

    def features(self, nu_r: Tensor, s: Tensor, c: Tensor, channels: Tensor) -> Tensor:
        """Network features: ν_r scaled, the NED axes in the body frame (the entries of
        R(Θ)), the scaled input channels."""
        return torch.cat([nu_r / self.net.nu_scale, ned_axes(s, c), channels], -1)

    def correction(self, fld: Field, x: Tensor, u: Tensor) -> Tensor:
        """f_θ (force level) or a_θ (acceleration level) at states ``x`` and held inputs
        ``u``."""
        s, c = trig(x)
        _, nu_r = fld.features(x[..., 6:12], s, c)
        return self.net(self.features(nu_r, s, c, self.channels(u)))

    def vector_field(self, fld: Field):
        """ẋ = f(x, u) of the hybrid on the physics ``fld``."""
        force_level = self.level == "force"

        def f(x: Tensor, u: Tensor) -> Tensor:
            nu = x[..., 6:12]
            s, c = trig(x)
            z, nu_r = fld.features(nu, s, c)
            corr = self.net(self.features(nu_r, s, c, u[..., 6:]))
            if force_level:
                acc = fld.accelerations(u[..., 0:6] + corr, z)
            else:
                acc = fld.accelerations(u[..., 0:6], z) + corr
            return torch.cat([form_eta_dot(nu, s, c, fld.positions), acc], -1)

        return f

    def arrays(self, params: dict[str, Tensor] | None = None) -> tuple[FeatureForm, NetArrays]:
        """The physics and the network at ``params`` (a :func:`functional_call` dictionary;
        default and for what it leaves out: the module's own) as the compiled kernel takes
        them."""
        given = params or {}
        with torch.no_grad():
            delta = given.get("physics.delta", self.physics.delta)
            blocks = []
            for i, layer in enumerate(self.net.layers):
                if isinstance(layer, nn.Linear):
                    for name in ("weight", "bias"):
                        value = given.get(f"net.layers.{i}.{name}", getattr(layer, name))
                        blocks.append(value.detach().reshape(-1))
            sizes = [layer.in_features for layer in self.net.layers if isinstance(layer, nn.Linear)]
            net = NetArrays(
                torch.cat(blocks).numpy().astype(np.float64),
                np.array([*sizes, 6], dtype=np.int64),
                self.net.nu_scale.numpy().copy(),
                (self.net.out_scale * self.net.dof_mask).numpy().copy(),
            )
            return self.physics.feature_form(delta), net

    @property
    def compiled(self) -> bool:
        """Whether free runs without gradients take the compiled kernel (the fixed-step
        methods; ``dopri5`` stays on torchdiffeq)."""
        return self.method in _RULES

    def free_run(
        self,
        x0: Tensor,
        inputs: Tensor,
        dt: float,
        substeps: int = 1,
        params: dict[str, Tensor] | None = None,
        arrays: tuple[FeatureForm, NetArrays] | None = None,
    ) -> Tensor:
        """:meth:`forward` without gradients, through the compiled kernel
        (:mod:`nnid.models.hybrid_kernel`) where :attr:`compiled`; the states at ``params``
        (or at the ready ``arrays`` of :meth:`arrays`)."""
        if not self.compiled:
            with torch.no_grad():
                if params is None:
                    return self(x0, inputs, dt, substeps)
                return functional_call(self, params, (x0, inputs, dt, substeps))
        form, net = arrays if arrays is not None else self.arrays(params)
        states = free_run(
            form,
            net,
            x0.detach().numpy(),
            inputs.detach().numpy(),
            dt,
            substeps,
            _RULES[self.method],
            self.level,
            self.lag,
        )
        return torch.as_tensor(states)

    def forward(
        self, x0: Tensor, inputs: Tensor, dt: float, substeps: int = 1, positions: bool = True
    ) -> Tensor:
        params = tuple(p for p in self.parameters() if p.requires_grad)
        return integrate(
            self.vector_field(self.physics.field(positions)),
            x0,
            SampledInput(inputs, dt, lag=self.lag),
            steps=inputs.shape[-2],
            method=self.method,
            substeps=substeps,
            adjoint=self.adjoint,
            adjoint_params=params if self.adjoint else None,
        )


def power_of_two_substeps(dt: float, max_step: float = MAX_STEP) -> int:
    """The smallest power of two of sub-steps per sample that keeps steps ≤ ``max_step``."""
    n = max(1, int(np.ceil(dt / max_step - 1e-9)))
    return 1 << (n - 1).bit_length()


class _Problem:
    """The hybrid as the multiple-shooting trainer sees it (:class:`ShootingProblem`)."""

    def __init__(self, model: HybridModel, dt: float, substeps: int) -> None:
        self.model = model
        self.module = model.dynamics_
        self.dt = dt
        self.substeps = substeps
        self.index = [6 + DOFS.index(d) for d in model.scored_]
        self.scale = torch.as_tensor([model.velocity_scale_[d] for d in model.scored_])

    def simulate(
        self, params: dict[str, Tensor], x0: Tensor, inputs: Tensor, train: bool = True
    ) -> Tensor:
        if not train:  # a held-out score: no gradient, the compiled kernel
            return self.module.free_run(x0, inputs, self.dt, self.substeps, params)
        # positions do not feed back into the dynamics: the fit leaves them out
        return functional_call(self.module, params, (x0, inputs, self.dt, self.substeps, False))

    def outputs(self, states: Tensor) -> Tensor:
        return states[..., self.index] / self.scale

    def penalty(self, params: dict[str, Tensor], batch: Batch, rows: int) -> Tensor:
        """The network's force at the measured states, relative to its scale, weighted by
        ``force_penalty``; with joint physics, δ / prior weighted by ``prior_weight``."""
        out = []
        model = self.model
        if model.force_penalty > 0:
            net = {k[4:]: v for k, v in params.items() if k.startswith("net.")}
            dyn = self.module
            x, u = batch.measured, batch.inputs.transpose(0, 1)
            # at measured states only: a NaN velocity's force would make every gradient NaN
            known = torch.isfinite(x).all(-1)
            if not bool(known.all()):
                x, u = x[known], u[known]
            s, c = trig(x)
            _, nu_r = dyn.physics.field(False).features(x[..., 6:12], s, c)
            feats = dyn.features(nu_r, s, c, dyn.channels(u))
            f = functional_call(dyn.net, net, (feats,)) / dyn.net.out_scale
            if f.numel():
                out.append((model.force_penalty * rows / f.numel()) ** 0.5 * f.reshape(-1))
        if model.physics == "joint" and model.prior_weight > 0 and self.module.physics.joint:
            delta = params["physics.delta"]
            w = (model.prior_weight * rows / delta.numel()) ** 0.5
            out.append(w * delta / model.prior)
        return torch.cat(out) if out else torch.zeros(0, dtype=DTYPE)


def _kept_on(stages: list[dict]) -> str:
    """What chose each stage's kept epoch: ``"validation free run"`` where every stage scored
    held-out windows (:func:`~nnid.trainers.history.scored_validation`), ``"training loss"``
    where none did (fitted without validation data: nothing held out, so never to be read as
    early stopping), and says so where the stages differ."""
    scored = [scored_validation([stage]) for stage in stages]
    if all(scored):
        return "validation free run"
    return "training loss" if not any(scored) else "validation free run in some stages only"


class HybridModel(FossenPlant):
    """Fossen model plus a learned correction (module docstring), behind the model protocol.

    Args:
        vehicle: the vehicle file (rigid body and what is known).
        physics: ``"frozen"`` (the parametric fit stays) or ``"joint"`` (its added mass and
            damping train with the network, prior around the fit).
        level: ``"force"`` or ``"acceleration"``: where the network's output enters.
        unknowns, dofs, physics_trainer: the parametric fit (:class:`ParametricModel`); the
            network corrects the same DOFs.
        hidden: widths of the network's tanh layers.
        memory: time constants (s) of the input memory features (empty: none).
        force_penalty: weight of the mean square of the network's force (relative to its
            scale) against the mean square of the normalised simulation error.
        prior: relative standard deviation of the joint parameters around the fit.
        prior_weight: weight of the prior (mean square of δ/prior) in the objective.
        segments, trainer, batch_segments, balance, validation_window: the multiple-shooting
            training (:class:`MultipleShooting`); ``trainer`` is the optimiser (Adam, or
            Levenberg-Marquardt for small networks). An optimiser step costs about the same
            for 64 segments as for 256 (per-operation overhead dominates on a CPU), so long
            segments want large batches; ``configs/hybrid.toml`` takes 64 of 5 samples.
        method: ``"auto"`` (default: torchdiffeq's fixed-step ``"rk4"``, or nnid's own
            ``"nnid_rk4"`` when the trainer is Levenberg-Marquardt, whose forward-mode
            Jacobians torchdiffeq's input handling cannot pass), ``"rk4"``, ``"dopri5"``
            (adaptive) or ``"nnid_rk4"`` (:func:`nnid.physics.odeint.integrate`);
            ``adjoint``: gradients by the adjoint ODE (less memory, slower on a CPU; torchdiffeq's
            solvers only, so neither with ``"nnid_rk4"`` nor with Levenberg-Marquardt).
        savgol_window, savgol_order: velocity and acceleration derivation where the log lacks
            them (:func:`nnid.models.parametric.prepare_motion`).
        zoh_midpoint: the parametric fit regresses on the mean of consecutive inputs (held
            commands; :class:`ParametricModel`); the simulation holds them.
        pose_velocities, pose_savgol: velocities derived from the pose before the fit and
            that derivative's window (:class:`ParametricModel`; ``nnid train`` sets them).
        seed: initial weights and segment draws.
    """

    kind = "hybrid"
    validation_role = "early stopping"

    def __init__(
        self,
        vehicle,
        physics: Literal["frozen", "joint"] = "frozen",
        level: Literal["force", "acceleration"] = "force",
        unknowns: Sequence[str] = ("added_mass", "damping"),
        dofs: Sequence[str] = DOFS,
        physics_trainer: Any = None,
        hidden: Sequence[int] = (32, 32),
        memory: Sequence[float] = (0.25, 1.0),
        force_penalty: float = 1e-3,
        prior: float = 0.1,
        prior_weight: float = 1e-2,
        segments: Sequence[float] = (0.5, 1.0, 2.0),
        trainer: Any = None,
        batch_segments: int = 256,
        balance: bool = True,
        validation_window: float | None = 5.0,
        method: str = "auto",
        adjoint: bool = False,
        savgol_window: float = 1.0,
        savgol_order: int = 4,
        zoh_midpoint: bool = True,
        pose_velocities: Sequence[str] = (),
        pose_savgol: tuple[float, int] | None = None,
        seed: int = 0,
    ) -> None:
        self.vehicle = vehicle
        self.physics = physics
        self.level = level
        self.unknowns = unknowns
        self.dofs = dofs
        self.physics_trainer = physics_trainer
        self.hidden = hidden
        self.memory = memory
        self.force_penalty = force_penalty
        self.prior = prior
        self.prior_weight = prior_weight
        self.segments = segments
        self.trainer = trainer
        self.batch_segments = batch_segments
        self.balance = balance
        self.validation_window = validation_window
        self.method = method
        self.adjoint = adjoint
        self.savgol_window = savgol_window
        self.savgol_order = savgol_order
        self.zoh_midpoint = zoh_midpoint
        self.pose_velocities = pose_velocities
        self.pose_savgol = pose_savgol
        self.seed = seed

    # -- settings --------------------------------------------------------------------------------
    def _check_settings(self) -> None:
        # the parametric fit's settings by its own checks, named as this model names them
        # (its trainer is physics_trainer here), before the fit would stumble on them
        checked_dofs(self.dofs)
        regression_trainer(self.physics_trainer, "physics_trainer")
        if self.physics not in ("frozen", "joint"):
            raise NnidInputError("physics is 'frozen' or 'joint'", field="physics")
        if self.level not in ("force", "acceleration"):
            raise NnidInputError("level is 'force' or 'acceleration'", field="level")
        lm = getattr(self.trainer, "kind", None) == "lm"
        if self.method == "auto":
            self.method_ = "nnid_rk4" if lm else "rk4"
        elif self.method not in METHODS:
            raise NnidInputError(f"method is 'auto' or one of {', '.join(METHODS)}", field="method")
        elif lm and self.method != "nnid_rk4":
            raise NnidInputError(
                "Levenberg-Marquardt takes forward-mode Jacobians (torch.func), which "
                "torchdiffeq's input handling does not support: use method 'auto' or "
                "'nnid_rk4' with it",
                field="method",
            )
        else:
            self.method_ = self.method
        adjoint_solver(self.adjoint, lm, self.method_)
        for name in ("hidden", "memory", "segments"):
            if isinstance(getattr(self, name), str | bytes) or not np.iterable(getattr(self, name)):
                raise NnidInputError(f"{name} is a list of numbers", field=name)
        for h in self.hidden:  # capped as the config caps it: wider is a typo
            checked_number(h, "hidden", 1, strict=False, integer=True, maximum=MAX_WIDTH)
        for t in self.memory:
            checked_number(t, "memory")  # time constants (s)
        for s in self.segments:
            checked_number(s, "segments")  # lengths (s)
        if self.validation_window is not None:
            checked_number(self.validation_window, "validation_window")
        checked_number(self.force_penalty, "force_penalty", strict=False)
        checked_number(self.prior, "prior")
        checked_number(self.prior_weight, "prior_weight", strict=False)
        checked_number(self.batch_segments, "batch_segments", 1, strict=False, integer=True)
        checked_number(self.seed, "seed", strict=False, integer=True)
        if self.trainer is not None and not callable(getattr(self.trainer, "fit", None)):
            raise NnidInputError(
                f"trainer is an optimiser (Adam, LevenbergMarquardt), not {self.trainer!r}",
                field="trainer",
            )

    def _physics_model(self) -> ParametricModel:
        return ParametricModel(
            self.vehicle,
            self.unknowns,
            self.dofs,
            self.physics_trainer,
            None,
            self.savgol_window,
            self.savgol_order,
            self.zoh_midpoint,
            self.pose_velocities,
            self.pose_savgol,
        )

    def _new_dynamics(self, generator: torch.Generator | None = None) -> HybridDynamics:
        joint = []
        if self.physics == "joint":
            joint = [
                n for n in self.structure_.names if ":" in n or (n.endswith("dot") and "_" in n)
            ]
        n_in = _STATE_FEATURES + 6 * (1 + len(self.memory))
        net = CorrectionNet(
            n_in,
            self.hidden,
            [d in self.dofs_ for d in DOFS],
            generator if generator is not None else torch.Generator().manual_seed(int(self.seed)),
        )
        return HybridDynamics(
            HybridPhysics(self.parts_, joint),
            net,
            self.level,
            self.method_,
            bool(self.adjoint),
            float(self.vehicle.actuator_lag),
        )

    # -- data ------------------------------------------------------------------------------------
    def _channels(self, log: pd.DataFrame, tau: np.ndarray) -> np.ndarray:
        """Held inputs ``[N, 6 + 6 (1 + len(memory))]``: τ_eff, then the network's channels
        τ/σ_τ and (τ − F_T τ)/σ_τ per memory time constant. With the vehicle's actuator lag T
        (``tau`` the lagged force), τ_eff is the applied force commanded and the lagged one at
        each sample ends them (:class:`HybridDynamics`), as
        :func:`~nnid.evaluation.prediction.predict_states` takes it."""
        scale = self.input_scale_
        chans = [self.parts_.applied(tau), tau / scale]
        for t in self.memory:
            chans.append((tau - first_order_lag(tau, log, float(t))) / scale)
        lag = float(self.vehicle.actuator_lag)
        if lag > 0:
            commanded = nominal_forces(log, self.vehicle, lagged=False)
            chans[0] = self.parts_.applied(commanded)
            chans.append(felt_forces(self.parts_, log, commanded, lag))
        return np.concatenate(chans, 1)

    def _runs(self, log: pd.DataFrame, data: dict[str, np.ndarray]) -> list[Run]:
        channels = self._channels(log, data["tau"])
        states = measured_states(log)
        # a velocity not measured stays missing (measured_states starts a prediction at 0
        # there): it trained the net toward ν = 0 and started segments from it; the trainer
        # scores no row of it and starts no segment from it, as the parametric fit leaves it out
        for k, c in enumerate(VELOCITY):
            if c in log:
                states[~np.isfinite(log[c].to_numpy(np.float64)), 6 + k] = np.nan
        targets = states[:, [6 + DOFS.index(d) for d in self.scored_]]
        targets = targets / np.array([self.velocity_scale_[d] for d in self.scored_])
        transient = label_transients(log).to_numpy()
        runs = []
        for _, pos in experiment_rows(log):
            runs.append(
                Run(
                    torch.as_tensor(states[pos]),
                    torch.as_tensor(channels[pos]),
                    torch.as_tensor(targets[pos]),
                    transient[pos],
                )
            )
        return runs

    @staticmethod
    def _dt(log: pd.DataFrame) -> float:
        """The typical step of ``log``'s runs, the joins between them left out."""
        return frame_step(log)

    # -- fit -------------------------------------------------------------------------------------
    def _fit(self, log: pd.DataFrame, validation: pd.DataFrame | None, progress: Progress) -> None:
        """The parametric fit, then the network (and the joint parameters) by multiple
        shooting on the training experiments; early stopping on ``validation``'s free runs."""
        self._check_settings()
        # time in seconds (the physics prediction's rule): a log in milliseconds trained for
        # hours on segments and windows of whole samples, then predicted nonsense
        check_time_unit(log)
        if validation is not None:
            check_time_unit(validation)
        # one rate over every run, validation's too: the training steps them all at one dt
        # (a 10-Hz run among 20-Hz ones was flown at 0.05 s: velocity RMS error 0.24)
        what = "the hybrid model's training"
        interval = check_uniform(log, what, "training log", one_rate=True)
        if validation is not None:
            check_uniform(validation, what, "validation log", interval, one_rate=True)
        physics = self._physics_model().fit(log, progress=staged(progress, "physics fit"))
        self.physics_ = physics
        self.parts_, self.structure_ = physics.parts_, physics.structure_
        self.report_ = physics.report_
        self._set_outputs(physics.dofs_)
        log, data = self._data(log, accelerations=False)
        self.scored_ = [d for d in self.dofs_ if d in log]
        if not self.scored_:
            raise NnidInputError("the log has no velocity of the fitted DOFs", field="dofs")
        std = {d: float(log[d].std()) for d in self.scored_}
        self.velocity_scale_ = {d: (s if s > 0 else 1.0) for d, s in std.items()}
        self.input_scale_ = input_scale(data["tau"])
        self.dynamics_ = self._new_dynamics()
        self._set_scales(log, data)
        dt = self._dt(log)
        self.dt_ = dt
        substeps = power_of_two_substeps(dt)
        runs = self._runs(log, data)
        val_runs: list[Run] = []
        if validation is not None:
            val_log, val_data = self._data(validation, accelerations=False)
            val_runs = self._runs(val_log, val_data)
        trainer = MultipleShooting(
            self.segments,
            self.trainer,
            self.batch_segments,
            self.balance,
            self.validation_window,
            self.seed,
        )
        self.trainer_ = trainer
        with torch_threads(1):
            self.history_ = trainer.fit(
                _Problem(self, dt, substeps), runs, dt, val_runs, staged(progress, "network")
            )
        self.stages_ = [
            {"segment_s": s, **h.as_dict()}
            for s, h in zip(self.segments, self.history_, strict=True)
        ]
        left_out = {
            what: max((stage.get(key, 0) for stage in self.stages_), default=0)
            for key, what in (
                ("segments_without_start", "training segments"),
                ("validation_windows_without_start", "validation windows"),
            )
        }
        if any(left_out.values()):
            said = " and ".join(f"{n} {what}" for what, n in left_out.items() if n)
            warnings.warn(
                f"{said} start from a velocity the log does not hold (NaN) and were left "
                "out of the hybrid's training (the most of any stage; describe()['stages'] "
                "counts them per stage)",
                UserWarning,
                stacklevel=3,
            )
        kept_on = _kept_on(self.stages_)
        if kept_on != "validation free run":
            # nothing held out to stop on (in every stage, or in some): the kept epoch was
            # chosen on the training loss itself there, and is no held-out choice
            if validation is None:
                why = "the hybrid was fitted without validation data"
            else:  # given, but too short to fly a stage's windows
                stages = "any stage" if kept_on == "training loss" else "some stages"
                why = f"the validation log gave no held-out free run to {stages}"
            warnings.warn(
                f"{why} (no held-out free run to stop on): those stages ran their epochs and "
                "kept the epoch of their lowest training loss (Adam; Levenberg-Marquardt its "
                "last accepted step), not one chosen on held-out data; give fit(log, "
                "validation) held-out experiments longer than the segments for early stopping",
                UserWarning,
                stacklevel=3,
            )

    def _validation_used(self, validation: pd.DataFrame | None) -> str | None:
        """Early stopping where a stage flew the validation log's windows; not where it had
        none to fly (``describe()["kept_on"]`` says what each stage kept its epoch on)."""
        held = validation is not None and scored_validation(self.stages_)
        return self.validation_role if held else None

    def _set_scales(self, log: pd.DataFrame, data: dict[str, np.ndarray]) -> None:
        """The network's input and output scales from the training data: ν by its standard
        deviation, the output by the input scale per DOF (:func:`input_scale`; divided by the
        diagonal of M at acceleration level)."""
        net = self.dynamics_.net
        nu_std = np.array([self.velocity_scale_.get(d, 1.0) for d in DOFS])
        scale = self.input_scale_.copy()
        if self.level == "acceleration":
            mass = self.parts_.model(check=False).mass_matrix().numpy()
            scale = scale / np.diag(mass)
        with torch.no_grad():
            net.nu_scale.copy_(torch.as_tensor(nu_std))
            net.out_scale.copy_(torch.as_tensor(scale))

    # -- prediction ------------------------------------------------------------------------------
    def _simulate(
        self,
        x0: np.ndarray,
        channels: np.ndarray,
        dt: float,
        arrays: tuple[FeatureForm, NetArrays] | None = None,
    ) -> np.ndarray:
        """States ``[L + 1, B, 12]`` from ``x0`` ``[B, 12]`` under ``channels`` ``[B, L, m]``
        (``arrays``: the kernel's, when the caller steps many times)."""
        states = self.dynamics_.free_run(
            torch.as_tensor(x0),
            torch.as_tensor(channels),
            dt,
            power_of_two_substeps(dt),
            arrays=arrays,
        )
        return states.numpy()

    def _predict(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        """Free run from each experiment's first measured state (experiments of one length and
        sampling interval integrated as one batch); k steps ahead from every measured state."""
        check_time_unit(log)  # stepped in seconds, as the fit was
        log, data = self._data(log, accelerations=False)
        check_uniform(log, "the hybrid model")
        channels = self._channels(log, data["tau"])
        x = measured_states(log)
        out = x.copy()
        k = mode_steps(mode)
        groups: dict[tuple[int, float], list[np.ndarray]] = {}
        for _, pos in experiment_rows(log):
            if pos.size >= 2:
                groups.setdefault((pos.size, self._dt(log.iloc[pos])), []).append(pos)
        with torch_threads(1):
            for (size, dt), members in groups.items():
                pos = np.stack(members)  # [B, size]
                if mode == "free_run":
                    states = self._simulate(x[pos[:, 0]], channels[pos[:, :-1]], dt)
                    out[pos.T] = states
                    continue
                # stepped through each run's rows, not the log's: a run's rows need not be
                # contiguous (runs A, B, A), and a window stepped by row ran on into B's
                rows = pos.reshape(-1)  # run after run, each in its own order
                n = max(size - k, 0)
                starts = (np.arange(len(members))[:, None] * size + np.arange(n)).reshape(-1)
                for a in range(0, starts.size, _CHUNK):
                    chunk = starts[a : a + _CHUNK]
                    windows = channels[rows[chunk[:, None] + np.arange(k)[None, :]]]
                    flown = self._simulate(x[rows[chunk]], windows, dt)
                    out[rows[chunk + k]] = flown[-1]
        pred = pd.DataFrame(out, columns=[*POSE, *VELOCITY], index=log.index)
        return blank_initial(pred, log, self.warmup_samples_ + k - 1)

    def closed_loop(
        self, log: pd.DataFrame, replay: Replay, mode: str | int = "free_run"
    ) -> pd.DataFrame:
        """The prediction flown under ``replay``'s autopilot, sample by sample (the command is
        the open-loop input plus the autopilot's feedback on the simulated state, held over the
        sample; the input memory follows the command as flown). Behind the vehicle's actuator
        lag T the stepper carries the force felt, as :meth:`_channels` lays it out: the
        physics' (applied, exact between samples) and the network's (nominal, its channels and
        memory), each stepped by the command held over the sample."""
        check_is_fitted(self, msg=NOT_FITTED)
        mode = check_mode(mode)
        check_time_unit(check_log(log))  # stepped in seconds, as the fit was
        log, data = self._data(log, accelerations=False)
        # the filters' states at every sample, of the commands as flown (the log's): a window
        # k samples ahead starts from them, as the open-loop prediction does (from the
        # window's own first command, a k-step flight differed by 0.9-1.6 std from it)
        logged = {t: first_order_lag(data["tau"], log, float(t)) for t in self.memory}
        lag = float(self.vehicle.actuator_lag)
        if lag > 0:  # data["tau"] is the nominal force felt, the network's input
            commanded = nominal_forces(log, self.vehicle, lagged=False)
            felt = (data["tau"], felt_forces(self.parts_, log, commanded, lag))
        arrays = self.dynamics_.arrays() if self.dynamics_.compiled else None

        def stepper(starts: np.ndarray, dt: float):
            memory = {t: history[starts] for t, history in logged.items()}
            if lag > 0:
                decay = np.exp(-dt / lag)
                state_of = {"nominal": felt[0][starts], "applied": felt[1][starts]}

            def step(state: np.ndarray, command: np.ndarray) -> np.ndarray:
                # through the deadband, as the log's forces the network learned from went
                command = apply_deadband(command, force_deadband(self.vehicle))
                applied = self.parts_.applied(command)
                # behind a lag the network sees the force the commands before this one built
                seen = state_of["nominal"] if lag > 0 else command
                chans = [applied, seen / self.input_scale_]
                for t in self.memory:
                    a = np.exp(-dt / float(t))
                    prev = memory[t]
                    chans.append((seen - prev) / self.input_scale_)
                    memory[t] = a * prev + (1 - a) * seen
                if lag > 0:  # the physics' lag starts from the force felt at the sample
                    chans.append(state_of["applied"])
                    for key, force in (("nominal", command), ("applied", applied)):
                        state_of[key] = decay * state_of[key] + (1 - decay) * force
                chans = np.concatenate(chans, 1)[:, None, :]
                return self._simulate(state, chans, dt, arrays)[-1]

            return step

        with torch_threads(1):
            pred = fly_closed_loop(log, replay, stepper, mode)
        return blank_initial(pred, log, self.warmup_samples_ + mode_steps(mode) - 1)

    # -- the equation and what the network learned -----------------------------------------------
    def correction(self, log: pd.DataFrame) -> pd.DataFrame:
        """The learned correction as a force (N, N m; M a_θ at acceleration level) at the
        measured states and inputs of ``log``, columns ``X … N``."""
        check_is_fitted(self, msg=NOT_FITTED)
        log, data = self._data(check_log(log), accelerations=False)
        x = torch.as_tensor(measured_states(log))
        u = torch.as_tensor(self._channels(log, data["tau"]))
        with torch.no_grad():
            physics = self.dynamics_.physics
            f = self.dynamics_.correction(physics.field(), x, u)
            if self.level == "acceleration":
                f = f @ physics.fossen().mass_matrix().T
        return pd.DataFrame(f.numpy(), columns=list(FORCES), index=log.index)

    def correction_share(self, log: pd.DataFrame) -> dict[str, float | None]:
        """RMS of the learned force over RMS of the physics' hydrodynamic damping force
        −D(ν_r)ν_r, per corrected DOF, and ``max``: how much the network adds to the physics."""
        f = self.correction(log)
        log, _ = self._data(log, accelerations=False)
        with torch.no_grad():
            x = torch.as_tensor(measured_states(log))
            s, c = trig(x)
            _, nu_r = self.dynamics_.physics.field().features(x[..., 6:12], s, c)
            damping = self.dynamics_.physics.fossen().damping_force(nu_r).numpy()
        out: dict[str, float | None] = {}
        for d in self.dofs_:
            k = DOFS.index(d)
            ref = float(np.sqrt(np.mean(damping[:, k] ** 2)))
            out[d] = float(np.sqrt(np.mean(f[FORCES[k]].to_numpy() ** 2))) / ref if ref else None
        shares = [v for v in out.values() if v is not None]
        out["max"] = max(shares) if shares else None
        return out

    def _residual(self, log: pd.DataFrame) -> pd.DataFrame:
        """R − f_θ: the Fossen equation error with the learned force on the model's side."""
        r = self._equation(log, self.joint_parts())
        f = self.correction(log)
        return r - f[r.columns].set_axis(r.index)

    def joint_parts(self) -> Parts:
        """The physics at its trained values (the fit itself unless ``physics="joint"``)."""
        parts = self.parts_.copy()
        for name, value in self.dynamics_.physics.values().items():
            parts.set(name, value)
        return parts

    def baseline(self) -> ParametricModel:
        """The physics-only model the hybrid starts from (the same split, no network)."""
        check_is_fitted(self, msg=NOT_FITTED)
        return self.physics_

    # -- protocol --------------------------------------------------------------------------------
    def _params(self) -> dict[str, dict[str, float | None]]:
        """The physics parameters (at their jointly trained values, without a standard
        error, when ``physics="joint"``)."""
        out = dict(self.physics_.params)
        for name, value in self.dynamics_.physics.values().items():
            out[name] = {"value": value, "stderr": None}
        return out

    def _n_params(self) -> int:
        return len(self.physics_.params) + sum(p.numel() for p in self.dynamics_.net.parameters())

    def describe(self) -> dict:
        return {
            **super().describe(),
            "vehicle": self.vehicle.name,
            "dofs": list(self.dofs_),
            "physics": self.physics,
            "level": self.level,
            "method": self.method_,
            "network_weights": sum(p.numel() for p in self.dynamics_.net.parameters()),
            "kept_on": _kept_on(self.stages_),
            "stages": self.stages_,
        }

    def _state(self) -> tuple[dict, dict[str, Tensor]]:
        # the physics fit's own tensors (a recursive trainer's θ path) under a prefix of their
        # own: the network's state dict has a "physics." submodule
        physics_state, physics_tensors = self.physics_._state()
        state = {
            "physics": physics_state,
            "physics_trainer": self.physics_.trainer_name(),
            "scored": list(self.scored_),
            "velocity_scale": self.velocity_scale_,
            "input_scale": self.input_scale_.tolist(),
            "dt": self.dt_,
            "stages": self.stages_,
            "fit_history": history_state(self.history_),  # every field: stages_ sums it up
        }
        tensors = {f"{_BASELINE}{k}": v for k, v in physics_tensors.items()}
        return state, {**dict(self.dynamics_.state_dict()), **tensors}

    def _restore(self, state: dict, tensors: dict[str, Tensor]) -> None:
        self._check_settings()
        physics = self._physics_model()
        own = {k: v for k, v in tensors.items() if k.startswith(_BASELINE)}
        physics._restore(state["physics"], {k[len(_BASELINE) :]: v for k, v in own.items()})
        physics.fitted_by_ = state.get("physics_trainer")  # absent from older files
        self.physics_ = physics
        self.parts_, self.structure_ = physics.parts_, physics.structure_
        if hasattr(physics, "report_"):  # absent from older files, as the history
            self.report_ = physics.report_
        if "fit_history" in state:
            self.history_ = restored_history(state["fit_history"])
        self._set_outputs(physics.dofs_)
        self.scored_ = list(state["scored"])
        self.velocity_scale_ = {k: float(v) for k, v in state["velocity_scale"].items()}
        self.input_scale_ = np.asarray(state["input_scale"], dtype=float)
        self.dt_ = float(state["dt"])
        self.stages_ = state["stages"]
        self.dynamics_ = self._new_dynamics()
        self.dynamics_.load_state_dict({k: v for k, v in tensors.items() if k not in own})
        self.dynamics_.physics.forget()


__all__ = ["CorrectionNet", "HybridDynamics", "HybridModel", "HybridPhysics"]
