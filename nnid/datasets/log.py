"""The vehicle log contract (ARCHITECTURE.md): one row per sample, SI units, NED/FRD, radians.

Columns: ``t`` (s, strictly increasing within an experiment), optional ``experiment``, pose
``x y z phi theta psi`` and/or body velocities ``u v w p q r``, optional accelerations
``du … dr``, inputs ``tau_X … tau_N`` or ``cmd_<thruster>``. Other columns are kept.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from nnid.errors import NnidInputError
from nnid.physics.dofs import DOFS, FORCES
from nnid.validation import shown

POSE = ("x", "y", "z", "phi", "theta", "psi")
VELOCITY = DOFS  # velocity columns are named after their DOF
ACCELERATION = tuple(f"d{s}" for s in VELOCITY)
TAU = tuple(f"tau_{f}" for f in FORCES)
ANGLES = ("phi", "theta", "psi")


def input_columns(df: pd.DataFrame) -> list[str]:
    """The input columns present: generalized forces, or thruster commands."""
    return [c for c in df.columns if c in TAU or str(c).startswith("cmd_")]


def validate_log(
    df: pd.DataFrame, source: str = "<log>", require_inputs: bool = True
) -> pd.DataFrame:
    """Check a log against the contract and return it unchanged.

    Raises :class:`NnidInputError` naming the file, the column and the row of the first problem.
    Nothing is dropped or repaired here.
    """
    if "t" not in df.columns:
        raise NnidInputError("required column 't' (time in seconds) is missing", source=source)
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
    _check_finite(
        df, ["t", *motion, *[c for c in ACCELERATION if c in df.columns], *inputs], source
    )
    _check_time(df, source)
    for col in ANGLES:
        if col in df.columns:
            peak = float(np.abs(df[col].to_numpy(dtype=np.float64)).max())
            if peak > 2 * math.pi + 1e-6:
                row = int(np.abs(df[col].to_numpy(dtype=np.float64)).argmax())
                raise NnidInputError(
                    f"angle of {peak:.4g} looks like degrees; angles must be in radians",
                    source=source,
                    field=col,
                    row=row,
                )
    return df


def _check_finite(df: pd.DataFrame, columns: list[str], source: str) -> None:
    """Every value of ``columns`` a finite number; else the first bad row, named."""
    for col in columns:
        values = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=np.float64)
        bad = ~np.isfinite(values)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise NnidInputError(
                f"value {shown(df[col].iloc[row])} is not a finite number "
                f"({int(bad.sum())} such rows in this column)",
                source=source,
                field=col,
                row=row,
            )


def _check_time(df: pd.DataFrame, source: str) -> None:
    """``t`` strictly increasing within each experiment; else the first bad row, named."""
    groups = df.groupby("experiment", sort=False).indices if "experiment" in df else {None: None}
    t_all = df["t"].to_numpy(dtype=np.float64)
    for name, idx in groups.items():
        t = t_all if idx is None else t_all[idx]
        dt = np.diff(t)
        if dt.size and (dt <= 0).any():
            k = int(np.flatnonzero(dt <= 0)[0])
            row = k + 1 if idx is None else int(idx[k + 1])
            what = "duplicated" if dt[k] == 0 else "decreasing"
            exp = "" if name is None else f" in experiment {name!r}"
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
    there is one) and the named ``columns`` present and finite. Returns it unchanged; other
    columns are kept and ignored."""
    timed = require_time or "t" in df.columns
    needed = ["t", *columns] if timed else list(columns)
    missing = [c for c in needed if c not in df.columns]
    if missing:
        raise NnidInputError(f"the table has no column(s) {missing}", source=source)
    if len(df) == 0:
        raise NnidInputError("the table has no rows", source=source)
    _check_finite(df, needed, source)
    if timed:
        _check_time(df, source)
    return df


def read_log(path: str | Path) -> pd.DataFrame:
    """Read a CSV or Parquet log (by suffix) and validate it."""
    path = Path(path)
    if not path.exists():
        raise NnidInputError("file not found", source=str(path))
    try:
        if path.suffix == ".parquet":
            df = pd.read_parquet(path)
        elif path.suffix in (".csv", ".gz") or path.name.endswith(".csv.gz"):
            df = pd.read_csv(path)
        else:
            raise NnidInputError(
                "unknown log format; expected .csv, .csv.gz or .parquet", source=str(path)
            )
    except NnidInputError:
        raise
    except Exception as err:  # pandas/pyarrow raise many types for a truncated or corrupt file
        raise NnidInputError(f"cannot be read as a log ({err})", source=str(path)) from None
    return validate_log(df, source=str(path))


def write_log(df: pd.DataFrame, path: str | Path) -> Path:
    """Write a log as CSV or Parquet, chosen by the suffix."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".parquet":
        df.to_parquet(path, index=False)
    elif path.suffix == ".csv":
        df.to_csv(path, index=False)
    else:
        raise NnidInputError("output must end in .csv or .parquet", source=str(path))
    return path
