"""Missing motion samples: a DVL that drops out in bursts while the pose and gyro go on.

An empty cell in a pose or velocity column is a gap, never a number. Gaps are handled in two
ways, each written to the cleaning report with counts, seconds and the longest gap (the
seconds missing: the missing samples times the sample interval, so 400 lone samples missing
at 20 Hz are 20 s, not the 40 s spanned between their present neighbours):

- **bridged** from the pose, as the log contract derives velocities (Savitzky-Golay rates and
  ν = J⁻¹(η) η̇, McCarter eq. 2.15): p q r wherever the attitude is complete, u v w wherever the
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
change the noise of a Savitzky-Golay derivative; they are bridged from the pose where it
allows, and the report says why. Masking one would take every row between its samples out
(its runs, in pieces of one row): a fit takes each run it is slow in out whole and says so, and
refuses a log that leaves nothing of (:func:`mask_gaps`, :func:`refuse_slow`). The rows
of a run before a slow channel's first sample or after its last are outside its sampled span,
said as such (:func:`span_ends`), not as a gap; a fit takes them out with the gaps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace

import numpy as np
import pandas as pd

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.log import (
    ANGLES,
    MOTION,
    PIECE_OF,
    POSE,
    VELOCITY,
    _experiment_sorted,
    _filled,
    euler_rate_matrices,
    turned_by,
    typical_step,
    wrap_angle,
)
from nnid.datasets.preprocess import derive_velocities, experiment_rows, true_runs
from nnid.errors import NnidInputError

#: a segment left between two gaps shorter than this many samples is masked with them
MIN_SEGMENT = 3
#: the ``DataFrame.attrs`` key of a log :func:`mask_gaps` cut at its gaps, where a run's rows
#: went on after its last piece kept (samples missing, and pieces too short to use): that
#: piece's label -> ``seconds`` (from its last row to its run's last in the log) and
#: ``samples`` (those of the short pieces dropped there). Detection says a window that ends
#: there cut short by a gap, not by the end of its run
DROPPED_TAILS = "nnid_dropped_tails"
#: the cleaning steps that say what became of the gaps (bridged from the pose, masked, or left
#: in a motion column no model reads: its own step, so no summary reads it as gaps masked)
BRIDGE_STEP, MASK_STEP, UNREAD_STEP = "bridge velocity gaps", "mask gaps", "unread motion"
GAP_STEPS = (BRIDGE_STEP, MASK_STEP, UNREAD_STEP)
#: a channel is logged slower than the clock when at least this share of the steps between
#: its samples is one stride of two rows or more (a sample landing a row early or late on a
#: merged clock is the rest)
SLOW_SHARE = 0.9
#: the fewest steps between a channel's samples that show it slow, not a few lone samples
SLOW_MIN_STEPS = 10
#: the most runs a sentence names for one rate of a slow channel (the rest are counted)
SAY_RUNS = 3
#: the most of a slow channel's own steps one interpolation spans: a longer hole is a gap
SLOW_SPAN = 3
#: the cleaning step that says which channels were slow and what became of them
SLOW_STEP = "slow channels"
#: the body rates that turn the attitude between a slow channel's samples
GYRO = ("p", "q", "r")


@dataclass
class SlowChannel:
    """A channel logged every ``stride`` rows of its runs' clock (module docstring); or, with
    ``samples``, one whose rate could not be measured in ``runs`` (:func:`slow_channels`)."""

    column: str
    stride: int  # rows between its samples, most of the time; 0 where not measured
    rate_hz: float | None  # its own rate: the clock's over the stride; None: not measured
    clock_hz: float  # its runs': 1 / the median of their sample steps (each run's typical_step)
    # the runs it is logged at this rate in; None: every run with an empty cell of it (a log
    # may join runs logged at different rates, each measured on its own)
    runs: list[str] | None = None
    # where its rate could not be measured: its samples in each of ``runs``, too few to
    # measure a rate on and with no other run of it measured at one they fit
    samples: list[int] | None = None

    def describe(self) -> str:
        """'z logged every 10th row: 2 Hz against 20 Hz' (and 'in a, b' for some runs, 'in 350
        runs (a, b, c and 347 more)' for many: the whole list is ``runs``, e.g. in
        ``inspect``'s summary.json); 'z's rate could not be measured in b (6 samples): …' (with
        ``runs`` None, where a sentence names the run already: '… measured (6 samples): …')."""
        if self.rate_hz is None:
            counts = [f"{n} sample{'s' * (n != 1)}" for n in self.samples or []]
            if self.runs is None:
                where = f"({', '.join(counts)})"
            else:
                where = f"in {some_runs(self.runs, counts)}"
            return (
                f"{self.column}'s rate could not be measured {where}: fewer than the "
                f"{SLOW_MIN_STEPS + 1} samples a rate needs, and no other run of it measured "
                "at a rate they fit"
            )
        k = self.stride
        suffix = "th" if 10 <= k % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(k % 10, "th")
        where = "" if self.runs is None else f" in {some_runs(self.runs)}"
        return (
            f"{self.column} logged every {k}{suffix} row{where}: {self.rate_hz:.3g} Hz against "
            f"{self.clock_hz:.3g} Hz"
        )


def some_runs(runs: list[str], counts: list[str] | None = None) -> str:
    """'a, b' or, past :data:`SAY_RUNS` runs, '350 runs (a, b, c and 347 more)': a log cut
    into hundreds of runs made a sentence hundreds of names long. ``counts``: what to say of
    each run in brackets after its name."""
    said = runs if counts is None else [f"{r} ({n})" for r, n in zip(runs, counts, strict=True)]
    if len(said) <= SAY_RUNS:
        return ", ".join(said)
    return f"{len(said)} runs ({', '.join(said[:SAY_RUNS])} and {len(said) - SAY_RUNS} more)"


def _stride(steps: np.ndarray) -> int:
    """The rows between a channel's samples in one run where at least :data:`SLOW_SHARE` of
    ``steps`` are that one stride of two rows or more; else 0 (dropouts, or no step)."""
    if not steps.size:
        return 0
    values, counts = np.unique(steps, return_counts=True)
    stride = int(values[np.argmax(counts)])
    return stride if stride >= 2 and counts.max() >= SLOW_SHARE * steps.size else 0


def slow_channels(log: pd.DataFrame, columns: list[str] | None = None) -> list[SlowChannel]:
    """The channels of ``columns`` (default: pose, velocity, acceleration) logged slower than
    the clock, measured in each run on its own clock: at least :data:`SLOW_SHARE` of the steps
    between a channel's samples within the run are one stride of two rows or more, over at
    least :data:`SLOW_MIN_STEPS` steps; runs at one stride and rate are one entry. A channel
    without an empty cell, or with scattered dropouts (its usual step one row), is not
    slow. A run with fewer steps, one stride apart, or a lone sample of it, is judged by the
    rate the channel's other runs measure, where its steps show it (a lone sample shows no
    step, so none does); else it is an entry whose rate could not be measured (``rate_hz``
    None, with each run's ``samples``)."""
    columns = [c for c in (columns or MOTION) if c in log]
    if not columns or not log[columns].isna().to_numpy().any():
        return []
    codes, names, order, _, _, step = _experiment_sorted(log)
    out = []
    for c in columns:
        present = log[c].notna().to_numpy()[order]
        if present.all():
            continue
        rows = np.flatnonzero(present)
        within = codes[rows[1:]] == codes[rows[:-1]]
        spacing, runs_of = np.diff(rows)[within], codes[rows[1:]][within]  # sorted by run
        lacking = np.unique(codes[~present])  # the runs with an empty cell of it
        lo, hi = (np.searchsorted(runs_of, lacking, side) for side in ("left", "right"))
        counted = np.bincount(codes[rows], minlength=len(names))  # its samples in each run
        rates: dict[tuple[int, str], list[int]] = {}  # (stride, clock as said): runs
        short: dict[int, int] = {}  # a run with too few steps to measure: the stride it shows
        for e, a, b in zip(lacking, lo, hi, strict=True):
            steps = spacing[a:b]
            if not step[e] > 0:
                continue
            stride = _stride(steps)
            if steps.size < SLOW_MIN_STEPS:
                # samples one stride apart, or a lone sample (no step): too few to measure,
                # judged by the channel's other runs below; scattered dropouts are not slow
                if counted[e] and (stride or not steps.size):
                    short[int(e)] = stride
                continue
            if stride:
                rates.setdefault((stride, f"{1.0 / step[e]:.3g}"), []).append(int(e))
        # A run with under SLOW_MIN_STEPS steps of it (a short run a reader cut, a few samples)
        # was not judged: its empty cells became gaps, masked into pieces of one row and lost
        # as 'too short'. It is judged by the rate measured on the other runs of the channel,
        # where its steps show that rate; else its rate could not be measured, and it is said
        # so, by run and samples: its runs go whole as a slow channel's do, never as gaps.
        measured = [1.0 / (k * float(np.median(step[r]))) for (k, _), r in rates.items()]
        unmeasured = []
        for e, stride in short.items():
            rate = 1.0 / (stride * step[e]) if stride else np.nan
            if any(np.isclose(rate, r, rtol=0.01) for r in measured):
                rates.setdefault((stride, f"{1.0 / step[e]:.3g}"), []).append(e)
            else:
                unmeasured.append(e)
        for (stride, _), runs in rates.items():
            runs = sorted(runs)
            clock = float(np.median(step[runs]))
            every = len(rates) == 1 and len(runs) == lacking.size
            named = None if every else [str(names[e]) for e in runs]
            out.append(SlowChannel(c, stride, 1.0 / (stride * clock), 1.0 / clock, named))
        if unmeasured:
            clock = 1.0 / float(np.median(step[unmeasured]))
            said = [str(names[e]) for e in unmeasured]
            out.append(SlowChannel(c, 0, None, clock, said, [int(counted[e]) for e in unmeasured]))
    return out


def fill_slow(log: pd.DataFrame, report: CleaningReport | None = None) -> pd.DataFrame:
    """``log`` with the empty cells of each slow roll, pitch or yaw (:func:`slow_channels`)
    beside a complete gyro filled between two of its samples within each experiment with what
    p q r turn it through, η̇ = T_Θ(η) ω (Weiss eq. 17), and what the gyro leaves unexplained
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
    kept = [ch.describe() for ch in slow if ch not in filling and ch.rate_hz is not None]
    unmeasured = [ch.describe() for ch in slow if ch.rate_hz is None]
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
                "bridged from the pose where it allows, else a fit that reads it takes its runs "
                "out (refused where that leaves nothing; a fit that does not, e.g. of x y, "
                "leaves it)"
            )
        if unmeasured:
            detail.append(
                f"{'; '.join(unmeasured)}: not filled, nor its empty cells masked as gaps (they "
                "may be its rate): a fit that reads it takes those runs out (refused where that "
                "leaves nothing; a fit that does not leaves it)"
            )
        columns = list(dict.fromkeys(ch.column for ch in slow))
        report.add(SLOW_STEP, "; ".join(detail), columns=columns)
    return out


def gyro_filled(log: pd.DataFrame, slow: list[SlowChannel]) -> list[SlowChannel]:
    """The channels of ``slow`` that :func:`fill_slow` fills: roll, pitch and yaw, where the
    log holds all three and a gyro (p q r; its own empty cells leave the spans they fall in
    unfilled)."""
    held = all(c in log for c in (*ANGLES, *GYRO))
    # a rate not measured gives no span to fill across: such a run goes whole (slow_channels)
    return [ch for ch in slow if held and ch.column in ANGLES and ch.rate_hz is not None]


def between_samples(log: pd.DataFrame, slow: list[SlowChannel] | None = None) -> pd.DataFrame:
    """``log`` as ``inspect`` counts its gaps: every slow channel's cells (``slow``, else
    :func:`slow_channels`) between its own samples filled linearly (the cells its rate leaves
    empty), and those outside its sampled span in a run (before its first sample, after its
    last: said apart, :func:`span_ends`) held at its nearest sample, as is every empty cell of
    a run whose rate could not be measured (said as that slow channel, they may be its rate);
    none is a gap, and what ``inspect`` counts as missing is the rest."""
    slow = slow_channels(log) if slow is None else slow
    out = _between_samples(log, slow, {})[0]
    codes, _, order, _, _, _ = _experiment_sorted(log)
    for column in dict.fromkeys(ch.column for ch in slow):
        rows = _slow_rows(log, [ch for ch in slow if ch.column == column])
        before, after = _beyond_span(log[column].notna().to_numpy()[order], codes)
        edges = np.empty(len(log), dtype=bool)
        edges[order] = before | after
        # a run whose rate could not be measured: its empty cells may be that rate, said
        # once as the slow channel (its entry), never counted again as gaps
        unmeasured = [ch for ch in slow if ch.column == column and ch.rate_hz is None]
        edges |= _slow_rows(log, unmeasured)
        edges &= rows
        values = out[column].to_numpy(np.float64)[:, None]
        held = nearest_samples(log, values, pieces=False)[:, 0]
        out.loc[edges, column] = held[edges]
    return out


def nearest_samples(log: pd.DataFrame, values: np.ndarray, pieces: bool = True) -> np.ndarray:
    """``values`` [N, k] (columns of ``log``'s rows, in its order) with each NaN taken from its
    run's last sample before it, else its first after; NaN stays only where a run holds no
    sample of that column. With ``pieces``, a piece cut at a gap (``piece_of``) is held within
    the run it was cut from (a simulated pose's start, the fault monitor's held pose); without,
    within its own label, as :func:`between_samples` counts each experiment's span."""
    if not np.isnan(values).any():
        return values
    runs = log["experiment"] if "experiment" in log else pd.Series(0, log.index)
    if pieces and PIECE_OF in log:  # a piece (a#1) may hold no sample of x where its run does
        runs = log[PIECE_OF].where(log[PIECE_OF].notna(), runs)
    held = pd.DataFrame(values).groupby(runs.to_numpy(object), sort=False)
    return held.ffill().fillna(held.bfill()).to_numpy()


def _beyond_span(present: np.ndarray, codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(before, after): the rows (sorted by experiment, :func:`_experiment_sorted`) before a
    channel's first sample in their run and after its last, ``present`` where it has one;
    every row of a run without a sample is both. The rows outside its sampled span, which
    :func:`between_samples` holds and :func:`span_ends` counts."""
    n = present.size
    rows = np.arange(n)
    start, stop = np.searchsorted(codes, codes, "left"), np.searchsorted(codes, codes, "right")
    last_seen = np.maximum.accumulate(np.where(present, rows, -1))  # at or before each row
    next_seen = np.minimum.accumulate(np.where(present, rows, n)[::-1])[::-1]  # at or after
    return last_seen < start, next_seen >= stop


def span_ends(log: pd.DataFrame, ch: SlowChannel) -> list[dict]:
    """Each run of ``ch`` whose rows go on before its first sample or after its last: the run
    (None in a log of one), the time of its first and last sample, and the rows before and
    after them. They are outside its sampled span, not gaps in it: a channel logged every k-th
    row leaves up to k - 1 rows after its last sample by its rate alone."""
    codes, names, order, t, _, _ = _experiment_sorted(log)
    present = log[ch.column].notna().to_numpy()[order]
    before, after = _beyond_span(present, codes)
    mine = _slow_rows(log, [ch])[order]
    n_before, n_after, n_present = (
        np.bincount(codes[rows], minlength=len(names)) for rows in (before, after, present)
    )
    out = []
    for e in np.unique(codes[mine]):
        if not n_present[e] or not (n_before[e] or n_after[e]):
            continue  # no sample in the run (nothing to say it by), or none outside its span
        a, b = np.searchsorted(codes, e, "left"), np.searchsorted(codes, e, "right")
        first, last = a + n_before[e], b - 1 - n_after[e]  # its first and last sample
        name = None if len(names) == 1 else str(names[e])  # one run: no need to name it
        out.append({"experiment": name, "first_t": float(t[first]), "before": int(n_before[e]),
                    "last_t": float(t[last]), "after": int(n_after[e])})  # fmt: skip
    return out


def say_ends(ends: list[dict]) -> str:
    """:func:`span_ends` in words: 'its samples end at t = 19.5 s: 9 rows after its last'."""
    said = []
    for end in ends:
        where = "" if end["experiment"] is None else f"in {end['experiment']}, "
        parts = []
        if end["before"]:
            parts.append(
                f"start at t = {end['first_t']:.4g} s: {end['before']} "
                f"row{'s' * (end['before'] != 1)} before its first sample"
            )
        if end["after"]:
            parts.append(
                f"end at t = {end['last_t']:.4g} s: {end['after']} "
                f"row{'s' * (end['after'] != 1)} after its last sample"
            )
        said.append(f"{where}its samples {'; they '.join(parts)}")
    return "; ".join(said)


def _slow_rows(log: pd.DataFrame, slow: list[SlowChannel]) -> np.ndarray:
    """Which rows of ``log`` (in its own order) belong to a run that a channel of ``slow`` is
    logged slower in: its ``runs``, or, where they are None, each run with an empty cell of it
    (a run that logs it on every row is not one)."""
    if "experiment" not in log:
        return np.full(len(log), bool(slow))
    names = log["experiment"].astype(str)
    out = np.zeros(len(log), dtype=bool)
    for ch in slow:
        runs = names[log[ch.column].isna()].unique() if ch.runs is None else ch.runs
        out |= names.isin(runs).to_numpy()
    return out


def still_slow(parts: list[pd.DataFrame], columns: list[str]) -> list[SlowChannel]:
    """The channels of ``columns`` still logged slower than the clock in the parts of one log,
    measured on them joined (:func:`slow_channels`: not filled from the gyro, nor bridged from
    the pose by now)."""
    parts = [p for p in parts if len(p)]
    if not any(p[[c for c in columns if c in p]].isna().to_numpy().any() for p in parts):
        return []  # nothing empty: no copy of the log
    joined = parts[0] if len(parts) == 1 else pd.concat(parts, ignore_index=True)
    return slow_channels(joined, [c for c in columns if c in joined])


def refuse_slow(
    parts: list[pd.DataFrame], slow: list[SlowChannel], part: str | None = None
) -> NnidInputError:
    """The error for a log that the ``slow`` channels (:func:`still_slow`) leave nothing of
    to fit: masking a slow channel's empty cells takes every row between its samples out, and
    a piece of one row between two is too short to use, so each run it is slow in goes; where
    that is every run of every part, it ended as 'the training split is empty'. It names
    each channel, its rate, the rows it empties and what to do. ``part``: the one part
    (e.g. 'validation', of ``parts`` its only one) whose every run went, the rest kept; it
    ended as 'the validation split is empty: hold out an experiment', which was untrue."""
    parts = [p for p in parts if len(p)]
    said = "; ".join(ch.describe() for ch in slow)
    its, it = ("its", "it") if len({ch.column for ch in slow}) == 1 else ("their", "them")
    # where slow_channels could not measure the rate, the empty cells may be it, not are
    are = "may be" if any(ch.rate_hz is None for ch in slow) else "are"
    if part is not None:
        runs = parts[0]["experiment"].astype(str).unique() if "experiment" in parts[0] else ["run"]
        return NnidInputError(
            f"{said}: the empty cells between {its} samples {are} {its} rate, not dropouts, and "
            f"a fit reads the motion on every row, so each run {it} is slow in is taken out "
            f"whole; that leaves nothing of the {part} part ({len(parts[0])} rows: "
            f"{', '.join(runs)}). Log {it} at the full rate, resample the log to {its} rate, "
            f"or put a run without {it} slow in the {part} part",
            field=slow[0].column,
        )
    emptied = [
        np.logical_or.reduce([_slow_rows(p, [ch]) & p[ch.column].isna().to_numpy() for ch in slow])
        for p in parts
    ]
    empty = int(sum(e.sum() for e in emptied))  # a slow channel's own cells, in its own runs
    return NnidInputError(
        f"{said}: the empty cells between {its} samples {are} {its} rate, not dropouts, and a "
        f"fit reads the motion on every row; masked as gaps they would take {empty} of the "
        f"{sum(map(len, parts))} rows out and leave pieces of one row, too short to fit, and "
        f"nothing of the log to fit on. Log {it} at the full rate, or resample the log to "
        f"{its} rate; a velocity is bridged between its samples where the log holds the whole "
        "pose (x y z, roll, pitch, yaw), and an attitude filled where it holds a gyro (p q r)",
        field=slow[0].column,
    )


def _slow_runs(parts: list[pd.DataFrame], slow: list[SlowChannel]) -> list[np.ndarray]:
    """Each part's rows (in its own order) of the runs that a channel of ``slow`` is logged
    slower in (:func:`_slow_rows`), the same runs in every part: a block split puts pieces of
    one run in several."""
    if not slow:
        return [np.zeros(len(p), dtype=bool) for p in parts]
    found = [_slow_rows(p, slow) for p in parts]
    if not any("experiment" in p for p in parts):
        return found
    runs = {str(e) for p, f in zip(parts, found, strict=True) if len(p) for e in p["experiment"][f]}
    return [p["experiment"].astype(str).isin(runs).to_numpy() if len(p) else f
            for p, f in zip(parts, found, strict=True)]  # fmt: skip


def _say_slow_runs(
    parts: list[pd.DataFrame], slow: list[SlowChannel], taken: list[np.ndarray]
) -> tuple[str, int]:
    """What :func:`mask_gaps` says of the runs it takes out whole (``taken``, each part's
    rows, :func:`_slow_runs`) because a channel of ``slow`` is logged slower in them: each
    run with its rows and its slow channels' rates (never as the gaps their empty cells
    would count as), and how many rows that is."""
    rows: dict[str, int] = {}
    why: dict[str, list[str]] = {}
    for p, mask in zip(parts, taken, strict=True):
        if not len(p):
            continue
        names = p["experiment"].astype(str) if "experiment" in p else pd.Series("run", p.index)
        for ch in slow:
            for run in names[_slow_rows(p, [ch])].unique():
                if ch.rate_hz is None:  # no rate to say: the run's own samples of it
                    n = (ch.samples or [])[(ch.runs or []).index(run)]
                    plain = replace(ch, runs=None, samples=[n]).describe()  # run said before
                else:
                    plain = replace(ch, runs=None).describe()  # its rate, the run said before
                if plain not in why.setdefault(run, []):
                    why[run].append(plain)
        for run, n in names[mask].value_counts(sort=False).items():
            rows[run] = rows.get(run, 0) + int(n)
    said = "; ".join(f"{run} ({rows[run]} rows): {', '.join(why[run])}" for run in why)
    # where slow_channels could not measure the rate, the empty cells may be it, not are
    are = "may be" if any(ch.rate_hz is None for ch in slow) else "are"
    return (
        f"{said}: taken out, not masked as gaps: the empty cells between a slow channel's "
        f"samples {are} its rate, a fit reads the motion on every row, and pieces of one row "
        "between them are too short to fit. Log it at the full rate, or resample the log to "
        "its rate, to fit on these runs",
        sum(rows.values()),
    )


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
    ±π or [0, 2π)); never across a hole longer than :data:`SLOW_SPAN` of its own steps (each
    run's own stride), nor across a row of ``blocked`` (the same order: where the turning is
    not known), nor before its first sample or after its last: those stay empty, the rows
    outside its span said as such (:func:`span_ends`), the rest as gaps. With what was done
    to each channel, said."""
    if not slow:
        return log, []
    out = log.copy()
    codes, _, order, t, _, _ = _experiment_sorted(log)
    said = []
    for column in dict.fromkeys(ch.column for ch in slow):
        channels = [ch for ch in slow if ch.column == column]
        limit = np.zeros(len(log), dtype=np.int64)  # a run where it is not slow: no fill
        for ch in channels:
            limit[_slow_rows(log, [ch])[order]] = SLOW_SPAN * ch.stride
        y = log[column].to_numpy(np.float64)[order]
        angle = column in ANGLES
        turned = turning.get(column, np.zeros_like(y))
        new = _filled(y - turned, t, codes, angle, max_rows=limit) + turned
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
        out[column] = values
        for ch in channels:
            mine = _slow_rows(log, [ch])[order]
            ends = span_ends(log, ch)
            outside = sum(e["before"] + e["after"] for e in ends)
            left = int((~np.isfinite(new[mine])).sum()) - outside
            holes = (
                f", {left} in longer holes"
                + " or where the gyro has empty cells" * bool(blocked is not None and blocked.any())
                + " left as gaps"
            ) * bool(left)
            span = (
                f"; {say_ends(ends)}: outside its sampled span, taken out with the gaps"
                if ends
                else ""
            )
            filled = int(np.isfinite(new[mine]).sum() - np.isfinite(y[mine]).sum())
            said.append(f"{ch.describe()} ({filled} samples between its own filled{holes}{span})")
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
    missing_s: float  # missing: rows × the experiment's sample step (typical_step)


def _gap_runs(part: pd.DataFrame, columns: list[str]):
    """(Gap, first row, stop row) of each gap of one experiment, rows by position."""
    name = part["experiment"].iloc[0] if "experiment" in part else None
    return _gaps_of(part[columns].isna().to_numpy(), part["t"].to_numpy(np.float64), name, columns)


def _gaps_of(missing: np.ndarray, t: np.ndarray, name: object, columns: list[str]):
    """:func:`_gap_runs` on one experiment's arrays: ``missing`` (rows × ``columns``), its
    times ``t`` and its name."""
    dt = typical_step(t, 0.0)
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
    # one pass over the log: a run without an empty cell (most of them) costs nothing more
    missing = log[columns].isna().to_numpy()
    t = log["t"].to_numpy(np.float64)
    names = log["experiment"] if "experiment" in log else None
    return [
        g
        for _, pos in experiment_rows(log)
        if missing[pos].any()
        for g, _, _ in _gaps_of(
            missing[pos], t[pos], None if names is None else names.iloc[pos[0]], columns
        )
    ]


def _summary(gaps: list[Gap]) -> str:
    seconds = sum(g.missing_s for g in gaps)
    longest = max((g.missing_s for g in gaps), default=0.0)
    order = list(MOTION)
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
    # a run's rows by position, as its cells are written: by label, a log joined by pd.concat
    # (labels repeated) read both runs as one and wrote a bridge into the other's rows too
    for _, pos in experiment_rows(log):
        part = log.iloc[pos]
        pose = [c for c in POSE if c in part]
        complete = [c for c in pose if part[c].notna().all()]
        if not all(a in complete for a in ANGLES):
            continue
        # derive_velocities sees no velocity column, so it makes each one the pose gives; w
        # from depth alone assumes u = v = 0, an approximation a bridge must not use. The
        # experiment column stays, so that what it warns of names the run, not "the log", and
        # piece_of, so that a piece cut at a gap shorter than the window gets no derivative
        # (it was refused as a run too short for the window)
        named = [c for c in ("experiment", PIECE_OF) if c in part]
        derived = derive_velocities(part[["t", *named, *complete]], window_s, order)
        can = [c for c in ("p", "q", "r") if c in velocity]
        if all(c in complete for c in ("x", "y", "z")):
            can += [c for c in ("u", "v", "w") if c in velocity]
        for gap, a, b in _gap_runs(part, velocity):
            # a short piece has no derivative: no column (nothing derived) or NaN on its rows
            cols = [
                c
                for c in gap.columns
                if c in can and c in derived and derived[c].iloc[a:b].notna().all()
            ]
            if gap.length_s > max_bridge_s or not cols:
                continue
            for c in cols:
                at = out.columns.get_loc(c)
                held = out.iloc[pos[a:b], at].to_numpy(np.float64)
                bridge = derived[c].to_numpy(np.float64)[a:b]
                out.iloc[pos[a:b], at] = np.where(np.isnan(held), bridge, held)
            bridged.append(replace(gap, columns=cols))
    if report is not None and bridged:
        report.add(
            BRIDGE_STEP,
            f"{_summary(bridged)} bridged from the pose by Savitzky-Golay "
            f"(order {order}, {window_s:g} s window) and J⁻¹(η)",
            columns=sorted({c for g in bridged for c in g.columns}, key=VELOCITY.index),
        )
    return out


#: how the training path says a simulated pose starts where an unread pose column is empty
SIMULATED_START = "a simulated pose starts from its run's last sample before (else its first after)"


def say_unread(
    log: pd.DataFrame,
    read: Sequence[str],
    report: CleaningReport | None,
    reader: str = "no model of this run reads",
    kept: str = "the fit and the scores, which read",
    start: str = SIMULATED_START,
) -> None:
    """Say in ``report`` each motion column with empty cells that is not masked because
    nothing reads it (``read``: those masked; ``reader`` says who does not, ``kept`` what the
    rows stay in and that it reads none): its rows are kept, not dropped, and an empty pose
    cell takes its run's last sample before, else first after (``start`` says what for;
    :func:`nearest_samples`)."""
    empty = {c: int(log[c].isna().sum()) for c in MOTION if c in log and c not in read}
    unread = [c for c, n in empty.items() if n]
    if report is None or not unread:
        return
    them = "them" if len(unread) > 1 else "it"
    report.add(
        UNREAD_STEP,
        f"{', '.join(unread)} not masked: {reader} {them} "
        f"({', '.join(f'{empty[c]} empty cells in {c}' for c in unread)}): their rows stay "
        f"in {kept} no cell of {them}"
        f"{f'; {start}' if any(c in POSE for c in unread) else ''}",
        columns=unread,
    )


def mask_gaps(
    parts: list[pd.DataFrame],
    columns: list[str],
    report: CleaningReport | None = None,
    names: Sequence[str] | None = None,
) -> list[pd.DataFrame]:
    """Take the rows with an empty cell in ``columns`` out of each part of one log (e.g. its
    training and held-out parts) and cut each run at them into segments ``<experiment>#<k>``
    (module docstring; k from 0, as :func:`nnid.datasets.preprocess.resample_log` and the
    readers count, each segment keeping the run's clock ``t``), reported once; a segment's
    ``piece_of`` column names its run, which is how a piece is told from a whole run (never
    by the ``#`` in its label, which a user's may hold too). Parts without gaps are returned
    as they are. A run in which a channel of ``columns`` is logged slower than the clock
    (:func:`still_slow`) is taken out whole and said as such, its rate, not gaps: masked, its
    empty cells would leave pieces of one row, too short to use; where that leaves nothing
    of the log, or of one part that had rows (``names``: each part's, as an error says it),
    it is refused (:func:`refuse_slow`): not as an empty split with another cause."""
    slow = still_slow(parts, columns)  # a slow channel's cells between its samples are no gaps
    slow_runs = _slow_runs(parts, slow)
    out, gaps, short = [], [], 0
    for log, taken in zip(parts, slow_runs, strict=True):
        cols = [c for c in columns if c in log]
        missing = log[cols].isna().any(axis=1).to_numpy() if cols else np.zeros(len(log), bool)
        if not missing.any() and not taken.any():
            out.append(log)
            continue
        gaps += find_gaps(log[~taken], cols)
        keep = ~missing & ~taken
        label = np.empty(len(log), dtype=object)
        piece_of = np.full(len(log), None, dtype=object)  # a reader's piece stays one
        if PIECE_OF in log:
            piece_of[:] = log[PIECE_OF].to_numpy(object)
        # the runs' own names: a piece named as another run would join it (rows by label)
        named = {str(n) for n in log["experiment"].unique()} if "experiment" in log else set()
        tails: dict[str, dict] = {}
        for name, pos in experiment_rows(log):
            runs = true_runs(keep[pos])
            for k, (a, b) in enumerate(runs):  # from #0, as resample_log and the readers
                if b - a < MIN_SEGMENT:
                    keep[pos[a:b]] = False
                    short += b - a
                base = "run" if name is None else str(name)
                piece = base if len(runs) == 1 else f"{base}#{k}"
                if piece != base and piece in named:
                    raise NnidInputError(
                        f"cutting experiment '{base}' at its gaps makes a piece '{piece}', the "
                        "name of another experiment of the log: its rows would join that run; "
                        "rename that experiment",
                        field="experiment",
                    )
                label[pos[a:b]] = piece
                if len(runs) > 1:
                    piece_of[pos[a:b]] = [base if pd.isna(p) else p for p in piece_of[pos[a:b]]]
            tail = _dropped_tail(log["t"].to_numpy(np.float64)[pos], runs)
            if tail is not None:
                tails[label[pos[tail.pop("last")]]] = tail
        cut = log.assign(experiment=label, **{PIECE_OF: piece_of})[keep].reset_index(drop=True)
        if tails:  # a new dict: pandas may share attrs with the log it was cut from
            cut.attrs = {**cut.attrs, DROPPED_TAILS: tails}
        out.append(cut)
    if slow and any(len(p) for p in parts) and not any(len(p) for p in out):
        raise refuse_slow(parts, slow)
    for k, (log, taken, kept) in enumerate(zip(parts, slow_runs, out, strict=True)):
        if len(log) and not len(kept) and taken.any():  # its runs went for their rate
            mine = [ch for ch in slow if _slow_rows(log, [ch]).any()] or slow
            raise refuse_slow([log], mine, names[k] if names else f"part {k + 1}")
    said, taken = _say_slow_runs(parts, slow, slow_runs) if slow else ("", 0)
    if report is not None and gaps:
        extra = f"; {short} samples between gaps too short to use" if short else ""
        report.add(
            MASK_STEP,
            f"{_summary(gaps)} masked (out of regressions and scores; runs cut into segments "
            f"at them, each simulated from its own start{extra})",
            rows_removed=sum(len(a) - len(b) for a, b in zip(parts, out, strict=True)) - taken,
            columns=sorted({c for g in gaps for c in g.columns}),
        )
    if report is not None and slow:
        columns = list(dict.fromkeys(ch.column for ch in slow))
        report.add(SLOW_STEP, said, rows_removed=taken, columns=columns)
    return out


def _dropped_tail(t: np.ndarray, pieces: list[tuple[int, int]]) -> dict | None:
    """Where a run (its clock ``t``, its present ``pieces`` as :func:`mask_gaps` cuts them)
    goes on after its last piece kept: that piece's ``last`` row (in ``t``), the ``seconds``
    from it to the run's last row, and the ``samples`` of the short pieces dropped there
    (:data:`DROPPED_TAILS`); None where its last piece kept ends the run, or none is kept."""
    kept = [(a, b) for a, b in pieces if b - a >= MIN_SEGMENT]
    if not kept or kept[-1][1] == t.size:
        return None
    end = kept[-1][1]
    samples = sum(b - a for a, b in pieces if a >= end)
    return {"last": end - 1, "seconds": float(t[-1] - t[end - 1]), "samples": int(samples)}


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
