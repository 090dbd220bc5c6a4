"""Pydantic models of the TOML configs the CLI runs, and their loader.

Every command's config has a ``kind`` ("simulate", "train", "compare", "loop"); a model is a
table whose ``kind`` names the model ("fossen", "caccia", "synthesis", "sindy", "narx",
"state_space", "hybrid", "ensemble": a seed ensemble of another model table, ``[model.member]``)
and whose other keys are that model's constructor arguments (one
option model per kind, each building its model with ``from_config``); a trainer is a table
whose ``kind`` names it ("ls", "rls", "gradient", "ukf", "lm", "adam") with that trainer's
arguments, or just the name. Unknown keys are refused, damping masks and DOFs are literals,
effect names are checked against the vocabulary. A bad config is one :class:`NnidInputError`
naming the file and the key (dotted path), raised before any data is loaded or simulated.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    Field,
    Strict,
    field_validator,
    model_validator,
)

from nnid.datasets.excitation import (
    APRBS,
    PRBS,
    Chirp,
    DOptimalSine,
    Multisine,
    Sine,
    Stairs,
    Step,
    WeissSequence,
)
from nnid.datasets.log import FASTEST_STEP, MAX_DISTANCE, MAX_SPEED
from nnid.datasets.measurement import Measurement
from nnid.datasets.simulator import Autopilot
from nnid.errors import NnidInputError
from nnid.physics.damping_masks import MASKS
from nnid.physics.dofs import DOFS, FORCES
from nnid.physics.effects import parse_effect
from nnid.validation import (
    ALPHA_MAX,
    ALPHA_MIN,
    MAX_FALSE_ALARMS_PER_HOUR,
    MAX_SEED,
    MAX_WIDTH,
    MIN_WINDOW_S,
    PositiveFloat,
    StrictModel,
    adjoint_solver,
    disjoint_columns,
    read_toml,
    refuse_other_file,
    repeated,
    validated,
    window_lengths,
)
from nnid.vehicle import vehicle_name

Signal = Annotated[
    Step | Stairs | Chirp | Multisine | PRBS | APRBS | Sine | DOptimalSine,
    Field(discriminator="kind"),
]
Dof = Literal[DOFS]  # type: ignore[valid-type]
Force = Literal[FORCES]  # type: ignore[valid-type]
MaskName = Literal[tuple(MASKS)]  # type: ignore[valid-type]
#: the longest duration a setting may name, s (eleven days: beyond any log; a larger one
#: overflowed the sample count)
MAX_DURATION_S = 1e6
Duration = Annotated[float, Field(gt=0, le=MAX_DURATION_S, allow_inf_nan=False)]
#: the most random draws of a sweep (more is a typo that fills the memory before any trial)
MAX_SAMPLES = 100_000
Number = Annotated[float, Field(allow_inf_nan=False)]
#: a random seed: numpy's generators take no negative one, torch's none of 2⁶⁴ (MAX_SEED)
Seed = Annotated[int, Field(ge=0, le=MAX_SEED)]


def _a_path(path: str) -> str:
    """A path a config names, not blank: ``""`` named the current folder or none, said as
    ".: is a folder, not a TOML file", naming neither the config nor the key."""
    if not path.strip():
        raise ValueError("is empty: a file's path (or a preset's name, for a vehicle) is expected")
    return path


#: a file a config names (its vehicle, log, reader config, simulate config): a blank one is
#: refused naming the key; a config that names none leaves the key out
PathText = Annotated[str, AfterValidator(_a_path)]


def _once(names: list[str]) -> list[str]:
    """``names``, or an error naming those given more than once."""
    twice = repeated(names)
    if twice:
        raise ValueError(f"{', '.join(twice)} named twice")
    return names


#: a list of names, or DOFs, each given once (``dofs = ["u", "u"]`` is a typo, not a weight)
Names = Annotated[list[str], AfterValidator(_once)]
#: a name that heads a report's rows and columns (a model's, a reference's): a visible
#: character, on one line, as a vehicle's name
Label = Annotated[str, AfterValidator(vehicle_name)]
Dofs = Annotated[list[Dof], Field(min_length=1), AfterValidator(_once)]


def _inert(model: BaseModel, keys: tuple[str, ...], because: str, remedy: str) -> None:
    """Refuse a key written (one of ``keys``) that another key's value leaves doing nothing
    (``because`` names that key and value; ``remedy`` is the other way out): accepted without a
    word, it read as taken."""
    given = [k for k in keys if k in model.model_fields_set]
    if given:
        raise NnidInputError(
            f"does nothing with {because}: remove {given[0]}, or {remedy}", field=given[0]
        )


def _kind_shorthand(value: Any) -> Any:
    """``trainer = "lm"`` stands for ``[trainer] kind = "lm"``."""
    return {"kind": value} if isinstance(value, str) else value


# -- simulate ------------------------------------------------------------------------------------


class Effect(StrictModel):
    """An injected effect by its vocabulary name (see :mod:`nnid.physics.effects`)."""

    name: str
    value: Number

    @field_validator("name")
    @classmethod
    def _known(cls, name: str) -> str:
        parse_effect(name)
        return name


class Experiment(StrictModel):
    """One run: signals summed per channel, from rest unless ``x0`` (η, or η and ν) is given."""

    name: str
    duration: PositiveFloat | None = None
    x0: list[Number] | None = None
    signals: list[Signal] = Field(default_factory=list)
    effects: list[Effect] = Field(default_factory=list)

    @field_validator("x0")
    @classmethod
    def _x0(cls, x0: list[float] | None) -> list[float] | None:
        if x0 is not None and len(x0) not in (6, 12):
            raise ValueError("x0 has 6 (pose) or 12 (pose and velocity) values")
        if x0 is not None and max(abs(a) for a in x0[3:6]) > 2 * math.pi:
            raise ValueError("x0's angles (its 4th to 6th values) are radians, within ±2π")
        # the log the run writes must hold them: its bounds on a position and a velocity
        if x0 is not None and max(abs(a) for a in x0[0:3]) > MAX_DISTANCE:
            raise ValueError(
                f"x0's position (its 1st to 3rd values) is metres, within ±{MAX_DISTANCE:g}"
            )
        if x0 is not None and max((abs(a) for a in x0[6:12]), default=0.0) > MAX_SPEED:
            raise ValueError(
                f"x0's velocity (its 7th to 12th values) is m/s and rad/s, within ±{MAX_SPEED:g}"
            )
        return x0

    def end(self) -> float:
        ends = [s.end() for s in self.signals]
        return self.duration if self.duration is not None else max(ends, default=0.0)


class SimulateConfig(StrictModel):
    """``nnid simulate``: a vehicle, experiments or a sequence, injected effects, sensors."""

    kind: Literal["simulate"] = "simulate"
    vehicle: PathText
    dt: PositiveFloat = 0.01
    substeps: int = Field(1, ge=1, le=1000)
    integrator: Literal["rk4", "adaptive", "torch"] = "rk4"
    seed: Seed = 0
    effects: list[Effect] = Field(default_factory=list)
    measurement: Measurement = Field(default_factory=Measurement)
    experiments: list[Experiment] = Field(default_factory=list)
    sequence: WeissSequence | None = None
    autopilot: Autopilot | None = None

    @field_validator("dt")
    @classmethod
    def _dt(cls, dt: float) -> float:
        # no finer than a log nnid reads (FASTEST_STEP): a finer simulated clock was refused
        # downstream as hours read as seconds
        if dt < FASTEST_STEP:
            raise ValueError(
                f"{dt:g} s is a finer step than any log nnid reads (at least {FASTEST_STEP:g} s, "
                f"{1 / FASTEST_STEP:g} Hz): is dt in seconds?"
            )
        return dt

    @model_validator(mode="after")
    def _runs(self) -> SimulateConfig:
        # checked here, where the config can be named: the log it writes would carry a blank
        # or repeated experiment label, or a run of one sample, and be refused as that file.
        # Each error names the key (``experiments.2.signals.0.f1``; a run of the sequence is
        # ``sequence``, whose keys make all its runs) and the value expected there.
        from nnid.datasets.log import MAX_RUN_SAMPLES

        if self.integrator == "adaptive":  # DOP853 chooses its own steps
            _inert(self, ("substeps",), 'integrator = "adaptive" (it chooses its own steps)',
                   'integrate with "rk4" or "torch"')  # fmt: skip
        if not self.all_experiments():
            raise ValueError("nothing to simulate: give [[experiments]] or a [sequence]")
        twice = repeated([e.name for e in self.effects])
        if twice:  # applied twice, or the last one kept: either way not what was written
            raise NnidInputError(f"{', '.join(twice)} given twice", field="effects")
        nyquist = 0.5 / self.dt
        seen: dict[str, str] = {}
        for i, exp in enumerate(self.all_experiments()):
            where = f"experiments.{i}" if i < len(self.experiments) else "sequence"

            def at(key: str, where: str = where) -> str:
                return where if where == "sequence" else f"{where}.{key}"

            twice = repeated([e.name for e in (*self.effects, *exp.effects)])
            if twice:
                raise NnidInputError(
                    f"experiment {exp.name!r}: effect {', '.join(twice)} given twice (once in "
                    "the config's effects, which apply to every experiment, or in its own)",
                    field=at("effects"),
                )
            for j, signal in enumerate(exp.signals):
                top = signal.top_frequency()
                if top >= nyquist:  # sampled at dt it would alias to a slower signal, unseen
                    key = signal.top_key()
                    raise NnidInputError(
                        f"experiment {exp.name!r}: its {signal.kind} reaches {top:g} Hz, at or "
                        f"above the {nyquist:g} Hz that dt = {self.dt:g} s can carry; expected "
                        f"below {nyquist:g} Hz (or a smaller dt)",
                        field=at(f"signals.{j}" + (f".{key}" if key else "")),
                    )
            if not exp.name.strip():
                raise NnidInputError(
                    "every experiment needs a name: a non-blank text is expected",
                    field=at("name"),
                )
            try:  # one line, as a vehicle's name: it labels the log's runs and report lines
                vehicle_name(exp.name)
            except ValueError as exc:
                raise NnidInputError(f"experiment {exp.name!r}: {exc}", field=at("name")) from None
            if exp.name in seen:
                # a run of the sequence has a fixed name: the explicit experiment's is the key
                # to change
                first = seen[exp.name]
                explicit = where == "sequence" and first != "sequence"
                raise NnidInputError(
                    f"experiment name {exp.name!r} is used twice (also by "
                    f"{'a run of the sequence' if explicit else first}): each experiment needs "
                    "its own name",
                    field=f"{first}.name" if explicit else at("name"),
                )
            seen[exp.name] = where
            # the end is the duration if given, else the signals' last end
            length = at("duration") if exp.duration is not None else at("signals")
            if round(exp.end() / self.dt) < 1:  # the simulator logs round(end / dt) + 1
                raise NnidInputError(
                    f"experiment {exp.name!r} lasts {exp.end():g} s, under one step dt = "
                    f"{self.dt:g} s: it would log a single sample; expected at least one "
                    f"step ({self.dt:g} s)",
                    field=length,
                )
            if exp.end() / self.dt > MAX_RUN_SAMPLES:
                raise NnidInputError(
                    f"experiment {exp.name!r} lasts {exp.end():g} s: {exp.end() / self.dt:.3g} "
                    f"steps of dt = {self.dt:g} s, more than the {MAX_RUN_SAMPLES:.0e} a run may "
                    "hold (is dt in seconds?)",
                    field=length,
                )
        return self

    def all_experiments(self) -> list[Experiment]:
        """The explicit experiments followed by those of the sequence."""
        extra = self.sequence.experiments() if self.sequence else []
        return [*self.experiments, *(Experiment.model_validate(e) for e in extra)]


# -- data ----------------------------------------------------------------------------------------


class _DataCommon(StrictModel):
    """What every data source shares: the experiments to keep, the Savitzky-Golay filter
    (``savgol_window`` s, ``savgol_order``) that derives the velocities a log lacks from its
    pose (once, before the split: every model is fitted and scored on the same velocities),
    and light white noise on logged signals (``noise``: standard deviation as a fraction of
    each column's, on ``noise_columns``, default the inputs and velocities; seeded by
    ``noise_seed``; Weiss V.B) of at most the column's own std (``noise`` ≤ 1)."""

    experiments: Names | None = None
    # light noise: at 1 it is as large as the signal it is added to, beyond it the column is
    # mostly noise (1e300 was taken, and every score read "diverged")
    noise: float = Field(0.0, ge=0, le=1.0, allow_inf_nan=False)
    noise_columns: Names | None = None
    noise_seed: Seed = 0
    savgol_window: PositiveFloat = 1.0
    savgol_order: int = Field(4, ge=2, le=8)

    @field_validator("experiments")
    @classmethod
    def _not_empty(cls, names: list[str] | None) -> list[str] | None:
        # an empty list was read as no list: every run kept and fitted without a word
        if names is not None and not names:
            raise ValueError(
                "an empty list keeps no experiment: name at least one, or leave the key out "
                "to keep every experiment of the log"
            )
        return names

    @model_validator(mode="after")
    def _noise_given(self) -> _DataCommon:
        if self.noise == 0:
            _inert(self, ("noise_columns",), "noise = 0 (no noise is added)",
                   "give noise, the fraction of each column's std to add")  # fmt: skip
        return self


