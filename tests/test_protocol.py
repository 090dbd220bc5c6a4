"""The model protocol (issue 12, ARCHITECTURE.md "The model protocol"): every model kind runs
through the same checks on a small log of a vehicle that is not a preset.

Fit; predict in one-step, k-step and free-run modes on the log's index; residual; save ->
``nnid.load_model`` -> identical predictions; strict-JSON ``params`` and ``describe``; a clear
error before ``fit``; identical refits; no process-wide state changed (torch's and NumPy's
global generators, torch's thread count, matplotlib's backend, the warning filters); and
scikit-learn's ``get_params``/``set_params``/``clone``.
"""

from __future__ import annotations

import functools
import json
import os
import pickle
import re
import signal
import warnings
from importlib import resources
from pathlib import Path

import matplotlib
import numba
import numpy as np
import pandas as pd
import pytest
import torch
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from nnid import load_model
from nnid.datasets.simulator import simulate
from nnid.errors import NnidInputError
from nnid.loop.scenarios import effect_log
from nnid.models.base import MODEL_KINDS, model_class
from nnid.models.caccia import CacciaModel
from nnid.models.ensemble import EnsembleModel
from nnid.models.hybrid import HybridModel
from nnid.models.narx import NarxModel
from nnid.models.neural_state_space import NeuralStateSpace
from nnid.models.parametric import ParametricModel
from nnid.models.sindy import SindyDamping
from nnid.models.synthesis import SynthesisModel
from nnid.serialization import read_json
from nnid.threads import numba_threads, torch_threads
from nnid.trainers.adam import Adam
from nnid.trainers.caccia import CacciaTwoStep
from nnid.trainers.least_squares import LeastSquares
from nnid.trainers.levenberg_marquardt import LevenbergMarquardt
from nnid.trainers.neural_ode import MultipleShooting
from nnid.vehicle import load_vehicle

MINIROV = resources.files("nnid.demo_data").joinpath("minirov.toml")
K = 3  # the k of the k-step mode checked


@pytest.fixture(scope="module")
def minirov():
    return load_vehicle(str(MINIROV))


@pytest.fixture(scope="module")
def runs(minirov) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Three 30 s runs at 20 Hz, every DOF excited (DVL, gyro, depth, attitude): two to fit,
    one held out."""
    log = effect_log(minirov, duration=90.0, n_experiments=3, seed=4)
    return log[log["experiment"] != "run2"], log[log["experiment"] == "run2"]


@pytest.fixture(scope="module")
def heave_campaign(minirov) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Caccia's campaign for the minirov's heave: constant-force plateaus both ways and a
    sinusoid run (exact measurements), and a held-out sinusoid at another offset."""
    dt = 0.1

    def run(force: np.ndarray, name: str) -> pd.DataFrame:
        inputs = np.zeros((force.size, 6))
        inputs[:, 2] = force
        return simulate(minirov, inputs, dt, substeps=5, experiment=name)

    levels = np.repeat([15.0, -15.0, 30.0, -30.0, 45.0, -45.0], 300)
    t = np.arange(600) * dt
    train = pd.concat(
        [run(levels, "steady"), run(30.0 + 20.0 * np.sin(1.2 * t), "sinusoid")],
        ignore_index=True,
    )
    return train, run(25.0 + 15.0 * np.sin(0.8 * t), "held_out")


BUILDERS = {
    "fossen": lambda v: ParametricModel(
        v, ["added_mass", "damping"], trainer=LeastSquares(filter_lambda=1.0)
    ),
    "caccia": lambda v: CacciaModel(v, dof="w"),
    "synthesis": lambda v: SynthesisModel(v, mask="fossen", filter_lambda=1.0),
    "sindy": lambda v: SindyDamping(v, thresholds=[0.01, 0.05, 0.2], filter_lambda=1.0),
    "narx": lambda v: NarxModel(
        ["tau_X", "tau_Z", "tau_N"],
        ["u", "w", "r"],
        2,
        2,
        hidden=(4,),
        trainer=LevenbergMarquardt(max_epochs=4),
        lm_samples=400,
        seed=3,
    ),
    "state_space": lambda v: NeuralStateSpace(
        ["tau_X", "tau_Z"],
        ["u", "w"],
        hidden_states=1,
        hidden=4,
        warmup=5,
        windows=(20,),
        trainer=Adam(max_epochs=3, lr=0.01),
        seed=3,
    ),
    "hybrid": lambda v: HybridModel(
        v,
        physics="joint",
        hidden=(6,),
        segments=(0.5,),
        validation_window=5.0,
        trainer=Adam(max_epochs=3, lr=0.01),
        seed=3,
    ),
    "ensemble": lambda v: EnsembleModel(
        NarxModel(["tau_X", "tau_Z"], ["u", "w"], 2, 2, hidden=(3,), trainer=Adam(max_epochs=2)),
        seeds=(3, 4),
    ),
}


