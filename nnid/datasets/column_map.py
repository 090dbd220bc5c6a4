"""The reader config (a small TOML next to a log): which files, which time column, which columns
become which log columns, in which units and frames, and the common time base.

```toml
name = "liu-bluerov1-2016"
root = "../../../shared/data/liu-bluerov1-2016"   # relative to this file; read by train,
                              # compare and sweep when the run gives no --data or data.log
rate = 50.0                   # Hz: resample every source onto one time base (absent: the
                              # median step of the fastest measured, "linear", source)
gap = 0.5                     # s: a longer gap splits an experiment instead of being bridged
experiment = "run"            # column naming the run; "file" = each file a run (its name without
                              # the suffix); absent = one run; a list of columns joins their values
                              # with "/" ("test/AddWeight_0")
include = "^(all|yaw)_"       # optional regex on experiment names (exclude likewise)
drop_nonfinite = false        # true: drop NaN/inf rows and report the count; false: error
vehicle = "bluerov1_liu.toml" # optional vehicle file, relative to this file

[[sources]]
file = "thrusters.csv.gz"     # a path or glob under root (or a bag topic, an ArduPilot message)
time = "t_unix_s"             # time column
time_scale = 1.0              # to seconds (1e-9 for nanoseconds); the default 1.0 declares
                              # nothing: the unit is still guessed from the steps
time_unit = "s"               # optional: declares the time column's unit (s, ms, us, ns),
                              # converted to seconds and not guessed from its steps (a 1-Hz
                              # logger stepping by whole seconds); not with another time_scale
# row_clock = 20.0            # or, instead of time_unit, optional, Hz: t = row number within
                              # the experiment / row_clock, for a time column too coarse to use
                              # (an hhmmss clock); time is then still read but only the row
                              # order counts
method = "hold"               # "hold" (zero-order, commands sent on change) or "linear"
hold_timeout = 0.5            # optional: a held value is stale this long after the last one
frame = "ned_frd"             # or "enu_flu": converted to NED/FRD after renaming
quaternion = []               # [w, x, y, z] source columns -> phi theta psi
[sources.columns]             # log column = source column, or a table
cmd_1 = { from = "pwm_1", offset = -1500.0, scale = 0.0025 }   # (pwm - 1500) / 400
psi = { from = "yaw", unit = "deg" }       # value = (x + offset) * scale, then the unit
u = { from = "vx", unit = "mm/s" }         # units: rad deg rad/s deg/s m cm mm m/s cm/s mm/s,
                                           # each checked against the pose or velocity
```
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Literal

from pydantic import Field, field_validator, model_validator

from nnid.datasets.log import (
    ACCELERATION,
    ANGLES,
    FASTEST_STEP,
    POSE,
    TAU,
    TIME_UNITS,
    VELOCITY,
    checked_time_unit,
)
from nnid.errors import NnidInputError
from nnid.validation import StrictModel, one_line, visible_line

UNITS = {"rad": 1.0, "deg": 0.017453292519943295, "rad/s": 1.0, "deg/s": 0.017453292519943295,
         "m": 1.0, "cm": 0.01, "mm": 0.001, "m/s": 1.0, "cm/s": 0.01, "mm/s": 0.001}  # fmt: skip
# (time is scaled by the source's ``time_scale``: no column takes "s" or "ms", which the
# message of an unknown unit had offered)
#: the units each pose and velocity column of the log may be converted from
TARGET_UNITS = {
    **dict.fromkeys(("x", "y", "z"), ("m", "cm", "mm")),
    **dict.fromkeys(("phi", "theta", "psi"), ("rad", "deg")),
    **dict.fromkeys(("u", "v", "w"), ("m/s", "cm/s", "mm/s")),
    **dict.fromkeys(("p", "q", "r"), ("rad/s", "deg/s")),
}
#: the log's own column names (ARCHITECTURE.md, the log); ``cmd_<thruster>`` besides
CONTRACT = (*POSE, *VELOCITY, *ACCELERATION, *TAU)


def _pattern(pattern: str) -> str:
    try:
        re.compile(pattern)
    except re.error as exc:  # not a ValueError: pydantic would let it through as a traceback
        raise ValueError(f"{pattern!r} is not a regular expression ({exc})") from None
    return pattern


class ColumnSpec(StrictModel):
    """value = (source + offset) * scale, then converted from ``unit`` to SI."""

    source: str = Field(alias="from")
    offset: float = Field(0.0, allow_inf_nan=False)
    # 0 is allowed (a channel known to stay neutral), and said in the cleaning report
    scale: float = Field(1.0, allow_inf_nan=False)
    unit: str | None = None

    @field_validator("unit")
    @classmethod
    def _unit(cls, unit: str | None) -> str | None:
        if unit is not None and unit not in UNITS:
            raise ValueError(f"unknown unit '{unit}'; expected one of {', '.join(UNITS)}")
        return unit

    def factor(self) -> float:
        return self.scale * (UNITS[self.unit] if self.unit else 1.0)


#: the axis letter a quaternion column's name ends in, after an optional '.' or '_'
_AXIS_END = re.compile(r"[._]?([wxyz])$", re.IGNORECASE)


class Source(StrictModel):
    file: str
    time: str
    time_scale: float = Field(1.0, gt=0)
    #: the declared unit of ``time`` (one of :data:`~nnid.datasets.log.TIME_UNITS`): the
    #: default ``time_scale`` of 1.0 cannot tell "seconds, as declared" from "not said"
    time_unit: str | None = None
    row_clock: float | None = Field(None, gt=0)
    method: Literal["hold", "linear"] = "linear"
    hold_timeout: float | None = Field(None, gt=0)
    frame: Literal["ned_frd", "enu_flu"] = "ned_frd"
    quaternion: list[str] = Field(default_factory=list)
    columns: dict[str, str | ColumnSpec] = Field(default_factory=dict)

    @field_validator("file")
    @classmethod
    def _file(cls, file: str) -> str:
        # said in the cleaning report's lines and in messages, which a line break would split
        return one_line(file)

    @field_validator("time_unit")
    @classmethod
    def _time_unit(cls, unit: str | None) -> str | None:
        if unit is None:
            return unit
        try:
            return checked_time_unit(unit)
        except NnidInputError as err:  # said by pydantic against sources.N.time_unit
            raise ValueError(err.message) from None

    @model_validator(mode="after")
    def _one_clock_declaration(self) -> Source:
        # two scalings of one clock would multiply; a row clock reads no time unit at all
        if self.time_unit is not None and self.time_scale != 1.0:
            raise ValueError(
                f"time_unit = {self.time_unit!r} and time_scale = {self.time_scale:g} both scale "
                'the time column: give one (time_unit = "ms" is time_scale = 0.001)'
            )
        if self.time_unit is not None and self.row_clock is not None:
            raise ValueError(
                "time_unit declares the time column's unit, which row_clock does not read "
                "(t is the row number / row_clock, in seconds): give one"
            )
        return self

    def declares_clock(self) -> bool:
        """Whether the source's clock is in seconds by declaration (``time_unit``, or a
        ``row_clock`` in Hz), so that its steps are not guessed at."""
        return self.time_unit is not None or self.row_clock is not None

    def ticks_per_second(self) -> float:
        """How many units of the time column make a second: the number its stamps were read
        as before their conversion to seconds (1e9 for nanoseconds), whose float64 rounding
        the grid allows for (:func:`nnid.datasets.preprocess.clock_tolerance`)."""
        if self.row_clock is not None:  # row numbers, held exactly, over the rate in Hz
            return 1.0
        if self.time_unit is not None:
            return TIME_UNITS[self.time_unit][1]
        return 1.0 / self.time_scale

    @field_validator("quaternion")
    @classmethod
    def _quat(cls, q: list[str]) -> list[str]:
        if q and len(q) != 4:
            raise ValueError("quaternion names four columns: w, x, y, z")
        # ROS lists orientation.x, .y, .z, .w: that order passes the norm check and reads
        # another attitude without a word
        # the axis a name ends in: orientation.x, quat_x, qx (a dotted name only let the
        # undotted ["qx", "qy", "qz", "qw"] through)
        ends = [m.group(1).lower() if (m := _AXIS_END.search(str(c))) else "" for c in q]
        if sorted(ends) == ["w", "x", "y", "z"] and ends != ["w", "x", "y", "z"]:
            expected = [c for _, c in sorted(zip(ends, q, strict=True))]  # w, x, y, z
            raise ValueError(
                f"quaternion lists {', '.join(q)}: nnid reads w, x, y, z in that order (ROS "
                f"lists x, y, z, w); give {', '.join(expected)}"
            )
        return q

    @field_validator("columns")
    @classmethod
    def _targets(cls, columns: dict[str, str | ColumnSpec]) -> dict[str, str | ColumnSpec]:
        for name, spec in columns.items():
            if name in ("t", "experiment"):
                raise ValueError(f"'{name}' comes from the source's 'time' or the config's "
                                 "'experiment', not from columns")  # fmt: skip
            # a case slip only: "theta_d" or "tau_X2" are columns of the user's own
            typo = [c for c in CONTRACT if c.lower() == name.lower()]
            if name not in CONTRACT and not name.startswith("cmd_") and typo:
                # kept as an extra column, the log's own column would be missing unseen
                raise ValueError(f"'{name}' is no log column; did you mean '{typo[0]}'?")
            unit = spec.unit if isinstance(spec, ColumnSpec) else None
            if unit and name in TARGET_UNITS and unit not in TARGET_UNITS[name]:
                raise ValueError(
                    f"{name} in {unit!r}: {name} takes {', '.join(TARGET_UNITS[name])}"
                )
            if unit and name not in TARGET_UNITS:
                # the units are lengths, angles and their rates: cm on tau_X scaled it by 0.01
                raise ValueError(
                    f"{name} in {unit!r}: {name} takes no unit (a unit converts pose and "
                    "velocity columns; forces in N and N m, accelerations in m/s² and rad/s², "
                    "commands as the vehicle file reads them, other columns as logged); "
                    "convert with scale"
                )
        # two motion columns read from one source column: a copy-paste slip (u and v both
        # "vx" loaded as a vehicle moving diagonally); commands may share a channel
        motion = {}
        for name, spec in columns.items():
            if name in (*POSE, *VELOCITY, *ACCELERATION):
                source = spec.source if isinstance(spec, ColumnSpec) else spec
                if source in motion:
                    raise ValueError(
                        f"{motion[source]} and {name} both read source column '{source}'"
                    )
                motion[source] = name
        return columns

    def targets(self) -> list[str]:
        """The log columns this source gives (the quaternion's three angles among them)."""
        return [*self.columns, *(ANGLES if self.quaternion else ())]

    def specs(self) -> dict[str, ColumnSpec]:
        return {
            name: ColumnSpec.model_validate({"from": spec}) if isinstance(spec, str) else spec
            for name, spec in self.columns.items()
        }


class ColumnMap(StrictModel):
    """A validated reader config."""

    name: str = "log"
    root: str | None = None
    rate: float | None = Field(None, gt=0)
    gap: float | None = Field(None, gt=0)
    experiment: str | list[str] | None = None
    include: str | None = None
    exclude: str | None = None
    drop_nonfinite: bool = False
    vehicle: str | None = None
    # regexes on experiment names, one per group of runs that are copies (replays) of one
    # run: a split keeps each group on one side
    replays: list[str] = Field(default_factory=list)
    sources: list[Source] = Field(min_length=1)

    @field_validator("rate")
    @classmethod
    def _rate(cls, rate: float | None) -> float | None:
        # no faster than a log nnid reads (FASTEST_STEP): a finer grid was refused downstream
        # as a clock in a coarser unit
        if rate is not None and rate > 1.0 / FASTEST_STEP:
            raise ValueError(
                f"{rate:g} Hz is faster than any log nnid reads (at most {1 / FASTEST_STEP:g} "
                "Hz): is rate in Hz?"
            )
        return rate

    @field_validator("name")
    @classmethod
    def _name(cls, name: str) -> str:
        # it heads the cleaning report (cleaning.md's title) and names the reading's source
        return visible_line(name)

    @field_validator("include", "exclude")
    @classmethod
    def _regex(cls, pattern: str | None) -> str | None:
        return None if pattern is None else _pattern(pattern)

    @field_validator("replays")
    @classmethod
    def _regexes(cls, patterns: list[str]) -> list[str]:
        return [_pattern(p) for p in patterns]

    @field_validator("sources")
    @classmethod
    def _one_source_each(cls, sources: list[Source]) -> list[Source]:
        # two sources of one column: the later one won at assembly, without a word
        seen: dict[str, int] = {}
        for i, source in enumerate(sources):
            for name in source.targets():
                if name in seen:
                    which = (
                        f"source {i} gives '{name}' from its columns and its quaternion"
                        if seen[name] == i
                        else f"sources {seen[name]} and {i} both give '{name}'"
                    )
                    raise ValueError(f"{which}: map it from one")
                seen[name] = i
        return sources

    def replay_group(self, experiment: str) -> str | None:
        """The replay group of an experiment (``replays[i]``), or None."""
        for i, pattern in enumerate(self.replays):
            if re.search(pattern, experiment):
                return f"replays[{i}]"
        return None

    @field_validator("experiment")
    @classmethod
    def _experiment(cls, experiment: str | list[str] | None) -> str | list[str] | None:
        if isinstance(experiment, list) and (not experiment or "file" in experiment):
            raise ValueError('a list names one or more columns (not "file")')
        return experiment

    def keeps(self, experiment: str) -> bool:
        if self.include and not re.search(self.include, experiment):
            return False
        return not (self.exclude and re.search(self.exclude, experiment))

    def resolve_root(self, config_path: Path | None, data: str | Path | None = None) -> Path:
        """Where the files live: ``data`` if given, else ``root`` relative to the config."""
        if data is not None:
            return Path(data)
        base = config_path.parent if config_path else Path.cwd()
        return (base / self.root) if self.root else base


def load_column_map(path: str | Path) -> ColumnMap:
    """Read and validate a reader config; NnidInputError names the file and the field."""
    from nnid.validation import read_toml, refuse_other_file, validated

    data = read_toml(path)
    refuse_other_file(data, "columns", "a reader config", str(path))
    return validated(ColumnMap, data, str(path))
