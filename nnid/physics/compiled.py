"""Compiled RK4 for the Fossen model: the lean path for long and for many trajectories.

It evaluates :class:`nnid.physics.fossen.FeatureForm`, the model's right-hand side extracted
from the torch terms, so the physics is still written once; only the kinematics J(η)ν and the
atom values of the basis library are spelled out here, and tests hold them equal to the torch
versions. Numba compiles it on first use and caches the machine code on disk.

:func:`fly_pd` flies the same RK4 under a PD autopilot on generalized forces inside the
compiled loop: stepping from Python costs a call per sample (433,000 in the VT 690
comparison), several times the integration itself.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from nnid.physics.damping_library import SIGN_FLOOR
from nnid.physics.fossen import FeatureForm
from nnid.threads import torch_threads_kept


@njit(cache=True, inline="always")  # inlined: a call costs as much as the evaluation
def _rhs(x, tau, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, out, scratch):
    # scratch [4, 18]: ν then R(Θ) row-major [0, 0:15], ν_r [1, 0:6], the atoms [2], the
    # forces [3]; a caller may read ν_r and R(Θ) after the call (the hybrid's network features)
    phi, th, psi = x[3], x[4], x[5]
    cf, sf = math.cos(phi), math.sin(phi)
    ct, st = math.cos(th), math.sin(th)
    cp, sp = math.cos(psi), math.sin(psi)
    r00, r01, r02 = cp * ct, -sp * cf + cp * st * sf, sp * sf + cp * cf * st
    r10, r11, r12 = sp * ct, cp * cf + sf * st * sp, -cp * sf + st * sp * cf
    r20, r21, r22 = -st, ct * sf, ct * cf
    u, v, w, p, q, r = x[6], x[7], x[8], x[9], x[10], x[11]
    out[0] = r00 * u + r01 * v + r02 * w
    out[1] = r10 * u + r11 * v + r12 * w
    out[2] = r20 * u + r21 * v + r22 * w
    out[3] = p + (sf * q + cf * r) * st / ct
    out[4] = cf * q - sf * r
    out[5] = (sf * q + cf * r) / ct
    # ν_c = J₁ᵀ v_c and ν̇_c = ν_c × ω
    cu = r00 * cur[0] + r10 * cur[1] + r20 * cur[2]
    cv = r01 * cur[0] + r11 * cur[1] + r21 * cur[2]
    cw = r02 * cur[0] + r12 * cur[1] + r22 * cur[2]
    nu = scratch[0]
    nur = scratch[1]
    for i in range(6):
        nu[i] = x[6 + i]
        nur[i] = x[6 + i]
    nu[6], nu[7], nu[8] = r00, r01, r02
    nu[9], nu[10], nu[11] = r10, r11, r12
    nu[12], nu[13], nu[14] = r20, r21, r22
    nur[0] -= cu
    nur[1] -= cv
    nur[2] -= cw
    ncd0, ncd1, ncd2 = cv * r - cw * q, cw * p - cu * r, cu * q - cv * p
    # atoms of the basis library at ν_r (nnid.physics.damping_library.ATOMS order)
    at = scratch[2]
    for i in range(6):
        at[i] = nur[i]
        at[6 + i] = abs(nur[i])
    big_v = math.sqrt(nur[1] * nur[1] + nur[2] * nur[2] + 1e-30)
    big_u = math.sqrt(nur[0] * nur[0] + nur[1] * nur[1] + nur[2] * nur[2] + 1e-30)
    at[12] = big_u
    at[13] = big_v
    # damping_library.rounded_sign; numba freezes SIGN_FLOOR into the cached machine code
    at[14] = big_v * np.sign(nur[1]) if abs(nur[1]) > SIGN_FLOOR else 0.0
    at[15] = big_v * np.sign(nur[2]) if abs(nur[2]) > SIGN_FLOOR else 0.0
    at[16] = u_c / big_u - 1.0
    at[17] = 1.0
    s0, s1, s2 = st, ct * sf, ct * cf
    f = scratch[3]
    for i in range(6):
        f[i] = (tau[i] if lag <= 0.0 else x[12 + i]) + bias[i]
        f[i] -= g_mat[i, 0] * s0 + g_mat[i, 1] * s1 + g_mat[i, 2] * s2
        f[i] += ma[i, 0] * ncd0 + ma[i, 1] * ncd1 + ma[i, 2] * ncd2
    k = 0
    for a in range(6):
        for b in range(a, 6):
            mrb = nu[a] * nu[b]
            mra = nur[a] * nur[b]
            for i in range(6):
                f[i] -= q_rb[i, k] * mrb + q_a[i, k] * mra
            k += 1
    for j in range(codes.shape[0]):
        term = at[codes[j, 0]] * at[codes[j, 1]] * at[codes[j, 2]]
        for i in range(6):
            f[i] += theta[i, j] * term
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += m_inv[i, j] * f[j]
        out[6 + i] = acc
    if lag > 0.0:
        for i in range(6):
            out[12 + i] = (tau[i] - x[12 + i]) / lag


@njit(cache=True, inline="always")
def _lagged(a, tau, decay, out):
    # T ȧ = τ − a with τ held, stepped exactly: a(t + s) = τ + (a(t) − τ) e^(−s/T), decay the
    # exponential; out[:6] may be a itself (each entry is read before it is written)
    for i in range(6):
        out[i] = tau[i] + (a[i] - tau[i]) * decay


@njit(cache=True)
def _integrate(
    x0, tau, dt, substeps, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, states
):
    n = x0.shape[0]
    h = dt / substeps
    scratch = np.empty((4, 18))
    k1, k2, k3, k4 = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    tmp = np.empty(n)
    # the actuator lag T ȧ = τ − a (states 12-17) is linear with τ held over the step: stepped
    # exactly, a(t + c h) = τ + (a − τ) e^(−c h / T), and the RK4 stages of ν read it there.
    # As an RK4 state it decayed by 0.99 a step where e^(−h/T) is 0.06 (h/T = 2.8), and grew
    # past h/T = 2.79 (a 0.03-s lag at 10 Hz diverged)
    lagged = lag > 0.0 and n > 12
    half = math.exp(-0.5 * h / lag) if lagged else 0.0
    full = half * half
    x = x0.copy()
    states[0] = x
    for step in range(tau.shape[0]):
        u = tau[step]
        for _ in range(substeps):
            _rhs(x, u, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, k1, scratch)
            for i in range(n):
                tmp[i] = x[i] + 0.5 * h * k1[i]
            if lagged:
                _lagged(x[12:], u, half, tmp[12:])
            _rhs(
                tmp, u, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, k2, scratch
            )
            for i in range(n):
                tmp[i] = x[i] + 0.5 * h * k2[i]
            if lagged:
                _lagged(x[12:], u, half, tmp[12:])
            _rhs(
                tmp, u, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, k3, scratch
            )
            for i in range(n):
                tmp[i] = x[i] + h * k3[i]
            if lagged:
                _lagged(x[12:], u, full, tmp[12:])
            _rhs(
                tmp, u, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, k4, scratch
            )
            if lagged:  # the stages left x's lag states as they were: the exact step
                for i in range(6):
                    k1[12 + i] = 0.0
                    k2[12 + i] = 0.0
                    k3[12 + i] = 0.0
                    k4[12 + i] = 0.0
                _lagged(x[12:], u, full, x[12:])
            for i in range(n):
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
        states[step + 1] = x


#: below this many RK4 steps in a batch, threads cost more than they save (a parallel launch is
#: tens of microseconds; a caller that steps one sample at a time makes one call per sample)
PARALLEL_MIN_STEPS = 20_000


@njit(cache=True)
def _integrate_serial(
    x0, tau, dt, substeps, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, states
):
    for b in range(x0.shape[0]):
        _integrate(
            x0[b],
            tau[b],
            dt,
            substeps,
            m_inv,
            q_rb,
            q_a,
            g_mat,
            theta,
            codes,
            ma,
            bias,
            cur,
            u_c,
            lag,
            states[b],
        )


@njit(cache=True, parallel=True)
def _integrate_batch(
    x0, tau, dt, substeps, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, states
):
    for b in prange(x0.shape[0]):
        _integrate(
            x0[b],
            tau[b],
            dt,
            substeps,
            m_inv,
            q_rb,
            q_a,
            g_mat,
            theta,
            codes,
            ma,
            bias,
            cur,
            u_c,
            lag,
            states[b],
        )


def _kernel_array(a, dtype=np.float64) -> np.ndarray:
    """``a`` as the kernels take it: C-contiguous, of ``dtype``, writable. Numba types a
    read-only array (pandas' view of a column) apart from a writable one, so each kernel it
    reaches would compile a second variant, seconds in every process on a cold cache; the copy
    has the same bits."""
    a = np.ascontiguousarray(a, dtype=dtype)
    return a if a.flags.writeable else a.copy()


def form_args(form: FeatureForm) -> tuple:
    """The form as the compiled kernels take it: a tuple of arrays and scalars."""
    return (
        form.m_inv,
        form.q_rb,
        form.q_a,
        form.g_mat,
        form.theta,
        form.codes,
        form.added_mass,
        form.bias,
        form.current,
        form.u_c,
        form.lag,
    )


def rhs(form: FeatureForm, x: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """ẋ at one state (for tests and adaptive integrators)."""
    x = _kernel_array(x)
    out = np.empty_like(x)
    _rhs(x, _kernel_array(tau), *form_args(form), out, np.empty((4, 18)))
    return out


def integrate_rk4(
    form: FeatureForm, x0: np.ndarray, tau: np.ndarray, dt: float, substeps: int = 1
) -> np.ndarray:
    """Fixed-step RK4 with ``substeps`` per sample, τ held over each sample (zero-order hold).

    ``x0`` is ``[n]`` or ``[B, n]``, ``tau`` ``[N, 6]`` or ``[B, N, 6]``; returns the states at
    the N+1 sample times, ``[N+1, n]`` or ``[B, N+1, n]``. Batches of at least
    :data:`PARALLEL_MIN_STEPS` steps run in parallel threads (the same numbers either way).
    """
    x0 = _kernel_array(x0)
    tau = _kernel_array(tau)
    if x0.ndim == 1:
        states = np.empty((tau.shape[0] + 1, x0.shape[0]))
        _integrate(x0, tau, float(dt), int(substeps), *form_args(form), states)
        return states
    states = np.empty((x0.shape[0], tau.shape[1] + 1, x0.shape[1]))
    small = x0.shape[0] * tau.shape[1] * substeps < PARALLEL_MIN_STEPS
    if small:
        _integrate_serial(x0, tau, float(dt), int(substeps), *form_args(form), states)
        return states
    with torch_threads_kept():
        _integrate_batch(x0, tau, float(dt), int(substeps), *form_args(form), states)
    return states


@njit(cache=True)
def _fly(x0, tau_open, start, dt, substeps, pilot, deadband, form, states, commanded):
    # the numpy operations of Autopilot.force, apply_deadband and apply_installation, in their
    # order, so that the compiled flight gives the bits of the per-sample one
    kp, kd, ref, eta_pos, eta_neg = pilot[0], pilot[1], pilot[2], pilot[3], pilot[4]
    held = np.empty((1, 6))
    push = np.empty(6)
    states[0] = x0
    for j in range(states.shape[0] - 1):
        x = states[j]
        for i in range(6):
            e = x[i] - ref[i]
            if i >= 3:
                e = (e + np.pi) % (2 * np.pi) - np.pi
            push[i] = -kp[i] * e
        if kp[0] != 0.0 or kp[1] != 0.0:  # north/east push turned into surge/sway by ψ
            cos, sin = np.cos(x[5]), np.sin(x[5])
            north, east = push[0], push[1]
            push[0] = cos * north + sin * east
            push[1] = -sin * north + cos * east
        for i in range(6):
            c = tau_open[start + j, i] + (push[i] - kd[i] * x[6 + i])
            if commanded.shape[0] > 0:
                commanded[j, i] = c
            if abs(c) <= deadband:
                c = 0.0
            held[0, i] = eta_pos[i] * c if c >= 0 else eta_neg[i] * c
        _integrate(x, held, dt, substeps, *form, states[j : j + 2])
        if not np.isfinite(states[j + 1]).all():
            states[j + 2 :] = np.nan
            return


@njit(cache=True, parallel=True)
def _fly_batch(x0, tau_open, starts, dt, substeps, pilot, deadband, form, states, commanded):
    for b in prange(x0.shape[0]):
        _fly(x0[b], tau_open, starts[b], dt, substeps, pilot, deadband, form, states[b],
             commanded[b])  # fmt: skip


def fly_pd(
    form: FeatureForm,
    x0: np.ndarray,
    tau_open: np.ndarray,
    starts: np.ndarray,
    steps: int,
    dt: float,
    pilot: np.ndarray,
    deadband: float | None = None,
    substeps: int = 1,
    record: bool = False,
) -> tuple[np.ndarray, np.ndarray | None]:
    """Fly ``steps`` samples from each state ``x0`` ``[B, n]`` under a PD autopilot on
    generalized forces, held over each sample: window b commands
    ``tau_open[starts[b] + j] − k_p (η − η_ref) − k_d ν`` (heading errors wrapped to ±π), then
    the ``deadband`` (None: none) and the installation (Caccia eq. 3) give the applied force.
    ``pilot`` is ``[5, 6]``: k_p, k_d, η_ref, η⁺, η⁻.

    Returns the states ``[B, steps + 1, n]``, and with ``record`` the commanded forces
    ``[B, steps, 6]`` (before deadband and installation). A window whose state turns
    non-finite stops there: that state is kept and every later one is NaN (commands not flown
    are left zero). Windows run in parallel threads (the same numbers either way); one kernel
    for any number of them, since a flight is one call, not one per sample, and each compiled
    variant costs seconds of compilation on a cold cache."""
    x0 = _kernel_array(np.atleast_2d(x0))
    tau_open = _kernel_array(tau_open)
    starts = _kernel_array(starts, np.int64)
    pilot = _kernel_array(pilot)
    if pilot.shape != (5, 6):
        raise ValueError("pilot is [5, 6]: kp, kd, reference, eta_pos, eta_neg")
    if starts.shape != (x0.shape[0],) or (
        starts.size and (starts.min() < 0 or starts.max() + steps > tau_open.shape[0])
    ):
        raise ValueError("each window needs tau_open rows starts[b] … starts[b] + steps − 1")
    states = np.empty((x0.shape[0], steps + 1, x0.shape[1]))
    commanded = np.zeros((x0.shape[0], steps if record else 0, 6))
    width = -1.0 if deadband is None else float(deadband)
    with torch_threads_kept():
        _fly_batch(
            x0,
            tau_open,
            starts,
            float(dt),
            int(substeps),
            pilot,
            width,
            form_args(form),
            states,
            commanded,
        )
    return states, (commanded if record else None)
