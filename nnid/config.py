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
