"""Levenberg-Marquardt for any PyTorch module with a residual vector (Weiss eqs 54-61, trainlm).

The trainer minimises the sum of squared residuals E(θ) = ½‖r(θ)‖² of a module's parameters θ
(flattened into one float64 vector). Each epoch builds the Gauss-Newton normal equations
(Weiss eqs 54-61) accumulated over the training batches,

    JᵀJ = Σ_b J_bᵀ J_b,    Jᵀr = Σ_b J_bᵀ r_b,

and solves the damped system of MATLAB's ``trainlm``

    (JᵀJ + μ I) δ = −Jᵀr.

A trial step θ + δ is accepted when the training SSE decreases (then μ ← μ·μ_dec), otherwise
μ ← μ·μ_inc and the system is solved again with the same Jacobian, until μ > μ_max.
``damping="nielsen"`` replaces trainlm's fixed factors by Nielsen's gain-ratio rule (Nielsen
1999; Madsen, Nielsen & Tingleff 2004, eq. 2.21): with ρ the ratio of the SSE's actual to its
predicted decrease, δᵀ(μδ − Jᵀr), an accepted step sets μ ← μ·max(1/3, 1 − (2ρ − 1)³) and
ν ← 2, a rejected one μ ← μ·ν, ν ← 2ν: μ falls fast where the Gauss-Newton model is good and
barely moves where it is poor, instead of swinging by 10× each way. ``geodesic=True`` adds
Transtrum & Sethna's geodesic acceleration (2012, "Improvements to the Levenberg-Marquardt
algorithm for nonlinear least-squares minimization", arXiv:1201.5885): with δ the
step above and r_δδ the residual's second directional derivative along it (exact, by forward
mode over forward mode), the acceleration a = −(JᵀJ + μI)⁻¹ Jᵀ r_δδ bends the step along the
curve the residual follows, θ + δ + a/2, and a trial whose 2‖a‖/‖δ‖ exceeds ``geodesic_ratio``
(their α = 0.75) is rejected as if its SSE had risen: the step left the region where the
quadratic model holds. It costs one second-order forward pass and one backward pass over the
training batches per trial. Defaults are
those documented for ``trainlm``: μ = 0.001, μ_dec = 0.1, μ_inc = 10, μ_max = 1e10,
epochs = 1000, max_fail = 6 validation checks, min_grad = 1e-7, goal = 0. As in ``trainlm`` μ is
floored at 1e-20 after a decrease, and when validation batches are given the returned
parameters are those of the best validation error.

Jacobians come from :mod:`torch.func`; there are these modes:

- ``jacobian="forward"`` (always valid): forward-mode products J v for a block of unit
  tangents at a time (``vmap`` over ``jvp``).
  It works for any residual, including ones that
  couple all rows (a simulated trajectory integrated with RK4, a parallel NARX simulation).
  When the whole n × P Jacobian of a batch fits the memory budget it is formed and JᵀJ is one
  matrix product. Otherwise the columns are taken in blocks J_a of width c (n·c ≤ budget) and
  the columns of JᵀJ are accumulated as Jᵀ(J_a) by reverse-mode products (``vmap`` over the
  ``vjp`` of the same forward pass), so memory holds one n × c block and never n × P, and every
  column block is computed once.
- ``jacobian="reverse"`` (always valid): the rows of J by reverse mode, ``vmap`` over the
  ``vjp`` of one forward pass with a block of unit cotangents at a time (c rows, c·max(n, P)
  ≤ budget), each block's JᵀJ and Jᵀr added into the system.
- ``"auto"`` without ``separable`` or ``jacobian_rows`` chooses between the two per batch,
  from what the residual's differentiable operations move (counted once per batch, on the
  pass that finds n): forward mode carries P tangents of each operation's result, reverse
  mode n cotangents of each of its inputs that need a gradient (the whole stacked trajectory
  where a step is read back from it). Per operation forward mode costs more (~25-100 µs
  against ~17 µs under ``vmap``; an operand without a tangent, a constant or a Python number,
  gets a zero one whose shape torch infers through a Python meta kernel, ~0.3-0.5 ms),
  per element moved both ~2.5 ns (torch 2.13, CPU). Reverse mode is taken where its extra
  elements per operation, (n·R − P·F)/ops, are at most 2¹² (R and F the elements above),
  i.e. where the per-operation cost dominates: a physics model stepped through a long
  rollout of small states (one surge state through 150 RK4 steps, P = 2: 0.51 s forward,
  0.08 s reverse; 2400 steps: 8.6 against 2.0 s), and batches with fewer rows than
  parameters. Forward mode stays where the tensors or the read-back trajectories are large
  (a hybrid's 240 shooting segments, n = 14,400, P = 230; a neural state-space simulation of
  200 rows, 0.11 s forward against 0.19 s reverse, of 584 rows 0.07 against 2.3 s).
- ``jacobian="samples"``: for residuals that are separable by sample (a one-step-ahead/series-
  parallel NARX, a static regression), the per-sample Jacobians are taken with ``vmap`` over
  samples of ``jacrev``. The batch is then a tensor, or a (nested) tuple/list/dict of tensors,
  whose leading dimension indexes samples, and ``residual(params, batch[i:j])`` must return the
  rows of samples i..j-1 (in sample-major order). Samples are processed in row chunks of at most
  ``budget / (8 P)`` rows (and at most 8192 rows, beyond which chunks only cost memory), whose
  JᵀJ and Jᵀr are added into the P × P system. This is much cheaper than forward mode for
  networks with many samples.
- ``jacobian_rows`` given to :meth:`fit` (mode ``"supplied"``, what ``"auto"`` then uses): the
  caller computes the rows of J itself, in blocks within the budget, where it knows a cheaper
  formulation than forward mode, e.g. the sensitivity recursion of a recurrent simulation
  (:meth:`nnid.models.narx.NarxModel._simulation_rows`): one batched pass of per-step local
  Jacobians, then a linear recursion in time, instead of one closed-loop pass per parameter.

``train_batches`` may also be a function of the epoch that returns that epoch's batches (as
Adam's are drawn): each epoch's normal equations, trial steps and reported training error are
then those of its own batches, a subsampled Gauss-Newton method. Where JᵀJ dominates an epoch
(a large network on many simulation windows: its cost grows as rows × P²), a subset of the
rows per epoch buys proportionally cheaper iterations, at a price: each step is judged on one
draw only (on the Seamor four-output net a quarter of the windows made epochs 3.7× cheaper and
stopped at far higher validation errors; ``benchmarks/RESULTS.md``).

``curvature_batches`` given to :meth:`fit` keeps the rows that judge a step and draws only the
curvature (subsampled Gauss-Newton curvature; Byrd, Chin, Neveitt & Nocedal 2011, "On the use
of stochastic Hessian information in optimization methods for machine learning"): each
epoch's JᵀJ from that epoch's curvature batches, scaled by the ratio of rows, while Jᵀr comes
from every training batch by one reverse-mode pass (no Jacobian rows) and every trial step is
accepted or rejected on the SSE of all of them. The gradient, the descent test and the
reported error stay exact; only the step's metric is estimated, so the step is a descent
direction of the whole objective for any μ. The backward pass holds one training batch's
autograd graph at a time (not bounded by ``memory_budget_mb``, which bounds Jacobian blocks).

The same trainer fits nonlinear physics parameters: any ``nn.Module`` whose parameters are the
unknowns and a residual that computes model − measurement with ``functional_call``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from sklearn.base import BaseEstimator
from torch.func import jacrev, jvp, vjp, vmap
from torch.overrides import TorchFunctionMode

from nnid.errors import NnidInputError, checked_number
from nnid.trainers.history import History, Progress, silent, stopping_score

__all__ = ["LevenbergMarquardt", "NormalEquations", "unpenalised_names"]

Residual = Callable[[dict[str, torch.Tensor], Any], torch.Tensor]
#: ``recorded(r, batch)``: the rows of a batch's residual whose mean square is recorded
Recorded = Callable[[torch.Tensor, Any], torch.Tensor]
#: ``jacobian_rows(params, batch, budget_elements)`` yields (J block [rows, P], residual [rows])
JacobianRows = Callable[
    [dict[str, torch.Tensor], Any, int], Iterable[tuple[torch.Tensor, torch.Tensor]]
]

_MU_FLOOR = 1e-20  # trainlm: ``if mu < 1e-20, mu = 1e-20``
_CACHE_ROWS = 8192  # samples mode: row chunks above this are no faster (cache), only larger
#: "auto": reverse mode where (n·R − P·F)/ops is at most this (module docstring). The
#: threshold is the low end of the break-even, (o_f − o_r)/2.5 ns with forward's per-operation
#: overhead o_f 25-100 µs and reverse's o_r ~17 µs (2,400-35,000 elements): where the choice
#: errs, reverse mode costs at most ~ops·4 µs more; measured winners of reverse were ≤ 4,000,
#: of forward ≥ 18,000 (a 200-row neural state-space simulation; 2026-11-29)
_REVERSE_ELEMENTS = 2**12


@dataclass
class NormalEquations:
    """Accumulated Gauss-Newton system of one parameter point (float64)."""

    jtj: torch.Tensor  # [P, P]
    jtr: torch.Tensor  # [P]
    sse: float
    n: int


def unpenalised_names(module: torch.nn.Module, names: Iterable[str]) -> set[str]:
    """``names``, parameters of ``module`` that a trainer's weight penalty leaves alone (free
    initial states, which are no weights), checked: a name the module lacks is refused."""
    free = set(names)
    known = [k for k, _ in module.named_parameters()]
    unknown = sorted(free - set(known))
    if unknown:
        raise NnidInputError(
            f"unpenalised names {', '.join(unknown)}, which are not parameters of the module "
            f"({', '.join(known)})",
            field="unpenalised",
        )
    return free


# --------------------------------------------------------------------------- batch pytrees


def add_gram(jtj: torch.Tensor, jtr: torch.Tensor, jac: torch.Tensor, r: torch.Tensor) -> None:
    """``jtj += JᵀJ`` and ``jtr += Jᵀr`` in place for the rows ``jac`` [n, P] and residuals
    ``r`` [n] (float64; Weiss eqs 54-61).

    JᵀJ is what an LM epoch costs on a large network (rows × P²). With one torch thread (every
    worker process nnid starts: ensemble members, batch tasks) the product goes through numpy,
    which hands ``Aᵀ @ A`` of one buffer to OpenBLAS's symmetric rank-k update: on the AMD EPYC
    of the CI machine 0.98 s for 40,000 × 934 rows against 2.0 s through torch's MKL (one
    thread each; ``benchmarks/RESULTS.md``). With more torch threads it stays in torch: a
    multi-threaded OpenBLAS call between torch's parallel operations leaves its threads
    spinning for the cores torch wants next (one LM iteration of ``benchmarks/bench_lm.py``
    0.27 → 0.39-0.47 s on two cores)."""
    if torch.get_num_threads() > 1:
        jtj += jac.T @ jac
        jtr += jac.T @ r
        return
    a = jac.detach().numpy()
    gram = jtj.numpy()
    gram += a.T @ a
    jtr.numpy()[:] += a.T @ r.detach().numpy()


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


class _Cost(TorchFunctionMode):
    """What one pass's differentiable operations move, per direction of each mode: the
    elements they return (a forward-mode tangent each) and the elements of their inputs that
    need a gradient (a reverse-mode cotangent each); module docstring."""

    def __init__(self) -> None:
        super().__init__()
        self.ops = 0
        self.forward = 0
        self.reverse = 0

    def __torch_function__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        tracked = [t for t in _tensors((args, kwargs)) if t.requires_grad]
        if tracked and isinstance(out, torch.Tensor):
            self.ops += 1
            self.forward += out.numel()
            self.reverse += sum(t.numel() for t in tracked)
        return out


def _tensors(tree: Any) -> list[torch.Tensor]:
    """The tensors in a call's arguments."""
    if isinstance(tree, torch.Tensor):
        return [tree]
    if isinstance(tree, dict):
        tree = list(tree.values())
    if isinstance(tree, (tuple, list)):
        return [t for v in tree for t in _tensors(v)]
    return []


