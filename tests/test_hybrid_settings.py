"""The hybrid's settings given in Python (the config checks its own) and the held-out
windows its early stopping flies."""

from __future__ import annotations

import warnings
from importlib import resources
from types import SimpleNamespace
from typing import ClassVar

import numpy as np
import pandas as pd
import pytest
import torch

from nnid.datasets.log import TAU
from nnid.datasets.simulator import Autopilot
from nnid.errors import NnidInputError
from nnid.evaluation.prediction import Replay
from nnid.loop.scenarios import effect_log
from nnid.models.hybrid import HybridModel
from nnid.models.io_model import seeded_linear
from nnid.trainers.adam import Adam
from nnid.trainers.history import History
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
from nnid.trainers.neural_ode import MultipleShooting, Run
from nnid.vehicle import load_vehicle

MINIROV = str(resources.files("nnid.demo_data").joinpath("minirov.toml"))
NAN = float("nan")


@pytest.fixture(scope="module")
def short_log():
    return effect_log(load_vehicle(MINIROV), duration=20.0, n_experiments=2, seed=5)


@pytest.mark.parametrize(
    ("field", "settings"),
    [
        ("hidden", {"hidden": (NAN,)}),  # int(nan): a bare ValueError
        ("hidden", {"hidden": (1.5,)}),  # trained one unit wide
        ("hidden", {"hidden": 8}),  # 'int' object is not iterable
        ("memory", {"memory": (NAN,)}),  # trained to a non-finite loss
        ("force_penalty", {"force_penalty": NAN}),
        ("prior", {"prior": NAN}),
        ("prior_weight", {"prior_weight": -1.0}),  # was named force_penalty
        ("segments", {"segments": (NAN,)}),  # round(nan): a bare ValueError
        ("segments", {"segments": (float("inf"),)}),
        ("validation_window", {"validation_window": NAN}),
        ("batch_segments", {"batch_segments": 0}),  # trained in batches of one
        ("seed", {"seed": -1}),  # numpy's bare ValueError
        ("trainer", {"trainer": "sgd"}),  # AttributeError
        ("lr", {"trainer": Adam(lr=NAN)}),  # torch's "Invalid learning rate"
        ("lr", {"trainer": Adam(lr=0.0)}),  # ran its epochs without moving
        ("max_epochs", {"trainer": Adam(max_epochs=-1)}),  # no epoch, said "max_epochs"
        ("max_fail", {"trainer": Adam(max_fail=0)}),  # stopped after one epoch
        # nnid's RK4 has no adjoint: a bare ValueError at the first batch, after the physics fit
        ("adjoint", {"trainer": LevenbergMarquardt(max_epochs=1), "adjoint": True}),
        ("adjoint", {"method": "nnid_rk4", "adjoint": True}),
        ("adjoint", {"adjoint": "yes"}),
    ],
)
def test_a_bad_setting_is_one_error_naming_its_field(short_log, field, settings):
    settings = {"trainer": Adam(max_epochs=1), "segments": (0.5,), "hidden": (4,), **settings}
    first = short_log["experiment"] == short_log["experiment"].iloc[0]
    model = HybridModel(load_vehicle(MINIROV), **settings)
    with pytest.raises(NnidInputError, match=rf"^field '{field}': "):
        model.fit(short_log[first], short_log[~first])


class _Recorder:
    """An optimiser that records the held-out windows it is given and trains nothing."""

    kind = "adam"
    seen: ClassVar[list[list[tuple[int, int]]]] = []

    def fit(self, module, loss, batches, val_batches, progress=None) -> History:
        _Recorder.seen.append([tuple(b.inputs.shape[:2]) for b in val_batches or []])
        return History()


def _run(n: int) -> Run:
    return Run(torch.zeros(n, 12), torch.zeros(n, 6), torch.zeros(n, 1), np.zeros(n, bool))


@pytest.mark.parametrize(
    ("window", "expected"),
    [(5.0, [(2, 100), (1, 40)]), (None, [(1, 199), (1, 40)])],  # [segments, steps] per batch
)
def test_a_short_validation_run_leaves_the_other_runs_windows_whole(window, expected):
    """A 41-sample validation run beside a 200-sample one: the longer one is still flown in
    windows of validation_window (5 s = 100 samples), or whole; the shortest run set every
    run's window (40 steps: early stopping judged 2-s free runs where 5-s ones were asked)."""
    _Recorder.seen.clear()
    trainer = MultipleShooting(segments=(0.5,), optimizer=_Recorder(), validation_window=window)
    problem = SimpleNamespace(
        module=seeded_linear(1, 1, torch.Generator().manual_seed(0), torch.float64)
    )
    trainer.fit(problem, [_run(200)], 0.05, [_run(200), _run(41)])
    assert _Recorder.seen == [expected]


