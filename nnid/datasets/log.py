"""The vehicle log contract (ARCHITECTURE.md): one row per sample, SI units, NED/FRD, radians.

Columns: ``t`` (s, strictly increasing within an experiment), optional ``experiment``, pose
``x y z phi theta psi`` and/or body velocities ``u v w p q r``, optional accelerations
``du … dr``, inputs ``tau_X … tau_N`` or ``cmd_<thruster>``. Other columns are kept.
"""

from __future__ import annotations

import math
import os
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import pandas as pd
from pandas.api.types import is_bool_dtype, is_numeric_dtype

from nnid.errors import NnidInputError
from nnid.physics.dofs import DOFS, FORCES
from nnid.validation import one_line, shown

POSE = ("x", "y", "z", "phi", "theta", "psi")
VELOCITY = DOFS  # velocity columns are named after their DOF
ACCELERATION = tuple(f"d{s}" for s in VELOCITY)
TAU = tuple(f"tau_{f}" for f in FORCES)
ANGLES = ("phi", "theta", "psi")
#: the motion columns: a gap in one is masked where a fit or a score reads it (mask_gaps)
MOTION = (*POSE, *VELOCITY, *ACCELERATION)
#: the largest |velocity| a log may hold, m/s or rad/s (a bound on corrupt data, not physics)
MAX_SPEED = 100.0
#: the largest |generalized force| a log may hold, N or N m (ten meganewtons: no thruster's)
MAX_FORCE = 1e7
#: the largest |acceleration| a log may hold, m/s² or rad/s² (a thousand g: corrupt data)
MAX_ACCELERATION = 1e4
#: the largest |position| a log may hold, m (ten times a UTM northing: corrupt data)
MAX_DISTANCE = 1e8
#: the largest |angle| a log may hold, rad (unwrapped: some 1600 turns)
MAX_ANGLE = 1e4
#: the most samples one run of a log may have: a rate or step in the wrong unit, not a run
#: (ten million: 28 hours at 100 Hz), refused before it fills the memory
MAX_RUN_SAMPLES = 10_000_000
#: optional column: the replay group of a run (copies of one run, declared by the reader config)
REPLAY_GROUP = "replay_group"
#: optional column: the run a piece was cut from at a gap (``mask_gaps``, ``resample``, the
#: readers), empty for a whole run; a piece is told by it, never by its experiment's label
PIECE_OF = "piece_of"
#: the units a log's ``t`` may be declared in (``--time-unit``, ``[data] time_unit``, a batch
#: manifest's ``time_unit``, a reader config source's ``time_unit``): name
#: and how many make a second
TIME_UNITS: dict[str, tuple[str, float]] = {
    "s": ("seconds", 1.0),
    "ms": ("milliseconds", 1e3),
    "us": ("microseconds", 1e6),
    "ns": ("nanoseconds", 1e9),
}
#: the ``DataFrame.attrs`` key of a log whose time unit the user declared: the unit guess of
#: :func:`check_time_unit` is skipped for it (the clock alone cannot tell a 1-Hz log in
#: seconds from one in integer milliseconds); it travels with the log's copies and slices
TIME_UNIT_ATTR = "time_unit"
#: the median step, s, from which a log's t reads as milliseconds or coarser (the unit guess of
#: :func:`time_unit_slip`): no vehicle's dynamics are sampled this slowly (five 1-Hz steps)
SLOWEST_STEP = 5.0
#: the median step, s, under which a log's t is refused as a clock in a coarser unit than the
#: one assumed (:func:`fine_clock_slip`): the mirror of :data:`SLOWEST_STEP`, a fifth of the step
#: of the fastest logger the unit guess reads (1 kHz in microseconds): 5 kHz, beyond any
#: vehicle's log (the measured ones under ``shared/data`` log at 270 Hz at most)
FASTEST_STEP = 2e-4
#: the units coarser than seconds a clock too fine for its unit may be in: seconds in each
COARSER_UNITS: dict[str, float] = {"minutes": 60.0, "hours": 3600.0}
#: how a time unit is declared, named where the guess refuses one
DECLARE_TIME_UNIT = (
    "if it is, or to have it converted, declare t's unit with --time-unit, the config's "
    "[data] time_unit or a batch manifest's time_unit (s, ms, us, ns)"
)


def input_columns(df: pd.DataFrame) -> list[str]:
    """The input columns present: generalized forces, or thruster commands."""
    return [c for c in df.columns if c in TAU or str(c).startswith("cmd_")]


def check_log(log: Any, name: str = "log") -> pd.DataFrame:
    """The log a model, the residual loop or the fault monitor is given in Python: a DataFrame
    with rows, each row under its own index label. Each run's rows are found by position
    (:func:`nnid.datasets.preprocess.experiment_rows`), but labels given twice are refused,
    not reset: ``predict`` answers on the log's own index, which a reset would change and a
    repeated label leaves ambiguous, and a split's rows are matched with the whole log's by
    label (a closed-loop replay's open-loop inputs, :func:`check_unique_labels`). (Files are
    read onto fresh row numbers: :func:`nnid.datasets.readers.read_table`.)"""
    if not isinstance(log, pd.DataFrame):
        raise NnidInputError(f"the {name} must be a pandas DataFrame, not {type(log).__name__}")
    if len(log) == 0:
        raise NnidInputError(f"the {name} has no rows")
    check_unique_labels(
        log.index, f"the {name}'s index", "rows are answered on, and matched, by their labels"
    )
    return log


def check_unique_labels(index: pd.Index, what: str, why: str) -> None:
    """Raise where ``index`` (``what``, as "the log's index") repeats a label, naming the
    first and ``why`` a label must name one row."""
    if index.is_unique:
        return
    repeated = index[index.duplicated()].unique()
    raise NnidInputError(
        f"{what} repeats {len(repeated)} label{'s' * (len(repeated) != 1)} "
        f"(the first: {shown(repeated[0])}): {why}, so the runs would be mixed up; this "
        "usually comes from pd.concat without ignore_index=True: give the log a fresh index "
        "with log.reset_index(drop=True)"
    )


def validate_log(
    df: pd.DataFrame, source: str = "<log>", require_inputs: bool = True
) -> pd.DataFrame:
    """Check a log against the contract and return it unchanged.

    Raises :class:`NnidInputError` naming the file, the column and the row of the first problem.
    Nothing is dropped or repaired here.
    """
    _check_spelling(df, source)
    if "t" not in df.columns:
        # a Parquet file written from a frame indexed by time keeps t as its index
        where = " (it is the file's index: write it as a column)" if df.index.name == "t" else ""
        raise NnidInputError(
            f"required column 't' (time in seconds) is missing{where}", source=source
        )
    if len(df) == 0:
        raise NnidInputError("the log has no rows", source=source)
    motion = [c for c in (*POSE, *VELOCITY) if c in df.columns]
    if not motion:
        raise NnidInputError(
            "no motion columns: expected pose (x y z phi theta psi) and/or body velocities "
            "(u v w p q r)",
            source=source,
        )
    inputs = input_columns(df)
    if require_inputs and not inputs:
        raise NnidInputError(
            "no input columns: expected generalized forces tau_X..tau_N or thruster commands "
            "cmd_<name>",
            source=source,
        )
    accelerations = [c for c in ACCELERATION if c in df.columns]
    _check_finite(df, ["t", *inputs], source)
    # an empty motion cell is a gap (a DVL dropout), bridged or masked downstream
    # (nnid.datasets.gaps); anything else that is not a finite number is refused
    _check_finite(df, [*motion, *accelerations], source, gaps=True)
    _check_experiments(df, source)
    _check_time(df, source)
    check_time_unit(df, source)
    if inputs and all(np.all(pd.to_numeric(df[c], errors="coerce") == 0) for c in inputs):
        warnings.warn(
            f"{source}: every input column ({', '.join(inputs)}) is zero throughout: only free "
            "motion (decay, restoring) can be identified from this log",
            stacklevel=2,
        )
    for col, (bound, _, _) in SI_BOUNDS.items():
        if col in df.columns:
            size = np.abs(df[col].to_numpy(dtype=np.float64))
            if np.nanmax(size) > bound:
                row = int(np.nanargmax(size))
                raise out_of_bounds(col, df[col].iloc[row], source, row)
    for col in ANGLES:
        if col in df.columns and looks_like_degrees(df, col):
            size = np.abs(df[col].to_numpy(dtype=np.float64))
            raise degrees_error(df, col, source, int(np.nanargmax(size)))
    check_rate_units(df, source)
    check_depth_units(df, source)
    _check_velocity_frame(df, source)
    return df


# a unit slip (mm/s) or a corrupt sample, caught at reading rather than as an absurd estimate or
# an overflow far downstream; real vehicles stay far below these bounds
#: column -> (the largest |value| a log may hold, what it is, its SI unit)
SI_BOUNDS: dict[str, tuple[float, str, str]] = {
    **{c: (MAX_SPEED, "a speed", "m/s" if c in "uvw" else "rad/s") for c in VELOCITY},
    **{c: (MAX_FORCE, "a force", "N" if c in TAU[:3] else "N m") for c in TAU},
    **{
        c: (MAX_ACCELERATION, "an acceleration", "m/s²" if c in ACCELERATION[:3] else "rad/s²")
        for c in ACCELERATION
    },
    **{c: (MAX_DISTANCE, "a position", "m") for c in POSE[:3]},
    **{c: (MAX_ANGLE, "an angle", "rad") for c in ANGLES},
}


