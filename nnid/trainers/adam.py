"""Adam for any PyTorch module with a residual vector, with a learning-rate schedule, gradient
clipping and early stopping on a validation split.

Same calling convention as :class:`nnid.trainers.levenberg_marquardt.LevenbergMarquardt`:
``fit(module, residual, train_batches, val_batches)`` where ``residual(params, batch)`` returns a
1-D residual tensor (computed with ``torch.func.functional_call(module, params, ...)``) and the
loss is its mean square (the performance function of Weiss's NARX training, section IV.A.2).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Literal

import torch
from sklearn.base import BaseEstimator

from nnid.errors import checked_number
from nnid.trainers.history import History, Progress, silent, stopping_score
from nnid.trainers.levenberg_marquardt import unpenalised_names

Residual = Callable[[dict[str, torch.Tensor], Any], torch.Tensor]
Batches = Sequence[Any] | Callable[[int], Iterable[Any]]


class Adam(BaseEstimator):
    """Adam with a learning-rate schedule from :mod:`torch.optim.lr_scheduler` (``"cosine"``:
    cosine annealing to ``lr_min`` over ``max_epochs``; ``"plateau"``: halve the rate after
    ``plateau`` epochs without validation improvement, not below ``lr_min``; ``"constant"``;
    an ``lr_min`` above ``lr`` keeps ``lr``),
    gradient-norm clipping at ``clip`` and early stopping after ``max_fail`` epochs without
    validation improvement (MATLAB's max_fail); the best validation state is restored (the start
    included). ``max_seconds`` (MATLAB's ``time``; default no limit) stops after the first epoch
    that ends past that wall time. ``average`` (a decay, e.g. 0.95; default off) keeps an
    exponential moving average of the weights over the optimiser steps (Polyak averaging): it is
    what validation scores and what is kept, a smoother path than the last step's weights when
    minibatch gradients are noisy."""

    kind = "adam"

    def __init__(
        self,
        lr: float = 1e-2,
        max_epochs: int = 200,
        schedule: Literal["cosine", "plateau", "constant"] = "cosine",
        lr_min: float = 1e-4,
        plateau: int = 5,
        clip: float | None = 1.0,
        max_fail: int = 20,
        weight_decay: float = 0.0,
        max_seconds: float | None = None,
        average: float | None = None,
    ) -> None:
        self.lr = lr
        self.max_epochs = max_epochs
        self.schedule = schedule
        self.lr_min = lr_min
        self.plateau = plateau
        self.clip = clip
        self.max_fail = max_fail
        self.weight_decay = weight_decay
        self.max_seconds = max_seconds
        self.average = average

    def _scheduler(self, opt: torch.optim.Optimizer):
        sched = torch.optim.lr_scheduler
        # a schedule lowers the rate: the default floor never lifts a smaller lr above itself
        floor = min(self.lr_min, self.lr)
        if self.schedule == "cosine":
            return sched.CosineAnnealingLR(opt, T_max=max(1, self.max_epochs - 1), eta_min=floor)
        if self.schedule == "plateau":
            # threshold 0: any improvement on the best resets the count, as early stopping's does
            return sched.ReduceLROnPlateau(
                opt,
                factor=0.5,
                patience=max(self.plateau - 1, 0),
                threshold=0.0,
                min_lr=floor,
            )
        if self.schedule == "constant":
            return None
        raise ValueError(f"schedule is 'cosine', 'plateau' or 'constant', not {self.schedule!r}")

    @staticmethod
    def _groups(
        module: torch.nn.Module, params: dict[str, torch.Tensor], unpenalised: Iterable[str]
    ) -> list:
        """The optimiser's parameters: all of them, or two groups, the ``unpenalised`` ones
        without weight decay."""
        free = unpenalised_names(module, unpenalised)
        if not free:
            return list(params.values())
        groups = [
            {"params": [p for k, p in params.items() if k not in free]},
            {"params": [p for k, p in params.items() if k in free], "weight_decay": 0.0},
        ]
        return [g for g in groups if g["params"]]

    def fit(
        self,
        module: torch.nn.Module,
        residual: Residual,
        train_batches: Batches,
        val_batches: Sequence[Any] | None = None,
        progress: Progress | None = None,
        recorded: Callable[[torch.Tensor, Any], torch.Tensor] | None = None,
        unpenalised: Iterable[str] = (),
    ) -> History:
        """Minimise mean(residual²) over ``train_batches`` (a list, or a callable giving the
        batches of an epoch, for resampling); stop early on ``val_batches``. ``progress(epoch,
        max_epochs, message)`` is called after every epoch; ``extra["lr"]`` holds the rate each
        epoch trained with. ``recorded(r, batch)``: the rows of a batch's residual whose mean
        square is recorded as the training error (default: all; an objective with penalty rows
        records its error rows, comparable with the validation error). A batch whose loss or
        gradient is not finite takes no step (counted in ``info["skipped_batches"]``); an epoch
        none of whose batches could step ends the fit ("non-finite loss"). ``unpenalised``:
        names of parameters (as ``named_parameters`` gives them) that ``weight_decay`` leaves
        alone, e.g. free initial states that are no weights."""
        checked_number(self.lr, "lr")  # torch refused a NaN with its own error, ran 0 idle
        checked_number(self.max_epochs, "max_epochs", strict=False, integer=True)
        checked_number(self.max_fail, "max_fail", 1, strict=False, integer=True)
        start = time.perf_counter()
        report = progress or silent
        params = {k: p for k, p in module.named_parameters() if p.requires_grad}
        opt = torch.optim.Adam(
            self._groups(module, params, unpenalised), lr=self.lr, weight_decay=self.weight_decay
        )
        scheduler = self._scheduler(opt)
        hist = History()

        avg = None
        if self.average is not None:
            if not 0.0 < self.average < 1.0:
                raise ValueError(f"average is a decay in (0, 1), not {self.average}")
            avg = {k: p.detach().clone() for k, p in params.items()}

        def kept() -> dict[str, torch.Tensor]:
            """The weights validation judges and the fit keeps: the average, or the last."""
            return params if avg is None else avg

        def state() -> dict[str, torch.Tensor]:
            out = copy.deepcopy(module.state_dict())
            if avg is not None:
                out.update({k: v.clone() for k, v in avg.items()})
            return out

        def mean_square(batches: Iterable[Any], weights: dict[str, torch.Tensor]) -> float:
            batches = list(batches)
            with torch.no_grad():
                rs = [residual(weights, b) for b in batches]
                if recorded is not None:
                    rs = [recorded(r, b) for r, b in zip(rs, batches, strict=True)]
            return float(sum((r**2).sum() for r in rs) / max(sum(r.numel() for r in rs), 1))

        first = train_batches(0) if callable(train_batches) else train_batches
        score = mean_square(val_batches, params) if val_batches else None
        hist.record(mean_square(first, params), score, time.perf_counter() - start)
        best = stopping_score(score if score is not None else hist.train[0])
        if isinstance(scheduler, torch.optim.lr_scheduler.ReduceLROnPlateau):
            scheduler.step(best)  # the start counts, as it does for early stopping
        best_state = state()
        since_best = 0
        hist.stop_reason = "max_epochs"
        for epoch in range(self.max_epochs):
            rate = opt.param_groups[0]["lr"]
            batches = train_batches(epoch) if callable(train_batches) else train_batches
            total, count, skipped, stepped = 0.0, 0, 0, 0
            for batch in batches:
                opt.zero_grad(set_to_none=True)
                r = residual(params, batch)
                loss = (r**2).mean()
                # a non-finite loss (a segment that diverged) or gradient takes no step: its
                # NaN, through clipping and Adam's moments, broke every weight at once. Nor is
                # it in the epoch's recorded error: a NaN there, without validation, was the
                # stopping score (inf), and the fit went back to its start
                if not math.isfinite(float(loss.detach())):
                    skipped += 1
                    continue
                if recorded is None:
                    total += float(loss.detach()) * r.numel()
                    count += r.numel()
                else:
                    part = recorded(r.detach(), batch)
                    total += float((part**2).sum())
                    count += part.numel()
                loss.backward()
                if not _finite_gradient(params.values(), self.clip):
                    skipped += 1
                    continue
                opt.step()
                stepped += 1
                if avg is not None:
                    with torch.no_grad():
                        for k, p in params.items():
                            avg[k].lerp_(p.detach(), 1.0 - self.average)
            # the batches whose error was measured; NaN where none was
            train = total / count if count else math.nan
            if skipped:
                hist.info["skipped_batches"] = hist.info.get("skipped_batches", 0) + skipped
            score = mean_square(val_batches, kept()) if val_batches else None
            hist.record(train, score, time.perf_counter() - start, lr=rate)
            # a diverged validation free run is a failure; only a non-finite training loss
            # (the weights themselves broke) ends the fit
            value = stopping_score(score if score is not None else train)
            report(
                epoch + 1,
                self.max_epochs,
                f"Adam epoch {epoch + 1}: train MSE {train:.4g}"
                + (f", validation {score:.4g}" if score is not None else ""),
                train=train,
                **({} if score is None else {"validation": score}),
            )
            if not stepped and skipped:
                # no batch of the epoch gave a finite step: the weights cannot move on
                hist.stop_reason = "non-finite loss"
                break
            if value < best:
                best, since_best, hist.best_epoch = value, 0, epoch + 1
                best_state = state()
            else:
                since_best += 1
                if val_batches and since_best >= self.max_fail:
                    hist.stop_reason = hist.early_stop_reason()
                    break
            if isinstance(scheduler, torch.optim.lr_scheduler.ReduceLROnPlateau):
                scheduler.step(value)
            elif scheduler is not None:
                scheduler.step()
            if self.max_seconds is not None and hist.time[-1] >= self.max_seconds:
                hist.stop_reason = "max_seconds"
                break
        module.load_state_dict(best_state)
        return hist


def _finite_gradient(params: Iterable[torch.Tensor], clip: float | None) -> bool:
    """Clip the gradients' norm at ``clip`` (None: leave them); whether they are finite (a
    NaN norm would have made every clipped gradient NaN)."""
    grads = [p for p in params if p.grad is not None]
    if clip is not None:
        return math.isfinite(float(torch.nn.utils.clip_grad_norm_(grads, clip)))
    return all(bool(torch.isfinite(p.grad).all()) for p in grads)
