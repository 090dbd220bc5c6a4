"""What the input-output models (NARX, neural state space) share: named input and output
columns standardised on the training data (buffers of the network, saved with it), per-
experiment segments, a free-run error for early decisions, and their learned state as the
network's state dict (``tensors.pt``, loaded with ``weights_only=True``) plus JSON."""

from __future__ import annotations

from abc import abstractmethod
from collections.abc import Iterable
from typing import Any

import numpy as np
import pandas as pd
import torch
from torch import nn

from nnid.datasets.log import validate_table
from nnid.datasets.preprocess import check_uniform, experiment_rows
from nnid.errors import NnidInputError
from nnid.evaluation.evaluate import score_split, target_columns
from nnid.evaluation.metrics import warmup_mask
from nnid.models.base import NnidModel
from nnid.trainers.history import history_state, restored_history

DTYPE = torch.float64


def init_linear(layer: nn.Linear, generator: torch.Generator) -> nn.Linear:
    """``layer.reset_parameters()`` drawn from ``generator`` instead of torch's global one:
    weights and biases U(−1/√fan_in, 1/√fan_in), as kaiming_uniform(a=√5) gives."""
    nn.init.kaiming_uniform_(layer.weight, a=5**0.5, generator=generator)
    fan_in = layer.weight.shape[1]
    bound = 1.0 / fan_in**0.5 if fan_in > 0 else 0.0
    nn.init.uniform_(layer.bias, -bound, bound, generator=generator)
    return layer


def seeded_linear(
    n_in: int, n_out: int, generator: torch.Generator, dtype: torch.dtype = torch.float32
) -> nn.Linear:
    """An ``nn.Linear`` of ``dtype`` initialised from ``generator`` (built uninitialised
    first, so torch's global generator is never drawn from)."""
    layer = nn.utils.skip_init(nn.Linear, n_in, n_out, dtype=dtype)
    return init_linear(layer, generator)


