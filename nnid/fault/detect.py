"""Detection end to end: the monitor over a log, each alarm isolated on the window after it.

The alarm records follow the ``detect.json`` contract (ARCHITECTURE.md): time, kind, thruster and
remaining efficiency, effect, severity (the peak of the larger statistic over its threshold in the
window) and confidence.

While an isolated change persists its residual keeps the statistics above their thresholds, and
the monitor alone would not re-arm until it ends: a second fault during the first would not be
alarmed. So after an alarm whose change is isolated (a hypothesis named that leaves no more than
noise, :data:`nnid.fault.isolation.UNEXPLAINED_RATIO`), the rest of the experiment is watched
on the residual that change leaves (the fitted hypothesis taken out, fresh EWMA and CUSUM from
the end of the isolation window, the same thresholds, each whitened DOF read against what the
change may leave there: :meth:`Rewatch.step`, the model's error growing where the change acts):
a new alarm there is a residual the first change no longer explains, and is isolated on that
residual (a thruster's efficiency stated against its nominal thrust, the losses taken out
before included).

An alarm that is not isolated (unexplained, not significant) has nothing to take out. Left as
they were, its statistics stayed above their thresholds long after such a change had gone: a
snag from 20 to 27 s left the CUSUM at 9,526 times its threshold at its window's end, the
monitor was blind for 72 minutes, and h1 at 30 % from 45 s was not alarmed. So the statistics
restart after its window too, on the residual watched as it is (the model's own, less any
isolated change taken out before). A change that persists then alarms again at once, and a
healthy second cannot tell a change gone from one not excited just then (a damping change reads
as noise while the vehicle barely moves): a later alarm on the restarted rows is isolated as
usual. Named and significant, it is a new change and a new record; not isolated again, it is
no new alarm but the unexplained change persisting, counted in its open record (``repeats``,
``last_seen_t`` and its ``meaning``: :func:`persisting`), and the statistics restart after its
window again. One unexplained record is open per run (the pieces a dropout cut it into,
:func:`run_key`, are one; so are the changes isolated, carried into its later pieces:
:func:`_rewatch`), from its first such alarm on: a second change that no hypothesis explains
reads as the first persisting, and so does a named fault that isolation cannot tell apart
from a change that persists in its window. An alarm whose window holds too few rows to isolate
(the log's end, a gap) is not judged (:func:`not_judged`): a record of its own, neither
opening nor repeating an unexplained one.

A change can also go away (a snag freed, a thruster that recovers): the residual it leaves is
then its signature reversed, which isolation would name as a new change (a pull the other way,
a thruster giving 170 %), and a window that straddles the end fits no hypothesis at all. So an
alarm on rows watched on what isolated changes leave is first tested for their end
(:func:`ended_alarm`): the changes held until a time τ in the window and gone after it, nothing
significant left of them after τ, yet the changes at their size rejected there (the rows after
τ would show them persisting: a thruster commanded about nothing after τ reads alike stopped or
working, and an end not measured is no end, the change stays taken out), and the model's own
residual (or what the changes still in effect leave) healthy noise from τ on. Such an alarm is
recorded as the change(s) having ended, and the rest is watched without them. A change can
also come back only partly (a stopped thruster back to 80 %) or grow (h1 from 50 % down to
20 %): an alarm that is no end, and not within what the changes may leave, or holding their
signature (a ballast from 10 N down to 4 N: :meth:`_Splits.signature_left`) or a new change in
the DOFs they leave alone (a ballast change after a snag: :meth:`_Splits.change_beside`), is then
tested for a change of their size at τ (:func:`resized_alarm`), refitted on the rows after it;
such an alarm is recorded as the change resized, and the rest is watched with it taken out at
its new size (:func:`rewatched_alarm` orders the tests, for batch and ``--follow`` alike). Each
test's "within what a hypothesis may leave" is isolation's one rule,
:func:`nnid.fault.isolation.allowed_ratio`, of the residual named at each call.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from scipy.special import expit

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.gaps import DROPPED_TAILS
from nnid.datasets.log import typical_step
from nnid.fault import kernel
from nnid.fault.isolation import (
    LEAST_ROWS,
    SIGNIFICANCE,
    STOPPED_SLACK,
    TOO_FEW,
    Diagnosis,
    Hypotheses,
    Refit,
    allowed_over,
    allowed_ratio,
    dof_noise_ratios,
    dof_weights,
    fits_rows,
    hypothesis_columns,
    isolate,
    model_error,
    refit,
    signature,
    whitened_power,
)
from nnid.fault.monitor import ResidualMonitor, Trace, held_seconds, monitor_inputs
from nnid.reports.cells import number

#: the columns of alarms.csv: the record's keys, and for an alarm that says an earlier change
#: ended or changed size (hypothesis ``change_ended``, ``change_resized``) ``change_t``, the
#: time τ it did so, and ``change_alarm_t``, the time of the alarm(s) that isolated it; so
#: too for an alarm isolated whose own change ended inside its window (:func:`ended_within`),
#: ``change_alarm_t`` then its own time (:func:`alarm_row`; the record has them under
#: ``ended`` or ``resized``); then, of an alarm that is not isolated, ``repeats`` and
#: ``last_seen_t`` (:func:`persisting`). No ``blind_until`` (nor ``blind`` in the record): they
#: said how long statistics left over their thresholds kept the monitor from re-arming after an
#: unexplained alarm, and the statistics now restart at every alarm's window end
#: (:func:`unexplained`), so they were always empty; a value never measured is not kept as one
ALARM_FIELDS = ["experiment", "t", "kind", "thruster", "efficiency", "efficiency_low",
                "efficiency_high", "effect", "value", "stderr", "severity", "confidence",
                "explained", "residual_ratio", "hypothesis", "meaning", "change_t",
                "change_alarm_t", "repeats", "last_seen_t"]  # fmt: skip


def alarm_row(record: dict) -> dict:
    """An alarm record as a row of alarms.csv (:data:`ALARM_FIELDS`)."""
    row = {k: record.get(k) for k in ALARM_FIELDS}
    of = record.get("ended") or record.get("resized")
    if of:
        row["change_t"] = of["t"]
        row["change_alarm_t"] = " ".join(f"{t:.2f}" for t in of["alarms"])
    return row


@dataclass
class DetectResult:
    """The trace watched, the alarm records and the seconds taken. ``withdrawn``: the alarms
    ``detect --follow`` announced ("ALARM t = …") that ``alarms`` does not hold, each with
    the alarm whose judgement withdrew it (:func:`withdrawn_record`); batch announces none,
    and the two agree on ``alarms``. ``dismissed`` (batch only; ``--follow`` says them
    withdrawn): the alarms judged within what the isolated changes may leave, no record,
    each with its ``experiment`` and ``t``, and ``beside_ratio`` and ``beside_allowed``, what
    it held over the DOF equations the changes leave alone and the level it was judged
    against there (:meth:`_Splits.change_beside`; None where the changes act on every one),
    and ``why`` (:func:`dismissed_why`), and ``cut_short`` where the log's end cut its
    window short, or a gap left its rows over part of it (:func:`on_part`). ``unjudged``:
    per experiment, the rows at its end that were not judged (:func:`unjudged_tail`), batch
    and ``--follow`` alike. ``dropped``: the rows watched before the trace's first (a long
    ``--follow`` forgets its older rows; none in batch). ``stopped``: why ``--follow`` stopped
    before its input ended (an interrupt, a refused row), None where it ended."""

    trace: Trace
    alarms: list[dict]
    seconds: float
    withdrawn: list[dict] = field(default_factory=list)
    dismissed: list[dict] = field(default_factory=list)
    unjudged: list[dict] = field(default_factory=list)
    dropped: int = 0
    stopped: str | None = None

    @property
    def samples(self) -> int:
        """The rows watched: those forgotten and those the trace holds."""
        return self.dropped + int(self.trace.t.size)


def dismissed_why(ratio: float | None, allowed: float | None, short: dict | None = None) -> str:
    """Why batch dismissed an alarm on what isolated changes leave (:attr:`DetectResult.
    dismissed`), from its reading beside the changes (:meth:`_Splits.change_beside`), and on
    how much of its window where the log's end (or a gap) cut it ``short`` (:func:`on_part`)."""
    within = "within what the isolated changes may leave"
    if ratio is None:
        why = f"{within} (they act on every DOF equation watched)"
    elif ratio <= allowed:
        why = f"{within}; beside them, no more than noise ({ratio:.3g} <= {allowed:.3g})"
    else:
        why = (
            f"{within}; beside them more than noise ({ratio:.3g} > {allowed:.3g}), but no new "
            "change named there leaves it within noise"
        )
    return why if short is None else f"{why}; {part_clause(short, DISMISSED_HOW)}"


def withdrawn_record(
    experiment: str | None,
    t: float,
    by: float,
    why: str,
    beside: tuple[float, float] | None = None,
    short: dict | None = None,
) -> dict:
    """An announced alarm at time ``t`` that the final alarms do not hold, as batch
    :func:`detect` drops it; ``why``: ``"dismissed"`` (its window within what the isolated
    changes may leave: :func:`rewatched_alarm`; said as batch's ``dismissed`` says it, by
    :func:`dismissed_why` of ``beside`` and ``short``, its :attr:`Verdict.beside` and
    :attr:`Verdict.cut_short`, and holding ``short`` as ``cut_short`` where there is one, as
    batch's entry does: detect.json says it in either mode), ``"inside"`` the window
    of the alarm at time ``by`` whose judgement restarted the statistics after it
    (:func:`_rewatch` clears the window's alarms), or ``"after"`` it (a row read before that
    judgement, watched again on the restarted statistics: ``--follow`` holds rows after a
    window until it is judged, so this is a safeguard, not a case it is known to reach), or
    ``"persisting"``: not isolated, the unexplained change alarmed at ``by`` persisting
    (:func:`persisting`, counted in its record)."""
    reasons = {
        "dismissed": dismissed_why(*(beside or (None, None)), short),
        "inside": f"inside the window of the alarm at t = {by:.2f} s, judged with it; the "
        "statistics restart after that window",
        "after": f"read before the alarm at t = {by:.2f} s was judged, after its window: "
        "watched again on the statistics restarted there",
        "persisting": f"not isolated: the unexplained change alarmed at t = {by:.2f} s "
        "persisting, counted in its record's repeats; the statistics restart after this window",
    }
    record = {"experiment": experiment, "t": float(t), "by": float(by), "reason": reasons[why]}
    if why == "dismissed" and short is not None:  # as batch's dismissed entry holds it
        record["cut_short"] = short
    return record


