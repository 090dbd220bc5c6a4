"""The NARX network's free run, compiled.

Why a second evaluator of the NARX: a free run feeds each output back as a regressor of the
next step, so it is a loop of one small matrix-vector product per layer and step, and in numpy
each step paid its calls' overhead whatever the network's size: 5.5 µs a step for the 10-node,
4-output net, 18 µs with the Fossen regressors of ``configs/seamor_narx_*.toml`` (the ensemble
test of that config spent about a quarter of its time there). Here the same steps cost 0.8 and
1.2 µs (``benchmarks/bench_narx.py``). The first layer is written out on the inputs and the
delay buffer, the output transform of each new output is computed once and kept beside it, and
the layers after the first are :func:`nnid.models.hybrid_kernel._mlp`. With
``rest_equilibrium`` the output at rest is computed by the same arithmetic as every step and
subtracted, so that the increment at rest is exactly zero. Every closed loop run without
gradients goes through here: predictions, and the trial errors, validation runs and
trajectories of Levenberg-Marquardt on the simulation error. Gradients (training) go through
the torch rollout, :meth:`nnid.models.narx.NarxModel._rollout`; tests hold the two equal.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from nnid.models.hybrid_kernel import _mlp

#: codes of :attr:`NarxModel.output_transform` in the kernel
TRANSFORMS = {None: 0, "products": 1, "fossen": 2, "sqrt": 3}


@njit(cache=True)
def _transform(y, code, pi, pj, y_std, y_mean, s_mean, s_std, out):
    """The standardised transform of one normalised output row ``y`` into ``out``, as
    :meth:`NarxModel._transform_t`."""
    m = y.shape[0]
    if code == 3:  # √ of the level, clamped as the torch path clamps it
        for c in range(m):
            real = y[c] * y_std[c] + y_mean[c]
            if real < 1e-12:
                real = 1e-12
            out[c] = (math.sqrt(real) - s_mean[c]) / s_std[c]
        return
    n_p = pi.shape[0]
    for p in range(n_p):
        out[p] = (y[pi[p]] * y[pj[p]] - s_mean[p]) / s_std[p]
    if code == 2:  # the Fossen regressors add y|y| of the real outputs
        for c in range(m):
            real = y[c] * y_std[c] + y_mean[c]
            out[n_p + c] = (real * abs(real) - s_mean[n_p + c]) / s_std[n_p + c]


@njit(cache=True)
def _first(k, buf, tbuf, u, w1u, b1, dense, dense_s, out):
    """The first layer's activation at the delay states of buffer rows k … k + dy − 1 (row
    k + r holds y(k − (dy − r))) and the input regressor ``u``."""
    m, n_s = buf.shape[1], tbuf.shape[1]
    dy = dense.shape[1] // m
    for h in range(b1.shape[0]):
        acc = b1[h]
        for f in range(u.shape[0]):
            acc += w1u[h, f] * u[f]
        for r in range(dy):
            for c in range(m):
                acc += dense[h, r * m + c] * buf[k + r, c]
            for s in range(n_s):
                acc += dense_s[h, r * n_s + s] * tbuf[k + r, s]
        out[h] = math.tanh(acc)


@njit(cache=True)
def _run(buf, tbuf, uf, w1u, b1, dense, dense_s, code, pi, pj, y_std, y_mean, s_mean, s_std,
         flat, sizes, delta, lo, hi, o_rest, h1, a, b):  # fmt: skip
    n = uf.shape[0]
    dy = buf.shape[0] - n
    m = buf.shape[1]
    if code:
        for r in range(dy):
            _transform(buf[r], code, pi, pj, y_std, y_mean, s_mean, s_std, tbuf[r])
    for k in range(n):
        _first(k, buf, tbuf, uf[k], w1u, b1, dense, dense_s, h1)
        o = _mlp(h1, flat, sizes, a, b)
        for c in range(m):
            inc = o[c] - o_rest[c]
            v = buf[k + dy - 1, c] + inc if delta else inc
            if v < lo[c]:  # NaN passes through, as np.clip lets it
                v = lo[c]
            elif v > hi[c]:
                v = hi[c]
            buf[k + dy, c] = v
        if code:
            _transform(buf[k + dy], code, pi, pj, y_std, y_mean, s_mean, s_std, tbuf[k + dy])


@njit(cache=True)
def _runs(hist, uf, out, w1u, b1, dense, dense_s, code, pi, pj, y_std, y_mean, s_mean, s_std,
          flat, sizes, delta, lo, hi, rest, y_rest, u_rest):  # fmt: skip
    dy, n, m = hist.shape[1], uf.shape[1], hist.shape[2]
    n_s = dense_s.shape[1] // dy
    width = 1
    for k in range(sizes.shape[0]):
        width = max(width, sizes[k])
    h1 = np.empty(b1.shape[0])
    a, b = np.empty(width), np.empty(width)
    o_rest = np.zeros(m)
    if rest:  # the output at rest, by the same arithmetic as every step: zero increment there
        rbuf = np.empty((dy, m))
        rtbuf = np.zeros((dy, n_s))
        for r in range(dy):
            rbuf[r] = y_rest
            if code:
                _transform(rbuf[r], code, pi, pj, y_std, y_mean, s_mean, s_std, rtbuf[r])
        _first(0, rbuf, rtbuf, u_rest, w1u, b1, dense, dense_s, h1)
        o_rest[:] = _mlp(h1, flat, sizes, a, b)[:m]
    buf = np.empty((dy + n, m))
    tbuf = np.zeros((dy + n, n_s))
    for w in range(hist.shape[0]):
        buf[:dy] = hist[w]
        _run(buf, tbuf, uf[w], w1u, b1, dense, dense_s, code, pi, pj, y_std, y_mean, s_mean,
             s_std, flat, sizes, delta, lo, hi, o_rest, h1, a, b)  # fmt: skip
        out[w] = buf[dy:]


def free_run(
    hist: np.ndarray,
    uf: np.ndarray,
    first: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None],
    transform: str | None,
    scales: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    layers: list[tuple[np.ndarray, np.ndarray]],
    delta: bool,
    bounds: tuple[np.ndarray, np.ndarray] | None,
    rest: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Normalised outputs ``[B, T, m]`` of B closed loops, each from its delay states
    ``hist[b]`` ``[dy, m]`` (oldest first) under its input regressors ``uf[b]`` ``[T, F_u]``.
    ``first``: the first layer as (W_u ``[H, F_u]``, b ``[H]``, W_y ``[H, dy·m]``, W_s
    ``[H, dy·n_s]`` or None): its weights on the inputs, its bias, and its weights on the
    delay buffer and on the buffer's transform, slot dy − d for delay d (zero where a delay is
    not a regressor); ``scales``: (y_std, y_mean, s_mean, s_std); ``layers``: [(W, b)] of the
    layers after the first, tanh then a linear output (its increment scale folded in);
    ``bounds``: normalised (lo, hi) or None; ``rest``: the normalised outputs and input
    regressor at rest, whose output is subtracted from every step's (``rest_equilibrium``:
    exactly zero at rest)."""
    w1u, b1, dense, dense_s = first
    n_out = layers[-1][0].shape[0]
    out = np.empty((hist.shape[0], uf.shape[1], n_out))
    pi, pj = np.triu_indices(n_out)
    lo, hi = bounds or (np.full(n_out, -np.inf), np.full(n_out, np.inf))
    y_rest, u_rest = rest or (np.zeros(n_out), np.zeros(uf.shape[2]))

    def f64(x):
        return np.ascontiguousarray(x, dtype=np.float64)

    _runs(
        f64(hist),
        f64(uf),
        out,
        f64(w1u),
        f64(b1),
        f64(dense),
        f64(dense_s if dense_s is not None else np.zeros((dense.shape[0], 0))),
        TRANSFORMS[transform],
        pi.astype(np.int64),
        pj.astype(np.int64),
        *(f64(s) for s in scales),
        f64(np.concatenate([np.concatenate([w.reshape(-1), b]) for w, b in layers])),
        np.array([layers[0][0].shape[1], *(w.shape[0] for w, _ in layers)], dtype=np.int64),
        bool(delta),
        f64(lo),
        f64(hi),
        rest is not None,
        f64(y_rest),
        f64(u_rest),
    )
    return out


__all__ = ["TRANSFORMS", "free_run"]
