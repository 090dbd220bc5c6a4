"""Integration of a vehicle ODE driven by sampled inputs, through torchdiffeq.

torchdiffeq integrates ẋ = f(t, x) and leaves inputs to its users (its issues #128, #129,
#145). A logged input is a sequence of samples on a uniform grid: :class:`SampledInput` holds
them, batched over segments (``[B, N, m]``), and returns the input at any time by zero-order
hold (a command held over its sample, as thrusters receive it) or by linear interpolation.
:func:`integrate` is the one entry point: it builds the time grid, checks the arguments once,
and calls ``torchdiffeq.odeint`` (or ``odeint_adjoint``):

- ``method="rk4"`` (default): fixed steps of ``dt / substeps`` on the sample grid, with
  torchdiffeq's ``perturb`` so that the last stage of a step is evaluated just before the
  sample boundary: a held input switches exactly at the samples, never inside a step. Time
  runs in samples inside (ẋ scaled by ``dt``), so the grid and the stage times are exact binary
  numbers (``substeps`` a power of two) and the one-ulp perturbation always lands on the
  right side of a sample;
- ``method="dopri5"``: adaptive steps with the sample times as ``jump_t`` (where a held input
  jumps), so the error control restarts there instead of shrinking the step to nothing. A
  solve that diverges (torchdiffeq asserts on a non-finite state or a step that underflows)
  gives NaN states, as a fixed-step solve that diverges does: a diverged free run, not an
  exception;
- ``adjoint=True``: gradients by the adjoint ODE (``odeint_adjoint``), which stores no
  intermediate states: a memory saver for long horizons, slower on a CPU (it integrates the
  system backwards a second time);
- ``method="nnid_rk4"``: nnid's own classic RK4 (:func:`nnid.physics.integrate.rk4`), which
  holds each input over its step explicitly instead of through the time it is called at. It
  exists for forward-mode Jacobians (Levenberg-Marquardt's ``torch.func.jvp``/``vmap``):
  torchdiffeq's perturbation is an ``autograd.Function`` without ``setup_context``, which
  those transforms refuse. It is also ~10 % faster (fewer operations per step), which is why
  the neural state-space model, whose small vector field is dominated by per-step overhead,
  keeps it.

A first-order lag on the first six inputs (a vehicle's actuator lag T: the force felt follows
the force commanded through 1/(T s + 1)) is :class:`SampledInput`'s ``lag``: the force felt is
exact between samples, from its value at each sample, wherever an integrator evaluates it
(``nnid_rk4`` steps it as :func:`~nnid.physics.integrate.rk4`'s lag states instead, from its
value at the first sample: the same numbers to rounding). Holding the lagged force's samples
instead delays it by about half a sample.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Literal

import torch
from torch import Tensor, nn
from torchdiffeq import odeint, odeint_adjoint

from nnid.physics.integrate import rk4

METHODS = ("rk4", "dopri5", "nnid_rk4")
Hold = Literal["zoh", "linear"]
#: inputs a ``lag`` acts on: the first six (a generalized force)
LAGGED = 6
#: how torchdiffeq's adaptive solvers' assertions on a diverged state begin
_DIVERGED = ("underflow in dt", "non-finite values in state")


class SampledInput(nn.Module):
    """Inputs sampled every ``dt`` seconds: ``values`` ``[N, m]`` or ``[B, N, m]`` (a batch of
    segments on one relative grid). Called at a time ``s`` counted in samples (a scalar
    tensor; :func:`integrate` works in samples), it returns the inputs there, ``[m]`` or
    ``[B, m]``: the sample at or before ``s`` (``hold="zoh"``) or the straight line between
    the two around it (``"linear"``); beyond the last sample, the last one.

    With ``lag`` T > 0 the first :data:`LAGGED` inputs are commanded to a first-order lag
    T ȧ = τ − a and ``values`` ends with :data:`LAGGED` more columns, a at each sample; the
    input at ``s`` is then a(s), exact under the held command (a(t_k + σ) = τ_k +
    (a_k − τ_k) e^(−σ/T), as :func:`nnid.physics.integrate.rk4` steps its lag states), before
    the other inputs (``m`` − :data:`LAGGED` wide: the last columns are not returned)."""

    def __init__(self, values: Tensor, dt: float, hold: Hold = "zoh", lag: float = 0.0) -> None:
        super().__init__()
        if hold not in ("zoh", "linear"):
            raise ValueError(f"hold is 'zoh' or 'linear', not {hold!r}")
        if values.dim() not in (2, 3) or values.shape[-2] < 1:
            raise ValueError("values must be [N, m] or [B, N, m] with N ≥ 1 samples")
        if lag > 0 and values.shape[-1] < 2 * LAGGED:
            raise ValueError(f"a lag takes {LAGGED} commanded and {LAGGED} lagged columns")
        self.values = values
        self.dt = float(dt)
        self.hold = hold
        self.lag = float(lag)
        self.n = values.shape[-2]

    def dt_field(self, f: Callable[[Tensor, Tensor], Tensor]) -> Callable[[Tensor, Tensor], Tensor]:
        """dx/ds = dt · f(x, u): the field in samples, for an integrator that holds u itself."""
        dt = self.dt
        return lambda x, u: dt * f(x, u)

    def forward(self, s: Tensor) -> Tensor:
        pos = float(s.detach())
        k = min(max(int(pos // 1.0), 0), self.n - 1)
        now = self.values[..., k, :]
        if self.lag > 0:
            # the lag state leaves its sample for the held command: past the last sample too
            decay = math.exp(-max(pos - k, 0.0) * self.dt / self.lag)
            command, rest, lagged = now.split([LAGGED, now.shape[-1] - 2 * LAGGED, LAGGED], -1)
            felt = command + (lagged - command) * decay
            if self.hold == "linear" and k + 1 < self.n:
                frac = min(max(pos - k, 0.0), 1.0)
                rest = torch.lerp(rest, self.values[..., k + 1, LAGGED:-LAGGED], frac)
            return torch.cat([felt, rest], -1)
        if self.hold == "zoh" or k + 1 >= self.n:
            return now
        frac = min(max(pos - k, 0.0), 1.0)
        return torch.lerp(now, self.values[..., k + 1, :], frac)


class _Field(nn.Module):
    """dx/ds = dt · f(x, u(s)) with ``s`` in samples, as torchdiffeq's ``func(s, x)``; a module
    so that the adjoint finds the parameters of ``f``."""

    def __init__(self, f: Callable[[Tensor, Tensor], Tensor], inputs: SampledInput) -> None:
        super().__init__()
        self.f = f
        self.inputs = inputs

    def forward(self, s: Tensor, x: Tensor) -> Tensor:
        return self.inputs.dt_field(self.f)(x, self.inputs(s))


def integrate(
    f: Callable[[Tensor, Tensor], Tensor],
    x0: Tensor,
    inputs: SampledInput,
    steps: int | None = None,
    method: str = "rk4",
    substeps: int = 1,
    adjoint: bool = False,
    adjoint_params: tuple[Tensor, ...] | None = None,
    rtol: float = 1e-7,
    atol: float = 1e-9,
) -> Tensor:
    """States at the sample times ``0, dt, …, steps·dt`` (``steps`` default: every sample
    but the last, whose input acts after the window), ``[steps + 1, …]`` with ``x0``'s shape
    after the first axis. ``f(x, u)`` is the vector field; with ``adjoint`` it must be (or
    belong to) an ``nn.Module`` whose parameters the gradient reaches, or the tensors to
    differentiate are given as ``adjoint_params``."""
    if method not in METHODS:
        raise ValueError(f"method is one of {', '.join(METHODS)}, not {method!r}")
    if substeps < 1 or substeps & (substeps - 1):
        raise ValueError("substeps must be a power of two (1, 2, 4, ...)")
    steps = inputs.n - 1 if steps is None else int(steps)
    if steps < 1:
        raise ValueError("integrate needs at least one step")
    if method == "nnid_rk4":
        if inputs.hold != "zoh" or adjoint:
            raise ValueError("nnid_rk4 holds inputs (zoh) and has no adjoint")
        held = inputs.values[..., :steps, :].movedim(-2, 0)  # time first
        if inputs.lag > 0:
            return _rk4_lagged(f, x0, inputs, held, substeps)
        return rk4(inputs.dt_field(f), x0, held, 1.0, substeps)
    s = torch.arange(steps + 1, dtype=x0.dtype)  # time in samples: exact grid points
    if method == "rk4":
        options = {"step_size": 1.0 / substeps, "perturb": True}
    else:
        options = {"jump_t": s[1:]}
    field = _Field(f, inputs)
    solve = odeint_adjoint if adjoint else odeint
    if adjoint and adjoint_params is None:
        adjoint_params = tuple(field.parameters())
    kwargs = {"adjoint_params": adjoint_params} if adjoint else {}
    try:
        return solve(field, x0, s, rtol=rtol, atol=atol, method=method, options=options, **kwargs)
    except AssertionError as error:
        if not str(error).startswith(_DIVERGED):
            raise
        # the states left the finite numbers: NaN from the start (no gradient), scored as a
        # diverged run, where a bare AssertionError ended a fit or a prediction
        return torch.full((steps + 1, *x0.shape), math.nan, dtype=x0.dtype)


def _rk4_lagged(
    f: Callable[[Tensor, Tensor], Tensor],
    x0: Tensor,
    inputs: SampledInput,
    held: Tensor,
    substeps: int,
) -> Tensor:
    """``nnid_rk4`` under a lagged :class:`SampledInput`: the force felt as
    :func:`~nnid.physics.integrate.rk4`'s lag states behind the first state, started from its
    value at the first sample and stepped exactly (in samples, the time unit inside)."""
    n = x0.shape[-1]

    def lagged(x: Tensor, u: Tensor) -> Tensor:
        rate = f(x[..., :n], torch.cat([x[..., n:], u[..., LAGGED:]], -1))
        return torch.cat([rate, torch.zeros_like(x[..., n:])], -1)  # rk4 steps the lag itself

    x = torch.cat([x0, inputs.values[..., 0, -LAGGED:]], -1)
    lag = inputs.lag / inputs.dt
    states = rk4(inputs.dt_field(lagged), x, held[..., :-LAGGED], 1.0, substeps, lag, LAGGED)
    return states[..., :n]
