"""Continuous-time neural state-space model: ẋ = f_θ(x, u), y = the first states.

The state-space counterpart of the NARX network (Weiss IV.A.2): where a NARX maps past outputs
and inputs to the next output, this model keeps a state x of ``len(outputs)`` measured states
(the outputs, normalised) and ``hidden_states`` unmeasured ones, and learns the vector field

    ẋ_i = W₂,ᵢ tanh(W₁,ᵢ [x, u]_{S_i} + b₁,ᵢ) + b₂,ᵢ        i = 1..n_x

with one tanh hidden layer per state derivative that sees only the variables its row S_i of
``structure`` allows (e.g. a cascade: the upper tank's level does not depend on the lower
one's). Time runs in samples (the log must be uniformly sampled within each experiment); the
input is held over each sample (zero-order hold) and the ODE is integrated by the shared RK4
(:func:`nnid.physics.integrate.rk4`), not torchdiffeq: its default trainer is
Levenberg-Marquardt, whose forward-mode Jacobians torchdiffeq's fixed-grid ``perturb`` cannot
pass through, and on this small vector field the own RK4 is also the faster
(``benchmarks/bench_hybrid.py speed``; :mod:`nnid.physics.odeint` says why). This is the
model class of the published 0.33 V neural continuous-time result on Cascaded Tanks
(Forgione & Piga 2021).

Training is simulation-error (output-error) only: the free run of each training window from its
initial state, which is estimated with the network (all states of every window are free
parameters, the measured ones starting at the measurement). The trainer is any object with
``fit(module, residual, train_batches, val_batches)``: Levenberg-Marquardt by default (forward-
mode Jacobians of the whole simulated window), or Adam. Early stopping uses held-out windows
whose initial states are free parameters fitted to their first ``warmup`` samples only (the
network held fixed in that residual), moved by the trainer's steps together with the weights
(Levenberg-Marquardt: one step an epoch) from where the previous stage left them; the samples
after the warm-up are the validation error. That is not prediction's estimate, which starts
again from the measurement (and ``hidden_init``) and runs ``state_epochs`` epochs with the
trained network, so the score an epoch is kept on can differ from the error ``predict`` then
makes on the same run. Training runs in stages of growing window length (``windows``; multiple
shooting with continuity links between neighbouring windows); early stopping applies to the
last stage, the earlier ones being the pre-training that makes the long simulation error
tractable. Prediction estimates each experiment's initial state from its warm-up
(:meth:`NeuralStateSpace.initial_state`), then runs free; the warm-up samples are never
scored.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
import torch
from sklearn.base import clone
from torch import nn
from torch.func import functional_call

from nnid.datasets.gaps import some_runs
from nnid.datasets.log import run_label
from nnid.datasets.preprocess import experiment_rows
from nnid.datasets.splits import split_log
from nnid.errors import NnidInputError, checked_number
from nnid.evaluation.prediction import mode_steps
from nnid.models.bounds import (
    OutputBounds,
    bound_arrays,
    check_bounds,
    resolve_bounds,
    restored_bounds,
)
from nnid.models.io_model import DTYPE, InputOutputModel
from nnid.physics.integrate import rk4
from nnid.threads import torch_threads
from nnid.trainers.history import Progress, scored_validation, staged
from nnid.validation import MAX_WIDTH, checked_names, disjoint_columns

#: derivatives are learned per sample and scaled down, so a small network starts slow
_RATE = 0.1


def _structure_mask(structure: Sequence[Sequence[Any]] | None, n_x: int, n_u: int) -> np.ndarray:
    """The n_x × (n_x + n_u) boolean mask: row i = what ẋ_i depends on (states, then inputs)."""
    if structure is None:
        return np.ones((n_x, n_x + n_u), dtype=bool)
    mask = np.asarray(structure, dtype=float)
    if mask.shape != (n_x, n_x + n_u) or not np.isin(mask, (0.0, 1.0)).all():
        raise NnidInputError(
            f"structure must be {n_x} rows (one per state derivative) of {n_x + n_u} zeros or "
            "ones (the states, measured first, then the inputs)",
            field="structure",
        )
    if not mask.any(axis=1).all():
        raise NnidInputError("every state derivative must depend on something", field="structure")
    return mask.astype(bool)


class StateSpaceNet(nn.Module):
    """The vector field f_θ (masked block network) and the normalisation buffers.

    ``forward(x0, u)`` integrates from ``x0`` [B, n_x] under normalised inputs ``u`` [N, B, n_u]
    and returns the states at the N sample times [N, B, n_x] (x(0) first).
    """

    def __init__(
        self,
        n_x: int,
        n_y: int,
        n_u: int,
        hidden: int,
        mask: np.ndarray,
        substeps: int = 1,
        generator: torch.Generator | None = None,
    ) -> None:
        super().__init__()
        gen = generator if generator is not None else torch.Generator()
        self.n_x, self.n_y, self.n_u, self.hidden, self.substeps = n_x, n_y, n_u, hidden, substeps
        n_h = n_x * hidden
        m1 = torch.as_tensor(np.repeat(mask, hidden, axis=0), dtype=DTYPE)
        m2 = torch.kron(torch.eye(n_x, dtype=DTYPE), torch.ones(1, hidden, dtype=DTYPE))
        self.register_buffer("mask1", m1)
        self.register_buffer("mask2", m2)
        fan_in = m1.sum(1).clamp(min=1.0)
        self.w1 = nn.Parameter(
            (torch.rand(n_h, n_x + n_u, dtype=DTYPE, generator=gen) * 2 - 1)
            / fan_in.sqrt()[:, None]
        )
        self.b1 = nn.Parameter(
            (torch.rand(n_h, dtype=DTYPE, generator=gen) * 2 - 1) / fan_in.sqrt()
        )
        # a small output layer: the initial model is nearly constant, so early free runs stay finite
        self.w2 = nn.Parameter(torch.randn(n_x, n_h, dtype=DTYPE, generator=gen) * 1e-2)
        self.b2 = nn.Parameter(torch.zeros(n_x, dtype=DTYPE))
        for name, n in (("u_mean", n_u), ("y_mean", n_y), ("hidden_init", n_x - n_y)):
            self.register_buffer(name, torch.zeros(n, dtype=DTYPE))
        for name, n in (("u_std", n_u), ("y_std", n_y)):
            self.register_buffer(name, torch.ones(n, dtype=DTYPE))

    def forward(self, x0: torch.Tensor, u: torch.Tensor) -> torch.Tensor:
        w1 = self.w1 * self.mask1
        w1x = w1[:, : self.n_x].T
        zu = u @ w1[:, self.n_x :].T + self.b1  # the inputs' share of the hidden layer, all steps
        w2 = (self.w2 * self.mask2).T * _RATE
        b2 = self.b2 * _RATE

        def f(x: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
            return torch.addmm(b2, torch.tanh(torch.addmm(z, x, w1x)), w2)

        return rk4(f, x0, zu, 1.0, self.substeps)[:-1]


@dataclass
class _Group:
    """Training windows of one length: inputs [L, B, n_u] and outputs [L, B, n_y]
    (normalised), and the rows of the initial-state parameter they start from (None: all)."""

    u: torch.Tensor
    y: torch.Tensor
    #: (window b, sample i, window b'): window b' starts at sample i of window b (in the group)
    links: torch.Tensor
    rows: slice | None


@dataclass
class _Windows:
    """Training windows, grouped by length (a run shorter than the window is one window of its
    own length), where each starts (experiment number, sample; in the order of the initial
    states) and the experiments' lengths."""

    groups: list[_Group]
    where: list[tuple[int, int]]
    lengths: list[int]

    @property
    def window_lengths(self) -> list[int]:
        """The lengths of the windows, in samples (one per group), shortest first."""
        return sorted(g.u.shape[0] for g in self.groups)

    def batches(self, kind: str) -> list[tuple]:
        """The groups as ``(kind, u, y, links, rows)`` batches of :meth:`_shooting_residual`."""
        return [(kind, g.u, g.y, g.links if kind == "fit" else None, g.rows) for g in self.groups]


