"""Missing motion samples: a DVL that drops out in bursts while the pose and gyro go on.

An empty cell in a pose or velocity column is a gap, never a number. Gaps are handled in two
ways, each written to the cleaning report with counts, seconds and the longest gap (the
seconds missing: the missing samples times the sample interval, so 400 lone samples missing
at 20 Hz are 20 s, not the 40 s spanned between their present neighbours):

- **bridged** from the pose, as the log contract derives velocities (Savitzky-Golay rates and
  ν = J⁻¹(η) η̇, Weiss eq. 17): p q r wherever the attitude is complete, u v w wherever the
  whole pose is, for gaps up to ``max_bridge_s``;
- **masked** otherwise: the rows are taken out of regressions and scores and the run is cut
  into segments at them (``<experiment>#<k>``), each simulated from its own measured start, so
  a free run never integrates across time nobody measured.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.log import ACCELERATION, ANGLES, PIECE_OF, POSE, VELOCITY
from nnid.datasets.preprocess import derive_velocities, experiments, true_runs

#: a segment left between two gaps shorter than this many samples is masked with them
MIN_SEGMENT = 3
#: the cleaning steps that say what became of the gaps (bridged from the pose, or masked)
BRIDGE_STEP, MASK_STEP = "bridge velocity gaps", "mask gaps"
GAP_STEPS = (BRIDGE_STEP, MASK_STEP)


@dataclass
class Gap:
    """One run of consecutive rows with a missing cell in ``columns``."""

    experiment: str | None
    t: float  # time of the first missing sample, s
    length_s: float  # spanned: from the last sample before to the first sample after
    rows: int
    columns: list[str]
    missing_s: float  # missing: rows × the experiment's median sample interval


def _gap_runs(part: pd.DataFrame, columns: list[str]):
    """(Gap, first row, stop row) of each gap of one experiment, rows by position."""
    missing = part[columns].isna().to_numpy()
    t = part["t"].to_numpy(np.float64)
    name = part["experiment"].iloc[0] if "experiment" in part else None
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    for a, b in true_runs(missing.any(axis=1)):
        t0 = t[a - 1] if a > 0 else t[a]
        t1 = t[b] if b < t.size else t[b - 1]
        cols = [c for c, m in zip(columns, missing[a:b].any(axis=0), strict=True) if m]
        gap = Gap(
            None if name is None else str(name),
            float(t[a]),
            float(t1 - t0),
            int(b - a),
            cols,
            float((b - a) * dt),
        )
        yield gap, a, b


def find_gaps(log: pd.DataFrame, columns: list[str] | None = None) -> list[Gap]:
    """The gaps (runs of rows with an empty cell in ``columns``; default: pose and velocity)
    of each experiment."""
    columns = [c for c in (columns or [*POSE, *VELOCITY]) if c in log]
    if not columns:
        return []
    return [g for _, idx in experiments(log) for g, _, _ in _gap_runs(log.loc[idx], columns)]


def _summary(gaps: list[Gap]) -> str:
    seconds = sum(g.missing_s for g in gaps)
    longest = max((g.missing_s for g in gaps), default=0.0)
    order = [*POSE, *VELOCITY, *ACCELERATION]
    cols = sorted(
        {c for g in gaps for c in g.columns},
        key=lambda c: (c not in order, order.index(c) if c in order else c),
    )
    return (
        f"{len(gaps)} gaps in {', '.join(cols)} ({sum(g.rows for g in gaps)} samples, "
        f"{seconds:.3g} s missing in total, longest {longest:.3g} s)"
    )


def bridge_from_pose(
    log: pd.DataFrame,
    window_s: float = 0.5,
    order: int = 4,
    max_bridge_s: float = 2.0,
    report: CleaningReport | None = None,
) -> pd.DataFrame:
    """Fill empty velocity cells from the pose where it allows (module docstring): p q r from a
    complete attitude, u v w from a complete pose, in gaps up to ``max_bridge_s``."""
    velocity = [c for c in VELOCITY if c in log]
    if not velocity or not log[velocity].isna().any().any() or not all(a in log for a in ANGLES):
        return log
    out = log.copy()
    bridged: list[Gap] = []
    for _, idx in experiments(log):
        part = log.loc[idx]
        pose = [c for c in POSE if c in part]
        complete = [c for c in pose if part[c].notna().all()]
        if not all(a in complete for a in ANGLES):
            continue
        # derive_velocities sees no velocity column, so it makes each one the pose gives; w
        # from depth alone assumes u = v = 0, an approximation a bridge must not use
        derived = derive_velocities(part[["t", *complete]], window_s, order)
        can = [c for c in ("p", "q", "r") if c in velocity]
        if all(c in complete for c in ("x", "y", "z")):
            can += [c for c in ("u", "v", "w") if c in velocity]
        for gap, a, b in _gap_runs(part, velocity):
            cols = [c for c in gap.columns if c in can]
            if gap.length_s > max_bridge_s or not cols:
                continue
            rows = part.index[a:b]
            for c in cols:
                out.loc[rows, c] = out.loc[rows, c].fillna(derived.loc[rows, c])
            bridged.append(replace(gap, columns=cols))
    if report is not None and bridged:
        report.add(
            BRIDGE_STEP,
            f"{_summary(bridged)} bridged from the pose by Savitzky-Golay "
            f"(order {order}, {window_s:g} s window) and J⁻¹(η)",
            columns=sorted({c for g in bridged for c in g.columns}, key=VELOCITY.index),
        )
    return out


def mask_gaps(
    parts: list[pd.DataFrame], columns: list[str], report: CleaningReport | None = None
) -> list[pd.DataFrame]:
    """Take the rows with an empty cell in ``columns`` out of each part of one log (e.g. its
    training and held-out parts) and cut each run at them into segments ``<experiment>#<k>``
    (module docstring; k from 0, as :func:`nnid.datasets.preprocess.resample_log` and the
    readers count, each segment keeping the run's clock ``t``), reported once; a segment's
    ``piece_of`` column names its run, which is how a piece is told from a whole run (never
    by the ``#`` in its label, which a user's may hold too). Parts without gaps are returned
    as they are."""
    out, gaps, short = [], [], 0
    for log in parts:
        cols = [c for c in columns if c in log]
        missing = log[cols].isna().any(axis=1).to_numpy() if cols else np.zeros(len(log), bool)
        if not missing.any():
            out.append(log)
            continue
        gaps += find_gaps(log, cols)
        keep = ~missing
        label = np.empty(len(log), dtype=object)
        piece_of = np.full(len(log), None, dtype=object)  # a reader's piece stays one
        if PIECE_OF in log:
            piece_of[:] = log[PIECE_OF].to_numpy(object)
        for name, idx in experiments(log):
            pos = np.flatnonzero(log.index.isin(idx))
            runs = true_runs(keep[pos])
            for k, (a, b) in enumerate(runs):  # from #0, as resample_log and the readers
                if b - a < MIN_SEGMENT:
                    keep[pos[a:b]] = False
                    short += b - a
                base = "run" if name is None else str(name)
                label[pos[a:b]] = base if len(runs) == 1 else f"{base}#{k}"
                if len(runs) > 1:
                    piece_of[pos[a:b]] = [base if pd.isna(p) else p for p in piece_of[pos[a:b]]]
        out.append(
            log.assign(experiment=label, **{PIECE_OF: piece_of})[keep].reset_index(drop=True)
        )
    if report is not None and gaps:
        extra = f"; {short} samples between gaps too short to use" if short else ""
        report.add(
            MASK_STEP,
            f"{_summary(gaps)} masked (out of regressions and scores; runs cut into segments "
            f"at them, each simulated from its own start{extra})",
            rows_removed=sum(len(a) - len(b) for a, b in zip(parts, out, strict=True)),
            columns=sorted({c for g in gaps for c in g.columns}),
        )
    return out


def gaps_record(gaps: list[Gap]) -> dict:
    """JSON-ready: counts, seconds missing (samples × sample interval), the longest gap's and
    each gap (``length_s`` the time spanned between the present samples around it, one sample
    interval more than ``missing_s`` inside a run)."""
    return {
        "count": len(gaps),
        "samples": int(sum(g.rows for g in gaps)),
        "seconds": float(sum(g.missing_s for g in gaps)),
        "longest_s": float(max((g.missing_s for g in gaps), default=0.0)),
        "gaps": [asdict(g) for g in gaps],
    }
