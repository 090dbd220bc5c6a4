"""Multiple-shooting training of a neural ODE on logged runs.

A free run of a whole experiment is a long, badly conditioned function of the weights (an
error early in the run bends everything after it). Multiple shooting cuts every training
experiment into short segments that each start from the *measured* state and simulates them
all at once (one batched integration): the simulation error of a segment reflects the model
over that horizon only, the gradient is well scaled, and the batch keeps the integration
cheap. Segment length grows in stages (e.g. 0.5 s, 1 s, 2 s): short segments fit the fast
dynamics, longer ones the slow drift that only shows over seconds (a current, a lag).

Segments are drawn so that transient and steady-state segments weigh the same (Weiss V.B,
:class:`nnid.datasets.segmentation.BalancedSampler` over segment labels): with Adam a new
balanced draw each epoch; with Levenberg-Marquardt, whose epochs need a fixed sum of squares,
the same balance as weights on the segments' rows. Early stopping watches the free-run error
of held-out experiments, simulated in windows of ``validation_window`` seconds from their
measured starts (a damped vehicle forgets its initial state within seconds, so this is the
free-run error at the cost of a batched integration instead of one long sequential one); the
optimiser's start is the first entry of each stage's history, so a stage that does not improve
the held-out free run returns what it started from.

The model supplies the problem (:class:`ShootingProblem`): its module, how it simulates a
batch, its normalised outputs and the penalty rows of its objective.
"""

from __future__ import annotations

import inspect
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import torch
from sklearn.base import BaseEstimator, clone
from torch import Tensor, nn

from nnid.datasets.segmentation import BalancedSampler
from nnid.errors import NnidInputError
from nnid.trainers.history import History, Progress, staged


@dataclass
class Run:
    """One experiment as the trainer sees it: measured states ``[N, n]`` (where segments
    start), held inputs ``[N, m]``, normalised measured outputs ``[N, n_y]`` and transient
    labels ``[N]``. A value not measured is NaN: no segment starts from it, no error row
    scores it."""

    states: Tensor
    inputs: Tensor
    targets: Tensor
    transient: np.ndarray

    def __len__(self) -> int:
        return int(self.states.shape[0])


@dataclass
class Batch:
    """Segments of one length simulated together: start states ``[B, n]``, inputs
    ``[B, L, m]``, measured states ``[L, B, n]`` (for penalties on the measured data), targets
    of samples 1..L ``[L, B, n_y]`` and per-segment row weights ``[B]`` (None: all 1)."""

    x0: Tensor
    inputs: Tensor
    measured: Tensor
    targets: Tensor
    weight: Tensor | None = None
    train: bool = True


class ShootingProblem(Protocol):
    """What a model gives the trainer."""

    module: nn.Module

    def simulate(
        self, params: dict[str, Tensor], x0: Tensor, inputs: Tensor, train: bool = True
    ) -> Tensor:
        """States at samples 0..L ``[L + 1, B, n]`` from ``x0`` ``[B, n]`` under
        ``inputs`` ``[B, L, m]``; ``train=False`` (a held-out score, never differentiated):
        the problem may take a faster path without gradients."""
        ...

    def outputs(self, states: Tensor) -> Tensor:
        """Normalised outputs ``[..., n_y]`` of states ``[..., n]``."""
        ...

    def penalty(self, params: dict[str, Tensor], batch: Batch, rows: int) -> Tensor:
        """Extra residual rows of the objective (1-D, possibly empty), scaled for a batch of
        ``rows`` error rows: the sum of their squares is added to the error's."""
        ...


def cut_segments(runs: Sequence[Run], length: int) -> list[tuple[int, int]]:
    """(run, start) of every segment of ``length`` steps: each run tiled from its start, a
    segment's last sample being the next one's first; a last segment ending at the run's end
    (overlapping its neighbour) so no sample is left out. Runs shorter than one segment give
    none."""
    out = []
    for j, run in enumerate(runs):
        n = len(run)
        if n <= length:
            continue
        starts = sorted({*range(0, n - length, length), n - 1 - length})
        out += [(j, s) for s in starts]
    return out