class VehicleData(_DataCommon):
    """A vehicle log: a file (``log``, through a reader config ``columns`` if it is not in
    nnid's format) or a simulate config run on the fly (``simulate``). Paths are relative to
    the config file; ``--data`` and ``--columns`` override them. ``time_unit`` declares the
    unit of a log file's ``t`` (``s``, ``ms``, ``us``, ``ns``; ``--time-unit`` overrides it):
    converted to seconds, and not guessed from its steps."""

    kind: Literal["vehicle"] = "vehicle"
    log: PathText | None = None
    columns: PathText | None = None
    simulate: PathText | None = None
    time_unit: Literal["s", "ms", "us", "ns"] | None = None

    @model_validator(mode="after")
    def _one_log(self) -> VehicleData:
        # the log was read and the simulation dropped without a word (its file still required)
        if self.log is not None and self.simulate is not None:
            raise NnidInputError(
                "a [data] table reads one log: data.log (a file) or data.simulate (a simulate "
                "config run here), not both; remove one",
                field="simulate",
            )
        return self


class TableData(_DataCommon):
    """A generic input-output table (``t``, optional ``experiment``, the model's named columns),
    not a vehicle log: for the input-output models (NARX, neural state space)."""

    kind: Literal["table"]
    log: PathText | None = None


