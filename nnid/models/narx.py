"""NARX network: nonlinear autoregressive model with exogenous inputs (Weiss section IV.A.2, V.B).

The model is Weiss's regression y(k) = f(φ(k)) with the regressor φ(k) of past outputs and
inputs (eqs 54-61 write the linear-in-θ case y = φᵀθ; a NARX replaces φᵀθ by a small network):

    φ(k) = [y(k − d_y) for d_y in output_delays] ++ [u(k − d_u) for d_u in input_delays]
    y(k) = y(k − 1) + s_Δ · W₂ tanh(W₁ φ(k) + b₁) + b₂      (``delta=True``, default)
    y(k) = W₂ tanh(W₁ φ(k) + b₁) + b₂                        (``delta=False``, MATLAB's form)

in normalised units (inputs and outputs standardised on the training data; the statistics are
buffers of the network, saved with it). Inputs are any named columns (generalized forces
``tau_*``, thruster commands ``cmd_*``, or the input of a generic table); outputs are any named
columns (body velocities u v w r ...).

* **Series-parallel** (open-loop, teacher-forced) training on one-step targets, or on a
  ``multi_step`` horizon (closed loop over K steps from measured delay states).
* **Parallel** (closed-loop) free run: the network fed its own outputs; without gradients
  through the compiled kernel :func:`nnid.models.narx_kernel.free_run` (input contributions of
  the first layer precomputed in one matmul), with gradients through torch.
* **Simulation-error (parallel) training** (``simulation_epochs``): after the series-parallel
  (one-step) initialisation, LM or Adam on the output error of free runs over windows cut
  from every training experiment, each started from measured delay states; windows may grow
  in stages (``simulation_window=[64, 256, 2000]``: short windows first, a smoother objective);
  early-stopped on the validation runs' whole free runs, and kept only if it lowers the
  same measure: the mean over validation runs and the outputs each excites of its squared
  free-run NRMSE (``finetune_`` records it and the pooled NRMSE, before and after); with
  ``simulation_run_floor`` the training windows' errors are in their own run's std too.
* **Multi-experiment**: a delay vector never reaches across an experiment boundary; the first
  ``warmup`` samples of each experiment (the delay states) are never predicted nor scored.
* **Balanced sampling** (Weiss V.B: a net trained mostly on steady state misses the
  transients): training samples drawn by :class:`nnid.datasets.segmentation.BalancedSampler`.
* **Output bounds** (``output_bounds``, off by default): predicted outputs clamped to a range
  (a saturating sensor, an overflowing tank) in every prediction mode and inside the closed
  loop of simulation-error training, so a free run cannot leave the range the plant can reach.
* **Levenberg-Marquardt on simulation error** (``simulation_trainer="lm"``): on deterministic
  windows, the Jacobian of the closed loop by its sensitivity recursion
  (:meth:`NarxModel._simulation_rows`): written-out local Jacobians of every step in one
  batched pass, then a linear recursion in time (1.1-2.6× a one-step LM iteration on as many
  rows, where forward mode, one closed-loop pass per parameter, costs 15-38×;
  ``benchmarks/bench_narx_simulation.py``). :meth:`NarxModel.simulation_objective` hands the
  same objective to a trainer of one's own.
* **Output transform** (off by default): extra regressors computed from every lagged output,
  standardised, inside the closed loop too; still a NARX. ``"sqrt"``: √max(y(k − d_y), 0) of
  each output (in its units), e.g. Torricelli's outflow of a tank. ``"products"``: the
  products y_i y_j (i ≤ j, of the standardised outputs) of each lag, the bilinear terms of the
  Coriolis, centripetal and Munk forces (Fossen's C(ν)ν, Weiss eqs 22-28) that a small tanh
  layer otherwise has to approximate. ``"fossen"``: those products and y_i|y_i| (in the
  outputs' units), the quadratic damping terms (Weiss eq. 45): with them one explicit Euler
  step of the Fossen model is linear in the regressor, and the network only has to learn it.
* **Rest equilibrium** (``rest_equilibrium``, off by default, Δ form only): the increment is
  W₂ (tanh(W₁φ + b₁) − tanh(W₁φ_rest + b₁)), zero at φ_rest, the regressor of zero outputs and
  inputs in their units: a neutrally buoyant vehicle at rest with its thrusters off stays at
  rest exactly, where an unconstrained net creeps (b₂ cancels and stays untrained).
"""

from __future__ import annotations

import functools
import numbers
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import torch
from sklearn.base import clone
from sklearn.utils.validation import check_is_fitted
from torch import nn
from torch.func import functional_call
from torch.nn.utils import parameters_to_vector

from nnid.datasets.log import PIECE_OF, VELOCITY
from nnid.datasets.preprocess import experiment_rows
from nnid.datasets.segmentation import BalancedSampler, label_transients, run_bounds
from nnid.datasets.splits import split_log
from nnid.errors import NnidInputError, checked_number
from nnid.evaluation.evaluate import target_columns
from nnid.models import narx_kernel
from nnid.models.base import NOT_FITTED
from nnid.models.bounds import (
    OutputBounds,
    bound_arrays,
    check_bounds,
    resolve_bounds,
    restored_bounds,
)
from nnid.models.io_model import DTYPE, InputOutputModel, seeded_linear
from nnid.serialization import jsonable
from nnid.trainers.history import History, Progress, scored_validation, staged, stopping_score
from nnid.validation import MAX_SEED, MAX_WIDTH, checked_names, disjoint_columns, window_lengths

#: ``output_transform`` values: extra regressors computed from each lagged output
OUTPUT_TRANSFORMS = (None, "sqrt", "products", "fossen")

#: the settings of an LM ``trainer`` its free-run stage (``simulation_trainer="lm"``) takes
#: too: how it steps and the memory its Jacobian blocks may hold. Not its stopping rules nor
#: its penalty (``simulation_epochs``, ``simulation_max_fail``, ``simulation_l2``: the stage's
#: own), nor ``jacobian``: the stage supplies its rows (the sensitivity recursion)
LM_STEP_SETTINGS = (
    "mu", "mu_dec", "mu_inc", "mu_max", "memory_budget_mb", "damping", "geodesic",
    "geodesic_ratio",
)  # fmt: skip


