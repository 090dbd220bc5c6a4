"""What a log holds: columns, rate, duration, experiments, gaps in time and empty motion cells
(:mod:`nnid.datasets.gaps`), derivable signals, how much each DOF is excited (its velocity as
logged or as the fits derive it from the pose) and how much each input channel moves. Used by
``nnid inspect``; returns data, prints nothing."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pandas as pd

from nnid.datasets.gaps import (
    between_samples,
    find_gaps,
    gaps_record,
    gyro_filled,
    slow_channels,
    span_ends,
)
from nnid.datasets.log import (
    ACCELERATION,
    ANGLES,
    PIECE_OF,
    POSE,
    REPLAY_GROUP,
    TAU,
    VELOCITY,
    clock_step,
    input_columns,
)
from nnid.datasets.preprocess import (
    derivable_velocities,
    derive_velocities,
    excited_dofs,
    experiment_rows,
    logged_rate,
)
from nnid.errors import NnidInputError

DOF_FORCE = dict(zip(VELOCITY, TAU, strict=True))


def rate_of(intervals: np.ndarray) -> float:
    """1 / the median sample interval, NaN where there is none (a run of one sample). The
    intervals of a coarsely rounded clock are read at its step first (:func:`summarize`)."""
    return 1.0 / float(np.median(intervals)) if intervals.size else float("nan")


def activity(values: pd.Series) -> dict[str, float]:
    """How much an input channel moves: its standard deviation and the share of samples where
    it is not zero."""
    return {"std": float(values.std()), "active_share": float((values.abs() > 1e-9).mean())}


def velocities_from_pose(
    log: pd.DataFrame, savgol_window: float, savgol_order: int
) -> tuple[pd.DataFrame, dict]:
    """``log`` with the body velocities it lacks derived from its pose as the fits derive them
    (:func:`nnid.datasets.preprocess.derive_velocities`, the pipeline's condition and [data]'s
    window), and what was derived: ``columns``, ``approximate`` (w from the depth rate alone),
    the window, or ``error`` where the pose gives none (a run shorter than the window)."""
    if all(c in log for c in VELOCITY) or not all(a in log for a in ANGLES):
        return log, {}
    record: dict = {"window_s": float(savgol_window), "order": int(savgol_order)}
    try:
        out = derive_velocities(log, savgol_window, savgol_order)
    except NnidInputError as exc:  # said in the summary, never a failed inspect
        return log, {**record, "columns": [], "error": exc.message}
    made = [c for c in VELOCITY if c in out and c not in log]
    approximate = ["w"] if "w" in made and "x" not in log else []
    return out, {**record, "columns": made, "approximate": approximate}


def summarize(log: pd.DataFrame, savgol_window: float = 1.0, savgol_order: int = 4) -> dict:
    """A JSON-ready summary of a validated log. ``runs`` counts the experiments as recorded:
    the pieces a reader cut one run into at its gaps (``experiments`` rows with ``piece_of``)
    are one run. ``duration_s`` is the time sampled; ``gap_s`` the time in gaps (each gap's
    length less one sample interval, as :mod:`nnid.datasets.gaps` counts missing samples,
    the hole between two consecutive pieces of one run included, as their run's clock shows
    it). Velocities the log lacks are derived from its pose
    with ``savgol_window`` s and ``savgol_order`` (:func:`velocities_from_pose`) for the
    excitation and ``excited`` (:func:`nnid.datasets.preprocess.excited_dofs`). ``commands``:
    the excitation of each ``cmd_*`` channel, a command and not a force without a vehicle
    file's thrusters. ``slow``: the channels logged slower than the clock
    (:func:`nnid.datasets.gaps.slow_channels`; ``filled`` where the fits fill it with the gyro),
    whose empty cells between their samples are not in ``missing``, nor the rows outside their
    sampled span (``ends``, :func:`nnid.datasets.gaps.span_ends`). A run whose stamps come in
    bursts (``bursts``: :func:`nnid.datasets.log.burst_clock`'s sentence, else None) has its
    rate over the run (:func:`nnid.datasets.preprocess.logged_rate`) and no gaps counted
    (``gap_s`` None): its steps are a burst's and the next burst's, no sample interval, so
    its ``duration_s`` is its whole span, no gap taken out. Each run's ``rate_hz`` is its
    logged rate, the rate lowpass and resample design at (a clock rounded coarsely,
    :func:`nnid.datasets.log.rounded_clock`: 120 Hz stamped in whole ms, not the 125 Hz of
    its median 8-ms step), and the log's is that of most of its runs' intervals, each
    one-sample step of a rounded clock read at its run's step."""
    inputs = input_columns(log)
    known = {"t", "experiment", PIECE_OF, REPLAY_GROUP, *POSE, *VELOCITY, *ACCELERATION, *inputs}
    groups = experiment_rows(log)
    exp_rows, gaps, intervals = [], [], []
    before: tuple[str | None, float] = (None, float("nan"))  # the last piece's run and end
    t_all = log["t"].to_numpy(np.float64)
    for name, pos in groups:
        t = t_all[pos]
        dt = np.diff(t)
        rate, burst = logged_rate(t, np.nan)
        med, rounding = clock_step(t) if dt.size else (float("nan"), 0.0)
        if rounding:
            # a rounded clock's steps within its rounding of its step are one sample each
            # (8 and 9 ms at 120 Hz): read at its step, as its rate is
            dt = np.where(np.abs(dt - med) <= rounding, med, dt)
        if burst:
            # the median step is one inside a burst (an IMU's ten samples every 10 ms read as
            # 100 kHz, and every burst's end as a gap): the run's rate is its rate over the
            # run, and its steps tell no gap from the next burst
            med = 1.0 / rate
            dt = np.full(dt.size, med)
        intervals.append(dt)
        # a piece cut from a run at a gap (the readers' ``<run>#<k>``) is not an experiment of
        # its own: told by PIECE_OF, never by its label (nnid.datasets.log)
        whole = log[PIECE_OF].iloc[pos[0]] if PIECE_OF in log and len(pos) else None
        whole = str(whole) if pd.notna(whole) and str(whole) else None
        label = None if name is None else str(name)
        held = []
        for k in np.flatnonzero(dt > 1.5 * med):
            held.append({"experiment": label, "t": float(t[k]), "length_s": float(dt[k]),
                         "missing_s": float(dt[k] - med)})  # fmt: skip
        if whole is not None and whole == before[0] and t.size and t[0] > before[1]:
            # the hole a reader or resample cut a run at: pieces keep the run's clock
            # (outside either piece's span: in the log's gaps, not in a piece's gap_s)
            hole = float(t[0] - before[1])
            gaps.append({"experiment": whole, "t": before[1], "length_s": hole,
                         "missing_s": hole - med})  # fmt: skip
        before = (whole, float(t[-1]) if t.size else float("nan"))
        gaps += held
        span = float(t[-1] - t[0]) if t.size else 0.0
        held_s = float(sum(g["missing_s"] for g in held))
        exp_rows.append({"name": label, "samples": int(t.size), "duration_s": span - held_s,
                         "gap_s": None if burst else held_s,
                         "rate_hz": rate, "piece_of": whole,
                         "bursts": burst})  # fmt: skip
    pose = [c for c in POSE if c in log]
    made = derivable_velocities(pose)
    derivable = [c for c in ("p", "q", "r", "u", "v") if c in made and c not in log]
    if "w" in made and "w" not in log:  # pose-derived w is exact only with x and y
        derivable.append("w" if "x" in log else "w (approximate, from depth rate)")
    derivable += [f"d{c}" for c in VELOCITY if c in log and f"d{c}" not in log]
    moving, from_pose = velocities_from_pose(log, savgol_window, savgol_order)
    excitation = {}
    for dof in VELOCITY:
        entry = {}
        if dof in moving:
            entry["velocity_std"] = float(moving[dof].std())
            if dof in from_pose.get("columns", []):
                entry["velocity_from_pose"] = True
        force = DOF_FORCE[dof]
        if force in log:
            moves = activity(log[force])
            entry["force_std"], entry["force_active_share"] = moves["std"], moves["active_share"]
        if entry:
            excitation[dof] = entry
    slow = slow_channels(log)
    filled = gyro_filled(log, slow)
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
        # the time sampled: a 10-s hole in a run was counted as 10 s of data
        "duration_s": float(sum(e["duration_s"] for e in exp_rows)),
        # not measured where no run's steps tell a gap (every run in bursts, no hole between
        # a run's pieces)
        "gap_s": None
        if not gaps and all(e["bursts"] for e in exp_rows)
        else float(sum(g["missing_s"] for g in gaps)),
        "runs": len({e["piece_of"] or e["name"] for e in exp_rows}),
        "experiments": exp_rows,
        "gaps": gaps,
        # a channel logged slower than the clock: its rate, not gaps, and the rows before its
        # first sample or after its last in a run are outside its span (``ends``); what it
        # leaves empty beyond its own steps inside its span (a longer hole) is
        "slow": [asdict(ch) | {"filled": ch in filled, "ends": span_ends(log, ch)} for ch in slow],
        "missing": gaps_record(find_gaps(between_samples(log, slow))),
        "derivable": derivable,
        "velocity_from_pose": from_pose,
        "excitation": excitation,
        "excited": excited_dofs(moving, list(VELOCITY)),
        "commands": {c: activity(log[c]) for c in inputs if c.startswith("cmd_")},
    }