class SinusoidSpec(StrictModel):
    """Caccia's d-optimal sinusoid run φⁿ = offset + amplitude sin(ω_opt t) (eqs 13-15) on the
    DOF's force channel, designed from step 1 of the campaign: ``prior_inertia`` (kg, or
    kg m²; default the rigid inertia × (1 + ``prior_added_fraction``), Caccia's range 0.1-1,
    L153), ``duration`` s, the noise ``seed`` and an optional ``measurement``."""

    offset: Number
    amplitude: PositiveFloat
    prior_inertia: PositiveFloat | None = None
    prior_added_fraction: float = Field(0.5, ge=0.1, le=1.0)
    duration: PositiveFloat
    seed: Seed = 1000
    measurement: Measurement | None = None

    @model_validator(mode="after")
    def _no_inversion(self) -> SinusoidSpec:
        if self.amplitude > abs(self.offset):
            raise ValueError("amplitude must not exceed |offset|: the thrust would reverse")
        return self


class ValidationRunSpec(StrictModel):
    """A held-out PRBS run on the identified DOF (``experiment`` names it), from the campaign's
    plant with fresh noise: amplitude ``fraction`` × the largest of |offset|, the sinusoid's
    amplitude and the campaign's RMS force, switching every ``hold`` s."""

    experiment: str = "validation_prbs"
    duration: PositiveFloat = 120.0
    hold: PositiveFloat = 8.0
    fraction: PositiveFloat = 0.6
    seed: Seed = 5


class CacciaCampaignData(_DataCommon):
    """Caccia's campaign simulated end to end (section III): the steady-state campaign
    (``campaign``, a simulate config; ``campaign_seed`` replaces its noise seed), then the
    d-optimal ``sinusoid`` designed from step 1 of the model's procedure and flown, then an
    optional held-out ``validation`` run. One log; its experiments are the campaign's,
    ``sinusoid`` and the validation run's."""

    kind: Literal["caccia_campaign"]
    campaign: PathText
    campaign_seed: Seed | None = None
    sinusoid: SinusoidSpec
    validation: ValidationRunSpec | None = Field(default_factory=ValidationRunSpec)


DataSpec = Annotated[VehicleData | TableData | CacciaCampaignData, Field(discriminator="kind")]


#: a split given both ways, named experiments and fractions (a train config's [split], a loop
#: config's validation and validation_fraction): the fractions were dropped without a word
FRACTIONS_BESIDE_NAMES = (
    "gives fractions beside named experiments: a split names its experiments or cuts "
    "by fractions, not both"
)


def _data_kind(value: Any) -> Any:
    """A ``[data]`` table without ``kind`` is a vehicle log."""
    if isinstance(value, dict) and "kind" not in value:
        return {**value, "kind": "vehicle"}
    return value


class SplitSpec(StrictModel):
    """Train / validation / test: whole ``experiment``s (named, or by ``fractions`` of the
    samples in order), contiguous ``block``s of each experiment (MATLAB's divideblock), or
    ``auto``: whole experiments when every part with a fraction gets at least one, else blocks
    (the residual loop's rule: a config that runs on any log). A key left out is not named; a
    list given is what it says: ``test = []`` is no test part, and an empty ``train`` or
    ``validation`` (a fit needs both) is refused, not read as "split by fractions"."""

    by: Literal["experiment", "block", "auto"] = "block"
    fractions: list[Annotated[float, Field(ge=0, le=1)]] = Field(
        default_factory=lambda: [0.7, 0.15, 0.15], min_length=3, max_length=3
    )
    train: Names | None = None
    validation: Names | None = None
    test: Names | None = None

    @field_validator("train", "validation")
    @classmethod
    def _not_empty(cls, names: list[str] | None, info) -> list[str] | None:
        if names is not None and not names:
            raise ValueError(
                f"an empty list names no {info.field_name} experiment, and a fit needs one: "
                "name at least one, or leave the key out to split by fractions"
            )
        return names

    @model_validator(mode="after")
    def _consistent(self) -> SplitSpec:
        # what the config alone shows, said before any log is read or simulated; what needs
        # the log (a name it lacks, a part left empty) is make_split's
        from nnid.datasets.splits import PARTS, check_disjoint, check_fractions

        check_fractions(self.fractions)
        named = [p for p in PARTS if getattr(self, p) is not None]  # test = [] says: no test
        if named and self.by != "experiment":  # they would be ignored
            raise NnidInputError(
                f'lists experiments for {", ".join(named)}, which only by = "experiment" uses '
                f"(by = {self.by!r} cuts every experiment by fractions)",
                field=named[0],
            )
        check_disjoint({p: getattr(self, p) for p in named})
        if named and "fractions" in self.model_fields_set:  # they would be ignored
            raise NnidInputError(FRACTIONS_BESIDE_NAMES, field="fractions")
        return self


# -- trainers ------------------------------------------------------------------------------------


class _Trainer(StrictModel):
    def build(self):
        """The trainer these options describe."""
        from nnid.models.base import trainer_class

        return trainer_class(self.kind)(**self.model_dump(exclude={"kind"}))  # type: ignore[attr-defined]


class LeastSquaresSpec(_Trainer):
    """Batch least squares with covariance (:class:`nnid.trainers.least_squares.LeastSquares`)."""

    kind: Literal["ls"]
    weighting: Literal["feasible", "none"] = "feasible"
    filter_lambda: PositiveFloat | None = None
    correlated: bool = True


class RecursiveSpec(_Trainer):
    """Recursive least squares with forgetting (Weiss eqs 52-53)."""

    kind: Literal["rls"]
    forgetting: float = Field(1.0, gt=0, le=1)
    p0: PositiveFloat = 1e6
    filter_lambda: PositiveFloat | None = None
    theta0: list[Number] | None = None


