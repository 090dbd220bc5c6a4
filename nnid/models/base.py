"""The model protocol every nnid model speaks (ARCHITECTURE.md, "The model protocol").

A model is a scikit-learn estimator (:class:`sklearn.base.BaseEstimator`): the constructor only
stores its arguments, so ``get_params``, ``set_params`` and :func:`sklearn.base.clone` work;
what ``fit`` learns ends in ``_``. As pysindy's ``BaseOptimizer.fit`` wraps an abstract
``_reduce``, :meth:`NnidModel.fit` checks the input once and calls the model's own ``_fit``;
``predict``, ``residual``, ``params``, ``describe`` and ``save`` first check that the model was
fitted (scikit-learn's ``check_is_fitted``), so a model used too early raises one clear error.

- ``fit(log, validation=None, progress=None) -> self``; ``progress(done, total, message)``.
- ``predict(log, mode="free_run")``: ``"one_step"``, ``"free_run"`` or an int k (k steps
  ahead); a DataFrame on the log's index with the model's output columns ``outputs_``. The
  first ``warmup_samples_ + k − 1`` rows of each experiment (k = 1 for one step and free run)
  are initial conditions, not predictions, and are NaN.
- ``residual(log)``: the equation error (a generalized force for physics models, columns
  ``X Y Z K M N``; the one-step output error otherwise), on the log's index.
- ``params`` (``{name: {"value", "stderr"}}``) and ``describe()`` (a JSON-ready summary).
- ``motion_columns(columns)``: the motion columns the fit and scores read on every row, the
  ones whose gaps are masked (default: all of them).
- ``acceleration_parts()``: where the fit and scores derive accelerations with the model's
  Savitzky-Golay window (:class:`AccelerationParts`; default: nowhere).
- ``baseline()``: the simpler fitted model this one builds on (a hybrid's physics), or None;
  reports score it beside the model on the same data.
- ``save(dir)`` and :func:`load_model`: ``model.json`` (kind, schema version, constructor
  settings, learned scalars; strict JSON) and ``tensors.pt`` (loaded with
  ``weights_only=True``): no code runs on load, and a round trip predicts identically.
"""

from __future__ import annotations

import hashlib
import importlib
import inspect
import io
import json
import math
import pickle
import struct
import time
from abc import ABC, abstractmethod
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd
import torch
from sklearn.base import BaseEstimator
from sklearn.utils.validation import check_is_fitted

from nnid.datasets.log import MOTION, check_log
from nnid.datasets.preprocess import refuse_bursty_runs
from nnid.errors import NnidInputError
from nnid.evaluation.prediction import check_mode
from nnid.serialization import (
    FLOAT_TAG,
    SCHEMA_VERSION,
    exact_float,
    jsonable,
    read_exact_float,
    read_json,
    write_atomic,
    write_json,
)
from nnid.trainers.history import Progress, silent