@pytest.mark.parametrize(
    ("field", "settings", "says"),
    [
        ("hidden", {"hidden": (200_000,)}, "at most 100000"),  # the config's MAX_WIDTH
        ("physics_trainer", {"physics_trainer": "nope"}, "a regression trainer is expected"),
        ("physics_trainer", {"physics_trainer": Adam()}, "cannot fit a Fossen model's"),
        ("dofs", {"dofs": ["x"]}, "'x' is not a DOF"),  # tuple.index(x): a bare ValueError
        ("dofs", {"dofs": "u"}, "a list of DOFs"),
    ],
)
def test_a_bad_physics_setting_is_named_as_the_hybrid_names_it(short_log, field, settings, says):
    """Not capped as the config caps it (hidden), an AttributeError ('str' object has no
    attribute 'fit'), the parametric fit's own name ('trainer', the hybrid's network
    optimiser) and a bare ValueError."""
    settings = {"trainer": Adam(max_epochs=1), "segments": (0.5,), "hidden": (4,), **settings}
    first = short_log["experiment"] == short_log["experiment"].iloc[0]
    model = HybridModel(load_vehicle(MINIROV), **settings)
    with pytest.raises(NnidInputError, match=rf"^field '{field}': .*{says}"):
        model.fit(short_log[first], short_log[~first])


@pytest.mark.parametrize(
    ("field", "settings"), [("trainer", {"trainer": "nope"}), ("dofs", {"dofs": ["x"]})]
)
def test_a_bad_parametric_setting_is_one_error_naming_its_field(short_log, field, settings):
    from nnid.models.parametric import ParametricModel

    with pytest.raises(NnidInputError, match=rf"^field '{field}': "):
        ParametricModel(load_vehicle(MINIROV), **settings).fit(short_log)


@pytest.mark.parametrize("kind", ["fossen", "hybrid"])
def test_unknowns_given_as_one_string_are_refused_as_the_config_refuses_them(short_log, kind):
    """``unknowns="damping"`` was read letter by letter ("unknown parameter 'd'"); the config
    refuses a bare string (a list is expected), and so does ``dofs="u"`` in Python."""
    from nnid.models.parametric import ParametricModel

    vehicle = load_vehicle(MINIROV)
    model = (
        ParametricModel(vehicle, unknowns="damping")
        if kind == "fossen"
        else HybridModel(vehicle, unknowns="damping", trainer=Adam(max_epochs=1), hidden=(4,))
    )
    with pytest.raises(NnidInputError, match=r"^field 'unknowns': unknowns is a list") as err:
        model.fit(short_log)
    assert "['damping']" in err.value.message  # the list it should have been


def test_a_fit_without_validation_says_its_epochs_were_kept_on_the_training_loss(short_log):
    """docs/hybrid.md said early stopping is never on the training error, while a fit
    without validation silently kept each stage's lowest-training-loss epoch."""
    settings = {"trainer": Adam(max_epochs=2), "segments": (0.5,), "hidden": (4,)}
    first = short_log["experiment"] == short_log["experiment"].iloc[0]
    model = HybridModel(load_vehicle(MINIROV), **settings)
    with pytest.warns(UserWarning, match="without validation data .* lowest training loss"):
        model.fit(short_log[first])
    assert model.describe()["kept_on"] == "training loss"
    assert all(stage["validation"] == [] for stage in model.describe()["stages"])
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*without validation data")
        model.fit(short_log[first], short_log[~first])
    assert model.describe()["kept_on"] == "validation free run"


def test_a_fit_without_validation_does_not_say_it_used_validation_for_early_stopping(short_log):
    """``validation_used_for`` (metrics.json) said "early stopping" of a hybrid whose stages
    kept the epochs of their lowest training loss, nothing held out."""
    settings = {"trainer": Adam(max_epochs=2), "segments": (0.5,), "hidden": (4,)}
    first = short_log["experiment"] == short_log["experiment"].iloc[0]
    model = HybridModel(load_vehicle(MINIROV), **settings)
    with pytest.warns(UserWarning, match="without validation data"):
        model.fit(short_log[first])
    assert model.validation_use is None
    model.fit(short_log[first], short_log[~first])
    assert model.validation_use == "early stopping"