def make_batch(
    runs: Sequence[Run],
    where: Sequence[tuple[int, int]],
    length: int,
    weight: Tensor | None = None,
    train: bool = True,
) -> Batch:
    """The segments ``where`` of ``length`` steps as one batch."""
    x0 = torch.stack([runs[j].states[s] for j, s in where])
    inputs = torch.stack([runs[j].inputs[s : s + length] for j, s in where])
    measured = torch.stack([runs[j].states[s : s + length] for j, s in where], 1)
    targets = torch.stack([runs[j].targets[s + 1 : s + length + 1] for j, s in where], 1)
    return Batch(x0, inputs, measured, targets, weight, train)


def take(batch: Batch, index: Tensor) -> Batch:
    """The segments ``index`` of a batch (drawing minibatches without restacking runs)."""
    return Batch(
        batch.x0[index],
        batch.inputs[index],
        batch.measured[:, index],
        batch.targets[:, index],
        None if batch.weight is None else batch.weight[index],
        batch.train,
    )


def residual(problem: ShootingProblem, params: dict[str, Tensor], batch: Batch) -> Tensor:
    """The simulation error of a batch's segments (normalised outputs, weighted rows) where
    the target was measured (a missing one, NaN, has no row), then the problem's penalty rows
    on training batches."""
    states = problem.simulate(params, batch.x0, batch.inputs, batch.train)
    err = problem.outputs(states[1:]) - batch.targets
    if batch.weight is not None:
        err = err * batch.weight[None, :, None]
    known = torch.isfinite(batch.targets)
    err = err.reshape(-1) if bool(known.all()) else err[known]
    if not batch.train:
        return err
    return torch.cat([err, problem.penalty(params, batch, err.numel())])


def error_rows(r: Tensor, batch: Batch) -> Tensor:
    """The simulation-error rows of a batch's :func:`residual` (the penalty rows follow them):
    what a training error is recorded on, as the validation error is."""
    return r[: int(torch.isfinite(batch.targets).sum())]


def startable(
    runs: Sequence[Run], where: Sequence[tuple[int, int]]
) -> tuple[list[tuple[int, int]], int]:
    """The segments of ``where`` whose start state was measured (finite), and how many were
    left out: a simulation cannot start from a missing velocity."""
    kept = [(j, s) for j, s in where if bool(torch.isfinite(runs[j].states[s]).all())]
    return kept, len(where) - len(kept)