def isolated_alarm(
    monitor: ResidualMonitor,
    data: dict,
    trace: Trace,
    k: int,
    window_s: float,
    residual: np.ndarray | None = None,
    taken: Sequence[tuple[str, float]] = (),
) -> tuple[dict, Diagnosis, np.ndarray]:
    """The alarm that starts at row ``k``, isolated on [t_k, t_k + window_s]: its record, the
    diagnosis and the rows of the window. The window starts at the alarm, never before: the
    change began at or before the alarm, and healthy samples before its onset would bias the
    size of the change toward zero. ``residual`` [N, 6]: the one to isolate (the trace's own
    by default); ``taken``: the changes already taken out of it (:attr:`Rewatch.fitted`).

    A change isolated that ended inside its own window (:func:`ended_within`) is sized on its
    own span, the window's rows before its end (a 10 N ballast dropped 8 s into the window
    read 7.96 N on the whole window), and its record says when it ended (``ended``: τ and
    its own alarm; nothing of it is taken out after the window). The severity stays the
    window's."""
    rows = window_rows(data, k, window_s)
    residual = trace.values[:, 0:6] if residual is None else residual
    diag = isolate(monitor, data, residual, rows, list(taken))
    end = ended_within(monitor, data, k, window_s, residual, diag) if diag.isolated else None
    if end is not None:
        own = isolate(monitor, data, residual, rows[rows < end], list(taken))
        diag, end = (own, end) if own.isolated else (diag, None)
    severity = _severity(monitor, trace, rows)
    interval = diag.efficiency_interval or (None, None)
    name = trace.experiment[k]
    record = {
        "experiment": None if name is None else str(name),
        "t": float(data["t"][k]),
        "kind": diag.kind,
        "thruster": diag.thruster,
        "efficiency": diag.efficiency,
        "efficiency_low": interval[0],
        "efficiency_high": interval[1],
        "effect": diag.effect,
        "value": diag.value,
        "stderr": diag.stderr,
        "severity": severity,
        "confidence": diag.confidence,
        "meaning": diag.meaning,
        "explained": diag.explained,
        "residual_ratio": diag.residual_ratio,
        "hypothesis": diag.hypothesis,
        "p_value": diag.p_value,
        "alternatives": diag.alternatives,
        "components": diag.components,
        "repeats": None,  # an isolated change: no unexplained one persisting (unexplained())
        "last_seen_t": None,
    }
    if end is not None:
        t_end = float(data["t"][end])
        record["ended"] = {"t": t_end, "alarms": [record["t"]]}
        record["meaning"] = (
            f"{record['meaning']}; it ended at about {t_end:.2f} s, inside the window: sized "
            f"on the {t_end - record['t']:.3g} s before, and not taken out after the window"
        )
    short = on_part(data, k, window_s, rows, monitor.max_interval)
    if diag.meaning == TOO_FEW:  # isolation had too few rows: nothing was judged
        judged_on_part(record, short, None)
        finite = int(fits_rows(rows, residual[rows]).sum())
        not_judged(record, int(rows.size), finite, window_s)
        return record, diag, rows
    judged_on_part(record, short, ISOLATED_HOW if diag.isolated else UNEXPLAINED_HOW)
    if not diag.isolated:
        unexplained(record, float(data["t"][rows[-1]]))
    return record, diag, rows


def cut_short(data: dict, k: int, window_s: float, rows: np.ndarray) -> bool:
    """Whether the end of its experiment's rows cuts the isolation window of the alarm at row
    ``k`` short (:func:`window_rows`): the span from its last row to t_k + ``window_s`` is
    more than half the typical step of the window's rows, a sample missing. ``--follow``
    judges a window before its run ends only once it is whole, so batch and it agree."""
    t, codes = data["t"], data["experiment"]
    run = t[codes == codes[k]]
    # a grid t = i*dt ending one window after the alarm can end 1 ulp short of t_k + window_s:
    # no sample is missing there (one step: one is); a window of one sample has no step. The
    # step is read on the window's rows, which --follow holds as batch does: on the whole run,
    # batch read it on rows that --follow (which keeps its latest 100,000 to 200,000) had
    # forgotten, and a clock whose step drifted read another half step there
    return bool(t[k] + window_s - run[-1] > typical_step(t[rows], 0.0) / 2)


#: a window whose rows hold samples over less than this share of it, samples missing inside
#: its run (a gap in the log), is said judged on that part (:func:`on_part`), as one the log's
#: end cut short is
HELD_SHARE = 0.5


def on_part(data: dict, k: int, window_s: float, rows: np.ndarray, max_step: float) -> dict | None:
    """The ``cut_short`` key of the record of the alarm at row ``k`` whose isolation window
    (``rows``, :func:`window_rows`) holds samples over part of it only: the end of its run
    cuts it short (:func:`cut_short`; ``by`` "end"), or samples missing inside the run (a gap
    of more than ``max_step``) leave its rows over less than :data:`HELD_SHARE` of it (``by``
    "gap": a 10-s window of 10 rows over 0.45 s before a 10-s gap was isolated unsaid). The
    ``seconds`` its rows hold samples over (:func:`held_seconds`), ``window_s``, ``samples``
    and ``by``; None where it is whole, or holds samples over most of it."""
    held_s = held_seconds(data["t"][rows], max_step)
    code = int(data["experiment"][k])
    runs = data.get("experiment_runs")  # batch: a gap cut a run into pieces (piece_of)
    run = None if runs is None or runs[code] == data["experiment_names"][code] else runs[code]
    # a piece with a later one of its run ends at a gap (a dropout), not at the run's end
    later = run is not None and bool(np.any(runs[code + 1 :] == run))
    end = not later and cut_short(data, k, window_s, rows)
    if not end and held_s >= HELD_SHARE * window_s:
        return None
    short = {"seconds": held_s, "window_s": float(window_s), "samples": int(rows.size),
             "by": "end" if end else "gap"}  # fmt: skip
    if end and run is not None:  # the last piece of a run: its run's end, not the log's
        short["piece_of"] = str(run)
    # a run that went on after these rows, dropped at a gap (mask_gaps): not its end
    names = data.get("experiment_names")
    tail = None if names is None else data.get(DROPPED_TAILS, {}).get(str(names[code]))
    if end and tail and not np.any(names[code + 1 :] == names[code]):
        short["dropped"] = dict(tail)
    return short


#: what ended a window whose rows end with their run's (:func:`on_part`, ``by`` "end"), as
#: said (:func:`end_of`) where that run is whole
LOG_END = "the end of the log"
#: that, where the rows are the last piece a gap (a dropout) cut their run into
RUN_END = "the end of its run"


def end_of(short: dict | None) -> str:
    """What ended the window ``short`` (:func:`on_part`, ``by`` "end") as said: the end of the
    log (:data:`LOG_END`), or of its run (:data:`RUN_END`) where the window lies in the last
    piece a gap cut a run into; a gap, where the run went on in the log after the rows kept
    (``dropped``: samples missing, then pieces too short to use, :data:`DROPPED_TAILS`)."""
    dropped = short.get("dropped") if short else None
    if dropped:
        then = f", then {dropped['samples']} samples too few to use" if dropped["samples"] else ""
        return (
            f"a gap that dropped its run's last {dropped['seconds']:.2f} s (samples missing{then})"
        )
    return RUN_END if short and short.get("piece_of") else LOG_END


def before_end(end: str) -> str:
    """Where an alarm was judged on a window that ``end`` (:func:`end_of`) cut short."""
    return f"on the part of its window before {end}"


def part_clause(short: dict, how: str) -> str:
    """The clause that says an alarm was judged (``how``: :data:`ISOLATED_HOW`,
    :data:`UNEXPLAINED_HOW`, :data:`ENDED_HOW`, :data:`RESIZED_HOW`, :data:`DISMISSED_HOW`)
    on the part of its window that ``short`` (:func:`on_part`) holds: "isolated on the part …
    (3.00 s of 10 s)", before :func:`end_of` ``short``; :data:`ON_HELD` where samples missing
    inside the run, not the end of its rows, left that part."""
    where = ON_HELD if short.get("by") == "gap" else before_end(end_of(short))
    return f"{how} {where} ({short['seconds']:.2f} s of {short['window_s']:g} s)"


def judged_on_part(record: dict, short: dict | None, how: str | None) -> None:
    """An alarm's ``record`` judged on the window ``short`` (:func:`on_part`; None: whole,
    nothing to say): its ``cut_short`` key, and its ``meaning`` ending with what was judged
    there (``how``, as :func:`part_clause` takes it; None for a record :func:`not_judged`
    says). :func:`isolated_alarm` and the ends and resizes of :meth:`_Splits.record` alike: an
    end said on the 2 s a log kept of its window read as measured on all 10."""
    if short is None:
        return
    record["cut_short"] = short  # detect.json says so of every such alarm, judged or not
    if how is not None:  # finding() keeps the clause
        record["meaning"] = f"{record['meaning']}; {part_clause(short, how)}"


def cut_window(end: str) -> str:
    """How the ``meaning`` of a record whose window ``end`` (:func:`end_of`) cut short to
    fewer rows than isolation fits starts (:func:`not_judged`)."""
    return f"not judged: {end} cut the isolation window short"