def test_every_registered_kind_is_checked():
    assert set(BUILDERS) == set(MODEL_KINDS)
    for kind in MODEL_KINDS:
        assert model_class(kind).kind == kind


def _data(kind, runs, heave_campaign):
    return heave_campaign if kind == "caccia" else runs


def _global_state() -> dict:
    """What a fit must leave as it found it in the user's process."""
    return {
        # numba first: its first call starts its OpenMP layer, which resets the count torch
        # reads (numba's doing, not the fit's)
        "numba threads": numba.get_num_threads(),
        "torch seed": torch.initial_seed(),
        "torch rng": torch.get_rng_state().clone(),
        "numpy rng": np.random.get_state()[1].copy(),  # noqa: NPY002 (the user's generator)
        "torch threads": torch.get_num_threads(),
        "default dtype": torch.get_default_dtype(),
        "grad mode": torch.is_grad_enabled(),
        "backend": matplotlib.get_backend(),
        "warning filters": list(warnings.filters),
        "environment": dict(os.environ),
        "cwd": os.getcwd(),
        "sigterm": signal.getsignal(signal.SIGTERM),
    }


@pytest.fixture(scope="module")
def fitted(minirov, runs, heave_campaign):
    """Each kind fitted (at the session's thread counts: the models the tests use); the
    global state before and after a second fit of each. The first round also imports what
    third-party modules import lazily on first use (torch's sympy, ...), which may add
    warning filters of their own, which is not nnid changing state. The second runs on
    every numba thread and 2 torch threads: under pytest-xdist both are 1, and a fit that
    left one of them at 1 would pass unseen."""
    models = {
        kind: build(minirov).fit(*_data(kind, runs, heave_campaign))
        for kind, build in BUILDERS.items()
    }
    out = {}
    with numba_threads(numba.config.NUMBA_NUM_THREADS), torch_threads(2):
        for kind, build in BUILDERS.items():
            before = _global_state()
            build(minirov).fit(*_data(kind, runs, heave_campaign))
            out[kind] = (models[kind], before, _global_state())
    return out


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_predict_modes_on_the_logs_index(kind, fitted, runs, heave_campaign):
    model, *_ = fitted[kind]
    _, val = _data(kind, runs, heave_campaign)
    val = val.set_axis(np.arange(len(val)) * 3 + 7)  # any index: predictions follow it
    for mode, steps in (("one_step", 1), (K, K), ("free_run", 1)):
        pred = model.predict(val, mode)
        assert pred.index.equals(val.index) and list(pred.columns) == model.outputs_
        first = model.warmup_samples_ + steps - 1  # initial conditions, not predictions
        targets = pred[model.targets_].to_numpy()
        assert np.isnan(targets[:first]).all()
        assert np.isfinite(targets[first:]).all(), (kind, mode)
    residual = model.residual(val)
    assert residual.index.equals(val.index) and len(residual.columns) >= 1
    with pytest.raises(ValueError, match="prediction mode"):
        model.predict(val, 0)


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_save_load_reproduces_predictions(kind, fitted, runs, heave_campaign, tmp_path):
    model, *_ = fitted[kind]
    _, val = _data(kind, runs, heave_campaign)
    model.save(tmp_path)
    saved = read_json(tmp_path / "model.json")  # strict: NaN or Infinity would raise
    assert saved["kind"] == kind and saved["schema_version"] == 1
    back = load_model(tmp_path)
    assert type(back) is type(model)
    for mode in ("one_step", K, "free_run"):
        np.testing.assert_allclose(
            back.predict(val, mode).to_numpy(), model.predict(val, mode).to_numpy(), rtol=1e-12
        )
    pd.testing.assert_frame_equal(back.residual(val), model.residual(val))
    assert back.params == model.params
    # what fitted it and how long it took, as reported before saving (a loaded Caccia model
    # named its trainer "method", a hybrid "adam" where "shooting" fitted it)
    assert back.describe() == model.describe()
    assert model.trainer_name() == TRAINER_NAMES[kind]
    assert back.trainer_name() == model.trainer_name()
    if kind == "hybrid":  # and its physics fit's ("ls", None after loading): least squares
        assert model.baseline().trainer_name() == LeastSquares.kind  # physics_trainer None
        assert back.baseline().trainer_name() == model.baseline().trainer_name()