#: model kind -> "module:Class", imported when first needed (torch-heavy modules stay unloaded
#: until a model of theirs is used)
MODEL_KINDS: dict[str, str] = {
    "fossen": "nnid.models.parametric:ParametricModel",
    "caccia": "nnid.models.caccia:CacciaModel",
    "synthesis": "nnid.models.synthesis:SynthesisModel",
    "sindy": "nnid.models.sindy:SindyDamping",
    "narx": "nnid.models.narx:NarxModel",
    "state_space": "nnid.models.neural_state_space:NeuralStateSpace",
    "hybrid": "nnid.models.hybrid:HybridModel",
    "ensemble": "nnid.models.ensemble:EnsembleModel",
}
#: trainer kind -> "module:Class" (trainers are scikit-learn estimators too)
TRAINER_KINDS: dict[str, str] = {
    "ls": "nnid.trainers.least_squares:LeastSquares",
    "rls": "nnid.trainers.recursive:RecursiveLeastSquares",
    "gradient": "nnid.trainers.recursive:GradientEstimator",
    "ukf": "nnid.trainers.ukf:UnscentedKalman",
    "lm": "nnid.trainers.levenberg_marquardt:LevenbergMarquardt",
    "adam": "nnid.trainers.adam:Adam",
}
#: the trainers that fit a regression's parameters (a physics model's, alone or in a decoupled
#: sequence); lm and adam train networks
REGRESSION_TRAINERS = ("ls", "rls", "gradient", "ukf")
NETWORK_TRAINERS = ("lm", "adam")
MODEL_FILE = "model.json"
TENSOR_FILE = "tensors.pt"
#: a detection model's calibration beside its model files (:mod:`nnid.fault.monitor`), bound
#: to them by :func:`model_fingerprint`: a model saved into the folder removes it
MONITOR_FILE = "monitor.json"
#: the key of model.json that ties it to its tensors.pt (their sha256; null: no tensors)
TENSOR_HASH = "tensors_sha256"
#: a tensors.pt beside a model.json that another save wrote, as :func:`load_model` says it
FOREIGN_TENSORS = (
    f"{TENSOR_FILE} does not belong to {MODEL_FILE} (not the tensors it records): the two "
    "were written by different saves, one interrupted, or edited; save the model again"
)
#: the first part of the name of a tensor that records a fit sample by sample (a filter's θ
#: path, its innovations), not a weight: a per-sample series is no learned scalar, so it goes to
#: ``tensors.pt``, not ``model.json`` (ARCHITECTURE.md, "The model protocol")
RECORD = "record"
#: what steps a log at its runs' typical step, as said in a refusal of stamps in bursts
#: (:func:`~nnid.datasets.preprocess.refuse_bursty_runs`; the pipeline's too)
FIT_AND_SIMULATION = "a model's fit and simulation"


def _checked(log: pd.DataFrame, what: str = "log") -> pd.DataFrame:
    """``log`` checked (:func:`~nnid.datasets.log.check_log`) and refused where a run's stamps
    come in bursts: every model fits, simulates and scores at a run's typical step, one inside
    a burst (:func:`~nnid.datasets.preprocess.refuse_bursty_runs`, the pipeline's rule)."""
    log = check_log(log, what)
    refuse_bursty_runs(log, FIT_AND_SIMULATION)
    return log


NOT_FITTED = (
    "this %(name)s is not fitted yet: call fit(log) first, or load a saved model with "
    "nnid.load_model(dir)"
)


def resolve(kinds: Mapping[str, str], kind: str, what: str) -> type:
    """The class registered under ``kind``."""
    if kind not in kinds:
        raise NnidInputError(f"unknown {what} '{kind}'; expected one of {', '.join(kinds)}")
    module, name = kinds[kind].split(":")
    return getattr(importlib.import_module(module), name)


def model_class(kind: str) -> type[NnidModel]:
    """The model class of a kind ("fossen", "narx", ...)."""
    return resolve(MODEL_KINDS, kind, "model kind")


def trainer_class(kind: str) -> type:
    """The trainer class of a kind ("ls", "lm", ...)."""
    return resolve(TRAINER_KINDS, kind, "trainer")


# -- settings as JSON ----------------------------------------------------------------------------