#: that start where the end of the log cut it (:func:`cut_window`)
NOT_JUDGED = cut_window(LOG_END)
#: how the ``meaning`` of a record whose window, not cut by the log's end, holds fewer rows
#: than isolation fits (a gap in the log, or a window shorter than that many steps) starts
#: (:func:`not_judged`)
TOO_FEW_ROWS = "not judged: the isolation window holds too few rows"
#: how the ``meaning`` of a record whose window holds rows enough, but too few of them with a
#: finite residual (a sensor dropout, the run's last rows not judged), starts (:func:`not_judged`)
TOO_FEW_FINITE = "not judged: too few rows with a finite residual in the isolation window"
#: what the clause that ends the ``meaning`` of an alarm judged on part of its window says
#: after how it was read (:func:`part_clause`; the seconds follow), in place of
#: :func:`before_end`'s words where samples missing inside the run (a gap in the log) left the
#: window's rows over part of it (:func:`on_part`, ``by`` "gap")
ON_HELD = "on the part of its window that holds samples, the rest missing"
#: how that clause starts for a change isolated there (:func:`part_clause`)
ISOLATED_HOW = "isolated"
#: for an alarm isolation judged there and did not isolate: an unexplained change
UNEXPLAINED_HOW = "not isolated"
#: for the end of changes measured there (:func:`ended_alarm`)
ENDED_HOW = "the end measured"
#: for the new size of changes measured there (:func:`resized_alarm`)
RESIZED_HOW = "the new size measured"
#: ending its ``why``, for an alarm dismissed there (:func:`dismissed_why`)
DISMISSED_HOW = "judged"


def not_judged(record: dict, samples: int, finite: int, window_s: float) -> None:
    """The ``record`` of an alarm whose window (``window_s``) of ``samples`` rows holds fewer
    that isolation fits (``finite``, :func:`~nnid.fault.isolation.fits_rows`) than
    :data:`~nnid.fault.isolation.LEAST_ROWS` (said :data:`~nnid.fault.isolation.TOO_FEW`).
    The cause said is the one that left too few: fewer ``samples`` than that, the end of the
    log cut it short (:data:`NOT_JUDGED`; its ``cut_short`` key, which
    :func:`judged_on_part` sets, says how much of it there was) or else the window holds too
    few rows (:data:`TOO_FEW_ROWS`: a gap, ``cut_short`` ``by`` "gap" where the rows it holds
    span less than :data:`HELD_SHARE` of it, or a window of fewer steps than that at the
    log's rate); rows enough but too few of them with a finite residual, that (a dropout, the
    run's last rows not judged: :data:`TOO_FEW_FINITE`). A 0.5-s window of 6 rows at 10 Hz,
    every one finite, was said "too few rows with a finite residual (6 of the 6 …)", and one
    the log's end cut to 50 rows, 5 of them finite, "the end of the log cut the isolation
    window short". Not judged, not an unexplained change (no ``repeats``, no
    record opened for a later alarm to persist in, nor a repeat of one open: :func:`filed`).
    A 0.35-s window was an unexplained record whose statistics "restart at the window's
    end", and so was a window that a 10-s gap in the log left 5 rows. No hypothesis was
    fitted: ``confidence`` and ``explained`` are None, not measured (the diagnosis's 0 read
    "confidence 0.00, explaining 0 %"). On more rows isolation judges it, and an alarm it
    does not isolate is an unexplained change (:func:`part_clause`, :data:`UNEXPLAINED_HOW`)."""
    record["confidence"] = record["explained"] = None
    short = record.get("cut_short")
    by = None if short is None else short["by"]
    held = "" if short is None else f" over {short['seconds']:.2f} s of {short['window_s']:g} s"
    some = f", {finite} of them finite" if finite < samples else ""
    if samples < LEAST_ROWS and by == "end":  # how much of it the log kept says the rest
        said = cut_window(end_of(short))
        record["meaning"] = (
            f"{said} ({short['seconds']:.2f} s of {short['window_s']:g} s, {samples} "
            f"samples{some}): {TOO_FEW}"
        )
        return
    if samples >= LEAST_ROWS:  # rows enough: too few of them had a residual
        end = f", {end_of(short)} cutting it short" if by == "end" else ""
        said = f"{TOO_FEW_FINITE} ({finite} of the {samples} samples it holds{held}{end}"
    elif by == "gap":
        said = f"{TOO_FEW_ROWS} ({samples} samples{some}{held}, samples missing in the rest"
    else:  # the window itself spans too few steps at the log's rate
        said = f"{TOO_FEW_ROWS} ({samples} samples{some} in its {window_s:g} s"
    record["meaning"] = f"{said}; at least {LEAST_ROWS} needed): {TOO_FEW}"


def ended_within(
    monitor: ResidualMonitor,
    data: dict,
    k: int,
    window_s: float,
    residual: np.ndarray,
    diag: Diagnosis,
) -> int | None:
    """The row at which the change ``diag`` just isolated at row ``k`` ended inside its own
    window, or None where it persists. The window is split as :func:`ended_alarm` splits a
    later alarm's (:meth:`_Splits.ended`): the change taken out before τ, the ``residual``
    [N, 6] isolated (the model's, less the changes taken out before) after it, nothing
    significant of the change left after τ yet the change at its size rejected there, and that
    residual healthy noise there; at least :data:`CHANGED_S` on each side (the refit on the
    change's own span needs its rows). The end must also be the better reading by BIC (τ its
    one parameter): the confidence that :func:`ended_alarm`'s record states, over one half,
    against the change persisting."""
    w = Rewatch(monitor)
    w.changes.append(Change(float(data["t"][k]), "", list(diag.fitted)))
    rows = window_rows(data, k, window_s)
    r = residual[rows]
    splits = _Splits(monitor, data, k, window_s, w, r, w.left(data, rows, r))
    if splits.n < 2 * splits.least:
        return None
    # the gain of the best τ, as ended() finds it, before its refit (most changes persist:
    # the residual isolated after τ then holds the change, and no τ gains)
    bar = splits.persisting_bar()
    if np.min(splits.ended_costs(splits.power(splits.r))) >= bar:
        return None
    split = splits.ended()
    if split is None or split.j < splits.least or split.cost >= bar:
        return None
    return int(splits.rows[split.j])


def unexplained(record: dict, restart_t: float) -> None:
    """The ``record`` of an alarm that is not isolated, as the module docstring has it: the
    statistics restart at ``restart_t`` (its window's end) on the residual watched, and a later
    alarm that is not isolated either is this change persisting (:func:`persisting`), counted
    in ``repeats`` (0 here) with the time of the latest in ``last_seen_t`` (its own here).
    Restarted, the monitor is blind only over each alarm's window, as after any alarm: no
    blind time is left to state (the statistics left as they were kept it blind 72 minutes
    after a snag, a thruster lost in them unsaid)."""
    record["repeats"], record["last_seen_t"] = 0, record["t"]
    record["meaning"] = (
        f"{record['meaning'] or 'a change no hypothesis explains'}{RESTARTS}"
        f"({restart_t:.2f} s) with nothing more taken out (an isolated change "
        "before it stays taken out): a later alarm isolated is a new change, one that is not "
        "isolated either is this change persisting"
    )


#: how :func:`unexplained` starts its clause of a record's ``meaning``
RESTARTS = "; the statistics restart at the window's end "
#: how :func:`persisting` starts its clause of a record's ``meaning`` (rewritten each time)
PERSISTING = "; alarmed again "


def finding(record: dict) -> str:
    """What isolation said of an alarm: its ``meaning`` without the clauses that
    :func:`unexplained` and :func:`persisting` add to a record not isolated (the statistics'
    restart, and the later alarms taken as the change persisting, whose count a console line
    gives once, up front); the record keeps them."""
    return (record.get("meaning") or "").partition(RESTARTS)[0].partition(PERSISTING)[0]


def how_often(n: int) -> str:
    """A count of repeats as a person says it: "once", "3 times"."""
    return "once" if n == 1 else f"{n} times"


def persisting(record: dict, t: float, restart_t: float) -> None:
    """Fold an alarm at time ``t`` that is not isolated into the open unexplained ``record``
    of its experiment (:func:`unexplained`): no new record, the same change persisting (the
    statistics restarted after its window cannot tell it from a new one that no hypothesis
    explains either). ``repeats`` counts such alarms, ``last_seen_t`` is the latest, and the
    ``meaning`` says so once (its clause rewritten, not appended). ``restart_t``: the end of
    this alarm's window, where the statistics restart again. ``detect`` and ``detect
    --follow`` alike."""
    record["repeats"] += 1
    record["last_seen_t"] = float(t)
    base = record["meaning"].partition(PERSISTING)[0]
    record["meaning"] = (
        f"{base}{PERSISTING}{how_often(record['repeats'])} on the restarted statistics, the "
        f"latest at {t:.2f} s, not isolated: taken as this change persisting (restarted again "
        f"at {restart_t:.2f} s; a new change no hypothesis explains, or a fault not told apart "
        "from this one, reads the same)"
    )


def filed(
    record: dict, diag: Diagnosis, open_: dict[int, dict], code: int, restart_t: float
) -> tuple[bool, Change | None]:
    """How an alarm judged by :func:`isolated_alarm` is filed, ``detect`` and ``detect
    --follow`` alike (the module docstring): whether ``record`` is a new record, and the change
    taken out after its window. Isolated: new, its change taken out unless it ended. Not
    judged (:func:`not_judged`): new, whatever is open, and opening nothing: an alarm never
    judged is no evidence that an unexplained change persists (one that the log's end or a
    gap left too few rows was counted in the open record's repeats, "not isolated …
    persisting"). Not isolated, with an unexplained record open in its run ``code``
    (:func:`run_key`; ``open_``): the change persisting, folded into that record
    (:func:`persisting`; ``restart_t``, its window's end), no record; else a new record, which
    opens the run's unexplained record."""
    if diag.isolated:
        return True, None if record.get("ended") else Change.of(record, diag)
    if diag.meaning == TOO_FEW:  # not judged (not_judged): neither opens nor repeats a record
        return True, None
    if code in open_:
        persisting(open_[code], record["t"], restart_t)
        return False, None
    open_[code] = record
    return True, None


def _severity(monitor: ResidualMonitor, trace: Trace, rows: np.ndarray) -> float:
    """The peak of the larger statistic over its threshold on ``rows``."""
    h_t, h_g = monitor.threshold_values
    return float(np.nanmax(np.maximum(trace.values[rows, 18] / h_t, trace.values[rows, 19] / h_g)))