class _Fit(nn.Module):
    """What a trainer sees: the network and the free initial states of the windows."""

    def __init__(self, net: StateSpaceNet, x0: torch.Tensor, x0_val: torch.Tensor | None) -> None:
        super().__init__()
        self.net = net
        self.x0 = nn.Parameter(x0)
        self.x0_val = nn.Parameter(x0_val) if x0_val is not None else None


class NeuralStateSpace(InputOutputModel):
    """Continuous-time neural state-space model, a scikit-learn estimator behind the model
    protocol. ``predict(log, mode)``: free run from the initial state estimated on each
    experiment's warm-up; one step or k steps ahead from the measured outputs at each start,
    the hidden states taken from that free run (an open-loop observer for what is not
    measured).

    Args:
        inputs, outputs: column names; the outputs are the first (measured) states.
        hidden_states: unmeasured states after the measured ones.
        hidden: tanh units per state derivative.
        structure: None (every derivative sees every state and input) or n_x rows of
            n_x + n_u zeros/ones (states, measured first, then inputs).
        substeps: RK4 steps per sample.
        warmup: samples at the start of each experiment used to estimate the initial state and
            never scored.
        windows: training stages, one window length in samples each (None: whole
            experiments, each at its own length; an experiment shorter than a window is one
            window of its own length, never a cut of the others); every window has its own
            free initial state, which a trainer's weight penalty (``l2``, ``weight_decay``)
            leaves alone. ``stages_`` records the lengths simulated. Each stage starts from
            the previous one's weights and simulated states: short windows first make the
            simulation error easier to minimise (multiple shooting), longer ones then fit the
            long-horizon behaviour.
        trainer: an object with ``fit(module, residual, train_batches, val_batches,
            progress=)`` (Levenberg-Marquardt and Adam are also told the free states,
            ``unpenalised=``); default ``LevenbergMarquardt(max_epochs=100)``.
        output_bounds: clamp of the predicted outputs (:mod:`nnid.models.bounds`).
        fractions: contiguous train/validation/test blocks when no ``validation_log`` is given
            (MATLAB's divideblock; the test block is left unused).
        state_epochs: Levenberg-Marquardt epochs of the initial-state estimate at prediction.
        continuity: weight of the multiple-shooting links (the state simulated to a window's
            last sample minus the next window's initial state, every state, normalised units)
            in the sum of squares; they tie the hidden states of neighbouring windows together.
        seed: seeds the initial weights.
    """

    kind = "state_space"
    counts_samples = "the state-space model"
    validation_role = "early stopping"

    def __init__(
        self,
        inputs: Sequence[str],
        outputs: Sequence[str],
        hidden_states: int = 1,
        hidden: int = 16,
        structure: Sequence[Sequence[Any]] | None = None,
        substeps: int = 1,
        warmup: int = 10,
        windows: Sequence[int | None] = (None,),
        trainer: Any = None,
        output_bounds: OutputBounds = None,
        fractions: Sequence[float] = (0.7, 0.15, 0.15),
        state_epochs: int = 50,
        continuity: float = 1.0,
        seed: int = 0,
    ) -> None:
        self.inputs = inputs
        self.outputs = outputs
        self.hidden_states = hidden_states
        self.hidden = hidden
        self.structure = structure
        self.substeps = substeps
        self.warmup = warmup
        self.windows = windows
        self.trainer = trainer
        self.output_bounds = output_bounds
        self.fractions = fractions
        self.state_epochs = state_epochs
        self.continuity = continuity
        self.seed = seed

    def _configure(self) -> None:
        """The settings in working form, checked (by ``fit`` and on load)."""
        self.inputs_ = checked_names(self.inputs, "inputs")
        self.outputs_ = checked_names(self.outputs, "outputs")
        if not self.outputs_:
            raise NnidInputError("a state-space model needs at least one output", field="outputs")
        disjoint_columns(self.inputs_, self.outputs_)  # an output read as an input: no model
        # capped as the config caps it (wider is a typo); int() made 1.5 one unit wide
        checked_number(self.hidden, "hidden", 1, strict=False, integer=True, maximum=MAX_WIDTH)
        # each named, and whole: 1.5 hidden states or a NaN warm-up passed the comparisons
        checked_number(self.hidden_states, "hidden_states", 0, strict=False, integer=True)
        checked_number(self.substeps, "substeps", 1, strict=False, integer=True)
        checked_number(self.warmup, "warmup", 1, strict=False, integer=True)
        given = self.windows
        many = not isinstance(given, str | bytes) and np.iterable(given)
        # whole lengths, as the config's: int() trained a 12.7-sample window 12 long
        windows = [
            None if w is None else checked_number(w, "windows", 1, strict=False, integer=True)
            for w in (given if many else [])
        ]
        if not windows or any(w is not None and w <= self.warmup for w in windows):
            raise NnidInputError(
                "windows: one or more lengths (None: whole experiments), each longer than warmup",
                field="windows",
            )
        self.windows_ = windows
        checked_number(self.state_epochs, "state_epochs", 1, strict=False, integer=True)
        # a NaN weight stopped Levenberg-Marquardt at its first epoch without a word, and a
        # negative one made the links' weight (continuity ** 0.5) complex
        checked_number(self.continuity, "continuity", strict=False)
        self.targets_ = list(self.outputs_)
        self.warmup_samples_ = int(self.warmup)
        self.n_x_ = len(self.outputs_) + int(self.hidden_states)
        self.mask_ = _structure_mask(self.structure, self.n_x_, len(self.inputs_))
        self.output_bounds_ = check_bounds(self.output_bounds, len(self.outputs_))

    def _new_net(self, generator: torch.Generator | None = None) -> StateSpaceNet:
        n_y, n_u = len(self.outputs_), len(self.inputs_)
        return StateSpaceNet(
            self.n_x_, n_y, n_u, int(self.hidden), self.mask_, int(self.substeps), generator
        )

    def _n_params(self) -> int:
        """Free network weights (the masked-out ones are not counted)."""
        net = self.net_
        return int(net.mask1.sum() + net.n_x * net.hidden + net.mask2.sum() + net.n_x)

    def _params(self) -> dict[str, dict[str, float | None]]:
        """A network has no physical parameters: its size; the weights are the tensors."""
        return {"n_params": {"value": float(self._n_params()), "stderr": None}}

    def describe(self) -> dict:
        return {
            **super().describe(),
            "inputs": self.inputs_,
            "states": self.n_x_,
            "hidden_states": int(self.hidden_states),
            "hidden_units_per_derivative": int(self.hidden),
            "structure": self.structure,
            **self._learned(),
        }

    def _learned(self) -> dict:
        return {
            "bounds": self.bounds_,
            "division": self.division_,
            "stages": self.stages_,
        }

    def _set_learned(self, state: dict) -> None:
        self.bounds_ = restored_bounds(state["bounds"], self.outputs_)
        self.division_ = state["division"]
        self.stages_ = state["stages"]

    # -- data ------------------------------------------------------------------------------------
    def _windows(
        self, log: pd.DataFrame, length: int | None, what: str = "training log"
    ) -> _Windows:
        """Windows of ``length`` samples (None: each experiment whole) starting at each
        experiment's start and every ``length − 1`` samples after (a window's last sample is
        the next one's first), the last one ending at the experiment's end (overlapping more if
        need be, so no sample is left out). An experiment shorter than ``length`` is one window
        of its own length; experiments no longer than the warm-up are left out (``what``: the
        log, in the error where none is longer)."""
        segs = [s for s in self._segments(log) if len(s[1]) > self.warmup_samples_]
        if not segs:
            raise NnidInputError(
                f"no run of the {what} is longer than the warm-up ({self.warmup_samples_} samples)",
                field="warmup",
            )
        # per experiment, its window length and starts; windows of one length are one group
        # (one batch, one simulation), in order of first appearance
        plan: dict[int, list[tuple[int, list[int]]]] = {}
        for j, (_, yn, _) in enumerate(segs):
            n = len(yn)
            size = n if length is None else min(length, n)
            starts = sorted({*range(0, n - size + 1, max(1, size - 1)), n - size})
            plan.setdefault(size, []).append((j, starts))
        groups, where = [], []
        for size, runs in plan.items():
            us, ys, links, first = [], [], [], len(where)
            for j, starts in runs:
                _, yn, un = segs[j]
                for k, s in enumerate(starts):
                    if k:  # the previous window must reach this start: multiple-shooting link
                        links.append(
                            (len(where) - first - 1, s - starts[k - 1], len(where) - first)
                        )
                    us.append(un[s : s + size])
                    ys.append(yn[s : s + size])
                    where.append((j, s))
            # one group takes every initial state as it is (no indexing: the same operations,
            # so the same Jacobian mode and numbers, as before runs of other lengths had groups)
            rows = None if len(plan) == 1 else slice(first, len(where))
            groups.append(
                _Group(
                    torch.as_tensor(np.stack(us, 1)),
                    torch.as_tensor(np.stack(ys, 1)),
                    torch.as_tensor(links).reshape(-1, 3),
                    rows,
                )
            )
        return _Windows(groups, where, [len(s[1]) for s in segs])

    def _runs_too_short(self, log: pd.DataFrame) -> list[str]:
        """The experiments of ``log`` no longer than the warm-up, each with its sample count."""
        w = self.warmup_samples_
        short = [(name, len(pos)) for name, pos in experiment_rows(log) if len(pos) <= w]
        return [f"{run_label(n)} ({k} sample{'s' * (k != 1)})" for n, k in short]

    def _initial_states(self, y: torch.Tensor) -> torch.Tensor:
        """Start of the estimate: the measured states at their first sample, the hidden ones
        at ``hidden_init`` (their mean over the simulated training record; 0 before a fit)."""
        hidden = self.net_.hidden_init.expand(y.shape[1], -1)
        return torch.cat([y[0], hidden], 1).clone()

    def _track(self, win: _Windows, x0: torch.Tensor) -> list[np.ndarray]:
        """Per experiment, the states simulated from the fitted initial states of its windows
        (a later window overwrites the overlap): where the next stage's windows start."""
        tracks = [np.zeros((n, self.n_x_)) for n in win.lengths]
        b = 0
        for g in win.groups:
            with torch.no_grad():
                states = self.net_(x0 if g.rows is None else x0[g.rows], g.u).numpy()
            for k in range(states.shape[1]):
                j, s = win.where[b]
                tracks[j][s : s + states.shape[0]] = states[:, k]
                b += 1
        return tracks

    def _starts(self, win: _Windows, tracks: list[np.ndarray] | None) -> torch.Tensor:
        if tracks is None:
            return torch.cat([self._initial_states(g.y) for g in win.groups])
        return torch.as_tensor(np.stack([tracks[j][s] for j, s in win.where]))

    # -- torch pieces ----------------------------------------------------------------------------
    def _outputs(self, states: torch.Tensor) -> torch.Tensor:
        y = states[..., : len(self.outputs_)]
        if self.bounds_ is None:
            return y
        lo, hi = bound_arrays(self.bounds_, self.net_.y_mean, self.net_.y_std)
        return torch.clamp(y, lo, hi)

    def _simulate(self, params: dict[str, torch.Tensor], x0: torch.Tensor, u: torch.Tensor):
        return self._outputs(functional_call(self.net_, params, (x0, u)))

    def _shooting_residual(self, params: dict[str, torch.Tensor], batch: tuple) -> torch.Tensor:
        """Training windows (``"fit"``: whole window), held-out windows' warm-ups with the
        network held fixed (``"state"``: their initial states only) and after it (``"val"``)."""
        kind, u, y, links, rows = batch
        net = {k[4:]: v for k, v in params.items() if k.startswith("net.")}
        x0 = params["x0" if kind == "fit" else "x0_val"]
        if rows is not None:  # this group's windows of several lengths
            x0 = x0[rows]
        if kind == "fit":
            states = functional_call(self.net_, net, (x0, u))
            fit = self._outputs(states) - y
            if not len(links) or self.continuity == 0:
                return fit.reshape(-1)
            gap = states[links[:, 1], links[:, 0]] - x0[links[:, 2]]
            return torch.cat([fit.reshape(-1), self.continuity**0.5 * gap.reshape(-1)])
        if kind == "state":
            fixed = {k: v.detach() for k, v in net.items()}
            w = self.warmup_samples_
            return (self._simulate(fixed, x0, u[:w]) - y[:w]).reshape(-1)
        return (self._simulate(net, x0, u) - y)[self.warmup_samples_ :].reshape(-1)

    # -- training --------------------------------------------------------------------------------
    def _fit(
        self, log: pd.DataFrame, validation_log: pd.DataFrame | None, progress: Progress
    ) -> None:
        """Normalise on the training data, then minimise the simulation error of the training
        windows over the weights and the windows' initial states; early stopping on the
        held-out windows (the ``validation_log``, or the validation block of ``log``)."""
        with torch_threads(1):
            self._fit_stages(log, validation_log, progress)

    def _fit_stages(
        self, log: pd.DataFrame, validation_log: pd.DataFrame | None, progress: Progress
    ) -> None:
        from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

        self._configure()
        self.sample_interval_ = self._check(log)  # every later log is checked against it
        self.net_ = self._new_net(self._generator())
        if validation_log is None:
            split = split_log(log, "block", self.fractions)  # type: ignore[arg-type]
            log, validation_log = split.train, split.validation
            self.division_ = split.record
        else:
            self._check(validation_log, "validation log")
            self.division_ = {"by": "given"}
        self._standardise(log)
        self.bounds_ = resolve_bounds(self.output_bounds_, self.outputs_, log)
        trainer = (
            clone(self.trainer, safe=False)
            if self.trainer is not None
            else LevenbergMarquardt(max_epochs=100)
        )
        self.trainer_ = trainer
        self._say_short_runs(log)
        held_out = self._held_out(validation_log)
        tracks = val_tracks = None
        self.history_, lengths, fit_errors = [], [], []  # per stage
        for i, length in enumerate(self.windows_):
            win = self._windows(log, length)
            val = self._windows(validation_log, length, "validation log") if held_out else None  # type: ignore[arg-type]
            fit = _Fit(
                self.net_,
                self._starts(win, tracks),
                None if val is None else self._starts(val, val_tracks),
            )
            train_batches = win.batches("fit")
            if val is not None:
                train_batches += val.batches("state")
            last = i == len(self.windows_) - 1
            checks = val.batches("val") if val is not None and last else None
            stage = f"stage {i + 1}/{len(self.windows_)} (window {length or 'whole runs'})"
            self.history_.append(
                trainer.fit(
                    fit,
                    self._shooting_residual,
                    train_batches,
                    checks,
                    progress=staged(progress, stage),
                    **self._free_states(trainer, fit),
                )
            )
            tracks = self._track(win, fit.x0.detach())
            if val is not None:
                val_tracks = self._track(val, fit.x0_val.detach())
            lengths.append((win.window_lengths, [] if val is None else val.window_lengths))
            fit_errors.append(self._windows_error(win, fit.x0.detach()))
        # the lengths simulated (a run shorter than the window is one window of its own length)
        # and the training windows' error apart from the trainer's objective (``train``)
        self.stages_ = [
            {
                "window": w,
                "window_lengths": n,
                "validation_window_lengths": v,
                "train_windows_mse": e,
                **h.as_dict(),
            }
            for w, (n, v), e, h in zip(
                self.windows_, lengths, fit_errors, self.history_, strict=True
            )
        ]
        with torch.no_grad():
            if self.hidden_states:
                x0 = torch.as_tensor(np.concatenate(tracks))  # type: ignore[arg-type]
                self.net_.hidden_init.copy_(x0[:, len(self.outputs_) :].mean(0))

    def _say_short_runs(self, log: pd.DataFrame) -> None:
        """A warning naming the training runs no longer than the warm-up, which the windows
        leave out (where every run is, :meth:`_windows` refuses the log)."""
        short = self._runs_too_short(log)
        if short and len(short) < len(experiment_rows(log)):
            warnings.warn(
                f"{len(short)} training run{'s' * (len(short) != 1)} no longer than the warm-up "
                f"({self.warmup_samples_} samples) left out of the state-space fit: "
                f"{some_runs(short)}",
                stacklevel=5,
            )

    def _held_out(self, validation_log: pd.DataFrame | None) -> bool:
        """Whether the validation log has a run longer than the warm-up to stop early on; a
        warning where it has rows but no such run (NARX's rule)."""
        if validation_log is None or not len(validation_log):
            return False
        w = self.warmup_samples_
        if any(len(pos) > w for _, pos in experiment_rows(validation_log)):
            return True
        warnings.warn(
            f"no run of the validation log is longer than the warm-up ({w} samples): the "
            "state-space model trains without early stopping, on its training error alone",
            stacklevel=5,
        )
        return False

    @staticmethod
    def _free_states(trainer: Any, fit: _Fit) -> dict[str, Any]:
        """The trainer's ``unpenalised`` argument where it has one: the windows' initial states
        are free parameters, not weights, and a weight penalty must not pull them toward 0."""
        from nnid.trainers.adam import Adam
        from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

        if not isinstance(trainer, LevenbergMarquardt | Adam):
            return {}
        return {"unpenalised": [k for k, _ in fit.named_parameters() if not k.startswith("net.")]}

    def _windows_error(self, win: _Windows, x0: torch.Tensor) -> float:
        """The mean square of the training windows' simulated outputs against the data
        (normalised): the fit alone, without the continuity links and the held-out warm-ups
        that the trainer's ``train`` series adds to it."""
        params = dict(self.net_.named_parameters())
        total, count = 0.0, 0
        with torch.no_grad():
            for g in win.groups:
                r = self._simulate(params, x0 if g.rows is None else x0[g.rows], g.u) - g.y
                total += float((r**2).sum())
                count += r.numel()
        return total / count

    def _validation_used(self, validation: pd.DataFrame | None) -> str | None:
        """Early stopping where a given validation log's windows were scored; not where it was
        no longer than the warm-up, nor where the fit held out a block of its training log
        itself (``division_``)."""
        given = validation is not None and self.division_.get("by") == "given"
        return self.validation_role if given and scored_validation(self.history_) else None

    # -- prediction ------------------------------------------------------------------------------
    def initial_state(self, y: np.ndarray, u: np.ndarray) -> torch.Tensor:
        """The state at the first sample, estimated from the first ``warmup`` normalised outputs
        ``y`` and inputs ``u`` by Levenberg-Marquardt with the network fixed."""
        from nnid.trainers.levenberg_marquardt import LevenbergMarquardt

        w = self.warmup_samples_
        ut = torch.as_tensor(u[:w])[:, None]
        yt = torch.as_tensor(y[:w])[:, None]
        holder = nn.Module()
        holder.x0 = nn.Parameter(self._initial_states(yt))
        fixed = {k: v.detach() for k, v in self.net_.named_parameters()}

        def residual(params: dict[str, torch.Tensor], batch: Any) -> torch.Tensor:
            return (self._simulate(fixed, params["x0"], ut) - yt).reshape(-1)

        LevenbergMarquardt(max_epochs=int(self.state_epochs)).fit(holder, residual, [None])
        return holder.x0.detach()

    def _predict(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        """Free run from the initial state estimated on each experiment's warm-up; k steps
        ahead (one step: k = 1) from the measured outputs at each start, with the hidden states
        of that free run. Rows before ``warmup + k − 1`` of each experiment are NaN."""
        with torch_threads(1):
            return self._predict_outputs(log, mode)

    def _predict_outputs(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        self._check(log)
        out = np.full((len(log), len(self.outputs_)), np.nan)
        mean, std = self.net_.y_mean.numpy(), self.net_.y_std.numpy()
        params = dict(self.net_.named_parameters())
        n_y, w = len(self.outputs_), self.warmup_samples_
        k = mode_steps(mode)
        for pos, yn, un in self._segments(log):
            n = len(yn)
            if n <= w:
                continue
            x0 = self.initial_state(yn, un)
            u = torch.as_tensor(un)
            with torch.no_grad():
                states = functional_call(self.net_, params, (x0, u[:, None]))[:, 0]
                if mode == "free_run":
                    pred = self._outputs(states).numpy()
                    out[pos[w:]] = pred[w:] * std + mean
                    continue
                starts = torch.arange(w - 1, n - k)
                if starts.numel() == 0:
                    continue
                x_start = torch.cat([torch.as_tensor(yn)[starts], states[starts, n_y:]], 1)
                inputs = u[starts[None, :] + torch.arange(k + 1)[:, None]]  # [k + 1, B, n_u]
                ahead = functional_call(self.net_, params, (x_start, inputs))[-1]
                out[pos[starts.numpy() + k]] = self._outputs(ahead).numpy() * std + mean
        return pd.DataFrame(out, index=log.index, columns=self.outputs_)
