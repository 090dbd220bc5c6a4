"""What a log holds: columns, rate, duration, experiments, gaps in time and empty motion cells
(:mod:`nnid.datasets.gaps`), derivable signals and how much
each DOF is excited. Used by ``nnid inspect``; returns data, prints nothing."""

from __future__ import annotations

import numpy as np
import pandas as pd

from nnid.datasets.gaps import find_gaps, gaps_record
from nnid.datasets.log import (
    ACCELERATION,
    ANGLES,
    PIECE_OF,
    POSE,
    REPLAY_GROUP,
    VELOCITY,
    input_columns,
)
from nnid.datasets.preprocess import experiments

DOF_FORCE = dict(zip(VELOCITY, ("tau_X", "tau_Y", "tau_Z", "tau_K", "tau_M", "tau_N"), strict=True))


def summarize(log: pd.DataFrame) -> dict:
    """A JSON-ready summary of a validated log."""
    inputs = input_columns(log)
    known = {"t", "experiment", PIECE_OF, REPLAY_GROUP, *POSE, *VELOCITY, *ACCELERATION, *inputs}
    groups = experiments(log)
    exp_rows, gaps, rates = [], [], []
    for name, idx in groups:
        t = log.loc[idx, "t"].to_numpy(np.float64)
        dt = np.diff(t)
        med = float(np.median(dt)) if dt.size else float("nan")
        rates.append(1.0 / med if dt.size else float("nan"))
        exp_rows.append({"name": None if name is None else str(name), "samples": int(t.size),
                         "duration_s": float(t[-1] - t[0]) if t.size else 0.0})  # fmt: skip
        for k in np.flatnonzero(dt > 1.5 * med):
            gaps.append({"experiment": None if name is None else str(name),
                         "t": float(t[k]), "length_s": float(dt[k])})  # fmt: skip
    pose = [c for c in POSE if c in log]
    derivable = []
    if all(a in log for a in ANGLES):
        derivable += [c for c in ("p", "q", "r") if c not in log]
        if all(c in log for c in ("x", "y", "z")):
            derivable += [c for c in ("u", "v", "w") if c not in log]
        elif "z" in log and "w" not in log:
            derivable.append("w (approximate, from depth rate)")
    derivable += [f"d{c}" for c in VELOCITY if c in log and f"d{c}" not in log]
    excitation = {}
    for dof in VELOCITY:
        entry = {}
        if dof in log:
            entry["velocity_std"] = float(log[dof].std())
        force = DOF_FORCE[dof]
        if force in log:
            entry["force_std"] = float(log[force].std())
            entry["force_active_share"] = float((log[force].abs() > 1e-9).mean())
        if entry:
            excitation[dof] = entry
    return {
        "samples": len(log),
        "columns": {
            "pose": pose,
            "velocity": [c for c in VELOCITY if c in log],
            "acceleration": [c for c in ACCELERATION if c in log],
            "inputs": inputs,
            "other": [str(c) for c in log.columns if c not in known],
        },
        "rate_hz": float(np.nanmedian(rates)),
        "duration_s": float(sum(e["duration_s"] for e in exp_rows)),
        "experiments": exp_rows,
        "gaps": gaps,
        "missing": gaps_record(find_gaps(log)),
        "derivable": derivable,
        "excitation": excitation,
    }
