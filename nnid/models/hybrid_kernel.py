"""The neural-ODE hybrid's free run, compiled: the Fossen kernel plus the correction network.

Why a second evaluator of the hybrid: a free run steps a small state through time, so through
torchdiffeq every right-hand-side evaluation costs its ~100 tensor operations' overhead
(~0.8 ms, whatever the batch), and a held-out free run of a 5-s window at 20 Hz is 400 of them
in sequence. Early stopping does that every epoch and scoring does it for every prediction:
about 40 % of a hybrid's training time was spent there (profiled on a 300-s log, 115 s in all).
Here the same vector field costs microseconds: the physics is
:func:`nnid.physics.compiled._rhs` on the model's :class:`~nnid.physics.fossen.FeatureForm`
(one implementation of Weiss eqs 11-31, the one the monitor and the simulator use), and the
network (:class:`nnid.models.hybrid.CorrectionNet`, tanh layers) is written out on its weights.
Gradients still go through the torch path (:class:`nnid.models.hybrid.HybridDynamics`); tests
hold the two equal.

The steps are those of the torch path, so the numbers agree to rounding: torchdiffeq's ``rk4``
is the 3/8-rule Runge-Kutta (``rule="3/8"``), nnid's ``nnid_rk4`` the classic one
(``rule="classic"``); both hold each input over its sample, but for a vehicle's actuator lag T:
then the force the physics feels follows the force commanded through 1/(T s + 1), stepped
exactly at every stage from its value at the window's first sample (the rule of
:func:`nnid.physics.compiled._integrate`, whose step :func:`~nnid.physics.compiled._lagged`
this kernel calls). At force level the network's
force joins the applied force (M⁻¹(τ + f_θ + …) = the physics' ν̇ + M⁻¹f_θ, by linearity), at
acceleration level its output adds to ν̇. The RK4 steps are written here again around this
field rather than shared with :mod:`nnid.physics.compiled` through a function argument: numba
compiles a step per field, and the 3/8 rule exists only here.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from nnid.physics.compiled import PARALLEL_MIN_STEPS, _lagged, _rhs, form_args
from nnid.physics.fossen import FeatureForm
from nnid.threads import torch_threads_kept

RULES = {"classic": 0, "3/8": 1}


class NetArrays(NamedTuple):
    """A :class:`~nnid.models.hybrid.CorrectionNet` as arrays: every layer's weight ``[out,
    in]`` (row-major) then bias, one after the other in ``flat``; the layer widths ``sizes``
    (inputs first, 6 last); the velocity scale of its inputs and its per-DOF output scale
    (``out_scale`` times the DOF mask)."""

    flat: np.ndarray
    sizes: np.ndarray
    nu_scale: np.ndarray
    out_scale: np.ndarray


@njit(cache=True, inline="always")
def _mlp(feats, flat, sizes, a, b):
    src = feats
    off = 0
    last = sizes.shape[0] - 2
    for layer in range(last + 1):
        n_in, n_out = sizes[layer], sizes[layer + 1]
        dst = a if layer % 2 == 0 else b
        bias = off + n_out * n_in
        for o in range(n_out):
            acc = flat[bias + o]
            row = off + o * n_in
            for i in range(n_in):
                acc += flat[row + i] * src[i]
            dst[o] = math.tanh(acc) if layer < last else acc
        off = bias + n_out
        src = dst
    return src


@njit(cache=True)
def _field(x, u, form, net, force_level, out, scratch, feats, a, b):
    flat, sizes, nu_scale, out_scale = net
    m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag = form
    _rhs(x, u, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, out, scratch)
    # ν_r, and the entries of R(Θ) row-major (nnid.physics.form.ned_axes), as _rhs left them
    nur, rot = scratch[1], scratch[0]
    for i in range(6):
        feats[i] = nur[i] / nu_scale[i]
    for i in range(9):
        feats[6 + i] = rot[6 + i]
    for i in range(6, u.shape[0]):
        feats[9 + i] = u[i]
    y = _mlp(feats, flat, sizes, a, b)
    for i in range(6):
        if force_level:
            acc = 0.0
            for j in range(6):
                acc += m_inv[i, j] * (y[j] * out_scale[j])
            out[6 + i] += acc
        else:
            out[6 + i] += y[i] * out_scale[i]


@njit(cache=True)
def _window(x0, inputs, dt, substeps, rule, lag, form, net, force_level, states):
    n = x0.shape[0]
    h = dt / substeps
    width = 1
    for k in range(net[1].shape[0]):
        width = max(width, net[1][k])
    scratch = np.empty((4, 18))
    feats = np.empty(net[1][0])
    a, b = np.empty(width), np.empty(width)
    k1, k2, k3, k4 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    tmp = np.empty(n)
    # with a lag the inputs end with the lagged force at each sample, of which only the first
    # starts the lag state: u is what the field reads, the force felt at the stage first
    lagged = lag > 0.0
    m = inputs.shape[1] - 6 if lagged else inputs.shape[1]
    u = np.empty(m)
    felt = np.empty(6)
    if lagged and inputs.shape[0] > 0:
        for i in range(6):
            felt[i] = inputs[0, m + i]
    # the stages' times in the step: h/2, h/2, h (classic) or h/3, 2h/3, h (3/8 rule)
    c2, c3 = (0.5, 0.5) if rule == 0 else (1.0 / 3.0, 2.0 / 3.0)
    d2 = math.exp(-c2 * h / lag) if lagged else 0.0
    d3 = math.exp(-c3 * h / lag) if lagged else 0.0
    d4 = math.exp(-h / lag) if lagged else 0.0
    x = x0.copy()
    states[0] = x
    for step in range(inputs.shape[0]):
        held = inputs[step]
        for i in range(m):
            u[i] = held[i]
        for _ in range(substeps):
            if lagged:
                for i in range(6):
                    u[i] = felt[i]
            _field(x, u, form, net, force_level, k1, scratch, feats, a, b)
            if rule == 0:
                for i in range(n):
                    tmp[i] = x[i] + 0.5 * h * k1[i]
                if lagged:
                    _lagged(felt, held, d2, u)
                _field(tmp, u, form, net, force_level, k2, scratch, feats, a, b)
                for i in range(n):
                    tmp[i] = x[i] + 0.5 * h * k2[i]
                if lagged:
                    _lagged(felt, held, d3, u)
                _field(tmp, u, form, net, force_level, k3, scratch, feats, a, b)
                for i in range(n):
                    tmp[i] = x[i] + h * k3[i]
                if lagged:
                    _lagged(felt, held, d4, u)
                _field(tmp, u, form, net, force_level, k4, scratch, feats, a, b)
                for i in range(n):
                    x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            else:  # the 3/8 rule, as torchdiffeq's rk4_alt_step_func
                for i in range(n):
                    tmp[i] = x[i] + h * k1[i] / 3.0
                if lagged:
                    _lagged(felt, held, d2, u)
                _field(tmp, u, form, net, force_level, k2, scratch, feats, a, b)
                for i in range(n):
                    tmp[i] = x[i] + h * (k2[i] - k1[i] / 3.0)
                if lagged:
                    _lagged(felt, held, d3, u)
                _field(tmp, u, form, net, force_level, k3, scratch, feats, a, b)
                for i in range(n):
                    tmp[i] = x[i] + h * (k1[i] - k2[i] + k3[i])
                if lagged:
                    _lagged(felt, held, d4, u)
                _field(tmp, u, form, net, force_level, k4, scratch, feats, a, b)
                for i in range(n):
                    x[i] += (k1[i] + 3.0 * (k2[i] + k3[i]) + k4[i]) * h * 0.125
            if lagged:
                _lagged(felt, held, d4, felt)
        states[step + 1] = x


@njit(cache=True)
def _serial(x0, inputs, dt, substeps, rule, lag, form, net, force_level, states):
    for w in range(x0.shape[0]):
        _window(x0[w], inputs[w], dt, substeps, rule, lag, form, net, force_level, states[w])


@njit(cache=True, parallel=True)
def _parallel(x0, inputs, dt, substeps, rule, lag, form, net, force_level, states):
    for w in prange(x0.shape[0]):
        _window(x0[w], inputs[w], dt, substeps, rule, lag, form, net, force_level, states[w])


def free_run(
    form: FeatureForm,
    net: NetArrays,
    x0: np.ndarray,
    inputs: np.ndarray,
    dt: float,
    substeps: int = 1,
    rule: str = "3/8",
    level: str = "force",
    lag: float = 0.0,
) -> np.ndarray:
    """States ``[L + 1, B, 12]`` (η, ν) of the hybrid from ``x0`` ``[B, 12]`` under held
    inputs ``[B, L, m]`` (the applied forces τ_eff, then the network's input channels), with
    ``substeps`` RK4 steps of ``rule`` per sample. With an actuator ``lag`` T > 0 (the
    layout of :class:`nnid.models.hybrid.HybridDynamics`) the first six inputs are the force
    commanded and six more at the end the lagged force at each sample: the physics feels
    the lag stepped exactly from the first of those (module docstring). Batches of at least
    :data:`~nnid.physics.compiled.PARALLEL_MIN_STEPS` steps run in parallel threads (the
    same numbers either way)."""
    if form.lag > 0:
        raise ValueError("the hybrid's lag is the argument lag, its physics has no lag states")
    x0 = np.ascontiguousarray(x0, dtype=np.float64)
    inputs = np.ascontiguousarray(inputs, dtype=np.float64)
    n_feats = int(net.sizes[0])
    if x0.ndim != 2 or x0.shape[1] != 12 or inputs.ndim != 3 or inputs.shape[0] != x0.shape[0]:
        raise ValueError("x0 is [B, 12] and inputs [B, L, m]")
    if inputs.shape[2] - (6 if lag > 0 else 0) + 9 != n_feats:
        raise ValueError(f"the network takes {n_feats - 15} input channels after τ_eff")
    states = np.empty((x0.shape[0], inputs.shape[1] + 1, 12))
    small = x0.shape[0] * inputs.shape[1] * substeps < PARALLEL_MIN_STEPS
    kernel = _serial if small else _parallel
    with torch_threads_kept():  # a parallel launch resets torch's count
        kernel(
            x0,
            inputs,
            float(dt),
            int(substeps),
            RULES[rule],
            float(lag),
            form_args(form),
            tuple(net),
            level == "force",
            states,
        )
    return states.transpose(1, 0, 2)


__all__ = ["RULES", "NetArrays", "free_run"]
