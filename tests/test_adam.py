"""Adam trainer: one History (start and per-epoch entries), the wall-time cap, the learning-rate
schedules of torch.optim.lr_scheduler, and the progress callback."""

from __future__ import annotations

import math

import pytest
import torch
from torch.func import functional_call

from nnid.models.io_model import seeded_linear
from nnid.trainers.adam import Adam


def _problem():
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(64, 3, generator=gen)
    y = x @ torch.tensor([[1.0], [-2.0], [0.5]])
    # not torch's global generator, which other tests seed and draw from
    module = seeded_linear(3, 1, gen, x.dtype)

    def residual(params, batch):
        xb, yb = batch
        return (functional_call(module, params, (xb,)) - yb).reshape(-1)

    return module, residual, [(x[:32], y[:32]), (x[32:], y[32:])], [(x, y)]


def test_history_has_the_start_and_each_epoch_with_cumulative_time():
    module, residual, train, val = _problem()
    hist = Adam(lr=0.05, max_epochs=5).fit(module, residual, train, val)
    assert hist.stop_reason == "max_epochs" and hist.epochs == 5
    assert len(hist.time) == len(hist.train) == len(hist.validation) == 6  # start + 5
    assert all(0 < a < b for a, b in zip(hist.time, hist.time[1:], strict=False))
    assert hist.validation[hist.best_epoch] == min(hist.validation)
    assert hist.train[-1] < hist.train[0]


def test_max_seconds_stops_after_the_first_epoch_past_the_cap():
    module, residual, train, val = _problem()
    hist = Adam(lr=0.05, max_epochs=1000, max_seconds=0.0).fit(module, residual, train, val)
    assert hist.stop_reason == "max_seconds" and hist.epochs == 1
    # without validation batches the cap applies too
    hist = Adam(lr=0.05, max_epochs=1000, max_seconds=0.0).fit(module, residual, train)
    assert hist.stop_reason == "max_seconds" and hist.epochs == 1 and hist.validation == []


def test_cosine_schedule_is_the_closed_form_and_plateau_halves():
    module, residual, train, val = _problem()
    hist = Adam(lr=0.1, lr_min=0.001, max_epochs=9).fit(module, residual, train, val)
    expected = [0.001 + 0.5 * 0.099 * (1 + math.cos(math.pi * e / 8)) for e in range(9)]
    assert all(
        math.isclose(a, b, rel_tol=1e-9) for a, b in zip(hist.extra["lr"], expected, strict=True)
    )
    # a validation loss that never improves (a constant): the rate halves every 2 epochs
    module, residual, train, _ = _problem()
    flat = [(torch.zeros(4, 3), torch.zeros(4, 1) + 1e3)]
    hist = Adam(lr=0.08, schedule="plateau", plateau=2, max_fail=100, max_epochs=7).fit(
        module, lambda p, b: residual(p, b) * 0 + 1.0, train, flat
    )
    assert hist.extra["lr"] == [0.08, 0.08, 0.04, 0.04, 0.02, 0.02, 0.01]
    # a rate under the default floor (1e-4) stays put; the cosine rose to the floor before
    module, residual, train, val = _problem()
    hist = Adam(lr=5e-5, max_epochs=5).fit(module, residual, train, val)
    assert hist.extra["lr"] == [5e-5] * 5


def test_progress_reports_every_epoch():
    module, residual, train, val = _problem()
    calls = []
    hist = Adam(max_epochs=3).fit(
        module, residual, train, val, progress=lambda *a, **k: calls.append((a, k))
    )
    assert [(d, t) for (d, t, _), _ in calls] == [(1, 3), (2, 3), (3, 3)]
    assert all("validation" in m for (*_, m), _ in calls)
    # the epoch's scores as keywords, for a tuner (nnid sweep on Ray Tune)
    assert [k["validation"] for _, k in calls] == hist.validation[1:]
    assert [k["train"] for _, k in calls] == hist.train[1:]


def _diverged_while_poor(limit: float):
    """The problem of :func:`_problem` with a validation residual like a free run's: NaN (the
    run diverged) while the model's worst error exceeds ``limit``."""
    module, residual, train, val = _problem()

    def run(params, batch):
        if batch[0] == "free":
            r = residual(params, batch[1])
            return r if float(r.abs().max()) < limit else torch.full_like(r, math.nan)
        return residual(params, batch)

    return module, run, train, [("free", val[0])]


