"""Preprocessing of measured logs, with every change in the cleaning report.

- resampling onto a uniform time base, splitting experiments at gaps instead of bridging them;
- angle unwrapping;
- Savitzky-Golay differentiation (Caccia III-B and IV-D used fourth order, symmetric windows),
  with the noise gain the filter theory predicts; scipy's ``savgol_filter`` (interp mode)
  re-done in :func:`savgol_interp` for speed alone, bit for bit that of scipy ≥ 1.17 (the
  floor pyproject sets: an older scipy's edge fit is not checked): its dispatch cost ten times
  the arithmetic of a short window, which ``detect --follow`` pays six times a flush;
- body velocities from pose rates through ν = J⁻¹(η) η̇ (McCarter eq. 2.15);
- zero-phase Butterworth low-pass filtering (Weiss V.A.2);
- jump (occlusion) detection for motion capture (Weiss V.A.2);
- accelerometer and gyro bias estimation (McCarter eqs 2.84-2.87);
- derived accelerations ν̇ where a trainer needs them.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from functools import lru_cache
from itertools import pairwise
from typing import Literal

import numpy as np
import pandas as pd
from pydantic import BaseModel, ConfigDict, Field
from scipy.integrate import cumulative_trapezoid
from scipy.linalg import lstsq
from scipy.ndimage import convolve1d
from scipy.signal import butter, filtfilt, lfilter, savgol_coeffs
from scipy.stats import median_abs_deviation

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.log import (
    ACCELERATION,
    ANGLES,
    MAX_RUN_SAMPLES,
    MOTION,
    PIECE_OF,
    POSE,
    REPLAY_GROUP,
    TIME_UNIT_ATTR,
    TIME_UNITS,
    VELOCITY,
    burst_clock,
    clock_step,
    euler_rate_matrices,
    frame_step,
    input_columns,
    paced_step,
    refuse_rows,
    run_label,
    run_of,
    typical_step,
    wrap_angle,
)
from nnid.datasets.mapping import rotation_from_euler
from nnid.errors import ExcitationWarning, NnidInputError
from nnid.validation import shown


def experiment_rows(log: pd.DataFrame) -> list[tuple[object, np.ndarray]]:
    """(name, positions) of each experiment, in order of appearance (a log without an
    experiment column: one run named None), by row position (ascending), from one grouping
    pass: a run's index labels may repeat another's (``pd.concat`` without ``ignore_index``),
    and finding them in the whole log costs rows × runs: seconds on a log a reader cut into
    thousands of pieces."""
    if "experiment" not in log:
        return [(None, np.arange(len(log)))]
    return list(log.groupby("experiment", sort=False).indices.items())


def run_rows(log: pd.DataFrame) -> list[tuple[object, np.ndarray]]:
    """(run, positions) of each run of ``log`` as logged: :func:`experiment_rows`, the pieces
    a gap cut a run into (:func:`~nnid.datasets.log.run_of`) joined under that run's name, in
    order of first appearance. What is said of "runs" (each held-out run's own score) is of
    these: a run's pieces counted as runs made one gappy run several."""
    runs = run_of(log)
    joined: dict[object, list[np.ndarray]] = {}
    for name, pos in experiment_rows(log):
        joined.setdefault(runs.get(name, name), []).append(pos)
    return [(r, np.sort(np.concatenate(p))) for r, p in joined.items()]


def run_spans(log: pd.DataFrame) -> list[float]:
    """Each experiment's time span (s: its last sample's t less its first's, the runs of
    :func:`experiment_rows` in order)."""
    t = log["t"].to_numpy(np.float64)
    return [float(np.ptp(t[pos])) for _, pos in experiment_rows(log)]


# --- time base -------------------------------------------------------------------------------


#: how far one sampling interval may differ from the run's typical interval and still be one
#: sample (beyond a coarsely rounded clock's rounding, :func:`~nnid.datasets.log.rounded_clock`):
#: jitter, and stamps rounded to the millisecond that step 0.033 and 0.034 s at 30 Hz
UNIFORM_TOLERANCE = 0.1

#: how far one run's typical step may differ from another's (:func:`check_uniform`'s
#: ``one_rate``), relative, beyond what each clock's rounding leaves unread. Not
#: :data:`UNIFORM_TOLERANCE`, a single interval's jitter: a run's typical step is read over
#: all its steps (:func:`~nnid.datasets.log.clock_step`), a float clock's median to its float
#: error, a coarsely rounded clock's least-squares rate to within its rounding q over the run
#: (its stamps lie within q/2 of that rate's line: q/n over n steps, allowed on top), so a
#: 19-Hz run beside a 20-Hz one (5 %) is another rate, refused, where 10 % passed both and
#: trained them at one dt. 1 % leaves room for a median pulled by jitter or by a rare step
#: of a rounded clock (under 5 % of q: 0.5 % of a 10-ms step in milliseconds); the runs of
#: every bundled, shipped and benchmark log agree to 3e-5 (emps' two files)
RATE_TOLERANCE = 0.01


def off_steps(
    t: np.ndarray, tolerance: float = UNIFORM_TOLERANCE, within: np.ndarray | None = None
) -> tuple[float, np.ndarray, float]:
    """A run's typical sampling interval (``t``: its times, two or more;
    :func:`~nnid.datasets.log.clock_step`), where an interval differs from it by more than
    ``tolerance`` of it plus the clock's rounding (samples missing, a rate that changes,
    jitter beyond a clock's rounding), and that rounding (0 for a clock not rounded
    coarsely): :func:`check_uniform`'s rule. 120 Hz stamped in milliseconds steps 8 and 9 ms
    around 8.33 ms, each one sample; the median rule took the 9-ms steps for missing ones.
    ``within``: which steps are intervals (at least one), for a run whose rows resume after
    another's; its joins are neither read nor returned."""
    steps = np.diff(t)
    typical, rounding = clock_step(t, within)
    off = np.abs(steps - typical) > rounding + tolerance * typical
    if within is not None:
        off &= within
    return typical, np.flatnonzero(off), rounding


def uneven_runs(log: pd.DataFrame, method: str) -> None:
    """Warn, once for ``log``, of its runs whose intervals are not one interval
    (:func:`off_steps`), naming each and the spread of its steps: ``method`` (what reads the
    samples, as said to the user) takes them as evenly spaced at the typical step, so where
    a step is longer (a dropped sample) or shorter it acts over another span of time. Not
    refused: a few dropped samples move a filter or a derivative there only."""
    t_all = log["t"].to_numpy(np.float64)
    said = []
    for name, pos in experiment_rows(log):
        t = t_all[pos]
        if t.size < 2:
            continue
        typical, off, rounding = off_steps(t)
        if off.size:
            steps = np.diff(t)
            said.append(
                f"{run_label(name)} is not evenly sampled ({off.size} of its {steps.size} "
                f"steps more than {UNIFORM_TOLERANCE:.0%}{_beyond(rounding)} off its "
                f"{'step' if rounding else 'median'} {typical:.4g} s, "
                f"from {steps.min():.4g} to {steps.max():.4g} s)"
            )
    if said:
        more = f", nor are {len(said) - 1} other runs" if len(said) > 1 else ""
        warnings.warn(
            f"{said[0]}{more}: {method} takes the samples as evenly spaced at the typical "
            "step, so where a step differs it acts over another span of time; resample the "
            "log onto a uniform grid first (resample_log)",
            stacklevel=3,
        )


def _beyond(rounding: float) -> str:
    """The words for a clock's rounding in a message about steps off the typical one."""
    return f" (beyond the clock's rounding of {rounding:.4g} s)" if rounding else ""


def check_uniform(
    log: pd.DataFrame,
    what: str,
    name: str = "log",
    interval: float | None = None,
    one_rate: bool = False,
    tolerance: float = UNIFORM_TOLERANCE,
) -> float | None:
    """Raise unless every experiment of ``log`` is uniformly sampled (each interval within
    :data:`UNIFORM_TOLERANCE` of the run's typical interval, beyond a coarsely rounded clock's
    rounding: :func:`off_steps`; a longer one has samples missing, a rate that changes within
    the run leaves the typical one), naming the first row that is not (by its
    index label: the file's row for a log as read, whatever runs were left out): models that
    count time in samples (``what``) need it. With ``one_rate`` every experiment is sampled
    at one rate, its typical step within :data:`RATE_TOLERANCE` (beyond the clocks' rounding
    over the runs) of ``interval`` where it is given (the rate a model was trained at), else
    of the first run's. A model that steps in physical time passes a wider ``tolerance``: an
    interval 1 + ``tolerance`` times the median has samples missing. Returns that interval
    (the first run's without ``one_rate``; None where no run has two samples)."""
    given = interval is not None
    first = ""  # the run that set the interval, in a message
    unread = 0.0  # what the interval's run's clock rounding leaves unread of its step (s)
    t_all = log["t"].to_numpy(np.float64)
    for exp, pos in experiment_rows(log):
        t = t_all[pos]
        if t.size < 2:
            continue
        dt = np.diff(t)
        typical, off, rounding = off_steps(t, tolerance)
        where = f" (experiment {exp})" if exp is not None else ""
        # a rounded clock's least-squares step is read to its rounding over the run's steps
        slack = rounding / dt.size
        if (
            one_rate
            and interval is not None
            and abs(typical - interval) > RATE_TOLERANCE * interval + slack + unread
        ):
            raise NnidInputError(
                f"the {name}{where} is sampled every {typical:.4g} s, against "
                f"{interval:.4g} s {'at training' if given else f'in its first run{first}'}, "
                f"{abs(typical / interval - 1):.1%} apart (one rate: within "
                f"{RATE_TOLERANCE:.0%}), and {what} counts time in samples; resample the log "
                "to one rate",
                field="t",
            )
        if interval is None:
            interval, first, unread = typical, where, slack
        if off.size:
            k = int(off[0])
            label = log.index[pos[k + 1]]  # the row named by its label, as the file's row
            raise NnidInputError(
                f"column t of the {name}{where} is not uniformly sampled: {dt[k]:.4g} s from "
                f"t = {t[k]:.6g} to {t[k + 1]:.6g} s against {typical:.4g} s elsewhere"
                f"{_beyond(rounding)}, and {what} counts time in samples; resample the log, "
                "or split the run where samples are missing",
                field="t",
                row=int(label) if isinstance(label, (int, np.integer)) else None,
            )
    return interval


def resample_log(
    log: pd.DataFrame, rate: float, gap: float | None = None, report: CleaningReport | None = None
) -> pd.DataFrame:
    """Every experiment onto a uniform grid at ``rate`` Hz: inputs by zero-order hold, the rest
    by linear interpolation (angles through their unwrapped values, :func:`unwrap_finite`, and
    wrapped back to ±π where the log had them so); gaps longer
    than ``gap`` s split the experiment, each piece labelled ``<experiment>#<k>`` (``run#<k>``
    for a log without an experiment column; k from 0, as :func:`nnid.datasets.gaps.mask_gaps`
    and the readers count) and marked ``piece_of`` its run. Each run's clock starts at 0 at
    its first sample (a first piece too short to keep leaves the next one starting later), and
    its pieces keep that clock, so the hole between two pieces is seen in ``t``. Without
    ``gap``, a run's longest hole over :data:`SILENCE` typical steps is interpolated over and
    said (a warning, and the report), as the readers say it. A column that is
    not a number (a mode, a fault label), holds integers (a mode or fault code; not a motion
    column) or holds true/false is kept by its previous value,
    as an input is: a label is never blended, and no column is left out."""
    held = set(input_columns(log))
    numeric = [
        c
        for c in log.columns
        if c not in ("t", "experiment")
        and pd.api.types.is_numeric_dtype(log[c])
        and not pd.api.types.is_bool_dtype(log[c])
    ]
    # an integer column of the log's own (a mode, a fault code) is a label too: 0 next to 2
    # was interpolated to 1.0, a code never logged; held as an input is, its type kept
    coded = {
        c
        for c in numeric
        if pd.api.types.is_integer_dtype(log[c]) and c not in held and c not in MOTION
    }
    # a run's labels the grid keeps: a piece stays one (short_piece), a replay in its group
    labels = [c for c in (PIECE_OF, REPLAY_GROUP) if c in log and c not in numeric]
    # any other column that is not a number: a mode, a fault label, a flag (once dropped)
    categorical = [c for c in log.columns if c not in ("t", "experiment", *numeric, *labels)]
    pieces, rates = [], []
    dropped_total = 0
    # a t declared in a finer unit was a number of those before it was seconds (ns since the
    # epoch are rounded to 256 ns): the samples are snapped to that rounding too
    _, per_second = TIME_UNITS.get(log.attrs.get(TIME_UNIT_ATTR), ("seconds", 1.0))
    for name, pos in experiment_rows(log):
        part = log.iloc[pos]
        t = part["t"].to_numpy(np.float64)
        logged, burst = logged_rate(t, rate)
        rates.append(logged)
        cuts = np.flatnonzero(np.diff(t) > gap) + 1 if gap else np.array([], int)
        bounds = np.split(np.arange(t.size), cuts)
        # a sample alone between gaps (or a run of one) spans no interval to put a grid on
        alone = sum(seg.size for seg in bounds if seg.size < 2)
        dropped_total += alone
        for k, seg in enumerate(bounds):
            if seg.size < 2:
                continue
            ts = t[seg]
            # the end, and a grid time on a sample, to the clock's rounding: on an epoch clock
            # (~1.7e9 s, units of 2.4e-7 s) 1e-9 samples of slack lost a last sample on the
            # grid, and a held input took the sample before one it fell a unit short of
            tolerance = clock_tolerance(ts, ts[0], rate, per_second)
            grid = ts[0] + run_grid(ts[-1] - ts[0], rate, tolerance)
            on = snap_to_samples(grid, ts, tolerance)
            # the run's clock from its first sample: a later piece starts where it was
            # measured (as mask_gaps's pieces do), so the hole before it stays in the log
            out = {"t": grid - grid[0] + (ts[0] - t[0])}
            previous = np.clip(np.searchsorted(ts, grid, "right") - 1, 0, None)
            for col in numeric:
                y = part[col].to_numpy(np.float64)[seg]
                if col in held:
                    out[col] = y[previous]
                elif col in coded:
                    out[col] = part[col].to_numpy()[seg][previous]
                elif col in ANGLES:  # a step across ±π was interpolated through zero
                    a = np.interp(grid, ts, unwrap_finite(y))
                    # back to ±π where the log had it so (the unwrap step is the config's);
                    # a sample on the grid as logged, not unwrapped and wrapped back (2πk
                    # added and taken away moves its last bits)
                    if np.nanmax(np.abs(y)) <= np.pi:
                        a = wrap_angle(a)
                        a[on] = y[previous[on]]
                    out[col] = a
                else:
                    out[col] = np.interp(grid, ts, y)
            for col in categorical:
                out[col] = part[col].to_numpy()[seg][previous]
            frame = pd.DataFrame(out).astype({c: log[c].dtype for c in categorical})
            base = "run" if name is None else name  # the piece's piece_of below
            label = name if len(bounds) == 1 else f"{base}#{k}"
            if name is not None or len(bounds) > 1:
                frame.insert(1, "experiment", label)
            for col in labels:
                if pd.notna(part[col].iloc[0]):
                    frame[col] = part[col].iloc[0]
            if len(bounds) > 1 and PIECE_OF not in frame:  # told by it, never by its label
                frame[PIECE_OF] = str(base)
            pieces.append(frame)
        # the typical step as the readers take it: the run's (its pace, for stamps in
        # bursts) or the grid's, whichever is longer
        hole = None if gap else longest_silence(t, max(1.0 / logged, 1.0 / rate))
        if hole is not None:  # without gap the hole is bridged: said, as the readers say it
            said = silence_said(run_label(name), t, *hole)
            if report is not None:
                report.add("interpolated over a silence", said)
            warnings.warn(said, stacklevel=2)
        if report is not None:
            report.add(
                "resample",
                f"{run_label(name)}: {t.size} samples at {logged:.3g} Hz"
                + (" over the run (its stamps in bursts)" if burst else "")
                + f" -> uniform {rate:g} Hz"
                + (f", split in {len(bounds)} at gaps > {gap} s" if len(bounds) > 1 else "")
                + _alone_note(alone, gap),
                rows_removed=alone,
            )
    if not pieces:  # pd.concat said "No objects to concatenate"
        raise NnidInputError(
            f"no run of the log has two samples{f' within {gap:g} s' if gap else ''}: "
            f"each of its {dropped_total} samples is alone, and resampling needs an interval"
            + (" (give a longer gap)" if gap else ""),
            field="gap" if gap else "t",
        )
    fastest, slowest = max(rates, default=rate), min(rates, default=rate)
    if fastest > RESAMPLE_RATIO * rate:  # np.interp picks samples: nothing filters first
        warnings.warn(
            f"resampling from {fastest:.3g} Hz to {rate:g} Hz without an anti-alias filter: "
            f"what the log holds between {rate / 2:g} and {fastest / 2:.3g} Hz (noise, "
            "vibration) folds into the kept samples; low-pass the log first, or keep a rate "
            "nearer its own",
            stacklevel=2,
        )
    if slowest * RESAMPLE_RATIO < rate:
        warnings.warn(
            f"resampling from {slowest:.3g} Hz to {rate:g} Hz: the added samples are "
            "interpolated, not measured, and every score counts them as data",
            stacklevel=2,
        )
    return pd.concat(pieces, ignore_index=True)


def _alone_note(samples: int, gap: float | None) -> str:
    """The resample report's words for the ``samples`` of a run that :func:`resample_log`
    dropped, each without another within ``gap`` s (or in a run of one)."""
    if not samples:
        return ""
    within = f"within {gap:g} s" if gap else "in its run"
    return (
        f"; {samples} sample{'' if samples == 1 else 's'} without another {within} "
        "(no interval to put a grid on) dropped"
    )


def logged_rate(t: np.ndarray, rate: float) -> tuple[float, str | None]:
    """A run's logged rate (``t``: its times; ``rate``: the grid's, for a run of one sample)
    and, where its stamps come in bursts, :func:`nnid.datasets.log.burst_clock`'s sentence
    of them (else None): the typical step's rate (:func:`~nnid.datasets.log.clock_step`: the
    median's, or a coarsely rounded clock's), or for stamps in bursts the rate over the run,
    as the median step is one inside a burst (an IMU's ten samples every 10 ms read as
    100 kHz, not 1 kHz)."""
    if t.size < 2:
        return rate, None
    burst, overall = _burst_pace(t)
    return (1.0 / overall if burst else 1.0 / clock_step(t)[0]), burst


def _burst_pace(t: np.ndarray) -> tuple[str | None, float]:
    """:func:`nnid.datasets.log.burst_clock`'s sentence of a run's stamps (``t``: two or more)
    where they come in bursts, else None, and their pace over the run
    (:func:`~nnid.datasets.log.paced_step`): the median step is one inside a burst."""
    steps = np.diff(t)
    overall = paced_step(steps)
    return burst_clock(float(np.median(steps)), overall), overall


def refuse_bursts(t: np.ndarray, name: object, method: str, field: str) -> float:
    """Refuse the run ``name`` (``t``: its times) whose stamps come in bursts
    (:func:`logged_rate`): ``method`` (what reads the samples, as said to the user) steps
    sample by sample at one rate, which they do not have; ``field``: the error's. Returns
    the run's logged rate (NaN for a run of one sample), read once for the check and its
    caller."""
    rate, burst = logged_rate(t, np.nan)  # a run of one sample is no burst
    if burst:
        # no rate fits: at the median step's (~100 kHz) a 5 Hz cut-off acted at 0.05 Hz (and
        # a derivative came out ~190 times too large); at the run's, a burst's samples would
        # be spread over its gap
        raise NnidInputError(
            f"{run_label(name)}: {burst}; {method} steps sample by sample at one rate, which "
            "these samples do not have: resample the run onto a uniform grid first (the "
            "preprocessing's rate, resample_log)",
            field=field,
        )
    return rate


def refuse_bursty_runs(log: pd.DataFrame, method: str) -> None:
    """:func:`refuse_bursts` on each run of ``log`` (field ``t``), a piece that a gap cut
    from a run named as that run (:func:`~nnid.datasets.log.run_of`): what every whole-log
    entry (the pipeline, a model's ``fit``, the fault monitor) checks before it steps at a
    run's typical step (:func:`~nnid.datasets.log.typical_step`), one inside a burst."""
    if "t" not in log:
        return
    t = log["t"].to_numpy(np.float64)
    for name, pos in experiment_rows(log):
        # the burst check alone (no rate: a rounded clock's is read per run, on every fit);
        # run_of only to name a run refused: it reads the whole log, and a log cut into
        # thousands of pieces is checked on every fit
        if pos.size > 1 and _burst_pace(t[pos])[0]:
            refuse_bursts(t[pos], run_of(log).get(name, name), method, "t")


#: how far :func:`resample_log` may move a log's rate before it is warned of
RESAMPLE_RATIO = 2.0
#: how near (a share of the grid's interval) a grid time of :func:`resample_log` or of the
#: readers (:func:`nnid.datasets.readers.assemble`) must be to a logged time to be that
#: sample: k/rate is not the logged k·Δt in floating point (k/10 and k·0.1 differ in the last
#: bits), which moved every value of a log resampled at its own rate
ON_SAMPLE = 1e-9


#: a measured column silent for this many of its typical intervals is said when it is bridged
SILENCE = 10


def longest_silence(t: np.ndarray, typical: float) -> tuple[int, float] | None:
    """The (index, length) of the longest step of sorted times ``t`` if it exceeds
    :data:`SILENCE` typical steps: what an interpolation over them makes up without a
    sample, said by the readers and :func:`resample_log` alike; else None."""
    steps = np.diff(t)
    if not steps.size:
        return None
    k = int(np.argmax(steps))
    return (k, float(steps[k])) if steps[k] > SILENCE * typical else None


def silence_said(who: str, t: np.ndarray, k: int, length: float, clock: str = "") -> str:
    """The sentence of a silence (:func:`longest_silence`) bridged by interpolation."""
    return (
        f"{who} has no sample for {length:.3g} s (t = {t[k]:.6g}-{t[k + 1]:.6g} s{clock}): "
        "interpolated over; set gap to split the run there"
    )


def run_grid(span: float, rate: float, tolerance: float) -> np.ndarray:
    """A run's times from 0 every 1/``rate`` s to ``span`` (its stop less its start), the grid
    of the readers and of :func:`resample_log`, the last time kept where it is ``span`` to
    ``tolerance`` (:func:`clock_tolerance`): on an epoch clock ``span`` is rounded by ~1e-7 s,
    and a run whose last logged sample is on the grid lost it (1e-9 samples of slack); no time
    more than ``tolerance`` beyond ``span`` is added."""
    return np.arange(int(np.floor(span * rate + tolerance * rate)) + 1) / rate


def clock_tolerance(t: np.ndarray, start: float, rate: float, per_second: float = 1.0) -> float:
    """How near a grid time must be to a source's time (``t``, before ``start`` is taken away)
    to be that sample: :data:`ON_SAMPLE` of the grid's interval, or the rounding of the
    source's clock where that is coarser. Each stamp carries half a unit in the last place of
    its seconds (the conversion to seconds) and half a unit of the number it was read as (a
    count of 1/``per_second`` s: a parser's, a ``time_scale``'s), and ``t - start`` both
    stamps' rounding: two units of an epoch's seconds (~1.7e9 s, held to ~2.4e-7 s), and 2.07
    for nanoseconds since the epoch (~1.7e18, held to 256 ns before the division: stamps
    10 ms apart were 2.04 units off, and a sample on the grid was taken for one off it). No
    more, as a clock that resolves microseconds has a stamp 1e-6 s off a grid time that is
    not on it."""
    largest = max(float(np.max(np.abs(t))), abs(start)) if t.size else abs(start)
    read = float(np.spacing(largest * per_second)) / per_second
    return max(ON_SAMPLE / rate, float(np.spacing(largest)) + read)


def snap_to_samples(grid: np.ndarray, ts: np.ndarray, tolerance: float) -> np.ndarray:
    """Set each time of ``grid`` within ``tolerance`` of a time of ``ts`` (increasing) to that
    time, in place, and return where: np.interp gives such a sample exactly, and a held value
    is the sample's own, never the one before."""
    k = np.clip(np.searchsorted(ts, grid), 1, max(ts.size - 1, 1))
    nearest = np.where(np.abs(ts[k - 1] - grid) <= np.abs(ts[k] - grid), k - 1, k)
    on = np.abs(ts[nearest] - grid) <= tolerance
    grid[on] = ts[nearest[on]]
    return on


def unwrap_finite(angle: np.ndarray) -> np.ndarray:
    """``np.unwrap`` over the finite samples of ``angle`` only: an empty cell (a gap,
    :mod:`nnid.datasets.gaps`) stays empty, where ``np.unwrap`` carried it into every later
    sample of the run."""
    angle = np.asarray(angle, dtype=np.float64)
    ok = np.isfinite(angle)
    out = angle.copy()
    out[ok] = np.unwrap(angle[ok])
    return out


def unwrap_angles(log: pd.DataFrame, report: CleaningReport | None = None) -> pd.DataFrame:
    """Unwrap φ, θ, ψ within each experiment (readers may deliver them wrapped at ±π); an
    empty cell stays a gap (:func:`unwrap_finite`)."""
    out = log.copy()
    runs = experiment_rows(out)  # by position: a run's labels may repeat another's (pd.concat)
    for col in ANGLES:
        if col not in out:
            continue
        raw = out[col].to_numpy(np.float64)
        angle = _unwrap_runs(raw, runs)
        changed = int(np.sum(np.abs(angle - raw) > 1e-12))
        out[col] = angle
        if report is not None and changed:
            report.add("unwrap", f"{col}: {changed} samples shifted by multiples of 2π")
    return out


def _unwrap_runs(raw: np.ndarray, runs: list[tuple[object, np.ndarray]]) -> np.ndarray:
    """:func:`unwrap_finite` of each run of ``raw`` (row positions, :func:`experiment_rows`).
    The runs without an empty cell are unwrapped by length, each length's runs as the rows of
    one array (``np.unwrap`` along them is ``np.unwrap`` of each row, to the bit): a call per
    run is a fixed cost per run, on a log a reader cut into thousands of runs
    (benchmarks/bench_runs.py)."""
    angle = raw.copy()
    finite = np.isfinite(raw)
    by_length: dict[int, list[np.ndarray]] = {}
    for _, pos in runs:
        if finite[pos].all():
            by_length.setdefault(pos.size, []).append(pos)
        else:
            angle[pos] = unwrap_finite(raw[pos])
    for group in by_length.values():
        rows = np.stack(group)
        angle[rows] = np.unwrap(raw[rows], axis=1)
    return angle


# --- Savitzky-Golay ---------------------------------------------------------------------------


def savgol_window(seconds: float, rate: float, order: int, name: str | None = None) -> int:
    """An odd window (samples) of about ``seconds`` that a polynomial of ``order`` fits.

    Fewer samples than ``order + 2`` are widened to that many; where ``seconds`` is a user's
    setting, ``name`` names it in a warning, as the smoothing is then wider than asked (an
    internal default at a low rate is widened without one)."""
    asked = round(seconds * rate)
    n = max(asked, order + 2)
    n = n if n % 2 else n + 1
    if asked < order + 2 and name is not None:
        warnings.warn(
            f"{name} = {seconds:g} s is {asked} samples at {rate:.3g} Hz, too few for a "
            f"Savitzky-Golay polynomial of order {order}: widened to {n} samples "
            f"({n / rate:.3g} s)",
            stacklevel=2,
        )
    return n


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of each run of True in ``mask`` (the stretches between gaps, a gap's
    rows, a plateau's samples)."""
    edges = np.diff(np.concatenate([[0], np.asarray(mask).astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


@lru_cache(maxsize=64)
def _savgol_kernel(window: int, order: int, deriv: int, delta: float) -> np.ndarray:
    """scipy's Savitzky-Golay convolution coefficients (``savgol_coeffs``), made once per
    setting: a call costs ten times the convolution of a short signal."""
    coeffs = savgol_coeffs(window, order, deriv=deriv, delta=delta)
    coeffs.setflags(write=False)
    return coeffs


@lru_cache(maxsize=64)
def _edge_design(window: int, order: int) -> tuple[np.ndarray, np.ndarray]:
    """The least squares of scipy's edge fit (its ``polyfit`` of a window's samples at
    0 … window − 1): the Vandermonde matrix, columns scaled to unit norm, and their scale."""
    powers = np.flip(np.arange(order + 1, dtype=np.float64))
    lhs = np.arange(0, window, dtype=np.float64)[:, None] ** powers[None, :]
    scale = np.sqrt(np.sum(lhs * lhs, axis=0))
    lhs /= scale
    lhs.setflags(write=False)
    scale.setflags(write=False)
    return lhs, scale


def savgol_interp(y: np.ndarray, window: int, order: int, deriv: int, delta: float) -> np.ndarray:
    """``scipy.signal.savgol_filter(y, window, order, deriv=deriv, delta=delta, axis=0,
    mode="interp")`` of a float64 ``y`` (1-D, or each column of a 2-D one), bit for bit (a
    test holds it to scipy's), at a tenth of its cost on a short signal: the same convolution
    with the same coefficients, and each end's half window from the same least-squares
    polynomial of the window's samples (all columns in one solve, as scipy's), differentiated
    and evaluated as scipy does; what is made once per setting is kept
    (:func:`_savgol_kernel`, :func:`_edge_design`). scipy's array-API dispatch cost about 1 ms
    a call, where the arithmetic of a 2-s window costs 0.1 ms: ``detect --follow`` takes six
    such derivatives from every 0.5 s of rows."""
    y = np.asarray(y, dtype=np.float64)
    if window > y.shape[0]:  # callers refuse it first (_check_window_fits, piece_window)
        raise ValueError(f"a Savitzky-Golay window of {window} samples on {y.shape[0]} samples")
    out = convolve1d(y, _savgol_kernel(window, order, deriv, delta), axis=0, mode="constant")
    lhs, scale = _edge_design(window, order)
    half, n = window // 2, y.shape[0]
    for start, lo, hi in ((0, 0, half), (n - window, n - half, n)):
        edge = y[start : start + window].reshape(window, -1)  # (window, columns), as scipy's
        coeffs, *_ = lstsq(lhs, edge, cond=window * np.finfo(np.float64).eps)
        p = (coeffs.T / scale).T
        if deriv > 0:  # scipy's _polyder of the (order + 1, columns) coefficients
            if p.shape[0] <= deriv:
                p = np.zeros_like(p[:1])
            else:
                dp = p[:-deriv].copy()
                for k in range(deriv):
                    dp *= np.arange(p.shape[0] - k - 1, deriv - k - 1, -1, dtype=p.dtype)[:, None]
                p = dp
        at = np.arange(lo - start, hi - start, dtype=p.dtype)[:, None]
        values = np.zeros((at.shape[0], p.shape[1]))
        for j in range(p.shape[0]):  # Horner's rule, as scipy's polyval
            values = values * at + p[j]
        out[lo:hi] = (values / (delta**deriv)).reshape(hi - lo, *y.shape[1:])
    return out


def savgol_derivative(
    y: np.ndarray,
    dt: float,
    window: int,
    order: int = 4,
    deriv: int = 1,
    where: str = "signal",
    setting: str | None = None,
    steps: np.ndarray | None = None,
) -> np.ndarray:
    """Symmetric-window Savitzky-Golay derivative of order ``deriv`` (Caccia III-B).
    ``setting``: the user's key that chose ``window``, named where ``y`` is too short for it.
    ``steps``: the sample positions where the derivative jumps (the steps of inputs held
    between samples), never smoothed across (:func:`_between_steps`)."""
    if window % 2 == 0 or window <= order:
        raise NnidInputError(
            f"Savitzky-Golay window {window} must be odd and larger than the order {order}",
            field="savgol.window",
        )
    y = np.asarray(y, dtype=np.float64)
    _check_window_fits(len(y), window, where, setting)
    missing = np.isnan(y)
    steps = None if steps is None else np.asarray(steps, dtype=np.int64)
    if not missing.any() and steps is None:
        return savgol_interp(y, window, order, deriv, dt)
    # a gap (nnid.datasets.gaps): each stretch between gaps on its own, never across one;
    # a stretch shorter than the window has no estimate
    out = np.full_like(y, np.nan)
    for a, b in true_runs(~missing):
        if b - a < window:
            continue
        if steps is None:
            out[a:b] = savgol_interp(y[a:b], window, order, deriv, dt)
        else:
            inside = steps[(steps > a) & (steps < b - 1)] - a
            out[a:b] = _between_steps(y[a:b], dt, window, order, deriv, inside)
    return out


def too_short_for_window(
    where: str, samples: int, window: int, setting: str | None
) -> NnidInputError:
    """The refusal of ``where`` (a run, a part's run), ``samples`` long, for a Savitzky-Golay
    ``window`` (samples) longer than it, naming the user's key ``setting`` that chose it."""
    if samples < 2:  # no interval to set a window by: no setting would make it fit
        return NnidInputError(
            f"{where} has {samples} sample{'' if samples == 1 else 's'}: velocities and "
            f"accelerations are derived over a Savitzky-Golay window, and a run needs at least "
            f"{window} samples for it",
        )
    # a window of 1e300 s is a 300-digit count: written to 3 figures beyond a run's size
    size = window if window <= MAX_RUN_SAMPLES else f"{float(window):.3g}"
    return NnidInputError(
        f"{where} has {samples} samples, too few for the Savitzky-Golay window of {size} "
        "samples (velocities and accelerations are derived with it)"
        + (f": give a shorter {setting} or a longer run" if setting else ""),
        field=setting,
    )


def run_window(
    t: np.ndarray, window_s: float, order: int, name: object, setting: str | None = None
) -> tuple[float, int]:
    """A run's median step (``t``: the times of the run ``name``) and its Savitzky-Golay
    window of ``window_s`` s (:func:`savgol_window`, ``setting`` named where widened), for a
    derivative that takes its samples as evenly spaced: a run whose stamps come in bursts is
    refused (:func:`refuse_bursts`), as its median step is one inside a burst (an IMU's ten
    samples every 10 ms: a 0.02 s window took 2001 samples, 2 s of them, as 0.02 s, and a
    derivative of amplitude π came out at 600).
    A run of one sample has no step (NaN, where the window's count was "cannot convert float
    NaN to integer"): the shortest window an ``order`` allows stands for it, which it is too
    short for (a piece cut at a gap gets no derivative, :func:`short_piece`; a run is
    refused, :func:`_check_window_fits`)."""
    if t.size < 2:
        return np.nan, savgol_window(0.0, 1.0, order)
    refuse_bursts(t, name, "a Savitzky-Golay derivative", "t")
    return step_window(t, window_s, order, np.nan, setting)


def step_window(
    t: np.ndarray,
    window_s: float,
    order: int,
    one_sample: float,
    setting: str | None = None,
) -> tuple[float, int]:
    """A run's typical step (:func:`~nnid.datasets.log.typical_step`, ``one_sample`` for a run
    of one sample) and the Savitzky-Golay window of ``window_s`` s at its rate
    (:func:`savgol_window`, ``setting`` named where widened). No check of the clock:
    :func:`run_window` is the one that refuses stamps in bursts before a derivative."""
    dt = typical_step(t, one_sample)
    return dt, savgol_window(window_s, 1.0 / dt, order, setting)


def _check_window_fits(n: int, window: int, where: str, setting: str | None) -> None:
    """Refuse ``n`` samples of ``where`` as too few for the Savitzky-Golay ``window``
    (``setting``: the user's key that chose it, named)."""
    if n < window:
        raise too_short_for_window(where, n, window, setting)


def _refuse_infinite(
    log: pd.DataFrame, columns: Sequence[str], what: str, by: str = "Savitzky-Golay"
) -> None:
    """Refuse an infinite value in ``columns`` of ``log``, or in ``t`` any value that is not a
    finite number, naming its column and row (the row's index label: the file's row for a
    log as read): an empty cell is a gap, which a Savitzky-Golay derivative or a low-pass
    filter (``what``, ``by`` the filter) leaves out, but an inf at a run's end stopped scipy's
    edge fit with a message that named neither, and one inside a run turned the window
    around it into ±inf and NaN without a word."""
    for col in columns:
        values = log[col].to_numpy(np.float64)
        bad = ~np.isfinite(values) if col == "t" else np.isinf(values)
        refuse_rows(
            log,
            col,
            bad,
            None,
            f"is not a finite number, which {what} by {by} needs"
            + ("" if col == "t" else "; an empty cell would be a gap, left out"),
            labels=True,
        )


def _between_steps(
    y: np.ndarray, dt: float, window: int, order: int, deriv: int, steps: np.ndarray
) -> np.ndarray:
    """:func:`savgol_derivative` of a finite ``y`` cut at ``steps`` (positions 1 … n − 2,
    ascending), as Caccia's step 1 cuts at each input change (:mod:`nnid.trainers.caccia`):
    a velocity under a held force is smooth between the steps and only continuous at one, so
    a window across a step smears the jump of the acceleration, which the fit reads as
    inertia. Each piece from one step to the next (both in it: the velocity is continuous
    there) is differentiated on its own, with the widest odd window up to ``window`` it holds
    and an order below that window (two samples: their slope); a step sample takes the mean
    of its two one-sided derivatives, the acceleration of the mean force held before and
    after it (``zoh_midpoint``)."""
    bounds = np.concatenate([[0], steps, [y.size - 1]]).astype(int)
    total, count = np.zeros_like(y), np.zeros_like(y)
    for a, b in pairwise(bounds):
        piece = y[a : b + 1]
        w = piece_window(piece.size, window)
        if w >= 3:
            d = savgol_interp(piece, w, min(order, w - 1), deriv, dt)
        else:  # two samples: a slope, and no higher derivative
            d = np.full(2, (piece[1] - piece[0]) / dt if deriv == 1 else np.nan)
        total[a : b + 1] += d
        count[a : b + 1] += 1
    return total / count


def savgol_noise_gain(window: int, order: int, dt: float, deriv: int = 1) -> float:
    """Standard deviation of the SG estimate per unit white measurement noise: sqrt(Σ cₖ²)."""
    return float(np.sqrt(np.sum(savgol_coeffs(window, order, deriv=deriv, delta=dt) ** 2)))


def piece_window(size: int, window: int) -> int:
    """The widest odd window up to ``window`` that a piece of ``size`` samples holds."""
    return min(window, size - (1 - size % 2))


def savgol_derivative_gain2(
    n: int,
    dt: float,
    window: int,
    order: int = 4,
    deriv: int = 1,
    steps: np.ndarray | None = None,
    missing: np.ndarray | None = None,
) -> np.ndarray:
    """Per sample, the variance per unit white measurement noise of :func:`savgol_derivative`
    of ``n`` samples with these arguments (``missing``: its NaN samples): NaN where it gives
    no estimate. Without ``steps`` each sample has the full window's :func:`savgol_noise_gain`
    squared. Cut at ``steps``, each sample has the gain of the estimate that made it
    (:func:`_between_steps_gain2`): at the centre of a 3- or 5-sample piece 8-10 times the
    noise gain of a 21-sample window (60-110 times its variance), more at a piece's ends, and
    at a step that of the mean of two one-sided estimates."""
    out = np.full(n, np.nan)
    missing = np.zeros(n, dtype=bool) if missing is None else np.asarray(missing, dtype=bool)
    steps = None if steps is None else np.asarray(steps, dtype=np.int64)
    full = savgol_noise_gain(window, order, dt, deriv) ** 2
    for a, b in true_runs(~missing):
        if b - a < window:  # as savgol_derivative: no estimate
            continue
        if steps is None:
            out[a:b] = full
        else:
            inside = steps[(steps > a) & (steps < b - 1)] - a
            out[a:b] = _between_steps_gain2(b - a, dt, window, order, deriv, inside)
    return out


def _between_steps_gain2(
    n: int, dt: float, window: int, order: int, deriv: int, steps: np.ndarray
) -> np.ndarray:
    """The variance per unit white noise of each sample of :func:`_between_steps`: Σⱼ cᵢⱼ² of
    the weights cᵢⱼ of sample j in the estimate at i. In a piece the Savitzky-Golay fit of
    its window (the first and last half window evaluated off-centre, scipy's ``interp``); at a
    step the mean of the two pieces' estimates, which share the step sample: (g²ₗ + g²ᵣ +
    2 cₗ cᵣ)/4. The stretch's own ends (the off-centre half window of its first and last
    piece) keep their window's centre gain, as a stretch without steps does
    (:func:`savgol_derivative_gain2`): those were never counted, and one step more or less
    must not change how a run's ends count."""
    bounds = np.concatenate([[0], steps, [n - 1]]).astype(int)
    var, count = np.zeros(n), np.zeros(n)
    first, last = np.zeros(n), np.zeros(n)  # a piece's weight of its own first / last sample
    ends = []  # (rows, centre gain²) of the stretch's first and last piece's outer half window
    for a, b in pairwise(bounds):
        size = b - a + 1
        w = piece_window(size, window)
        if w >= 3:
            o = min(order, w - 1)
            fit = savgol_interp(np.eye(w), w, o, deriv, dt)  # row i: the weights at sample i
            rows2 = np.sum(fit**2, axis=1)  # rows: the estimates at the window's samples
            gain2 = np.full(size, savgol_noise_gain(w, o, dt, deriv) ** 2)
            h = w // 2
            if a == 0:
                ends.append((slice(0, h), gain2[0]))
            if b == n - 1:
                ends.append((slice(n - h, n), gain2[0]))
            gain2[:h], gain2[size - h :] = rows2[:h], rows2[w - h :]
            first[a], last[b] = fit[0, 0], fit[-1, -1]
        else:  # two samples: their slope (no higher derivative, as _between_steps)
            gain2 = np.full(2, 2.0 / dt**2 if deriv == 1 else np.nan)
            first[a], last[b] = -1.0 / dt, 1.0 / dt
        var[a : b + 1] += gain2
        count[a : b + 1] += 1
    out = np.where(count == 2, (var + 2.0 * first * last) / 4.0, var)
    for rows, centre in ends:
        out[rows] = centre
    return out


def excited_dofs(log: pd.DataFrame, columns: list[str], rel: float = 0.1) -> list[str]:
    """Velocity columns the data excites: std above ``rel`` of the largest linear (u v w) or
    angular (p q r) std. A DOF that only trembles through coupling is not scored: its NRMSE
    would divide by its own noise."""
    stds = {c: float(log[c].std()) for c in columns if c in log}
    lin = max([stds.get(c, 0.0) for c in "uvw"] + [0.0])
    ang = max([stds.get(c, 0.0) for c in "pqr"] + [0.0])
    return [c for c, s in stds.items() if s > rel * (lin if c in "uvw" else ang) and s > 0]


def velocity_sources(columns) -> dict[str, tuple[str, ...]]:
    """Each body velocity a pose of these columns gives (:func:`derive_velocities`) and the
    pose columns it is derived from: p, q, r from the attitude; u, v, w from x, y, z with it;
    w alone from z with it. What a fit that derives a velocity reads of the pose."""
    have = set(columns)
    if not all(a in have for a in ANGLES):
        return {}
    out = dict.fromkeys(("p", "q", "r"), tuple(ANGLES))
    if all(c in have for c in ("x", "y", "z")):
        out.update(dict.fromkeys(("u", "v", "w"), ("x", "y", "z", *ANGLES)))
    elif "z" in have:
        out["w"] = ("z", *ANGLES)
    return out


def derivable_velocities(columns) -> set[str]:
    """The body velocities a pose of these columns gives (:func:`velocity_sources`)."""
    return set(velocity_sources(columns))


def check_velocities(
    columns, dofs, remedy: str = "fit only the DOFs the log has (the model's dofs)"
) -> None:
    """Refuse a log that neither has nor can derive (:func:`derivable_velocities`) the
    velocity of one of ``dofs``. Read as zero, it would be fitted and scored as a vehicle at
    rest in that DOF. ``remedy``: what else the user can do, besides logging it."""
    have = set(columns) | derivable_velocities(columns)
    missing = [d for d in dofs if d not in have]
    if missing:
        raise NnidInputError(
            f"the log has no {', '.join(missing)} column and its pose cannot give "
            f"{'it' if len(missing) == 1 else 'them'} (u, v from x, y, z with phi, theta, psi; "
            f"w also from z and the attitude; p, q, r from the attitude): log the velocity, or "
            f"{remedy}",
            field=missing[0],
        )


#: roll or pitch (rad, about 6°) that a log's own rates turn the vehicle through, their median
#: (a gyro's bias) taken out, beyond which a level vehicle is no reading
TILTED = 0.1


def check_attitude(log: pd.DataFrame, vehicle, dofs: Sequence[str]) -> None:
    """Refuse a log without roll or pitch whose own rates p, q show the vehicle rolling or
    pitching (its angle spanning more than :data:`TILTED` within a run), where the restoring
    forces of the fitted ``dofs`` depend on that angle (Weiss eq. 30: weight ≠ buoyancy, or
    r_g ≠ r_b across it): read as zero, the attitude makes them those of a level vehicle, and
    the fit puts the error in the added mass. The rate's median is taken out first: a gyro's
    bias turns a level vehicle through a radian in minutes, while a vehicle that tilts and
    holds the tilt rotates only while it tilts (its median rate stays ~0; the mean would call
    the tilt a bias)."""
    import torch

    from nnid.datasets.log import turned_by
    from nnid.physics.dofs import DOFS
    from nnid.physics.restoring import restoring_force

    def restoring(phi: float, theta: float) -> np.ndarray:
        eta = torch.tensor([0.0, 0.0, 0.0, phi, theta, 0.0], dtype=torch.float64)
        arms = [torch.tensor(r, dtype=torch.float64) for r in (vehicle.r_g, vehicle.r_b)]
        g = restoring_force(eta, vehicle.weight, vehicle.buoyancy, *arms).numpy()
        return g[[DOFS.index(d) for d in dofs]]

    level = restoring(0.0, 0.0)
    for angle, rate, tilt in (("phi", "p", (TILTED, 0.0)), ("theta", "q", (0.0, TILTED))):
        if angle in log or rate not in log or "t" not in log:
            continue
        if np.allclose(restoring(*tilt), level, rtol=0.0, atol=1e-9 * (1 + vehicle.weight)):
            continue  # the fitted DOFs' restoring forces do not read this angle
        rates, t = log[rate].to_numpy(np.float64), log["t"].to_numpy(np.float64)
        for exp, pos in experiment_rows(log):
            w = rates[pos]
            if not np.isfinite(w).any():  # a run with no rate says nothing of its attitude
                continue
            turned = turned_by(t[pos], w - np.nanmedian(w))
            if np.ptp(turned) > TILTED:
                run = f" in experiment {exp!r}" if exp is not None else ""
                raise NnidInputError(
                    f"the log has no {angle} column, and its {rate}{run} turns the vehicle "
                    f"through {np.ptp(turned):.2g} rad (its median taken out): the restoring "
                    f"forces of {vehicle.name} in {', '.join(dofs)} need the attitude; log "
                    f"{angle} (or map it in a reader config)",
                    field=angle,
                )


def derive_velocities(
    log: pd.DataFrame,
    window_s: float = 0.5,
    order: int = 4,
    report: CleaningReport | None = None,
    overwrite: bool = False,
    setting: str = "savgol_window",
) -> pd.DataFrame:
    """Body velocities from pose by SG differentiation and ν = J⁻¹(η) η̇ (McCarter eq. 2.15).

    With the full pose: u v w p q r. With attitude only: p q r = T_Θ⁻¹ Θ̇. With depth and
    attitude but no x, y: also w ≈ ż / (cos θ cos φ), exact when u = v = 0 and reported as an
    approximation. Existing velocity columns are kept unless ``overwrite``. ``setting``: the
    user's key that chose ``window_s``, named where the window is widened or refused.
    """
    have = [c for c in POSE if c in log]
    derivable = derivable_velocities(have)
    if not derivable:
        raise NnidInputError("deriving body velocities needs phi, theta and psi", field="phi")
    _refuse_infinite(log, ["t", *have], "deriving velocities from the pose")
    out = unwrap_angles(log)
    new = {c: np.full(len(out), np.nan) for c in VELOCITY}
    tilted = short = stretches = 0
    # each column read once and each run's rows taken by position: looking a run's labels up
    # in the whole log cost rows × runs, and a label repeated (pd.concat) read another run
    column = {c: out[c].to_numpy(np.float64) for c in ("t", *have)}
    runs = []  # every run's window checked before any is derived: one too short was refused
    for name, pos in experiment_rows(out):  # after the work on every run before it
        dt, window = run_window(column["t"][pos], window_s, order, name, setting)
        if short_piece(out, pos, window):
            short += len(pos)
            continue
        _check_window_fits(len(pos), window, run_label(name), setting)
        runs.append((name, pos, dt, window))
    # T_Θ⁻¹ and J₁ of every row in one call each (row by row the same numbers): once per run,
    # scipy's Rotation was a fixed cost per run on a log of many short runs (bench_runs.py)
    angles = np.stack([column[a] for a in ANGLES], 1)
    inverse = euler_rate_matrices(angles, inverse=True)
    turn = rotation_from_euler(angles) if "u" in derivable else None
    for name, pos, dt, window in runs:
        rates = {
            c: savgol_derivative(
                column[c][pos],
                dt,
                window,
                order,
                where=run_label(name),
                setting=setting,
            )
            for c in have
        }
        stretches += without_derivative([column[c][pos] for c in have], list(rates.values()))
        # a run's rows in one stretch (ascending positions) as a view: no copy of its matrices
        rows = slice(pos[0], pos[-1] + 1) if pos[-1] - pos[0] + 1 == pos.size else pos
        dphi, dth, dpsi = rates["phi"], rates["theta"], rates["psi"]
        body_rates = np.einsum("nij,nj->ni", inverse[rows], np.stack([dphi, dth, dpsi], 1))
        new["p"][pos], new["q"][pos], new["r"][pos] = body_rates.T
        if turn is not None:
            ned = np.stack([rates["x"], rates["y"], rates["z"]], 1)
            body = np.einsum("nji,nj->ni", turn[rows], ned)  # J₁ᵀ ṗ
            for k, c in enumerate(("u", "v", "w")):
                new[c][pos] = body[:, k]
        elif "w" in derivable:
            # ż = −sθ u + cθsφ v + cθcφ w: w ≈ ż/(cθcφ) holds only near level; the divisor
            # is kept at 0.5 or more (60° of tilt) so that it cannot blow up
            tilt = np.cos(column["theta"][pos]) * np.cos(column["phi"][pos])
            tilted += int(np.sum(np.abs(tilt) < 0.5))
            new["w"][pos] = rates["z"] / np.copysign(np.maximum(np.abs(tilt), 0.5), tilt)
    uneven_runs(out, "the Savitzky-Golay derivative")
    made = []
    for c, values in new.items():
        if np.isfinite(values).any() and (overwrite or c not in out):
            out[c] = values
            made.append(c)
    if report is not None and made:
        approx = ""
        if "w" in made and "x" not in have:
            approx = f" (w from depth rate, assuming u = v = 0; {tilted} samples tilted beyond "
            approx += "60°, where it is only a bound)"
        report.add(
            "derive velocities",
            f"{', '.join(made)} from pose by Savitzky-Golay "
            f"(order {order}, {window_s:g} s window) and J⁻¹(η){approx}"
            + short_pieces_note(short, stretches),
            columns=made,
        )
    return out


def short_piece(log: pd.DataFrame, rows: np.ndarray, window: int) -> bool:
    """Whether the experiment at row positions ``rows`` of ``log`` (:func:`experiment_rows`)
    is a piece of a run cut at a gap (its ``piece_of`` column set:
    :func:`nnid.datasets.gaps.mask_gaps`, :func:`resample`, the readers) shorter than the
    Savitzky-Golay ``window``: it gets no derivative, as a stretch between gaps within a run
    gets none (an empty cell 20 samples from a run's start was an error blaming the
    savgol_window setting). A whole run that short is still refused, whatever its label holds
    (a '#' in a user's experiment name made it a piece)."""
    return len(rows) < window and PIECE_OF in log and bool(log[PIECE_OF].iloc[rows].notna().all())


def short_pieces_note(samples: int, stretches: int = 0) -> str:
    """The cleaning report's words for the samples :func:`short_piece` left without one, and
    for the ``stretches`` samples (:func:`without_derivative`) that a stretch between empty
    cells of a run, shorter than the window, left without one."""
    note = f"; {samples} samples in pieces between gaps shorter than the window" if samples else ""
    if stretches:
        note += f"; {stretches} samples in stretches between empty cells shorter than the window"
    return f"{note}: none there" if note else ""


def without_derivative(values: Sequence[np.ndarray], derived: Sequence[np.ndarray]) -> int:
    """How many samples (rows) hold a value in one of the columns ``values`` whose
    Savitzky-Golay derivative (``derived``, the same columns) :func:`savgol_derivative` left
    empty: those of a stretch between gaps shorter than the window."""
    if not values:
        return 0
    left = np.isfinite(np.column_stack(values)) & np.isnan(np.column_stack(derived))
    return int(left.any(axis=1).sum())


def _held_steps(log: pd.DataFrame, pos: np.ndarray, held: list[str]) -> np.ndarray | None:
    """The positions in the experiment at row positions ``pos`` where one of the ``held``
    inputs steps (the cuts of :func:`_between_steps`), or None without held inputs."""
    if not held:
        return None
    step = np.diff(log[held].to_numpy(np.float64)[pos], axis=0)
    return np.flatnonzero((np.isfinite(step) & (step != 0)).any(axis=1)) + 1


def acceleration_gain2(
    log: pd.DataFrame, window_s: float, order: int, cut_at_steps: bool = False
) -> np.ndarray:
    """Per row of ``log``, the variance per unit white velocity noise of the acceleration
    :func:`derive_accelerations` derives with these arguments
    (:func:`savgol_derivative_gain2`), NaN where it derives none. Cut at the steps of held
    inputs the short pieces between steps are much noisier than the full window says."""
    out = np.full(len(log), np.nan)
    held = held_inputs(log) if cut_at_steps else []
    # derive_accelerations has warned of a widened window: not said a second time
    velocity = log[[c for c in VELOCITY if c in log]].to_numpy(float)
    for _, pos, dt, window, steps in _derivative_runs(log, window_s, order, held, None):
        if window is None:
            continue
        missing = ~np.isfinite(velocity[pos])
        out[pos] = savgol_derivative_gain2(
            len(pos), dt, window, order, 1, steps, missing.any(axis=1)
        )
    return out


def _derivative_runs(
    log: pd.DataFrame, window_s: float, order: int, held: list[str], setting: str | None
):
    """Per experiment of ``log``, how :func:`derive_accelerations` differentiates it, which
    :func:`acceleration_gain2` must follow: (name, row positions, median step, Savitzky-Golay
    window or None for a run shorter than it, the steps of the ``held`` inputs or None).
    ``setting``: the key named where the window is widened (None: not warned again)."""
    t = log["t"].to_numpy(np.float64)
    for name, pos in experiment_rows(log):
        dt, window = run_window(t[pos], window_s, order, name, setting)
        if short_piece(log, pos, window):
            yield name, pos, dt, None, None
        else:
            yield name, pos, dt, window, _held_steps(log, pos, held)


def check_acceleration_window(
    log: pd.DataFrame, window_s: float, order: int, part: str, setting: str = "savgol_window"
) -> None:
    """The refusal :func:`derive_accelerations` would give ``log`` (the ``part`` of a split,
    named in it): an experiment (not a piece cut at a gap) shorter than the Savitzky-Golay
    window of ``window_s`` s, said before a fit whose scores would derive them (a hybrid's
    training of minutes ended in it)."""
    for name, pos, _, window, _ in _derivative_runs(log, window_s, order, [], None):
        if window is not None:
            _check_window_fits(len(pos), window, f"the {part} part's {run_label(name)}", setting)


def derive_accelerations(
    log: pd.DataFrame,
    window_s: float = 0.5,
    order: int = 4,
    report: CleaningReport | None = None,
    cut_at_steps: bool = False,
    setting: str = "savgol_window",
    warn_uneven: bool = True,
) -> pd.DataFrame:
    """ν̇ (``du`` … ``dr``) by SG differentiation of the body velocities present;
    ``cut_at_steps`` (inputs held between samples, ``zoh_midpoint``): never across a step of
    the inputs that look held (:func:`held_inputs`, :func:`_between_steps`). ``setting``: the
    user's key that chose ``window_s``, named where the window is widened or refused.
    ``warn_uneven`` False: the caller has just derived this log's velocities
    (:func:`derive_velocities`), which warned of its uneven runs (:func:`uneven_runs`) on the
    same clock: not said twice."""
    cols = [c for c in VELOCITY if c in log]
    _refuse_infinite(log, ["t", *cols], "deriving accelerations from the velocities")
    out = log.copy()
    held = held_inputs(log) if cut_at_steps else []
    short = cuts = stretches = 0
    # each run's rows by position: a run's labels may repeat another's (pd.concat)
    velocity = {c: out[c].to_numpy(np.float64) for c in cols}
    derived = {c: np.full(len(out), np.nan) for c in cols}
    runs = _derivative_runs(out, window_s, order, held, setting)
    for name, pos, dt, window, steps in runs:
        if window is None:
            short += len(pos)
            continue
        cuts += 0 if steps is None else steps.size
        for c in cols:
            derived[c][pos] = savgol_derivative(
                velocity[c][pos],
                dt,
                window,
                order,
                where=run_label(name),
                setting=setting,
                steps=steps,
            )
        stretches += without_derivative(
            [velocity[c][pos] for c in cols], [derived[c][pos] for c in cols]
        )
    if warn_uneven:
        uneven_runs(out, "the Savitzky-Golay derivative")
    for c in cols:
        out["d" + c] = derived[c]
    if report is not None and cols:
        cut = f", not across the {cuts} steps of the held inputs {', '.join(held)}" if held else ""
        report.add(
            "derive accelerations",
            f"d{', d'.join(cols)} by Savitzky-Golay (order {order}, {window_s:g} s window)"
            + cut
            + short_pieces_note(short, stretches),
            columns=["d" + c for c in cols],
        )
    return out


# --- filtering and cleaning -------------------------------------------------------------------


def lowpass(
    log: pd.DataFrame,
    columns: list[str],
    cutoff: float,
    order: int = 4,
    report: CleaningReport | None = None,
) -> pd.DataFrame:
    """Zero-phase Butterworth low-pass (forward-backward, no delay) per experiment, designed
    at the run's logged rate (:func:`logged_rate`, as :func:`resample_log` reads it). The
    filter steps sample by sample, so a run whose stamps come in bursts (an IMU's ten
    samples together every 10 ms) is refused (:func:`refuse_bursts`), and one whose steps
    are not one step (dropped samples, jitter) is warned of (:func:`uneven_runs`): resample
    it first (:func:`resample_log`). An empty cell is a gap: each stretch between gaps is
    filtered on its own (an IIR filter run across one turned the whole run's column NaN),
    one too short for the filter's padding is left as logged and counted in the report."""
    _refuse_infinite(log, ["t", *columns], "low-pass filtering", by="a Butterworth filter")
    out = log.copy()
    t_all = out["t"].to_numpy(np.float64)
    # each run's rows by position: a run's labels may repeat another's (pd.concat)
    values = {c: out[c].to_numpy(np.float64, copy=True) for c in columns}
    need = 3 * (order + 1)  # filtfilt's padding: three times the filter's order + 1 taps
    unfiltered = 0  # samples in stretches between gaps too short for the padding
    for name, pos in experiment_rows(out):
        t = t_all[pos]
        if len(t) <= need:  # before the rate: a run of one sample has no step to read it by
            raise NnidInputError(
                f"{run_label(name)} has {len(t)} samples, too few for the "
                f"low-pass filter ({need} needed)",
                field="lowpass",
            )
        rate = refuse_bursts(t, name, "a Butterworth filter", "lowpass")  # two samples or more
        if cutoff >= rate / 2:
            raise NnidInputError(
                f"cut-off {cutoff} Hz is not below the Nyquist rate {rate / 2:g} Hz",
                field="lowpass.cutoff",
            )
        b, a = butter(order, cutoff, fs=rate)
        for c in columns:
            y = values[c][pos]
            for lo, hi in true_runs(np.isfinite(y)):  # a run without a gap: one stretch
                if hi - lo <= need:
                    unfiltered += hi - lo
                else:
                    y[lo:hi] = filtfilt(b, a, y[lo:hi])
            values[c][pos] = y
    uneven_runs(out, "the low-pass filter (designed at its rate)")
    for c in columns:
        out[c] = values[c]
    if report is not None:
        detail = f"{', '.join(columns)}: zero-phase Butterworth order {order}, {cutoff:g} Hz"
        if any(np.isnan(values[c]).any() for c in columns):
            detail += "; each stretch between gaps (empty cells) on its own"
        if unfiltered:
            detail += (
                f", {unfiltered} samples in stretches of {need} samples or fewer (too few for "
                "the filter's padding) left unfiltered"
            )
        report.add("low-pass", detail, columns=columns)
    return out


def detect_jumps(
    y: np.ndarray, kernel: int = 7, threshold: float = 6.0, min_jump: float = 0.0
) -> np.ndarray:
    """Samples that jump away from the median of their neighbours (the sample itself left
    out) by more than ``threshold`` robust standard deviations and ``min_jump``: motion-capture
    occlusions and glitches (Weiss V.A.2). An empty cell (a gap) is never one, and is left
    out of its neighbours' medians and of the robust spread (it made the spread NaN, and no
    sample of the run was found). Beyond the run's ends is read as a gap: an end sample padded
    with itself (``mode="edge"``) was half its own reference, so a clean sine's ends were
    jumps and a glitch there had to be twice as big to be found."""
    y = np.asarray(y, dtype=np.float64)
    half = kernel // 2
    # 2*half empty cells a side: the straight lines below reach 2*half samples away
    wide = np.lib.stride_tricks.sliding_window_view(
        np.pad(y, 2 * half, constant_values=np.nan), 4 * half + 1
    )
    neighbours = np.delete(wide[:, half : 3 * half + 1], half, axis=1)
    reference = np.median(neighbours, axis=1)
    # beside a gap the neighbour opposite each empty one is left out too: a median of the
    # others, all on one side, is a sample off the trend (a jump on any slope); elsewhere
    # np.median's numbers as before
    gapped = np.isnan(neighbours) | np.isnan(neighbours[:, ::-1])
    if gapped.any():
        some = gapped.any(axis=1) & ~gapped.all(axis=1)
        reference[some] = np.nanmedian(np.where(gapped, np.nan, neighbours)[some], axis=1)
        # no neighbour with a partner across the sample (a run's end, a side of a wide gap):
        # the median of the straight lines through the samples k and 2k away on one side,
        # which stays on a slope's trend and outvotes one glitch among them
        k, centre = np.arange(1, half + 1), 2 * half
        alone = gapped.all(axis=1)
        lone = wide[alone]
        lines = np.concatenate(
            [
                2 * lone[:, centre + k] - lone[:, centre + 2 * k],
                2 * lone[:, centre - k] - lone[:, centre - 2 * k],
            ],
            axis=1,
        )
        drawn = ~np.isnan(lines).all(axis=1)  # a sample with none stays unmeasured
        fallback = np.full(lines.shape[0], np.nan)
        fallback[drawn] = np.nanmedian(lines[drawn], axis=1)
        reference[alone] = fallback
    resid = y - reference
    measured = ~np.isnan(resid)  # an inf is a jump, repaired as before
    if not measured.any():
        return np.zeros(y.shape, dtype=bool)
    sigma = median_abs_deviation(resid[measured], scale="normal") + 1e-12
    size = np.abs(resid)
    # a big jump also nudges its neighbours' reference; keep only samples that carry at least
    # half the largest residual around them (a multi-frame occlusion keeps all its frames);
    # an empty cell counts as no residual there, not as NaN that no sample beside it beats
    near = np.where(measured, size, 0.0)
    local_max = np.max(
        np.lib.stride_tricks.sliding_window_view(np.pad(near, half, mode="edge"), kernel), axis=1
    )
    return measured & (size > threshold * sigma) & (size > min_jump) & (size >= 0.5 * local_max)


def repair_jumps(
    log: pd.DataFrame,
    columns: list[str],
    kernel: int = 7,
    threshold: float = 6.0,
    min_jump: float = 0.0,
    report: CleaningReport | None = None,
) -> pd.DataFrame:
    """Replace detected jumps by linear interpolation from their neighbours, and report them."""
    out = log.copy()
    total = 0
    t_all = out["t"].to_numpy(np.float64)
    # each run's rows by position: a run's labels may repeat another's (pd.concat)
    values = {c: out[c].to_numpy(np.float64, copy=True) for c in columns}
    repaired = set()
    for _, pos in experiment_rows(out):
        t = t_all[pos]
        for c in columns:
            y = values[c][pos]
            bad = detect_jumps(y, kernel, threshold, min_jump)
            good = ~bad & np.isfinite(y)  # an empty cell is no neighbour to interpolate from
            if bad.any() and good.sum() >= 2:
                y[bad] = np.interp(t[bad], t[good], y[good])
                values[c][pos] = y
                repaired.add(c)
                total += int(bad.sum())
    for c in columns:
        if c in repaired:  # a column without a jump is left as it was
            out[c] = values[c]
    if report is not None:
        report.add(
            "jumps",
            f"{total} samples in {', '.join(columns)} jumped more than {threshold:g} "
            "robust σ from a running median (occlusion or glitch) and were interpolated",
            columns=columns,
        )
    return out


# --- held inputs ------------------------------------------------------------------------------


def zoh_midpoint_inputs(log: pd.DataFrame) -> pd.DataFrame:
    """The log with every input column replaced by :func:`zoh_midpoint` of it."""
    cols = input_columns(log)
    out = log.copy()
    out[cols] = zoh_midpoint(out[cols].to_numpy(np.float64), log)
    return out


def zoh_midpoint(x: np.ndarray, log: pd.DataFrame) -> np.ndarray:
    """Per experiment, the mean of consecutive samples (the first kept): the force a
    zero-order-held input applies around t_k, which a smoothed acceleration at t_k sees."""
    y = np.array(x, dtype=np.float64, copy=True)
    for _, pos in experiment_rows(log):
        y[pos[1:]] = 0.5 * (x[pos[1:]] + x[pos[:-1]])
    return y


#: The sample time from which a fit on held inputs without ``zoh_midpoint`` is warned of. On a
#: noise-free simulated Seamor log of yaw moments held 0.5-2 s, the filtered regressors
#: (λ = 1 rad/s) fitted N_ṙ (truth −0.154) −37 % off at 10 Hz, −19 % at 20 Hz, −7.3 % at
#: 50 Hz and −3.3 % at 100 Hz; with ``zoh_midpoint`` within 3.4 % at every rate. The bias of
#: the inertia m − N_ṙ is about Δt/(2T) (T its velocity time constant): a half-sample delay
#: of the force, read as inertia. From 50 Hz down it is several % of the added mass.
HELD_DT = 0.02
#: The share of a moving input's consecutive samples that must be equal for it to look held
#: (a command that holds each level over at least two samples; a sampled smooth signal has none).
HELD_SHARE = 0.5


def held_inputs(log: pd.DataFrame) -> list[str]:
    """The input columns that look held between samples: per experiment, at least
    :data:`HELD_SHARE` of their consecutive samples are equal and at least one is not (a
    column that never moves steps nowhere). A sampled smooth signal is never equal twice, but
    may rest at zero between its bursts: a pair of samples both at zero is left out."""
    held, groups = [], [pos for _, pos in experiment_rows(log)]
    for c in input_columns(log):
        equal = steps = 0
        column = log[c].to_numpy(np.float64)
        for pos in groups:
            x = column[pos]
            d = np.diff(x)
            d = d[np.isfinite(d) & ((x[1:] != 0) | (x[:-1] != 0))]
            equal += int(np.count_nonzero(d == 0.0))
            steps += int(np.count_nonzero(d != 0.0))
        if steps and equal >= HELD_SHARE * (equal + steps):
            held.append(c)
    return held


def held_at(log: pd.DataFrame) -> tuple[list[str], float]:
    """The inputs that look held (:func:`held_inputs`) and the sample time of the log's
    experiments, their steps read together (:func:`~nnid.datasets.log.log_step`: the median,
    or a coarsely rounded clock's step; NaN where none has two samples): whether and how far
    a held force lags. 120 Hz stamped in whole ms read 8 ms, its median, not 8.33."""
    held = held_inputs(log)
    if not held:
        return held, float("nan")
    return held, frame_step(log)


# --- sensor biases ----------------------------------------------------------------------------


def first_order_lag(tau: np.ndarray, log: pd.DataFrame, time_constant: float) -> np.ndarray:
    """a_{k+1} = e^{−Δt/T} a_k + (1 − e^{−Δt/T}) τ_k per experiment, from a_0 = τ_0: the
    state of T ȧ + a = τ at the sample times when τ is held between samples."""
    if time_constant <= 0:
        return tau
    out = np.empty_like(tau)
    t = log["t"].to_numpy(np.float64)
    for _, pos in experiment_rows(log):
        dt = typical_step(t[pos], 1.0)
        a = np.exp(-dt / time_constant)
        # zi = τ_0 starts the filter at rest on the first input
        out[pos] = lfilter([0.0, 1.0 - a], [1.0, -a], tau[pos], axis=0, zi=tau[pos][:1])[0]
    return out


def _refuse_gaps(**arrays: tuple[np.ndarray, Sequence[str]]) -> None:
    """Every sample of each ``name=(values, column names)`` a finite number: the bias
    estimates fit integrals from a run's first sample, and one empty cell (a gap) made every
    later integral, and so the estimate, NaN without a word."""
    for name, (values, columns) in arrays.items():
        values = np.asarray(values, dtype=np.float64).reshape(len(values), -1)
        bad = ~np.isfinite(values)
        if bad.any():
            row, axis = (int(k[0]) for k in np.nonzero(bad))
            raise NnidInputError(
                f"{name}: value {shown(values[row, axis])} is not a finite number "
                f"({int(bad.any(axis=1).sum())} such rows): the bias is fitted on integrals "
                "from the run's first sample, which a gap breaks; estimate it on a stretch "
                "without gaps",
                field=columns[axis],
                row=row,
            )


def estimate_accelerometer_bias(
    t: np.ndarray, velocity: np.ndarray, accel: np.ndarray
) -> np.ndarray:
    """Constant accelerometer bias b from velocity (DVL) and acceleration (McCarter eqs 2.84-2.85).

    v(t) = v(t₀) + ∫(a − b) dτ, so v(t) − ∫a dτ = v(t₀) − b (t − t₀): least squares per axis.
    """
    _refuse_gaps(t=(t, ["t"]), velocity=(velocity, VELOCITY[:3]), accel=(accel, ACCELERATION[:3]))
    integral = cumulative_trapezoid(accel, t, axis=0, initial=0.0)
    design = np.stack([np.ones_like(t), -(t - t[0])], 1)
    coef, *_ = np.linalg.lstsq(design, velocity - integral, rcond=None)
    return coef[1]


def estimate_gyro_bias(t: np.ndarray, angles: np.ndarray, gyro: np.ndarray) -> np.ndarray:
    """Constant gyro bias b from attitude and rates (McCarter eqs 2.86-2.87).

    Θ(t) = Θ(t₀) + ∫ T_Θ(Θ) (ω − b) dτ; with T_Θ evaluated on the measured attitude this is
    linear in Θ(t₀) and b, solved by least squares over all samples and axes. A run with a
    gap (an empty angle or rate) is refused, naming it: the integrals cannot cross it.
    """
    _refuse_gaps(t=(t, ["t"]), angles=(angles, ANGLES), gyro=(gyro, VELOCITY[3:]))
    tmat = euler_rate_matrices(angles)
    rate_integral = cumulative_trapezoid(np.einsum("nij,nj->ni", tmat, gyro), t, axis=0, initial=0)
    t_integral = cumulative_trapezoid(tmat, t, axis=0, initial=0)  # ∫ T_Θ dτ, [N, 3, 3]
    n = t.size
    design = np.zeros((3 * n, 6))
    design[:, :3] = np.tile(np.eye(3), (n, 1))
    design[:, 3:] = -t_integral.reshape(3 * n, 3)
    target = (np.unwrap(angles, axis=0) - rate_integral).reshape(3 * n)  # finite: checked
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    return coef[3:]


# --- the pipeline -----------------------------------------------------------------------------


class PreprocessConfig(BaseModel):
    """What preprocessing does to a log; everything off unless asked."""

    model_config = ConfigDict(extra="forbid")
    rate: float | None = Field(None, gt=0)
    gap: float | None = Field(None, gt=0)
    unwrap: bool = True
    jumps: list[str] = Field(default_factory=list)
    jump_threshold: float = Field(6.0, gt=0)
    lowpass: list[str] = Field(default_factory=list)
    cutoff: float = Field(5.0, gt=0)
    savgol_window: float = Field(0.5, gt=0)
    savgol_order: int = Field(4, ge=1, le=8)
    velocities: Literal["keep", "derive", "replace"] = "keep"
    accelerations: bool = False


def preprocess(
    log: pd.DataFrame,
    cfg: PreprocessConfig,
    report: CleaningReport | None = None,
    actuator_lag: float = 0.0,
) -> tuple[pd.DataFrame, CleaningReport]:
    """Run the configured steps in order; return the log and the report. ``actuator_lag``:
    the vehicle's (s), where known: behind a lag the force felt is continuous, so accelerations
    derived across the steps of held commands have no jump to smear, and are not warned of
    (as a fit's held-input warning, :func:`nnid.models.parametric.warn_held_inputs`)."""
    report = report or CleaningReport()
    if cfg.rate:
        log = resample_log(log, cfg.rate, cfg.gap, report)
    if cfg.unwrap:
        log = unwrap_angles(log, report)
    if cfg.jumps:
        log = repair_jumps(log, cfg.jumps, threshold=cfg.jump_threshold, report=report)
    if cfg.lowpass:
        log = lowpass(log, cfg.lowpass, cfg.cutoff, report=report)
    derived = cfg.velocities != "keep"
    if derived:
        log = derive_velocities(
            log, cfg.savgol_window, cfg.savgol_order, report, overwrite=cfg.velocities == "replace"
        )
    if cfg.accelerations and not all(c in log for c in ACCELERATION):
        log = derive_accelerations(
            log, cfg.savgol_window, cfg.savgol_order, report, warn_uneven=not derived
        )
        held, dt = held_at(log) if actuator_lag == 0 else ([], float("nan"))
        if held:
            # a fit then reads them as logged, and its own held-input warning cannot fire;
            # the smear does not shrink with the sample time, so at every rate
            warnings.warn(
                f"the accelerations were derived by Savitzky-Golay across the steps of the "
                f"inputs {', '.join(held)}, which are held between samples (at least "
                f"{100 * HELD_SHARE:.0f} % of their samples repeat the one before; "
                f"Δt = {dt:.3g} s): the window smears each jump of the acceleration, which a "
                "fit on them reads as inertia (on a simulated Seamor log of held yaw steps "
                "N_ṙ came out 8-12 % off at 10-100 Hz with zoh_midpoint, 16-47 % without). "
                "Leave the accelerations to the model, with zoh_midpoint = true, which "
                "differentiates between the steps",
                ExcitationWarning,
                stacklevel=2,
            )
    return log, report
