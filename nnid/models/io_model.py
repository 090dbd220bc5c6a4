"""What the input-output models (NARX, neural state space) share: named input and output
columns standardised on the training data (buffers of the network, saved with it), per-
experiment segments, scores, and saving as a state dict plus a JSON config (no pickle)."""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from nnid.datasets.preprocess import experiments
from nnid.evaluation.metrics import nrmse


class InputOutputModel(ABC):
    """Base of a model with ``inputs``, ``outputs``, a network ``net_`` holding the buffers
    ``u_mean u_std y_mean y_std``, ``config()`` (its constructor arguments) and ``predict``."""

    #: file names: ``<stem>.pt`` (state dict) and ``<stem>.json`` (config)
    stem = "model"
    inputs: list[str]
    outputs: list[str]
    net_: Any

    @abstractmethod
    def config(self) -> dict:
        """The JSON-serialisable constructor arguments."""

    @abstractmethod
    def predict(self, log: pd.DataFrame, mode: Any = "free_run") -> pd.DataFrame:
        """Predicted outputs (columns ``outputs``, the log's index), warm-up rows NaN."""

    def save(self, folder: str | Path) -> Path:
        """``<stem>.pt`` (the state dict: weights, normalisation) and ``<stem>.json``."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        torch.save(self.net_.state_dict(), folder / f"{self.stem}.pt")
        (folder / f"{self.stem}.json").write_text(json.dumps(self.config(), indent=2))
        return folder

    @classmethod
    def load(cls, folder: str | Path):
        """Rebuild from ``<stem>.json`` and load ``<stem>.pt`` with ``weights_only=True``."""
        folder = Path(folder)
        cfg = json.loads((folder / f"{cls.stem}.json").read_text())
        cfg.pop("trainer", None)
        model = cls(**cfg)
        model.net_.load_state_dict(torch.load(folder / f"{cls.stem}.pt", weights_only=True))
        return model

    def _standardise(self, log: pd.DataFrame) -> None:
        """Means and standard deviations (1 where a column is constant) of the training data."""
        net = self.net_
        for cols, mean, std in (
            (self.outputs, net.y_mean, net.y_std),
            (self.inputs, net.u_mean, net.u_std),
        ):
            v = log[cols].to_numpy(np.float64)
            s = v.std(0)
            mean.copy_(torch.as_tensor(v.mean(0)))
            std.copy_(torch.as_tensor(np.where(s > 0, s, 1.0)))

    def _segments(self, log: pd.DataFrame) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(positions, normalised outputs, normalised inputs) per experiment."""
        net = self.net_
        y = (log[self.outputs].to_numpy(np.float64) - net.y_mean.numpy()) / net.y_std.numpy()
        u = (log[self.inputs].to_numpy(np.float64) - net.u_mean.numpy()) / net.u_std.numpy()
        out = []
        for _, idx in experiments(log):
            pos = log.index.get_indexer(idx)
            out.append((pos, y[pos], u[pos]))
        return out

    def score(self, log: pd.DataFrame, mode: Any = "free_run") -> dict[str, float]:
        """NRMSE per output and ``total`` (their mean), warm-up excluded (NaN rows)."""
        pred = self.predict(log, mode)
        out = {c: nrmse(log[c].to_numpy(), pred[c].to_numpy()) for c in self.outputs}
        finite = [v for v in out.values() if np.isfinite(v)]
        out["total"] = float(np.mean(finite)) if finite else float("nan")
        return out
