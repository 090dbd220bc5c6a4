"""Adam trainer: per-epoch wall-time stamps and the wall-time cap."""

from __future__ import annotations

import torch
from torch.func import functional_call

from nnid.trainers.adam import Adam


def _problem():
    torch.manual_seed(0)
    x = torch.randn(64, 3)
    y = x @ torch.tensor([[1.0], [-2.0], [0.5]])
    module = torch.nn.Linear(3, 1)

    def residual(params, batch):
        xb, yb = batch
        return (functional_call(module, params, (xb,)) - yb).reshape(-1)

    return module, residual, [(x[:32], y[:32]), (x[32:], y[32:])], [(x, y)]


def test_history_time_is_cumulative_per_epoch():
    module, residual, train, val = _problem()
    hist = Adam(lr=0.05, max_epochs=5).fit(module, residual, train, val)
    assert hist.stop == "max_epochs"
    assert len(hist.time) == len(hist.train) == len(hist.validation) == 5
    assert all(0 < a < b for a, b in zip(hist.time, hist.time[1:], strict=False))
    assert hist.time[-1] <= hist.seconds


def test_max_seconds_stops_after_the_first_epoch_past_the_cap():
    module, residual, train, val = _problem()
    hist = Adam(lr=0.05, max_epochs=1000, max_seconds=0.0).fit(module, residual, train, val)
    assert hist.stop == "max_seconds"
    assert len(hist.train) == len(hist.time) == 1
    # without validation batches the cap applies too
    hist = Adam(lr=0.05, max_epochs=1000, max_seconds=0.0).fit(module, residual, train)
    assert hist.stop == "max_seconds" and len(hist.time) == 1
