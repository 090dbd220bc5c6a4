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

A channel logged slower than the others on one clock (a 1-Hz depth beside a 10-Hz DVL, a
10-Hz attitude beside a 100-Hz gyro) has empty cells between its samples that are its rate,
not dropouts (:func:`slow_channels`). A slow roll, pitch or yaw beside a complete gyro is
**filled** between its own samples with what p q r turn it through (:func:`fill_slow`): the
fits read the attitude on every row (the restoring forces g(η), the kinematics J(η)), and the
gyro measures how it moves between samples. Nothing else is: a velocity or an acceleration is
the fits' response and is differentiated into accelerations, and a position or an attitude
without a gyro is differentiated into velocities, so samples made between their own by a
straight line would be fitted as measured (standard errors as if from k times the data) and
change the noise of a Savitzky-Golay derivative; they are bridged from the pose or masked, as
a gap is, and the report says why.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.log import (
    ACCELERATION,
    ANGLES,
    PIECE_OF,
    POSE,
    VELOCITY,
    _experiment_sorted,
    _filled,
    euler_rate_matrices,
    turned_by,
    wrap_angle,
)
from nnid.datasets.preprocess import derive_velocities, experiments, true_runs

#: a segment left between two gaps shorter than this many samples is masked with them
MIN_SEGMENT = 3
#: the cleaning steps that say what became of the gaps (bridged from the pose, or masked)
BRIDGE_STEP, MASK_STEP = "bridge velocity gaps", "mask gaps"
GAP_STEPS = (BRIDGE_STEP, MASK_STEP)
#: a channel is logged slower than the clock when at least this share of the steps between
#: its samples is one stride of two rows or more (a sample landing a row early or late on a
#: merged clock is the rest)
SLOW_SHARE = 0.9
#: the fewest steps between a channel's samples that show it slow, not a few lone samples
SLOW_MIN_STEPS = 10
#: the most of a slow channel's own steps one interpolation spans: a longer hole is a gap
SLOW_SPAN = 3
#: the cleaning step that says which channels were slow and what became of them
SLOW_STEP = "slow channels"
#: the body rates that turn the attitude between a slow channel's samples
GYRO = ("p", "q", "r")


@dataclass
class SlowChannel:
    """A channel logged every ``stride`` rows of the log's clock (module docstring)."""

    column: str
    stride: int  # rows between its samples, most of the time
    rate_hz: float  # its own rate: the clock's over the stride
    clock_hz: float  # the log's: 1 / its median sample interval within runs

    def describe(self) -> str:
        """'z logged every 10th row: 2 Hz against 20 Hz'."""
        k = self.stride
        suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
        return (
            f"{self.column} logged every {k}{suffix} row: {self.rate_hz:.3g} Hz against "
            f"{self.clock_hz:.3g} Hz"
        )


def slow_channels(log: pd.DataFrame, columns: list[str] | None = None) -> list[SlowChannel]:
    """The channels of ``columns`` (default: pose, velocity, acceleration) logged slower than
    the clock: at least :data:`SLOW_SHARE` of the steps between a channel's samples within a
    run are one stride of two rows or more, over at least :data:`SLOW_MIN_STEPS` steps. A
    channel without an empty cell, or with scattered dropouts (its usual step one row), is
    not slow."""
    columns = [c for c in (columns or [*POSE, *VELOCITY, *ACCELERATION]) if c in log]
    if not columns or not log[columns].isna().to_numpy().any():
        return []
    codes, _, order, _, dt, _ = _experiment_sorted(log)
    inside = codes[1:] == codes[:-1]
    clock = float(np.median(dt[inside])) if inside.any() else float("nan")
    out = []
    for c in columns:
        present = log[c].notna().to_numpy()[order]
        if present.all():
            continue
        rows = np.flatnonzero(present)
        steps = np.diff(rows)[codes[rows[1:]] == codes[rows[:-1]]]
        if steps.size < SLOW_MIN_STEPS:
            continue
        values, counts = np.unique(steps, return_counts=True)
        stride = int(values[np.argmax(counts)])
        if stride >= 2 and counts.max() >= SLOW_SHARE * steps.size and clock > 0:
            out.append(SlowChannel(c, stride, 1.0 / (stride * clock), 1.0 / clock))
    return out


