"""The monitor's hot path, compiled: residual, whitening, EWMA and CUSUM of one sample.

Written here with Numba (and not through :class:`nnid.physics.thrusters.Actuation` and the torch
physics) because the streaming update must cost microseconds and allocate nothing per sample:
every buffer is created once by :class:`nnid.fault.monitor.Stream`. The physics is still the one
of the physics package: the right-hand side is :func:`nnid.physics.compiled._rhs` on the model's
:class:`~nnid.physics.fossen.FeatureForm`, and the thrust curves are the three kinds of
:class:`~nnid.physics.thrusters.ThrustCurve`, held equal to it by the tests.

The residual of the interval [t_{k-1}, t_k] is the Fossen equation error at its midpoint,

    r_k = M ((ν_k − ν_{k−1}) / Δt − f(x̄, τ_{k−1})),   x̄ = (x_{k−1} + x_k) / 2,

a generalized force (Weiss eq. 11 with the acceleration replaced by the difference quotient,
second-order accurate for inputs held over the sample); τ_{k−1} is the force of the commands
held over the interval through the thrust curves, the allocation and the installation
coefficients (Caccia eq. 3).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from nnid.physics.compiled import _rhs

CURVE_POLY, CURVE_QUADRATIC, CURVE_TABLE, CURVE_FORCE = 0, 1, 2, 3

# layout of the scalar settings vector ``cfg``; MAX_DT: the longest interval given a residual
TAU, ALLOWANCE, H_EWMA, H_CUSUM, DIM, REARM, MAX_DT = range(7)
CFG_SIZE = 7
# layout of the state vector ``st``: flags and CUSUM, then the EWMA [EWMA:EWMA + 6]
HAS_PREV, CUSUM, ACTIVE, QUIET, EWMA = range(5)
STATE_SIZE = EWMA + 6
# :func:`watch`'s state after it: the level of the changes' signature [LEVEL:LEVEL + 6]
# (:func:`levels`), carried with the statistics so that rows given in pieces read alike
LEVEL = STATE_SIZE
WATCH_STATE_SIZE = LEVEL + 6
#: the per-DOF scale of :func:`_statistics` where the residual is read against healthy noise
UNSCALED = np.ones(6)


@njit(cache=True, inline="always")
def _interp(x, xs, ys, row, n):
    """np.interp on row ``row`` of the tables (ends held), without slicing."""
    if x <= xs[row, 0]:
        return ys[row, 0]
    if x >= xs[row, n - 1]:
        return ys[row, n - 1]
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if xs[row, mid] <= x:
            lo = mid
        else:
            hi = mid
    w = (x - xs[row, lo]) / (xs[row, hi] - xs[row, lo])
    return ys[row, lo] + w * (ys[row, hi] - ys[row, lo])


@njit(cache=True, inline="always")
def _force(src, off, n, act, work):
    """work[2] ← the generalized force of the commands ``src[off:off + n]`` held over the
    interval (deadband, clip, curves, allocation, η); work[3] ← each thrust. Indices, not
    slices: a slice is an object with a reference count, paid on every sample. Table curves
    get a loop of their own: in the same loop as the closed-form curves they make the whole
    update several times slower."""
    kinds, coeffs, tab_cmd, tab_thrust, n_tab, lo, hi, alloc, eta_pos, eta_neg, deadband = act
    tables = False
    for i in range(n):
        c = src[off + i]
        if abs(c) <= deadband:
            c = 0.0
        c = min(max(c, lo[i]), hi[i])
        kind = kinds[i]
        if kind == CURVE_QUADRATIC:  # forward, reverse coefficient (Caccia eq. 6)
            work[3, i] = (coeffs[i, 0] if c >= 0.0 else coeffs[i, 1]) * c * abs(c)
        elif kind == CURVE_POLY:
            mag, out, power = abs(c), 0.0, 1.0
            for j in range(coeffs.shape[1]):
                out += coeffs[i, j] * power
                power *= mag
            work[3, i] = math.copysign(out, c) if c != 0.0 else 0.0
        else:  # a generalized force as it is, or a table below
            work[3, i] = c
            tables = tables or kind == CURVE_TABLE
    if tables:
        for i in range(n):
            if kinds[i] == CURVE_TABLE:
                work[3, i] = _interp(work[3, i], tab_cmd, tab_thrust, i, n_tab[i])
    for d in range(6):
        acc = 0.0
        for i in range(n):
            acc += alloc[d, i] * work[3, i]
        work[2, d] = eta_pos[d] * acc if acc >= 0.0 else eta_neg[d] * acc


@njit(cache=True, inline="always")
def _residual(prev, x, n, dt, form, mass, mask, act, out, work, scratch):
    """out[0:6] ← the midpoint equation error of the interval from ``prev`` (state [12], then
    the n commands held) to ``x``; False if a value is not finite."""
    for i in range(12):
        if not math.isfinite(x[i]) or not math.isfinite(prev[i]):
            return False
    for i in range(n):
        if not math.isfinite(prev[12 + i]):
            return False
    for i in range(12):
        work[0, i] = 0.5 * (prev[i] + x[i])
    for i in range(3, 6):  # angles: the midpoint on the circle
        step = x[i] - prev[i]
        step -= 2.0 * math.pi * math.floor((step + math.pi) / (2.0 * math.pi))
        work[0, i] = prev[i] + 0.5 * step
    _force(prev, 12, n, act, work)
    m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag = form
    mid, xdot, tau = work[0], work[1], work[2]
    _rhs(mid, tau, m_inv, q_rb, q_a, g_mat, theta, codes, ma, bias, cur, u_c, lag, xdot, scratch)
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += mass[i, j] * ((x[6 + j] - prev[6 + j]) / dt - work[1, 6 + j])
        out[i] = acc * mask[i]
    return True


@njit(cache=True, inline="always")
def _statistics(dt, mu, whiten, s_inv, cfg, out, st, scale):
    """out[6:12] ← z = W (r − μ) of r = out[0:6]; the EWMA (kept in ``st``, copied to
    out[12:18]) and the CUSUM updated; returns (T, g). ``scale`` [6]: how many times the
    healthy noise's excess each whitened DOF may hold (:data:`UNSCALED`, but in :func:`watch`):
    the EWMA reads z / √scale, the CUSUM z² / scale + 1 − 1 / scale (the noise's mean kept, its
    excess read in units of scale; at 1 both are z and z² exactly)."""
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += whiten[i, j] * (out[j] - mu[j])
        out[6 + i] = acc
    lam = 1.0 - math.exp(-dt / cfg[TAU])
    power = 0.0
    for i in range(6):
        z, a = out[6 + i], scale[i]
        st[EWMA + i] = (1.0 - lam) * st[EWMA + i] + lam * (z / math.sqrt(a))
        out[12 + i] = st[EWMA + i]
        power += z * z / a + (1.0 - 1.0 / a)
    t_stat = 0.0
    for i in range(6):
        for j in range(6):
            t_stat += out[12 + i] * s_inv[i, j] * out[12 + j]
    st[CUSUM] = max(0.0, st[CUSUM] + power - cfg[DIM] - cfg[ALLOWANCE])
    return t_stat, st[CUSUM]


@njit(cache=True, inline="always")
def _alarm(t_stat, g, dt, cfg, st):
    """1 when a new alarm starts at this sample; an alarm re-arms after ``REARM`` seconds with
    both statistics below their thresholds."""
    above = t_stat > cfg[H_EWMA] or g > cfg[H_CUSUM]
    if st[ACTIVE] > 0.0:
        if above:
            st[QUIET] = 0.0
        else:
            st[QUIET] += dt
            if st[QUIET] >= cfg[REARM]:
                st[ACTIVE] = 0.0
        return 0
    if above:
        st[ACTIVE] = 1.0
        st[QUIET] = 0.0
        return 1
    return 0


@njit(cache=True, inline="always")
def _update(t, x, cmd, prev, st, cfg, form, mass, mask, act, mu, whiten, s_inv, out, work, scratch):
    """One sample at time ``t``: state ``x`` [12] and commands ``cmd`` held from now.
    ``prev`` [13 + n_channels] keeps the previous sample. ``out`` ← r [0:6], z [6:12],
    EWMA [12:18], T [18], g [19]; returns 1 for a new alarm, 0 otherwise, −1 while there is no
    residual (first sample, a time that does not increase, an interval longer than
    ``cfg[MAX_DT]``, or a value that is not finite). Across a long interval (samples missing)
    the commands were not held and the difference quotient is not the acceleration, so it is
    skipped as a value that is not finite is: the statistics carry their state across."""
    n_ch = cmd.shape[0]
    code = -1
    dt = t - prev[12 + n_ch]
    if st[HAS_PREV] > 0.0 and 0.0 < dt <= cfg[MAX_DT]:
        if _residual(prev, x, n_ch, dt, form, mass, mask, act, out, work, scratch):
            t_stat, g = _statistics(dt, mu, whiten, s_inv, cfg, out, st, UNSCALED)
            out[18] = t_stat
            out[19] = g
            code = _alarm(t_stat, g, dt, cfg, st)
    finite = math.isfinite(t)
    for i in range(12):
        finite = finite and math.isfinite(x[i])
    for i in range(n_ch):
        finite = finite and math.isfinite(cmd[i])
    for i in range(12):
        prev[i] = x[i]
    for i in range(n_ch):
        prev[12 + i] = cmd[i]
    prev[12 + n_ch] = t
    st[HAS_PREV] = 1.0 if finite else 0.0
    return code


@njit(cache=True)
def update(t, x, cmd, prev, st, cfg, form, mass, mask, act, mu, whiten, s_inv, out, work, scratch):
    """:func:`_update` as a call of its own: the streaming entry point. ``out`` is NaN where
    there is no residual, as :func:`run` leaves it (a skipped interval kept the previous
    sample's values, which ``--follow`` then watched as a residual)."""
    for i in range(20):
        out[i] = np.nan
    return _update(t, x, cmd, prev, st, cfg, form, mass, mask, act, mu, whiten, s_inv, out, work,
                   scratch)  # fmt: skip


@njit(cache=True)
def run(ts, xs, cmds, prev, st, cfg, form, mass, mask, act, mu, whiten, s_inv, out, work, scratch):
    """:func:`_update` over every row of one experiment; ``out`` ``[N, 21]`` gets the 20 values
    of each sample and its code in column 20 (NaN where there was no residual)."""
    for k in range(xs.shape[0]):
        row = out[k]
        for i in range(20):
            row[i] = np.nan
        row[20] = _update(ts[k], xs[k], cmds[k], prev, st, cfg, form, mass, mask, act, mu,
                          whiten, s_inv, row, work, scratch)  # fmt: skip
    return out


@njit(cache=True)
def levels(t_prev, ts, sig, cfg, whiten, st, out):
    """``out`` [N, 6] ← the level of the signature ``sig`` [N, 6] (what isolated changes put in
    the model's residual) in each whitened DOF at times ``ts`` (``t_prev`` the time before the
    first): its power there, or where more its EWMA over the monitor's time constant (kept in
    ``st[LEVEL:]``, zeros: a fresh one). The EWMA holds it over the motion's lag: a model's
    error that the change caused outlasts the change's own force by some tenths of a second."""
    for k in range(sig.shape[0]):
        dt = ts[k] - (t_prev if k == 0 else ts[k - 1])
        lam = 1.0 - math.exp(-dt / cfg[TAU]) if dt > 0.0 else 0.0
        for i in range(6):
            acc = 0.0
            for j in range(6):
                acc += whiten[i, j] * sig[k, j]
            p = acc * acc if math.isfinite(acc) else 0.0
            st[LEVEL + i] = (1.0 - lam) * st[LEVEL + i] + lam * p
            out[k, i] = max(p, st[LEVEL + i])
    return out


@njit(cache=True)
def watch(t_prev, ts, rs, scale, cfg, mu, whiten, s_inv, st, out):
    """The statistics and alarms of :func:`_update` over residuals already made, ``rs`` [N, 6]
    (NaN: none) at times ``ts`` (``t_prev`` the time before the first), from the state ``st``
    (zeros: a fresh one; carried on, so rows given in pieces are watched as in one call): the
    monitor on a residual re-referenced to an isolated change, each DOF read against what the
    change may leave there (``scale`` [N, 6], :func:`_statistics`). ``out`` as :func:`run`'s."""
    for k in range(rs.shape[0]):
        row = out[k]
        for i in range(20):
            row[i] = np.nan
        row[20] = -1.0
        dt = ts[k] - (t_prev if k == 0 else ts[k - 1])
        finite = dt > 0.0
        for i in range(6):
            finite = finite and math.isfinite(rs[k, i])
        if not finite:
            continue
        for i in range(6):
            row[i] = rs[k, i]
        t_stat, g = _statistics(dt, mu, whiten, s_inv, cfg, row, st, scale[k])
        row[18] = t_stat
        row[19] = g
        row[20] = _alarm(t_stat, g, dt, cfg, st)
    return out


@njit(cache=True, parallel=True)
def run_blocks(starts, ts, xs, cmds, cfg, form, mass, mask, act, mu, whiten, s_inv, out):
    """:func:`run` over the row blocks [starts[j], starts[j + 1]) (the experiments), each from a
    fresh state, the blocks in parallel threads (each block's numbers are :func:`run`'s)."""
    n_ch = cmds.shape[1]
    for j in prange(starts.shape[0] - 1):
        a, b = starts[j], starts[j + 1]
        prev = np.zeros(13 + n_ch)
        st = np.zeros(STATE_SIZE)
        work = np.zeros((4, max(18, n_ch)))
        scratch = np.zeros((4, 18))
        run(ts[a:b], xs[a:b], cmds[a:b], prev, st, cfg, form, mass, mask, act, mu, whiten,
            s_inv, out[a:b], work, scratch)  # fmt: skip
    return out