#: what fits each of BUILDERS' models, by its settings there: the trainer given (NARX's LM,
#: the state space's Adam, the ensemble's members' Adam), the hybrid's multiple shooting that
#: steps its Adam, Caccia's two steps, synthesis' default method "ls", SINDy's default
#: optimizer "stlsq"
TRAINER_NAMES = {
    "fossen": LeastSquares.kind,
    "caccia": CacciaTwoStep.kind,
    "synthesis": "masked least squares",
    "sindy": "pysindy stlsq",
    "narx": LevenbergMarquardt.kind,
    "state_space": Adam.kind,
    "hybrid": MultipleShooting.kind,
    "ensemble": Adam.kind,
}


#: what a fit records beside what it learned: the cleaning steps of its data, the added masses
#: biased by errors in variables, the trainer's per-epoch history
FIT_RECORD = ("report_", "attenuated_", "history_")


def _fit_record(model) -> dict:
    """A model's fit record, comparable after a JSON round trip (a History by its fields)."""
    from dataclasses import asdict

    from nnid.trainers.history import History

    def plain(value):
        if isinstance(value, History):
            return asdict(value)
        if isinstance(value, list):
            return [plain(v) for v in value]
        return value.to_dict() if hasattr(value, "to_dict") else value

    return {a: plain(getattr(model, a)) for a in FIT_RECORD if hasattr(model, a)}


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_save_load_keeps_the_fit_record(kind, fitted, tmp_path):
    """A loaded model lacked the report_ (its data's cleaning steps), attenuated_ and
    history_ the fitted one had (a NARX's history_ was its summary dict, without the time
    series, where the fitted model's is a History): saved in model.json and restored, for
    each kind, an ensemble's members and a hybrid's physics fit."""
    model, *_ = fitted[kind]
    model.save(tmp_path)
    back = load_model(tmp_path)
    pairs = [(model, back)]
    if kind == "ensemble":
        pairs += list(zip(model.members_, back.members_, strict=True))
    if kind == "hybrid":
        pairs.append((model.baseline(), back.baseline()))
    held = set()
    for fit, loaded in pairs:
        record = _fit_record(fit)
        held |= set(record)
        np.testing.assert_equal(_fit_record(loaded), record)
        for name in record:
            assert type(getattr(loaded, name)) is type(getattr(fit, name)), name
    expected = {
        "fossen": {"report_", "attenuated_"},
        "hybrid": set(FIT_RECORD),
        "narx": {"history_"},
        "state_space": {"history_"},
        "ensemble": {"history_"},
    }
    assert held == expected.get(kind, set())  # fmt: skip