# --------------------------------------------------------------------------- trainer


class LevenbergMarquardt(BaseEstimator):
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
        jacobian: ``"forward"`` or ``"reverse"`` (any residual), ``"samples"`` (residual
            separable by sample; see the module docstring) or ``"auto"`` (default: the
            caller's ``jacobian_rows`` when :meth:`fit` is given them, else "samples" when the
            caller says the residual is separable, else forward or reverse mode per batch,
            whichever its shape makes cheaper).
        damping: ``"trainlm"`` (μ·μ_dec after an accepted step, μ·μ_inc after a rejected one)
            or ``"nielsen"`` (the gain-ratio rule of the module docstring; μ_dec and μ_inc
            unused).
        l2: λ of a penalty λ‖θ − θ_c‖² added to the sum of squares (Tikhonov / weight decay:
            the rows √λ (θ − θ_c) appended to the residual, √λ I to the Jacobian; default 0).
        l2_center: θ_c, the flat parameter vector the penalty pulls toward, in the order of
            ``module.parameters()`` (default None: the origin, plain weight decay); e.g. an
            earlier fit whose gains the penalty should not shrink. The parameters named in
            :meth:`fit`'s ``unpenalised`` are left out of the penalty.
        geodesic: add geodesic acceleration to each trial step (module docstring; default
            False, trainlm's step).
        geodesic_ratio: the largest 2‖a‖/‖δ‖ a geodesic trial may have (Transtrum & Sethna's
            α, 0.75).
    """

    kind = "lm"

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
        jacobian: str = "auto",
        damping: str = "trainlm",
        l2: float = 0.0,
        l2_center: Sequence[float] | torch.Tensor | None = None,
        geodesic: bool = False,
        geodesic_ratio: float = 0.75,
    ) -> None:
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
        self.damping = damping
        self.l2 = l2
        self.l2_center = l2_center
        self.geodesic = geodesic
        self.geodesic_ratio = geodesic_ratio
        self._mode = "forward"
        self._rows_fn: JacobianRows | None = None
        self._peak_rows = 0
        self._peak_elements = 0
        # id(batch): (its tensors' shapes, n, its cost) for one fit; the shapes, because an id
        # passes to a fresh object once the batch is freed (one of another size read a stale n)
        self._rows: dict[int, tuple[tuple, int, _Cost]] = {}
        self._center: torch.Tensor | None = None
        #: 1 where the penalty applies, 0 for the ``unpenalised`` parameters; None: everywhere
        self._weights: torch.Tensor | None = None

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

    def _sse(
        self,
        residual: Residual,
        theta: torch.Tensor,
        layout: list,
        batches: Sequence[Any],
        penalised: bool = True,
        recorded: Recorded | None = None,
    ) -> tuple[float, int, float]:
        """(SSE, number of residuals, recorded error) over ``batches`` at ``theta`` (no
        autograd); the SSE with the λ‖θ − θ_c‖² penalty unless ``penalised`` is False
        (validation scores the data alone). The recorded error is the mean square of each
        batch's ``recorded(r, batch)`` rows (every row without it), never the λ penalty: the
        error a History records, comparable with the validation error."""
        params = self._unflatten(theta, layout)
        sse, n, kept, rows = 0.0, 0, 0.0, 0
        with torch.no_grad():
            for b in batches:
                r = residual(params, b).reshape(-1).to(torch.float64)
                sse += float(r @ r)
                n += r.numel()
                if recorded is not None:
                    part = recorded(r, b)
                    kept += float(part @ part)
                    rows += part.numel()
        error = sse / max(n, 1) if recorded is None else kept / max(rows, 1)
        return sse + (self._penalty(theta) if penalised else 0.0), n, error

    def _checked_center(self, n: int) -> torch.Tensor | None:
        """``l2_center`` as a float64 vector of the module's ``n`` parameters."""
        if self.l2_center is None:
            return None
        center = torch.as_tensor(self.l2_center, dtype=torch.float64).detach().reshape(-1)
        if center.numel() != n or not bool(torch.isfinite(center).all()):
            raise NnidInputError(
                f"l2_center must hold {n} finite values, one per parameter (got {center.numel()})",
                field="l2_center",
            )
        return center.clone()

    @staticmethod
    def _penalised(module: torch.nn.Module, unpenalised: Iterable[str]) -> torch.Tensor | None:
        """The flat 0/1 mask of the parameters the penalty applies to (None: all of them)."""
        free = unpenalised_names(module, unpenalised)
        if not free:
            return None
        parts = [
            torch.full((p.numel(),), float(k not in free)) for k, p in module.named_parameters()
        ]
        return torch.cat(parts).to(torch.float64)

    def _offset(self, theta: torch.Tensor) -> torch.Tensor:
        """θ − θ_c, what the penalty squares (θ itself without a centre), 0 where the
        parameter is not penalised."""
        d = theta if self._center is None else theta - self._center
        return d if self._weights is None else d * self._weights

    def _penalty(self, theta: torch.Tensor) -> float:
        if self.l2 <= 0:
            return 0.0
        d = self._offset(theta)
        return self.l2 * float(d @ d)

    def _curvature_pull(
        self, residual: Residual, theta: torch.Tensor, layout: list, batches: Sequence[Any],
        delta: torch.Tensor,
    ) -> torch.Tensor:  # fmt: skip
        """Jᵀ r_δδ over ``batches``: r_δδ = d²/dt² r(θ + tδ) at t = 0 (Transtrum & Sethna
        2012), by forward mode over forward mode, pulled back by one vjp. The λ‖θ − θ_c‖²
        rows are linear in θ: their r_δδ is zero."""
        out = torch.zeros_like(theta)
        for b in batches:

            def f(th: torch.Tensor, b=b) -> torch.Tensor:
                return residual(self._unflatten(th, layout), b).reshape(-1)

            def slope(th: torch.Tensor, f=f) -> torch.Tensor:
                return jvp(f, (th,), (delta,))[1]

            rdd = jvp(slope, (theta,), (delta,))[1].detach()
            _, pull = vjp(f, theta)
            out += pull(rdd.to(theta.dtype))[0].detach().to(torch.float64)
        return out

    def normal_equations(
        self,
        module: torch.nn.Module,
        residual: Residual,
        batches: Sequence[Any],
        separable: bool = False,
        jacobian_rows: JacobianRows | None = None,
    ) -> NormalEquations:
        """JᵀJ, Jᵀr and SSE over ``batches`` at the module's current parameters (float64),
        in the mode :meth:`fit` would use with the same arguments."""
        self._select_mode(separable, jacobian_rows)
        theta = self._flatten(module)
        self._center = self._checked_center(theta.numel())
        self._weights = None
        return self._normal_equations(residual, theta, self._layout(module), batches)

    def _select_mode(self, separable: bool, jacobian_rows: JacobianRows | None) -> None:
        if self.jacobian not in ("auto", "forward", "reverse", "samples"):
            raise NnidInputError(
                f"jacobian is 'auto', 'forward', 'reverse' or 'samples', not {self.jacobian!r}",
                field="jacobian",
            )
        self._rows_fn = jacobian_rows
        self._rows = {}  # batches of an earlier fit, whose contents may have changed
        if self.jacobian != "auto":
            self._mode = self.jacobian
        elif jacobian_rows is not None:
            self._mode = "supplied"
        else:  # "dense": forward or reverse mode, chosen per batch
            self._mode = "samples" if separable else "dense"

    def _normal_equations(
        self,
        residual: Residual,
        theta: torch.Tensor,
        layout: list,
        batches: Sequence[Any],
        penalised: bool = True,
    ) -> NormalEquations:
        p = theta.numel()
        jtj = torch.zeros(p, p, dtype=torch.float64)
        jtr = torch.zeros(p, dtype=torch.float64)
        sse, n = 0.0, 0
        for b in batches:
            if self._mode in ("forward", "reverse", "dense"):
                s, k = self._accumulate_dense(residual, theta, layout, b, jtj, jtr)
            elif self._mode == "supplied":
                s, k = self._accumulate_supplied(theta, layout, b, jtj, jtr)
            else:
                s, k = self._accumulate_samples(residual, theta, layout, b, jtj, jtr)
            sse += s
            n += k
        ne = NormalEquations(jtj, jtr, sse, n)
        return self._penalise(ne, theta) if penalised else ne

    def _penalise(self, ne: NormalEquations, theta: torch.Tensor) -> NormalEquations:
        """The λ‖θ − θ_c‖² rows added to a system of the data alone."""
        if self.l2 > 0:
            ne.jtj.diagonal().add_(self.l2 if self._weights is None else self.l2 * self._weights)
            ne.jtr += self.l2 * self._offset(theta)
            ne.sse += self._penalty(theta)
        return ne

    def _subsampled_equations(
        self,
        residual: Residual,
        theta: torch.Tensor,
        layout: list,
        batches: Sequence[Any],
        curvature: Sequence[Any],
    ) -> NormalEquations:
        """JᵀJ from the ``curvature`` batches, scaled to the rows of ``batches``; Jᵀr and the
        SSE from every batch by reverse mode (one backward pass a batch, no Jacobian)."""
        sub = self._normal_equations(residual, theta, layout, curvature, penalised=False)
        params = {
            k: v.detach().clone().requires_grad_(True)
            for k, v in self._unflatten(theta, layout).items()
        }
        grads = [torch.zeros_like(v) for v in params.values()]
        sse, n = 0.0, 0
        for b in batches:
            r = residual(params, b).reshape(-1)
            parts = torch.autograd.grad(0.5 * (r @ r), list(params.values()), allow_unused=True)
            for g, d in zip(grads, parts, strict=True):
                if d is not None:
                    g += d.detach()
            r64 = r.detach().to(torch.float64)
            sse += float(r64 @ r64)
            n += r64.numel()
        jtr = torch.cat([g.reshape(-1).to(torch.float64) for g in grads])
        jtj = sub.jtj * (n / max(sub.n, 1))
        return self._penalise(NormalEquations(jtj, jtr, sse, n), theta)

    def _accumulate_supplied(self, theta, layout, batch, jtj, jtr) -> tuple[float, int]:
        """Jacobian rows computed by the caller (``jacobian_rows``), block by block."""
        params = {k: v.detach() for k, v in self._unflatten(theta, layout).items()}
        sse, n = 0.0, 0
        for jac, r in self._rows_fn(params, batch, self._budget_elements):  # type: ignore[misc]
            jac = jac.detach().to(torch.float64)
            r64 = r.detach().reshape(-1).to(torch.float64)
            self._note(jac.shape[0], jac.shape[1])
            add_gram(jtj, jtr, jac, r64)
            sse += float(r64 @ r64)
            n += r64.numel()
        return sse, n

    def _accumulate_dense(self, residual, theta, layout, batch, jtj, jtr) -> tuple[float, int]:
        """The Jacobian of one batch by forward or reverse mode (module docstring)."""

        def f(th: torch.Tensor) -> torch.Tensor:
            return residual(self._unflatten(th, layout), batch).reshape(-1)

        p = theta.numel()
        shape = self._rows.get(id(batch))
        shapes = tuple(tuple(x.shape) for x in _tensors(batch))
        if shape is None or shape[0] != shapes:
            cost = _Cost()
            if self._mode == "dense":  # the pass that finds n also weighs the two modes
                with torch.enable_grad(), cost:
                    n = f(theta.detach().requires_grad_(True)).numel()
            else:
                with torch.no_grad():
                    n = f(theta).numel()
            shape = self._rows[id(batch)] = (shapes, n, cost)
        _, n, cost = shape
        if self._mode == "dense":
            extra = n * cost.reverse - p * cost.forward  # elements reverse moves beyond forward
            reverse = extra <= _REVERSE_ELEMENTS * max(cost.ops, 1)
        else:
            reverse = self._mode == "reverse"
        if reverse:
            return self._accumulate_reverse(f, theta, n, jtj, jtr), n
        return self._accumulate_forward(f, theta, n, jtj, jtr), n

    def _accumulate_reverse(self, f, theta, n, jtj, jtr) -> float:
        """Reverse-mode rows of one batch's Jacobian, in row blocks within the budget; the
        batch's SSE."""
        p = theta.numel()
        r, pull = vjp(f, theta)
        r64 = r.detach().to(torch.float64)
        height = max(1, min(n, self._budget_elements // max(n, p)))
        for a in range(0, n, height):
            units = torch.zeros(min(height, n - a), n, dtype=r.dtype)
            units.diagonal(a).fill_(1.0)  # rows a.. of the identity
            block = vmap(lambda u: pull(u)[0])(units).detach().to(torch.float64)  # [c, P]
            self._note(block.shape[0], p)
            add_gram(jtj, jtr, block, r64[a : a + block.shape[0]])
            del units, block
        return float(r64 @ r64)

    def _accumulate_forward(self, f, theta, n, jtj, jtr) -> float:
        """Forward-mode Jacobian of one batch, in column blocks within the budget; the
        batch's SSE."""
        p = theta.numel()
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
            add_gram(jtj, jtr, jac.T, r64)
        else:
            for a in range(0, p, width):
                block = vmap(tangent)(eye[a : a + width]).detach()  # [c, n] = J_aᵀ
                self._note(n, block.shape[0])
                cols = vmap(lambda u: vjp_fn(u)[0])(block)  # [c, P] = (Jᵀ J_a)ᵀ
                jtj[:, a : a + width] += cols.T.to(torch.float64)
                del block, cols
            jtr += vjp_fn(r.detach())[0].detach().to(torch.float64)
        return float(r64 @ r64)

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
            add_gram(jtj, jtr, jac, r64)
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

    def _accelerate(
        self, residual: Residual, theta: torch.Tensor, layout: list, batches: Sequence[Any],
        ne: NormalEquations, mu: float, delta: torch.Tensor,
    ) -> torch.Tensor | None:  # fmt: skip
        """δ + a/2 with the geodesic acceleration a (module docstring); None when the trial is
        refused (2‖a‖/‖δ‖ above ``geodesic_ratio``, or a not finite)."""
        acc = self._solve(ne.jtj, self._curvature_pull(residual, theta, layout, batches, delta), mu)
        if acc is None:
            return None
        size = float(torch.linalg.vector_norm(delta))
        fits = 2.0 * float(torch.linalg.vector_norm(acc)) <= self.geodesic_ratio * size
        return delta + 0.5 * acc if fits else None

    # ------------------------------------------------------------------ training

    def fit(
        self,
        module: torch.nn.Module,
        residual: Residual,
        train_batches: Sequence[Any] | Callable[[int], Sequence[Any]],
        val_batches: Sequence[Any] | None = None,
        progress: Progress | None = None,
        separable: bool = False,
        jacobian_rows: JacobianRows | None = None,
        curvature_batches: Callable[[int], Sequence[Any]] | None = None,
        unpenalised: Iterable[str] = (),
        recorded: Recorded | None = None,
    ) -> History:
        """Train ``module``'s parameters in place; returns the per-epoch :class:`History`
        (``extra``: ``mu`` per entry, ``gradient`` ‖∇ MSE‖ = 2‖Jᵀr‖/N per Jacobian pass;
        ``info``: the largest Jacobian block held, rows and elements).

        ``residual(params, batch)`` returns the 1-D residual of one batch, computed with
        ``torch.func.functional_call(module, params, ...)`` on a parameter dict shaped like
        ``dict(module.named_parameters())``. Stops at ``max_epochs`` (0: the start alone is
        recorded, as Adam records it), ``goal``, gradient below
        ``min_grad``, μ > ``mu_max``, ``max_fail`` consecutive validation increases, or a
        training error or gradient that is not finite ("non-finite loss"); with
        validation batches the best-validation parameters are written back (as trainlm).
        ``progress(epoch, max_epochs, message)`` is called after every epoch. ``separable``
        tells ``jacobian="auto"`` that the residual is separable by sample (then "samples"
        mode, else forward or reverse mode per batch); ``jacobian_rows(params, batch,
        budget_elements)``, when given, yields the Jacobian's rows of a batch with their
        residuals in blocks of at most ``budget_elements`` (then "supplied" mode under
        "auto"; it must agree with ``residual``, which still judges the trial steps).
        ``train_batches(epoch)``, when a function, draws each epoch's batches (module
        docstring). ``curvature_batches(epoch)``, when given, returns the batches (a subset of
        the training data) whose JᵀJ, scaled to the training rows, stands for the whole one in
        that epoch, while the gradient Jᵀr and the trial steps' SSE stay those of every
        training batch (module docstring). ``unpenalised``: names of parameters (as
        ``named_parameters`` gives them) that ``l2`` leaves alone, e.g. free initial states
        that are no weights. ``train`` records the error, not the objective:
        the mean square of the rows ``recorded(r, batch)`` keeps of each training batch's
        residual (default: all; an objective with penalty rows records its error rows) without
        the λ‖θ − θ_c‖² penalty, comparable with the validation error, which scores the data
        alone; the steps, ``goal`` and early stopping read the objective and the validation
        error as before.
        """
        self._select_mode(separable, jacobian_rows)
        # as Adam: max_fail 0 stopped before any validation error, said "validation diverged"
        checked_number(self.max_epochs, "max_epochs", strict=False, integer=True)
        checked_number(self.max_fail, "max_fail", 1, strict=False, integer=True)
        if not (0.0 < self.mu_dec < 1.0 < self.mu_inc):
            raise NnidInputError("need 0 < mu_dec < 1 < mu_inc", field="mu_dec")
        if self.memory_budget_mb <= 0:
            raise NnidInputError("memory_budget_mb must be positive", field="memory_budget_mb")
        if self.l2 < 0:
            raise NnidInputError("l2 must be at least 0", field="l2")
        if self.damping not in ("trainlm", "nielsen"):
            raise NnidInputError("damping is 'trainlm' or 'nielsen'", field="damping")
        if not self.geodesic_ratio > 0:
            raise NnidInputError("geodesic_ratio must be positive", field="geodesic_ratio")
        nielsen = self.damping == "nielsen"
        nu = 2.0
        t0 = time.perf_counter()
        report = progress or silent
        self._rows = {}
        self._peak_rows = 0
        self._peak_elements = 0
        layout = self._layout(module)
        theta = self._flatten(module)
        self._center = self._checked_center(theta.numel())
        self._weights = self._penalised(module, unpenalised)
        hist = History()
        mu = self.mu
        use_val = bool(val_batches)

        def val_mse(th: torch.Tensor) -> float | None:
            if not use_val:
                return None
            s, k, _ = self._sse(residual, th, layout, val_batches, penalised=False)  # type: ignore[arg-type]
            return s / max(k, 1)

        start_val = val_mse(theta)
        best_val = None if start_val is None else stopping_score(start_val)
        best_theta = theta.clone()
        fails = 0
        epoch = 0
        last_accepted = 0  # without validation, the epoch whose parameters are kept
        stop = ""
        mse = math.nan
        # A trial is judged against the SSE of the current point computed by the same code path
        # (``_sse``): the normal equations' SSE comes from another path (per-sample vmap in
        # "samples" mode) whose rounding differs by ~1e-17, and comparing across the two once
        # accepted null steps forever at the optimum, a stall that depended on the CPU's kernels.
        drawn = callable(train_batches)
        batches = train_batches(0) if drawn else train_batches
        sse, _, error = self._sse(residual, theta, layout, batches, recorded=recorded)
        while True:
            # Stopping criteria (trainlm's); those that need no Jacobian are tested first.
            if epoch > 0 and mse <= self.goal:
                stop = "goal"
            elif mu > self.mu_max:
                stop = "mu_max"
            elif epoch >= self.max_epochs:
                stop = "max_epochs"
            elif use_val and fails >= self.max_fail:
                stop = hist.early_stop_reason()
            if stop:
                break
            if drawn and epoch > 0:  # this epoch's batches: the point's SSE on them
                batches = train_batches(epoch)
                sse, _, error = self._sse(residual, theta, layout, batches, recorded=recorded)
            if curvature_batches is None:
                ne = self._normal_equations(residual, theta, layout, batches)
            else:
                ne = self._subsampled_equations(
                    residual, theta, layout, batches, curvature_batches(epoch)
                )
            n = max(ne.n, 1)
            mse = sse / n  # the objective that trials are judged against, and ``goal``
            grad = 2.0 * float(torch.linalg.vector_norm(ne.jtr)) / n
            if epoch == 0:
                hist.record(error, start_val, time.perf_counter() - t0, mu=mu)
            hist.extra.setdefault("gradient", []).append(grad)
            if not (math.isfinite(mse) and math.isfinite(grad)):
                # the training error overflowed (a free run diverged): no trial is judged
                # against it, and "mu_max" would read as a stall (Adam's words for this end)
                stop = "non-finite loss"
            elif mse <= self.goal:
                stop = "goal"
            elif grad < self.min_grad:
                stop = "min_grad"
            if stop:
                break
            # Levenberg-Marquardt step (retries with larger μ on the same Jacobian).
            accepted = False
            while mu <= self.mu_max:
                delta = self._solve(ne.jtj, ne.jtr, mu)
                if delta is not None and self.geodesic:
                    delta = self._accelerate(residual, theta, layout, batches, ne, mu, delta)
                if delta is not None:
                    trial = theta + delta
                    sse2, _, error2 = self._sse(residual, trial, layout, batches, recorded=recorded)
                    if math.isfinite(sse2) and sse2 < sse:
                        if self.geodesic:  # the linear model's decrease for any step
                            predicted = -float(2 * delta @ ne.jtr + delta @ ne.jtj @ delta)
                        else:  # the same, for the step that solves the damped system
                            predicted = float(delta @ (mu * delta - ne.jtr))
                        rho = (sse - sse2) / predicted if predicted > 0 else 1.0
                        theta, sse, error = trial, sse2, error2
                        mse = sse2 / n
                        if nielsen:
                            mu, nu = mu * max(1 / 3, 1 - (2 * rho - 1) ** 3), 2.0
                        else:
                            mu = mu * self.mu_dec
                        mu = max(mu, _MU_FLOOR)
                        accepted = True
                        break
                if nielsen:
                    mu, nu = mu * nu, 2 * nu
                else:
                    mu *= self.mu_inc
            epoch += 1
            if accepted:
                last_accepted = epoch
            v = val_mse(theta) if accepted else (hist.validation[-1] if use_val else None)
            if use_val and accepted:
                score = stopping_score(v)
                if score < best_val:
                    best_val, best_theta, fails = score, theta.clone(), 0
                    hist.best_epoch = epoch
                elif score > best_val or math.isinf(score):
                    fails += 1
            hist.record(error, v, time.perf_counter() - t0, mu=mu)
            report(
                epoch,
                self.max_epochs,
                f"LM epoch {epoch}: train MSE {error:.4g}"
                + (f", validation {v:.4g}" if v is not None else "")
                + f", mu {mu:.1e}",
                train=error,
                **({} if v is None else {"validation": v}),
            )
        if not hist.train:  # stopped before the first Jacobian (max_epochs=0): the start, as Adam
            hist.record(error, start_val, time.perf_counter() - t0, mu=mu)
        if use_val:
            theta = best_theta
        else:  # a rejected step leaves θ as it was: the last accepted one is what is kept
            hist.best_epoch = last_accepted
        self._write_back(module, theta)
        hist.stop_reason = stop
        hist.info = {
            "peak_jacobian_rows": self._peak_rows,
            "peak_jacobian_elements": self._peak_elements,
        }
        return hist