def out_of_bounds(col: str, value, source: str, row: int) -> NnidInputError:
    """The error of a value past its column's :data:`SI_BOUNDS`."""
    bound, what, unit = SI_BOUNDS[col]
    return NnidInputError(
        f"{shown(value)} {unit} is not {what} an underwater vehicle meets (over {bound:g}); the "
        "log must be in SI units",
        source=source,
        field=col,
        row=row,
    )


def degrees_error(df: pd.DataFrame, col: str, source: str, row: int) -> NnidInputError:
    """The error of an angle column that :func:`looks_like_degrees`."""
    size = np.abs(df[col].to_numpy(dtype=np.float64))
    return NnidInputError(
        f"angle of {np.nanmax(size):.4g} looks like degrees; angles must be in radians"
        + (UNWRAPPED if RATE_OF[col] not in df else PITCH_RANGE if col == "theta" else ""),
        source=source,
        field=col,
        row=row,
    )


#: the body rate each Euler angle turns with when roll and pitch are small
RATE_OF = {"phi": "p", "theta": "q", "psi": "r"}
UNWRAPPED = (
    " (unwrapped radians past ±2π are read where the log also has the angle's rate, p, q or r, "
    "to tell them from degrees)"
)
PITCH_RANGE = " (the zyx Euler pitch theta stays within ±π/2)"