def test_a_diverged_validation_run_is_a_failure_not_the_end_of_the_fit():
    """The validation free run diverged at the start and while the model was poor: those are
    failures, and the first finite score is the best. A NaN validation used to end the fit
    ("non-finite loss") with the start's weights, though training itself was sound."""
    module, residual, train, val = _diverged_while_poor(limit=4.0)
    start = module.weight.detach().clone()
    hist = Adam(lr=0.1, max_epochs=200, max_fail=10).fit(module, residual, train, val)
    assert math.isnan(hist.validation[0]) and math.isnan(hist.validation[1])
    assert hist.stop_reason != "non-finite loss" and hist.best_epoch > 1
    assert math.isfinite(hist.validation[hist.best_epoch])
    assert not torch.equal(module.weight.detach(), start)


def test_a_validation_run_that_always_diverges_stops_after_max_fail():
    module, residual, train, val = _diverged_while_poor(limit=-1.0)
    start = module.weight.detach().clone()
    hist = Adam(lr=0.05, max_epochs=200, max_fail=5).fit(module, residual, train, val)
    assert hist.stop_reason == "validation diverged" and hist.epochs == 5 and hist.best_epoch == 0
    assert torch.equal(module.weight.detach(), start)


def test_a_batch_whose_loss_is_not_finite_takes_no_step_and_the_fit_goes_on():
    """A batch with a NaN row (a training segment that diverged) in the first epoch: its NaN
    gradient, through clipping and Adam's moments, made every weight NaN, and the fit stopped
    ("non-finite loss") on its start. It now takes no step, is counted, and the rest train."""
    module, residual, train, val = _problem()

    def run(params, batch):
        r = residual(params, batch[1])
        return torch.cat([r, r[:1] * math.nan]) if batch[0] == "diverged" else r

    def epoch(k):
        batches = [("ok", b) for b in train]
        return [("diverged", train[0]), *batches] if k == 0 else batches

    hist = Adam(lr=0.05, max_epochs=5).fit(module, run, epoch, [("ok", val[0])])
    assert hist.stop_reason == "max_epochs" and hist.info["skipped_batches"] == 1
    assert math.isfinite(hist.train[1])  # the error of the batches that were measured
    assert bool(torch.isfinite(module.weight).all())
    assert hist.best_epoch == 5 and hist.validation[-1] < hist.validation[0]
    # without validation the training error is the stopping score: a NaN there (the skipped
    # batch counted in) never read as a best epoch, and the fit went back to its start
    module, residual, train, val = _problem()
    start = module.weight.detach().clone()
    diverging = [("diverged", train[0]), *[("ok", b) for b in train]]
    hist = Adam(lr=0.05, max_epochs=5).fit(module, run, diverging, None)
    assert hist.info["skipped_batches"] == 5 and hist.best_epoch == 5
    assert not torch.equal(module.weight.detach(), start)
    # an epoch none of whose batches can step ends the fit, its start kept
    module, residual, train, val = _problem()
    start = module.weight.detach().clone()
    hist = Adam(lr=0.05, max_epochs=5).fit(module, run, [("diverged", b) for b in train], None)
    assert hist.stop_reason == "non-finite loss" and hist.epochs == 1
    assert torch.equal(module.weight.detach(), start)


def test_weight_decay_leaves_the_unpenalised_parameters_alone():
    # a neural state-space fit's free initial states are no weights: named unpenalised, x0
    # reaches the data's value, 1 (decayed too, it stopped near 1 / (1 + decay) = 0.5), while
    # the weight, which no data holds, decays to 0
    module = torch.nn.Module()
    module.w = torch.nn.Parameter(torch.ones(()))
    module.x0 = torch.nn.Parameter(torch.zeros(()))

    def residual(params, batch):
        return torch.stack([params["x0"] - 1.0, 0.0 * params["w"]])

    trainer = Adam(lr=0.02, max_epochs=300, schedule="constant", clip=None, weight_decay=1.0)
    trainer.fit(module, residual, [None], unpenalised=["x0"])
    assert float(module.x0.detach()) == pytest.approx(1.0, abs=0.01)
    assert abs(float(module.w.detach())) < 0.01