def test_a_model_saved_over_another_leaves_none_of_its_files(fitted, tmp_path):
    """A network's tensors.pt stayed beside a least-squares model saved into its folder
    later: a folder that held two models' files."""
    fitted["narx"][0].save(tmp_path)
    assert (tmp_path / "tensors.pt").exists()
    fitted["fossen"][0].save(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.json"]
    assert load_model(tmp_path).kind == "fossen"


def test_a_tensors_file_another_save_wrote_is_refused(fitted, tmp_path):
    """model.json and tensors.pt are written one after the other (and a run's are moved into
    --out one by one): a save cut between them left one save's tensors beside another's
    model.json, which loaded them without a word. model.json records their sha256."""
    narx, fossen = fitted["narx"][0], fitted["fossen"][0]
    narx.save(tmp_path / "narx")
    tensors = torch.load(tmp_path / "narx" / "tensors.pt", weights_only=True)
    name = next(k for k, v in tensors.items() if v.is_floating_point())
    tensors[name] = tensors[name] + 1.0  # another fit's weights: finite, of the same shapes
    torch.save(tensors, tmp_path / "narx" / "tensors.pt")
    with pytest.raises(NnidInputError, match=r"tensors\.pt does not belong to model\.json") as err:
        load_model(tmp_path / "narx")
    assert err.value.source == str(tmp_path / "narx")
    # a model without tensors beside a tensors.pt: not its own either
    fossen.save(tmp_path / "fossen")
    (tmp_path / "fossen" / "tensors.pt").write_bytes(
        (tmp_path / "narx" / "tensors.pt").read_bytes()
    )
    with pytest.raises(NnidInputError, match="does not belong") as err:
        load_model(tmp_path / "fossen")
    assert err.value.source == str(tmp_path / "fossen")
    # a model.json saved before the hash was kept loads as it did, unchecked
    saved = read_json(tmp_path / "narx" / "model.json")
    del saved["tensors_sha256"]
    (tmp_path / "narx" / "model.json").write_text(json.dumps(saved))
    assert load_model(tmp_path / "narx").kind == "narx"


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_a_damaged_saved_model_is_one_input_error_naming_the_file(kind, fitted, tmp_path):
    """A model.json edited by hand (a key gone, a setting unknown) or a tensors.pt cut short
    is an NnidInputError naming the file, never a KeyError or an unpickling error."""
    from nnid.errors import NnidInputError

    model, *_ = fitted[kind]
    model.save(tmp_path)
    good = read_json(tmp_path / "model.json")
    damage = {
        "no settings": lambda p: p.pop("settings"),
        "unknown setting": lambda p: p["settings"].update(bogus=1),
        "no state": lambda p: p.pop("state"),
        "warm-up as text": lambda p: p.update(warmup_samples="two"),
        # values of the right type that no fit writes: they loaded and predicted
        "negative warm-up": lambda p: p.update(warmup_samples=-5),
        "fractional warm-up": lambda p: p.update(warmup_samples=2.5),
    }
    for edit in damage.values():
        broken = json.loads(json.dumps(good))
        edit(broken)
        (tmp_path / "model.json").write_text(json.dumps(broken))
        with pytest.raises(NnidInputError, match=r"model\.json: damaged"):
            load_model(tmp_path)
    if (tmp_path / "tensors.pt").exists():
        (tmp_path / "model.json").write_text(json.dumps(good))
        (tmp_path / "tensors.pt").write_bytes(b"cut sh")
        with pytest.raises(NnidInputError, match=r"tensors\.pt: damaged"):
            load_model(tmp_path)
        # a pickle of objects: refused without torch's advice to load it unsafely
        (tmp_path / "tensors.pt").write_bytes(pickle.dumps({"w": Path("x")}))
        with pytest.raises(NnidInputError, match="never code from a file") as err:
            load_model(tmp_path)
        assert "weights_only" not in str(err.value)
        model.save(tmp_path)
        tensors = torch.load(tmp_path / "tensors.pt", weights_only=True)
        name = next(k for k, v in tensors.items() if v.is_floating_point())
        tensors[name] = tensors[name].clone().fill_(float("nan"))
        torch.save(tensors, tmp_path / "tensors.pt")
        with pytest.raises(NnidInputError, match=rf"tensors\.pt: '{re.escape(name)}' holds NaN"):
            load_model(tmp_path)
    for version in (0, 2):
        (tmp_path / "model.json").write_text(json.dumps({**good, "schema_version": version}))
        with pytest.raises(NnidInputError, match="versions 1 to 1"):
            load_model(tmp_path)


def _set(*path):
    """An edit of a saved model.json: the value at ``path[:-1]`` set to ``path[-1]``."""

    def edit(payload: dict) -> None:
        *keys, last, value = path
        for key in keys:
            payload = payload[key]
        payload[last] = value

    return edit


#: hand edits of a saved model's state or settings that loaded, and then failed inside the
#: first prediction or describe() with a ValueError, TypeError or IndexError of their own
LOADED_THEN_FAILED = {
    ("synthesis", "unknown term"): _set("state", "terms", 0, "x"),
    ("synthesis", "no standard errors"): _set("state", "stderr", []),
    ("synthesis", "unknown mask"): _set("settings", "mask", "x"),
    ("sindy", "unknown term"): _set("state", "terms", 0, "x"),
    ("sindy", "unknown mode"): _set("settings", "mode", "x"),
    ("narx", "bounds of no output"): _set("state", "bounds", []),
    ("narx", "bounds as a number"): _set("state", "bounds", 2.5),
    ("state_space", "one bound"): _set("state", "bounds", [[1.0]]),
    ("ensemble", "a member's bounds as text"): _set("state", "members", 0, "state", "bounds", "x"),
}


#: hand edits of a saved fit record (FIT_RECORD) that no fit writes: refused at loading, never
#: a report_, attenuated_ or history_ that fails when read
FIT_RECORD_DAMAGED = {
    ("fossen", "a report step as a number"): _set("state", "report", "steps", [1]),
    ("fossen", "a report without steps"): _set("state", "report", {"source": "x"}),
    ("fossen", "attenuation of no unknown"): _set("state", "attenuated", {"X_vdot": [0.2, 1.0]}),
    ("fossen", "attenuation of one number"): _set("state", "attenuated", {"X_udot": [0.2]}),
    ("narx", "history as text"): _set("state", "fit_history", "x"),
    ("narx", "history's train as text"): _set("state", "fit_history", "train", "x"),
    ("state_space", "history's time of text"): _set("state", "fit_history", 0, "time", ["x"]),
    ("hybrid", "history without train"): lambda p: p["state"]["fit_history"][0].pop("train"),
    ("hybrid", "physics' report as a list"): _set("state", "physics", "report", []),
    ("synthesis", "an estimated term as unidentified"): _set("state", "unidentified", ["X:u"]),
    ("synthesis", "unidentified off the mask"): _set("state", "unidentified", ["X:v"]),
}


@pytest.mark.parametrize(("kind", "damage"), [*LOADED_THEN_FAILED, *FIT_RECORD_DAMAGED])
def test_a_damaged_state_is_refused_at_loading_not_at_use(kind, damage, fitted, tmp_path):
    from nnid.errors import NnidInputError

    model, *_ = fitted[kind]
    model.save(tmp_path)
    broken = read_json(tmp_path / "model.json")
    {**LOADED_THEN_FAILED, **FIT_RECORD_DAMAGED}[kind, damage](broken)
    (tmp_path / "model.json").write_text(json.dumps(broken))
    with pytest.raises(NnidInputError, match=r"model\.json: damaged"):
        load_model(tmp_path)


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_params_and_describe_are_strict_json(kind, fitted):
    model, *_ = fitted[kind]
    for part in (model.params, model.describe()):
        json.dumps(part, allow_nan=False)  # raises on NaN, infinity or a non-JSON type
    for entry in model.params.values():
        assert {"value", "stderr"} <= set(entry)
    assert model.describe()["kind"] == kind and model.n_params >= 1


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_use_before_fit_is_one_clear_error(kind, minirov, runs, tmp_path):
    model = BUILDERS[kind](minirov)
    _, val = runs
    for use in (
        lambda: model.predict(val),
        lambda: model.residual(val),
        lambda: model.params,
        lambda: model.describe(),
        lambda: model.save(tmp_path),
    ):
        with pytest.raises(NotFittedError, match="not fitted yet: call fit"):
            use()


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_refit_with_the_same_seed_is_identical(kind, fitted, minirov, runs, heave_campaign):
    model, *_ = fitted[kind]
    train, val = _data(kind, runs, heave_campaign)
    again = clone(model).fit(train, val)
    # Same seed, same numbers to rounding: torch's MKL BLAS may pick kernels by buffer
    # alignment (no conditional numerical reproducibility), so a refit in the same process can
    # differ in the last bits (5e-15 seen in a NARX under pytest-xdist), never more
    np.testing.assert_allclose(
        again.predict(val, "free_run").to_numpy(),
        model.predict(val, "free_run").to_numpy(),
        rtol=1e-10,
        atol=1e-13,
    )


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_fit_leaves_process_wide_state_alone(kind, fitted):
    _, before, after = fitted[kind]
    before, after = dict(before), dict(after)
    assert torch.equal(after.pop("torch rng"), before.pop("torch rng"))  # untouched
    assert np.array_equal(after.pop("numpy rng"), before.pop("numpy rng"))
    assert after == before
    assert before["torch threads"] == 2  # the fit ran at a count it does not set itself


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_scikit_learn_params_round_trip(kind, minirov):
    model = BUILDERS[kind](minirov)
    params = model.get_params(deep=False)
    assert set(params) <= set(model.__init__.__code__.co_varnames)
    twin = clone(model)
    assert type(twin) is type(model) and twin.get_params(deep=False).keys() == params.keys()
    if "seed" in params:
        assert twin.set_params(seed=11).seed == 11 and model.seed != 11
    if "trainer" in params and params["trainer"] is not None:
        deep = model.get_params(deep=True)
        assert any(k.startswith("trainer__") for k in deep)


def test_unidentified_parameter_stderr_stays_null_after_a_round_trip(minirov, runs, tmp_path):
    """A parameter the data cannot excite (a roll-pitch cross added mass on runs that hold the
    vehicle level enough, asked for on purpose) is NaN, reported null, and still null after
    save and load: never a made-up 0."""
    train, _ = runs
    level = train.assign(p=0.0, q=0.0, dp=0.0, dq=0.0)
    with pytest.warns(UserWarning, match="K_qdot"):
        model = ParametricModel(minirov, ["X_udot", "K_qdot"], ["u", "p"]).fit(level)
    assert model.params["K_qdot"]["stderr"] is None and model.params["K_qdot"]["value"] is None
    model.save(tmp_path)
    saved = json.loads((tmp_path / "model.json").read_text())
    assert saved["state"]["theta"][1] is None
    back = load_model(tmp_path)
    assert back.params["K_qdot"] == {
        "value": None,
        "stderr": None,
        "percentile_error": None,
        "significant": False,
        "excited": False,  # least squares' own verdict (a zero column), kept on save
        "simulated_at": 0.0,  # not an estimate: what the model simulates (no term in the file)
    }
    assert back.from_file_ == {"K_qdot": None}
    assert back.params == model.params


_FIRST_PARALLEL_LAUNCH = {
    "integrate_rk4": """
import numpy as np
from nnid.physics import compiled
from nnid.physics.fossen import FossenModel
from nnid.vehicle import load_vehicle
form = FossenModel.from_vehicle(load_vehicle("seamor")).feature_form()
compiled.integrate_rk4(form, np.zeros((4, 12)), np.ones((4, 6000, 6)), 0.01)
""",
    "monitor": """
import warnings
from importlib import resources
from nnid.fault.monitor import ResidualMonitor
from nnid.loop.scenarios import effect_log
from nnid.models.parametric import ParametricModel
from nnid.vehicle import load_vehicle
warnings.simplefilter("ignore")
v = load_vehicle(str(resources.files("nnid.demo_data") / "minirov.toml"))
log = effect_log(v, duration=60.0, n_experiments=2, seed=2)
model = ParametricModel(v, unknowns=()).fit(log[log.experiment == "run0"])
ResidualMonitor(model).fit(log[log.experiment == "run1"])
""",
}


@pytest.mark.parametrize("where", list(_FIRST_PARALLEL_LAUNCH))
def test_a_parallel_kernel_leaves_torchs_thread_count_alone(where):
    """The first numba parallel launch of a process starts its OpenMP layer, which resets the
    OpenMP count torch reads: a monitor's first fit moved a user's 1 thread to 2. Run in a
    fresh interpreter, since it happens once per process."""
    import subprocess
    import sys

    script = (
        "import torch\ntorch.set_num_threads(1)\n"
        + _FIRST_PARALLEL_LAUNCH[where]
        + "\nprint(torch.get_num_threads())\n"
    )
    env = {k: v for k, v in os.environ.items() if not k.endswith("NUM_THREADS")}
    env["NUMBA_NUM_THREADS"] = "2"  # a parallel layer with more than the user's one thread
    out = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=300
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split()[-1] == "1", out.stdout


@pytest.mark.parametrize("kind", ["narx", "state_space", "ensemble"])
def test_a_model_that_counts_samples_refuses_another_rate(kind, fitted, runs, tmp_path):
    """A model whose delays or steps count samples predicts only at the rate it was trained
    at, saved and loaded too (a state-space model fitted at 20 Hz predicted a 10-Hz log
    exactly as the 20-Hz one), and trains on runs of one rate."""
    from nnid.errors import NnidInputError

    model, *_ = fitted[kind]
    train, val = runs
    slow = val.assign(t=val["t"] * 2)
    model.save(tmp_path)
    for m in (model, load_model(tmp_path)):
        with pytest.raises(NnidInputError, match=r"0\.1 s, against 0\.05 s at training") as err:
            m.predict(slow)
        assert err.value.field == "t"
    mixed = pd.concat([train, slow], ignore_index=True)
    with pytest.raises(NnidInputError, match="in its first run"):
        clone(model).fit(mixed)


def test_a_hybrid_trains_on_runs_of_one_rate(minirov, runs):
    """The hybrid's training steps every run at one dt: a 10-Hz run among 20-Hz ones was
    flown at 0.05 s (velocity RMS error 0.24 against 0.005 in prediction)."""
    from nnid.errors import NnidInputError

    train, val = runs
    slow = val.assign(t=val["t"] * 2)
    with pytest.raises(NnidInputError, match="in its first run"):
        BUILDERS["hybrid"](minirov).fit(pd.concat([train, slow], ignore_index=True))
    with pytest.raises(NnidInputError, match="at training") as err:
        BUILDERS["hybrid"](minirov).fit(train, slow)
    assert err.value.field == "t"


def test_a_log_whose_index_repeats_labels_is_one_clear_error(fitted, runs):
    """Runs joined by pd.concat without ignore_index keep their labels twice, and a run's rows
    are found by label: a fit mixed the runs up, a prediction said 'not uniformly sampled' or
    raised pandas' InvalidIndexError. Refused at every entry, saying the fix; not reset, as
    a prediction answers on the log's own index."""
    _, val = runs
    twice = pd.concat([val, val.assign(experiment="copy")])
    said = (
        rf"index repeats {len(val)} labels \(the first: {val.index[0]}\).*pd\.concat without "
        r"ignore_index=True.*log\.reset_index\(drop=True\)"
    )
    for model, *_ in fitted.values():
        uses = [
            (clone(model).fit, twice),
            (functools.partial(clone(model).fit, val), twice),
            (functools.partial(model.predict, mode="one_step"), twice),
            (model.residual, twice),
        ]
        for use, log in uses:
            with pytest.raises(NnidInputError, match=said):
                use(log)


def _in_bursts(log: pd.DataFrame, run: str) -> pd.DataFrame:
    """``log`` with ``run``'s stamps in bursts: five samples 10 us apart every 0.25 s (its
    20 Hz over the run), the other runs as they were."""
    rows = (log["experiment"] == run).to_numpy()
    t, k = log["t"].to_numpy(np.float64).copy(), np.arange(int(rows.sum()))
    t[rows] = 0.25 * (k // 5) + 1e-5 * (k % 5)
    return log.assign(t=t)


@pytest.mark.parametrize("kind", list(BUILDERS))
def test_every_kind_refuses_a_run_whose_stamps_come_in_bursts_before_any_fit(kind, minirov, runs):
    """Every model fits and simulates at a run's typical step, one inside a burst: through
    the Python API the fossen, synthesis and SINDy fits went on, the models that count
    samples said the run 'sampled every 1e-05 s' and Caccia's found no plateau, where the
    pipeline refuses the log before any fit. The protocol's one fit refuses it by the
    pipeline's rule, in the training and in the validation log, naming the run, before the
    model's own fit reports progress."""
    train, val = runs
    said: list[str] = []
    for log, validation in ((_in_bursts(train, "run1"), val), (train, _in_bursts(val, "run2"))):
        run = "run1" if validation is val else "run2"
        with pytest.raises(NnidInputError, match=f"experiment '{run}': its stamps come in") as err:
            BUILDERS[kind](minirov).fit(log, validation, progress=lambda *a: said.append(a))
        assert err.value.field == "t" and "a model's fit and simulation" in err.value.message
    assert said == []


def test_a_fitted_model_and_the_loop_refuse_a_log_whose_stamps_come_in_bursts(minirov, runs):
    """A fitted model's predict, residual and force series step at a run's typical step too,
    as does the residual loop's fit in Python (a bursty log ran the loop at a 10-us step): each
    refuses the log by the pipeline's rule, naming the run."""
    from nnid.loop.residual_loop import ResidualLoop

    train, val = runs
    model = BUILDERS["fossen"](minirov).fit(train, val)
    bursty = _in_bursts(val, "run2")
    calls = [
        lambda: model.predict(bursty),
        lambda: model.residual(bursty),
        lambda: model.force_series(bursty),
        lambda: ResidualLoop(minirov).fit(_in_bursts(train, "run1")),
    ]
    for call in calls:
        with pytest.raises(NnidInputError, match="its stamps come in bursts") as err:
            call()
        assert err.value.field == "t"
