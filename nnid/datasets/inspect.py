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


def rate_of(intervals: np.ndarray) -> float:
    """1 / the median sample interval, NaN where there is none (a run of one sample)."""
    return 1.0 / float(np.median(intervals)) if intervals.size else float("nan")


def summarize(log: pd.DataFrame) -> dict:
    """A JSON-ready summary of a validated log. ``runs`` counts the experiments as recorded:
    the pieces a reader cut one run into at its gaps (``experiments`` rows with ``piece_of``)
    are one run."""
    inputs = input_columns(log)
    known = {"t", "experiment", PIECE_OF, REPLAY_GROUP, *POSE, *VELOCITY, *ACCELERATION, *inputs}
    groups = experiments(log)
    exp_rows, gaps, intervals = [], [], []
    for name, idx in groups:
        t = log.loc[idx, "t"].to_numpy(np.float64)
        dt = np.diff(t)
        med = float(np.median(dt)) if dt.size else float("nan")
        intervals.append(dt)
        # a piece cut from a run at a gap (the readers' ``<run>#<k>``) is not an experiment of
        # its own: told by PIECE_OF, never by its label (nnid.datasets.log)
        whole = log.loc[idx[0], PIECE_OF] if PIECE_OF in log and len(idx) else None
        whole = str(whole) if pd.notna(whole) and str(whole) else None
        exp_rows.append({"name": None if name is None else str(name), "samples": int(t.size),
                         "duration_s": float(t[-1] - t[0]) if t.size else 0.0,
                         "rate_hz": rate_of(dt), "piece_of": whole})  # fmt: skip
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
        # the median interval of all samples: the median of the runs' rates was a rate no run
        # had (55 Hz for a run at 10 Hz and one at 100 Hz); each run's is in ``experiments``
        "rate_hz": rate_of(np.concatenate(intervals)),
        "duration_s": float(sum(e["duration_s"] for e in exp_rows)),
        "runs": len({e["piece_of"] or e["name"] for e in exp_rows}),
        "experiments": exp_rows,
        "gaps": gaps,
        "missing": gaps_record(find_gaps(log)),
        "derivable": derivable,
        "excitation": excitation,
    }