class MultipleShooting(BaseEstimator):
    """Multiple-shooting trainer (module docstring).

    Args:
        segments: segment lengths in seconds, one training stage each, in order.
        optimizer: :class:`nnid.trainers.adam.Adam` (default ``Adam(lr=3e-3, max_epochs=60,
            max_fail=10)``) or :class:`nnid.trainers.levenberg_marquardt.LevenbergMarquardt`
            (small networks: its Jacobian has one column per weight).
        batch_segments: segments per optimiser step (Adam) or per Jacobian batch (LM).
        balance: weigh transient and steady-state segments equally.
        validation_window: seconds per held-out free-run window (None: whole experiments; a
            run shorter than a window is flown whole).
        seed: seeds the draws of segments.
    """

    kind = "shooting"

    def __init__(
        self,
        segments: Sequence[float] = (0.5, 1.0, 2.0),
        optimizer: Any = None,
        batch_segments: int = 256,
        balance: bool = True,
        validation_window: float | None = 5.0,
        seed: int = 0,
    ) -> None:
        self.segments = segments
        self.optimizer = optimizer
        self.batch_segments = batch_segments
        self.balance = balance
        self.validation_window = validation_window
        self.seed = seed

    def _optimizer(self):
        from nnid.trainers.adam import Adam

        if self.optimizer is None:
            return Adam(lr=3e-3, max_epochs=60, max_fail=10)
        return clone(self.optimizer, safe=False)

    def steps(self, seconds: float | None, dt: float, longest: int, field: str = "segments") -> int:
        """Samples of ``seconds`` (None or longer than the data: ``longest``); under one
        sample is refused, naming ``field``: it was trained as one sample without a word."""
        if seconds is None or seconds / dt >= longest:
            return longest
        if round(seconds / dt) < 1:
            raise NnidInputError(f"{seconds:g} s is under one sample (dt = {dt:g} s)", field=field)
        return int(min(round(seconds / dt), longest))

    def fit(
        self,
        problem: ShootingProblem,
        runs: Sequence[Run],
        dt: float,
        validation: Sequence[Run] = (),
        progress: Progress | None = None,
    ) -> list[History]:
        """Train ``problem.module`` stage by stage; the history of each stage."""
        if not self.segments or any(s <= 0 for s in self.segments):
            raise NnidInputError("segments: one or more positive lengths (s)", field="segments")
        longest = max(len(r) for r in runs) - 1
        val_batches = None
        windows_dropped = 0
        if validation:
            # each run in windows of validation_window, a run shorter than one whole: the
            # shortest run set every run's window (a 2-s run made the 5-s windows 2-s ones)
            longest_val = max(len(r) for r in validation) - 1
            val_len = self.steps(self.validation_window, dt, longest_val, "validation_window")
            by_length: dict[int, list[tuple[int, int]]] = {}
            for j, run in enumerate(validation):
                n = min(val_len, len(run) - 1)
                if n >= 1:
                    windows = [(j, s) for _, s in cut_segments([run], n)]
                    windows, dropped = startable(validation, windows)
                    windows_dropped += dropped
                    if windows:
                        by_length.setdefault(n, []).extend(windows)
            val_batches = [
                make_batch(validation, where, n, train=False)
                for n, where in sorted(by_length.items(), reverse=True)
            ] or None
        histories = []
        for i, seconds in enumerate(self.segments):
            length = self.steps(seconds, dt, longest)
            where = cut_segments(runs, length)
            if not where:
                raise NnidInputError(
                    f"no training experiment is longer than a segment of {seconds:g} s",
                    field="segments",
                )
            where, dropped = startable(runs, where)
            if not where:
                raise NnidInputError(
                    f"every segment of {seconds:g} s starts from a missing (NaN) velocity",
                    field="segments",
                )
            labels = np.array(
                [runs[j].transient[s : s + length].mean() >= 0.5 for j, s in where], dtype=bool
            )
            sampler = BalancedSampler(labels, balance=self.balance, seed=self.seed + i)
            optimizer = self._optimizer()
            batches = self._batches(optimizer, runs, where, length, sampler)
            stage = f"stage {i + 1}/{len(self.segments)} (segments of {length * dt:g} s)"

            def loss(params: dict[str, Tensor], batch: Batch) -> Tensor:
                return residual(problem, params, batch)

            # Adam and LM record the error rows' mean square, comparable with the validation
            # error (with the penalty rows it was MSE·n_y/(n_y + 6) under the force penalty);
            # an optimiser of one's own whose fit takes no ``recorded`` records its objective
            takes = "recorded" in inspect.signature(optimizer.fit).parameters
            fit_args = {"recorded": error_rows} if takes else {}
            history = optimizer.fit(
                problem.module,
                loss,
                batches,
                val_batches,
                progress=staged(progress, stage),
                **fit_args,
            )
            # left out for a start state that was not measured: recorded
            if dropped:
                history.info["segments_without_start"] = dropped
            if windows_dropped:
                history.info["validation_windows_without_start"] = windows_dropped
            # a segment asked longer than every run trains on the longest run: recorded
            if seconds / dt >= longest:
                history.info["segment_s_trained"] = length * dt
            histories.append(history)
        return histories

    def _batches(self, optimizer, runs, where, length, sampler: BalancedSampler):
        """Adam: a callable giving each epoch a new balanced draw, in minibatches. LM: fixed
        batches whose rows carry the balance as weights (a fixed sum of squares)."""
        size = max(1, int(self.batch_segments))
        every = make_batch(runs, where, length)
        if getattr(optimizer, "kind", None) == "lm":
            every.weight = torch.as_tensor(np.sqrt(sampler.weights() * len(where)))
            return [
                take(every, torch.arange(a, min(a + size, len(where))))
                for a in range(0, len(where), size)
            ]

        def epoch_batches(epoch: int) -> list[Batch]:
            drawn = torch.as_tensor(sampler.sample(len(where), epoch))
            return [take(every, drawn[a : a + size]) for a in range(0, len(drawn), size)]

        return epoch_batches