@dataclass
class Change:
    """An isolated change that a :class:`Rewatch` takes out: the time of its alarm, what it was
    (:func:`said`) and its fitted hypothesis (:attr:`Diagnosis.fitted`)."""

    t: float
    said: str
    fitted: list[tuple[str, float]] = field(default_factory=list)

    @classmethod
    def of(cls, record: dict, diag: Diagnosis) -> Change:
        return cls(record["t"], said(record), list(diag.fitted))


def said(record: dict) -> str:
    """An isolated change in a few words, as a later record recalls it."""
    if record.get("thruster") and record.get("efficiency") is not None:
        return f"thruster {record['thruster']} at {100 * record['efficiency']:.0f} % of nominal"
    if record.get("components"):
        parts = ", ".join(f"{n} {c['value']:.3g}" for n, c in record["components"].items())
        return f"{record['kind']}: {parts}"
    if record.get("effect"):
        return f"{record['effect']} {record['value']:.3g}"
    return str(record.get("hypothesis"))


#: the fewest seconds after the time τ at which changes ended or changed size that
#: :func:`ended_alarm` and :func:`resized_alarm` fit (and never fewer than the
#: :data:`~nnid.fault.isolation.LEAST_ROWS` rows a :func:`~nnid.fault.isolation.refit`
#: needs). A time, so that a log at another rate is split alike: 1 s is the acceleration
#: smoothing window of the fitted models (``savgol_window``) that an added-mass or payload
#: signature is smoothed over, so the rows after τ are not all rows whose smoothed
#: acceleration straddles τ; and it holds 120 whitened samples at 20 Hz, on which healthy
#: noise reads under :data:`~nnid.fault.isolation.UNEXPLAINED_RATIO`.
CHANGED_S = 1.0
#: what is left of a change after its end must not be significant at this level: its 95 %
#: interval, as the record states it, holds nominal (a thruster's 100 %, an effect's 0). The
#: change persisting at its size must also be rejected there, at isolation's
#: :data:`~nnid.fault.isolation.SIGNIFICANCE` (:meth:`_Splits.ended`)
ENDED_LEVEL = 0.05


@dataclass
class _Split:
    """The changes ``gone`` (indices into :attr:`Rewatch.changes`) ended or changed size at
    the window's row ``j``: ``kept`` the fitted hypotheses of the others, ``after`` the
    residual from row j on under the hypothesis, ``fit`` the gone changes' hypotheses refitted
    there, ``cost`` the window's whitened power under the hypothesis."""

    gone: list[int]
    kept: list[tuple[str, float]]
    j: int
    after: np.ndarray
    fit: Refit
    cost: float