class GradientSpec(_Trainer):
    """Weiss's gradient estimator (eqs 62-65)."""

    kind: Literal["gradient"]
    gain: Number | list[Number] | list[list[Number]] = 1.0
    normalized: bool = False
    filter_lambda: PositiveFloat | None = None
    theta0: list[Number] | None = None
    dt: PositiveFloat | None = None

    @field_validator("gain")
    @classmethod
    def _gain(cls, gain: Any) -> Any:
        """Γ as the gradient law takes it, the check a gain given from Python gets too
        (:func:`~nnid.trainers.recursive.gain_problem`): a scalar or vector above 0, a matrix
        square, symmetric and positive definite (a ragged one failed in numpy with a
        traceback, a negative definite one climbed the squared error)."""
        from nnid.trainers.recursive import gain_problem

        problem = gain_problem(gain)
        if problem:
            raise ValueError(problem)
        return gain


class KalmanSpec(_Trainer):
    """The augmented-state unscented Kalman filter (Weiss eqs 77-84)."""

    kind: Literal["ukf"]
    # per √s (UnscentedKalman): 1e-3 and 1e-4 per step at 20 Hz, the rate they were chosen at
    process_noise: PositiveFloat | list[PositiveFloat] = 1e-3 / 0.05**0.5
    measurement_noise: PositiveFloat | list[PositiveFloat] | None = None
    parameter_noise: float = Field(1e-4 / 0.05**0.5, ge=0, allow_inf_nan=False)
    theta0: list[Number] | None = None
    theta0_std: list[PositiveFloat] | None = None
    min_std: PositiveFloat = 1e-3
    alpha: PositiveFloat = 0.1
    beta: Number = 2.0
    kappa: Number = 0.0
    check: bool = True


class LevenbergMarquardtSpec(_Trainer):
    """Levenberg-Marquardt (MATLAB's trainlm defaults; Weiss eqs 54-61)."""

    kind: Literal["lm"]
    mu: PositiveFloat = 1e-3
    mu_dec: float = Field(0.1, gt=0, lt=1)
    mu_inc: float = Field(10.0, gt=1, allow_inf_nan=False)
    mu_max: PositiveFloat = 1e10
    max_epochs: int = Field(1000, ge=1)
    max_fail: int = Field(6, ge=1)
    min_grad: float = Field(1e-7, ge=0, allow_inf_nan=False)
    goal: float = Field(0.0, ge=0, allow_inf_nan=False)
    memory_budget_mb: PositiveFloat = 256.0
    jacobian: Literal["auto", "forward", "reverse", "samples"] = "auto"
    damping: Literal["trainlm", "nielsen"] = "trainlm"
    l2: float = Field(0.0, ge=0, allow_inf_nan=False)
    geodesic: bool = False
    geodesic_ratio: PositiveFloat = 0.75


class AdamSpec(_Trainer):
    """Adam with a learning-rate schedule and early stopping."""

    kind: Literal["adam"]
    lr: PositiveFloat = 1e-2
    max_epochs: int = Field(200, ge=1)
    schedule: Literal["cosine", "plateau", "constant"] = "cosine"
    lr_min: float = Field(1e-4, ge=0, allow_inf_nan=False)
    plateau: int = Field(5, ge=1)
    clip: PositiveFloat | None = 1.0
    max_fail: int = Field(20, ge=1)
    weight_decay: float = Field(0.0, ge=0, allow_inf_nan=False)
    max_seconds: PositiveFloat | None = None
    average: float | None = Field(None, gt=0, lt=1)

    @model_validator(mode="after")
    def _floor_below_rate(self) -> AdamSpec:
        # the schedule anneals from lr down to lr_min: a floor given above it is a typo (the
        # default floor, 1e-4, only stops the annealing of a smaller lr: the trainer's rule)
        if "lr_min" in self.model_fields_set and self.lr_min > self.lr:
            raise ValueError(f"lr_min ({self.lr_min:g}) must not exceed lr ({self.lr:g})")
        if self.schedule != "plateau":  # the patience of the plateau schedule alone
            _inert(self, ("plateau",), f'schedule = "{self.schedule}" (the patience of the '
                   '"plateau" schedule)', 'set schedule = "plateau"')  # fmt: skip
        if self.schedule == "constant":  # the floor the other schedules anneal to
            _inert(self, ("lr_min",), 'schedule = "constant" (which keeps lr)',
                   'set schedule = "cosine" or "plateau"')  # fmt: skip
        return self


RegressionTrainer = Annotated[
    LeastSquaresSpec | RecursiveSpec | GradientSpec | KalmanSpec, Field(discriminator="kind")
]
NetworkTrainer = Annotated[LevenbergMarquardtSpec | AdamSpec, Field(discriminator="kind")]


# -- models --------------------------------------------------------------------------------------


class _Model(StrictModel):
    """A model table: ``kind`` and the model's constructor arguments; ``name`` labels it in a
    comparison (default: its kind)."""

    name: Label | None = None

    @field_validator("trainer", mode="before", check_fields=False)
    @classmethod
    def _trainer_name(cls, value: Any) -> Any:
        return _kind_shorthand(value)

    @property
    def fitted(self) -> _Model:
        """The table of the model fitted to the data: this one (an ensemble's: its member)."""
        return self

    def build(self, vehicle=None):
        """The (unfitted) model: ``from_config`` of its class."""
        from nnid.models.base import model_class

        return model_class(self.kind).from_config(self, vehicle)  # type: ignore[attr-defined]

    def label(self) -> str:
        return self.name or self.kind  # type: ignore[attr-defined]

    def arguments(self) -> dict[str, Any]:
        """The constructor arguments (the trainer built, ``name`` and ``kind`` left out)."""
        args = self.model_dump(exclude={"kind", "name", "trainer"})
        trainer = getattr(self, "trainer", None)
        if trainer is not None:
            args["trainer"] = trainer.build()
        return args


class SequenceStep(StrictModel):
    """One step of a decoupled identification sequence (Weiss eqs 99-108)."""

    experiments: Annotated[Names, Field(min_length=1)]
    dofs: Dofs
    unknowns: Annotated[Names, Field(min_length=1)]


class _PhysicsModel(_Model):
    """A model with a parametric Fossen fit: unknown parameters (``added_mass`` and
    ``damping`` are shortcuts for the DOFs' diagonal added mass and the vehicle's damping
    terms; ``damping`` written where the vehicle declares none in those equations is
    refused, and by default said not estimated)
    identified from the ``dofs`` equations."""

    unknowns: Names = Field(default_factory=lambda: ["added_mass", "damping"])
    dofs: Dofs = Field(default_factory=lambda: list(DOFS))
    savgol_window: PositiveFloat = 1.0
    savgol_order: int = Field(4, ge=2, le=8)

    @field_validator("unknowns")
    @classmethod
    def _names(cls, unknowns: list[str]) -> list[str]:
        from nnid.models.parametric import canonical_parameter

        for name in unknowns:
            if name not in ("added_mass", "damping"):
                canonical_parameter(name)
        return unknowns