def turned_by(t: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """The angle a body rate turns through from the first sample on (trapezoids); a gap in
    the rate (a dropout) adds no turning instead of making every later value NaN."""
    steps = np.nan_to_num(0.5 * (rate[1:] + rate[:-1]) * np.diff(t))
    return np.concatenate([[0.0], np.cumsum(steps)])


def radian_limit(col: str, rate_logged: bool) -> float:
    """The largest |angle| of ``col`` read as radians without asking whether it is degrees:
    2π (roll and yaw wrap at ±π or [0, 2π)), and ±π/2 for the zyx pitch where its rate q is
    logged to vouch for radians past it (a pitch of 4° logged in degrees passed as 4 rad).
    Without q the pitch's limit is 2π too: nnid's simulator, which integrates the Euler
    angles, flies a pose-only log's pitch through ±π (Seamor's surge-heave run loops), and
    nothing tells that from degrees."""
    return math.pi / 2 if col == "theta" and rate_logged else 2 * math.pi


def looks_like_degrees(df: pd.DataFrame, col: str) -> bool:
    """Whether angle column ``col`` of ``df`` (``t``, optional ``experiment``) holds degrees:
    values past :func:`radian_limit` (±2π; ±π/2 for a pitch whose rate q is logged), unless
    the log's body rate of that angle (:data:`RATE_OF`) says they are unwrapped radians (a yaw
    past 2π after a full turn, as a filter or nnid's simulator writes it): over windows of
    about a second where the rate turned the vehicle by more than 0.05 rad, the angle changed
    as much, not 57 times as much, and the rate itself reads as rad/s (under π rad/s, not a
    log whose rates are in deg/s too)."""
    angle = df[col].to_numpy(dtype=np.float64)
    rate = RATE_OF[col]
    if not angle.size or not np.nanmax(np.abs(angle)) > radian_limit(col, rate in df) + 1e-6:
        return False
    if rate not in df:
        return True
    t = df["t"].to_numpy(dtype=np.float64)
    r = df[rate].to_numpy(dtype=np.float64)
    label = df["experiment"].to_numpy() if "experiment" in df else np.zeros(len(df))
    # windows of about a second: a held or quantised heading moves between its samples
    step = np.nanmedian(np.diff(t)) if t.size > 1 else np.nan
    lag = max(1, round(1.0 / step)) if np.isfinite(step) and step > 0 else 1
    if t.size <= lag:
        return True
    turned = turned_by(t, r)
    d_angle = np.abs(angle[lag:] - angle[:-lag])
    d_turn = np.abs(turned[lag:] - turned[:-lag])
    use = (label[lag:] == label[:-lag]) & np.isfinite(d_angle) & (d_turn > 0.05)
    if use.sum() < 5:  # too little turning to tell: the plain reading
        return True
    # the median ignores the few windows across a wrap (2π or 360)
    if np.median(d_angle[use] / d_turn[use]) > 5.0:
        return True
    return bool(np.nanpercentile(np.abs(r), 99) > math.pi)


#: what a caller takes for the step of a run too short to have one (:func:`typical_step`)
OneSample = TypeVar("OneSample", float, None)


def typical_step(t: np.ndarray, one_sample: OneSample) -> float | OneSample:
    """A run's typical sampling step, s (``t``: its times): the median of its steps, or
    ``one_sample`` for a run of one sample, which has none (each caller says what stands for
    it: NaN where nothing may). Stamps that come in bursts have a median step inside a burst
    (an IMU's ten samples every 10 ms step by 10 µs, not 1 ms): what steps by this refuses
    them first (:func:`nnid.datasets.preprocess.refuse_bursty_runs`: the pipeline, every
    model's ``fit``, ``predict``, ``residual`` and ``force_series``, the residual loop's
    ``fit``, the fault monitor before any residual; the derivatives and the low-pass filter
    refuse them too). A clock rounded coarsely (:func:`rounded_clock`: 120 Hz stamped in
    milliseconds steps 8, 8, 9 ms) steps by the mean of its one-sample steps instead: its
    median, 8 ms, made every derivative 4 % too large."""
    t = np.asarray(t)
    return clock_step(t)[0] if t.size > 1 else one_sample


def clock_step(t: np.ndarray, within: np.ndarray | None = None) -> tuple[float, float]:
    """A run's typical step (``t``: its times; ``within``: which of its steps are sample
    steps, where a run resumes after another's rows) and its clock's rounding, s: a coarsely
    rounded clock's (:func:`rounded_clock`), else the median step and 0. (NaN, 0) where no
    step is a sample step (a run of one sample, runs of one sample each): there is none to
    read, as :func:`typical_step`'s ``one_sample``."""
    rounded = rounded_clock(t, within)
    if rounded is not None:
        return rounded
    steps = np.diff(t)
    inside = steps if within is None else steps[within]
    return (float(np.median(inside)) if inside.size else math.nan), 0.0


def log_step(t: np.ndarray, experiment: np.ndarray | None = None) -> float:
    """The typical step of a log's runs together (``t``: its times in log order;
    ``experiment``: each row's run, None for a log of one run): :func:`clock_step` over the
    steps within a run, the step across a join left out (t restarting at 0 is a negative
    step, and a coarsely rounded clock read with it fell back to the median, 8 ms for 120 Hz
    stamped in ms, where each run alone reads 8.33 ms). NaN where no run has two samples."""
    t = np.asarray(t, dtype=np.float64)
    if experiment is None:
        return clock_step(t)[0]
    runs = np.asarray(experiment)
    return clock_step(t, runs[1:] == runs[:-1])[0]


def frame_step(log: pd.DataFrame) -> float:
    """:func:`log_step` of a log's own ``t`` and ``experiment`` columns (a log without the
    latter is one run): the typical step of its runs, the joins between them left out."""
    # codes, not labels: numpy's == on object labels is a Python call a row
    runs = pd.factorize(log["experiment"])[0] if "experiment" in log else None
    return log_step(log["t"].to_numpy(np.float64), runs)


#: how many times a step's float error the resolution of a clock must be to be read as its
#: rounding (:func:`rounded_clock`): finer, the stamps' float error blurs which multiple of it
#: a step is (an epoch clock, ~1.7e9 s, is read to a millisecond)
ROUNDING_OVER_FLOAT = 1e3


#: the least share of a rounded clock's one-sample steps that each of its two step values
#: holds (:func:`rounded_clock`): a rate between multiples n and n + 1 of the rounding q
#: steps n q a share 1 - f of the time and (n + 1) q the rest, f, and its median n q is f q
#: short of the step. Below this share the median is under 5 % of q off (0.5 µs of 1-ms
#: stamps, 0.05 % of a 10-ms step), while a glitch or two among thousands of steps of an
#: exact float grid (one 11-ms step among 10-ms ones) is no rounding to read
ROUNDED_SHARE = 0.05


def rounded_clock(t: np.ndarray, within: np.ndarray | None = None) -> tuple[float, float] | None:
    """(step, resolution q), s, of a run (``t``: its times) whose clock is rounded coarsely:
    q a decimal resolution (1 ms, 0.1 ms: 10^-k s), every step a whole number of q (to the
    stamps' float error), q at most half the median step, and its one-sample steps (those
    within q of the median) two neighbouring multiples of q, each a real share of them
    (:data:`ROUNDED_SHARE`), that keep the stamps within a few q of one line (a rate between
    multiples of q, rounded: 120 Hz in milliseconds steps 8, 8, 9 ms; a rate that changes
    from 8 to 9 ms drifts off the line). The step is the rate over the run: the slope of the
    stamps against their count of samples (a dropped sample's step counts two), each piece
    between joins with an offset of its own. None for any other clock (float stamps, jitter,
    a rate a whole number of q, a clock alternating 0.04 and 0.06 s), whose step stays the
    median (:func:`typical_step`). ``within``: which steps are sample steps (else all), for a
    run whose rows resume after another's: the others, its joins, are read for nothing, and
    each piece between them keeps to a line of its own."""
    t = np.asarray(t, dtype=np.float64)
    steps = np.diff(t)
    inside = steps if within is None else steps[within]
    if inside.size < 2:
        return None
    median = float(np.median(inside))
    if not median > 0:
        return None
    # a step holds both its stamps' float rounding and their reading (a count of ms divided)
    err = 4.0 * float(np.spacing(np.max(np.abs(t))))
    near = inside[np.abs(inside - median) < 0.5 * median]
    if not near.size:  # steps split between two rates far apart (0.01, 0.1 s): no one step
        return None
    above = near - near.min()
    above = above[above > err]
    if not above.size:  # one step throughout: the median is it
        return None
    # a clock's resolution is a decimal unit of the second: a clock alternating 0.04 and
    # 0.06 s steps by multiples of 0.02 s, an uneven clock, not a rounded one. q is read
    # to 2 err (a difference of two steps)
    decimal = 10.0 ** round(math.log10(above.min()))
    if abs(above.min() - decimal) > 2.0 * err:
        return None
    q = decimal
    # one unit of q apart may be a dropped sample (1 and 2 ms), not rounding
    if q < ROUNDING_OVER_FLOAT * err or q > median / 2:
        return None
    units = np.round(inside / q)
    if np.any(np.abs(inside - units * q) > (1.0 + 2.0 * units) * err):
        return None
    one = np.abs(units - np.round(median / q)) <= 1
    values, counts = np.unique(units[one], return_counts=True)
    # three values are jitter, not rounding; a value too rare is a glitch (ROUNDED_SHARE)
    if values.size != 2 or counts.min() < ROUNDED_SHARE * counts.sum():
        return None
    # the mean of the one-sample steps is off by their rounding at each dropped sample, a few
    # dozen of which drift it off the line: it only counts each step's samples, and the step
    # is the least-squares slope of the stamps against that count, a line for each piece
    count = np.round(steps / float(inside[one].mean()))
    if within is not None:
        count[~within] = 0.0  # a join counts no sample: its piece has an offset of its own
    k = np.concatenate([[0.0], np.cumsum(count)])
    piece = np.zeros(t.size, np.int64) if within is None else np.r_[0, np.cumsum(~within)]
    size = np.bincount(piece)
    rel = t - t[0]
    k_c = k - (np.bincount(piece, k) / size)[piece]
    t_c = rel - (np.bincount(piece, rel) / size)[piece]
    spread_k = float(k_c @ k_c)
    if not spread_k > 0:
        return None
    step = float(k_c @ t_c) / spread_k
    # rounded stamps stay within q/2 of the line of the true step; a rate change drifts off
    # it. A join's count shifts every later stamp alike, so each piece is measured against
    # its own line
    off_line = rel - k * step
    starts = np.flatnonzero(np.r_[True, piece[1:] != piece[:-1]])
    spread = np.maximum.reduceat(off_line, starts) - np.minimum.reduceat(off_line, starts)
    if np.max(spread) > 3.0 * q:
        return None
    return step, q


def run_label(name: object) -> str:
    """An experiment in a message: ``experiment 'x'``, or ``the log`` for a log without an
    experiment column (its one run is named None, which read as "experiment None")."""
    return "the log" if name is None else f"experiment {str(name)!r}"


def run_of(log: pd.DataFrame) -> dict:
    """Each experiment of ``log`` (in log order) -> the run it belongs to: its ``piece_of``
    where a gap cut a run into pieces (:mod:`nnid.datasets.gaps`), else itself; empty for a
    log without experiments."""
    if "experiment" not in log:
        return {}
    first = log.drop_duplicates("experiment")
    if PIECE_OF not in log:
        return {e: e for e in first["experiment"]}
    return {
        e: r if pd.notna(r) else e
        for e, r in zip(first["experiment"], first[PIECE_OF].to_numpy(object), strict=True)
    }


def run_pieces(log: pd.DataFrame, names: Sequence[object]) -> list:
    """``names`` of experiments as a user gives them, each name of a run that a gap cut into
    pieces (:func:`run_of`) standing for all its pieces in log order: the run is what the
    user logged and names (a split, ``--exclude``, held-out runs); any other name is kept as
    it is, for the caller to judge."""
    runs = run_of(log)
    out = []
    for n in names:
        pieces = [e for e, r in runs.items() if r == n] if n not in runs else []
        out += pieces or [n]
    return out


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Wrap to [−π, π)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def euler_rate_matrices(angles: np.ndarray, inverse: bool = False) -> np.ndarray:
    """T_Θ (Weiss eq. 17; McCarter eq. 2.7), or T_Θ⁻¹ with ``inverse`` (McCarter eq. 2.14), of
    angles ``[..., 3]`` = (φ, θ, ψ) as ``[..., 3, 3]``: :mod:`nnid.physics.kinematics`'
    euler_rate_matrix and its inverse in numpy, because reading, cleaning and deriving a log
    do not load torch (tests/test_kinematics.py checks that they agree)."""
    angles = np.asarray(angles, dtype=np.float64)
    phi, theta = angles[..., 0], angles[..., 1]
    cphi, sphi, cth = np.cos(phi), np.sin(phi), np.cos(theta)
    one, zero = np.ones_like(phi), np.zeros_like(phi)
    if inverse:
        sth = np.sin(theta)
        rows = [[one, zero, -sth], [zero, cphi, cth * sphi], [zero, -sphi, cth * cphi]]
    else:
        tth = np.tan(theta)
        rows = [[one, sphi * tth, cphi * tth], [zero, cphi, -sphi], [zero, sphi / cth, cphi / cth]]
    return np.stack([np.stack(row, -1) for row in rows], -2)


#: a body rate logged in deg/s reads 180/π ≈ 57.3 times the attitude's kinematic rate
#: (:func:`rate_slopes`); a slope in this range on an axis that turns is refused as that slip.
#: Wide below: an attitude that lags or disagrees with its gyro pulls the slope down (the
#: Haizhe excerpt's gyro without its deg/s unit reads 47; 20 is met by a gyro in deg/s beside
#: an attitude whose own slope is 0.35 or more), while the measured logs under shared/data
#: read -0.5 to 1.3 (a diverged EKF attitude: 0.05-0.9; up to 2.1 over under 2 s of turning)
DEG_PER_S_SLOPE = (20.0, 100.0)
#: the attitude must turn an axis by more than this (rad) over a window of about a second for
#: the window to count: a held or noisy attitude says nothing of the rate's unit
RATE_CHECK_TURN = 0.05
#: and the turning windows of an experiment must cover this many seconds for its slope to count
RATE_CHECK_SECONDS = 2.0
#: steps where |cos θ| is under this are left out: near θ = ±π/2 (zyx gimbal lock) φ and ψ
#: jump by up to π between samples, and T_Θ⁻¹ at a step's midpoint is not the step's (nnid's
#: simulator flies Seamor's pitch through ±π)
RATE_CHECK_MIN_COS = 0.2


def rate_slopes(df: pd.DataFrame) -> list[tuple[object, str, float, float]]:
    """Per experiment and logged body rate p, q, r of a log with the whole attitude φ, θ, ψ:
    the least-squares slope of the rate on the attitude's kinematic rate ν₂ = T_Θ⁻¹ Θ̇
    (McCarter eq. 2.14, the inverse of Weiss eq. 17), over windows of about a second where the
    attitude turns that axis by more than :data:`RATE_CHECK_TURN`. Both sides are integrated
    over the window (the rate by trapezoids; Θ̇ as the wrapped difference of consecutive
    angles, each step through T_Θ⁻¹ at its midpoint) so that the attitude's noise does not
    swamp its differences; the rate is regressed on the attitude, so that noise pulls the slope
    down, away from a false 57. A column logged slower than the others (an attitude at 2 Hz
    beside a 10-Hz gyro: an empty cell between its samples) is read across the spans between
    its samples (:func:`_sampled_spans`); a step across a gap (a hole in t, a dropout longer
    than two windows) or near gimbal lock is left out of both sums, and no window spans two
    experiments. Returns (experiment, rate column, slope, seconds of turning windows) for
    each pair with any: about 1 for a consistent log, 57.3 for rates in deg/s beside
    radians."""
    rates = [c for c in ("p", "q", "r") if c in df]
    # T_Θ⁻¹ needs the whole attitude: a missing roll or pitch taken as level would compare a
    # tilted vehicle's r (all θ̇ when rolled 90°) with ψ̇ alone
    if not rates or not all(a in df for a in ANGLES) or len(df) < 3:
        return []
    codes, names, order, t, dt, step = _experiment_sorted(df)
    logged = df[list(ANGLES)].to_numpy(dtype=np.float64)[order]
    angles = np.stack([_filled(a, t, codes, angle=True) for a in logged.T], 1)
    # wrapped differences: the unwrapped angle's steps, and a gap stays out (NaN)
    d_angle = wrap_angle(np.diff(angles, axis=0))
    mid = angles[:-1] + 0.5 * d_angle
    cth = np.cos(mid[:, 1])
    # T_Θ⁻¹ ΔΘ, the body's turning in each step
    body = np.einsum("nij,nj->ni", euler_rate_matrices(mid, inverse=True), d_angle)
    turn = dict(zip(("p", "q", "r"), body.T, strict=True))
    # a step over a hole in t (longer than thrice its experiment's step) is no rate
    good = (dt < 3 * step[codes[1:]]) & (np.abs(cth) > RATE_CHECK_MIN_COS)
    attitude = np.isfinite(logged).all(1)
    out = []
    for col in rates:
        logged_rate = df[col].to_numpy(dtype=np.float64)[order]
        rate = _filled(logged_rate, t, codes)
        gyro = 0.5 * (rate[1:] + rate[:-1]) * dt
        ok = good & np.isfinite(gyro) & np.isfinite(turn[col])
        # a span left out is left out of both sums, so an empty cell every few samples leaves
        # the windows around it
        first, stop, starts, ends, _ = _sampled_spans(
            codes, t, attitude & np.isfinite(logged_rate), ok, step, 1.0
        )
        g = _window_sums(_span_sums(gyro, first, stop), starts, ends)
        a = _window_sums(_span_sums(turn[col], first, stop), starts, ends)
        use = np.abs(a) > RATE_CHECK_TURN
        k = codes[starts][use]
        n = np.bincount(k, minlength=len(names))
        ga = np.bincount(k, g[use] * a[use], minlength=len(names))
        aa = np.bincount(k, a[use] ** 2, minlength=len(names))
        for e in np.flatnonzero(n):
            out.append((names[e], col, float(ga[e] / aa[e]), float(n[e] * step[e])))
    return out


def _experiment_sorted(
    df: pd.DataFrame,
) -> tuple[np.ndarray, list, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The rows of ``df`` grouped by experiment for the per-experiment window checks
    (:func:`rate_slopes`, :func:`depth_slopes`, :func:`velocity_frame_ratios`): the sorted
    experiment codes, their names (``[None]`` without an experiment column), the row order,
    the times and time steps in that order, and each experiment's own sample step (a log may
    join a 10-Hz run and a 100-Hz one: each sizes its own windows; :func:`_experiment_steps`)."""
    if "experiment" in df:
        codes, labels = pd.factorize(df["experiment"])
        names = labels.tolist()  # indexing pandas' arrow strings one at a time is slow
    else:
        codes, names = np.zeros(len(df), dtype=np.int64), [None]
    order = np.argsort(codes, kind="stable")  # an experiment's rows, in order, side by side
    codes = codes[order]
    t = df["t"].to_numpy(dtype=np.float64)[order]
    dt = np.diff(t)
    return codes, names, order, t, dt, _experiment_steps(codes, order, t, len(names))


def _experiment_steps(codes: np.ndarray, order: np.ndarray, t: np.ndarray, n: int) -> np.ndarray:
    """The typical step (:func:`clock_step`) of each of ``n`` experiments (``codes`` of the
    rows, sorted; ``order`` their positions in the log; ``t`` their times), over the steps
    within it: its own rate, as a log may join runs of loggers at different rates. The
    median's 8 ms of 120 Hz stamped in whole ms sized a second's window 125 steps and said its
    120 steps were 0.96 s. Where an experiment's rows resume after another's (a reader's
    resumed run, an interleaved log), the step across is no sample step: only steps between
    rows side by side in the log are read, each piece on a line of its own. An experiment
    whose rows mostly alternate with another's (two loggers written row by row, or merged by
    time) is read over all its steps in time order: its few rows side by side (where the
    other dropped a row) are no sample of its step. NaN for an experiment of one row."""
    same = codes[1:] == codes[:-1]
    within = same & (np.diff(order) == 1)
    # side by side for fewer than half its steps: interleaved, not resumed. "None side by
    # side" flipped to reading one step where the other logger dropped one row
    beside = np.bincount(codes[1:][within], minlength=n)
    interleaved = 2 * beside < np.bincount(codes[1:][same], minlength=n)
    within |= same & interleaved[codes[1:]]
    bounds = np.searchsorted(codes, np.arange(n + 1))
    median, ruled = _plain_steps(codes, t, within, bounds)
    step = median.copy()  # pandas' array, read-only
    # the rounded-clock rule, one experiment at a time, only where the screen cannot say it
    # reads the median (a clock rounded coarsely, or stamps the screen does not judge)
    for e in np.flatnonzero(ruled):
        a, b = bounds[e], bounds[e + 1]
        step[e] = clock_step(t[a:b], within[a : b - 1])[0]
    return step


def _plain_steps(
    codes: np.ndarray, t: np.ndarray, within: np.ndarray, bounds: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each experiment's median step (of the steps ``within`` it; NaN where none), as
    :func:`clock_step` computes it, and which experiments may be rounded clocks (``True``:
    ask :func:`clock_step`). :func:`rounded_clock`'s refusals before it looks for a
    resolution are read here, for all experiments at once (fewer than two steps, no step
    near a positive median, the steps near it one step to the stamps' float error: a grid, a
    resampled log), and such an experiment keeps its median; non-finite stamps are asked. A
    log a reader cut into 10^4 pieces took half a second a call asking the rule one
    experiment at a time."""
    n = bounds.size - 1
    x = np.diff(t)[within]
    k = codes[1:][within]
    median = _experiment_medians(codes, np.diff(t), n, within)
    with np.errstate(invalid="ignore"):
        near = np.abs(x - median[k]) < 0.5 * median[k]
    low, high = np.full(n, np.inf), np.full(n, -np.inf)
    np.minimum.at(low, k[near], x[near])
    np.maximum.at(high, k[near], x[near])
    # rounded_clock's err: the stamps' float error at the run's largest |t|
    err = 4.0 * np.spacing(np.maximum.reduceat(np.abs(t), bounds[:-1])) if t.size else np.zeros(n)
    finite = np.bincount(codes[~np.isfinite(t)], minlength=n) == 0
    one_step = high - low <= err  # no step above the least by more than err: "one step"
    plain = finite & ((np.bincount(k, minlength=n) < 2) | one_step)
    return median, ~plain