class _Splits:
    """The window of an alarm on rows watched on what the changes of a :class:`Rewatch` leave,
    split at a time τ: ``left`` [rows, 6] (the residual watched) before τ, and after it what the
    model's residual ``r`` leaves with some changes gone (:meth:`ended`) or refitted
    (:meth:`resized`). All the changes are tried together, and each one alone where there are
    several. Each side of τ must be within what a hypothesis may leave
    (:func:`~nnid.fault.isolation.allowed_ratio`) of the model's residual on that side, or of
    the healthy noise where no change is left in effect."""

    def __init__(self, monitor, data, k, window_s, rewatch, r, left) -> None:
        self.monitor, self.data, self.rewatch = monitor, data, rewatch
        self.changes = rewatch.changes
        rows = window_rows(data, k, window_s)
        ok = np.isfinite(r).all(1) & np.isfinite(left).all(1) & (rows > 0)
        self.rows, self.r, self.left, self.n = rows[ok], r[ok], left[ok], int(ok.sum())
        self.dim = max(float(monitor.mask_.sum()), 1.0)
        self.least = max(LEAST_ROWS, int(np.ceil(CHANGED_S / monitor.interval - 1e-6)))
        self.p_left = self.power(self.left)
        self.before = np.r_[0.0, np.cumsum(self.p_left)]  # before[j]: on the rows before j
        self.sets = [list(range(len(self.changes)))]
        if len(self.changes) > 1:
            self.sets += [[i] for i in range(len(self.changes))]
        self._signature: bool | None = None
        self._new: Diagnosis | None = None
        # (the noise ratio, its allowed level) over the equations beside, once read
        self.beside: tuple[float, float] | None = None

    def usable(self) -> bool:
        """Enough rows, changes taken out, and what they leave more than noise may be, or
        their signature still in it (:meth:`signature_left`)."""
        return (
            self.n >= self.least
            and bool(self.changes)
            and (self.ratio(self.p_left) > allowed_ratio(1.0) or self.signature_left())
        )

    def signature_left(self) -> bool:
        """Whether ``left`` on the window still holds the changes' own signature: all their
        hypotheses refitted to it together significant (:data:`SIGNIFICANCE`, isolation's
        level) and taking out of it more power than the model's error in the model's residual
        there (:func:`~nnid.fault.isolation.model_error`). The window's power alone misses a
        change of size that a few DOF show: of a 10 N ballast down to 4 N, the 6 N left 1.4
        times the noise power (averaged over every DOF watched), within the 2 any hypothesis
        may leave, where the EWMA that alarmed averages the noise away; the change stayed
        taken out at 10 N. And the model's error, which grows with the change, is no change of
        its size: after a stopped thruster its refit was significant (a 1-3 % thrust change,
        taking out 0.05-0.9 times the noise power) in windows whose model's residual was
        135-1,100 times the noise (its error share: 2.7-22)."""
        if self._signature is None:
            self._signature = False
            fit = refit(self.monitor, self.data, self.left, self.rows, self.names(self.sets[0]))
            if fit is not None and fit.p_value <= SIGNIFICANCE:
                gain = self.ratio(self.p_left) - self.ratio(self.power(fit.left))
                self._signature = gain > model_error(self.ratio(self.power(self.r)))
        return self._signature

    def change_beside(self) -> bool | None:
        """Whether ``left`` holds a new change in the DOF equations that the changes leave
        alone, judged there as a first alarm is (None: more than noise there, on fewer rows
        than a first alarm's isolation needs, :data:`~nnid.fault.isolation.LEAST_ROWS`: not
        judged, so not dismissed either, and isolated as a first alarm is, which says
        :data:`~nnid.fault.isolation.TOO_FEW`): where their signature (``r`` less ``left``)
        has no more power than the noise, what ``left`` holds there is more than a hypothesis
        may leave of that noise (:meth:`beside_ratio` over
        :func:`~nnid.fault.isolation.allowed_over` those equations), and the alarm isolated as
        a new change (:meth:`new_change`) leaves no more there. :func:`explained_by_the_changes`
        allows a share of the model's residual, the model's error, which grows where the
        changes act on the motion; pooled over the DOFs, a snag's yaw moment (1 N m, 3,600
        times the noise power in yaw) lent heave, which it leaves alone, 13 times the noise,
        and a 10 N ballast change after it was dismissed at every window. A change's own error
        where its fitted signature is small stays within (a payload sized by its buoyancy left
        its unclaimed mass in pitch, up to 4.6 times the noise there, at most 1.70 over the
        five equations it leaves alone, where 2.12 is allowed)."""
        acts = dof_noise_ratios(self.monitor, self.r - self.left) > 1.0
        beside = (self.monitor.mask_ > 0) & ~acts
        if not beside.any():
            return False
        # read where measured: the equations the changes act on hold their share of the
        # model's error, and read as noise (1), unmeasured, they averaged a change in one
        # DOF down by six
        allowed = allowed_over(int(beside.sum()), self.dim)
        self.beside = (self.beside_ratio(self.left, beside), allowed)
        if self.beside[0] <= allowed:
            return False
        if self.n < LEAST_ROWS:  # the window cut short: "no new change" would be unmeasured
            return None
        new = self.new_change()
        if not new.isolated:
            return False
        after = _left(self.monitor, self.data, self.rows, self.left, new.fitted)
        return self.beside_ratio(after, beside) <= allowed

    def beside_ratio(self, e: np.ndarray, beside: np.ndarray) -> float:
        """The :func:`~nnid.fault.isolation.noise_ratio` of ``e`` [rows, 6] over the DOF
        equations ``beside`` [6] alone."""
        return float(dof_noise_ratios(self.monitor, e - self.monitor.mu_)[beside].mean())

    def new_change(self) -> Diagnosis:
        """The alarm isolated on ``left`` as a new change
        (:func:`~nnid.fault.isolation.isolate`, the changes taken out named to it), made once."""
        if self._new is None:
            residual = np.full((self.data["t"].size, 6), np.nan)
            residual[self.rows] = self.left
            self._new = isolate(self.monitor, self.data, residual, self.rows, self.rewatch.fitted)
        return self._new

    def power(self, e: np.ndarray) -> np.ndarray:
        """Each row's :func:`~nnid.fault.isolation.whitened_power` of ``e`` [rows, 6] (μ taken
        out here), summed over the DOF equations; NaN on a row that is not finite, so that row
        j stays row j (:attr:`before` and the splits index it)."""
        m = self.monitor
        e = e - m.mu_
        ok = np.isfinite(e).all(1)
        out = np.full(e.shape[0], np.nan)
        out[ok] = np.sum(whitened_power(m, e), axis=1)
        return out

    def ratio(self, p: np.ndarray) -> float:
        return float(p.sum()) / max(p.size * self.dim, 1.0)

    def names(self, gone: list[int]) -> list[str]:
        return list(dict.fromkeys(name for i in gone for name, _ in self.changes[i].fitted))

    def after_r(self, gone: list[int]) -> tuple[list, np.ndarray]:
        """The other changes' fitted hypotheses, and what they leave of ``r``."""
        kept = [f for i, c in enumerate(self.changes) if i not in gone for f in c.fitted]
        return kept, _left(self.monitor, self.data, self.rows, self.r, kept)

    def within(self, split: _Split, healthy: bool) -> bool:
        """Whether each side of τ is within what a hypothesis may leave: before τ, ``left``
        of the model's residual there (the changes in effect; shorter than the fewest rows
        fitted, it is not judged), from τ on ``split.after`` of the model's residual there,
        or of the healthy noise (``healthy``: no change left in effect)."""
        j = split.j
        if j >= self.least and self.ratio(self.p_left[:j]) > allowed_ratio(
            self.ratio(self.power(self.r[:j]))
        ):
            return False
        base = 1.0 if healthy else self.ratio(self.power(self.r[j:]))
        return self.ratio(self.power(split.after)) <= allowed_ratio(base)

    def ended(self) -> _Split | None:
        """The changes gone at τ (that minimises the window's whitened power), what is left of
        them refitted after τ not significant (:data:`ENDED_LEVEL`) and significantly less than
        their size taken out (:data:`~nnid.fault.isolation.SIGNIFICANCE`: the rows after τ
        would show them persisting), what is left from τ on within what the changes still in
        effect may leave (the healthy noise: no share, where none is). The split of least power
        where several are. Without the second test, v3 stopped and never back was said ended
        at 88.20 s on the 1 s after it, where v3 was commanded about 0.06 N: its refit, 87 ±
        50 % lost, held nominal and the loss alike, and the loss was alarmed again at 90.15 s."""
        best = None
        for gone in self.sets:
            kept, after_r = self.after_r(gone)
            cost = self.ended_costs(self.power(after_r))
            j = int(np.argmin(cost))
            names = self.names(gone)
            fit = refit(self.monitor, self.data, after_r[j:], self.rows[j:], names)
            if fit is None or fit.p_value <= ENDED_LEVEL:
                continue  # some of the change is left: not its end
            if fit.p_differs([_theta(self.changes, gone, n) for n in names]) > SIGNIFICANCE:
                continue  # the rows after τ would not show the change persisting: no end measured
            split = _Split(gone, kept, j, after_r[j:], fit, float(cost[j]))
            if self.within(split, healthy=not kept) and (best is None or split.cost < best.cost):
                best = split
        return best

    def ended_costs(self, p_after: np.ndarray) -> np.ndarray:
        """The window's whitened power split at each row j that an end may be at (at least
        :attr:`least` rows from it on): ``left`` before j, ``p_after`` (the power of what is
        left with the changes gone) from j on; :meth:`ended` takes its least, and
        :func:`ended_within` checks it first."""
        after = np.cumsum(p_after[::-1])[::-1]  # after[j]: from row j on
        return (self.before[:-1] + after)[: self.n - self.least + 1]

    def resized(self) -> _Split | None:
        """The changes of another size from τ on: refitted there (τ minimises the window's
        whitened power with them refitted after it), the new size significantly another
        (:data:`~nnid.fault.isolation.SIGNIFICANCE`, isolation's level), what is left from τ
        on within what a change may leave of the model's residual there. The split of least
        power where several are."""
        best = None
        for gone in self.sets:
            names = self.names(gone)
            kept, after_r = self.after_r(gone)
            j = self._resized_at(after_r, names)
            fit = (
                None
                if j is None
                else refit(self.monitor, self.data, after_r[j:], self.rows[j:], names)
            )
            if fit is None or fit.p_differs([_theta(self.changes, gone, n) for n in names]) > (
                SIGNIFICANCE
            ):
                continue  # the same size as taken out: not a change of it
            cost = float(self.before[j] + self.power(fit.left).sum())
            split = _Split(gone, kept, j, fit.left, fit, cost)
            # the sets are nested (all the changes, each alone): the larger always fits at
            # least as well, so they are compared as the record's confidence weighs them
            # (BIC: each refitted θ pays the penalty), not by power alone, which merged a
            # change that kept its size into one that changed
            if self.within(split, healthy=False) and (
                best is None
                or self.penalised(split.cost, len(split.fit.fits))
                < self.penalised(best.cost, len(best.fit.fits))
            ):
                best = split
        return best

    def penalty(self) -> float:
        """BIC's penalty of one parameter over the window's independent samples."""
        m = self.monitor
        return 0.5 * np.log(max(self.n * len(m.plant_.dofs_) / m.correlation_time_, 2.0))

    def persisting_bar(self, n_theta: int = 0) -> float:
        """The whitened power that the changes ending (or resized, ``n_theta`` θ refitted)
        must leave on the window, less than it, to be the better reading by BIC (τ and the
        θ its parameters) than them persisting: where :meth:`record` gives the end (or the
        new size) a confidence over one half."""
        return float(self.p_left.sum()) - self.penalised(0.0, 1 + n_theta)

    def penalised(self, cost: float, n_theta: int) -> float:
        """The whitened power ``cost`` left on the window plus the BIC penalty of ``n_theta``
        fitted θ, in whitened power."""
        return cost + 2 * self.monitor.correlation_time_ * self.penalty() * n_theta

    def new_change_fits_better(self, split: _Split) -> bool:
        """Whether a new change, as the alarm would be isolated on ``left`` otherwise
        (:func:`~nnid.fault.isolation.isolate`), leaves less of the window than ``split``
        (resized) does, and is another hypothesis than the one resized: then a fault came on
        top (a 6-DOF wrench resized takes up part of a thruster lost after it, within the share
        a large residual allows). Of the same hypothesis, the two are one fit, and the resize
        says it. Each pays the BIC penalty of its θ (:meth:`penalised`), as the resized sets
        do: by power alone, a snag's 6-DOF wrench resized (its w now 10 N) fitted a 10 N
        ballast change after the snag as closely as the ballast did (1,159.5 against 1,160.8
        of whitened power) with five θ more, and was said in its place."""
        diag = self.new_change()
        if not diag.isolated or {n for n, _ in diag.fitted} <= set(split.fit.fits):
            return False
        new = self.penalised(diag.residual_ratio * self.n * self.dim, len(diag.fitted))
        return new < self.penalised(split.cost, len(split.fit.fits))

    def _resized_at(self, after_r: np.ndarray, names: list[str]) -> int | None:
        """The row j at which ``left`` before it and ``after_r`` with the hypotheses ``names``
        fitted from it on (whitened least squares, in closed form for every j) have the least
        whitened power; None where a hypothesis has no column on the window."""
        m = self.monitor
        _, cands, cols = hypothesis_columns(m, self.data, self.rows, set(names))
        index = {c.name: k for k, c in enumerate(cands)}
        if any(name not in index for name in names):
            return None
        x = cols[:, :, [index[n] for n in names]]
        last = self.n - self.least + 1

        def suffix(v: np.ndarray) -> np.ndarray:  # sums from each row on
            return np.cumsum(v[::-1], axis=0)[::-1][:last]

        # θ as refit has it (isolate's per-DOF weights), so that the τ chosen is the one whose
        # refit leaves the least; the power it leaves, whitened by the full covariance
        e = after_r - m.mu_
        wt = np.sqrt(dof_weights(m, e))
        xw, ew = x * wt[None, :, None], e * wt
        theta = -np.einsum(
            "nkl,nl->nk",
            np.linalg.pinv(suffix(np.einsum("nik,nil->nkl", xw, xw))),
            suffix(np.einsum("nik,ni->nk", xw, ew)),
        )
        a = np.einsum("ij,njk->nik", m.whiten_, x)
        e = (after_r - m.mu_) @ m.whiten_.T
        g = suffix(np.einsum("nik,nil->nkl", a, a))
        b = suffix(np.einsum("nik,ni->nk", a, e))
        c = suffix(np.einsum("ni,ni->n", e, e))
        # ‖e + aθ‖² summed from row j on
        power = c + 2 * np.einsum("nk,nk->n", theta, b) + np.einsum("nk,nkl,nl->n", theta, g, theta)
        cost = self.before[:last] + power
        if not np.isfinite(cost).any():
            return None
        return int(np.nanargmin(cost))

    def record(self, trace: Trace, k: int, window_s: float, split: _Split, ended: bool) -> dict:
        """The alarm's record: the changes ``split.gone`` ended (``ended``) or resized, what
        is left of them refitted after τ (against nominal for a thruster)."""
        m, changes, gone, j = self.monitor, self.changes, split.gone, split.j
        names = list(split.fit.fits)
        thrusters = [n for n in names if n.startswith("thruster_loss.")]
        effects = [n for n in names if n not in thrusters]
        components = {}
        for name, fit in split.fit.fits.items():
            if name in thrusters:  # against nominal: what the changes kept take of it, and now
                eff = 1.0 - sum(t for n, t in split.kept if n == name) - fit["theta"]
                components[name] = {"value": eff, "stderr": fit["se"]}
            else:
                components[name] = {"value": fit["value"], "stderr": fit["value_se"]}
        if not ended and len(components) > 1:  # of a resized joint change, the members that
            # are significant now or were (its record and said() name them, as isolation's)
            clear = {
                n: c
                for n, c in components.items()
                if max(abs(split.fit.fits[n]["theta"]), abs(_theta(changes, gone, n)))
                >= 1.96 * split.fit.fits[n]["se"]
            }
            components = clear or components
        thruster = efficiency = low = high = effect = value = stderr = None
        kind = "model_change"
        if len(thrusters) == 1 and not effects:
            thruster = thrusters[0].split(".", 1)[1]
            efficiency = components[thrusters[0]]["value"]
            half = 1.96 * components[thrusters[0]]["stderr"]
            low, high = efficiency - half, efficiency + half
            if not ended and high >= -STOPPED_SLACK and low <= 1.0:  # a loss, as isolation says
                kind = "thruster_loss"
                efficiency, low, high = (float(np.clip(v, 0, 1)) for v in (efficiency, low, high))
        elif effects and not thrusters:
            # the clearest member of the change: its θ over the standard error now
            effect = max(
                [n for n in effects if n in components],
                key=lambda n: abs(_theta(changes, gone, n)) / max(split.fit.fits[n]["se"], 1e-300),
            )
            value, stderr = components[effect]["value"], components[effect]["stderr"]
            if not ended and all(n.startswith("external_bias.") for n in effects):
                kind = "external_force"
        t_split = float(self.data["t"][self.rows[j]])
        which = " and ".join(f"{changes[i].t:.2f} s ({changes[i].said})" for i in gone)
        when = f"{'by' if j == 0 else 'at about'} {t_split:.2f} s"
        plural = "s" if len(gone) > 1 else ""
        if ended:
            # healthy noise (at most UNEXPLAINED_RATIO) only where no change is left in effect;
            # else within allowed_ratio of the model's residual, whose share can be far above it
            rest = "the model's own residual is healthy noise after it"
            if split.kept:
                rest = (
                    "what the changes still in effect leave after it is within what they may leave"
                )
            meaning = f"the change{plural} alarmed at {which} ended {when}: {rest}"
        else:
            if thruster is not None:
                was = 1.0 - sum(t for n, t in split.kept if n == thrusters[0])
                was -= _theta(changes, gone, thrusters[0])
                now = (
                    f"thruster {thruster} {'back' if efficiency > was else 'down'} to "
                    f"{100 * efficiency:.0f} % of nominal"
                )
            else:
                now = ", ".join(f"{n} now {number(c['value'], 3)} ± {number(c['stderr'], 2)}"
                                for n, c in components.items())  # fmt: skip
            meaning = (
                f"the change{plural} alarmed at {which} changed size {when}: {now}; what is "
                "left after it is within what the change may leave"
            )
        n_par = 0 if ended else len(names)
        gain = (float(self.p_left.sum()) - split.cost) / (2 * m.correlation_time_)
        name = trace.experiment[k]
        window = window_rows(self.data, k, window_s)
        record = {
            "experiment": None if name is None else str(name),
            "t": float(self.data["t"][k]),
            "kind": kind,
            "thruster": thruster,
            "efficiency": efficiency,
            "efficiency_low": low,
            "efficiency_high": high,
            "effect": effect,
            "value": value,
            "stderr": stderr,
            "severity": _severity(m, trace, window),
            "confidence": float(expit(gain - (1 + n_par) * self.penalty())),
            "meaning": meaning,
            "explained": 1.0 - split.cost / float(self.p_left.sum()),
            "residual_ratio": self.ratio(self.power(split.after)),  # from τ on
            "hypothesis": "change_ended" if ended else "change_resized",
            "p_value": None,
            "alternatives": [],
            "components": components or None,
            "repeats": None,  # no unexplained change (unexplained())
            "last_seen_t": None,
            "ended" if ended else "resized": {"t": t_split, "alarms": [changes[i].t for i in gone]},
        }
        # measured on the rows the log kept of the window (at least self.least: usable())
        short = on_part(self.data, k, window_s, window, m.max_interval)
        judged_on_part(record, short, ENDED_HOW if ended else RESIZED_HOW)
        return record


