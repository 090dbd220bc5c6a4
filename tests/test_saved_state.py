"""What a saved model gives back on loading: the state a user reads of the fitted one (the
trainer and its filter history, the excitation verdicts, a history's inf), and a model saved
by an older nnid whose vehicle name a newer check refuses."""

from __future__ import annotations

import json
import math
import os
import warnings

import numpy as np
import pandas as pd
import pytest
import torch

from nnid import load_model
from nnid.datasets.simulator import simulate
from nnid.errors import NnidInputError
from nnid.models.hybrid import HybridModel
from nnid.models.parametric import ParametricModel, vehicle_with
from nnid.reports.train_report import _params_table
from nnid.serialization import dumps, write_json
from nnid.trainers.adam import Adam
from nnid.trainers.history import History, history_state, restored_history
from nnid.trainers.least_squares import Estimate, ExcitationWarning, solve_least_squares
from nnid.trainers.recursive import GradientEstimator, RecursiveLeastSquares
from nnid.trainers.ukf import UnscentedKalman
from nnid.vehicle import load_vehicle, vehicle_from_dict

#: the per-sample series a UKF fit keeps (its history), in the order it saves them
UKF_HISTORY = ("t", "theta", "theta_std", "nu", "innovation", "innovation_std")


@pytest.fixture(scope="module")
def seamor():
    return load_vehicle("seamor")


@pytest.fixture(scope="module")
def surge(seamor):
    """20 s of held surge forces, all forward (u ≥ 0: u|u| and u² are the same column)."""
    rng = np.random.default_rng(1)
    inputs = np.zeros((400, 6))
    inputs[:, 0] = np.repeat(rng.uniform(2.0, 15.0, 10), 40)
    return simulate(seamor, inputs, 0.05)


def _edit(folder, change) -> None:
    """Edit the saved model.json as a hand (or an older nnid) would have written it."""
    saved = json.loads((folder / "model.json").read_text())
    change(saved)
    (folder / "model.json").write_text(json.dumps(saved))


@pytest.fixture(scope="module")
def ukf_model(seamor, surge):
    model = ParametricModel(seamor, ["X_udot", "X:u*abs(u)"], ["u"], trainer=UnscentedKalman())
    with warnings.catch_warnings():  # a noise-free log: the filter says it is underconfident
        warnings.simplefilter("ignore", UserWarning)
        return model.fit(surge)


def test_a_loaded_ukf_model_keeps_its_trainer_and_filter_history(ukf_model, tmp_path):
    """trainer_ was not saved: a UKF-fitted model's filter history (trainer_.history_, the
    per-sample θ, σ_θ, ν and innovation) and the estimate's θ path were gone on loading."""
    model = ukf_model
    model.save(tmp_path)
    back = load_model(tmp_path)
    assert back.trainer_.kind == "ukf" and back.trainer_name() == "ukf"
    fitted = model.trainer_.history_
    assert set(back.trainer_.history_) == set(fitted) == set(UKF_HISTORY)
    for key, series in fitted.items():
        np.testing.assert_array_equal(back.trainer_.history_[key], series)
        assert back.trainer_.history_[key].dtype == np.float64
    np.testing.assert_array_equal(back.estimate_.history, model.estimate_.history)
    # a file saved before these were kept loads as it did: no trainer_, no history
    _edit(tmp_path, lambda s: [s["state"].pop(k) for k in ("trainer_history", "history")])
    (tmp_path / "tensors.pt").unlink()
    old = load_model(tmp_path)
    assert not hasattr(old, "trainer_") and old.estimate_.history is None
    assert old.trainer_name() == "ukf"
    old.save(tmp_path / "again")  # and saved again: still none, not an unfitted trainer_
    again = load_model(tmp_path / "again")
    assert not hasattr(again, "trainer_") and not (tmp_path / "again" / "tensors.pt").exists()