def fill_slow(log: pd.DataFrame, report: CleaningReport | None = None) -> pd.DataFrame:
    """``log`` with the empty cells of each slow roll, pitch or yaw (:func:`slow_channels`)
    beside a complete gyro filled between two of its samples within each experiment with what
    p q r turn it through, η̇ = T_Θ(η) ω (Weiss eq. 16), and what the gyro leaves unexplained
    spread linearly in ``t`` so that each sample is met (:func:`_between_samples`). A straight
    line alone would miss the angle's curvature, the rate's derivative, and put the restoring
    forces' error into the added mass (K_pdot 5 s.e. off on a 5th-row attitude). Every slow
    channel is said in ``report``, those not filled with why (module docstring). ``log``
    itself where no channel is slow."""
    slow = slow_channels(log)
    if not slow:
        return log
    filling = gyro_filled(log, slow)
    turning, blocked = {}, None
    if filling:
        codes, _, order, t, _, _ = _experiment_sorted(log)
        line = [_filled(log[a].to_numpy(np.float64)[order], t, codes, True) for a in ANGLES]
        gyro = log[list(GYRO)].to_numpy(np.float64)[order]
        rates = np.einsum("nij,nj->ni", euler_rate_matrices(np.column_stack(line)), gyro)
        turning = {a: turned_by(t, rates[:, k]) for k, a in enumerate(ANGLES)}
        blocked = ~np.isfinite(gyro).all(1)  # where the turn between two samples is unknown
    out, said = _between_samples(log, filling, turning, blocked)
    kept = [ch.describe() for ch in slow if ch not in filling]
    if report is not None:
        detail = []
        if said:
            detail.append(
                f"{'; '.join(said)}: with the gyro, within each run, what p q r turn it "
                "through between its samples (η̇ = T(η) ω) and the rest linearly in t, never "
                f"across a hole longer than {SLOW_SPAN} of its own steps"
            )
        if kept:
            detail.append(
                f"{'; '.join(kept)}: not filled (it is differentiated, or is the fits' "
                "response: samples made between its own would be fitted as measured); "
                "bridged from the pose or masked where used"
            )
        report.add(SLOW_STEP, "; ".join(detail), columns=[ch.column for ch in slow])
    return out


def gyro_filled(log: pd.DataFrame, slow: list[SlowChannel]) -> list[SlowChannel]:
    """The channels of ``slow`` that :func:`fill_slow` fills: roll, pitch and yaw, where the
    log holds all three and a gyro (p q r; its own empty cells leave the spans they fall in
    unfilled)."""
    held = all(c in log for c in (*ANGLES, *GYRO))
    return [ch for ch in slow if held and ch.column in ANGLES]


def between_samples(log: pd.DataFrame, slow: list[SlowChannel] | None = None) -> pd.DataFrame:
    """``log`` with every slow channel's cells (``slow``, else :func:`slow_channels`) between
    its own samples filled linearly: the cells its rate leaves empty, not gaps (what
    ``inspect`` counts as missing is the rest)."""
    return _between_samples(log, slow_channels(log) if slow is None else slow, {})[0]


def _between_samples(
    log: pd.DataFrame,
    slow: list[SlowChannel],
    turning: dict[str, np.ndarray],
    blocked: np.ndarray | None = None,
) -> tuple[pd.DataFrame, list[str]]:
    """``log`` with the empty cells of each channel of ``slow`` between two of its samples
    within an experiment filled in ``t``: what ``turning`` (an angle's turn from the first row,
    in :func:`nnid.datasets.log._experiment_sorted` order) gives, and the rest linearly, so
    each sample is met (an angle along the shorter turn, wrapped back to the log's range,
    ±π or [0, 2π)); never across a hole longer than :data:`SLOW_SPAN` of its own steps, nor
    across a row of ``blocked`` (the same order: where the turning is not known), nor before
    its first sample or after its last: those stay gaps, bridged or masked as any. With what
    was done to each channel, said."""
    if not slow:
        return log, []
    out = log.copy()
    codes, _, order, t, _, _ = _experiment_sorted(log)
    said = []
    for ch in slow:
        y = log[ch.column].to_numpy(np.float64)[order]
        angle = ch.column in ANGLES
        turned = turning.get(ch.column, np.zeros_like(y))
        new = _filled(y - turned, t, codes, angle, max_rows=SLOW_SPAN * ch.stride) + turned
        if angle:  # wrapped back to the range the log keeps
            lo, hi = np.nanmin(y), np.nanmax(y)
            if -np.pi <= lo and hi <= np.pi:
                new = wrap_angle(new)
            elif 0.0 <= lo and hi <= 2 * np.pi:
                new = np.mod(new, 2 * np.pi)
        new = np.where(np.isfinite(y), y, new)
        if blocked is not None and blocked.any():
            new = _unblocked(new, y, codes, blocked)
        values = np.empty_like(new)
        values[order] = new
        out[ch.column] = values
        left = int((~np.isfinite(new)).sum())
        ends = (
            f", {left} at a run's ends, in longer holes"
            + " or where the gyro has empty cells" * bool(blocked is not None and blocked.any())
            + " left as gaps"
        ) * bool(left)
        filled = int(np.isfinite(new).sum() - np.isfinite(y).sum())
        said.append(f"{ch.describe()} ({filled} samples between its own filled{ends})")
    return out, said


def _unblocked(
    new: np.ndarray, y: np.ndarray, codes: np.ndarray, blocked: np.ndarray
) -> np.ndarray:
    """``new`` (``y`` filled between its samples) with each span between two samples of ``y``
    in one experiment that holds a ``blocked`` row empty again."""
    rows = np.flatnonzero(np.isfinite(y))
    a, b = rows[:-1], rows[1:]
    count = np.concatenate([[0], np.cumsum(blocked)])
    spans = (codes[a] == codes[b]) & (b - a > 1) & (count[b + 1] - count[a] > 0)
    out = new.copy()
    for i, j in zip(a[spans], b[spans], strict=True):
        out[i + 1 : j] = np.nan
    return out


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
        f"{len(gaps)} gap{'s' * (len(gaps) != 1)} in {', '.join(cols)} "
        f"({sum(g.rows for g in gaps)} samples, "
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
