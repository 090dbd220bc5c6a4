"""What a config alone shows wrong, refused as it is read (one NnidInputError naming the file
and the key's dotted path), before any data is loaded, simulated or fitted; and the files a
config names, read beside it, never from the current folder."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
import torch
from conftest import SIM_STEP as SIM

from nnid.config import LoopConfig, SimulateConfig, TrainConfig, load_config
from nnid.errors import NnidInputError

ROOT = Path(__file__).resolve().parents[1]
MINIROV = (ROOT / "nnid" / "demo_data" / "minirov.toml").read_text()

TRAIN = """kind = "train"
vehicle = "seamor"
[data]
log = "log.csv"
[model]
kind = "fossen"
"""

HYBRID = TRAIN.replace('kind = "fossen"', 'kind = "hybrid"')

NARX = """kind = "train"
[data]
log = "log.csv"
[model]
kind = "narx"
inputs = ["tau_X"]
outputs = ["u"]
"""


def refused(tmp_path: Path, text: str, model=TrainConfig) -> NnidInputError:
    """The error reading ``text`` as a config raises (it must raise one)."""
    path = tmp_path / "c.toml"
    path.write_text(text)
    with pytest.raises(NnidInputError) as info:
        load_config(path, model)
    assert info.value.source == str(path), info.value
    return info.value


# -- 1. paths relative to the config -------------------------------------------------------------


def _vehicle(folder: Path, name: str) -> None:
    folder.mkdir(exist_ok=True)
    text = MINIROV.replace('name = "minirov"', f'name = "{name}"')
    assert text != MINIROV
    (folder / "v.toml").write_text(text)


def test_a_config_path_is_read_beside_the_config_not_in_the_current_folder(tmp_path, monkeypatch):
    from nnid.pipeline import check_paths, vehicle_for

    _vehicle(tmp_path / "configs", "beside")
    _vehicle(tmp_path / "here", "here")
    (tmp_path / "here" / "log.csv").write_text("t\n0\n")  # only in the current folder
    monkeypatch.chdir(tmp_path / "here")
    config = tmp_path / "configs" / "c.toml"
    # a file of the same name in the current folder silently won over the one beside it
    assert vehicle_for("v.toml", config).name == "beside"
    # an option's path is the user's, relative to the current folder
    assert vehicle_for("v.toml", config, "--vehicle").name == "here"
    config.write_text(TRAIN)
    with pytest.raises(NnidInputError) as info:
        check_paths(load_config(config, TrainConfig), config, None, None)
    assert info.value.field == "data.log" and str(tmp_path / "configs") in info.value.message


# -- 2. a gain matrix ----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("gain", "said"),
    [
        ("[[1.0, 2.0], [3.0]]", "square"),  # a ragged one: numpy's ValueError, a traceback
        ("[[1.0, 2.0], [0.0, 1.0]]", "symmetric"),
        ("[[-1.0, 0.0], [0.0, -1.0]]", "positive definite"),  # it climbed the error
    ],
)
def test_a_gradient_gain_matrix_is_square_symmetric_and_positive_definite(tmp_path, gain, said):
    err = refused(tmp_path, f'{TRAIN}trainer = {{ kind = "gradient", gain = {gain} }}\n')
    assert err.field == "model.trainer.gain" and said in err.message, err


def test_a_positive_definite_gain_matrix_is_taken(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text(f'{TRAIN}trainer = {{ kind = "gradient", gain = [[2.0, 0.5], [0.5, 1.0]] }}\n')
    assert load_config(path, TrainConfig).model.trainer.gain == [[2.0, 0.5], [0.5, 1.0]]


# -- 3. [reference] before the fit ---------------------------------------------------------------


def test_a_misspelt_reference_is_refused_before_the_split_and_the_fit(tmp_path, monkeypatch):
    import nnid.pipeline as pipeline
    from nnid.datasets.preprocess import CleaningReport
    from nnid.vehicle import load_vehicle

    path = tmp_path / "c.toml"
    path.write_text(TRAIN + 'dofs = ["w"]\nunknowns = ["Z_wdot"]\n[reference]\nZ_wdott = -18.7\n')
    cfg = load_config(path, TrainConfig)
    inputs = pipeline.Inputs(pd.DataFrame(), CleaningReport(source="x"), load_vehicle("seamor"))
    monkeypatch.setattr(pipeline, "loaded_inputs", lambda *a, **k: (inputs, []))

    def no_fit(*args, **kwargs):
        raise AssertionError("split or fitted before the [reference] was checked")

    monkeypatch.setattr(pipeline, "make_split", no_fit)
    monkeypatch.setattr(pipeline, "fit_model", no_fit)
    with pytest.raises(NnidInputError) as info:
        pipeline.run_train(cfg, path)
    assert info.value.field == "reference.Z_wdott" and "'Z_wdot'" in info.value.message


# -- 4, 5, 6, 7, 10, 11: keys the config alone shows dropped or wrong -------------------------


@pytest.mark.parametrize(
    ("text", "model", "field", "said"),
    [
        # 4: the sequence's steps name the unknowns and DOFs; these were dropped unsaid
        (TRAIN + 'sequence = "weiss"\ndofs = ["u"]\n', TrainConfig, "model.dofs", "sequence"),
        (TRAIN + 'sequence = "weiss"\nunknowns = ["X_udot"]\n', TrainConfig, "model.unknowns",
         "sequence"),
        # 5: the log was read, the simulation ignored (its file still required)
        (TRAIN.replace('log = "log.csv"', 'log = "log.csv"\nsimulate = "sim.toml"'), TrainConfig,
         "data.simulate", "not both"),
        # 6: the named runs were held out, the fraction dropped
        ('kind = "loop"\nvalidation = ["b"]\nvalidation_fraction = 0.2\n', LoopConfig,
         "validation_fraction", "gives fractions beside named experiments"),
        # 7: refused only once the log had been loaded or simulated
        (TRAIN + "[split]\nfractions = [0.5, 0.5, 0.5]\n", TrainConfig, "split.fractions",
         "summing to 1"),
        (TRAIN + '[split]\nby = "experiment"\nvalidation = ["a"]\ntest = ["a"]\n', TrainConfig,
         "split.test", "named for both validation and test"),
        (TRAIN + '[split]\nvalidation = ["a"]\n', TrainConfig, "split.validation",
         'only by = "experiment" uses'),
        (TRAIN + '[split]\nby = "experiment"\nvalidation = ["a"]\nfractions = [0.5, 0.5, 0]\n',
         TrainConfig, "split.fractions", "gives fractions beside named experiments"),
        # 10: ".: is a folder, not a TOML file", naming neither the config nor the key
        (SIM.replace('"seamor"', '""'), SimulateConfig, "vehicle", "is empty"),
        (TRAIN.replace('"log.csv"', '" "'), TrainConfig, "data.log", "is empty"),
        # 11: one option made inert by another, accepted without a word
        (TRAIN + 'trainer = "ls"\n', TrainConfig, None, None),  # (the base config is taken)
        (NARX + 'trainer = { kind = "adam", schedule = "cosine", plateau = 3 }\n', TrainConfig,
         "model.trainer.plateau", 'schedule = "cosine"'),
        (NARX + 'trainer = { kind = "adam", schedule = "constant", lr_min = 1e-5 }\n',
         TrainConfig, "model.trainer.lr_min", 'schedule = "constant"'),
        (SIM.replace("dt =", 'substeps = 4\nintegrator = "adaptive"\ndt ='), SimulateConfig,
         "substeps", 'integrator = "adaptive"'),
        (NARX + "simulation_window = 50\n", TrainConfig, "model.simulation_window",
         "simulation_epochs = 0"),
        (NARX + 'lm_samples = 500\ntrainer = "adam"\n', TrainConfig, "model.lm_samples", "Adam"),
        (NARX + "lm_samples = 500\n", TrainConfig, "model.lm_samples", "Adam"),  # Adam: default
        (NARX.replace('log = "log.csv"', 'log = "log.csv"\nnoise_columns = ["u"]'), TrainConfig,
         "data.noise_columns", "noise = 0"),
        (TRAIN.replace("[data]", 'reference_label = "Weiss"\n[data]'), TrainConfig,
         "reference_label", "[reference]"),
        # nnid's RK4 (the LM trainer's) has no adjoint: the physics fit ran, then a traceback
        (HYBRID + 'adjoint = true\n[model.trainer]\nkind = "lm"\n', TrainConfig,
         "model.adjoint", "no adjoint"),
        (HYBRID + 'adjoint = true\nmethod = "nnid_rk4"\n', TrainConfig, "model.adjoint",
         "no adjoint"),
    ],
)  # fmt: skip
def test_what_the_config_alone_shows_is_refused_as_it_is_read(tmp_path, text, model, field, said):
    path = tmp_path / "c.toml"
    path.write_text(text)
    if field is None:
        load_config(path, model)
        return
    err = refused(tmp_path, text, model)
    assert err.field == field and said in err.message, err


@pytest.mark.parametrize(
    "text",
    [
        NARX + "simulation_epochs = 2\nsimulation_window = 50\nlm_samples = 500\ntrainer = 'lm'\n",
        NARX + 'trainer = { kind = "adam", schedule = "plateau", plateau = 3, lr_min = 1e-5 }\n',
        SIM.replace("dt =", 'integrator = "adaptive"\ndt ='),
        NARX.replace('log = "log.csv"', 'log = "log.csv"\nnoise = 0.01\nnoise_columns = ["u"]'),
        TRAIN + 'sequence = "weiss"\n',
        HYBRID + "adjoint = true\n",  # Adam through torchdiffeq
    ],
)
def test_the_same_keys_are_taken_where_they_act(tmp_path, text):
    path = tmp_path / "c.toml"
    path.write_text(text)
    load_config(path, SimulateConfig if 'kind = "simulate"' in text else TrainConfig)


def test_a_reader_configs_root_beside_a_simulation_is_refused_before_either_is_read(tmp_path):
    from nnid.pipeline import check_paths

    (tmp_path / "dive").mkdir()
    (tmp_path / "sim.toml").write_text(SIM)
    (tmp_path / "map.toml").write_text(
        'root = "dive"\n[[sources]]\nfile = "nav.csv"\ntime = "t"\ncolumns = { u = "u" }\n'
    )
    path = tmp_path / "c.toml"
    path.write_text(TRAIN.replace('log = "log.csv"', 'simulate = "sim.toml"\ncolumns = "map.toml"'))
    with pytest.raises(NnidInputError) as info:  # the root's files were read, the simulation not
        check_paths(load_config(path, TrainConfig), path, None, None)
    assert info.value.field == "data.simulate" and "root" in info.value.message
    check_paths(load_config(path, TrainConfig), path, str(tmp_path / "sim.toml"), None)  # --data


# -- 8. seeds ------------------------------------------------------------------------------------


def test_a_seed_is_bounded_so_that_every_seed_derived_from_it_fits_torch(tmp_path):
    from nnid.validation import MAX_SEED

    err = refused(tmp_path, NARX + f"seed = {MAX_SEED + 1}\n")
    assert err.field == "model.seed", err
    path = tmp_path / "c.toml"
    path.write_text(NARX + f"seed = {MAX_SEED}\n")
    assert load_config(path, TrainConfig).model.seed == MAX_SEED
    # NARX's fine-tune seeds each epoch with seed * 100_003 + epoch
    torch.Generator().manual_seed(MAX_SEED * 100_003 + 10**9)


# -- 9. a sweep's values -------------------------------------------------------------------------


def test_a_sweep_tells_true_from_1_and_names_its_grid_entry(tmp_path):
    from nnid.scale.sweep import trials

    err = refused(tmp_path, TRAIN + '[sweep]\ngrid = { "warmup_s" = [1.0, 1.0] }\n')
    assert err.field == 'sweep.grid."warmup_s"' and "lists 1.0 twice" in err.message, err
    path = tmp_path / "c.toml"
    path.write_text(NARX + '[sweep]\ngrid = { "model.seed" = [1, true] }\n')
    with pytest.raises(NnidInputError) as info:  # "lists True twice": True == 1 in Python
        trials(path)
    assert info.value.field == 'sweep.grid."model.seed"', info.value
    assert "the value True" in info.value.message and "twice" not in info.value.message
    path.write_text(NARX + '[sweep]\nrandom = { "model.hidden" = [[4], [0]] }\nsamples = 4\n')
    with pytest.raises(NnidInputError) as info:  # was said as the config's model.hidden
        trials(path)
    assert info.value.field == 'sweep.random."model.hidden"', info.value
    assert "[0]" in info.value.message and "model.hidden.0" in info.value.message