class FossenModelSpec(_PhysicsModel):
    """The parametric Fossen model (:class:`nnid.models.parametric.ParametricModel`): which
    parameters are unknown, from which DOF equations, with which trainer; ``sequence`` runs
    Weiss's decoupled sequence instead."""

    kind: Literal["fossen"] = "fossen"
    sequence: Literal["weiss"] | list[SequenceStep] | None = None
    zoh_midpoint: bool = False
    trainer: RegressionTrainer | None = None

    @model_validator(mode="after")
    def _sequence_alone(self) -> FossenModelSpec:
        # the steps name their own unknowns and DOFs: beside a sequence these were dropped
        if self.sequence is not None:
            _inert(self, ("dofs", "unknowns"), "a sequence (its steps name the unknowns and "
                   "the DOF equations they are fitted from)", "the sequence")  # fmt: skip
        return self


class CacciaModelSpec(_Model):
    """Caccia's two-step model of one DOF (:class:`nnid.models.caccia.CacciaModel`)."""

    kind: Literal["caccia"]
    dof: Dof = "w"
    sinusoid_experiment: str = "sinusoid"
    # a TOML pair is a list: the one field of a strict config that takes it as a tuple
    reference: list[Annotated[tuple[str, Literal["pos", "neg"]], Strict(False)]] = Field(
        default_factory=lambda: [("", "pos")]
    )
    mode_column: str | None = None
    force_eta_one: bool = False
    terms: list[Literal["linear", "quadratic"]] = Field(
        default_factory=lambda: ["linear", "quadratic"], min_length=1
    )
    settings: dict[str, int] | None = None
    settle_window: PositiveFloat = 10.0
    settle_order: int = Field(2, ge=1, le=6)
    settle_accel: PositiveFloat = 2e-3
    min_plateau: PositiveFloat = 10.0
    speed: Literal["slope", "mean", "asymptote"] = "asymptote"
    velocity_window: PositiveFloat = 5.0
    velocity_order: int = Field(4, ge=2, le=8)
    correlated: bool = True
    weighting: Literal["none", "speed"] = "speed"


class SynthesisModelSpec(_Model):
    """A named damping model of the basis library fitted to McCarter's τ̄
    (:class:`nnid.models.synthesis.SynthesisModel`)."""

    kind: Literal["synthesis"]
    mask: MaskName | dict[Force, list[str]] = "mcfarland"
    method: Literal["ls", "mae", "mse", "rms", "mad"] = "ls"
    savgol_window: PositiveFloat = 1.0
    savgol_order: int = Field(4, ge=2, le=8)
    filter_lambda: PositiveFloat | None = None
    zoh_midpoint: bool = False

    @field_validator("mask")
    @classmethod
    def _mask(cls, mask: str | dict[str, list[str]]) -> str | dict[str, list[str]]:
        # said here, where the config names the field, not at fit time in the library
        from nnid.physics.damping_library import canonical_term

        if isinstance(mask, dict):
            if not any(mask.values()):
                raise ValueError("a mask of no terms fits nothing: name a model or give terms")
            for force, names in mask.items():
                try:
                    _once([canonical_term(t) for t in names])
                except ValueError as exc:
                    raise ValueError(f"{force}: {exc}") from None
        return mask


class SindyModelSpec(_Model):
    """SINDy over the basis library (:class:`nnid.models.sindy.SindyDamping`)."""

    kind: Literal["sindy"]
    optimizer: Literal["stlsq", "sr3", "ensemble"] = "stlsq"
    thresholds: Annotated[list[PositiveFloat], Field(min_length=1)] | None = None
    selection: Literal["validation", "aic", "bic"] = "validation"
    tolerance: float = Field(0.05, ge=0, allow_inf_nan=False)
    mode: Literal["residual", "control"] = "residual"
    terms: Annotated[list[str], Field(min_length=1)] | None = None
    alpha: float = Field(1e-8, ge=0, allow_inf_nan=False)
    holdout: float = Field(0.2, gt=0, lt=1)
    per_output: bool = True
    savgol_window: PositiveFloat = 1.0
    savgol_order: int = Field(4, ge=2, le=8)
    filter_lambda: PositiveFloat | None = None
    zoh_midpoint: bool = False
    seed: Seed = 0

    @field_validator("terms")
    @classmethod
    def _terms(cls, terms: list[str] | None) -> list[str] | None:
        # said here, where the config names the field, not at fit time in the library
        from nnid.physics.damping_library import canonical_term

        if terms is not None:
            _once([canonical_term(t) for t in terms])
        return terms


Bound = float | Literal["train", "open"]


def _bounds(value: Any) -> Any:
    """TOML has no null: "open" stands for an open bound."""
    if isinstance(value, list):
        return [[None if v == "open" else v for v in pair] for pair in value]
    return value


def _columns(names: list[str]) -> list[str]:
    """Log columns a network reads or predicts: each once, and data, not the time or the run
    label."""
    _once(names)
    if {"t", "experiment"} & set(names):
        raise ValueError("'t' and 'experiment' label the samples; they are not signals")
    return names


#: the input or output columns of an input-output model (:func:`_columns`)
Columns = Annotated[list[str], Field(min_length=1), AfterValidator(_columns)]


class _InputOutput(_Model):
    """What the input-output models share: an output is never also an input (the model would
    read the measured answer, in free run too)."""

    inputs: Columns
    outputs: Columns

    @model_validator(mode="after")
    def _disjoint(self) -> _InputOutput:
        disjoint_columns(self.inputs, self.outputs)  # the models' own check, named at inputs
        return self