def ended_alarm(
    splits: _Splits, trace: Trace, k: int, window_s: float
) -> tuple[dict, list[int]] | None:
    """The alarm at row ``k`` on rows watched on what the isolated changes leave (``splits``
    of its window, :class:`_Splits`), as the end of some of them: its record and the changes
    that ended (indices into :attr:`Rewatch.changes`), or None where no end explains it.

    The hypothesis: the changes held until a time τ of the window and ended there, so the
    residual is ``left`` before τ and what the changes still in effect leave of ``r`` from τ
    on (the model's own residual ``r`` where they all ended: a change's end is tested before
    anything else, not isolated as a new change that cancels it). τ minimises that residual's
    whitened power (at least :data:`CHANGED_S` after it); all the changes ending is tried,
    and each one alone where there are several. It is an end where the ended changes refitted
    after τ are not significant (:data:`ENDED_LEVEL`: a thruster's 95 % interval holds its
    nominal thrust) yet significantly less than their size (the rows after τ would show them
    persisting: an end they cannot show is not measured, and the changes stay taken out), and
    what is left after τ is within what a hypothesis may leave of the healthy noise
    (:func:`~nnid.fault.isolation.allowed_ratio` of 1: at most
    :data:`~nnid.fault.isolation.UNEXPLAINED_RATIO`, no share: the vehicle is healthy again),
    or of the model's residual there where other changes are still in effect. The confidence is
    its posterior weight (BIC, τ its one parameter) against the changes persisting, and must be
    over one half (:meth:`_Splits.persisting_bar`), as :func:`ended_within` has it: the tests
    above passed an end whose own record gave it 0.44 (a 2.5 % thrust loss, three standard
    errors, said ended on a healthy window), the changes persisting the better reading. The
    record states what is left of the ended changes (a thruster's efficiency against nominal,
    an effect's value) and ``residual_ratio`` the noise ratio after τ. A change that came back
    only partly is no end: :func:`resized_alarm`."""
    split = splits.ended() if splits.usable() else None
    if split is None or split.cost >= splits.persisting_bar():
        return None
    return splits.record(trace, k, window_s, split, ended=True), split.gone


def resized_alarm(
    splits: _Splits, trace: Trace, k: int, window_s: float
) -> tuple[dict, tuple[list[int], Change]] | None:
    """The alarm at row ``k`` (as :func:`ended_alarm`) as some of the isolated changes having
    changed size at a time τ of the window (a stopped thruster back to 81 %, a snag partly
    freed, h1 from 50 % down to 20 %): its record (hypothesis ``change_resized``, the kind of
    the change, its size now against nominal) and the changes resized with the one that
    replaces them, or None. The changes are refitted on the rows from τ on (τ minimises the
    window's whitened power so); the new size must differ from the one taken out
    significantly (:data:`~nnid.fault.isolation.SIGNIFICANCE`) and leave no more than a change
    may of the model's residual after τ (:func:`~nnid.fault.isolation.allowed_ratio`). As an
    end, it must be the better reading by BIC than the changes persisting
    (:meth:`_Splits.persisting_bar`, τ and each θ refitted its parameters): its record's
    confidence over one half. Without it, a 3-standard-error loss of h1 taken out of a
    healthy window was said resized with confidence 0.02, explaining 0.6 % of the window: a
    new size that its own record called far less likely than the change persisting."""
    split = splits.resized() if splits.usable() else None
    if split is None or split.cost >= splits.persisting_bar(len(split.fit.fits)):
        return None
    if splits.new_change_fits_better(split):
        return None
    record = splits.record(trace, k, window_s, split, ended=False)
    fitted = [(name, fit["theta"]) for name, fit in split.fit.fits.items()]
    return record, (split.gone, Change(splits.changes[split.gone[0]].t, said(record), fitted))


@dataclass
class Verdict:
    """What an alarm on rows watched on what isolated changes leave is
    (:func:`rewatched_alarm`): a ``record`` of changes that ended (``ended``, indices into
    :attr:`Rewatch.changes`) or changed size (``resized``: those changes and the one that
    replaces them), or ``dismissed``: within what the changes may leave, no record;
    ``beside``: the noise ratio over the DOF equations the changes leave alone and its
    allowed level, where :meth:`_Splits.change_beside` read them; ``cut_short``: of one
    dismissed on a window the log's end (or a gap) cut short, how much of it there was
    (:func:`on_part`)."""

    record: dict | None = None
    ended: list[int] = field(default_factory=list)
    resized: tuple[list[int], Change] | None = None
    dismissed: bool = False
    beside: tuple[float, float] | None = None
    cut_short: dict | None = None


def rewatched_alarm(
    monitor: ResidualMonitor,
    data: dict,
    trace: Trace,
    k: int,
    window_s: float,
    rewatch: Rewatch,
    r: np.ndarray,
    left: np.ndarray,
) -> Verdict | None:
    """The alarm at row ``k`` on rows watched on what the isolated changes of ``rewatch``
    leave, judged in turn (``r`` and ``left`` [rows, 6]: the model's residual and the one
    watched, on the window's rows): the end of changes
    (first: a window where one ends late is otherwise within what a large change may leave,
    and dismissed); within what the changes may leave (:func:`explained_by_the_changes`) and
    without their signature (:meth:`_Splits.signature_left`), dismissed; a change of their
    size (:func:`resized_alarm`). None: a new change, to
    isolate on ``left``. ``detect`` and ``detect --follow`` alike; each on the rows the log
    kept of its window, and said so where its end cut it short (:func:`on_part`)."""
    splits = _Splits(monitor, data, k, window_s, rewatch, r, left)  # once for both tests
    ended = ended_alarm(splits, trace, k, window_s)
    if ended is not None:
        return Verdict(ended[0], ended=ended[1])
    # within what the changes may leave, but holding their signature: their size changed;
    # or a new change where they leave the motion alone
    if (
        explained_by_the_changes(monitor, r, left)
        and not splits.signature_left()
        and splits.change_beside() is False  # None: too few rows to tell, not dismissed
    ):
        short = on_part(data, k, window_s, window_rows(data, k, window_s), monitor.max_interval)
        return Verdict(dismissed=True, beside=splits.beside, cut_short=short)
    resized = resized_alarm(splits, trace, k, window_s)
    if resized is not None:
        return Verdict(resized[0], resized=resized[1])
    return None


def _theta(changes: list[Change], gone: list[int], name: str) -> float:
    """The sum of the fitted θ of ``name`` over the changes ``gone``."""
    return sum(t for i in gone for n, t in changes[i].fitted if n == name)


def _left(
    monitor,
    data: dict,
    rows: np.ndarray,
    r: np.ndarray,
    fitted: list,
    hypotheses: Hypotheses | None = None,
) -> np.ndarray:
    """What the changes ``fitted`` leave of the model's residual ``r`` [N, 6] on ``rows``:
    minus their signature (:func:`nnid.fault.isolation.signature`, linear in the changes;
    ``hypotheses`` its columns' made before)."""
    if not fitted:
        return r.copy()
    # where a change cannot be shown (NaN) the residual is left as it was: watched blind
    # there, a later fault would pass unsaid
    return r - np.nan_to_num(signature(monitor, data, rows, fitted, hypotheses))


def run_names(names, codes, named: bool) -> np.ndarray:
    """The experiment of each row (``codes`` into ``names``) as the trace and the alarm records
    name it: its label, or None where the log has no experiment column (``named`` false): one
    run without a name, as :func:`nnid.datasets.preprocess.experiment_rows` gives it, not the
    placeholder its arrays carry ("0" in batch, "" in ``--follow``)."""
    labels = np.array(names if named else [None] * len(names), dtype=object)
    return labels[np.asarray(codes, dtype=int)]