def _experiment_medians(
    codes: np.ndarray, dt: np.ndarray, n: int, within: np.ndarray | None = None
) -> np.ndarray:
    """The median of each of ``n`` experiments' steps ``dt`` (``codes`` of the rows, sorted),
    over the steps within it (``within``: those read, else every step between two rows of
    it); NaN for an experiment of one row."""
    inside = codes[1:] == codes[:-1] if within is None else within
    medians = pd.Series(dt[inside]).groupby(codes[1:][inside]).median()
    return medians.reindex(range(n)).to_numpy(dtype=np.float64)


def _experiment_windows(
    codes: np.ndarray, step: np.ndarray, seconds: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Windows of steps within one experiment, each of about ``seconds`` at its experiment's
    ``step`` (:func:`_experiment_steps`; at least one step): the first step of every
    window that ends before its experiment does, the step after its last (for
    :func:`_window_sums`), and each experiment's window length in steps. An experiment without
    a positive step has no window."""
    steps = codes.size - 1
    with np.errstate(invalid="ignore", divide="ignore"):
        lags = np.rint(seconds / step)
    # a lag past the log's end (a step near 0) or none (a step of 0 or NaN) fits no window
    lags = np.where(step > 0, np.clip(np.nan_to_num(lags, nan=0.0), 1, steps + 1), steps + 1)
    lags = lags.astype(np.int64)
    starts = np.arange(steps)
    ends = starts + lags[codes[:-1]]
    fits = ends <= steps
    fits[fits] = codes[ends[fits]] == codes[:-1][fits]
    return starts[fits], ends[fits], lags


def _window_sums(x: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Sums of ``x`` over the elements ``starts[i]`` up to (not including) ``ends[i]``."""
    total = np.concatenate([[0.0], np.cumsum(x)])
    return total[ends] - total[starts]


def _filled(
    x: np.ndarray,
    t: np.ndarray,
    codes: np.ndarray,
    angle: bool = False,
    max_rows: int | np.ndarray | None = None,
) -> np.ndarray:
    """``x`` (rows sorted by experiment, :func:`_experiment_sorted`) with each run of empty
    cells between two samples of one experiment linearly interpolated in ``t`` (an ``angle``
    along the shorter turn), before its first sample and after its last left empty, and with
    ``max_rows`` (one number, or one per row: the row before the run) so is a run whose
    samples are more than that many rows apart (a hole, not a slower channel's step). A
    channel logged slower than the others on a common clock (a depth sensor at 1 Hz beside a
    10-Hz DVL) has an empty cell in every step: the window
    checks read it between its own samples, and :func:`_sampled_spans` keeps only spans that
    end on samples; :func:`nnid.datasets.gaps.fill_slow` fills a slow attitude with it.
    ``x`` itself without empty cells (a fully sampled log's numbers stay as they were)."""
    bad = ~np.isfinite(x)
    if not bad.any():
        return x
    rows = np.arange(x.size)
    prev = np.maximum.accumulate(np.where(bad, -1, rows))
    nxt = np.minimum.accumulate(np.where(bad, x.size, rows)[::-1])[::-1]
    fill = bad & (prev >= 0) & (nxt < x.size)
    fill[fill] = codes[prev[fill]] == codes[nxt[fill]]
    if max_rows is not None:  # one for all rows, or each row's own (a run's own stride)
        limit = np.broadcast_to(max_rows, x.shape)
        fill[fill] = nxt[fill] - prev[fill] <= limit[prev[fill]]
    a, b = prev[fill], nxt[fill]
    change = x[b] - x[a]
    out = x.copy()
    with np.errstate(invalid="ignore", divide="ignore"):  # a repeated stamp: no value, no span
        share = (t[fill] - t[a]) / (t[b] - t[a])
    out[fill] = x[a] + share * (wrap_angle(change) if angle else change)
    return out


def _sampled_spans(
    codes: np.ndarray,
    t: np.ndarray,
    sampled: np.ndarray,
    ok: np.ndarray,
    step: np.ndarray,
    seconds: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The spans a window check sums over (rows sorted by experiment): from one ``sampled`` row
    (every column the check reads has a value) to the next of its experiment, each span's
    steps all ``ok``, and no longer than two windows. A fully sampled log's spans are its steps;
    with a column logged slower than the clock, each runs from one of its samples to the next,
    so that the other side's steps are summed across the same span (the evidence that one
    empty cell in every step removed entirely). Windows (:func:`_experiment_windows`) are
    about ``seconds`` long, or the experiment's median span if longer, so that a window holds
    a span. Returns each span's first step and the step after its last, and the windows'
    starts, ends and lags."""
    rows = np.flatnonzero(sampled)
    # an experiment's median span: its step when fully sampled (the windows unchanged); a
    # slow channel's own spacing, rows of the clock with its samples a row early or late, only
    # floors a window's length, so its median stays
    span = step
    if rows.size < t.size:
        span = _experiment_medians(codes[rows], np.diff(t[rows]), step.size)
    starts, ends, lags = _experiment_windows(codes, step, np.fmax(seconds, span))
    first, stop = rows[:-1], rows[1:]
    left_out = np.concatenate([[0], np.cumsum(~ok)])
    # a span over a hole in t or an empty cell that could not be read across is no evidence,
    # and one longer than two windows is a dropout, not a slower channel (whose samples land
    # a row early or late on a merged clock): left out of both sums.
    # A span into the next experiment would end in its windows; the one step from an
    # experiment's last row to the next's first lies in no window, and stays in the running
    # sums of _window_sums so that their rounding is the fully sampled log's as before
    keep = (
        ((codes[first] == codes[stop]) | (stop - first == 1))
        & (stop - first <= 2 * lags[codes[first]])
        & (left_out[stop] == left_out[first])
    )
    return first[keep], stop[keep], starts, ends, lags


def _span_sums(x: np.ndarray, first: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """The steps ``x`` summed over each span of :func:`_sampled_spans`, at the span's last step
    and zero elsewhere, for :func:`_window_sums`: a window holds the spans that end in it, on
    both sides of a check alike. A one-step span is its step's value exactly."""
    out = np.zeros(x.size)
    one = stop - first == 1  # a step: its own value (every span of a fully sampled log)
    out[first[one]] = x[first[one]]
    if not one.all():
        edges = np.column_stack([first[~one], stop[~one]]).ravel()
        out[stop[~one] - 1] = np.add.reduceat(np.append(x, 0.0), edges)[::2]
    return out


def check_rate_units(df: pd.DataFrame, source: str, row: int | None = None) -> None:
    """Body rates p, q, r in rad/s beside an attitude in radians: a rate that reads about
    57.3 times the rate the attitude turns at (:func:`rate_slopes`, :data:`DEG_PER_S_SLOPE`)
    in any experiment is refused as deg/s. Per experiment, not pooled: a log joined from runs
    of two loggers may have the slip in some runs only, and pooling would dilute it into
    neither 1 nor 57. ``row`` names the row a stream was judged at (``detect --follow``)."""
    for name, col, slope, seconds in rate_slopes(df):
        if seconds >= RATE_CHECK_SECONDS and DEG_PER_S_SLOPE[0] <= slope <= DEG_PER_S_SLOPE[1]:
            run = "" if name is None else f" in experiment {str(name)!r}"
            raise NnidInputError(
                f"{col} reads {slope:.3g} times the body rate the attitude (phi, theta, psi) "
                f"turns at{run} ({seconds:.3g} s of turning): it looks like deg/s; body rates "
                f'must be rad/s: divide by 57.2958 (or set the unit: unit = "deg/s" for {col} '
                "in the reader config)",
                source=source,
                field=col,
                row=row,
            )


#: the depth change u, v, w imply (ż = J₁(Θ)₃ ν₁) over the depth change z logs, as a slope
#: (:func:`depth_slopes`): velocities in cm/s or mm/s beside a depth in metres read 100 or
#: 1000, a depth in cm or mm beside velocities in m/s 0.01 or 0.001. Logs read 0.94-1.03 (the
#: demo's runs, the octorov's simulated DVL, the romeo and vt690 simulate configs, the Tartan
#: session's 957 s)
DEPTH_UNIT_SLOPE = (20.0, 2000.0)
#: slopes that say z or w has its sign turned: a height or altitude (positive up) logged as z,
#: or a w positive up; a consistent log reads about +1
DEPTH_SIGN_SLOPE = (-2.0, -0.5)
#: windows of about this many seconds, where z changes by more than :data:`DEPTH_CHECK_CHANGE`
#: (in the log's own unit): a depth sensor's noise says nothing of the unit
DEPTH_CHECK_WINDOW = 2.0
DEPTH_CHECK_CHANGE = 0.05
#: the windows' depth change must explain this share of the implied one (the regression's R²):
#: a depth sensor's noise on a run that barely heaves pulls the slope toward 0, not a unit slip
DEPTH_CHECK_FIT = 0.5
#: the columns the depth-unit check reads (ψ plays no part in ż)
DEPTH_UNIT_COLUMNS = ("z", "phi", "theta", "u", "v", "w")


def depth_slopes(df: pd.DataFrame) -> list[tuple[object, float, float, float]]:
    """Per experiment of a log with z, φ, θ and body velocities u, v, w: the least-squares
    slope of the depth change the velocities imply, ż = −sin θ u + cos θ sin φ v + cos θ cos φ w
    (the third row of J₁, Weiss eq. 16), on the depth change z logs, over windows of about
    :data:`DEPTH_CHECK_WINDOW` where z changes by more than :data:`DEPTH_CHECK_CHANGE`, both
    sides summed over the window as :func:`rate_slopes` does. Returns (experiment, slope, R²,
    seconds of windows): about 1 for a consistent log, 100 for velocities in cm/s beside a
    depth in metres, 0.01 for a depth in cm beside velocities in m/s."""
    if not all(c in df for c in DEPTH_UNIT_COLUMNS) or len(df) < 3:
        return []
    codes, names, order, t, dt, step = _experiment_sorted(df)
    logged = df[list(DEPTH_UNIT_COLUMNS)].to_numpy(dtype=np.float64)[order]
    z, phi, theta, u, v, w = (
        _filled(x, t, codes, angle=c in ANGLES)
        for c, x in zip(DEPTH_UNIT_COLUMNS, logged.T, strict=True)
    )
    angles, nu, dz = np.stack([phi, theta], 1), np.stack([u, v, w], 1), np.diff(z)
    mid = angles[:-1] + 0.5 * wrap_angle(np.diff(angles, axis=0))
    sphi, cphi = np.sin(mid[:, 0]), np.cos(mid[:, 0])
    sth, cth = np.sin(mid[:, 1]), np.cos(mid[:, 1])
    u, v, w = (0.5 * (nu[1:] + nu[:-1])).T  # each step's velocity (trapezoid)
    implied = (-sth * u + cth * sphi * v + cth * cphi * w) * dt
    # a span over a hole in t or a dropout is left out of both sums, as in rate_slopes; a
    # depth logged slower than the DVL is compared with the velocities' steps summed between
    # its samples
    ok = (dt < 3 * step[codes[1:]]) & np.isfinite(implied) & np.isfinite(dz)
    first, stop, starts, ends, _ = _sampled_spans(
        codes, t, np.isfinite(logged).all(1), ok, step, DEPTH_CHECK_WINDOW
    )
    g = _window_sums(_span_sums(implied, first, stop), starts, ends)
    a = _window_sums(_span_sums(dz, first, stop), starts, ends)
    use = np.abs(a) > DEPTH_CHECK_CHANGE
    k = codes[starts][use]
    n = np.bincount(k, minlength=len(names))
    ga = np.bincount(k, g[use] * a[use], minlength=len(names))
    aa = np.bincount(k, a[use] ** 2, minlength=len(names))
    gg = np.bincount(k, g[use] ** 2, minlength=len(names))
    out = []
    for e in np.flatnonzero(n):
        fit = float(ga[e] ** 2 / (aa[e] * gg[e])) if gg[e] > 0 else 0.0
        out.append((names[e], float(ga[e] / aa[e]), fit, float(n[e] * step[e])))
    return out


def check_depth_units(df: pd.DataFrame, source: str, row: int | None = None) -> None:
    """Velocities u, v, w and the depth z in one unit of length: an experiment whose depth
    change the velocities imply reads 20 to 2000 times (or 1/2000 to 1/20 of) the one z logs
    (:func:`depth_slopes`, :data:`DEPTH_UNIT_SLOPE`) is refused as a unit slip, cm/s or mm/s
    velocities or a depth in cm or mm, which the fit would take as a vehicle 100 times
    faster or slower than it is. One that reads about −1 (:data:`DEPTH_SIGN_SLOPE`) is
    refused as a sign turned: a height for the depth, or an upward w, which the fit would take
    as a vehicle that climbs when it dives. Per experiment, as :func:`check_rate_units`."""
    low, high = DEPTH_UNIT_SLOPE
    for name, slope, fit, seconds in depth_slopes(df):
        if seconds < RATE_CHECK_SECONDS or fit < DEPTH_CHECK_FIT:
            continue
        run = "" if name is None else f" in experiment {str(name)!r}"
        said = f"({seconds:.3g} s of windows where z changes)"
        if low <= slope <= high:
            raise NnidInputError(
                f"u, v, w say the depth changes {slope:.3g} times as fast as z does{run} "
                f"{said}: the velocities look like cm/s or mm/s beside a depth in metres; "
                'velocities must be m/s (or set the unit: unit = "cm/s" in the reader config)',
                source=source,
                field="w",
                row=row,
            )
        if 1 / high <= slope <= 1 / low:
            raise NnidInputError(
                f"z changes {1 / slope:.3g} times as fast as u, v, w say it does{run} {said}: "
                "the depth looks like cm or mm beside velocities in m/s; z must be in metres "
                '(or set the unit: unit = "cm" in the reader config)',
                source=source,
                field="z",
                row=row,
            )
        if DEPTH_SIGN_SLOPE[0] <= slope <= DEPTH_SIGN_SLOPE[1]:
            # a run that dives by pitching (−sin θ u) reads the same with θ turned: z turned
            # is then only one of two readings, and turning z where θ was wrong passes a log
            # that climbs as it dives
            pitched = _pitch_turned(df, name)
            raise NnidInputError(
                f"u, v, w say the depth changes against the way z does{run} (slope "
                f"{slope:.3g}, {said[1:-1]}): z must be the depth, positive down (NED), and w "
                "positive down the body's z axis; a height or altitude is −z, an upward w is −w"
                + (
                    "; or theta is turned (it must be positive nose up): with −theta u, v, w "
                    "agree with z, as the depth changes mostly through the pitch"
                    if pitched
                    else ""
                ),
                source=source,
                field="z",
                row=row,
            )


def _pitch_turned(df: pd.DataFrame, name: object) -> bool:
    """Whether experiment ``name`` of ``df`` (None: the log without experiments) reads as a
    consistent log (:func:`depth_slopes` about +1) once θ is turned."""
    turned = depth_slopes(df.assign(theta=-df["theta"].to_numpy(dtype=np.float64)))
    return any(
        n == name and -DEPTH_SIGN_SLOPE[1] <= s <= -DEPTH_SIGN_SLOPE[0] and fit >= DEPTH_CHECK_FIT
        for n, s, fit, _ in turned
    )


#: NED velocities logged under the body names u v w fit the pose's displacement as they stand,
#: and worse once turned by the attitude: an experiment whose x, y move this many times better
#: with u, v read as north/east than with J₁(Θ) ν₁ (:func:`velocity_frame_ratios`) is refused.
#: The one measured log with both (Tartan, 957 s, heading -0.8..1.5 rad) reads 0.22 as one
#: run, at most 1.26 cut into minutes and 1.71 into 20 s pieces; its velocities turned into
#: NED read 4.6 as one run and 4.6-9 in the minutes whose heading spans over a radian
VELOCITY_FRAME_RATIO = 3.0
#: windows of about this many seconds: long beside the lag of a DVL or a filter's velocity
#: behind the position (Tartan's: ~0.25 s), short beside a turn
VELOCITY_CHECK_WINDOW = 2.0
#: the windows of an experiment must cover this many seconds for its ratio to count
VELOCITY_CHECK_SECONDS = 20.0
#: and the world reading must explain this share of the displacement (its R²): a ratio of two
#: poor fits (a pose and velocities that do not agree either way) says nothing of the frame
VELOCITY_CHECK_FIT = 0.5
#: a residual under this share of the displacement's sum of squares is rounding, not misfit:
#: it is added to both readings' residuals, so that two exact fits (a pose integrated from its
#: velocities at a held heading) read 1, not a ratio of rounding errors (0.1 to 12 by chance)
VELOCITY_CHECK_ROUNDING = 1e-9


def north_east(angles: np.ndarray, nu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The north and east components of J₁(Θ) ν₁ (Weiss eq. 16, J₁ = R_z(ψ) R_y(θ) R_x(φ)) of
    angles ``[n, 3]`` = (φ, θ, ψ) and body velocities ``[n, 3]``: nnid.datasets.mapping's
    rotation_from_euler written out in numpy, because scipy's Rotation takes a second on 240k
    rows and every log read passes here (tests/test_log_and_excitation.py checks the two
    agree)."""
    sphi, cphi = np.sin(angles[:, 0]), np.cos(angles[:, 0])
    sth, cth = np.sin(angles[:, 1]), np.cos(angles[:, 1])
    spsi, cpsi = np.sin(angles[:, 2]), np.cos(angles[:, 2])
    u, v, w = nu.T
    # R_y(θ) R_x(φ) ν₁ first: its x and y, then turned by ψ
    level_x = cth * u + sth * (sphi * v + cphi * w)
    level_y = cphi * v - sphi * w
    return cpsi * level_x - spsi * level_y, spsi * level_x + cpsi * level_y


def velocity_frame_ratios(df: pd.DataFrame) -> list[tuple[object, float, float, float]]:
    """Per experiment of a log with the pose x, y, φ, θ, ψ and body velocities u, v, w: how
    much better u, v, w read as NED velocities fit the horizontal displacement than read as
    body velocities turned by the attitude, η̇₁ = J₁(Θ) ν₁ (Weiss eq. 16). Over windows of
    about :data:`VELOCITY_CHECK_WINDOW`, the displacement Δ(x + iy) is regressed on the
    integrated velocity of each reading, with a complex gain (a constant heading offset and
    scale between the position's axes and the compass, or a DVL's mounting) and a constant
    drift (a current), so that only the heading's changes tell the readings apart. Returns
    (experiment, ratio of the body reading's residual to the world reading's, the world
    reading's R², seconds of windows): under 1 for body velocities on a log that turns, about
    1 on one that holds its heading, over 1 for NED velocities under body names. A position
    logged slower than the velocities (a USBL fix at 1 Hz) is read across the spans between
    its samples (:func:`_sampled_spans`); a step across a gap (a hole in t, a dropout longer
    than two windows) is left out of every sum, and no window spans two experiments."""
    needed = ("x", "y", *ANGLES, "u", "v", "w")
    if not all(c in df for c in needed) or len(df) < 3:
        return []
    codes, names, order, t, dt, step = _experiment_sorted(df)
    logged = df[list(needed)].to_numpy(dtype=np.float64)[order]
    x, y, *columns = (
        _filled(values, t, codes, angle=col in ANGLES)
        for col, values in zip(needed, logged.T, strict=True)
    )
    angles, nu = np.stack(columns[:3], 1), np.stack(columns[3:], 1)
    moved = np.diff(np.stack([x, y], 1), axis=0)
    # each step's velocity (trapezoid), and turned by the attitude at the step's midpoint
    world = 0.5 * (nu[1:] + nu[:-1]) * dt[:, None]
    mid = angles[:-1] + 0.5 * wrap_angle(np.diff(angles, axis=0))
    body = north_east(mid, world)
    ok = (
        (codes[1:] == codes[:-1])
        & (dt < 3 * step[codes[1:]])
        & np.isfinite(moved).all(1)
        & np.isfinite(body[0])
        & np.isfinite(body[1])
    )
    first, stop, starts, ends, lags = _sampled_spans(
        codes, t, np.isfinite(logged).all(1), ok, step, VELOCITY_CHECK_WINDOW
    )
    if not starts.size:
        return []

    def sums(x: np.ndarray) -> np.ndarray:
        return _window_sums(_span_sums(x, first, stop), starts, ends)

    d = sums(moved[:, 0]) + 1j * sums(moved[:, 1])
    tau = sums(dt)
    readings = {
        "body": sums(body[0]) + 1j * sums(body[1]),
        "world": sums(world[:, 0]) + 1j * sums(world[:, 1]),
    }
    k = codes[starts]
    n = len(names)

    def total(x: np.ndarray) -> np.ndarray:  # per experiment, complex weights in two passes
        x = np.asarray(x, dtype=np.complex128)
        return np.bincount(k, x.real, minlength=n) + 1j * np.bincount(k, x.imag, minlength=n)

    dd, td, tt = total(np.abs(d) ** 2).real, total(tau * d), total(tau**2).real
    with np.errstate(invalid="ignore", divide="ignore"):
        drift_only = dd - np.abs(td) ** 2 / tt  # the displacement a constant drift leaves
        residual = {}
        for name, x in readings.items():
            # least squares of d on [x, tau] with complex coefficients: the residual is
            # dd - bᴴ G⁻¹ b, the 2x2 Gram matrix G inverted in closed form
            xx, xt, xd = total(np.abs(x) ** 2).real, total(np.conj(x) * tau), total(np.conj(x) * d)
            det = xx * tt - np.abs(xt) ** 2
            fitted = (
                tt * np.abs(xd) ** 2 - 2 * np.real(np.conj(xd) * xt * td) + xx * np.abs(td) ** 2
            )
            residual[name] = np.where(det > 1e-12 * xx * tt, dd - fitted / det, np.nan)
        rounding = VELOCITY_CHECK_ROUNDING * dd
        ratio = (residual["body"] + rounding) / (residual["world"] + rounding)
        fit = 1.0 - residual["world"] / drift_only
    # a window counts by the share of its time that holds data: windows over a long gap in
    # u, v, w add no seconds of evidence (tau: the window's steps that are not left out)
    seconds = np.bincount(k, tau, minlength=n) / lags
    return [
        (names[e], float(ratio[e]), float(fit[e]), float(seconds[e]))
        for e in np.flatnonzero(np.isfinite(ratio) & np.isfinite(fit))
    ]


def _check_velocity_frame(df: pd.DataFrame, source: str) -> None:
    """Body velocities u, v, w in the body frame (FRD) beside the pose: an experiment whose
    x, y displacement u, v fit :data:`VELOCITY_FRAME_RATIO` times better read as north/east
    than turned by the attitude (:func:`velocity_frame_ratios`) is refused as NED velocities
    under the body names. Per experiment, as the rate-unit check."""
    for name, ratio, fit, seconds in velocity_frame_ratios(df):
        if (
            seconds >= VELOCITY_CHECK_SECONDS
            and fit >= VELOCITY_CHECK_FIT
            and ratio >= VELOCITY_FRAME_RATIO
        ):
            run = "" if name is None else f" in experiment {str(name)!r}"
            raise NnidInputError(
                f"u, v, w look like world-frame (NED) velocities{run}: read as north/east they "
                f"fit the displacement of x, y {ratio:.3g} times better than turned from the "
                f"body by the attitude (phi, theta, psi) ({seconds:.3g} s of windows); body "
                "velocities must be in the body frame (FRD): turn NED velocities by J₁(Θ)ᵀ, or "
                "leave u v w out to derive them from the pose (if they are body velocities, "
                "the heading psi may be in another convention: ENU yaw is π/2 − ψ)",
                source=source,
                field="u",
            )


def _check_finite(df: pd.DataFrame, columns: list[str], source: str, gaps: bool = False) -> None:
    """Every value of ``columns`` a finite number (``gaps``: or an empty cell, though never a
    whole column of them); else the first bad row, named."""
    for col in columns:
        if pd.api.types.is_bool_dtype(df[col]):  # true/false would be read as 1/0 N or m/s
            raise NnidInputError(
                "holds true/false values: store the column as numbers", source=source, field=col
            )
        if pd.api.types.is_datetime64_any_dtype(df[col]) or pd.api.types.is_timedelta64_dtype(
            df[col]
        ):  # read as nanoseconds, and advised so
            raise NnidInputError(
                "holds date-times or durations: store seconds (since the run's start, or Unix "
                "seconds) as numbers",
                source=source,
                field=col,
            )
        values = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=np.float64)
        bad = ~np.isfinite(values)
        if gaps:
            empty = df[col].isna().to_numpy()
            if empty.all():
                raise NnidInputError(
                    "the column is empty: no sample has a value", source=source, field=col
                )
            bad &= ~empty
        refuse_rows(df, col, bad, source, "is not a finite number")
        if not pd.api.types.is_numeric_dtype(df[col]):
            # numbers stored as text (a parquet column of strings) read as numbers above, but
            # every later step would meet strings: refused, not converted behind the user's back
            text = df[col].map(lambda v: isinstance(v, str)).to_numpy()
            refuse_rows(df, col, text, source, "is text: store the column as numbers")


def refuse_rows(
    df: pd.DataFrame,
    col: str,
    bad: np.ndarray,
    source: str | None,
    why: str,
    labels: bool = False,
) -> None:
    """An error naming the first row ``bad`` flags in ``col`` and how many it flags: its
    position, or with ``labels`` its index label (the file's row once rows were dropped; a
    label that is not a whole number, a DataFrame's own index given in Python, is named in
    the message)."""
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        label = df.index[row] if labels else row
        whole = isinstance(label, (int, np.integer))
        raise NnidInputError(
            f"value {shown(df[col].iloc[row])} {why} ({int(bad.sum())} such rows in this column"
            + ("" if whole else f"; the first at index {shown(label)}")
            + ")",
            source=source,
            field=col,
            row=int(label) if whole else None,
        )


#: the columns the contract names exactly (cmd_<name> aside)
CONTRACT = ("t", "experiment", REPLAY_GROUP, PIECE_OF, *POSE, *VELOCITY, *ACCELERATION, *TAU)


#: a unit written after a column's name (``u [m/s]``, ``tau_X (N)``)
_UNIT_SUFFIX = re.compile(r"\s*[\[(][^\])]*[\])]\s*$")


def _check_spelling(df: pd.DataFrame, source: str) -> None:
    """A column that is a contract column but for case, spaces or a unit after its name,
    where the contract column itself is absent: it would be kept as an unknown column and the
    quantity derived or left out in its place. Refused (``' w'``, ``tau_z``, ``Experiment``,
    ``CMD_left``, ``u [m/s]``), except a single letter that differs only in case, which is
    said: ``P`` may be a pressure and ``V`` a battery voltage as well as a roll rate or a sway
    speed mistyped."""
    folded = {c.lower(): c for c in CONTRACT}
    for col in map(str, df.columns):
        if col in CONTRACT or col.startswith("cmd_"):
            continue
        bare = _UNIT_SUFFIX.sub("", col).strip()
        key = bare.lower()
        meant = folded.get(key) or (f"cmd_{bare[4:]}" if key.startswith("cmd_") else None)
        if meant is None or meant in df.columns:
            continue
        # "u [m/s]" was kept unread and u said missing, beside the column that holds it
        why = "names are case-sensitive" if _UNIT_SUFFIX.search(col) is None else (
            "a name carries no unit: every column is in SI units"
        )  # fmt: skip
        said = f"column {col!r} is not a column of the log contract ({why})"
        if len(col) == 1:
            warnings.warn(
                f"{source}: {said}: it is not read; if it is {meant!r}, rename it",
                stacklevel=3,
            )
            continue
        raise NnidInputError(
            f"{said}; did you mean {meant!r}? Rename the column, or map it with a reader config",
            source=source,
            field=col,
        )


def _check_experiments(df: pd.DataFrame, source: str) -> None:
    """Every row labelled when there is an ``experiment`` column: an empty label would drop the
    row from every per-experiment step without a word."""
    if "experiment" not in df:
        return
    empty = blank_labels(df["experiment"])
    if empty.any():
        rows = np.flatnonzero(empty)
        raise NnidInputError(
            f"{rows.size} rows have an empty experiment label (rows {shown(rows[0])}"
            + (f" to {shown(rows[-1])}" if rows.size > 1 else "")
            + "): label every row, or remove the column for a single run",
            source=source,
            field="experiment",
            row=int(rows[0]),
        )
    codes, labels = pd.factorize(df["experiment"])
    first = np.unique(codes, return_index=True)[1]  # each label's first row, checked once
    for label, row in zip(labels, first, strict=True):
        check_label(label, source, int(row))


def check_label(label: object, source: str, row: int) -> None:
    """An experiment label on one line (:func:`nnid.validation.one_line`), as a simulated
    run's name and a vehicle's are: a line break in it split every report line and heading
    naming its run. ``row``: its first, which the error names."""
    try:
        one_line(str(label))
    except ValueError as exc:
        raise NnidInputError(
            f"experiment label {str(label)!r}: {exc}: rename the run",
            source=source,
            field="experiment",
            row=row,
        ) from None


def blank_labels(label: pd.Series) -> np.ndarray:
    """Where an experiment label is empty or blank (a row that belongs to no run)."""
    return label.isna().to_numpy() | (label.astype(str).str.strip() == "").to_numpy()


def checked_time_unit(unit: str, field: str = "time_unit", source: str | None = None) -> str:
    """``unit`` if it is one of :data:`TIME_UNITS`, else an error naming ``field`` and them."""
    if unit not in TIME_UNITS:
        raise NnidInputError(
            f"unknown time unit {unit!r}: expected one of {', '.join(TIME_UNITS)}",
            source=source,
            field=field,
        )
    return unit


def declare_time_unit(df: pd.DataFrame, unit: str) -> tuple[pd.DataFrame, str]:
    """The log with ``t`` read in the declared ``unit`` (one of :data:`TIME_UNITS`) and
    converted to seconds (a copy; ``t`` as given when it is seconds), marked so that
    :func:`check_time_unit` does not guess again; and the sentence for the cleaning report."""
    name, per_second = TIME_UNITS[checked_time_unit(unit)]
    out = df.copy()
    t = out["t"] if "t" in out else None
    numeric = t is not None and is_numeric_dtype(t) and not is_bool_dtype(t)
    if numeric and per_second != 1.0:
        # divided, not multiplied by 1e-3: whole milliseconds stay the nearest seconds
        out["t"] = t.to_numpy(dtype=np.float64) / per_second
        said = f"t read as {name}, as declared: divided by {per_second:.0f}"
    else:  # seconds; or a t that validate_log refuses (missing, text, true/false) as it is
        said = f"t read as {name}, as declared: its unit not guessed from its steps"
    out.attrs[TIME_UNIT_ATTR] = unit
    return out, said


def check_time_unit(
    df: pd.DataFrame, source: str | None = None, declare: str = DECLARE_TIME_UNIT
) -> None:
    """Time in seconds: a median step of 5 to 1000 looks like milliseconds (whole, computed in
    floating point, or a logger's jittered stamps; no vehicle's dynamics are sampled every 5 s),
    one over 1000 like microseconds (10 Hz to under 1 kHz), one of 10⁵ or more like micro- or
    nanoseconds. Below 5, a median step of 1 to 5 whose every step is a whole number (to a
    thousandth) looks like milliseconds at 250 Hz to 1 kHz, a logger's integer stamps: a log in
    seconds that steps by whole seconds only is a 1-Hz or slower logger's, too slow for a
    vehicle's dynamics, and is refused with it (a seconds log's stamps carry fractions: every
    measured log under ``shared/data`` steps by 0.1 s or less). Jittered milliseconds at those
    rates are not told from a ~1-Hz log in seconds and pass. A step of exactly 1000 in every
    row is read as microseconds (1 kHz): as milliseconds it would be such a whole-second 1-Hz
    log; a median of 1000 with other steps (a jittered 1-Hz logger's) as milliseconds.

    Only the user knows which such a clock is: a log whose unit was declared
    (:func:`declare_time_unit`) is not guessed at, and the refusal names how to declare it
    (``declare``: a reader config's log is declared in the reader config). Declared or not,
    a median step under :data:`FASTEST_STEP` is refused (:func:`fine_clock_slip`): hours or
    minutes read as seconds, seconds declared as milliseconds; not stamps that come in
    bursts, whose mean step a log may take."""
    within = None
    if "experiment" in df:  # the jump from one run's clock to the next is no sample step
        codes = pd.factorize(df["experiment"])[0]
        within = codes[1:] == codes[:-1]
    t = df["t"].to_numpy(dtype=np.float64)
    # a declared unit is checked too: seconds declared as milliseconds step too finely
    declared = df.attrs.get(TIME_UNIT_ATTR)
    unit = declared if declared in TIME_UNITS else "s"
    steps = _run_steps(t, within)
    fine = None
    if steps.size >= 2:
        fine = fine_clock_slip(float(np.median(steps)), unit, bool(declared), paced_step(steps))
    if fine:
        slip, seconds = fine
        convert = (
            "convert it to seconds (multiply by 3600 for hours, 60 for minutes): a declared "
            f"unit is one of {', '.join(TIME_UNITS)}"
        )
        fix = declare if seconds else convert
        raise NnidInputError(f"{slip}; t must be seconds: {fix}", source=source, field="t")
    if declared:
        return
    slip = time_unit_slip(t, within)
    if slip:
        raise NnidInputError(f"{slip}; t must be seconds: {declare}", source=source, field="t")


def _run_steps(t: np.ndarray, within: np.ndarray | None = None) -> np.ndarray:
    """The sample steps of a clock ``t``, those inside one experiment (``within``) only."""
    if t.size < 3:
        return np.empty(0)
    steps = np.abs(np.diff(t))
    return steps if within is None else steps[within]


def paced_step(steps: np.ndarray) -> float:
    """A clock's mean sample step without its pauses (``steps`` over ten times their 95th
    percentile), for :func:`burst_clock`: a unit slip with stops in its run (a 10-min stop,
    or 2-min pauses between 5-s runs, read in hours) is still fine throughout, where a plain
    mean would take the pauses for a sample rate. A burst's gap is no pause while bursts hold
    at most 20 stamps (the gaps then more than 5 % of the steps)."""
    if steps.size < 2:
        return float(steps.mean()) if steps.size else np.inf
    kept = steps[steps <= 10.0 * np.quantile(steps, 0.95)]
    return float(kept.mean()) if kept.size else float(steps.mean())


def fine_clock_slip(
    step: float, unit: str = "s", declared: bool = False, overall: float | None = None
) -> tuple[str, bool] | None:
    """What a median sample step of ``step`` s under :data:`FASTEST_STEP` looks like, read
    from a clock in ``unit`` (one of :data:`TIME_UNITS`; ``declared``: as the user declared
    it), or None for a step an underwater vehicle's log may take, or for stamps that come in
    bursts (``overall``, the clock's :func:`paced_step`, at least :data:`FASTEST_STEP`:
    :func:`burst_clock`). Returns the sentence and whether the clock looks like seconds (a
    finer unit declared for seconds: the fix is declaring them), else like a unit coarser
    than seconds (hours or minutes read as seconds: the fix is converting). A unit is named
    where its step would be one a log may take (:data:`FASTEST_STEP` to
    :data:`SLOWEST_STEP`)."""
    if not 0.0 < step < FASTEST_STEP:  # a clock that stands still is refused elsewhere
        return None
    if burst_clock(step, overall):
        return None
    name, per_second = TIME_UNITS[unit]
    given = step * per_second  # the median step as the clock wrote it
    likely = {"seconds": 1.0} if per_second > 1.0 else {}
    likely |= COARSER_UNITS
    named = [
        f"{u} (a step of {shown(given * f)} s, {_hz(1 / (given * f))})"
        for u, f in likely.items()
        if FASTEST_STEP <= given * f < SLOWEST_STEP
    ]
    read = f"declared in {name}" if declared else f"read as {name}"
    said = (
        f"time, {read}, steps by {shown(given)} {unit} (median), {_hz(1 / step)}: faster than "
        f"any underwater vehicle's log (over {_hz(1 / FASTEST_STEP)})"
    )
    if not named:
        return f"{said}: t is not in {name}", False
    return f"{said}: this looks like {' or '.join(named)}", named[0].startswith("seconds")


def burst_clock(step: float, overall: float | None) -> str | None:
    """What a clock whose median step ``step`` (s) is under :data:`FASTEST_STEP` but whose
    :func:`paced_step` ``overall`` is not looks like (None for any other): stamps that come
    in bursts (an IMU delivering ten samples together every 10 ms), at a rate a log may take
    over the run. A unit slip (hours read as seconds, seconds declared as milliseconds) scales every
    step, the run's span with them, and steps finely by both."""
    if overall is None or not 0.0 < step < FASTEST_STEP <= overall:
        return None
    return (
        f"its stamps come in bursts: {shown(step)} s apart (median), {_hz(1 / overall)} over "
        "the run"
    )


def _hz(rate: float) -> str:
    """A sample rate as said to a user: whole hertz from 100 Hz, else three digits."""
    return f"{rate:.0f} Hz" if rate >= 100 else f"{rate:.3g} Hz"


def time_unit_slip(t: np.ndarray, within: np.ndarray | None = None) -> str | None:
    """What a time column meant as seconds looks like when it steps as another unit does
    (:func:`check_time_unit`'s rule), or None. ``within``: which steps lie inside one
    experiment (the others, a clock's jump between runs, are left out)."""
    steps = _run_steps(t, within)
    if steps.size < 2:
        return None
    step = float(np.median(steps))
    # integer stamps, up to float64's last bits (ms of Unix time computed from seconds)
    whole = bool(np.all(np.abs(steps - np.round(steps)) <= 1e-3))
    if step >= 1e5:
        unit = "nanoseconds (divide by 1e9) or microseconds (by 1e6)"
    elif step > 1000 or np.all(np.abs(steps - 1000) <= 1e-3):
        # a 20 Hz log in microseconds passed as 50000 s steps, and hung a fit
        unit = "microseconds (divide by 1e6)"
    # whole or jittered: no vehicle's dynamics are sampled this slowly
    elif SLOWEST_STEP <= step <= 1000:
        unit = "milliseconds (divide by 1000)"
    elif step >= 1 and whole:  # 250 Hz in integer milliseconds passed as a 0.25-Hz log
        return (
            f"time steps by {shown(step)} (median) and every step is a whole number: this looks "
            "like milliseconds (divide by 1000)"
        )
    else:
        return None
    return f"time steps by {shown(step)} (median): this looks like {unit}"


def _check_time(df: pd.DataFrame, source: str) -> None:
    """``t`` strictly increasing within each experiment, and each experiment at least two
    samples long (one sample has no sample period: nothing can be derived or fitted from it);
    else the first bad row, named."""
    groups = df.groupby("experiment", sort=False).indices if "experiment" in df else {None: None}
    t_all = df["t"].to_numpy(dtype=np.float64)
    for name, idx in groups.items():
        t = t_all if idx is None else t_all[idx]
        if t.size < 2:
            fix = (
                "give a longer log"
                if name is None
                else "label this row with its neighbours' experiment, or remove it"
            )
            raise NnidInputError(
                f"{run_label(name)} has a single sample: an experiment needs at least two (its "
                f"sample period); {fix}",
                source=source,
                field="experiment" if name is not None else "t",
                row=0 if idx is None else int(idx[0]),
            )
        dt = np.diff(t)
        if dt.size and (dt <= 0).any():
            k = int(np.flatnonzero(dt <= 0)[0])
            row = k + 1 if idx is None else int(idx[k + 1])
            what = "duplicated" if dt[k] == 0 else "decreasing"
            exp = "" if name is None else f" in experiment {str(name)!r}"
            raise NnidInputError(
                f"time is {what}{exp} ({shown(t[k])} then {shown(t[k + 1])}); t must be strictly "
                "increasing within an experiment",
                source=source,
                field="t",
                row=row,
            )


def validate_table(
    df: pd.DataFrame, columns: list[str], source: str = "<table>", require_time: bool = True
) -> pd.DataFrame:
    """Check a generic input-output table (a benchmark, a plant that is not a vehicle): a time
    column ``t`` strictly increasing within each experiment (``require_time=False``: only if
    there is one), the named ``columns`` present and finite, and every experiment label
    given, on one line, as a vehicle log's. Returns it unchanged; other columns are kept and
    ignored."""
    timed = require_time or "t" in df.columns
    needed = ["t", *columns] if timed else list(columns)
    missing = [c for c in needed if c not in df.columns]
    if missing:
        raise NnidInputError(f"the table has no column(s) {missing}", source=source)
    if len(df) == 0:
        raise NnidInputError("the table has no rows", source=source)
    _check_finite(df, needed, source)
    # a row of no run was dropped by the per-run steps without a word (as in a vehicle log)
    _check_experiments(df, source)
    if timed:
        _check_time(df, source)
    return df


def write_log(df: pd.DataFrame, path: str | Path) -> Path:
    """Write a log as CSV or Parquet, chosen by the suffix."""
    path = Path(path)
    if path.suffix not in (".parquet", ".csv"):
        raise NnidInputError("output must end in .csv or .parquet", source=str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    # written beside and renamed: a failed write never leaves a truncated log at ``path``
    part = path.with_name(f".{path.name}.part")
    try:
        if path.suffix == ".parquet":
            df.to_parquet(part, index=False)
        else:
            df.to_csv(part, index=False)
        os.replace(part, path)
    finally:
        part.unlink(missing_ok=True)
    return path