def _acting(log) -> HybridModel:
    """An untrained hybrid (its physics fit) whose network then acts, memory channels too."""
    model = HybridModel(load_vehicle(MINIROV), trainer=Adam(max_epochs=0), segments=(0.5,))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # fitted without validation data: said, not tested here
        model.fit(log)
    generator = torch.Generator().manual_seed(1)
    with torch.no_grad():
        for p in model.dynamics_.net.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=generator, dtype=p.dtype))
    return model


def test_predictions_on_an_interleaved_log_are_those_of_the_log_grouped_by_run(short_log):
    """Runs A, B, A (a run's rows need not be contiguous): one-step and k-step windows were
    stepped by row, so A's window before B predicted B's first row from B's inputs, and the
    closed-loop flights flew A on B's open-loop inputs. Each run's predictions are now those
    of the same log with its runs grouped, row for row: the hybrid's, open and closed loop,
    and its physics fit's closed-loop flight (the shared compiled one)."""
    model = _acting(short_log)
    first = short_log["experiment"] == short_log["experiment"].iloc[0]
    a, b = short_log[first].iloc[:80], short_log[~first].iloc[:60]  # short: flown per sample
    half = len(a) // 2
    grouped = pd.concat([a, b])
    interleaved = pd.concat([a.iloc[:half], b, a.iloc[half:]])
    pilot = Autopilot(kp=[0, 0, 20, 0, 0, 0.5], kd=[20, 20, 20, 0.1, 0.1, 0.2])
    flown = {
        "hybrid": lambda log, mode: model.predict(log, mode),
        "hybrid closed loop": lambda log, mode: model.closed_loop(
            log, Replay(pilot, log[list(TAU)]), mode
        ),
        "physics closed loop": lambda log, mode: model.baseline().closed_loop(
            log, Replay(pilot, log[list(TAU)]), mode
        ),
    }
    for name, predict in flown.items():
        for mode in ("one_step", 3, "free_run"):
            expected = predict(grouped, mode)
            got = predict(interleaved, mode).loc[grouped.index]
            assert np.isfinite(expected.to_numpy()[half + 3]).all()
            pd.testing.assert_frame_equal(got, expected, check_exact=False, rtol=1e-12, obj=name)


def test_a_log_in_milliseconds_is_refused_by_the_fit_and_both_predictions(short_log):
    """The hybrid stepped a log with t in milliseconds (20 Hz: a 50-"second" step) without a
    word, training for very long and predicting nonsense; the physics prediction's rule
    (time in seconds) now refuses it, in the fit (training and validation logs) and in both
    predictions."""
    first = short_log["experiment"] == short_log["experiment"].iloc[0]
    train, held = short_log[first], short_log[~first]
    millis = held.iloc[:40].assign(t=held["t"].iloc[:40] * 1000.0)
    settings = {"trainer": Adam(max_epochs=1), "segments": (0.5,), "hidden": (4,)}
    seconds = r"^field 't': .*t must be seconds"
    for fit in (millis, train):
        with pytest.raises(NnidInputError, match=seconds):
            HybridModel(load_vehicle(MINIROV), **settings).fit(fit, millis)
    model = _acting(train)
    with pytest.raises(NnidInputError, match=seconds):
        model.predict(millis, 3)
    with pytest.raises(NnidInputError, match=seconds):
        model.closed_loop(millis, Replay(Autopilot(), millis[list(TAU)]))


def test_a_round_off_input_is_no_input_and_keeps_its_correction(short_log):
    """A DOF whose τ is round-off (1e-13 N m) was scaled by that RMS: its input channel
    was O(1) noise and its correction scaled to 1e-13. Its scale is floored relative to the
    largest of its unit group; the actuated DOFs keep their RMS, as before."""
    log = short_log.copy()
    sign = np.sign(np.sin(np.arange(len(log))))
    log["tau_K"] = 1e-13 * sign
    model = _acting(log)
    _, data = model._data(log, accelerations=False)
    channels = model._channels(log, data["tau"])
    assert np.abs(channels[:, 6 + 3]).max() < 1e-6  # τ_K / σ_K: no O(1) noise
    out = model.dynamics_.net.out_scale.numpy()
    assert out[3] > 1e-3 * out[[4, 5]].max()  # a correction of the moments' size
    rms = np.sqrt(np.mean(data["tau"] ** 2, 0))
    actuated = [0, 1, 2, 4, 5]
    np.testing.assert_array_equal(model.input_scale_[actuated], rms[actuated])