def window_rows(data: dict, k: int, window_s: float) -> np.ndarray:
    """The rows of the isolation window of an alarm at row ``k``: its experiment's on
    [t_k, t_k + window_s]."""
    t, codes = data["t"], data["experiment"]
    return np.flatnonzero((codes == codes[k]) & (t >= t[k]) & (t <= t[k] + window_s))


def explained_by_the_changes(monitor: ResidualMonitor, r: np.ndarray, left: np.ndarray) -> bool:
    """Whether an alarm on what isolated changes leave is no new change: the residual
    ``left`` [N, 6] on its window, each whitened DOF read against what the changes may leave
    there (:func:`leave_scale` of their signature, the model's residual ``r`` less ``left``),
    is within what a hypothesis may leave of healthy noise
    (:func:`~nnid.fault.isolation.allowed_ratio` of 1), as the statistics watched read it
    (:meth:`Rewatch.step`): the model's error grows with a change where the change acts, and
    small excursions of it are no second fault. Pooled over the DOFs, the share of a stopped
    vertical thruster's roll and pitch (7,354 and 1,818 times the noise power there) was lent
    to heave: a 10 N ballast change after it (7.9 times the noise in heave, 3.7 over the DOFs)
    was within the window's allowance of 31.6, and dismissed at every window. False where no
    row of the window is finite: nothing measured is not within (NaN compares False)."""
    scale = leave_scale(dof_noise_ratios(monitor, r - left))
    return read_ratio(monitor, dof_noise_ratios(monitor, left - monitor.mu_), scale) <= (
        allowed_ratio(1.0)
    )


def leave_scale(level: np.ndarray) -> np.ndarray:
    """How many times the healthy noise's excess a whitened DOF may hold where isolated
    changes put ``level`` (their signature's power there, in units of the noise power) in the
    model's residual: the excess over the noise a hypothesis may leave of that residual
    (:func:`~nnid.fault.isolation.allowed_ratio` of 1 + ``level``, less 1) over the excess it
    may leave of healthy noise, as the statistics read each DOF's excess in units of it
    (:func:`read_ratio`): a DOF then holding all it may leave reads as healthy noise at its
    allowance (the ratio of the totals allowed half of it where the changes act strongly);
    1 where the changes put little (a DOF they leave alone is read as healthy)."""
    allowed = allowed_ratio(1.0 + np.asarray(level, dtype=float))
    return (allowed - 1.0) / (allowed_ratio(1.0) - 1.0)


def read_ratio(monitor: ResidualMonitor, ratios: np.ndarray, scale: np.ndarray) -> float:
    """The noise ratio of a residual whose DOFs have the :func:`dof_noise_ratios` ``ratios``
    [6], each one's excess over the noise read in units of its ``scale`` [6]
    (:func:`leave_scale`), over the DOFs watched: as the statistics of :meth:`Rewatch.step`
    read it (:func:`nnid.fault.kernel.watch`)."""
    watched = monitor.mask_ > 0
    read = ratios / scale + (1.0 - 1.0 / scale)
    return float(read[watched].sum()) / max(float(watched.sum()), 1.0)


class Rewatch:
    """The monitor on the residual that the isolated changes of one experiment leave (the
    module docstring), for :func:`detect` and ``detect --follow`` alike: the changes' fitted
    hypotheses, and EWMA and CUSUM started fresh at the end of the latest one's window."""

    def __init__(self, monitor: ResidualMonitor) -> None:
        self.monitor = monitor
        self.cfg = monitor._cfg(monitor.threshold_values, monitor.interval)
        self.changes: list[Change] = []
        self.state = np.zeros(kernel.WATCH_STATE_SIZE)
        self.t_prev = np.nan
        # the columns of the changes' hypotheses, remade only when they name others
        self.hypotheses: Hypotheses | None = None
        # the rows at the run's end that :meth:`left` to it left unjudged, one (the time of the
        # row before its first, the times of each) per stretch of consecutive rows: judged rows
        # can lie between two (empty: none)
        self.tail: list[tuple[float, np.ndarray]] = []

    @property
    def fitted(self) -> list[tuple[str, float]]:
        """The fitted hypotheses of the changes taken out."""
        return [f for c in self.changes for f in c.fitted]

    def carried(self, t_prev: float) -> Rewatch:
        """A :class:`Rewatch` for the next piece of this one's run (a gap cut it): the same
        changes taken out, fresh statistics after ``t_prev``, no unjudged tail of its own yet."""
        out = Rewatch(self.monitor)
        out.changes, out.hypotheses = list(self.changes), self.hypotheses
        out.restart(t_prev)
        return out

    def restart(
        self,
        t_prev: float,
        change: Change | None = None,
        ended: Sequence[int] = (),
        resized: tuple[Sequence[int], Change] | None = None,
    ) -> None:
        """Fresh statistics after the time ``t_prev`` (the end of an alarm's window), with the
        isolated ``change`` also taken out, the changes ``ended`` (indices into
        :attr:`changes`, :func:`ended_alarm`) no longer, and the changes ``resized[0]``
        replaced by ``resized[1]`` (:func:`resized_alarm`: taken out at their new size)."""
        if resized is not None:
            gone, new = resized
            first = min(gone)
            self.changes = [new if i == first else c for i, c in enumerate(self.changes)]
            ended = [*ended, *(i for i in gone if i != first)]
        self.changes = [c for i, c in enumerate(self.changes) if i not in set(ended)]
        if change is not None:
            self.changes.append(change)
        self.state[:] = 0.0
        self.t_prev = float(t_prev)

    def left(self, data: dict, rows: np.ndarray, r: np.ndarray, to_end: bool = False) -> np.ndarray:
        """What the changes leave of the model's residual ``r`` [N, 6] on ``rows``: minus
        their signature (:func:`nnid.fault.isolation.signature`, linear in the changes).
        ``to_end``: ``rows`` run to their experiment's last row. A signature that reads the
        acceleration (an added mass, a payload) has there no half smoothing window after a
        row, and the derivative's polynomial extrapolated over it
        (:meth:`~nnid.fault.isolation.Hypotheses.extrapolated`) is not the centred estimate
        the change was fitted and is watched with: after a command step 0.5 s before a
        payload's run ended, those rows held 1.5-3.6 times the run's mean whitened power, the
        EWMA statistic rose from 35 to 152 over them (threshold 115), and the run's last
        sample alarmed (a model_change that too few rows could isolate). Those rows are NaN,
        not judged, as rows without a residual are, and kept in :attr:`tail` to be said
        (:func:`unjudged_tail`). The rows of an earlier tail before ``rows`` stay in it: they
        lie in the window of the alarm judged since (``rows`` run from its end), which read
        them NaN, so no window judged them; dropped, a tail that window reached into was
        said only from its end on. Where ``rows`` span less than a smoothing window, the
        half window left unjudged shrinks with it (:meth:`~nnid.fault.isolation.Hypotheses.
        extrapolated`), and the first of ``rows`` are judged: the tail is then two stretches
        with judged rows between, kept apart (one span from the earlier tail's first row to
        the run's end counted the judged rows as unjudged)."""
        fitted = self.fitted
        if fitted:
            names = {name for name, _ in fitted}
            self.hypotheses = Hypotheses.reused(self.hypotheses, self.monitor, names)
        out = _left(self.monitor, data, rows, r, fitted, self.hypotheses)
        if not (to_end and rows.size):  # no rows (a window to the run's end): the tail stays
            return out
        t = data["t"]
        kept = [(before, times[times < t[rows[0]]]) for before, times in self.tail]
        kept = [(before, times) for before, times in kept if times.size]
        gone = rows[self.hypotheses.extrapolated(data, rows)] if fitted else rows[:0]
        out[np.isin(rows, gone)] = np.nan
        if gone.size:
            before = float(t[gone[0] - 1])
            if kept and kept[-1][1][-1] == before:  # the row before is the earlier tail's last
                kept[-1] = (kept[-1][0], np.r_[kept[-1][1], t[gone]])
            else:
                kept.append((before, t[gone]))
        self.tail = kept
        return out

    def step(self, ts: np.ndarray, left: np.ndarray, r: np.ndarray) -> np.ndarray:
        """The statistics of the rows at times ``ts`` (after those of the last call) on the
        residual ``left``: [N, 21] as :func:`nnid.fault.kernel.run` gives them. Each whitened
        DOF is read against what the changes may leave there (:func:`leave_scale` of the
        level of their signature, the model's residual ``r`` less ``left``:
        :func:`nnid.fault.kernel.levels`), as :func:`explained_by_the_changes` judges the
        window of an alarm. Read against the healthy noise alone, the model's error that a
        stopped thruster leaves where it acts (1-2 % of its signature's power, in bursts where
        its command reverses) alarmed every 10-15 s, each alarm announced by ``--follow`` and
        then withdrawn as within what the change may leave."""
        m = self.monitor
        level = kernel.levels(self.t_prev, ts, r - left, self.cfg, m.whiten_, self.state,
                              np.empty((ts.size, 6)))  # fmt: skip
        out = kernel.watch(self.t_prev, ts, left, leave_scale(level), self.cfg, m.mu_,
                           m.whiten_, m.s_inv_, self.state, np.empty((ts.size, 21)))  # fmt: skip
        if ts.size:
            self.t_prev = float(ts[-1])
        return out


#: why :func:`unjudged_tail`'s rows were not judged, in short: the line a person reads
#: (:func:`nnid.fault.follow.unjudged_line`); ``detect.json`` says :data:`UNJUDGED_WHY`
UNJUDGED_SHORT = (
    "the isolated change taken out reads an extrapolated acceleration there (the last half "
    "smoothing window)"
)
#: why :func:`unjudged_tail`'s rows were not judged
UNJUDGED_WHY = (
    "the run's last half smoothing window: an isolated change taken out there reads the "
    "acceleration, whose smoothed derivative is extrapolated over these rows, not the centred "
    "estimate the change was fitted with; their statistics were not computed, so no alarm could "
    "be raised there"
)


