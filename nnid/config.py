"""Pydantic models of the TOML configs the CLI runs, and their loader.

A bad config is one :class:`NnidInputError` naming the file and the field (dotted path).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator

from nnid.datasets.excitation import (
    PRBS,
    Chirp,
    DOptimalSine,
    Multisine,
    Sine,
    Stairs,
    Step,
    WeissSequence,
)
from nnid.datasets.measurement import Measurement
from nnid.datasets.simulator import Autopilot
from nnid.physics.effects import parse_effect
from nnid.validation import read_toml, validated

Signal = Annotated[
    Step | Stairs | Chirp | Multisine | PRBS | Sine | DOptimalSine, Field(discriminator="kind")
]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid")


class Effect(_Strict):
    """An injected effect by its vocabulary name (see :mod:`nnid.physics.effects`)."""

    name: str
    value: float

    @field_validator("name")
    @classmethod
    def _known(cls, name: str) -> str:
        parse_effect(name)
        return name


class Experiment(_Strict):
    """One run: signals summed per channel, from rest unless ``x0`` (η, or η and ν) is given."""

    name: str
    duration: float | None = Field(None, gt=0)
    x0: list[float] | None = None
    signals: list[Signal] = Field(default_factory=list)
    effects: list[Effect] = Field(default_factory=list)

    @field_validator("x0")
    @classmethod
    def _x0(cls, x0: list[float] | None) -> list[float] | None:
        if x0 is not None and len(x0) not in (6, 12):
            raise ValueError("x0 has 6 (pose) or 12 (pose and velocity) values")
        return x0

    def end(self) -> float:
        ends = [s.end() for s in self.signals]
        return self.duration if self.duration is not None else max(ends, default=0.0)


class SimulateConfig(_Strict):
    """``nnid simulate``: a vehicle, experiments or a sequence, injected effects, sensors."""

    kind: Literal["simulate"] = "simulate"
    vehicle: str
    dt: float = Field(0.01, gt=0)
    substeps: int = Field(1, ge=1)
    integrator: Literal["rk4", "adaptive", "torch"] = "rk4"
    seed: int = 0
    effects: list[Effect] = Field(default_factory=list)
    measurement: Measurement = Field(default_factory=Measurement)
    experiments: list[Experiment] = Field(default_factory=list)
    sequence: WeissSequence | None = None
    autopilot: Autopilot | None = None

    def all_experiments(self) -> list[Experiment]:
        """The explicit experiments followed by those of the sequence."""
        extra = self.sequence.experiments() if self.sequence else []
        return [*self.experiments, *(Experiment.model_validate(e) for e in extra)]


def load_config(path: str | Path, model: type[BaseModel] = SimulateConfig) -> BaseModel:
    """Read and validate a TOML config; raise NnidInputError naming the file and field."""
    return validated(model, read_toml(path), str(path))


class DataSpec(_Strict):
    """Where the log comes from: a file (``log``, optionally through a reader config
    ``columns``), or a simulate config (``simulate``) run on the fly. Paths are relative to
    the config file. ``kind = "table"``: the file is a generic input-output table (``t``,
    optional ``experiment``, the model's named columns), not a vehicle log; for the
    input-output models (NARX, neural state space)."""

    kind: Literal["vehicle", "table"] = "vehicle"
    log: str | None = None
    columns: str | None = None
    simulate: str | None = None
    experiments: list[str] | None = None


class FossenSpec(_Strict):
    """Which parameters are unknown and which DOF equations identify them. ``unknowns`` may
    use the shortcuts ``added_mass`` (diagonal derivatives of the DOFs) and ``damping`` (the
    vehicle's damping-model terms of the DOFs' forces)."""

    unknowns: list[str] = Field(default_factory=lambda: ["added_mass", "damping"])
    dofs: list[str] = Field(default_factory=lambda: ["u", "v", "w", "p", "q", "r"])


class SequenceStep(_Strict):
    """One step of a decoupled identification sequence (Weiss eqs 99-108)."""

    experiments: list[str] = Field(min_length=1)
    dofs: list[str] = Field(min_length=1)
    unknowns: list[str] = Field(min_length=1)


class SplitSpec(_Strict):
    by: Literal["experiment", "block"] = "block"
    fractions: list[float] = Field(default_factory=lambda: [0.7, 0.15, 0.15])
    train: list[str] | None = None
    validation: list[str] | None = None
    test: list[str] | None = None


class NarxSpec(_Strict):
    """The NARX network of ``model = "narx"`` (Weiss IV.A.2, V.B; :mod:`nnid.models.narx`):
    named input and output columns, delays (a count n means 1..n), hidden tanh layers, the
    training budget, and optional light white noise (``noise``: standard deviation as a
    fraction of each column's, seeded by ``seed``) added to inputs and outputs, as Weiss did.
    The remaining keys are :class:`nnid.models.narx.NarxModel`'s options of the same names;
    ``output_bounds`` is "train" or one [low, high] per output, each a number, "train" or
    "open"."""

    inputs: list[str] = Field(min_length=1)
    outputs: list[str] = Field(min_length=1)
    input_delays: int | list[int] = 2
    output_delays: int | list[int] = 2
    hidden: list[int] = Field(default_factory=lambda: [10])
    balanced: bool = True
    seed: int = 0
    epochs: int = Field(200, ge=1)
    lr: float = Field(1e-2, gt=0)
    multi_step: int = Field(1, ge=1)
    simulation_epochs: int = Field(0, ge=0)
    simulation_window: int = Field(200, ge=2)
    lm_samples: int = Field(4000, ge=10)
    noise: float = Field(0.0, ge=0)
    simulation_lr: float = Field(1e-3, gt=0)
    simulation_trainer: Literal["adam", "lm"] = "adam"
    simulation_max_fail: int = Field(8, ge=1)
    simulation_l2: float = Field(0.0, ge=0)
    delta: bool = True
    output_transform: Literal["sqrt"] | None = None
    output_bounds: str | list[list[float | str]] | None = None


class StateSpaceSpec(_Strict):
    """The continuous-time neural state-space model of ``model = "state_space"``
    (:mod:`nnid.models.neural_state_space`): the outputs are the first states, ``hidden_states``
    more are unmeasured; ``structure`` (optional) is one row of 0/1 per state derivative over
    the states then the inputs; ``windows`` are the training stages' window lengths in samples
    (0: whole experiments); ``warmup`` samples estimate each run's initial state and are never
    scored; ``epochs`` per stage; ``output_bounds``: "train" or one [low, high] per output,
    each a number, "train" or "open"."""

    inputs: list[str] = Field(min_length=1)
    outputs: list[str] = Field(min_length=1)
    hidden_states: int = Field(1, ge=0)
    hidden: int = Field(16, ge=1)
    structure: list[list[int]] | None = None
    windows: list[int] = Field(default_factory=lambda: [0], min_length=1)
    warmup: int = Field(10, ge=1)
    substeps: int = Field(1, ge=1)
    epochs: int = Field(30, ge=1)
    lr: float = Field(1e-2, gt=0)
    continuity: float = Field(1.0, ge=0)
    output_bounds: str | list[list[float | str]] | None = None
    seed: int = 0


class TrainConfig(_Strict):
    """``nnid train``: one model, one trainer, a split, and what to report."""

    model: Literal["fossen", "narx", "state_space"] = "fossen"
    trainer: Literal["ls", "rls", "gradient", "ukf", "caccia", "lm", "adam"] = "ls"
    vehicle: str = ""
    narx: NarxSpec | None = None
    state_space: StateSpaceSpec | None = None
    data: DataSpec
    fossen: FossenSpec = Field(default_factory=FossenSpec)
    options: dict[str, float | str | bool] = Field(default_factory=dict)
    savgol_window: float = Field(1.0, gt=0)
    savgol_order: int = Field(4, ge=2, le=8)
    split: SplitSpec = Field(default_factory=SplitSpec)
    warmup_s: float = Field(1.0, ge=0)
    reference: dict[str, float] = Field(default_factory=dict)
    reference_label: str = "reference"
    nondimensional_speed: float | None = Field(None, gt=0)
    sequence: Literal["weiss"] | list[SequenceStep] | None = None


class LoopConfig(_Strict):
    """``nnid loop CONFIG``: the residual loop on a log (``--data``/``--vehicle`` override)."""

    kind: Literal["loop"] = "loop"
    vehicle: str = ""
    data: DataSpec = Field(default_factory=DataSpec)
    dofs: list[Literal["u", "v", "w", "p", "q", "r"]] | None = None
    validation: list[str] | None = None  # experiments held out; default the last 30 %
    validation_fraction: float = Field(0.3, gt=0, lt=1)
    max_effects: int = Field(3, ge=0)
    alpha: float = Field(0.01, gt=0, lt=0.5)
    coupled: bool = True
    filter_lambda: float | None = Field(1.0, gt=0)
    savgol_window: float = Field(1.0, gt=0)
    savgol_order: int = Field(4, ge=2, le=8)
    warmup_s: float = Field(2.0, ge=0)
    gate_horizon_s: float | None = Field(None, gt=0)  # None: the gate is the free run


class SindySpec(_Strict):
    """The SINDy fit of ``nnid compare``: optimizer and the thresholds of its path."""

    optimizer: Literal["stlsq", "sr3", "ensemble"] = "stlsq"
    thresholds: list[float] | None = None
    selection: Literal["validation", "aic", "bic"] = "validation"
    tolerance: float = Field(0.05, ge=0)


class CompareConfig(_Strict):
    """``nnid compare``: named damping models (masks of the basis library) and a SINDy model
    fitted on one split, compared on held-out data (McCarter ch. 5)."""

    kind: Literal["compare"] = "compare"
    vehicle: str
    data: DataSpec
    models: list[str] = Field(
        default_factory=lambda: [
            "mcfarland",
            "pitch_yaw",
            "gertler_hagen",
            "linear",
            "coe",
            "prestero",
            "uncoupled",
            "fossen",
        ]
    )
    sindy: SindySpec | bool = True  # false: named models only
    split: SplitSpec = Field(default_factory=SplitSpec)
    savgol_window: float = Field(1.0, gt=0)
    savgol_order: int = Field(4, ge=2, le=8)
    warmup_s: float = Field(2.0, ge=0)
    horizon_s: float = Field(2.0, gt=0)
    filter_lambda: float | None = Field(None, gt=0)
    zoh_midpoint: bool = False