def test_a_ukf_fit_keeps_its_per_sample_series_out_of_model_json(ukf_model, tmp_path):
    """The filter's series went into model.json as indented JSON (146 kB for these 400
    samples, tens of MB for a long log, parsed by every report and load): they are tensors,
    in tensors.pt (float64), and the θ path the estimate repeats is saved once."""
    ukf_model.save(tmp_path)
    saved = json.loads((tmp_path / "model.json").read_text())

    def longest(value) -> int:  # the longest list anywhere in the file
        if isinstance(value, dict):
            return max(map(longest, value.values()), default=0)
        if isinstance(value, list):
            return max([len(value), *map(longest, value)])
        return 0

    assert longest(saved) < 50 and (tmp_path / "model.json").stat().st_size < 10_000
    assert saved["state"]["trainer_history"] == list(UKF_HISTORY)
    assert saved["state"]["history"] == "trainer_history.theta"
    tensors = torch.load(tmp_path / "tensors.pt", weights_only=True)
    assert sorted(tensors) == sorted(
        f"record.trainer_history.{k}" for k in ukf_model.trainer_.history_
    )
    assert all(v.dtype == torch.float64 for v in tensors.values())
    (tmp_path / "tensors.pt").unlink()  # the series named, not there: said, with the file
    with pytest.raises(
        NnidInputError,
        match=r"'record\.trainer_history\.\w+' is not in tensors\.pt\); its tensors\.pt is miss",
    ):
        load_model(tmp_path)


