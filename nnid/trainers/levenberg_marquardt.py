"""Levenberg-Marquardt for any PyTorch module with a residual vector (Weiss eqs 54-61, trainlm).

The trainer minimises the sum of squared residuals E(θ) = ½‖r(θ)‖² of a module's parameters θ
(flattened into one float64 vector). Each epoch builds the Gauss-Newton normal equations
(Weiss eqs 54-61) accumulated over the training batches,

    JᵀJ = Σ_b J_bᵀ J_b,    Jᵀr = Σ_b J_bᵀ r_b,

and solves the damped system of MATLAB's ``trainlm``

    (JᵀJ + μ I) δ = −Jᵀr.

A trial step θ + δ is accepted when the training SSE decreases (then μ ← μ·μ_dec), otherwise
μ ← μ·μ_inc and the system is solved again with the same Jacobian, until μ > μ_max. Defaults are
those documented for ``trainlm``: μ = 0.001, μ_dec = 0.1, μ_inc = 10, μ_max = 1e10,
epochs = 1000, max_fail = 6 validation checks, min_grad = 1e-7, goal = 0. As in ``trainlm`` μ is
floored at 1e-20 after a decrease, and when validation batches are given the returned
parameters are those of the best validation error.

Jacobians come from :mod:`torch.func`; there are two modes:

- ``jacobian="forward"`` (default, always valid): forward-mode products J v for a block of unit
  tangents at a time (``vmap`` over ``jvp``). It works for any residual, including ones that
  couple all rows (a simulated trajectory integrated with RK4, a parallel NARX simulation).
  When the whole n × P Jacobian of a batch fits the memory budget it is formed and JᵀJ is one
  matrix product. Otherwise the columns are taken in blocks J_a of width c (n·c ≤ budget) and
  the columns of JᵀJ are accumulated as Jᵀ(J_a) by reverse-mode products (``vmap`` over the
  ``vjp`` of the same forward pass), so memory holds one n × c block and never n × P, and every
  column block is computed once.
- ``jacobian="samples"``: for residuals that are separable by sample (a one-step-ahead/series-
  parallel NARX, a static regression), the per-sample Jacobians are taken with ``vmap`` over
  samples of ``jacrev``. The batch is then a tensor, or a (nested) tuple/list/dict of tensors,
  whose leading dimension indexes samples, and ``residual(params, batch[i:j])`` must return the
  rows of samples i..j-1 (in sample-major order). Samples are processed in row chunks of at most
  ``budget / (8 P)`` rows (and at most 8192 rows, beyond which chunks only cost memory), whose
  JᵀJ and Jᵀr are added into the P × P system. This is much cheaper than forward mode for
  networks with many samples.

The same trainer fits nonlinear physics parameters: any ``nn.Module`` whose parameters are the
unknowns and a residual that computes model − measurement with ``functional_call``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import torch
from torch.func import jacrev, jvp, vjp, vmap

__all__ = ["LMHistory", "LevenbergMarquardt", "NormalEquations"]

Residual = Callable[[dict[str, torch.Tensor], Any], torch.Tensor]

_MU_FLOOR = 1e-20  # trainlm: ``if mu < 1e-20, mu = 1e-20``
_CACHE_ROWS = 8192  # samples mode: row chunks above this are no faster (cache), only larger


@dataclass
class LMHistory:
    """Per-epoch record of a :meth:`LevenbergMarquardt.fit` run.

    Entry 0 of each per-epoch list is the starting point; entry k is after epoch k.
    ``gradient[k]`` is ‖∇ MSE‖ = 2‖Jᵀr‖/N at the parameters of entry k (one shorter than the
    others when the run stopped without a last Jacobian pass). ``time`` is the cumulative wall
    time in seconds. ``peak_jacobian_rows`` and
    ``peak_jacobian_elements`` are the largest Jacobian block held at once (rows × columns).
    """

    train_mse: list[float] = field(default_factory=list)
    val_mse: list[float] = field(default_factory=list)
    mu: list[float] = field(default_factory=list)
    gradient: list[float] = field(default_factory=list)
    time: list[float] = field(default_factory=list)
    stop_reason: str = ""
    best_epoch: int = 0
    peak_jacobian_rows: int = 0
    peak_jacobian_elements: int = 0

    @property
    def epochs(self) -> int:
        """Number of epochs run (accepted or not)."""
        return len(self.train_mse) - 1


@dataclass
class NormalEquations:
    """Accumulated Gauss-Newton system of one parameter point (float64)."""

    jtj: torch.Tensor  # [P, P]
    jtr: torch.Tensor  # [P]
    sse: float
    n: int


# --------------------------------------------------------------------------- batch pytrees


def _tree_map(fn: Callable[[torch.Tensor], Any], batch: Any) -> Any:
    if isinstance(batch, torch.Tensor):
        return fn(batch)
    if isinstance(batch, dict):
        return {k: _tree_map(fn, v) for k, v in batch.items()}
    if isinstance(batch, (tuple, list)):
        return type(batch)(_tree_map(fn, v) for v in batch)
    raise TypeError(f"samples mode needs tensors in the batch, got {type(batch).__name__}")


def _leading_len(batch: Any) -> int:
    sizes: set[int] = set()
    _tree_map(lambda t: sizes.add(int(t.shape[0])), batch)
    if len(sizes) != 1:
        raise ValueError(f"batch tensors disagree on the sample dimension: {sorted(sizes)}")
    return sizes.pop()


# --------------------------------------------------------------------------- trainer


class LevenbergMarquardt:
    """Levenberg-Marquardt (``trainlm``) for a module's parameters and a residual function.

    Args:
        mu: initial damping μ (trainlm ``mu`` = 0.001).
        mu_dec: factor on μ after an accepted step (trainlm ``mu_dec`` = 0.1).
        mu_inc: factor on μ after a rejected step (trainlm ``mu_inc`` = 10).
        mu_max: stop when μ exceeds this (trainlm ``mu_max`` = 1e10).
        max_epochs: maximum number of epochs (trainlm ``epochs`` = 1000).
        max_fail: stop after this many consecutive increases of the validation MSE (trainlm
            ``max_fail`` = 6); the best-validation parameters are then restored.
        min_grad: stop when ‖∇ MSE‖ = 2‖Jᵀr‖/N falls below this (trainlm ``min_grad`` = 1e-7).
        goal: stop when the training MSE is at or below this (trainlm ``goal`` = 0).
        memory_budget_mb: the largest Jacobian block (float64) held at once, in MiB.
        jacobian: ``"forward"`` (any residual) or ``"samples"`` (residual separable by sample;
            see the module docstring).
    """

    def __init__(
        self,
        mu: float = 1e-3,
        mu_dec: float = 0.1,
        mu_inc: float = 10.0,
        mu_max: float = 1e10,
        max_epochs: int = 1000,
        max_fail: int = 6,
        min_grad: float = 1e-7,
        goal: float = 0.0,
        memory_budget_mb: float = 256.0,
        jacobian: str = "forward",
    ) -> None:
        if jacobian not in ("forward", "samples"):
            raise ValueError(f"jacobian must be 'forward' or 'samples', got {jacobian!r}")
        if not (0.0 < mu_dec < 1.0 < mu_inc):
            raise ValueError("need 0 < mu_dec < 1 < mu_inc")
        if memory_budget_mb <= 0:
            raise ValueError("memory_budget_mb must be positive")
        self.mu = mu
        self.mu_dec = mu_dec
        self.mu_inc = mu_inc
        self.mu_max = mu_max
        self.max_epochs = max_epochs
        self.max_fail = max_fail
        self.min_grad = min_grad
        self.goal = goal
        self.memory_budget_mb = memory_budget_mb
        self.jacobian = jacobian
        self._peak_rows = 0
        self._peak_elements = 0
        self._rows: dict[int, int] = {}

    # ------------------------------------------------------------------ parameters

    @staticmethod
    def _layout(module: torch.nn.Module) -> list[tuple[str, torch.Size, torch.dtype, int]]:
        return [(k, p.shape, p.dtype, p.numel()) for k, p in module.named_parameters()]

    @staticmethod
    def _flatten(module: torch.nn.Module) -> torch.Tensor:
        ps = [p.detach().reshape(-1).to(torch.float64) for p in module.parameters()]
        return torch.cat(ps) if ps else torch.zeros(0, dtype=torch.float64)

    @staticmethod
    def _unflatten(
        theta: torch.Tensor, layout: list[tuple[str, torch.Size, torch.dtype, int]]
    ) -> dict[str, torch.Tensor]:
        out: dict[str, torch.Tensor] = {}
        o = 0
        for name, shape, dtype, k in layout:
            out[name] = theta[o : o + k].reshape(shape).to(dtype)
            o += k
        return out

    @staticmethod
    def _write_back(module: torch.nn.Module, theta: torch.Tensor) -> None:
        o = 0
        with torch.no_grad():
            for p in module.parameters():
                k = p.numel()
                p.copy_(theta[o : o + k].reshape(p.shape).to(p.dtype))
                o += k

    @property
    def _budget_elements(self) -> int:
        return max(1, int(self.memory_budget_mb * 2**20) // 8)

    # ------------------------------------------------------------------ evaluation

    def _sse(self, residual: Residual, theta: torch.Tensor, layout: list, batches: Sequence[Any]):
        """(SSE, number of residuals) over ``batches`` at ``theta`` (no autograd)."""
        params = self._unflatten(theta, layout)
        sse, n = 0.0, 0
        with torch.no_grad():
            for b in batches:
                r = residual(params, b).reshape(-1).to(torch.float64)
                sse += float(r @ r)
                n += r.numel()
        return sse, n

    def normal_equations(
        self, module: torch.nn.Module, residual: Residual, batches: Sequence[Any]
    ) -> NormalEquations:
        """JᵀJ, Jᵀr and SSE over ``batches`` at the module's current parameters (float64)."""
        return self._normal_equations(
            residual, self._flatten(module), self._layout(module), batches
        )

    def _normal_equations(
        self, residual: Residual, theta: torch.Tensor, layout: list, batches: Sequence[Any]
    ) -> NormalEquations:
        p = theta.numel()
        jtj = torch.zeros(p, p, dtype=torch.float64)
        jtr = torch.zeros(p, dtype=torch.float64)
        sse, n = 0.0, 0
        for b in batches:
            if self.jacobian == "forward":
                s, k = self._accumulate_forward(residual, theta, layout, b, jtj, jtr)
            else:
                s, k = self._accumulate_samples(residual, theta, layout, b, jtj, jtr)
            sse += s
            n += k
        return NormalEquations(jtj, jtr, sse, n)

    def _accumulate_forward(self, residual, theta, layout, batch, jtj, jtr) -> tuple[float, int]:
        """Forward-mode Jacobian of one batch, in column blocks within the budget."""

        def f(th: torch.Tensor) -> torch.Tensor:
            return residual(self._unflatten(th, layout), batch).reshape(-1)

        p = theta.numel()
        n = self._rows.get(id(batch))
        if n is None:
            with torch.no_grad():
                n = f(theta).numel()
        width = max(1, min(p, self._budget_elements // max(n, 1)))
        eye = torch.eye(p, dtype=theta.dtype)
        if width >= p:
            with torch.no_grad():
                r64 = f(theta).to(torch.float64)
        else:
            r, vjp_fn = vjp(f, theta)
            r64 = r.detach().to(torch.float64)

        def tangent(v: torch.Tensor) -> torch.Tensor:
            return jvp(f, (theta,), (v,))[1]

        if width >= p:
            jac = vmap(tangent)(eye).to(torch.float64)  # [P, n] = Jᵀ
            self._note(n, p)
            jtj += jac @ jac.T
            jtr += jac @ r64
        else:
            for a in range(0, p, width):
                block = vmap(tangent)(eye[a : a + width]).detach()  # [c, n] = J_aᵀ
                self._note(n, block.shape[0])
                cols = vmap(lambda u: vjp_fn(u)[0])(block)  # [c, P] = (Jᵀ J_a)ᵀ
                jtj[:, a : a + width] += cols.T.to(torch.float64)
                del block, cols
            jtr += vjp_fn(r.detach())[0].detach().to(torch.float64)
        self._rows[id(batch)] = n
        return float(r64 @ r64), n

    def _accumulate_samples(self, residual, theta, layout, batch, jtj, jtr) -> tuple[float, int]:
        """Per-sample reverse-mode Jacobians (vmap over samples), in row chunks."""

        def one(params: dict[str, torch.Tensor], sample: Any) -> tuple[Any, torch.Tensor]:
            single = _tree_map(lambda t: t.unsqueeze(0), sample)
            r = residual(params, single).reshape(-1)
            return r, r

        # Differentiate with respect to the parameter tensors themselves (not the flat vector,
        # whose slicing backward would scatter every per-sample row into a zero P-vector).
        jac_fn = vmap(jacrev(one, has_aux=True), in_dims=(None, 0))
        p = theta.numel()
        params = {k: v.detach() for k, v in self._unflatten(theta, layout).items()}
        n_samples = _leading_len(batch)
        # Rows per sample from the first sample (cheap, no autograd).
        with torch.no_grad():
            first = _tree_map(lambda t: t[:1], batch)
            m = max(1, residual(params, first).numel())
        per_chunk = max(1, min(self._budget_elements // p, max(_CACHE_ROWS, m)) // m)
        sse, n = 0.0, 0
        for i in range(0, n_samples, per_chunk):
            chunk = _tree_map(lambda t, i=i: t[i : i + per_chunk], batch)
            blocks, r = jac_fn(params, chunk)  # {name: [s, m, *shape]}, [s, m]
            rows = r.numel()
            jac = torch.cat(
                [blocks[name].detach().reshape(rows, -1) for name, *_ in layout], dim=1
            ).to(torch.float64)
            r64 = r.detach().reshape(-1).to(torch.float64)
            self._note(jac.shape[0], p)
            jtj += jac.T @ jac
            jtr += jac.T @ r64
            sse += float(r64 @ r64)
            n += r64.numel()
            del jac
        return sse, n

    def _note(self, rows: int, cols: int) -> None:
        self._peak_rows = max(self._peak_rows, rows)
        self._peak_elements = max(self._peak_elements, rows * cols)

    @staticmethod
    def _solve(jtj: torch.Tensor, jtr: torch.Tensor, mu: float) -> torch.Tensor | None:
        """δ = −(JᵀJ + μI)⁻¹ Jᵀr by Cholesky; None when the damped matrix is not PD."""
        a = jtj + mu * torch.eye(jtj.shape[0], dtype=jtj.dtype)
        chol, info = torch.linalg.cholesky_ex(a)
        if int(info) != 0:
            return None
        delta = -torch.cholesky_solve(jtr.unsqueeze(1), chol).squeeze(1)
        return delta if bool(torch.isfinite(delta).all()) else None

    # ------------------------------------------------------------------ training

    def fit(
        self,
        module: torch.nn.Module,
        residual: Residual,
        train_batches: Sequence[Any],
        val_batches: Sequence[Any] | None = None,
    ) -> LMHistory:
        """Train ``module``'s parameters in place; returns the per-epoch history.

        ``residual(params, batch)`` returns the 1-D residual of one batch, computed with
        ``torch.func.functional_call(module, params, ...)`` on a parameter dict shaped like
        ``dict(module.named_parameters())``. Stops at ``max_epochs``, ``goal``, gradient below
        ``min_grad``, μ > ``mu_max`` or ``max_fail`` consecutive validation increases; with
        validation batches the best-validation parameters are written back (as trainlm).
        """
        t0 = time.perf_counter()
        self._rows = {}
        self._peak_rows = 0
        self._peak_elements = 0
        layout = self._layout(module)
        theta = self._flatten(module)
        hist = LMHistory()
        mu = self.mu
        use_val = bool(val_batches)

        def val_mse(th: torch.Tensor) -> float:
            if not use_val:
                return math.nan
            s, k = self._sse(residual, th, layout, val_batches)  # type: ignore[arg-type]
            return s / max(k, 1)

        best_val = val_mse(theta)
        best_theta = theta.clone()
        fails = 0
        epoch = 0
        stop = ""
        mse = math.nan
        while True:
            # Stopping criteria (trainlm's); those that need no Jacobian are tested first.
            if epoch > 0 and mse <= self.goal:
                stop = "goal"
            elif mu > self.mu_max:
                stop = "mu_max"
            elif epoch >= self.max_epochs:
                stop = "max_epochs"
            elif use_val and fails >= self.max_fail:
                stop = "validation"
            if stop:
                break
            ne = self._normal_equations(residual, theta, layout, train_batches)
            n = max(ne.n, 1)
            mse = ne.sse / n
            grad = 2.0 * float(torch.linalg.vector_norm(ne.jtr)) / n
            if epoch == 0:
                hist.train_mse.append(mse)
                hist.val_mse.append(best_val)
                hist.mu.append(mu)
                hist.time.append(time.perf_counter() - t0)
            hist.gradient.append(grad)
            if mse <= self.goal:
                stop = "goal"
            elif grad < self.min_grad:
                stop = "min_grad"
            if stop:
                break
            # Levenberg-Marquardt step (retries with larger μ on the same Jacobian).
            accepted = False
            while mu <= self.mu_max:
                delta = self._solve(ne.jtj, ne.jtr, mu)
                if delta is not None:
                    trial = theta + delta
                    sse2, _ = self._sse(residual, trial, layout, train_batches)
                    if math.isfinite(sse2) and sse2 < ne.sse:
                        theta = trial
                        mse = sse2 / n
                        mu = max(mu * self.mu_dec, _MU_FLOOR)
                        accepted = True
                        break
                mu *= self.mu_inc
            epoch += 1
            v = val_mse(theta) if accepted else hist.val_mse[-1]
            if use_val and accepted:
                if v < best_val:
                    best_val, best_theta, fails = v, theta.clone(), 0
                    hist.best_epoch = epoch
                elif v > best_val:
                    fails += 1
            hist.train_mse.append(mse)
            hist.val_mse.append(v)
            hist.mu.append(mu)
            hist.time.append(time.perf_counter() - t0)
        if use_val:
            theta = best_theta
        else:
            hist.best_epoch = hist.epochs
        self._write_back(module, theta)
        hist.stop_reason = stop
        hist.peak_jacobian_rows = self._peak_rows
        hist.peak_jacobian_elements = self._peak_elements
        return hist