class NarxModelSpec(_InputOutput):
    """A NARX network (:class:`nnid.models.narx.NarxModel`; Weiss IV.A.2, V.B): named input
    and output columns, delays (a count n means 1..n), hidden tanh layers, balanced sampling,
    optional simulation-error fine-tuning and output bounds ("train" or one [low, high] per
    output, each a number, "train" or "open")."""

    kind: Literal["narx"]
    input_delays: Annotated[int, Field(ge=1)] | list[Annotated[int, Field(ge=0)]] = 2
    output_delays: Annotated[int, Field(ge=1)] | list[Annotated[int, Field(ge=1)]] = 2
    # at least one layer: both closed loops (torch's, the compiled kernel) start from one
    hidden: list[Annotated[int, Field(ge=1, le=MAX_WIDTH)]] = Field(
        default_factory=lambda: [10], min_length=1
    )
    balanced: bool = True
    seed: Seed = 0
    delta: bool = True
    multi_step: int = Field(1, ge=1)
    simulation_epochs: int = Field(0, ge=0)
    simulation_window: int | list[int] = 200
    simulation_lr: PositiveFloat = 1e-3
    batch_size: int = Field(256, ge=1)
    samples_per_epoch: int | None = Field(None, ge=1)
    lm_samples: int = Field(4000, ge=10)
    output_bounds: Literal["train"] | list[list[Bound]] | None = None
    simulation_trainer: Literal["adam", "lm"] = "adam"
    simulation_max_fail: int = Field(8, ge=1)
    simulation_l2: float = Field(0.0, ge=0, allow_inf_nan=False)
    simulation_l2_center: Literal["zero", "one_step"] = "zero"
    simulation_curvature: float = Field(1.0, gt=0, le=1)
    simulation_run_floor: float | None = Field(None, gt=0, le=1)
    output_transform: Literal["sqrt", "products", "fossen"] | None = None
    rest_equilibrium: bool = False
    trainer: NetworkTrainer | None = None

    @field_validator("simulation_window")
    @classmethod
    def _windows(cls, window: int | list[int]) -> int | list[int]:
        try:
            window_lengths(window)  # the model's own check
        except NnidInputError as err:  # said against this key, as a field's error is
            raise ValueError(err.message) from None
        return window

    @model_validator(mode="after")
    def _rest_needs_delta(self) -> NarxModelSpec:
        if self.rest_equilibrium and not self.delta:
            raise ValueError("rest_equilibrium pins the Δ increment at rest: it needs delta = true")
        if self.simulation_epochs == 0:  # no simulation-error stage: its settings are unread
            stage = tuple(k for k in type(self).model_fields if k.startswith("simulation_"))
            _inert(self, tuple(k for k in stage if k != "simulation_epochs"),
                   "simulation_epochs = 0 (no simulation-error stage)",
                   "give simulation_epochs")  # fmt: skip
        if not isinstance(self.trainer, LevenbergMarquardtSpec):  # None: Adam
            _inert(self, ("lm_samples",), "an Adam trainer (LM's full-batch draw)",
                   'set trainer = "lm"')  # fmt: skip
        return self

    def arguments(self) -> dict[str, Any]:
        args = super().arguments()
        args["output_bounds"] = _bounds(args["output_bounds"])
        return args

    def epoch_measures(self) -> set[str]:
        """The validation measures the fit scores every epoch, in the sweep's metric names:
        its series-parallel stage's, and the free run's where it has a simulation stage (with
        a validation log, which a config's split always gives: ``NarxModel._fit``)."""
        first = "one_step_nrmse" if self.multi_step == 1 else "k_step_nrmse"
        return {first} | ({"free_run_nrmse"} if self.simulation_epochs > 0 else set())


class StateSpaceModelSpec(_InputOutput):
    """A continuous-time neural state-space model (:class:`nnid.models.neural_state_space.
    NeuralStateSpace`): the outputs are the first states, ``hidden_states`` more are
    unmeasured; ``structure`` (optional) is one row of 0/1 per state derivative over the states
    then the inputs; ``windows`` are the training stages' window lengths in samples (0: whole
    experiments); ``warmup`` samples estimate each run's initial state and are never scored."""

    kind: Literal["state_space"]
    hidden_states: int = Field(1, ge=0)
    hidden: int = Field(16, ge=1, le=MAX_WIDTH)
    structure: list[list[Literal[0, 1]]] | None = None
    substeps: int = Field(1, ge=1)
    warmup: int = Field(10, ge=1)
    windows: list[Annotated[int, Field(ge=0)]] = Field(default_factory=lambda: [0], min_length=1)
    state_epochs: int = Field(50, ge=1)
    continuity: float = Field(1.0, ge=0, allow_inf_nan=False)
    output_bounds: Literal["train"] | list[list[Bound]] | None = None
    seed: Seed = 0
    trainer: NetworkTrainer | None = None

    def arguments(self) -> dict[str, Any]:
        args = super().arguments()
        args["output_bounds"] = _bounds(args["output_bounds"])
        args["windows"] = [w or None for w in args["windows"]]
        return args


class HybridModelSpec(_PhysicsModel):
    """A neural-ODE hybrid (:class:`nnid.models.hybrid.HybridModel`): the parametric Fossen
    fit (``unknowns``, ``dofs``, ``physics_trainer``) plus a network (``hidden`` tanh layers)
    that learns the force the physics misses, trained by multiple shooting over ``segments``
    (seconds, one stage each) with ``trainer`` (Adam or LM) and early stopping on held-out
    free runs."""

    kind: Literal["hybrid"]
    physics: Literal["frozen", "joint"] = "frozen"
    level: Literal["force", "acceleration"] = "force"
    physics_trainer: RegressionTrainer | None = None
    hidden: list[Annotated[int, Field(ge=1, le=MAX_WIDTH)]] = Field(
        default_factory=lambda: [32, 32]
    )
    memory: list[PositiveFloat] = Field(default_factory=lambda: [0.25, 1.0])
    force_penalty: float = Field(1e-3, ge=0, allow_inf_nan=False)
    prior: PositiveFloat = 0.1
    prior_weight: float = Field(1e-2, ge=0, allow_inf_nan=False)
    segments: list[Duration] = Field(default_factory=lambda: [0.5, 1.0, 2.0], min_length=1)
    batch_segments: int = Field(256, ge=1)
    balance: bool = True
    validation_window: Duration | None = 5.0
    method: Literal["auto", "rk4", "dopri5", "nnid_rk4"] = "auto"
    adjoint: bool = False
    zoh_midpoint: bool = True
    seed: Seed = 0
    trainer: NetworkTrainer | None = None

    @field_validator("physics_trainer", mode="before")
    @classmethod
    def _physics_trainer_name(cls, value: Any) -> Any:
        return _kind_shorthand(value)

    @model_validator(mode="after")
    def _adjoint_needs_torchdiffeq(self) -> HybridModelSpec:
        # the model's own check, named at model.adjoint: the physics fit ran, then a traceback
        adjoint_solver(self.adjoint, isinstance(self.trainer, LevenbergMarquardtSpec), self.method)
        return self

    def arguments(self) -> dict[str, Any]:
        args = super().arguments()
        del args["physics_trainer"]
        if self.physics_trainer is not None:
            args["physics_trainer"] = self.physics_trainer.build()
        return args


SeededModelSpec = Annotated[
    NarxModelSpec | StateSpaceModelSpec | HybridModelSpec, Field(discriminator="kind")
]


class EnsembleModelSpec(_Model):
    """A seed ensemble (:class:`nnid.models.ensemble.EnsembleModel`): the ``[model.member]``
    table (a narx, state_space or hybrid model, without its own ``seed``) fitted once per
    seed in ``seeds``, predicting the pointwise ``combine`` of the members; with
    ``drop_diverged`` a member whose validation free run diverges is left out; ``n_jobs``
    members are fitted at once, each in its own process."""

    kind: Literal["ensemble"]
    member: SeededModelSpec
    seeds: list[Seed] = Field(default_factory=lambda: [0, 1, 2], min_length=2)
    combine: Literal["mean", "median"] = "mean"
    drop_diverged: bool = True
    n_jobs: int = Field(1, ge=1)

    @model_validator(mode="after")
    def _seeds(self) -> EnsembleModelSpec:
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError("the ensemble's seeds must differ")
        if "seed" in self.member.model_fields_set:
            raise ValueError("the members' seeds are the ensemble's 'seeds', not member.seed")
        return self

    @property
    def fitted(self) -> _Model:
        return self.member

    def arguments(self) -> dict[str, Any]:
        return self.model_dump(include={"seeds", "combine", "drop_diverged", "n_jobs"})


