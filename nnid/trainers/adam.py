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
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import torch

Residual = Callable[[dict[str, torch.Tensor], Any], torch.Tensor]
Batches = Sequence[Any] | Callable[[int], Iterable[Any]]


@dataclass
class AdamHistory:
    """Per-epoch training and validation mean-square residuals, and why training stopped.

    ``time[k]`` is the wall time in seconds from the start of ``fit`` to the end of epoch k's
    validation (cumulative, like ``LMHistory.time``); ``seconds`` is the whole ``fit``,
    restoring the best state included.
    """

    train: list[float] = field(default_factory=list)
    validation: list[float] = field(default_factory=list)
    lr: list[float] = field(default_factory=list)
    time: list[float] = field(default_factory=list)
    best_epoch: int = -1
    stop: str = "max_epochs"
    seconds: float = 0.0


class Adam:
    """Adam with ``schedule`` ("cosine" annealing to ``lr_min`` or "plateau": halve the rate
    after ``plateau`` epochs without validation improvement), gradient-norm clipping at
    ``clip`` and early stopping after ``max_fail`` epochs without validation improvement
    (MATLAB's max_fail); the best validation state is restored. ``max_seconds`` (MATLAB's
    ``time``; default no limit) stops after the first epoch that ends past that wall time."""

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

    def _rate(self, epoch: int, current: float, since_best: int) -> float:
        if self.schedule == "cosine":
            frac = epoch / max(1, self.max_epochs - 1)
            return self.lr_min + 0.5 * (self.lr - self.lr_min) * (1 + math.cos(math.pi * frac))
        if self.schedule == "plateau" and since_best > 0 and since_best % self.plateau == 0:
            return max(self.lr_min, current * 0.5)
        return current

    def fit(
        self,
        module: torch.nn.Module,
        residual: Residual,
        train_batches: Batches,
        val_batches: Sequence[Any] | None = None,
    ) -> AdamHistory:
        """Minimise mean(residual²) over ``train_batches`` (a list, or a callable giving the
        batches of an epoch, for resampling); stop early on ``val_batches``."""
        import time

        start = time.perf_counter()
        params = {k: p for k, p in module.named_parameters() if p.requires_grad}
        opt = torch.optim.Adam(params.values(), lr=self.lr, weight_decay=self.weight_decay)
        hist = AdamHistory()
        best, best_state, since_best, rate = math.inf, None, 0, self.lr
        for epoch in range(self.max_epochs):
            rate = self._rate(epoch, rate, since_best)
            for g in opt.param_groups:
                g["lr"] = rate
            batches = train_batches(epoch) if callable(train_batches) else train_batches
            total, count = 0.0, 0
            for batch in batches:
                opt.zero_grad(set_to_none=True)
                r = residual(params, batch)
                loss = (r**2).mean()
                loss.backward()
                if self.clip is not None:
                    torch.nn.utils.clip_grad_norm_(params.values(), self.clip)
                opt.step()
                total += float(loss.detach()) * r.numel()
                count += r.numel()
            hist.train.append(total / max(count, 1))
            hist.lr.append(rate)
            score = hist.train[-1]
            if val_batches:
                with torch.no_grad():
                    rs = [residual(params, b) for b in val_batches]
                score = float(sum((r**2).sum() for r in rs) / sum(r.numel() for r in rs))
                hist.validation.append(score)
            hist.time.append(time.perf_counter() - start)
            if not math.isfinite(score):
                hist.stop = "non-finite loss"
                break
            if score < best:
                best, since_best, hist.best_epoch = score, 0, epoch
                best_state = copy.deepcopy(module.state_dict())
            else:
                since_best += 1
                if val_batches and since_best >= self.max_fail:
                    hist.stop = "validation failures"
                    break
            if self.max_seconds is not None and hist.time[-1] >= self.max_seconds:
                hist.stop = "max_seconds"
                break
        if best_state is not None:
            module.load_state_dict(best_state)
        hist.seconds = time.perf_counter() - start
        return hist