@functools.cache
def _pairs(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs (i, j), i ≤ j, of the ``products`` transform of m outputs (cached: the
    closed loop asks once per simulated step)."""
    i, j = np.triu_indices(m)
    i.flags.writeable = j.flags.writeable = False
    return i, j


@functools.cache
def _pairs_t(m: int) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`_pairs` as index tensors (numpy indices are converted on every use)."""
    return tuple(torch.as_tensor(x.copy()) for x in _pairs(m))


@dataclass(frozen=True)
class SimulationObjective:
    """The simulation-error (free-run) objective of a NARX network, in the form the trainers
    take (:meth:`nnid.trainers.levenberg_marquardt.LevenbergMarquardt.fit`,
    :meth:`nnid.trainers.adam.Adam.fit`): what :meth:`NarxModel.simulation_objective` returns,
    so that a study of training (``benchmarks/bench_narx_adam_lm.py``) runs the model's own
    objective with a trainer of its own.

    ``module``: the network, trained in place. ``windows``: one batch of every training window
    (delay states [B, dy, m], input features [B, L, ·], measured outputs [B, L, m] and, with
    ``simulation_run_floor``, output weights [B, 1, m]); index each tensor alike to take a
    subset. ``residual(params, batch)``: the flat (weighted) free-run error of a batch of
    windows or of validation runs. ``jacobian_rows``: its Jacobian by the sensitivity
    recursion (LM's ``jacobian_rows``). ``validation``: one batch per validation run, its
    whole free run weighted by 1 / each excited output's std over the run, so the mean square
    is the early-stopping measure of the model's own stages (None without a validation log).
    ``order(n, epoch)``: the seeded permutation of n windows the model's stages use at that
    epoch."""

    module: nn.Module
    windows: tuple[torch.Tensor, ...]
    residual: Callable[[dict[str, torch.Tensor], tuple], torch.Tensor]
    jacobian_rows: Callable[..., Iterator[tuple[torch.Tensor, torch.Tensor]]]
    validation: list[tuple] | None
    order: Callable[[int, int], torch.Tensor]


def _delays(d: int | Sequence[int], minimum: int, what: str) -> list[int]:
    """A whole number n means delays 1..n (MATLAB's ``1:n``); a list is taken as given. Each
    whole (a numpy integer is one), as the config has them: ``int`` cut 1.5 to 1."""
    if isinstance(d, str | bytes) or not np.iterable(d):
        n = checked_number(d, what, 1, strict=False, integer=True)
        return list(range(1, int(n) + 1))
    out = sorted(
        {int(checked_number(x, f"{what}.{i}", minimum, strict=False, integer=True))
         for i, x in enumerate(d)}
    )  # fmt: skip
    if not out:
        # named as the setting: a config's empty list was said against the file alone
        raise NnidInputError(
            f"a positive count or a list of delays ≥ {minimum} is expected, not {d!r}", field=what
        )
    return out


class NarxNet(nn.Module):
    """The MLP (tanh hidden layers, linear output) and the normalisation buffers."""

    def __init__(
        self,
        n_in: int,
        n_out: int,
        n_u: int,
        hidden: Sequence[int],
        n_s: int = 0,
        generator: torch.Generator | None = None,
        rest: bool = False,
    ) -> None:
        super().__init__()
        gen = generator if generator is not None else torch.Generator()
        layers: list[nn.Module] = []
        prev = n_in
        for h in hidden:
            layers += [seeded_linear(prev, h, gen), nn.Tanh()]
            prev = h
        layers.append(seeded_linear(prev, n_out, gen))
        self.mlp = nn.Sequential(*layers).to(DTYPE)
        for name, n in (("u_mean", n_u), ("y_mean", n_out)):
            self.register_buffer(name, torch.zeros(n, dtype=DTYPE))
        for name, n in (("u_std", n_u), ("y_std", n_out), ("d_scale", n_out)):
            self.register_buffer(name, torch.ones(n, dtype=DTYPE))
        if n_s:  # standardisation of the transformed outputs (only with an output_transform)
            self.register_buffer("s_mean", torch.zeros(n_s, dtype=DTYPE))
            self.register_buffer("s_std", torch.ones(n_s, dtype=DTYPE))
        self.rest = rest
        if rest:  # the regressor of the vehicle at rest (zero outputs and inputs, in their units)
            self.register_buffer("phi_rest", torch.zeros(n_in, dtype=DTYPE))

    def forward(self, phi: torch.Tensor) -> torch.Tensor:
        if self.rest:  # the increment is zero at rest: W_o (h(φ) − h(φ_rest)), b_o cancels
            # φ_rest as one more row of the same product: a row equal to it then gives its
            # output to the bit (a lone vector takes another BLAS routine, summing in another
            # order, and left one-step increments of ~1e-16 at rest)
            lead = phi.shape[:-1]
            out = self.mlp(torch.cat([phi.reshape(-1, phi.shape[-1]), self.phi_rest[None]]))
            return (out[:-1] - out[-1]).reshape(*lead, -1)
        return self.mlp(phi)


def _finetune_as_stages(finetune: dict | None) -> dict | None:
    """``finetune_`` as saved, in today's shape: a record saved before the free-run stages were
    one ``stages`` list (2026-11-28) kept them as parallel lists (``windows``, ``stops``, and
    from later saves ``stage_epochs``, ``stage_best_epochs``); they become that list, an entry
    the record never held left out rather than guessed."""
    if not finetune or "stages" in finetune:
        return finetune
    old = dict(finetune)
    stops = old.pop("stops", [])
    columns = {
        "window": old.pop("windows", []),
        "epochs": old.pop("stage_epochs", None),
        "best_epoch": old.pop("stage_best_epochs", None),
    }
    old["stages"] = [
        {"stop_reason": stop, **{k: v[i] for k, v in columns.items() if v and i < len(v)}}
        for i, stop in enumerate(stops)
    ]
    return old


class NarxModel(InputOutputModel):
    """NARX model (Weiss IV.A.2, V.B), a scikit-learn estimator behind the model protocol.

    ``trainer``: an :class:`nnid.trainers.adam.Adam` (default) or a
    :class:`~nnid.trainers.levenberg_marquardt.LevenbergMarquardt` (one-step training; full
    batch for LM). Without a ``validation`` log the training log is divided into contiguous
    blocks (``division="block"``, ``fractions`` 70/15/15, MATLAB's divideblock; the test block
    is left unused) or at random (``division="random"``: warns, neighbouring samples are
    correlated; refused with ``simulation_epochs``, whose windows span the rows it holds out).
    ``seed`` seeds the initial weights and the sampling (local generators).

    * ``output_bounds``: None (no clamp), ``"train"`` (each output's training range) or one
      ``[low, high]`` per output in its units, each a number, None (open) or ``"train"``.
      Predictions are clamped in every mode and inside the closed loop of the simulation-error
      training; ``"train"`` entries are resolved at ``fit`` (``bounds_``).
    * ``simulation_epochs`` > 0: after one-step training, train on the simulation error of
      windows of ``simulation_window`` samples (a length, or a list of lengths trained in
      turn, each for up to ``simulation_epochs``) ending at each experiment's last sample and
      every half window before, with ``simulation_trainer`` ``"adam"`` (every window once an
      epoch in a seeded random order, ``simulation_lr``) or ``"lm"`` (sensitivity-recursion
      Jacobians, with an LM ``trainer``'s step and memory settings, :data:`LM_STEP_SETTINGS`);
      windows longer than the shortest experiment are cut to it (``finetune_``
      ``["stages"]``: per window length trained, its :meth:`History.as_dict` record, why it
      ended and the epoch it kept); early-stopped on the whole free runs of the validation
      experiments and kept only if that measure (each run's squared free-run NRMSE, averaged)
      falls (``finetune_``). ``simulation_max_fail``: validation failures before a stage
      stops; ``simulation_l2``: λ of a λ‖θ − θ_c‖² penalty on the LM sum of squares, θ_c
      zero or, with ``simulation_l2_center="one_step"``, the one-step fit's weights (decay
      toward the series-parallel solution, which does not shrink its gains);
      ``simulation_curvature`` < 1: each LM epoch's JᵀJ from that share of the windows, drawn
      per epoch from ``seed`` (subsampled curvature; the gradient and the SSE that judges a
      step stay those of every window). ``simulation_run_floor``
      (None: every window's error in the training std of each output): each training run's
      error in that run's own std of each output, floored at this share of the training std
      (an output the run leaves at its noise is not blown up), the units the validation runs
      are judged in, so a run that moves an output little is fitted as closely as one that
      moves it much.
    * ``output_transform``: None, ``"sqrt"`` (√max(y, 0) of every lagged output, output
      units), ``"products"`` (y_i y_j, i ≤ j, of every lag's standardised outputs) or
      ``"fossen"`` (those products, then y_i|y_i| in output units), each standardised on the
      training data and appended to the output regressors.
    * ``rest_equilibrium``: the Δ increment pinned to zero at zero outputs and inputs.
    """

    kind = "narx"
    counts_samples = "the NARX (its delays)"
    validation_role = "early stopping"

    def __init__(
        self,
        inputs: Sequence[str],
        outputs: Sequence[str],
        input_delays: int | Sequence[int] = 2,
        output_delays: int | Sequence[int] = 2,
        hidden: Sequence[int] = (10,),
        trainer: Any = None,
        balanced: bool = True,
        seed: int = 0,
        delta: bool = True,
        multi_step: int = 1,
        simulation_epochs: int = 0,
        simulation_window: int | Sequence[int] = 200,
        simulation_lr: float = 1e-3,
        division: str = "block",
        fractions: Sequence[float] = (0.7, 0.15, 0.15),
        batch_size: int = 256,
        samples_per_epoch: int | None = None,
        lm_samples: int = 4000,
        output_bounds: OutputBounds = None,
        simulation_trainer: str = "adam",
        simulation_max_fail: int = 8,
        simulation_l2: float = 0.0,
        simulation_l2_center: str = "zero",
        simulation_curvature: float = 1.0,
        simulation_run_floor: float | None = None,
        output_transform: str | None = None,
        rest_equilibrium: bool = False,
    ) -> None:
        self.inputs = inputs
        self.outputs = outputs
        self.input_delays = input_delays
        self.output_delays = output_delays
        self.hidden = hidden
        self.trainer = trainer
        self.balanced = balanced
        self.seed = seed
        self.delta = delta
        self.multi_step = multi_step
        self.simulation_epochs = simulation_epochs
        self.simulation_window = simulation_window
        self.simulation_lr = simulation_lr
        self.division = division
        self.fractions = fractions
        self.batch_size = batch_size
        self.samples_per_epoch = samples_per_epoch
        self.lm_samples = lm_samples
        self.output_bounds = output_bounds
        self.simulation_trainer = simulation_trainer
        self.simulation_max_fail = simulation_max_fail
        self.simulation_l2 = simulation_l2
        self.simulation_l2_center = simulation_l2_center
        self.simulation_curvature = simulation_curvature
        self.simulation_run_floor = simulation_run_floor
        self.output_transform = output_transform
        self.rest_equilibrium = rest_equilibrium

    def _configure(self) -> None:
        """The settings in working form, checked (by ``fit`` and on load)."""
        if self.division not in ("block", "random"):
            raise NnidInputError("division is 'block' or 'random'", field="division")
        if self.simulation_trainer not in ("adam", "lm"):
            raise NnidInputError("simulation_trainer is 'adam' or 'lm'", field="simulation_trainer")
        if self.simulation_l2_center not in ("zero", "one_step"):
            raise NnidInputError(
                "simulation_l2_center is 'zero' or 'one_step'", field="simulation_l2_center"
            )
        if self.output_transform not in OUTPUT_TRANSFORMS:
            raise NnidInputError(
                "output_transform is None, 'sqrt', 'products' or 'fossen'", field="output_transform"
            )
        if not 0.0 < float(self.simulation_curvature) <= 1.0:
            raise NnidInputError(
                "simulation_curvature is the share of the windows in (0, 1] whose JᵀJ stands for "
                "all in an LM epoch",
                field="simulation_curvature",
            )
        floor = self.simulation_run_floor
        if floor is not None and not 0.0 < float(floor) <= 1.0:
            raise NnidInputError(
                "simulation_run_floor is None or the share in (0, 1] of an output's training "
                "std below which a run's own std is not taken",
                field="simulation_run_floor",
            )
        if self.rest_equilibrium and not self.delta:
            raise NnidInputError(
                "rest_equilibrium makes the Δ increment zero at rest: it needs delta=True",
                field="rest_equilibrium",
            )
        self.inputs_ = checked_names(self.inputs, "inputs")
        self.outputs_ = checked_names(self.outputs, "outputs")
        if not self.inputs_ or not self.outputs_:
            raise NnidInputError("a NARX needs at least one input and one output", field="outputs")
        disjoint_columns(self.inputs_, self.outputs_)
        # as the config has them: numpy refused a negative seed with its own words, 2.5
        # horizons or epochs were cut by int()
        checked_number(self.seed, "seed", 0, strict=False, integer=True, maximum=MAX_SEED)
        checked_number(self.multi_step, "multi_step", 1, strict=False, integer=True)
        checked_number(self.simulation_epochs, "simulation_epochs", 0, strict=False, integer=True)
        self.targets_ = list(self.outputs_)
        self.input_delays_ = _delays(self.input_delays, 0, "input_delays")
        self.output_delays_ = _delays(self.output_delays, 1, "output_delays")
        if isinstance(self.hidden, str | bytes) or not np.iterable(self.hidden):
            raise NnidInputError("hidden is a list of layer widths", field="hidden")
        # capped as the config caps it (wider is a typo); int() made 1.5 one unit wide
        self.hidden_ = tuple(
            checked_number(h, "hidden", 1, strict=False, integer=True, maximum=MAX_WIDTH)
            for h in self.hidden
        )
        if not self.hidden_:  # both closed loops (torch's, the kernel's) start from one
            raise NnidInputError(
                "hidden is a list of layer widths, at least one: the network needs a hidden layer",
                field="hidden",
            )
        self.output_bounds_ = check_bounds(self.output_bounds, len(self.outputs_))
        self.dy_ = max(self.output_delays_)
        self.simulation_windows_ = window_lengths(self.simulation_window)
        #: the delay states: samples at the start of each experiment neither predicted nor scored
        self.warmup_samples_ = max(self.dy_, max(self.input_delays_))

    # -- configuration ---------------------------------------------------------------------------
    def _new_net(self, generator: torch.Generator | None = None) -> NarxNet:
        n_u = len(self.inputs_)
        return NarxNet(
            self._n_features(),
            len(self.outputs_),
            n_u,
            self.hidden_,
            self._n_s(),
            generator,
            rest=bool(self.rest_equilibrium),
        )

    def _n_s(self) -> int:
        """Transformed regressors per lag (0 without an ``output_transform``)."""
        m = len(self.outputs_)
        pairs = m * (m + 1) // 2
        return {None: 0, "sqrt": m, "products": pairs, "fossen": pairs + m}[self.output_transform]

    def _n_y_features(self) -> int:
        """Regressors from lagged outputs: the outputs, then their transforms (if any)."""
        return len(self.output_delays_) * (len(self.outputs_) + self._n_s())

    def _n_features(self) -> int:
        return self._n_y_features() + len(self.input_delays_) * len(self.inputs_)

    def _raw_transform(self, yn: torch.Tensor) -> torch.Tensor:
        """The transform of normalised outputs ``yn`` [..., m] before its standardisation."""
        y = yn * self.net_.y_std + self.net_.y_mean
        if self.output_transform in ("products", "fossen"):
            i, j = _pairs_t(yn.shape[-1])
            out = yn[..., i] * yn[..., j]
            return torch.cat([out, y * y.abs()], -1) if self.output_transform == "fossen" else out
        return torch.sqrt(torch.clamp(y, min=1e-12))

    def _transform_t(self, yn: torch.Tensor) -> torch.Tensor:
        """The standardised transform of normalised outputs ``yn`` (torch, differentiable)."""
        return (self._raw_transform(yn) - self.net_.s_mean) / self.net_.s_std

    def _transform_np(self, yn: np.ndarray) -> np.ndarray:
        """:meth:`_transform_t` on numpy arrays."""
        return self._transform_t(torch.as_tensor(yn)).numpy()

    def _transform_jacobian(self, yn: torch.Tensor) -> torch.Tensor:
        """∂(standardised transform)/∂yn [N, n_s, m] at normalised outputs ``yn`` [N, m]."""
        n, m = yn.shape
        net = self.net_
        y_real = yn * net.y_std + net.y_mean
        if self.output_transform in ("products", "fossen"):  # ∂(y_i y_j)/∂y_k = δ_ik y_j + …
            i, j = _pairs_t(m)
            out = torch.zeros(n, self._n_s(), m, dtype=yn.dtype)
            rows = torch.arange(len(i))
            out[:, rows, i] += yn[:, j]
            out[:, rows, j] += yn[:, i]
            if self.output_transform == "fossen":  # ∂(y|y|)/∂yn = 2|y| σ_y
                out[:, len(i) :] = torch.diag_embed(2 * y_real.abs() * net.y_std)
            return out / net.s_std[:, None]
        # d/dy of (√max(y·σ + μ, ε) − μ_s)/σ_s
        root = torch.sqrt(torch.clamp(y_real, min=1e-12))
        return torch.diag_embed(
            torch.where(y_real > 1e-12, net.y_std / (2 * root * net.s_std), 0.0)
        )

    def _norm_bounds(self) -> tuple[torch.Tensor, torch.Tensor] | None:
        """The resolved bounds in normalised units (±inf where open), or None."""
        if self.bounds_ is None:
            return None
        net = self.net_
        return bound_arrays(self.bounds_, net.y_mean, net.y_std)

    def _norm_bounds_np(self) -> tuple[np.ndarray, np.ndarray] | None:
        nb = self._norm_bounds()
        return None if nb is None else (nb[0].numpy(), nb[1].numpy())

    def layer_sizes(self) -> list[int]:
        """Regressor length, hidden sizes, outputs."""
        return [self._n_features(), *self.hidden_, len(self.outputs_)]

    # -- protocol --------------------------------------------------------------------------------
    def _params(self) -> dict[str, dict[str, float | None]]:
        """A network has no physical parameters: its size (weights and biases), as the state
        space model gives it; the weights are the tensors. The layer sizes are settings, not
        estimates: :meth:`describe` gives them (``layers``)."""
        return {"n_params": {"value": float(self._n_params()), "stderr": None}}

    def describe(self) -> dict:
        return {
            **super().describe(),
            "inputs": self.inputs_,
            "input_delays": self.input_delays_,
            "output_delays": self.output_delays_,
            "layers": self.layer_sizes(),
            **self._learned(),
        }

    def _learned(self) -> dict:
        history = getattr(self, "history_", None)
        return {
            "bounds": self.bounds_,
            "division": self.division_,
            "transient_share_of_training_draws": self.transient_share_,
            "simulation_finetune": self.finetune_,
            "history": history.as_dict() if hasattr(history, "as_dict") else history,
        }

    def _set_learned(self, state: dict) -> None:
        self.bounds_ = restored_bounds(state["bounds"], self.outputs_)
        self.division_ = state["division"]
        self.transient_share_ = state["transient_share_of_training_draws"]
        self.finetune_ = _finetune_as_stages(state["simulation_finetune"])
        self.history_ = state["history"]

    # -- data ------------------------------------------------------------------------------------
    def _u_features(self, u: np.ndarray) -> np.ndarray:
        """[u(k − d) for d in input_delays] per row k of one experiment (zeros before warm-up)."""
        n, p = u.shape
        out = np.zeros((n, len(self.input_delays_) * p))
        if n <= self.warmup_samples_:  # a run no longer than the delays: no row has them all
            return out
        for j, d in enumerate(self.input_delays_):
            out[self.warmup_samples_ :, j * p : (j + 1) * p] = u[self.warmup_samples_ - d : n - d]
        return out

    def _y_features(self, y: np.ndarray) -> np.ndarray:
        """[y(k − d)] per output delay, then (``output_transform``) the transformed lags."""
        n = len(y)
        blocks = [y, self._transform_np(y)] if self.output_transform else [y]
        out = np.zeros((n, self._n_y_features()))
        if n <= self.warmup_samples_:  # as in _u_features
            return out
        col = 0
        for src in blocks:
            w = src.shape[1]
            for d in self.output_delays_:
                out[self.warmup_samples_ :, col : col + w] = src[self.warmup_samples_ - d : n - d]
                col += w
        return out

    def _fit_normalisation(self, log: pd.DataFrame, rows: np.ndarray | None = None) -> None:
        """Standardisation, the scale of the Δ targets and of the transformed outputs, from
        the training ``rows`` of ``log`` (a boolean mask; all by default): a random division
        holds its validation rows in the same log."""
        net = self.net_
        rows = np.ones(len(log), dtype=bool) if rows is None else rows
        self._standardise(log[rows])
        y = log[self.outputs_].to_numpy(np.float64)[rows]
        # a step is a training one where both of its samples are
        diffs = [
            np.diff(yn, axis=0)[rows[pos][1:] & rows[pos][:-1]]
            for pos, yn, _ in self._segments(log)
            if len(yn) > 1
        ]
        d = np.concatenate(diffs).std(0) if diffs else np.ones(len(self.outputs_))
        net.d_scale.copy_(
            torch.as_tensor(np.where(d > 0, d, 1.0) if self.delta else np.ones_like(d))
        )
        if self.output_transform:
            yn = (y - net.y_mean.numpy()) / net.y_std.numpy()
            s = self._raw_transform(torch.as_tensor(yn)).numpy()
            s_std = s.std(0)
            net.s_mean.copy_(torch.as_tensor(s.mean(0)))
            net.s_std.copy_(torch.as_tensor(np.where(s_std > 0, s_std, 1.0)))
        if self.rest_equilibrium:
            net.phi_rest.copy_(self._rest_features())

    def _rest_features(self) -> torch.Tensor:
        """The regressor of zero outputs and zero inputs (in their units), laid out as
        :meth:`_y_features` then :meth:`_u_features` lay out a row."""
        net = self.net_
        yn = -net.y_mean / net.y_std
        blocks = [yn.repeat(len(self.output_delays_))]
        if self.output_transform:
            blocks.append(self._transform_t(yn).repeat(len(self.output_delays_)))
        blocks.append((-net.u_mean / net.u_std).repeat(len(self.input_delays_)))
        return torch.cat(blocks)

    def _rest_hidden(self, ws: list[tuple[torch.Tensor, torch.Tensor]]) -> torch.Tensor:
        """The last hidden layer's activation at rest for weights ``ws`` ([(W, b)] per layer)."""
        h = self.net_.phi_rest
        for w, b in ws[:-1]:
            h = torch.tanh(h @ w.T + b)
        return h

    def _table(self, log: pd.DataFrame) -> dict[str, torch.Tensor]:
        """Row-aligned tensors of a log: features, one-step targets, normalised outputs."""
        phi_y, phi_u, y_all, code = [], [], [], []
        for k, (_, yn, un) in enumerate(self._segments(log)):
            phi_y.append(self._y_features(yn))
            phi_u.append(self._u_features(un))
            y_all.append(yn)
            code.append(np.full(len(yn), k))
        y = torch.as_tensor(np.concatenate(y_all))
        py = torch.as_tensor(np.concatenate(phi_y))
        tgt = y
        if self.delta:  # only the Δ form needs y(k − 1): MATLAB's form takes any delays
            m = y.shape[1]
            tgt = (y - py[:, self._last_delay_slot() * m :][:, :m]) / self.net_.d_scale
        return {
            "phi": torch.cat([py, torch.as_tensor(np.concatenate(phi_u))], 1),
            "target": tgt,
            "y": y,
            "code": torch.as_tensor(np.concatenate(code)),
        }

    def _last_delay_slot(self) -> int:
        if 1 not in self.output_delays_:
            raise NnidInputError("delta=True needs output delay 1", field="output_delays")
        return self.output_delays_.index(1)

    def _labels(self, log: pd.DataFrame, rows: np.ndarray | None = None) -> np.ndarray:
        """Transient labels from the outputs (the rule of nnid.datasets.segmentation), its
        manoeuvre scales and noise levels from the training ``rows`` (all by default)."""
        tmp = pd.DataFrame(
            {VELOCITY[i]: log[c].to_numpy(np.float64) for i, c in enumerate(self.outputs_[:6])}
        )
        tmp["t"] = log["t"].to_numpy(np.float64) if "t" in log else np.arange(len(log), dtype=float)
        if "experiment" in log:
            tmp["experiment"] = log["experiment"].to_numpy()
        if PIECE_OF in log:  # a piece cut at a gap, shorter than the window, is labelled steady
            tmp[PIECE_OF] = log[PIECE_OF].to_numpy()
        return label_transients(tmp, rows=rows).to_numpy()

    # -- torch pieces ----------------------------------------------------------------------------
    def _weights(self) -> dict[str, torch.Tensor]:
        return dict(self.net_.named_parameters())

    def _rollout(
        self, params: dict[str, torch.Tensor], hist: torch.Tensor, uf: torch.Tensor
    ) -> torch.Tensor:
        """Closed loop over T steps: ``hist`` [B, dy, m] measured delay states (oldest first),
        ``uf`` [B, T, F_u] input features; returns normalised outputs [B, T, m]."""
        keys = [f"mlp.{i}" for i, mod in enumerate(self.net_.mlp) if isinstance(mod, nn.Linear)]
        ws = [(params[k + ".weight"], params[k + ".bias"]) for k in keys]
        m, n_y = hist.shape[2], self._n_y_features()
        w1, b1 = ws[0]
        n_d = len(self.output_delays_)
        n_s = self._n_s()
        w1y = [w1[:, j * m : (j + 1) * m].T for j in range(n_d)]
        w1s = [w1[:, n_d * m + j * n_s : n_d * m + (j + 1) * n_s].T for j in range(n_d)]
        transform = self._transform_t if self.output_transform else None
        zu = uf @ w1[:, n_y:].T + b1  # the inputs' share of the first layer, all steps at once
        scale = self.net_.d_scale if self.delta else torch.ones_like(self.net_.d_scale)
        wo, bo = ws[-1][0].T * scale, ws[-1][1] * scale
        if self.rest_equilibrium:  # o = W_o (h − h_rest): the output bias cancels
            bo = -self._rest_hidden(ws) @ wo
        lo, hi = self._norm_bounds() or (None, None)
        hs = list(hist.unbind(1))
        ss = [transform(x) for x in hs] if transform is not None else []  # once per sample
        outs = []
        for t in range(uf.shape[1]):
            a = zu[:, t]
            for j, d in enumerate(self.output_delays_):
                a = a + hs[-d] @ w1y[j]
                if transform is not None:
                    a = a + ss[-d] @ w1s[j]
            h = torch.tanh(a)
            for w, b in ws[1:-1]:
                h = torch.tanh(h @ w.T + b)
            o = h @ wo + bo
            y = hs[-1] + o if self.delta else o
            if lo is not None:
                y = torch.clamp(y, lo, hi)
            hs.append(y)
            if transform is not None:
                ss.append(transform(y))
            outs.append(y)
        return torch.stack(outs, 1)

    def _simulate(
        self, params: dict[str, torch.Tensor], hist: torch.Tensor, uf: torch.Tensor
    ) -> torch.Tensor:
        """:meth:`_rollout`; where no gradient is being recorded (predictions, the LM steps'
        trial errors, validation, the states of the sensitivity recursion), through the
        compiled kernel (:mod:`nnid.models.narx_kernel`; the same numbers to rounding)."""
        if torch.is_grad_enabled():
            return self._rollout(params, hist, uf)
        return torch.as_tensor(self._compiled_rollout(params, hist.numpy(), uf.numpy()))

    def _compiled_rollout(
        self, params: dict[str, torch.Tensor], hist: np.ndarray, uf: np.ndarray
    ) -> np.ndarray:
        """:meth:`_rollout` at ``params`` through :func:`nnid.models.narx_kernel.free_run`."""
        keys = [f"mlp.{i}" for i, mod in enumerate(self.net_.mlp) if isinstance(mod, nn.Linear)]
        ws = [
            (params[k + ".weight"].detach().numpy(), params[k + ".bias"].detach().numpy())
            for k in keys
        ]
        w1, b1 = ws[0]
        m, dy = len(self.outputs_), self.dy_
        n_y, n_d, n_s = self._n_y_features(), len(self.output_delays_), self._n_s()
        dense = np.zeros((w1.shape[0], dy * m))
        dense_s = np.zeros((w1.shape[0], dy * n_s)) if self.output_transform else None
        for j, d in enumerate(self.output_delays_):  # slot dy − d holds y(k − d)
            dense[:, (dy - d) * m : (dy - d + 1) * m] = w1[:, j * m : (j + 1) * m]
            if dense_s is not None:
                dense_s[:, (dy - d) * n_s : (dy - d + 1) * n_s] = w1[
                    :, n_d * m + j * n_s : n_d * m + (j + 1) * n_s
                ]
        net = self.net_
        scale = net.d_scale.numpy() if self.delta else np.ones(m)
        wo, bo = ws[-1][0] * scale[:, None], ws[-1][1] * scale
        rest = None
        if self.rest_equilibrium:  # o = W_o (h − h_rest): the output bias cancels
            phi_rest = net.phi_rest.numpy()
            rest, bo = (phi_rest[:m], phi_rest[n_y:]), np.zeros(m)
        none = np.zeros(0)
        scales = (
            net.y_std.numpy(),
            net.y_mean.numpy(),
            net.s_mean.numpy() if n_s else none,
            net.s_std.numpy() if n_s else none,
        )
        first = (w1[:, n_y:], b1, dense, dense_s)
        return narx_kernel.free_run(
            hist, uf, first, self.output_transform, scales, [*ws[1:-1], (wo, bo)], self.delta,
            self._norm_bounds_np(), rest,
        )  # fmt: skip

    def _windows(self, table: dict[str, torch.Tensor], ends: torch.Tensor, length: int):
        """Rows, delay-state history and input features of windows ending at ``ends``."""
        rows = ends[:, None] - length + 1 + torch.arange(length)
        starts = rows[:, 0]
        hist = table["y"][starts[:, None] - self.dy_ + torch.arange(self.dy_)]
        return rows, hist, table["phi"][rows][:, :, self._n_y_features() :]

    # -- training --------------------------------------------------------------------------------
    def _fit(
        self, log: pd.DataFrame, validation_log: pd.DataFrame | None, progress: Progress
    ) -> None:
        """Normalise, train one-step (or ``multi_step``) on the training data, early-stop on
        the validation data, then optionally fine-tune on simulation error."""
        from nnid.trainers.adam import Adam
        from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

        self._configure()
        self.sample_interval_ = self._check(log)  # every later log is checked against it
        if validation_log is None and self.division == "random" and self.simulation_epochs > 0:
            # its windows are cut over every row of each run: it would train in free run on
            # the rows held out to stop it (and on the test rows)
            raise NnidInputError(
                "division='random' holds out rows scattered through each run, and the "
                "free-run stage (simulation_epochs > 0) trains on windows of whole runs, "
                "those rows too: give a validation log, use division='block', or set "
                "simulation_epochs=0",
                field="division",
            )
        longest = max(len(pos) for _, pos in experiment_rows(log))
        if longest <= self.warmup_samples_:  # no sample has all its delayed regressors
            raise NnidInputError(
                f"the longest training run has {longest} samples, no more than the deepest "
                f"delay ({self.warmup_samples_}): no sample has every delayed regressor",
                field=self._deepest(),
            )
        self.net_ = self._new_net(self._generator())
        random_rows = None
        if validation_log is None and self.division == "block":
            split = split_log(log, "block", self.fractions)
            log, validation_log = split.train, split.validation
            self.division_ = split.record
        elif validation_log is None:
            warnings.warn(
                "random division puts neighbouring, strongly correlated samples in training and "
                "validation: the validation error is optimistic",
                stacklevel=2,
            )
            self.division_ = {"by": "random", "fractions": list(self.fractions)}
            random_rows = np.random.default_rng(self.seed).random(len(log))
        else:
            self._check(validation_log, "validation log")
            self.division_ = {"by": "given"}
        # statistics of the training rows alone: a random division's validation rows are in log
        fit_rows = None if random_rows is None else random_rows < self.fractions[0]
        self._fit_normalisation(log, fit_rows)
        trained = log if fit_rows is None else log[fit_rows]
        self.bounds_ = resolve_bounds(self.output_bounds_, self.outputs_, trained)
        tab = self._table(log)
        # the table's rows are the log's grouped by experiment (experiment_rows): labels and
        # masks of log rows are taken in that order (a run resumed after another, A B A,
        # put one sample's label on another)
        order = np.concatenate([pos for _, pos in experiment_rows(log)])
        horizon = int(self.multi_step)
        sampler = BalancedSampler(
            self._labels(log, fit_rows)[order],
            tab["code"].numpy(),
            window=self.warmup_samples_ + horizon,
            balance=self.balanced,
            seed=self.seed,
        )
        if fit_rows is not None:
            val_rows = sampler.eligible & ~fit_rows[order]
            sampler.eligible &= fit_rows[order]
            vtab, v_idx = tab, np.flatnonzero(val_rows)
        else:
            vtab = self._table(validation_log)
            v_idx = np.flatnonzero(self._eligible(vtab["code"].numpy(), horizon))
            if len(validation_log) and not v_idx.size:
                warnings.warn(
                    f"no validation run is longer than the deepest delay and horizon "
                    f"({self.warmup_samples_ + horizon} samples): the NARX trains without "
                    "early stopping, on its training error alone",
                    stacklevel=2,
                )
        if not sampler.eligible.any():  # the draw's weights were 0/0: numpy's "contain NaN"
            self._refuse_no_sample(tab, horizon, self.division_["by"])
        self.transient_share_ = sampler.transient_share(sampler.sample(20000))
        n_eligible = int(sampler.eligible.sum())
        trainer = clone(self.trainer, safe=False) if self.trainer is not None else Adam()
        self.trainer_ = trainer
        residual = self._one_step_residual if horizon == 1 else self._window_residual
        v_batches = [
            self._batch(vtab, torch.as_tensor(c), horizon)
            for c in np.array_split(v_idx, max(1, len(v_idx) // 4096))
            if len(c)
        ]
        if isinstance(trainer, LevenbergMarquardt):  # full batch: one fixed balanced draw
            n = min(n_eligible, max(1, self.lm_samples // horizon))
            train_b: Any = [self._batch(tab, torch.as_tensor(sampler.sample(n, 0)), horizon)]
        else:
            draw = self._epoch_batches(sampler, n_eligible, horizon)

            def train_b(epoch: int) -> list:
                return [self._batch(tab, idx, horizon) for idx in draw(epoch)]

        stage, measure = ("one-step", "one_step") if horizon == 1 else (f"{horizon}-step", "k_step")
        # every sample (or window) of a batch is its own residual block: LM's "samples" mode
        extra = {"separable": True} if isinstance(trainer, LevenbergMarquardt) else {}
        report = staged(progress, stage, f"{measure}_nrmse")
        self.history_ = trainer.fit(self.net_, residual, train_b, v_batches, report, **extra)
        self.finetune_ = None
        if self.simulation_epochs > 0:
            held_out = validation_log if random_rows is None else None
            self._simulation_finetune(
                tab, held_out, staged(progress, "simulation", "free_run_nrmse")
            )

    def _refuse_no_sample(self, tab: dict[str, torch.Tensor], horizon: int, division: str) -> None:
        """The error of a training log with no sample to train on: every run (its training
        block, after a block division) no longer than the delay states and the horizon."""
        starts, stops = run_bounds(tab["code"].numpy())
        lengths = sorted({int(n) for n in stops - starts}, reverse=True)
        shown = ", ".join(map(str, lengths[:5])) + (", …" if len(lengths) > 5 else "")
        need = self.warmup_samples_ + horizon
        what = f"the {horizon}-step horizon" if horizon > 1 else "the predicted sample"
        where = {
            "block": " (each run's training block: the block division holds out the rest)",
            "random": ", and none of their samples that have them is a training row of the "
            "random division",
        }.get(division, "")
        raise NnidInputError(
            f"no training sample has its {self.warmup_samples_} delay states and {what} in one "
            f"run ({need} samples): the training runs have {shown} samples{where}",
            field="multi_step" if horizon > 1 else self._deepest(),
        )

    def _deepest(self) -> str:
        """The delay setting that sets the delay states (``warmup_samples_``)."""
        return "input_delays" if max(self.input_delays_) >= self.dy_ else "output_delays"

    def trainer_name(self) -> str | None:
        """As :meth:`NnidModel.trainer_name`, and the free-run stage's trainer where it is
        another (``"lm (free run: adam)"``): the one-step trainer's name alone said "lm" of a
        net whose free-run stage Adam trained."""
        first = super().trainer_name()
        if getattr(self, "trainer_", None) is None and getattr(self, "fitted_by_", None):
            return first  # as saved: both stages' already
        stage = self.simulation_trainer if self.simulation_epochs > 0 else None
        if first is None or stage is None or stage == first:
            return first
        return f"{first} (free run: {stage})"

    def _validation_used(self, validation: pd.DataFrame | None) -> str | None:
        """Early stopping where a given validation log was scored by a stage (one-step or
        free run); not where it was too short for any (the fit warned), nor where the fit
        held out part of its training log itself (``division_``)."""
        stages = [self.history_, *((self.finetune_ or {}).get("stages") or [])]
        given = validation is not None and self.division_.get("by") == "given"
        return self.validation_role if given and scored_validation(stages) else None

    def _batch(self, table: dict[str, torch.Tensor], idx: torch.Tensor, horizon: int) -> tuple:
        """Tensors of a batch, sample-major: (φ, target) one-step, or windows ending at
        ``idx``: (delay states, input features, measured outputs)."""
        if horizon == 1:
            return table["phi"][idx], table["target"][idx]
        rows, hist, uf = self._windows(table, idx, horizon)
        return hist, uf, table["y"][rows]

    def _one_step_residual(self, params: dict[str, torch.Tensor], batch: tuple) -> torch.Tensor:
        phi, target = batch
        return (functional_call(self.net_, params, (phi,)) - target).reshape(-1)

    def _window_residual(self, params: dict[str, torch.Tensor], batch: tuple) -> torch.Tensor:
        """Free-run error of a batch of windows; a validation run's batch also carries each
        output's weight (:meth:`_whole_runs`), and so do the training windows with
        ``simulation_run_floor`` (:meth:`_fixed_windows`)."""
        hist, uf, y, *weight = batch
        err = self._simulate(params, hist, uf) - y
        return (err * weight[0] if weight else err).reshape(-1)

    def _local_jacobians(
        self,
        params: dict[str, torch.Tensor],
        states: torch.Tensor,
        uf: torch.Tensor,
        out: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Jacobians of one closed-loop step for a batch of N steps: delay states ``states``
        [N, dy, m] (oldest first), input features ``uf`` [N, F_u] → (∂y/∂θ [N, m, P],
        ∂y/∂states [N, m, dy, m]) of the next normalised output (Δ form, output transform, rest
        equilibrium and clamp included), written out for the tanh MLP: batched matrix products
        where ``vmap(jacrev(...))`` over the steps costs several times more. ∂y/∂θ is written
        into ``out`` (any tensor of N · m · P elements viewed as [..., m, P], e.g. a strided
        slice of the caller's buffer) when given, the largest array here, without a copy."""
        keys = [f"mlp.{i}" for i, mod in enumerate(self.net_.mlp) if isinstance(mod, nn.Linear)]
        ws = [(params[k + ".weight"], params[k + ".bias"]) for k in keys]
        n, dy, m = states.shape
        lags = [states[:, dy - d] for d in self.output_delays_]
        blocks = lags + ([self._transform_t(x) for x in lags] if self.output_transform else [])
        acts = [torch.cat([*blocks, uf], 1)]
        rest = self.rest_equilibrium
        if rest:  # one more row, the regressor at rest, whose output every step subtracts
            acts[0] = torch.cat([acts[0], self.net_.phi_rest[None]])
        rows = len(acts[0])
        for w, b in ws[:-1]:
            acts.append(torch.tanh(acts[-1] @ w.T + b))
        scale = self.net_.d_scale if self.delta else torch.ones_like(self.net_.d_scale)
        w_out, b_out = ws[-1]
        y = acts[-1] @ (w_out.T * scale) + b_out * scale
        if rest:
            y = y[:n] - y[n]
        if self.delta:
            y = y + states[:, -1]
        # back-propagate the m outputs at once: g = ∂o/∂(pre-activation of the layer)
        g = torch.diag_embed(scale.expand(rows, m))
        p = sum(w.numel() + b.numel() for w, b in ws)
        d_theta = torch.empty(n, m, p, dtype=states.dtype) if out is None else out
        end = p  # columns layer by layer, each its weight then its bias: filled from the end
        for i in range(len(ws) - 1, -1, -1):
            w, a_in = ws[i][0], acts[i]
            for block in (g, (g[..., None] * a_in[:, None, None, :]).reshape(rows, m, -1)):
                if rest:
                    block = block[:n] - block[n]
                cols = d_theta[..., end - block.shape[-1] : end]
                cols.copy_(block.reshape(cols.shape))
                end -= block.shape[-1]
            g_in = g @ w
            if i > 0:
                g = g_in * (1 - a_in**2)[:, None, :]
        if rest:
            g_in = g_in[:n]
        d_hist = torch.zeros(n, m, dy, m, dtype=states.dtype)
        n_d, n_s = len(self.output_delays_), self._n_s()
        for j, d in enumerate(self.output_delays_):
            d_hist[:, :, dy - d] += g_in[:, :, j * m : (j + 1) * m]
            if self.output_transform:  # through the transformed regressors of this lag
                g_s = g_in[:, :, n_d * m + j * n_s : n_d * m + (j + 1) * n_s]
                d_hist[:, :, dy - d] += g_s @ self._transform_jacobian(lags[j])
        if self.delta:
            d_hist[:, :, dy - 1] += torch.eye(m, dtype=states.dtype)
        bounds = self._norm_bounds()
        if bounds is not None:  # a clamped output does not move with θ or the states
            free = ((y >= bounds[0]) & (y <= bounds[1])).to(states.dtype)
            d_theta.mul_(free.reshape(*d_theta.shape[:-1], 1))
            d_hist = d_hist * free[:, :, None, None]
        return d_theta, d_hist

    def _simulation_rows(
        self,
        params: dict[str, torch.Tensor],
        batch: tuple,
        budget: int,
        peak: list[int] | None = None,
    ) -> Iterator[tuple[torch.Tensor, torch.Tensor]]:
        """Rows of the Jacobian of the window residual (``_window_residual``) by the sensitivity
        recursion of the closed loop, with their residuals, in blocks of ≤ ``budget`` elements.

        With y(k) = f(θ, y(k − dy) … y(k − 1), u-features(k)) and S(k) = ∂y(k)/∂θ,

            S(k) = ∂f/∂θ(k) + Σ_j ∂f/∂y(k − j)(k) · S(k − j),   S = 0 on the measured states,

        so the local Jacobians of every step (taken along the simulated trajectory) come from
        one batched pass (:meth:`_local_jacobians`), and only the linear recursion runs step
        by step: about the cost of one-step training, where forward mode repeats the closed
        loop once per parameter. A block may be a view of a buffer the next block overwrites:
        use it before drawing the next.

        ``budget`` bounds the rows of a block, not the buffer they grow in, which also carries
        the dy previous steps' S: nb·(dy + span)·m·P elements, up to (dy + 1)× ``budget``
        where one step fills it. The largest buffer's elements go into ``peak[0]`` when given
        (LM records the blocks'). Sizing the buffer to the budget instead would cut the rows
        into other blocks, and JᵀJ summed over other blocks rounds otherwise: another fit.
        """
        hist, uf, y, *weight = batch
        b_all, t_all, m = y.shape
        dy = hist.shape[1]
        p = sum(v.numel() for v in params.values())
        with torch.no_grad():
            sim = self._simulate(params, hist, uf)
        group = max(1, min(b_all, budget // (m * p)))  # windows at a time
        for b0 in range(0, b_all, group):
            sl = slice(b0, b0 + group)
            z = torch.cat([hist[sl], sim[sl]], 1)  # [B, dy + T, m]
            states = z.unfold(1, dy, 1).transpose(2, 3)  # [B, T + 1, dy, m], oldest first
            nb = z.shape[0]
            # steps at a time; never past the window: the buffer was the whole budget however
            # short the windows (the blocks are the same)
            span = max(1, min(t_all, budget // (nb * m * p)))
            # [B, dy + span, m, P]: the carried S (zero on the measured states), then the
            # block's ∂f/∂θ, written in place and growing into S; one buffer for every block
            sens = torch.zeros(nb, dy + span, m, p, dtype=y.dtype)
            if peak is not None:
                peak[0] = max(peak[0], sens.numel())
            for t0 in range(0, t_all, span):
                t1 = min(t_all, t0 + span)
                k = t1 - t0
                block = sens[:, : dy + k]
                _, d_hist = self._local_jacobians(
                    params,
                    states[:, t0:t1].reshape(-1, dy, m),
                    uf[sl, t0:t1].reshape(nb * k, -1),
                    out=block[:, dy:],
                )
                d_hist = d_hist.reshape(nb, k, m, dy, m)
                for t in range(k):
                    block[:, dy + t] += torch.einsum(
                        "bidj,bdjp->bip", d_hist[:, t], block[:, t : t + dy]
                    )
                rows, err = block[:, dy:], sim[sl, t0:t1] - y[sl, t0:t1]
                if weight:  # the residual's weights (:meth:`_fixed_windows`), [B, 1, m]
                    rows, err = rows * weight[0][sl, :, :, None], err * weight[0][sl]
                yield rows.reshape(-1, p), err.reshape(-1)
                sens[:, :dy] = block[:, k:].clone()  # the next block's carry

    def _eligible(self, code: np.ndarray, horizon: int) -> np.ndarray:
        keep = np.ones(code.size, dtype=bool)
        for s in run_bounds(code)[0]:
            keep[s : s + self.warmup_samples_ + horizon - 1] = False
        return keep

    def _epoch_batches(self, sampler: BalancedSampler, n_eligible: int, horizon: int):
        per_epoch = self.samples_per_epoch or n_eligible
        per_epoch = max(1, per_epoch // horizon)
        bs = max(1, self.batch_size // horizon) if horizon > 1 else self.batch_size

        def batches(epoch: int) -> list[torch.Tensor]:
            idx = torch.as_tensor(sampler.sample(per_epoch, epoch))
            return list(idx.split(bs))

        return batches

    def _simulation_finetune(self, tab, validation_log, progress: Progress) -> None:
        """Output-error training on free runs over windows of ``simulation_window`` samples
        (each length in turn) from measured delay states: Adam (back-propagation through the
        closed loop) or, with ``simulation_trainer="lm"``, Levenberg-Marquardt, on the same
        fixed windows; kept only if the measure each stage early-stopped on falls."""
        held_out = validation_log is not None
        val = self._whole_runs(self._table(validation_log), validation_log) if held_out else None
        before = self.free_run_error(validation_log) if held_out else None
        measure_before = self._mean_square(val) if val else None
        state = {k: v.clone() for k, v in self.net_.state_dict().items()}
        train = self._simulation_adam
        if self.simulation_trainer == "lm":
            # every stage's penalty pulls toward the same point: the one-step fit, not the
            # previous stage's result
            center = (
                parameters_to_vector(self.net_.parameters()).detach()
                if self.simulation_l2_center == "one_step"
                else None
            )
            train = functools.partial(self._simulation_lm, center=center)
        several = len(self.simulation_windows_) > 1
        stages = []
        for length in self.simulation_windows_:  # short windows first: a smoother objective
            report = staged(progress, f"{length} samples") if several else progress
            hist = train(tab, val, report, length)
            if hist is not None:
                # the window length trained, as cut to the shortest run (not the one asked for)
                window = self._window_length(tab, length)
                stages.append(jsonable({"window": window, **hist.as_dict()}))
        if not stages:
            return
        after = self.free_run_error(validation_log) if held_out else None
        measure_after = self._mean_square(val) if val else None
        # judged on the measure each stage early-stopped on, not on the pooled NRMSE
        kept = measure_before is None or measure_after < measure_before
        if not kept:
            self.net_.load_state_dict(state)
        # a diverged free run has no NRMSE: said as such, not as a missing (null) score; nor
        # has a validation log that excites no output, which is not a divergence
        self.finetune_ = {
            "validation_free_run_nrmse_before": jsonable(before),
            "validation_free_run_nrmse_after": jsonable(after),
            "validation_free_run_diverged_before": bool(before is not None and np.isinf(before)),
            "validation_free_run_diverged_after": bool(after is not None and np.isinf(after)),
            "validation_free_run_no_output_scored": bool(held_out and before is None),
            "validation_mean_squared_nrmse_before": jsonable(measure_before),
            "validation_mean_squared_nrmse_after": jsonable(measure_after),
            "kept": bool(kept),
            "epochs": sum(s["epochs"] for s in stages),
            # one History record per window length, as the state-space model's and the
            # hybrid's ``stages``: why each ended (the trainer's words: "validation",
            # "max_epochs", "mu_max", ...; a stall is not read as a convergence), the epoch it
            # kept, and its per-epoch errors
            "stages": stages,
        }

    def _window_length(self, table: dict[str, torch.Tensor], length: int) -> int | None:
        """``length`` cut to the shortest experiment of ``table`` after its warm-up (a window
        longer than every run means "whole runs"); None when no experiment is longer than
        the warm-up."""
        starts, stops = run_bounds(table["code"].numpy())
        spans = stops - starts - self.warmup_samples_
        if spans.max() < 1:
            return None
        return int(min(length, spans[spans >= 1].min()))

    def _fixed_windows(self, table: dict[str, torch.Tensor], length: int) -> tuple | None:
        """Windows of ``length`` samples (shortened to the shortest experiment after its
        warm-up) ending at the last sample of each experiment and every ``length // 2``
        samples before it, and one starting right after the experiment's delay states (so
        every sample of a run is in a window), as one batch; None when no experiment is longer
        than the warm-up. With ``simulation_run_floor`` the batch also carries each window's
        output weights [B, 1, m]: 1 / its run's std of each output (normalised units), floored."""
        length = self._window_length(table, length)
        if length is None:
            return None
        starts, stops = run_bounds(table["code"].numpy())
        ends: list[int] = []
        weights: list[torch.Tensor] = []
        floor = self.simulation_run_floor
        for s, e in zip(starts, stops, strict=True):
            first = (
                s + self.warmup_samples_ + length - 1
            )  # the earliest end whose delay states exist
            run_ends = list(range(e - 1, first - 1, -max(1, length // 2)))[::-1]
            if run_ends and run_ends[0] > first:
                # the half-window grid laid from the run's end leaves up to half a window
                # after the delay states in no window: the transient from rest (Weiss V.B)
                run_ends.insert(0, first)
            ends += run_ends
            if floor is not None:  # the run's std in training stds, floored: noise-only outputs
                std = table["y"][s:e].std(0, correction=0).clamp_min(float(floor))
                weights.append((1.0 / std).expand(len(run_ends), 1, -1))
        batch = self._batch(table, torch.as_tensor(ends), length)
        return (*batch, torch.cat(weights)) if floor is not None else batch

    def _whole_runs(self, table: dict[str, torch.Tensor], log: pd.DataFrame) -> list[tuple] | None:
        """One batch per experiment of ``log`` (``table``: its tensors): its free run from the
        measured delay states to its end, and each output's weight, 1 / the output's std over
        the run after its delay states where the run excites it (:func:`target_columns`),
        else 0. The mean square of the weighted error (:meth:`_mean_square`) is then
        Σ_runs T_r Σ_scored NRMSE²_r,o / (m Σ_runs T_r), T_r a run's samples after its delay
        states and m the outputs: each run's squared free-run NRMSE (its error and its std
        after the delay states, ``warmup_samples_``) summed over the outputs it excites,
        averaged over runs by length and divided by every output, an output a run does not
        excite counting 0. It scales each run as ``free_run_nrmse_per_experiment`` does, but
        is not that score (whose warm-up is ``warmup_s``, whose mean is over the scored
        outputs). One measure for early stopping and for keeping the stages: its denominator
        is fixed by the validation log, so it ranks epochs as a mean over scored outputs would
        (to rounding).
        Weighted by the training std instead, a run that barely moves an output (the yaw the
        Munk moment alone drives) barely counts."""
        starts, stops = run_bounds(table["code"].numpy())
        runs = []
        for (_, pos), s, e in zip(experiment_rows(log), starts, stops, strict=True):
            if e - s <= self.warmup_samples_:
                continue
            hist, uf, y = self._batch(
                table, torch.as_tensor([e - 1]), int(e - s - self.warmup_samples_)
            )
            excited = set(target_columns(self, log.iloc[pos]))
            scored = torch.tensor([c in excited for c in self.outputs_])
            std = y[0].std(0, correction=0)
            weight = torch.where(scored & (std > 0), 1.0 / std.clamp_min(1e-300), 0.0)
            runs.append((hist, uf, y, weight))
        return runs or None

    def _mean_square(self, runs: list[tuple]) -> float:
        """Mean square of the weighted free-run error over ``runs`` (:meth:`_whole_runs`;
        every element, zero-weighted outputs included), as the trainers' early stopping
        computes it; infinite when not finite."""
        with torch.no_grad():
            r = torch.cat([self._window_residual(self._weights(), b) for b in runs])
        return stopping_score(float(r @ r) / max(r.numel(), 1))

    def _epoch_order(self, n: int, epoch: int) -> torch.Tensor:
        """A permutation of ``n`` windows for ``epoch``, drawn from ``seed`` (local generator)."""
        gen = torch.Generator().manual_seed(int(self.seed) * 100_003 + epoch)
        return torch.randperm(n, generator=gen)

    def simulation_objective(
        self, log: pd.DataFrame, window: int, validation: pd.DataFrame | None = None
    ) -> SimulationObjective:
        """The simulation-error objective the free-run stages train (:class:`SimulationObjective`)
        on ``log``'s windows of ``window`` samples (cut to its shortest experiment after the
        warm-up; ending at each experiment's last sample and every half window before it),
        early-stopped on ``validation``'s whole free runs; at the fitted network's
        normalisation. Raises when no experiment of ``log`` is longer than the warm-up."""
        check_is_fitted(self, msg=NOT_FITTED)
        # a whole number of samples, never truncated: 2.5 would silently train 2-sample windows
        if isinstance(window, bool) or not isinstance(window, numbers.Integral) or window < 2:
            raise NnidInputError(
                f"window is a whole number of samples ≥ 2, got {window!r}", field="window"
            )
        self._check(log)
        val = None
        if validation is not None:
            self._check(validation)
            val = self._whole_runs(self._table(validation), validation)
        obj = self._objective(self._table(log), val, int(window))
        if obj is None:
            raise NnidInputError(
                f"no experiment is longer than the warm-up ({self.warmup_samples_} samples)",
                field="window",
            )
        return obj

    def _objective(self, tab, val: list[tuple] | None, length: int) -> SimulationObjective | None:
        windows = self._fixed_windows(tab, length)
        if windows is None:
            return None
        return SimulationObjective(
            self.net_, windows, self._window_residual, self._simulation_rows, val,
            self._epoch_order,
        )  # fmt: skip

    def _simulation_lm(
        self, tab, val, progress: Progress, length: int, center: torch.Tensor | None = None
    ) -> History | None:
        from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

        obj = self._objective(tab, val, length)
        if obj is None:
            return None
        # an LM trainer's memory budget and damping reach this stage too (its sensitivity
        # buffer was the default's 256 MiB blocks whatever the trainer said); an Adam's: LM's
        # defaults
        steps: dict[str, Any] = {}
        if isinstance(self.trainer_, LevenbergMarquardt):
            steps = {k: getattr(self.trainer_, k) for k in LM_STEP_SETTINGS}
        trainer = LevenbergMarquardt(
            **steps,
            max_epochs=int(self.simulation_epochs),
            max_fail=int(self.simulation_max_fail),
            l2=float(self.simulation_l2),
            l2_center=center,
        )
        train = obj.windows
        n = train[0].shape[0]
        share = float(self.simulation_curvature)

        def curvature(epoch: int) -> list:
            idx = obj.order(n, epoch)[: max(1, round(share * n))]
            return [tuple(x[idx] for x in train)]

        peak = [0]
        hist = trainer.fit(
            obj.module,
            obj.residual,
            [train],
            obj.validation,
            progress=progress,
            jacobian_rows=functools.partial(obj.jacobian_rows, peak=peak),
            curvature_batches=curvature if share < 1.0 else None,
        )
        # the memory the recursion held: its buffer carries dy steps beside the rows LM was
        # handed (LM's peak_jacobian_elements)
        hist.info["peak_sensitivity_elements"] = peak[0]
        return hist

    def _simulation_adam(self, tab, val, progress: Progress, length: int) -> History | None:
        """Adam on the windows of the LM stage (:meth:`_fixed_windows`): every window once an
        epoch, in an order drawn per epoch from ``seed``, 32 a step (back-propagation through
        the closed loop). On the Seamor net 128 balanced random windows an epoch never moved
        a good one-step start; a pass over every run does (benchmarks/RESULTS.md)."""
        from nnid.trainers.adam import Adam

        obj = self._objective(tab, val, length)
        if obj is None:
            return None
        n = obj.windows[0].shape[0]

        def batches(epoch: int) -> list:
            return [tuple(x[idx] for x in obj.windows) for idx in obj.order(n, epoch).split(32)]

        trainer = Adam(
            lr=self.simulation_lr,
            max_epochs=self.simulation_epochs,
            max_fail=self.simulation_max_fail,
        )
        return trainer.fit(obj.module, obj.residual, batches, obj.validation, progress=progress)

    # -- prediction ------------------------------------------------------------------------------
    def _predict(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        """Predicted outputs (columns ``outputs``, the log's index): ``"one_step"`` (measured
        delay states), ``"free_run"`` (closed loop from the measured warm-up of each
        experiment) or an int k (k steps closed loop from measured states k samples back).
        The warm-up rows of each experiment (and the first k − 1 after it) are NaN."""
        self._check(log)
        m = len(self.outputs_)
        out = np.full((len(log), m), np.nan)
        mean, std = self.net_.y_mean.numpy(), self.net_.y_std.numpy()
        with torch.no_grad():
            for pos, yn, un in self._segments(log):
                n = len(yn)
                if n <= self.warmup_samples_:
                    continue
                if mode == "one_step":
                    phi = np.concatenate([self._y_features(yn), self._u_features(un)], 1)
                    o = self.net_(torch.as_tensor(phi[self.warmup_samples_ :])).numpy()
                    pred = (
                        yn[self.warmup_samples_ - 1 : n - 1] + o * self.net_.d_scale.numpy()
                        if self.delta
                        else o
                    )
                    nb = self._norm_bounds_np()
                    if nb is not None:
                        pred = np.clip(pred, nb[0], nb[1])
                    out[pos[self.warmup_samples_ :]] = pred * std + mean
                elif mode == "free_run":
                    hist = yn[None, self.warmup_samples_ - self.dy_ : self.warmup_samples_]
                    uf = self._u_features(un)[None, self.warmup_samples_ :]
                    pred = self._compiled_rollout(self._weights(), hist, uf)[0]
                    out[pos[self.warmup_samples_ :]] = pred * std + mean
                else:
                    k = int(mode)
                    if k < 1:
                        raise NnidInputError("k-step prediction needs k ≥ 1", field="mode")
                    tab = {
                        "y": torch.as_tensor(yn),
                        "phi": torch.as_tensor(
                            np.concatenate([self._y_features(yn), self._u_features(un)], 1)
                        ),
                    }
                    ends = torch.arange(self.warmup_samples_ + k - 1, n)
                    if len(ends) == 0:
                        continue
                    _rows, hist, uf = self._windows(tab, ends, k)
                    pred = self._simulate(self._weights(), hist, uf)[:, -1].numpy()
                    out[pos[ends.numpy()]] = pred * std + mean
        return pd.DataFrame(out, index=log.index, columns=self.outputs_)