ModelSpec = Annotated[
    FossenModelSpec
    | CacciaModelSpec
    | SynthesisModelSpec
    | SindyModelSpec
    | NarxModelSpec
    | StateSpaceModelSpec
    | HybridModelSpec
    | EnsembleModelSpec,
    Field(discriminator="kind"),
]
PHYSICS_KINDS = ("fossen", "caccia", "synthesis", "sindy", "hybrid")
#: models that count time in samples (delays, integration steps): they need uniform sampling
SAMPLE_KINDS = ("narx", "state_space", "hybrid")


# -- commands ------------------------------------------------------------------------------------


class _Command(StrictModel):
    @field_validator("data", mode="before", check_fields=False)
    @classmethod
    def _data(cls, value: Any) -> Any:
        return _data_kind(value)


class DetectSpec(StrictModel):
    """``[detect]`` of a train config: calibrate a residual monitor
    (:class:`nnid.fault.monitor.ResidualMonitor`) on the validation part of the healthy log
    (never on the data the model was fitted on) and measure its false alarms on the test part;
    ``nnid detect --model DIR`` then works from the output folder alone."""

    false_alarm_per_hour: float = Field(
        0.01, gt=0, le=MAX_FALSE_ALARMS_PER_HOUR, allow_inf_nan=False
    )
    time_constant_s: PositiveFloat = 0.25
    allowance: PositiveFloat = 1.0
    rearm_s: PositiveFloat = 5.0
    # as --window bounds it; longer than the longest run of the log it calibrates on is refused
    # (nnid.pipeline.check_detect_window)
    window_s: float = Field(10.0, ge=MIN_WINDOW_S, allow_inf_nan=False)


def _option_path(path: str) -> str:
    """``path`` as a sweep sets it: dotted keys of the train config, none empty (``""`` or
    ``model..hidden`` set a key no config has, said without the path), and none in the
    ``[sweep]`` table or the config's ``kind`` (every trial would fit the same config)."""
    keys = path.split(".")
    if not all(k.strip() for k in keys):
        raise ValueError(
            f"{path!r} is no option path: dotted keys of the config, such as model.hidden"
        )
    if keys[0] in ("sweep", "kind"):
        raise ValueError(
            f"{path!r} is not searched: a sweep searches the train config's options, not its "
            "kind or its [sweep] table"
        )
    return path