def unjudged_tail(experiment: str | None, w: Rewatch) -> dict | None:
    """The rows at the end of ``experiment`` that its :class:`Rewatch` ``w`` left unjudged
    (:meth:`Rewatch.left` to the run's end), as ``detect.json`` states them: ``from_t`` and
    ``to_t`` the first and last, ``samples`` how many, ``seconds`` the time they cover (each
    stretch of consecutive rows from the last row judged before it, summed), ``segments``
    each stretch alike (``from_t``, ``to_t``, ``samples``, ``seconds``; more than one where
    judged rows lie between: from ``from_t`` to ``to_t`` is then not all unjudged), and
    ``why``; None where every row was judged. Dropped unsaid, a payload's run read as judged
    to its last sample."""
    if not w.tail:
        return None
    segments = [{"from_t": float(times[0]), "to_t": float(times[-1]), "samples": int(times.size),
                 "seconds": float(times[-1] - before)} for before, times in w.tail]  # fmt: skip
    name = None if experiment is None else str(experiment)
    return {"experiment": name, "from_t": segments[0]["from_t"], "to_t": segments[-1]["to_t"],
            "samples": sum(s["samples"] for s in segments),
            "seconds": sum(s["seconds"] for s in segments), "segments": segments,
            "why": UNJUDGED_WHY}  # fmt: skip


def detect(
    monitor: ResidualMonitor,
    log: pd.DataFrame,
    window_s: float = 10.0,
    report: CleaningReport | None = None,
) -> DetectResult:
    """Every alarm on ``log`` with its isolation on the ``window_s`` seconds after it; after an
    isolated change, the monitor watches what that change leaves, and after one that is not
    isolated, the residual as it was, a later unexplained alarm folded into its record (the
    module docstring). The trace keeps the model's residual r; its statistics and alarms are
    those watched. ``report`` records the velocities derived from the pose, where the log
    lacks them."""
    start = time.perf_counter()
    data = by_block(monitor_inputs(log, monitor.plant_, report))
    data[DROPPED_TAILS] = log.attrs.get(DROPPED_TAILS, {})  # what mask_gaps cut off runs' ends
    trace = monitor.run(log)
    values, alarm = trace.values.copy(), trace.alarm.copy()
    residual = trace.values[:, 0:6].copy()  # the residual watched, re-referenced per change
    names = run_names(data["experiment_names"], data["experiment"], "experiment" in log)
    watched = Trace(trace.t, names, values, alarm)
    t, codes = data["t"], data["experiment"]
    # per experiment; a later piece of a run a gap cut gets its own, the changes carried over
    rewatch: dict[int, Rewatch] = {}
    open_: dict[int, dict] = {}  # per run (run_key), its unexplained record (unexplained())
    alarms, dismissed, pos = [], [], 0
    changed = np.zeros(t.size, dtype=bool)  # rows watched on a re-referenced residual
    while (ks := np.flatnonzero(alarm[pos:])).size:
        k = pos + int(ks[0])
        taken = []
        if changed[k]:
            w = rewatch[int(codes[k])]
            rows = window_rows(data, k, window_s)
            r = trace.values[rows, 0:6]
            verdict = rewatched_alarm(monitor, data, watched, k, window_s, w, r, residual[rows])
            if verdict is not None:  # an end, a change of size, or dismissed
                if verdict.dismissed:
                    alarm[k] = False  # no record, so no mark in the trace either
                    ratio, allowed = verdict.beside or (None, None)
                    name = None if names[k] is None else str(names[k])
                    dismissed.append(
                        {
                            "experiment": name,
                            "t": float(t[k]),
                            "beside_ratio": ratio,
                            "beside_allowed": allowed,
                            "why": dismissed_why(ratio, allowed, verdict.cut_short),
                            **({"cut_short": verdict.cut_short} if verdict.cut_short else {}),
                        }
                    )
                else:
                    alarms.append(verdict.record)
                _rewatch(w, data, residual, values, alarm, rows, changed, verdict=verdict,
                         pieces=rewatch)  # fmt: skip
                pos = int(rows[-1]) + 1
                continue
            taken = w.fitted
        record, diag, rows = isolated_alarm(monitor, data, watched, k, window_s, residual, taken)
        code = int(codes[k])
        new, change = filed(record, diag, open_, run_key(data, code), float(t[rows[-1]]))
        if new:
            alarms.append(record)
        else:  # the unexplained change persisting: no record, nor mark
            alarm[k] = False
        # fresh statistics after the window, isolated or not (the module docstring)
        _rewatch(rewatch.setdefault(code, Rewatch(monitor)), data, residual, values, alarm, rows,
                 changed, change, pieces=rewatch)  # fmt: skip
        pos = int(rows[-1]) + 1
    tails = [unjudged_tail(names[np.argmax(codes == c)], w) for c, w in rewatch.items()]
    return DetectResult(watched, alarms, time.perf_counter() - start, dismissed=dismissed,
                        unjudged=[u for u in tails if u is not None])  # fmt: skip


def by_block(data: dict) -> dict:
    """:func:`~nnid.fault.monitor.monitor_inputs`' ``data`` with each stretch of consecutive
    rows of one experiment an experiment of its own (a run that resumes after another's rows,
    runs A, B, A: A's second stretch), named as its run; ``data`` itself where every
    experiment is one stretch. Detection reads an experiment as the rows from its first to its
    last (:func:`_rest`), so B's rows were watched as A's, A's isolated change taken out of
    them (or a KeyError); the monitor's pass restarts at each stretch (as ``--follow`` does),
    and so, now, does what detection reads."""
    codes = data["experiment"]
    if codes.size < 2:
        return data
    starts = np.r_[True, codes[1:] != codes[:-1]]
    if int(starts.sum()) == np.unique(codes).size:
        return data
    first = codes[starts]  # each stretch's experiment
    named = {k: data[k][first] for k in ("experiment_names", "experiment_runs") if k in data}
    return {**data, "experiment": np.cumsum(starts) - 1, **named}


def run_pieces(data: dict, code: int) -> np.ndarray:
    """The experiment codes of the run that experiment ``code`` is a piece of, a gap (a
    dropout) having cut it (:func:`nnid.datasets.gaps.mask_gaps`): the consecutive codes whose
    ``experiment_runs`` is its run, each a piece (its run not its own name); ``code`` alone
    where it is no piece, or the arrays name no runs (``--follow``'s). A run resumed after
    another's rows (:func:`by_block`) is no piece: its stretches are watched apart."""
    runs, names = data.get("experiment_runs"), data["experiment_names"]
    if runs is None or runs[code] == names[code]:
        return np.array([code])
    same = np.array([r == runs[code] and r != n for r, n in zip(runs, names, strict=True)])
    a = code - int(np.argmin(same[code::-1])) if not same[: code + 1].all() else -1
    b = code + int(np.argmin(same[code:])) if not same[code:].all() else len(runs)
    return np.arange(a + 1, b)


def run_key(data: dict, code: int) -> int:
    """The run experiment ``code`` belongs to, as its first piece's code (:func:`run_pieces`):
    what is kept per run (its open unexplained record) is found from each of its pieces."""
    return int(run_pieces(data, code)[0])


def later_pieces(data: dict, code: int) -> list[int]:
    """The codes of the pieces of ``code``'s run after it (:func:`run_pieces`)."""
    return [int(c) for c in run_pieces(data, code) if c > code]


def _rest(data: dict, rows: np.ndarray) -> np.ndarray:
    """The rows of the experiment after ``rows``."""
    codes = data["experiment"]
    k = int(rows[-1])
    return np.arange(k + 1, int(np.flatnonzero(codes == codes[k])[-1]) + 1)


def _rewatch(w: Rewatch, data, residual, values, alarm, rows, changed, change=None, verdict=None,
             pieces: dict[int, Rewatch] | None = None):  # fmt: skip
    """Watch ``residual`` from fresh statistics on the rest of the experiment after ``rows``
    (the window of an alarm: no new alarm within it); values and alarms rewritten there.
    ``change``: one just isolated, taken out of the model's residual there first; ``verdict``
    (:func:`rewatched_alarm`): changes that ended, no longer taken out, or changed size, taken
    out at their new size. ``pieces`` (the :class:`Rewatch` per experiment): each later piece
    of the run a gap cut (:func:`later_pieces`) gets one that carries ``w``'s changes, watched
    on what they leave from fresh statistics at its start, where the monitor's pass restarts.
    Watched on the model's own residual, a thruster stopped and isolated before one empty DVL
    row was alarmed again within a second of the gap and isolated again as a new loss: one
    record more per dropout."""
    rest = _rest(data, rows)
    alarm[rows[0] + 1 : rows[-1] + 1] = False
    verdict = verdict or Verdict(dismissed=True)
    w.restart(data["t"][rows[-1]], change, verdict.ended, verdict.resized)
    refer = change is not None or not verdict.dismissed  # values' first six columns are still r
    _watch(w, data, residual, values, alarm, rest, changed, refer)
    if pieces is None:
        return
    codes = data["experiment"]
    for code in later_pieces(data, int(codes[rows[0]])):
        piece = np.flatnonzero(codes == code)
        # its first row has no residual (the monitor's pass restarts there): the rest is
        # re-referenced, each row with its predecessor in the piece, not across the gap
        pieces[code] = w.carried(float(data["t"][piece[0]]))
        _watch(pieces[code], data, residual, values, alarm, piece[1:], changed, refer=True)


def _watch(w: Rewatch, data, residual, values, alarm, rest, changed, refer: bool) -> None:
    """Watch the rows ``rest`` (to their experiment's end) on ``w``'s statistics as they
    stand: ``residual`` there re-referenced to its changes first (``refer``; else it already
    is), values and alarms rewritten."""
    changed[rest] = bool(w.changes)  # with none left, a later alarm is a first one again
    if refer:
        residual[rest] = w.left(data, rest, values[rest, 0:6], to_end=True)
    if rest.size:
        out = w.step(data["t"][rest], residual[rest], values[rest, 0:6])
        values[rest, 6:20] = out[:, 6:20]
        alarm[rest] = out[:, 20] == 1
