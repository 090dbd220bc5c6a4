"""Raw source tables through the column map: columns renamed and scaled to SI units, time in
seconds, quaternions turned into zyx Euler angles and ENU/FLU frames into NED/FRD.

Every reader (tables in :mod:`nnid.datasets.readers`, ROS bags, ArduPilot logs) maps its raw
tables here; :func:`nnid.datasets.readers.assemble` then puts them onto one time base. The
attitude conversions go through scipy's ``Rotation``.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial.transform import Rotation

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.column_map import ColumnMap, Source
from nnid.datasets.log import (
    ANGLES,
    CONTRACT,
    MOTION,
    blank_labels,
    declare_time_unit,
    looks_like_degrees,
    paced_step,
    refuse_rows,
)
from nnid.errors import NnidInputError
from nnid.validation import shown

#: how far a logged quaternion's norm may be from the log's median norm (sensors write them
#: unit to ~1e-3, some as integers at a fixed scale)
QUATERNION_SLACK = 0.1


def euler_from_rotation(rot: np.ndarray) -> np.ndarray:
    """zyx Euler angles (φ, θ, ψ) of rotation matrices ``[..., 3, 3]`` (inverse of J₁), with
    φ and ψ in (−π, π] and θ in [−π/2, π/2]. Within about 1e-7 rad of θ = ±π/2 (gimbal lock),
    where only ψ ∓ φ is defined, φ = 0."""
    rot = np.asarray(rot, dtype=np.float64)
    ok = np.isfinite(rot).all((-2, -1))  # NaN rows (a zero quaternion) stay NaN, not an error
    angles = np.full(rot.shape[:-1], np.nan)
    with warnings.catch_warnings():
        # scipy warns on every call that holds a gimbal-locked matrix; the docstring says it
        warnings.filterwarnings("ignore", "Gimbal lock detected", UserWarning)
        angles[ok] = Rotation.from_matrix(rot[ok]).as_euler("ZYX")[..., ::-1]
    # scipy's range is [−π, π]; the half-open (−π, π] of atan2 is the one the logs use
    return np.where(angles == -np.pi, np.pi, angles)


def rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    """Rotation matrices of unit quaternions ``[..., 4]`` (w, x, y, z), normalised first; a zero
    or non-finite quaternion gives a NaN matrix."""
    q = np.asarray(q, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    ok = np.isfinite(q).all(-1)
    out = np.full((*q.shape[:-1], 3, 3), np.nan)
    # scipy refuses a zero quaternion (a sensor not yet initialised): its rows stay NaN, so one
    # bad message does not stop the whole log
    out[ok] = Rotation.from_quat(q[ok], scalar_first=True).as_matrix()
    return out


def rotation_from_euler(angles: np.ndarray) -> np.ndarray:
    """J₁(Θ) = R_z(ψ) R_y(θ) R_x(φ) of angles ``[..., 3]`` = (φ, θ, ψ), as ``[..., 3, 3]``
    (the convention of :func:`nnid.physics.kinematics.rotation_matrix`)."""
    angles = np.asarray(angles, dtype=np.float64)
    return Rotation.from_euler("ZYX", angles[..., ::-1]).as_matrix()


#: columns whose sign flips from ENU / FLU to NED / FRD (the world's z, the body's y and z
#: axes: velocities, rates, accelerations, forces and moments about them; pitch)
_FLIPPED = ("z", "v", "w", "q", "r", "dv", "dw", "dq", "dr", "tau_Y", "tau_Z", "tau_M", "tau_N",
            "theta")  # fmt: skip


def _to_ned_frd(out: pd.DataFrame, origin: str) -> None:
    """Convert the standard columns present from ENU world / FLU body to NED / FRD in place,
    each on its own: the world's x and y swap (so they come together), z and the body's y and
    z axes change sign, and the zyx Euler angles become (φ, −θ, π/2 − ψ) (the rotation
    T R(φ, θ, ψ) F with T the ENU-NED and F the FLU-FRD matrix, exactly). A depth sensor, a
    compass or a two-axis DVL is converted alone; before, only whole groups were, and the
    forces never."""
    if ("x" in out) != ("y" in out):
        given, absent = ("x", "y") if "x" in out else ("y", "x")
        raise NnidInputError(
            f"ENU {given} is NED {absent}: converting the frame needs both x and y (map "
            f"{absent} too, or leave {given} out)",
            source=origin,
            field=given,
        )
    if "x" in out:
        out["x"], out["y"] = out["y"].to_numpy(), out["x"].to_numpy()
    for col in _FLIPPED:
        if col in out:
            out[col] = -out[col]
    if "psi" in out:  # (−π, π], the logs' half-open range
        out["psi"] = np.angle(np.exp(1j * (np.pi / 2 - out["psi"].to_numpy(np.float64))))


def map_message_sources(
    rows: dict[str, list],
    cmap: ColumnMap,
    path: Path,
    stem: str,
    report: CleaningReport,
    empty: str,
    prepare=None,
) -> list[tuple[Source, pd.DataFrame]]:
    """The sources of a message log (ROS bag topics, ArduPilot message types) through
    :func:`map_source`: ``rows[source.file]`` holds the decoded messages of each; a source with
    none is an error whose text is ``empty`` formatted with its name; ``prepare(raw)`` may add
    derived columns first. The experiment is ``stem`` unless the column map names one."""
    by_stem = cmap.experiment in (None, "file")
    tables = []
    for i, source in enumerate(cmap.sources):
        origin = f"{path}:{source.file}"
        if not rows[source.file]:
            raise NnidInputError(
                empty.format(source.file), source=str(path), field=f"sources.{i}.file"
            )
        raw = pd.DataFrame(rows[source.file])
        if prepare is not None:
            prepare(raw)
        mapped = map_source(
            raw, source, origin, None if by_stem else cmap.experiment, cmap.drop_nonfinite, report
        )
        if by_stem:
            mapped["experiment"] = stem
        report.add("read", f"{origin}: {len(raw)} messages")
        tables.append((source, mapped))
    return tables


#: suffixes of a compressed table, removed with the data suffix before them
COMPRESSION = (".gz", ".bz2", ".xz", ".zip", ".zst")


def file_label(path: str) -> str:
    """A file's run label under ``experiment = "file"``: its name without the data suffix
    (``dive.2024-05-01.csv.gz`` -> ``dive.2024-05-01``; the dots before it are kept, or two days'
    files would both be ``dive``)."""
    name = Path(path).name
    for suffix in COMPRESSION:
        name = name.removesuffix(suffix)
    return Path(name).stem or name


def label_columns(experiment: str | list[str] | None) -> list[str]:
    """The columns a reader config names its runs by: ``experiment`` as a column or a list of
    them; none for "file" (the file's name) or None (one run)."""
    keys = [experiment] if isinstance(experiment, str) else list(experiment or [])
    return [] if keys == ["file"] else keys


def _measured(source: Source) -> list[str]:
    """The source columns of ``source`` that only feed measured motion columns (pose,
    velocities, accelerations, a quaternion) of a measured (``linear``) source: an empty cell
    there is a missing measurement, not a missing time, command or force."""
    if source.method != "linear":
        return []
    feeds: dict[str, set[str]] = {}
    for name, spec in source.specs().items():
        feeds.setdefault(spec.source, set()).add(name)
    motion = [col for col, names in feeds.items() if names <= set(MOTION)]
    return [c for c in [*motion, *source.quaternion] if c != source.time]


def map_source(
    raw: pd.DataFrame,
    source: Source,
    origin: str,
    experiment: str | list[str] | None,
    drop_nonfinite: bool,
    report: CleaningReport,
) -> pd.DataFrame:
    """Rename and convert one source table: columns ``t``, ``experiment`` and the mapped ones.

    ``experiment`` is a column, a list of columns (values joined with "/"), "file" (the file
    stem) or None (one run).
    """
    if raw.empty:  # a header and no data: nothing to align, said here and not as a traceback
        raise NnidInputError("has no rows", source=origin)
    needed = [source.time, *source.quaternion, *(s.source for s in source.specs().values())]
    keys = label_columns(experiment)
    # one source column may feed several targets (each its own offset and scale): read once
    needed = list(dict.fromkeys(needed + keys))
    for col in needed:
        if col not in raw.columns:
            raise NnidInputError(
                f"column '{col}' named in the reader config is missing; the file has "
                f"{', '.join(map(str, raw.columns[:20]))}",
                source=origin,
            )
    numeric = [c for c in needed if c not in keys]
    if source.row_clock:  # counted before any row is dropped: a dropped row leaves a gap
        rows = (
            raw.groupby(keys, sort=False, dropna=False).cumcount().to_numpy(np.float64)
            if keys
            else np.arange(len(raw), dtype=np.float64)
        )
        clock = pd.Series(rows / source.row_clock, index=raw.index)
    values = raw[numeric].apply(pd.to_numeric, errors="coerce")
    bad = ~np.isfinite(values.to_numpy(dtype=np.float64))
    # an empty cell of a measured motion column (a DVL's u, v, w while it lost bottom lock)
    # stays empty: the resampling bridges it where its neighbours are close and leaves a gap
    # (nnid.datasets.gaps) where not; dropped or refused, the row's other columns went too
    empty = raw[numeric].isna().to_numpy() & np.isin(numeric, _measured(source))
    if not drop_nonfinite and empty.any():
        bad &= ~empty
        report.add(
            "empty cells",
            f"{origin}: {int(empty.any(1).sum())} rows with an empty cell in "
            f"{', '.join(sorted({numeric[c] for c in np.nonzero(empty)[1]}))}: left empty, "
            "interpolated over where the samples beside them are close, else a gap",
        )
    if bad.any():
        rows, cols = np.nonzero(bad)
        if not drop_nonfinite:
            raise NnidInputError(
                f"value {shown(raw[numeric[cols[0]]].iloc[rows[0]])} is not a finite number "
                f"({int(bad.any(1).sum())} rows have one; set drop_nonfinite = true in the reader "
                "config to drop them)",
                source=origin,
                field=numeric[cols[0]],
                row=int(rows[0]),
            )
        keep = ~bad.any(1)
        report.add(
            "drop non-finite",
            f"{origin}: rows with NaN/inf in {sorted({numeric[c] for c in cols})}",
            int((~keep).sum()),
        )
        raw, values = raw[keep], values[keep]
        if raw.empty:
            raise NnidInputError(
                "no row is left once the non-finite ones are dropped", source=origin
            )
    out = pd.DataFrame(index=raw.index)
    if source.row_clock:
        out["t"] = clock.loc[raw.index].to_numpy()
    else:
        out["t"] = values[source.time].to_numpy(dtype=np.float64) * source.time_scale
        if source.time_unit is not None:  # declared: converted and said as a log's --time-unit
            out, said = declare_time_unit(out, source.time_unit)
            report.add("time unit", f"{origin}: {said}", columns=["t"])
    if experiment == "file":
        out["experiment"] = file_label(origin)
    elif keys:
        for key in keys:  # a row of no run would be dropped from every run without a word
            empty = blank_labels(raw[key])
            refuse_rows(raw, key, empty, origin, "is no experiment label", labels=True)
        ident = raw[keys[0]].astype(str)
        for key in keys[1:]:  # vectorised: a row-wise join is slow on a million rows
            ident = ident + "/" + raw[key].astype(str)
        out["experiment"] = ident.to_numpy()
    else:
        out["experiment"] = "0"
    specs = source.specs()
    for name, spec in specs.items():
        out[name] = (values[spec.source].to_numpy(dtype=np.float64) + spec.offset) * spec.factor()
    zeroed = [name for name, spec in specs.items() if spec.factor() == 0]
    if zeroed:  # a channel known to stay neutral, or a slip: either way, said
        report.add("zero scale", f"{origin}: {', '.join(zeroed)} mapped with scale 0: all zero")
    unitless = [col for col in ANGLES if col in specs and specs[col].unit is None]
    for col in unitless:
        # before the frame conversion and the resampling, which wrap angles to ±π: degrees
        # wrapped as radians would pass every later check; a unit given is the user's word
        if looks_like_degrees(out, col):
            # a source logs its angles in one unit: a small roll and pitch in degrees pass
            # the ±2π check, and were read as radians once the yaw alone was given "deg"
            others = [c for c in unitless if c != col]
            also = (
                f"; {', '.join(others)} of this source {'has' if len(others) == 1 else 'have'} "
                'no unit either: set unit = "deg" (or "rad") for each'
                if others
                else ""
            )
            raise NnidInputError(
                f"reaches {np.nanmax(np.abs(out[col])):.4g}, which looks like degrees for {col}: "
                f'set unit = "deg" for {col} in the reader config (or unit = "rad" for '
                f"unwrapped radians){also}",
                source=origin,
                field=specs[col].source,
            )
    declared = [col for col in ANGLES if col in specs and specs[col].unit is not None]
    if declared and unitless:
        # one source logs its attitude in one unit: a roll of a few degrees beside a yaw given
        # "deg" passes the degrees guess, and was read as radians
        raise NnidInputError(
            f"{', '.join(f'{c} ({specs[c].source!r})' for c in declared)} "
            f"{'declares a unit' if len(declared) == 1 else 'declare units'} but "
            f"{', '.join(f'{c} ({specs[c].source!r})' for c in unitless)} of the same source "
            f'{"has" if len(unitless) == 1 else "have"} none: set unit = "deg" (or "rad") '
            "for each angle",
            source=origin,
            field=specs[unitless[0]].source,
        )
    time = "row_clock" if source.row_clock else source.time
    check_clock(out, origin, time, report, "last" if source.method == "hold" else "first")
    if source.quaternion:
        quat = values[source.quaternion].to_numpy(dtype=np.float64)
        norm = np.linalg.norm(quat, axis=1)
        live = np.isfinite(norm) & (norm > 0)  # a zero quaternion: a sensor not yet initialised
        # against their median: a constant norm is a storage scale (q × 10⁴), a varying one
        # four columns that are not one quaternion
        scale = float(np.median(norm[live])) if live.any() else 1.0
        off = live & (np.abs(norm / scale - 1.0) > QUATERNION_SLACK)
        if off.sum() > 0.05 * max(live.sum(), 1):  # normalising would hide the wrong columns
            raise NnidInputError(
                f"the quaternion columns {', '.join(source.quaternion)} do not keep one norm "
                f"(from {np.min(norm[live]):.3g} to {np.max(norm[live]):.3g}; {int(off.sum())} "
                f"rows off their median by more than {QUATERNION_SLACK:.0%}): are they the w, x, "
                "y, z of one orientation?",
                source=origin,
                field="quaternion",
            )
        rot = rotation_from_quaternion(quat)
        if not live.all():
            report.add(
                "zero quaternion",
                f"{origin}: {int((~live).sum())} rows with a zero or undefined quaternion: their "
                "attitude is interpolated where the rows beside them are close, else a gap",
            )
        out["phi"], out["theta"], out["psi"] = euler_from_rotation(rot).T
    if source.frame == "enu_flu":
        _to_ned_frd(out, origin)
        # a column of the user's own (an accelerometer's acc_x) is not the contract's: it stays
        own = [c for c in out.columns if c not in CONTRACT and not str(c).startswith("cmd_")]
        report.add(
            "frame",
            f"{origin}: ENU/FLU converted to NED/FRD"
            + (f"; columns of its own left as logged: {', '.join(own)}" if own else ""),
        )
    return out.reset_index(drop=True)


#: the share of a run's samples that may sit behind an earlier stamp before the source is
#: refused as a clock reset (two runs of one file without their experiment column); a few late
#: messages are sorted in
RESET_SHARE = 0.1
#: how many of a source's typical steps (its pace, :func:`~nnid.datasets.log.paced_step`) a
#: late sample may sit behind an earlier stamp and still be sorted in; further back is a clock
#: reset (a reboot), whose samples would be interleaved with the others' times
LATE_STEPS = 5


def check_clock(
    out: pd.DataFrame, origin: str, time: str, report: CleaningReport, kept: str = "first"
) -> None:
    """A source's clock, per experiment: never reset (many samples behind an earlier stamp:
    two runs of one file without their experiment column; or any sample more than
    :data:`LATE_STEPS` steps behind, a reboot), refused; a few late samples (sorted in) and
    repeated stamps (the ``kept`` of each: the first measurement, the last command, which is
    the one in force) said in the cleaning report."""
    t_all = out["t"].to_numpy(dtype=np.float64)
    for exp, idx in out.groupby("experiment", sort=False).indices.items():
        t = t_all[idx]
        behind = t < np.maximum.accumulate(t)
        if behind.sum() > RESET_SHARE * t.size:
            k = int(np.flatnonzero(behind)[0])
            raise NnidInputError(
                f"time goes back by {t[:k].max() - t[k]:.4g} s in experiment '{exp}' and "
                f"{int(behind.sum())} of its {t.size} samples stay behind: two runs in one "
                "file? name the column that tells them apart (experiment = ...)",
                source=origin,
                field=time,
                row=int(out.index[idx[k]]),
            )
        if behind.any():
            # a reset in a few samples (a reboot near the log's end) is under the share above:
            # sorted in, its times were taken for the earlier ones'
            back = np.maximum.accumulate(t) - t
            limit = LATE_STEPS * paced_step(np.diff(np.sort(t)))
            if back.max() > limit:
                k = int(np.flatnonzero(back > limit)[0])
                raise NnidInputError(
                    f"time goes back from {t[:k].max():.12g} s to {t[k]:.12g} s in experiment "
                    f"'{exp}', by {back[k]:.4g} s: a late sample is sorted in up to "
                    f"{LATE_STEPS} of its steps back ({limit:.3g} s), this is a clock reset (a "
                    "reboot?); cut the file there, or name the column that tells the runs "
                    "apart (experiment = ...)",
                    source=origin,
                    field=time,
                    row=int(out.index[idx[k]]),
                )
            report.add("sort", f"{origin}: '{exp}': {int(behind.sum())} late samples sorted in")
        repeated = t.size - np.unique(t).size
        if repeated:
            hint = (
                "; stamps coarser than the samples (row_clock) or runs merged (experiment)?"
                if repeated > RESET_SHARE * t.size
                else ""
            )
            report.add(
                "repeated stamps",
                f"{origin}: '{exp}': {repeated} of {t.size} samples repeat a stamp, the {kept} "
                f"of each kept{hint}",
                repeated,
            )