def _same_value(a: Any, b: Any) -> bool:
    """Whether two TOML values are one setting: equal, and a boolean only to a boolean
    (Python's ``True == 1`` read ``[1, true]`` as "lists True twice"); 1 and 1.0 are one."""
    if isinstance(a, bool) or isinstance(b, bool):
        return type(a) is type(b) and a == b
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(map(_same_value, a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same_value(a[k], b[k]) for k in a)
    return a == b


class SweepSpec(StrictModel):
    """``[sweep]`` of a train config, read by ``nnid sweep``: option paths (dotted, as in the
    config: ``model.hidden``, ``model.trainer.lr``) searched on a grid (every combination)
    and/or by ``samples`` random draws from lists of choices, each setting fitted once per
    seed (set at ``seed_option``); settings are ranked by the mean over seeds of the
    validation part's ``metric`` (total over the excited DOFs), never by the test part."""

    grid: dict[str, list[Any]] = Field(default_factory=dict)
    random: dict[str, list[Any]] = Field(default_factory=dict)
    samples: int = Field(0, ge=0, le=MAX_SAMPLES)
    seed: Seed = 0  # of the random draws
    seeds: list[Seed] = Field(default_factory=list)
    seed_option: str = "model.seed"
    metric: Literal["free_run_nrmse", "one_step_nrmse", "k_step_nrmse"] = "free_run_nrmse"
    # on Ray (--address): Ray Tune's ASHA stops trials whose per-epoch validation objective
    # trails the others' at a rung (grace_epochs, then every reduction_factor × more epochs)
    early_stopping: bool = True
    grace_epochs: int = Field(10, ge=1)
    reduction_factor: int = Field(3, ge=2)

    @field_validator("grid", "random")
    @classmethod
    def _paths(cls, searched: dict[str, list[Any]]) -> dict[str, list[Any]]:
        for path, values in searched.items():
            _option_path(path)
            for i, value in enumerate(values):
                # a grid's repeat was merged into one setting, its seeds' scores counted twice
                # in the mean; a random list's repeat is drawn twice as often
                if any(_same_value(value, v) for v in values[:i]):
                    raise NnidInputError(
                        f"{path} lists {value!r} twice: give each value once", field=f'"{path}"'
                    )
        return searched

    @field_validator("seed_option")
    @classmethod
    def _seed_path(cls, path: str) -> str:
        key = _option_path(path).split(".")[-1]
        if key != "seed" and not key.endswith("_seed"):  # warmup_s took the seeds as seconds
            raise ValueError(
                f"{path!r} is no seed: seeds are set at a config's seed (model.seed, the "
                "default, or a key ending in _seed)"
            )
        return path

    @model_validator(mode="after")
    def _searches(self) -> SweepSpec:
        if not (self.grid or self.random or self.seeds):
            raise ValueError("give a grid, random choices or seeds to search")
        if bool(self.random) != bool(self.samples):
            raise ValueError("random choices and samples (how many draws) go together")
        empty = [k for k, v in {**self.grid, **self.random}.items() if not v]
        if empty:
            raise ValueError(f"no values to try for {', '.join(empty)}")
        both = sorted(set(self.grid) & set(self.random))
        if both:  # a random draw would overwrite the grid's value unsaid
            raise ValueError(f"{', '.join(both)} is searched in both grid and random: choose one")
        if len(set(self.seeds)) != len(self.seeds):  # a seed twice would count its score twice
            raise ValueError(f"seeds must differ: {self.seeds}")
        if self.seeds and self.seed_option in {**self.grid, **self.random}:
            # each trial's seed comes from seeds: a grid on it would be overwritten unsaid
            raise ValueError(
                f"{self.seed_option} is set by seeds; search it in seeds or in the grid, not both"
            )
        return self


class TrainConfig(_Command):
    """``nnid train``: one model on one split, scored on the held-out parts."""

    kind: Literal["train"] = "train"
    vehicle: PathText = ""  # none: the default, never validated
    data: DataSpec | None = None
    model: ModelSpec = Field(default_factory=FossenModelSpec)
    split: SplitSpec = Field(default_factory=SplitSpec)
    warmup_s: float = Field(1.0, ge=0, allow_inf_nan=False)
    k_step_s: Duration | None = None
    reference: dict[str, float] = Field(default_factory=dict)
    reference_label: Label = "reference"
    # m/s; below a micrometre per second its square underflows the prime-system scale
    nondimensional_speed: Annotated[float, Field(ge=1e-6)] | None = None
    detect: DetectSpec | None = None
    sweep: SweepSpec | None = None  # read by nnid sweep; nnid train fits the config as written

    @model_validator(mode="after")
    def _reference_labelled(self) -> TrainConfig:
        if not self.reference:  # the label heads the [reference] values' column
            _inert(self, ("reference_label",), "no [reference] table (the label of its "
                   "values)", "give [reference]")  # fmt: skip
        return self

    @field_validator("model", mode="before")
    @classmethod
    def _model(cls, value: Any) -> Any:
        return _kind_shorthand(value)


class CompareConfig(_Command):
    """``nnid compare``: models of any kinds fitted on one split and compared on the same
    held-out experiments (test when the split has one, else validation)."""

    kind: Literal["compare"] = "compare"
    vehicle: PathText = ""  # none: the default, never validated
    data: DataSpec | None = None
    models: list[ModelSpec] = Field(min_length=1)
    split: SplitSpec = Field(default_factory=SplitSpec)
    warmup_s: float = Field(2.0, ge=0, allow_inf_nan=False)
    k_step_s: Duration = 2.0
    replay_autopilot: bool = True

    @field_validator("models", mode="before")
    @classmethod
    def _models(cls, value: Any) -> Any:
        return [_kind_shorthand(v) for v in value] if isinstance(value, list) else value

    @field_validator("models")
    @classmethod
    def _unique(cls, models: list) -> list:
        twice = repeated([m.label() for m in models])
        if twice:
            raise ValueError(f"model names must differ (give each a 'name'): {', '.join(twice)}")
        return models


def _off_at_zero(value: float | None) -> float | None:
    """A setting that 0 switches off, as None (what the loop takes for "no filter")."""
    return value or None


class LoopConfig(_Command):
    """``nnid loop CONFIG``: the residual loop on a log (``--data``/``--vehicle`` override)."""

    kind: Literal["loop"] = "loop"
    vehicle: PathText = ""  # none: the default, never validated
    data: VehicleData = Field(default_factory=VehicleData)
    # given, a list names something: [] is an error, not "all" (leave the key out for all)
    dofs: Dofs | None = None
    validation: Annotated[Names, Field(min_length=1)] | None = None  # default: the last 30 %
    validation_fraction: float = Field(0.3, gt=0, lt=1)
    max_effects: int = Field(3, ge=0)
    alpha: float = Field(
        0.01, ge=ALPHA_MIN, le=ALPHA_MAX
    )  # as --alpha and a batch manifest take it
    coupled: bool = True
    # Weiss's filtered regressors, F(s) = λ/(s + λ) in rad/s (eqs 86-92); 0 switches the filter
    # off (the loop alone filters by default, and TOML has no null to unset it; the trainers'
    # filter is off unless their filter_lambda is given)
    filter_lambda: Annotated[
        float | None, Field(ge=0, allow_inf_nan=False), AfterValidator(_off_at_zero)
    ] = 1.0
    savgol_window: PositiveFloat = 1.0
    savgol_order: int = Field(4, ge=2, le=8)
    warmup_s: float = Field(2.0, ge=0, allow_inf_nan=False)
    gate_horizon_s: PositiveFloat | None = None  # None: the gate is the free run

    @model_validator(mode="after")
    def _held_out_once(self) -> LoopConfig:
        # the named runs were held out and the fraction dropped without a word; a train
        # config's [split] refuses the same (SplitSpec)
        if self.validation is not None and "validation_fraction" in self.model_fields_set:
            raise NnidInputError(FRACTIONS_BESIDE_NAMES, field="validation_fraction")
        return self


#: keys of the earlier config format, with what replaced them
LEGACY_KEYS: dict[str, dict[str, str]] = {
    "train": {
        "narx": 'the network is a [model] table with kind = "narx"',
        "state_space": 'the network is a [model] table with kind = "state_space"',
        "fossen": 'unknowns and dofs go in a [model] table with kind = "fossen"',
        "options": "trainer options go in [model.trainer] with the trainer's kind",
        "trainer": "the trainer is [model.trainer] (or trainer = NAME inside [model])",
        "sequence": "sequence is a key of the [model] table",
        "savgol_window": "[data] savgol_window derives velocities, [model] its accelerations",
    },
    "compare": {
        "sindy": 'SINDy is one of the [[models]], kind = "sindy"',
        "horizon_s": "the k-step horizon is k_step_s",
        "filter_lambda": "filter_lambda is a key of each damping model in [[models]]",
    },
}
COMMANDS: dict[str, type[BaseModel]] = {
    "simulate": SimulateConfig,
    "train": TrainConfig,
    "compare": CompareConfig,
    "loop": LoopConfig,
}


def set_option(data: dict[str, Any], path: str, value: Any, source: str = "") -> None:
    """Set the dotted option ``path`` (``model.hidden``, ``model.trainer.lr``) of a config's
    data in place; a table on the way that is not there is made, a value on the way is an
    error naming the path."""
    *tables, key = path.split(".")
    node = data
    for i, name in enumerate(tables):
        child = node.get(name, {})
        if isinstance(child, str) and name in ("model", "trainer"):  # shorthand: kind only
            child = {"kind": child}
        if not isinstance(child, dict):
            raise NnidInputError(
                f"'{'.'.join(tables[: i + 1])}' is a value, not a table", source=source, field=path
            )
        node[name] = child
        node = child
    node[key] = value


def load_config(
    path: str | Path,
    model: type[BaseModel] = SimulateConfig,
    overrides: dict[str, Any] | None = None,
    command: str | None = None,
) -> BaseModel:
    """Read and validate a TOML config; raise NnidInputError naming the file and field. A
    config written for another command is refused with that command's name. ``overrides``
    set dotted option paths first (a sweep's trial). ``command``: the command the user ran,
    if not the one the config kind is named for (``nnid sweep`` reads a 'train' config)."""
    data = read_toml(path)
    for option, value in (overrides or {}).items():
        set_option(data, option, value, str(path))
    expected = next((k for k, m in COMMANDS.items() if m is model), None)
    if expected is not None:
        refuse_other_file(data, "config", f"a '{expected}' config", str(path))
    kind = data.get("kind")
    if expected is not None and isinstance(kind, str) and kind != expected:
        if kind in COMMANDS:
            what = f"this is a '{kind}' config (for `nnid {kind}`)"
        else:  # not a kind nnid has: say which there are (detection is a train config)
            what = f"'{kind}' is not a config kind (kinds: {', '.join(COMMANDS)})"
        extra = (
            "; fault detection is a 'train' config with a [detect] table"
            if kind == "detect"
            else ""
        )
        raise NnidInputError(
            f"{what}; `nnid {command or expected}` needs a '{expected}' config{extra}",
            source=str(path),
            field="kind",
        )
    for key, hint in LEGACY_KEYS.get(expected or "", {}).items():
        if key in data:
            raise NnidInputError(
                f"is a key of the config format before nnid 0.2: {hint} "
                "(see docs/reference.md, Configs)",
                source=str(path),
                field=key,
            )
    return validated(model, data, str(path))