def test_a_recorded_series_may_hold_nan_and_inf_where_a_weight_may_not(seamor, surge, tmp_path):
    """A diverged gradient estimator's θ path runs through inf to NaN: a record, kept as the
    fit wrote it and loadable (load_model refuses a non-finite tensor only among weights); a
    θ path with no trainer history_ (RLS, gradient) is saved under its own name."""
    model = ParametricModel(
        seamor, ["X_udot", "X:u*abs(u)"], ["u"], trainer=GradientEstimator(gain=1e6)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # diverged, and said so
        model.fit(surge)
    path = model.estimate_.history
    assert np.isinf(path).any() and np.isnan(path).any()
    model.save(tmp_path)
    assert json.loads((tmp_path / "model.json").read_text())["state"]["history"] == (
        "estimate.history"
    )
    back = load_model(tmp_path)
    np.testing.assert_array_equal(back.estimate_.history, path)
    assert not hasattr(back.trainer_, "history_")


def test_a_history_keeps_an_infinite_validation_error_through_json():
    """A diverged validation run's inf was written null and read back NaN (undefined, not
    infinitely bad); it is tagged now. Null, as older files hold, still reads NaN; a tag that
    is no non-finite number is refused."""
    hist = History(
        train=[2.0, 1.0, 0.5],
        validation=[1.0, math.inf, math.nan],
        time=[0.0, 0.1, 0.2],
        extra={"mu": [1e-3, -math.inf, 1e-2]},
        info={"peak": math.inf},
    )
    back = restored_history(json.loads(dumps(history_state(hist))))
    assert back.validation[:2] == [1.0, math.inf] and math.isnan(back.validation[2])
    assert back.extra["mu"][1] == -math.inf and back.info["peak"] == math.inf
    assert back.train == hist.train and back.time == hist.time
    older = {**history_state(hist), "validation": [1.0, None, None]}
    assert all(math.isnan(v) for v in restored_history(older).validation[1:])
    with pytest.raises(TypeError, match="validation"):
        restored_history({**history_state(hist), "validation": [{"$float": "1e999"}]})


def test_a_model_saved_with_a_control_character_in_its_vehicle_name_loads(seamor, surge, tmp_path):
    """An older nnid saved vehicle names with control characters that vehicle_name now
    refuses: such a model stays loadable, its name escaped and said; new input is refused."""
    model = ParametricModel(seamor, ["X_udot", "X:u*abs(u)"], ["u"]).fit(surge)
    model.save(tmp_path)
    _edit(tmp_path, lambda s: s["settings"]["vehicle"]["$vehicle"].update(name="sea\nmor\x00"))
    with pytest.warns(UserWarning, match=r"control character.*loaded as 'sea\\\\nmor\\\\x00'"):
        back = load_model(tmp_path)
    assert back.vehicle.name == "sea\\nmor\\x00" and back.describe()["vehicle"] == "sea\\nmor\\x00"
    assert np.array_equal(back.estimate_.theta, model.estimate_.theta)
    data = {**seamor.model_dump(mode="json"), "name": "sea\nmor"}
    with pytest.raises(Exception, match="one line of text"):
        vehicle_from_dict(data, "new.toml")


def test_a_loaded_model_reports_what_least_squares_found_collinear_or_unexcited(
    seamor, surge, tmp_path
):
    """Estimate.from_state dropped the excitation report: a parameter least squares found
    collinear (u|u| and u² on u ≥ 0) or unexcited (a zero column) read "no" in the parameter
    table, a test result it is not. The fitted and the loaded model say why alike."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ExcitationWarning)
        model = ParametricModel(seamor, ["X_udot", "X:u*abs(u)", "X:u*u", "X:v"], ["u"])
        model.fit(surge)
    model.save(tmp_path)
    back = load_model(tmp_path)
    assert back.estimate_.excitation == model.estimate_.excitation
    assert back.estimate_.excitation.condition == math.inf  # tagged, not NaN
    assert back.params == model.params
    cells = {row[0]: row[5] for row in _params_table({"params": back.params})[1]}
    assert cells == {
        "`X_udot`": "yes",
        "`X:u*abs(u)`": "collinear",
        "`X:u*u`": "collinear",
        "`X:v`": "not excited",
    }
    # least squares' own verdict, apart from the model's not_excited_ (X:v is in both)
    phi = np.c_[np.linspace(1.0, 2.0, 50), np.zeros(50)]
    with pytest.warns(ExcitationWarning, match="not excited"):
        est = solve_least_squares(phi, 3.0 * phi[:, 0], names=["a", "b"])
    again = Estimate.from_state(json.loads(dumps(est.as_state())))
    assert again.as_dict()["b"]["excited"] is False and "excited" not in again.as_dict()["a"]


def test_a_model_saved_with_a_thruster_of_no_thrust_loads_and_predicts_as_saved(
    vehicle_factory, tmp_path
):
    """An older nnid saved vehicles whose thrust curve gave no thrust (k = 0), which
    _makes_thrust now refuses: such a model did not load at all. It loads with a warning, the
    thruster giving no thrust: the model predicts what it did, and new input is still refused."""
    push = {"position": [0.0, 0.0, 0.0], "direction": [1.0, 0.0, 0.0]}
    curve = {"kind": "signed_quadratic", "k": 40.0}
    vehicle = vehicle_factory(
        damping={"coefficients": {"X:u*abs(u)": -20.0}},
        thrusters=[{"name": "h1", **push, "curve": curve}, {"name": "h2", **push, "curve": curve}],
    )
    rng = np.random.default_rng(2)
    log = simulate(vehicle, np.repeat(rng.uniform(0.2, 1.0, (10, 2)), 20, axis=0), 0.05)
    model = ParametricModel(vehicle, ["X:u*abs(u)"], ["u"]).fit(log)
    model.save(tmp_path)
    _edit(
        tmp_path,
        lambda s: s["settings"]["vehicle"]["$vehicle"]["thrusters"][1]["curve"].update(k=0.0),
    )
    with pytest.warns(UserWarning, match=r"thruster 'h2' has a thrust curve of no thrust"):
        back = load_model(tmp_path)
    assert back.vehicle.thrusters[1].curve.k == 0.0
    assert "cmd_h2" in log and not np.array_equal(back.predict(log), model.predict(log))
    silent_h2 = log.assign(cmd_h2=0.0)  # k·0·|0| = 0: the thrust of the saved curve
    np.testing.assert_array_equal(back.predict(log), model.predict(silent_h2))
    # a copy with fitted values keeps the saved curve (the loop, explain and fault isolation)
    assert vehicle_with(back.vehicle, {"X:u*abs(u)": -10.0}).thrusters[1].curve.k == 0.0
    data = back.vehicle.model_dump(mode="json")
    with pytest.raises(NnidInputError, match="no thrust at any command"):
        vehicle_from_dict(data, "new.toml")


@pytest.mark.parametrize("separator", ["\u2028", "\u2029"])
def test_a_model_saved_with_a_line_separator_in_its_vehicle_name_loads_on_one_line(
    seamor, surge, separator, tmp_path
):
    """U+2028 and U+2029 are no control characters, yet str.splitlines breaks at them as at a
    line break: a saved model whose vehicle name holds one loads as the control characters'
    do, the name escaped on one line and the warning saying it on one line too."""
    model = ParametricModel(seamor, ["X_udot", "X:u*abs(u)"], ["u"]).fit(surge)
    model.save(tmp_path)
    _edit(
        tmp_path, lambda s: s["settings"]["vehicle"]["$vehicle"].update(name=f"sea{separator}mor")
    )
    escaped = f"sea\\u{ord(separator):04x}mor"
    with pytest.warns(UserWarning, match="line separator") as caught:
        back = load_model(tmp_path)
    (said,) = [str(w.message) for w in caught if "line separator" in str(w.message)]
    assert len(said.splitlines()) == 1 and repr(escaped) in said, said
    assert back.vehicle.name == escaped and back.describe()["vehicle"] == escaped
    assert np.array_equal(back.estimate_.theta, model.estimate_.theta)
    data = {**seamor.model_dump(mode="json"), "name": f"sea{separator}mor"}
    with pytest.raises(Exception, match="one line of text"):
        vehicle_from_dict(data, "new.toml")


@pytest.mark.parametrize("physics_trainer", [RecursiveLeastSquares(), UnscentedKalman()])
def test_a_hybrid_whose_physics_a_recursive_trainer_fitted_loads_and_predicts_as_saved(
    seamor, surge, physics_trainer, tmp_path
):
    """The physics fit's tensors (its per-sample θ path) were left out of the hybrid's
    tensors.pt: the hybrid saved, then failed to load ("'record.estimate.history' is not in
    tensors.pt")."""
    model = HybridModel(
        seamor,
        unknowns=["X_udot", "X:u*abs(u)"],
        dofs=["u"],
        physics_trainer=physics_trainer,
        hidden=(4,),
        memory=(),
        segments=(0.5,),
        trainer=Adam(max_epochs=1),
    )
    with warnings.catch_warnings():  # no validation data, a noise-free log
        warnings.simplefilter("ignore", UserWarning)
        model.fit(surge)
    back = load_model(model.save(tmp_path))
    np.testing.assert_array_equal(
        back.baseline().estimate_.history, model.physics_.estimate_.history
    )
    pd.testing.assert_frame_equal(back.predict(surge), model.predict(surge))


def test_a_history_keeps_a_count_a_whole_number_through_json():
    """An info count (Adam's skipped_batches) came back 3.0 from a saved model, where the
    fitted one said 3; other facts stay numbers, their inf tagged."""
    hist = History(train=[1.0], info={"skipped_batches": 3, "peak": 2.5, "big": math.inf})
    back = restored_history(json.loads(dumps(history_state(hist)))).info
    assert back == hist.info and type(back["skipped_batches"]) is int
    assert type(back["peak"]) is float


def test_a_number_too_large_for_a_float_in_model_json_is_one_input_error(seamor, surge, tmp_path):
    """1e999 parses to inf (NaN and Infinity were refused, it was not), and a whole number
    too large for a float overflows where it is read as one: both ended in a traceback
    (OverflowError) where a damaged file is one error naming it."""
    model = ParametricModel(seamor, ["X_udot", "X:u*abs(u)"], ["u"]).fit(surge)
    model.save(tmp_path)
    good = json.loads((tmp_path / "model.json").read_text())
    saved = json.loads(json.dumps(good))
    saved["state"]["n_obs"] = "HUGE"
    (tmp_path / "model.json").write_text(json.dumps(saved).replace('"HUGE"', "1e999"))
    with pytest.raises(NnidInputError, match="1e999 is too large") as err:
        load_model(tmp_path)
    assert err.value.source == str(tmp_path / "model.json") and err.value.field == "state.n_obs"
    _edit(tmp_path, lambda s: s.update(good) or s["state"].update(sigma2=10**400))
    with pytest.raises(NnidInputError, match=r"model\.json: damaged.*OverflowError"):
        load_model(tmp_path)


@pytest.mark.parametrize("umask", [0o022, 0o027])
def test_a_written_file_keeps_the_umask_not_mkstemps_0600(umask, tmp_path):
    """Files went through tempfile.mkstemp, mode 0600 whatever the umask: a shared model
    folder's model.json could be read by no colleague. A written file has the mode open()
    gives (0666 less the umask)."""
    old = os.umask(umask)
    try:
        write_json(tmp_path / "model.json", {"kind": "x"})
    finally:
        os.umask(old)
    assert (tmp_path / "model.json").stat().st_mode & 0o777 == 0o666 & ~umask
    assert [p.name for p in tmp_path.iterdir()] == ["model.json"]  # no temporary file left


def test_a_written_file_is_synced_to_the_disk_before_its_rename_and_its_folder_after(
    tmp_path, monkeypatch
):
    """write_atomic renamed a temporary file that was never synced: after a power loss the
    rename could reach the disk before the data, an empty model.json in place of the old one.
    The file is synced whole before the rename, its folder (the rename) after it."""
    import stat

    events = []
    sync, replace = os.fsync, os.replace

    def fsync(fd):
        st = os.fstat(fd)
        events.append(("folder",) if stat.S_ISDIR(st.st_mode) else ("file", st.st_size))
        sync(fd)

    def rename(src, dst):
        events.append(("rename", os.path.basename(dst)))
        replace(src, dst)

    monkeypatch.setattr(os, "fsync", fsync)
    monkeypatch.setattr(os, "replace", rename)
    path = write_json(tmp_path / "model.json", {"kind": "x"})
    size = path.stat().st_size
    assert events[:2] == [("file", size), ("rename", "model.json")]
    if os.name == "posix":  # a folder can be opened and synced there
        assert events[2:] == [("folder",)]