class InputOutputModel(NnidModel):
    """Base of a model of named ``inputs`` and ``outputs`` columns with a network ``net_``
    holding the buffers ``u_mean u_std y_mean y_std``.

    Subclasses implement ``_configure`` (the settings in working form: ``inputs_``,
    ``outputs_``, ``targets_``, ``warmup_samples_`` and what else the network's shape needs;
    called by ``fit`` and on load), ``_new_net(generator)``, ``_fit``, ``_predict``, and
    ``_learned`` / ``_set_learned`` for the JSON part of their state.
    """

    net_: Any

    def motion_columns(self, columns: Iterable[str]) -> list[str]:
        """The motion columns among its ``inputs`` and ``outputs``: it reads no other column
        (:meth:`_check`). Every motion column where those are not yet a list of names (the
        fit names what is wrong with them)."""
        named = [self.inputs, self.outputs]
        if not all(np.iterable(n) and not isinstance(n, str | bytes) for n in named):
            return super().motion_columns(columns)
        read = {c for n in named for c in n}
        return [c for c in super().motion_columns(columns) if c in read]

    @abstractmethod
    def _configure(self) -> None: ...

    @abstractmethod
    def _new_net(self, generator: torch.Generator | None = None) -> nn.Module: ...

    def _generator(self) -> torch.Generator:
        """The local generator of the initial weights (``seed``): the user's global torch
        generator is neither seeded nor drawn from."""
        return torch.Generator().manual_seed(int(self.seed))

    #: what counts time in samples, for the uniform-sampling check's error
    counts_samples = "the model"

    def _check(self, log: pd.DataFrame, name: str = "log") -> float | None:
        """The model's columns present (a missing one named under ``inputs`` or ``outputs``,
        beside the columns there are) and finite, and (with a ``t``) uniform sampling at one
        rate, the one the model was trained at once it is (``sample_interval_``): delays and
        integration steps count samples, so a run at another rate would be read as one whose
        dynamics are faster or slower (a state-space model fitted at 20 Hz predicted a 10-Hz
        log exactly as the 20-Hz one). Returns the log's sampling interval."""
        for role, columns in (("inputs", self.inputs_), ("outputs", self.outputs_)):
            missing = [c for c in columns if c not in log.columns]
            if missing:
                raise NnidInputError(
                    f"the {name} has no column(s) {missing}; it has {list(log.columns)}",
                    field=role,
                )
        validate_table(log, [*self.inputs_, *self.outputs_], source=name, require_time=False)
        if "t" not in log:
            return None
        trained = getattr(self, "sample_interval_", None)
        return check_uniform(log, self.counts_samples, name, trained, one_rate=True)

    def _standardise(self, log: pd.DataFrame) -> None:
        """Means and standard deviations (1 where a column is constant) of the training data."""
        net = self.net_
        for cols, mean, std in (
            (self.outputs_, net.y_mean, net.y_std),
            (self.inputs_, net.u_mean, net.u_std),
        ):
            v = log[cols].to_numpy(np.float64)
            s = v.std(0)
            mean.copy_(torch.as_tensor(v.mean(0)))
            std.copy_(torch.as_tensor(np.where(s > 0, s, 1.0)))

    def _segments(self, log: pd.DataFrame) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(positions, normalised outputs, normalised inputs) per experiment."""
        net = self.net_
        y = (log[self.outputs_].to_numpy(np.float64) - net.y_mean.numpy()) / net.y_std.numpy()
        u = (log[self.inputs_].to_numpy(np.float64) - net.u_mean.numpy()) / net.u_std.numpy()
        out = []
        for _, pos in experiment_rows(log):
            out.append((pos, y[pos], u[pos]))
        return out

    def free_run_error(self, log: pd.DataFrame) -> float | None:
        """Mean free-run NRMSE over the outputs the log excites (warm-up excluded; the columns
        of the reported scores, :func:`target_columns`): the number a fine-tuning reports
        before and after. Infinite when the free run diverges in any run
        (:func:`score_split`); None when no output is scored (the log excites none, or none
        has a scored sample), which is no divergence."""
        pred = self._predict(log, "free_run").set_axis(log.index)
        mask = warmup_mask(log, 0.0, self.warmup_samples_)
        nrmse, _, diverged, *_ = score_split(
            log, pred, target_columns(self, log), mask, lambda run: target_columns(self, run)
        )
        if diverged:
            return np.inf
        return None if nrmse["total"] is None else float(nrmse["total"])

    def _n_params(self) -> int:
        return sum(p.numel() for p in self.net_.parameters())

    def _state(self) -> tuple[dict, dict[str, torch.Tensor]]:
        interval = getattr(self, "sample_interval_", None)
        # every field of the fit's history (a NARX's summary in _learned has no time series):
        # a loaded model lacked the history_ the fitted one had, or held the summary instead
        history = history_state(getattr(self, "history_", None))
        learned = {**self._learned(), "sample_interval": interval, "fit_history": history}
        return learned, dict(self.net_.state_dict())

    def _restore(self, state: dict, tensors: dict[str, torch.Tensor]) -> None:
        self._configure()
        self.net_ = self._new_net()
        self.net_.load_state_dict(tensors)
        state = dict(state)
        interval = state.pop("sample_interval", None)  # absent from older files: not checked
        history = state.pop("fit_history", None)  # absent from older files, as the history
        number = isinstance(interval, float | int) and not isinstance(interval, bool)
        if interval is not None and not (number and interval > 0):
            raise ValueError(f"sample_interval must be a positive number, not {interval!r}")
        self.sample_interval_ = None if interval is None else float(interval)
        self._set_learned(state)
        if history is not None:
            self.history_ = restored_history(history)

    @abstractmethod
    def _learned(self) -> dict:
        """What ``fit`` learned besides the network, JSON-ready."""

    @abstractmethod
    def _set_learned(self, state: dict) -> None: ...