def encode_setting(value: Any) -> Any:
    """A constructor argument as JSON: a vehicle as its file's fields, a trainer or an
    (unfitted) model as its kind and parameters, arrays as lists (tagged so
    :func:`decode_setting` rebuilds them)."""
    from nnid.vehicle import Vehicle

    if isinstance(value, Vehicle):
        return {"$vehicle": value.model_dump(mode="json")}
    if isinstance(value, BaseEstimator) and getattr(value, "kind", None) in TRAINER_KINDS:
        return {"$trainer": value.kind, "params": encode_setting(value.get_params(deep=False))}
    if isinstance(value, NnidModel):  # an ensemble's member
        return {"$model": value.kind, "params": encode_setting(value.get_params(deep=False))}
    if isinstance(value, np.ndarray):  # its inf tagged as a float's: null read back as NaN
        return {"$array": encode_setting(value.tolist())}
    if isinstance(value, Mapping):
        return {str(k): encode_setting(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [encode_setting(v) for v in value]
    if isinstance(value, float | np.floating) and not math.isfinite(value):
        return exact_float(value)
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, (np.integer, np.floating, np.bool_)):
        return value.item()
    raise TypeError(f"cannot save a setting of type {type(value).__name__}")


def decode_setting(value: Any, source: str = "") -> Any:
    """Inverse of :func:`encode_setting` (no code runs: tags name data, not classes)."""
    if isinstance(value, list):
        return [decode_setting(v, source) for v in value]
    if not isinstance(value, dict):
        return value
    if "$vehicle" in value:
        from nnid.vehicle import saved_vehicle

        return saved_vehicle(value["$vehicle"], source)
    if "$trainer" in value:
        return trainer_class(value["$trainer"])(**decode_setting(value["params"], source))
    if "$model" in value:
        return model_class(value["$model"])(**decode_setting(value["params"], source))
    if "$array" in value:
        return np.asarray(decode_setting(value["$array"], source), dtype=float)
    if FLOAT_TAG in value:
        return read_exact_float(value, "a setting")
    return {k: decode_setting(v, source) for k, v in value.items()}


# -- the protocol --------------------------------------------------------------------------------


@dataclass(frozen=True)
class AccelerationParts:
    """Where a model's fit and scores derive accelerations by Savitzky-Golay: in the ``parts``
    of a split (``"train"``, ``"validation"``, ``"test"``), wherever such a part lacks the
    acceleration ``d<dof>`` of one of ``dofs``, with a window of ``window_s`` s and polynomial
    ``order`` set by the model's key ``field`` (an ensemble's: ``member.savgol_window``)."""

    parts: tuple[str, ...]
    dofs: tuple[str, ...]
    window_s: float
    order: int
    field: str = "savgol_window"


class NnidModel(BaseEstimator, ABC):
    """Base of every nnid model (see the module docstring for the protocol).

    Subclasses set ``kind`` (their key in :data:`MODEL_KINDS`), store every constructor
    argument unchanged, and implement ``_fit``, ``_predict``, ``_residual``, ``_params``,
    ``_state`` and ``_restore``. A model with a force equation (``has_force_equation``)
    also implements ``_force_series``: the force its fitted terms explain, for McCarter's
    J₀ (eq. 4.25).
    """

    kind: ClassVar[str] = ""
    #: whether ``residual`` is a generalized force (columns X..N) with a J₀ series
    has_force_equation: ClassVar[bool] = False
    #: what ``fit`` does with a validation log it can use ("early stopping", "model
    #: selection"), if anything; what one fit did is :attr:`validation_use`
    validation_role: ClassVar[str | None] = None
    #: whether the fit draws on ``seed`` with these settings: an ensemble of seeds of a fit
    #: that does not is one model repeated, its parameters counted once per member
    seeded: ClassVar[bool] = True

    @classmethod
    def from_config(cls, spec, vehicle=None) -> NnidModel:
        """The model a validated config table describes (:mod:`nnid.config`); physics models
        take the ``vehicle`` whose unknowns they identify."""
        args = spec.arguments()
        if "vehicle" in inspect.signature(cls.__init__).parameters:
            if vehicle is None:
                raise NnidInputError(
                    f"a {cls.kind} model needs a vehicle (the config's 'vehicle' or --vehicle)",
                    field="vehicle",
                )
            args["vehicle"] = vehicle
        return cls(**args)

    # -- fitting --------------------------------------------------------------------------------
    def fit(
        self,
        log: pd.DataFrame,
        validation: pd.DataFrame | None = None,
        progress: Progress | None = None,
    ) -> NnidModel:
        """Fit on ``log``; ``validation`` (held-out experiments) is used for early stopping or
        model selection where the model has such a choice; ``progress(done, total, message)``
        is called as the fit goes. Returns the model. A run of either log whose stamps come
        in bursts is refused before any fit: every model fits and simulates at a run's
        typical step, one inside a burst (:func:`~nnid.datasets.preprocess.refuse_bursty_runs`,
        the pipeline's rule).

        Not thread-safe: a fit sets process-wide settings for a while (torch's and BLAS's
        thread counts, :mod:`nnid.threads`; warning filters) and puts them back after, so fits
        in two threads of one process undo each other's settings. Run fits in separate
        processes, as nnid's engines do (:mod:`nnid.scale`)."""
        log = _checked(log, "training log")
        if validation is not None:
            validation = _checked(validation, "validation log")
        for name in [k for k in vars(self) if k.endswith("_") and not k.startswith("__")]:
            delattr(self, name)  # a refit starts from nothing learned
        start = time.perf_counter()
        self._fit(log, validation, progress or silent)
        self.fit_seconds_ = time.perf_counter() - start
        self.validation_use_ = self._validation_used(validation)
        return self

    def _validation_used(self, validation: pd.DataFrame | None) -> str | None:
        """What the fit just ended did with ``validation``: by default the model's
        ``validation_role`` where it was given one. Models whose fit can leave a given log
        unused (runs too short to score) say so from their record of the fit."""
        return self.validation_role if validation is not None else None

    @property
    def validation_use(self) -> str | None:
        """What the fit did with its validation log ("early stopping", "model selection"):
        scores on that log are then not independent of the fit. None where it did nothing
        with one: fitted without one (early stopping on a block of the training log is no use
        of held-out data), or one it could not use; and for a model loaded from a file saved
        before this was kept (not guessed). Before a fit: what a fit would do with a usable
        validation log (``validation_role``)."""
        return getattr(self, "validation_use_", self.validation_role)

    @abstractmethod
    def _fit(self, log: pd.DataFrame, validation: pd.DataFrame | None, progress: Progress):
        """Learn from ``log``; set ``outputs_`` (the columns ``predict`` returns),
        ``targets_`` (those compared with measurements) and ``warmup_samples_`` (initial
        conditions per experiment: 1 for a state-space plant, the largest delay of a NARX)."""

    # -- use ------------------------------------------------------------------------------------
    def predict(self, log: pd.DataFrame, mode: str | int = "free_run") -> pd.DataFrame:
        """Predicted outputs on the log's index (see the module docstring for ``mode``)."""
        check_is_fitted(self, msg=NOT_FITTED)
        mode = check_mode(mode)
        log = _checked(log)
        out = self._predict(log, mode)
        return out.set_axis(log.index)

    @abstractmethod
    def _predict(self, log: pd.DataFrame, mode: str | int) -> pd.DataFrame:
        """Predicted ``outputs_`` per row of ``log``; initial conditions NaN."""

    def score(
        self, log: pd.DataFrame, mode: str | int = "free_run", warmup_s: float = 0.0
    ) -> dict[str, float | None]:
        """NRMSE per target column and ``total`` in one prediction mode, by the rules of
        :func:`nnid.evaluation.evaluate.evaluate` (warm-up excluded, None where the prediction
        diverged)."""
        from nnid.evaluation.evaluate import evaluate

        mode = check_mode(mode)
        name = mode if isinstance(mode, str) else "k_step"
        k = mode if isinstance(mode, int) else None
        result = evaluate(self, log, (name,), k, warmup_s)
        return result[
            {"one_step": "one_step_nrmse", "free_run": "free_run_nrmse"}.get(name, "k_step_nrmse")
        ]

    def residual(self, log: pd.DataFrame) -> pd.DataFrame:
        """The model's equation error on the log's index: measured minus modelled (a
        generalized force ``X … N`` for physics models, the one-step output error else)."""
        check_is_fitted(self, msg=NOT_FITTED)
        return self._residual(_checked(log)).set_axis(log.index)

    def _residual(self, log: pd.DataFrame) -> pd.DataFrame:
        """Default: the one-step output error, measured minus predicted."""
        pred = self._predict(log, "one_step")
        return log[pred.columns].astype(float) - pred.set_axis(log.index)

    def force_series(self, log: pd.DataFrame) -> pd.DataFrame:
        """What the model's fitted terms must explain, columns ``X … N`` (the residual at zero
        parameters; McCarter's τ̄, eq. 4.4, for damping models): J = RMS(residual) and
        J₀ = RMS(this) (eq. 4.25). Only for models with a force equation."""
        if not self.has_force_equation:
            raise TypeError(f"a {self.kind} model has no force equation")
        check_is_fitted(self, msg=NOT_FITTED)
        return self._force_series(_checked(log)).set_axis(log.index)

    def motion_columns(self, columns: Iterable[str]) -> list[str]:
        """The motion columns of a log with ``columns`` (pose, velocity, acceleration:
        :data:`~nnid.datasets.log.MOTION`) that this model's fit and scores read on every
        row, as a regressor, a target or a simulation's state: a gap in one is masked
        (:func:`nnid.datasets.gaps.mask_gaps`), a gap in another left. Works before ``fit``
        (the settings say it). Default: every motion column, so a model that does not say
        has every gap masked."""
        present = set(columns)
        return [c for c in MOTION if c in present]

    def acceleration_parts(self, members_scored: bool = False) -> AccelerationParts | None:
        """Where this model's fit and scores derive accelerations with its Savitzky-Golay
        window (:class:`AccelerationParts`), so that a window longer than a run there can be
        refused before a long fit; None where they derive none (the default).
        ``members_scored``: an ensemble's members are scored on the held-out parts too (nnid
        train's table of members). Works before ``fit`` (the settings say it)."""
        return None

    def baseline(self) -> NnidModel | None:
        """The simpler fitted model this one builds on (a hybrid's physics-only fit), scored
        beside it on the same data; None for most models."""
        check_is_fitted(self, msg=NOT_FITTED)
        return None

    @property
    def params(self) -> dict[str, dict[str, float | None]]:
        """Identified parameters ``{name: {"value": θ, "stderr": σ or None}}``; names follow
        the vehicle file for physics models."""
        check_is_fitted(self, msg=NOT_FITTED)
        return self._params()

    @abstractmethod
    def _params(self) -> dict[str, dict[str, float | None]]: ...

    @property
    def n_params(self) -> int:
        """Number of fitted parameters."""
        check_is_fitted(self, msg=NOT_FITTED)
        return self._n_params()

    def _n_params(self) -> int:
        return len(self._params())

    def parameter_names(self) -> list[str] | None:
        """The names of the parameters a fit will estimate, where the settings alone give them
        (before any fit: a train config's ``[reference]`` is checked against them then, not
        after hours of fitting), else None: only the fit tells."""
        return None

    def trainer_name(self) -> str | None:
        """What fitted the model: the kind of its trainer (``trainer_`` after a fit, as saved
        for a loaded model; else the ``trainer`` setting)."""
        trainer = getattr(self, "trainer_", None)
        if trainer is None and getattr(self, "fitted_by_", None):
            return self.fitted_by_
        if trainer is None:  # a setting, never a method of the same name (Caccia's)
            trainer = self.get_params(deep=False).get("trainer")
        return None if trainer is None else getattr(trainer, "kind", type(trainer).__name__)

    def describe(self) -> dict:
        """A JSON-ready summary: kind, trainer, outputs, parameter count and values, fit time."""
        check_is_fitted(self, msg=NOT_FITTED)
        return {
            "kind": self.kind,
            "trainer": self.trainer_name(),
            "outputs": list(self.outputs_),
            "n_params": self.n_params,
            "params": self.params,
            "fit_seconds": getattr(self, "fit_seconds_", None),
        }

    # -- persistence ----------------------------------------------------------------------------
    def save(self, folder: str | Path) -> Path:
        """Write ``model.json`` and, where the model has tensors, ``tensors.pt`` into
        ``folder``; :func:`load_model` reads them back."""
        check_is_fitted(self, msg=NOT_FITTED)
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        form, tensors = _saved_form(self)
        data = None
        if tensors:
            buffer = io.BytesIO()
            torch.save(tensors, buffer)
            data = buffer.getvalue()
        payload = {
            "kind": form["kind"],
            "nnid_version": _version(),
            "settings": form["settings"],
            # the two files are written one after the other: a save cut between them left new
            # tensors beside the old model.json, which loaded them without a word
            TENSOR_HASH: None if data is None else hashlib.sha256(data).hexdigest(),
            **form,  # the learned part, after these (kind and settings keep their places)
        }
        # another model's calibration: detection applied it to this model
        (folder / MONITOR_FILE).unlink(missing_ok=True)
        if data is not None:  # atomically, as model.json: never half a file beside a whole one
            write_atomic(folder / TENSOR_FILE, lambda fh: fh.write(data))
        else:  # another model's, saved here before: not left beside this one's model.json
            (folder / TENSOR_FILE).unlink(missing_ok=True)
        write_json(folder / MODEL_FILE, payload)
        return folder

    @abstractmethod
    def _state(self) -> tuple[dict, dict[str, torch.Tensor]]:
        """What ``fit`` learned: JSON-ready scalars, and tensors by name."""

    @abstractmethod
    def _restore(self, state: dict, tensors: dict[str, torch.Tensor]) -> None:
        """Set the learned attributes from what :meth:`_state` returned."""


def load_model(folder: str | Path) -> NnidModel:
    """Load any saved nnid model from its folder (``model.json`` names its kind); tensors are
    read with ``weights_only=True``, so loading runs no code from the files."""
    folder = Path(folder)
    path = folder / MODEL_FILE if folder.is_dir() else folder
    if not path.exists():
        raise NnidInputError(f"no saved model here (expected {MODEL_FILE})", source=str(folder))
    try:
        payload = read_json(path)
    except NnidInputError as exc:  # said against the file once, with what is wrong with it
        raise NnidInputError(
            f"not a valid model file: {exc.message}", source=str(path), field=exc.field
        ) from None
    if not isinstance(payload, dict) or "kind" not in payload:
        raise NnidInputError("not an nnid model file (no 'kind')", source=str(path))
    version = payload.get("schema_version")
    if not isinstance(version, int) or not 1 <= version <= SCHEMA_VERSION:
        raise NnidInputError(
            f"schema_version {version!r}: this nnid reads model files of versions 1 to "
            f"{SCHEMA_VERSION}",
            source=str(path),
            field="schema_version",
        )
    # a file edited by hand or cut short fails somewhere inside a model's own restore; every
    # such failure is said against the file, as one input error, at this one boundary
    tensor_path = path.parent / TENSOR_FILE
    try:
        data = tensor_path.read_bytes() if tensor_path.exists() else None
        tensors = {} if data is None else torch.load(io.BytesIO(data), weights_only=True)
    except pickle.UnpicklingError:
        # torch's own message advises weights_only=False, which would run the file's code
        raise NnidInputError(UNSAFE_TENSORS, source=str(tensor_path)) from None
    except (EOFError, RuntimeError, ValueError) as exc:
        raise NnidInputError(_damaged(exc), source=str(tensor_path)) from None
    except OSError as exc:  # a folder in its place, no permission
        raise NnidInputError(f"cannot be read ({exc.strerror})", source=str(tensor_path)) from None
    except (KeyError, IndexError, struct.error):
        # bytes that are no zip archive are read as a legacy pickle, whose unpickler fails on
        # text with its own internals' errors (a file of "https://…" a KeyError, of "(…" an
        # IndexError): a traceback, where the file is simply not tensors
        raise NnidInputError(UNSAFE_TENSORS, source=str(tensor_path)) from None
    if not isinstance(tensors, dict):
        raise NnidInputError(_damaged(TypeError("no tensors by name")), source=str(tensor_path))
    # a NaN weight loads and predicts NaN everywhere: a damaged file, said at loading
    broken = [k for k, v in tensors.items() if torch.is_tensor(v) and not _sound(k, v)]
    if broken:
        raise NnidInputError(
            f"'{broken[0]}' holds NaN or infinite values: the file is damaged (only a "
            f"'{RECORD}.' series may, as its fit recorded them)",
            source=str(tensor_path),
        )
    _check_tensor_hash(payload, data, path)
    try:
        cls = model_class(payload["kind"])
        model = cls(**decode_setting(payload["settings"], str(path)))
        model = restore_learned(model, payload, tensors)
    except NnidInputError as exc:  # a model's check of its settings: named as a key of them
        settings = payload.get("settings")
        keys = settings if isinstance(settings, dict) else {}
        raise exc.within("settings", keys).with_source(str(path)) from None
    except (
        KeyError,
        TypeError,
        ValueError,
        RuntimeError,
        AttributeError,
        IndexError,
        ArithmeticError,  # a whole number too large for a float: float(10**400) overflows
    ) as exc:
        # a network without its tensors fails in load_state_dict, a RuntimeError
        gone = isinstance(exc, RuntimeError) and not tensor_path.exists()
        missing = f"; its {TENSOR_FILE} is missing" if gone else ""
        raise NnidInputError(_damaged(exc) + missing, source=str(path)) from None
    _check_learned(model, payload, str(path))
    return model


def _check_tensor_hash(payload: dict, data: bytes | None, path: Path) -> None:
    """The tensors.pt read (``data``; None: there is none) against the sha256 model.json
    records. A file saved before the hash was kept has none: loaded as before, unchecked. A
    missing tensors.pt is left to the model's restore, which says it where it needs one."""
    if TENSOR_HASH not in payload:
        return
    recorded = payload[TENSOR_HASH]
    if recorded is not None and not (isinstance(recorded, str) and len(recorded) == 64):
        raise NnidInputError(
            f"damaged, or not written by this nnid ({TENSOR_HASH} is no sha256: {recorded!r})",
            source=str(path),
            field=TENSOR_HASH,
        )
    if data is not None and recorded != hashlib.sha256(data).hexdigest():
        raise NnidInputError(FOREIGN_TENSORS, source=str(path.parent))


def model_fingerprint(folder: str | Path) -> str:
    """The sha256 of the saved model in ``folder``: of its model.json's bytes, then its
    tensors.pt's where it has one. A file written beside the model (monitor.json) records it,
    so that it is refused beside another model."""
    folder = Path(folder)
    digest = hashlib.sha256((folder / MODEL_FILE).read_bytes())
    if (folder / TENSOR_FILE).exists():
        digest.update((folder / TENSOR_FILE).read_bytes())
    return digest.hexdigest()


def learned_fingerprint(model: NnidModel) -> str:
    """The sha256 of what identifies a fitted model: its kind, settings and what it learned,
    as :meth:`NnidModel.save` writes them, and its tensors' values. Not which nnid saved it
    (``nnid_version``), nor the bytes torch gives its tensors: a model and that model saved
    and loaded again have the same one, where :func:`model_fingerprint` (a folder's bytes)
    tells one save from another."""
    form, tensors = _saved_form(model)
    digest = hashlib.sha256(json.dumps(jsonable(form), sort_keys=True).encode("utf-8"))
    for name in sorted(tensors):
        value = tensors[name].detach().cpu().contiguous()
        digest.update(name.encode("utf-8"))
        digest.update(f"{value.dtype}{tuple(value.shape)}".encode())
        # the bytes, not the numbers: a recorded NaN equals itself, -0.0 is not 0.0
        digest.update(value.reshape(-1).view(torch.uint8).numpy().tobytes())
    return digest.hexdigest()


def _saved_form(model: NnidModel) -> tuple[dict, dict[str, torch.Tensor]]:
    """What :meth:`NnidModel.save` writes of ``model``: model.json's kind, settings and
    learned part (:func:`learned_state`), and the tensors by name."""
    learned, tensors = learned_state(model)
    form = {"kind": model.kind, "settings": encode_setting(model.get_params(deep=False))}
    return {**form, **learned}, tensors


def _check_learned(model: NnidModel, payload: dict, source: str) -> None:
    """What model.json says of the fit against what the loaded model holds: its outputs and
    targets as its settings and state give them, and the trainer its restored trainer names.
    Edited by hand they loaded without a word (outputs ["zz"], trainer "bogus") and were
    reported beside a model that predicts other columns."""
    for key, held in (("outputs", model.outputs_), ("targets", model.targets_)):
        if list(payload[key]) != list(held):
            raise NnidInputError(
                f"{payload[key]} are not the {key} of this model ({list(held)}, as its settings "
                "and state give them): the file was edited or is damaged",
                source=source,
                field=key,
            )
    saved = payload.get("trainer")
    if getattr(model, "trainer_", None) is not None and saved != model.trainer_name():
        raise NnidInputError(
            f"{saved!r} is not the trainer of this model ({model.trainer_name()!r}, as its "
            "settings give it): the file was edited or is damaged",
            source=source,
            field="trainer",
        )


#: a tensors file that is no plain set of tensors: said without torch's advice to load it
#: unsafely
UNSAFE_TENSORS = (
    "damaged, or not written by this nnid: it holds something other than tensors (or is not a "
    "PyTorch file), and nnid loads tensors only, never code from a file"
)


def record_key(name: str) -> str:
    """The ``tensors.pt`` name of the per-sample series ``name`` (:data:`RECORD`)."""
    return f"{RECORD}.{name}"


def _sound(key: str, tensor: torch.Tensor) -> bool:
    """Whether a loaded tensor may be as it is: a weight only finite; a record (its name has a
    :data:`RECORD` part, an ensemble's member's too) as its fit wrote it, NaN and ±inf
    included: the UKF's innovation on a sample it made no update with is NaN, a diverged
    gradient estimator's θ path runs through inf to NaN, and its model stays loadable."""
    return RECORD in key.split(".") or bool(tensor.isfinite().all())


def record_tensor(series: np.ndarray) -> torch.Tensor:
    """A per-sample series as saved under a :func:`record_key`: float64, as fitted."""
    return torch.from_numpy(np.array(series, dtype=np.float64))


def saved_record(tensors: Mapping[str, torch.Tensor], name: str) -> np.ndarray:
    """The series :func:`record_tensor` saved under ``record_key(name)``, checked: a float64
    tensor; one missing is a RuntimeError, as a network's missing weight is in
    ``load_state_dict`` (:func:`load_model` then says whether the file is gone)."""
    key = record_key(name)
    if key not in tensors:
        raise RuntimeError(f"'{key}' is not in {TENSOR_FILE}")
    value = tensors[key]
    if not torch.is_tensor(value) or value.dtype != torch.float64:
        raise TypeError(f"'{key}' in {TENSOR_FILE} is no float64 tensor")
    return value.numpy().copy()


def _damaged(exc: Exception) -> str:
    what = f"no {exc}" if isinstance(exc, KeyError) else f"{type(exc).__name__}: {exc}"
    return f"damaged, or not written by this nnid ({what.splitlines()[0]})"


def learned_state(model: NnidModel) -> tuple[dict, dict[str, torch.Tensor]]:
    """What a fitted model learned, as saved: the JSON part (output columns, targets, warm-up
    samples and the model's own ``state``) and its tensors by name."""
    state, tensors = model._state()
    learned = {
        "outputs": list(model.outputs_),
        "targets": list(model.targets_),
        "warmup_samples": int(model.warmup_samples_),
        "state": state,
        # what describe() reports of the fit, kept so that a loaded model reports it too
        "trainer": model.trainer_name(),
        "fit_seconds": getattr(model, "fit_seconds_", None),
        "validation_use": getattr(model, "validation_use_", None),
    }
    return learned, tensors


def restore_learned(model: NnidModel, learned: dict, tensors: dict[str, torch.Tensor]):
    """Inverse of :func:`learned_state` on an unfitted model built from its settings."""
    warmup = learned["warmup_samples"]
    if not isinstance(warmup, int) or isinstance(warmup, bool) or warmup < 0:
        raise ValueError(f"warmup_samples must be a whole number, 0 or more, not {warmup!r}")
    model.outputs_ = list(learned["outputs"])
    model.targets_ = list(learned["targets"])
    model.warmup_samples_ = warmup
    model._restore(learned["state"], tensors)
    # files saved before these were kept have neither: describe() then says None, not a guess
    trainer, seconds = learned.get("trainer"), learned.get("fit_seconds")
    if trainer is not None and not isinstance(trainer, str):
        raise ValueError(f"trainer must be a name, not {trainer!r}")
    if seconds is not None and (isinstance(seconds, bool) or not isinstance(seconds, float | int)):
        raise ValueError(f"fit_seconds must be a number, not {seconds!r}")
    used = learned.get("validation_use")
    if used is not None and not isinstance(used, str):
        raise ValueError(f"validation_use must be a text or null, not {used!r}")
    model.fitted_by_ = trainer
    model.fit_seconds_ = seconds
    model.validation_use_ = used
    return model


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("nnid")
    except PackageNotFoundError:  # running from a source tree that is not installed
        return "unknown"
