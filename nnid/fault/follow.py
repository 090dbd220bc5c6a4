"""``nnid detect --follow``: a growing CSV (or stdin) watched one row at a time.

Rows go through :class:`nnid.fault.monitor.Stream` as they arrive; an alarm is announced at once
and isolated when the window after it has arrived (or at the end of the input). The log needs the
body velocities as columns (a live monitor cannot smooth over the future) and the inputs of the
model's vehicle; without roll or pitch it is read as batch reads it, level, and refused as batch
refuses it where the vehicle tilts and the restoring forces read the angle
(:func:`~nnid.datasets.preprocess.check_attitude`, on the experiment's rows so far, with the
units' checks). Its clock is checked on the rows it has: every
:data:`RATE_ROWS` rows, the current experiment's latest :data:`RATE_WINDOW` for stamps that come
in bursts, refused by batch's rule (:func:`~nnid.datasets.preprocess.refuse_bursts`), then all
the latest rows for the calibrated rate. The rows before the first check are watched unchecked,
and a run whose stamps begin to come in bursts later is refused once bursts hold the median of
its latest rows' steps. Whether an announced alarm stays is known only once the alarms before it
are judged: one that batch ``detect`` drops (dismissed, or inside the window of an earlier alarm
whose judgement restarts the statistics) is said withdrawn, with why, and kept in the result's
``withdrawn``, so that no announced alarm vanishes unsaid. An alarm is judged as
soon as its window (batch's rows, :func:`~nnid.fault.detect.window_rows`) is whole and watched,
and no row after that window is announced before the judgement: an alarm there, read before a
judgement that restarts the statistics, was announced and then withdrawn, one batch never has.

After an alarm whose change is isolated, the rest of the experiment is watched as batch
``detect`` watches it (:mod:`nnid.fault.detect`, its :class:`~nnid.fault.detect.Rewatch`): the
fitted change's signature taken out of each new row's residual, fresh EWMA and CUSUM from the end
of the isolation window, a later alarm judged by the same rule. The signature is computed on
:data:`REWATCH_S` seconds of rows at once (its columns cost milliseconds a call, whatever the
rows) and each row waits for the half Savitzky-Golay window after it that its signature's
acceleration is smoothed over, as batch has it, so an alarm there is announced up to that much
later; its time is its row's. The run's last rows, which never get that half window, are not
judged where the signature reads the acceleration (:meth:`~nnid.fault.detect.Rewatch.left`), as
in batch, and said in the result's ``unjudged`` (:func:`~nnid.fault.detect.unjudged_tail`).
After an alarm that is not isolated the statistics restart after its window too, as in batch,
with nothing more taken out (an isolated change before it
stays taken out; the rows watched the same way), and a later alarm that is not isolated
either is announced, then said withdrawn: the unexplained change persisting, counted in its
record (:func:`~nnid.fault.detect.persisting`). The per-sample update of a stream before its
first judged alarm is untouched.
"""

from __future__ import annotations

import csv
import os
import stat
import sys
import time
from collections.abc import Callable

import numpy as np
import pandas as pd

from nnid.datasets.arrays import beyond_range_message, check_commands, command_limits
from nnid.datasets.log import (
    ANGLES,
    DEPTH_UNIT_COLUMNS,
    POSE,
    RATE_OF,
    SI_BOUNDS,
    VELOCITY,
    check_depth_units,
    check_label,
    check_rate_units,
    degrees_error,
    looks_like_degrees,
    out_of_bounds,
    radian_limit,
)
from nnid.datasets.preprocess import check_attitude, refuse_bursts, savgol_window
from nnid.datasets.readers import csv_dialect, refuse_comment_header, refuse_repeated_names
from nnid.errors import NnidInputError, checked_number
from nnid.fault.detect import (
    UNJUDGED_SHORT,
    DetectResult,
    Rewatch,
    filed,
    finding,
    how_often,
    isolated_alarm,
    rewatched_alarm,
    run_names,
    unjudged_tail,
    window_rows,
    withdrawn_record,
)
from nnid.fault.isolation import UNEXPLAINED
from nnid.fault.monitor import (
    MONITOR_STEPS,
    UNREAD_BY,
    ResidualMonitor,
    Trace,
    input_columns,
    kernel_state,
    monitor_motion,
)
from nnid.reports.cells import missing, number
from nnid.validation import shown

#: the motion columns a streamed row fills (those absent read as 0)
STATE = (*POSE, *VELOCITY)
#: every this many rows, the typical interval of the latest :data:`RATE_WINDOW` is checked
#: against the monitor's calibration rate
RATE_ROWS = 11
#: rows whose typical interval (a 10 %-trimmed mean) is checked: enough that a clock dropping
#: 2 % of its samples reads as its rate (over 11 rows two drops read 1.125 and refused it)
RATE_WINDOW = 200
#: after an isolated change, the rows re-referenced to it at once (seconds of them)
REWATCH_S = 0.5
#: the body rates' unit is checked against the attitude (the whole-log reader's deg/s check,
#: :func:`nnid.datasets.log.check_rate_units`, and the depth's against the velocities,
#: :func:`~nnid.datasets.log.check_depth_units`) on an experiment's latest this many seconds of
#: rows: its first minute judged as that reader judges a one-minute log, at a cost that does
#: not grow with the run
RATE_UNIT_S = 60.0
#: a followed file that has not grown for this many seconds has ended (``--idle-s``)
IDLE_S = 3.0
#: every this many seconds of an experiment's rows, and at its end (a check of a minute at
#: 20 Hz costs 3-9 ms; the refusal needs 2 s of turning windows anyway)
RATE_UNIT_EVERY_S = 5.0
#: the notes on the log a watch keeps for its outputs (``follow_csv``'s ``notes``); those after
#: are counted there, said on the console only: a monitor left running over a log with a gap a
#: minute must not grow them without bound
NOTES_KEPT = 50


def _parse(line: str, source: str, count: int, sep: str = ",", header: str = "") -> list[str]:
    """One CSV line as cells, split at ``sep`` with the spaces after it dropped, as the
    whole-log reader splits them; a line the CSV reader refuses (a bare carriage return inside
    a field) is named by its data row, counted as the whole-log reader counts them, and so is
    a field that holds a line break inside quotes (a label ``"dive<newline>1"``): --follow
    reads a row a line, and its halves were said as rows of too few fields. ``header``: the
    header line, whose column the quoted field is named by."""
    where = "stdin" if source == "-" else source
    try:
        cells = next(csv.reader([line], delimiter=sep, skipinitialspace=True))
    except csv.Error as exc:
        raise NnidInputError(
            f"is not a CSV row ({exc})", source=where, row=count - 1 if count else None
        ) from None
    # a quote left open at the line's end holds the line break: the reader puts it in the last
    # cell, where a closed row never has one (the reader takes the line's own end off)
    if cells and cells[-1].endswith(("\n", "\r")):
        names = (
            next(csv.reader([header], delimiter=sep, skipinitialspace=True), []) if count else []
        )
        column = names[len(cells) - 1].strip() if len(cells) <= len(names) else None
        raise NnidInputError(
            f"a field holds a line break inside quotes ({cells[-1].rstrip()[:40]!r} then the "
            "next line): --follow reads one row a line; write the field on one line",
            source=where,
            field=column,
            row=count - 1 if count else None,
        )
    return cells


def _decoded(line: bytes, source: str, count: int) -> str:
    """One line as UTF-8 text, as the whole-log reader reads a CSV, a byte-order mark before
    the header dropped; else the error naming its data row (a Latin-1 degree sign was a
    UnicodeDecodeError traceback)."""
    try:
        text = line.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise NnidInputError(
            f"is not UTF-8 text (byte {exc.start} of {'this row' if count else 'the header'}): "
            "save it as UTF-8",
            source="stdin" if source == "-" else source,
            row=count - 1 if count else None,
        ) from None
    return text if count else text.removeprefix("\ufeff")


def _opened(source: str):
    """The byte stream of ``source`` (``-``: stdin), or the error naming ``--data``: a file
    that cannot be read, or no standard input (closed, or a service started without one)."""
    if source == "-":
        stdin = getattr(sys.stdin, "buffer", sys.stdin)
        if stdin is None or getattr(stdin, "closed", False):
            raise NnidInputError("'-': there is no standard input to read", field="--data")
        return stdin
    try:
        return open(source, "rb")
    except OSError as exc:
        raise NnidInputError(
            f"cannot be read ({exc.strerror or exc})", source=source, field="--data"
        ) from None


def _moved(source: str, handle, row: int | None) -> None:
    """Refuse a followed file that is no longer the one read: renamed away or replaced (a log
    rotated), or cut shorter than what was read (truncated in place). Either was taken as the
    log's end, or read on from the old offset in the middle of another row. A pipe (a named
    one, ``/dev/stdin`` fed by one, ``<(producer)``) has no size and cannot tell its offset:
    only its identity is checked."""
    try:
        now = os.stat(source)
    except OSError:
        now = None
    opened = os.fstat(handle.fileno())
    if now is None or (now.st_ino, now.st_dev) != (opened.st_ino, opened.st_dev):
        why = "was replaced (renamed, removed or rotated) while followed"
    elif stat.S_ISREG(opened.st_mode) and now.st_size < handle.tell():
        why = f"was truncated while followed ({now.st_size} bytes, {handle.tell()} read)"
    else:
        return
    raise NnidInputError(f"{why}: follow one file that only grows", source=source, row=row)


def _rows(
    source: str,
    idle_s: float,
    dialect: dict | None = None,
    say: Callable[[str], None] | None = None,
):
    """Rows of a CSV as lists of strings; a file is followed until it stops growing for
    ``idle_s`` seconds, stdin until it closes. Read as the whole-log reader reads a CSV:
    UTF-8, the separator and decimal mark of :func:`~nnid.datasets.readers.csv_dialect`
    (put in ``dialect`` once the first row is read) and blank lines skipped, not counted. A
    file's last row still unterminated when it stops growing is left out and said to ``say``:
    its writer may have stopped half way through a number (the last line of stdin or a pipe
    is whole: its writer closed)."""
    handle = _opened(source)
    found = {} if dialect is None else dialect
    # a pipe (a named one, /dev/stdin fed by one, <(producer)) ends when its writer closes, as
    # stdin does: no idle wait, and its last line is whole (it was left out as a row still
    # being written, where only a regular file can still grow)
    stream = source == "-" or not stat.S_ISREG(os.fstat(handle.fileno()).st_mode)
    try:
        buffer, quiet, count, header = b"", 0.0, 0, ""
        while True:
            line = handle.readline()
            if not line and source != "-":
                _moved(source, handle, count - 1 if count else None)  # the row to come
            if not line and not stream and quiet < idle_s:
                time.sleep(0.1)
                quiet += 0.1
                continue
            if not line and not buffer.strip():
                break
            if not line and not stream and count:  # a data row cut off by the idle end
                if say is not None:
                    said = buffer.decode("utf-8", "replace").strip()[:60]
                    say(
                        f"row {count - 1} left out: the file stopped growing for {idle_s:g} s "
                        f"inside it, no line end after {said!r} (a row still being written)"
                    )
                break
            if line:
                quiet = 0.0
                # bytes until the line is whole: a row still being written may end inside a
                # character of more than one byte
                buffer += line if isinstance(line, bytes) else line.encode()
                if not buffer.endswith(b"\n"):
                    continue  # a row still being written
            text, buffer = _decoded(buffer, source, count), b""  # at the end, what is left
            if not text.strip("\r\n"):
                continue  # a blank line, which the whole-log reader skips
            if count <= 1:  # the separator from the header, the decimal mark from a row
                header = header or text
                found.update(csv_dialect(header, text if count else ""))
            yield _parse(text, source, count, found.get("sep", ","), header)
            count += 1
    finally:
        if source != "-":
            handle.close()


def _numbers(
    row: list[str],
    read: list[tuple[str, int]],
    n: int,
    where: str,
    width: int,
    held: frozenset[str] = frozenset(),
    decimal: str = ".",
) -> dict:
    """The named cells of one streamed row as finite numbers within the log contract's SI
    bounds (a unit slip, a corrupt sample), as the whole-log reader checks them; else the first
    bad cell, named by its column and row (an empty motion cell too: a stream has no gap
    bridging). An empty cell of a column in ``held`` (a pose the residual never reads,
    :func:`~nnid.fault.monitor.monitor_motion`) is left out: the caller holds its run's last
    sample. A row of more cells than the header's ``width`` (a decimal comma; the whole-log
    reader refuses it too) or fewer is refused: its cells would be read under other columns.
    ``decimal``: the decimal mark (a comma in a semicolon-separated file, where a point is
    refused as that reader refuses it)."""
    if len(row) != width:
        raise NnidInputError(
            f"has {len(row)} fields against the header's {width} (a decimal comma, or a cell "
            "with a comma in it?)",
            source=where,
            row=n,
        )
    out = {}
    for name, i in read:
        cell = row[i] if i < len(row) else ""
        if name in held and not cell.strip():
            continue
        number = cell
        if decimal == ",":  # a point there is text to the whole-log reader, refused
            number = cell.replace(",", ".") if "." not in cell else "nan"
        try:
            value = float(number)
        except ValueError:
            value = np.nan
        if not np.isfinite(value):
            # an empty cell is most often a sensor logged slower than the others on one clock
            empty = (
                ": an empty cell, a sensor logged slower than the others or a dropout, which "
                "batch detect reads (a slow attitude filled from the gyro, gaps masked)"
            ) * (cell.strip() == "")
            mark = "; this file's decimal mark is a comma" * (decimal == "," and "." in cell)
            raise NnidInputError(
                f"value {shown(cell)} is not a finite number (--follow needs one in every "
                f"column it reads{empty}{mark})",
                source=where,
                field=name,
                row=n,
            )
        if name in SI_BOUNDS and abs(value) > SI_BOUNDS[name][0]:
            raise out_of_bounds(name, value, where, n)
        out[name] = value
    return out


def follow_csv(
    monitor: ResidualMonitor,
    source: str,
    window_s: float,
    say: Callable[[str], None],
    idle_s: float = IDLE_S,
    keep_rows: int = 100_000,
    stopped: Callable[[DetectResult], None] | None = None,
    notes: list[str] | None = None,
) -> DetectResult:
    """Watch ``source`` row by row; ``say`` gets one line per alarm and per isolation. The
    last ``keep_rows`` to twice as many samples are kept (for isolation and the report's
    traces), so a monitor left running does not grow without bound; every alarm is kept.
    ``idle_s``: how long a file may stop growing before its log has ended (0 or more).
    ``stopped``: given the result of the rows watched (settled, its ``stopped`` saying why)
    where an interrupt (Ctrl-C, a SIGTERM raised as SystemExit) or a refused row ends the
    watch after some rows, before that exception goes on: ending a live stream so is the
    normal stop, and lost every alarm. ``notes``: gets what is said of the log as it is said
    (a cut last row, a pose column held, an interval without samples; the first
    :data:`NOTES_KEPT`, then their count), for the outputs' notes as batch writes its own."""
    start = time.perf_counter()
    # checked before the source is opened: a NaN never compares, so a NaN wait was forever
    checked_number(idle_s, "idle_s", 0.0, strict=False)
    kept = [] if notes is None else notes
    unkept = 0  # the notes said beyond NOTES_KEPT

    def noted(line: str) -> None:
        """Say a note on the log, and keep it for the outputs."""
        nonlocal unkept
        say(line)
        if len(kept) < NOTES_KEPT:
            kept.append(line)
        else:
            unkept += 1

    dialect: dict = {}
    rows = _rows(source, idle_s, dialect, noted)
    header = next(rows, None)
    where = "stdin" if source == "-" else source
    if header is None:
        raise NnidInputError("is empty: expected a CSV header", source=where)
    header = [c.strip() for c in header]  # as the whole-log reader names its columns
    refuse_comment_header(header, where)
    # as the whole-log reader: header.index would read the first of two 'u' columns unseen
    refuse_repeated_names(pd.Series([c or None for c in header]), where)
    inputs = input_columns(monitor.channels_)
    # roll and pitch as batch has them: absent, read as level and checked on the rows
    # (check_units); demanded here, a log that batch watches was refused
    needed = ["t", *VELOCITY, *inputs]
    missing = [c for c in needed if c not in header]
    if missing:
        raise NnidInputError(
            f"--follow needs the columns {', '.join(missing)} (body velocities as measured, and "
            "the model's inputs)",
            source=where,
        )
    if monitor.plant_.vehicle.thrusters:
        try:
            check_commands(header, inputs, monitor.plant_.vehicle.name)
        except NnidInputError as exc:
            raise exc.with_source(where) from None
    col = {c: header.index(c) for c in header}
    state_cols = [col.get(c) for c in STATE]
    # a pose column the residual never reads (a 1-Hz GPS x, y beside a 20-Hz DVL): an empty
    # cell holds its run's last sample, said once a column, as batch detect holds it unmasked
    unread = [c for c in POSE if c in col and c not in monitor_motion(header)]
    kept_unread, said_held = frozenset(unread), set()
    unread_at = np.array([STATE.index(c) for c in unread], dtype=np.int64)  # kernel_state
    # which cells of each buffered row were held, not read: the unit checks see them empty,
    # as the whole-log reader does (a held depth read as a jump that w does not make)
    nothing_held = np.zeros(len(STATE), dtype=bool)
    input_cols = [col[c] for c in inputs]
    exp_col = col.get("experiment")
    stream = monitor.stream()
    x, u = np.zeros(12), np.zeros(len(inputs))
    ts, xs, us, vals, codes, names = [], [], [], [], [], []
    held_cells: list[np.ndarray] = []  # per row, the cells of xs held (nothing_held: none)
    watched: list[np.ndarray] = []  # vals as watched: after an isolated change, what it leaves
    pending: list[int] = []  # row numbers counted from the first row ever read
    alarm_rows: list[int] = []
    alarms: list[dict] = []
    withdrawn: list[dict] = []  # announced, then not in the final alarms (said so)
    unjudged: list[dict] = []  # per experiment ended, its rows left unjudged at its end
    current = None
    dropped = 0  # rows forgotten from the front of the buffers
    # after an isolated change: the experiment (code), the first row watched on what it leaves
    # (fresh statistics) and the first row of the latest change's signature (batch's rest
    # after that change's window: a dismissed alarm restarts the statistics, not the signature)
    ref: dict = {"rewatch": None, "code": -1, "start": 0, "edge": 0}
    open_: dict[int, dict] = {}  # per experiment, its unexplained record (batch's rule)
    queue: list[int] = []  # rows of it whose residual is not yet re-referenced
    block = max(round(REWATCH_S / monitor.interval), 1)
    context = max(int(np.ceil(monitor.plant_.savgol_window / monitor.interval)), block)
    # a row's signature smooths the acceleration over a window centred on it (an added-mass
    # or payload change): it waits for the half window after it, which batch has
    ahead = savgol_window(monitor.plant_.savgol_window, 1.0 / monitor.interval, 2) // 2 + 1

    def judged(k: int) -> bool:
        """Whether the alarm at ``k`` can be isolated now: its experiment has ended, or its
        window (batch's, :func:`window_rows`) is whole, the newest row its last or past it,
        and every row of it has been watched (a row waits for rows, not for time: after
        missing samples the time passes first)."""
        i = k - dropped
        if codes[i] != codes[-1]:
            return True
        if ts[-1] < ts[i] + window_s:  # the same sum as window_rows: a row there is in it
            return False
        return not (queue and ts[queue[0] - dropped] <= ts[i] + window_s)

    def announce(k: int) -> None:
        pending.append(k)
        alarm_rows.append(k)
        i = k - dropped
        name = names[codes[i]]
        say(f"ALARM t = {ts[i]:.2f} s{f' ({name})' if name else ''}: isolating over {window_s} s")

    def flush(final: bool = False, until: float = np.inf) -> None:
        """The queued rows re-referenced to the isolated changes and watched (the rows before
        them, from the first after the window, as context for the signature's derivative).
        Unless its run has ended (``final``), a row waits for the half smoothing window after
        it, and the rows taken must hold a whole window, as batch's do. No row after the
        window of an alarm still to be judged (``until``, the time its window ends, or the
        first pending alarm's) is watched: its judgement may restart the statistics before
        that row, and an alarm there would be announced that batch never has."""
        if not queue:
            return
        first, last = queue[0], queue[-1]  # the queue runs to its experiment's newest row
        ready = len(queue) if final else sum(k <= last - ahead for k in queue)
        if pending and codes[pending[0] - dropped] == codes[first - dropped]:
            until = min(until, ts[pending[0] - dropped] + window_s)
        ready = min(ready, sum(ts[k - dropped] <= until for k in queue))
        a = max(ref["edge"] - 1, first - context, dropped)  # rows from a + 1 get a signature
        i, j = a - dropped, last + 1 - dropped
        # and the smoothing's window must fit in the rows taken, whole, as it does in batch
        if ready == 0 or (j - i < max(3, 2 * ahead + 1) and not final):
            return
        data = _arrays(ts[i:j], xs[i:j], us[i:j], codes[i:j], names)
        rows = np.arange(1, j - i)
        model = np.array(vals[i + 1 : j])[:, 0:6]  # the model's residual r
        taken = slice(first - a - 1, first - a - 1 + ready)
        # the run ended (final): its last rows are not judged where the signature's
        # derivative is extrapolated (Rewatch.left), as batch does
        left = ref["rewatch"].left(data, rows, model, to_end=final)[taken]
        r = model[taken]
        w, times = ref["rewatch"], data["t"][first - a : first - a + ready]
        state, t_prev = w.state.copy(), w.t_prev
        out = w.step(times, left, r)
        alarmed = np.flatnonzero(out[:, 20] == 1)
        if alarmed.size:  # the rows after the first new alarm's window wait for its judgement
            keep = int(np.sum(times <= times[alarmed[0]] + window_s))
            if keep < ready:  # watched again from the state before, as one call (kernel.watch)
                w.state[:], w.t_prev, ready = state, t_prev, keep
                out = w.step(times[:ready], left[:ready], r[:ready])
        for row, (k, values) in enumerate(zip(queue[:ready], out, strict=True)):
            watched[k - dropped][0:6] = left[row]
            watched[k - dropped][6:20] = values[6:20]
            if values[20] == 1:
                announce(k)
        del queue[:ready]

    def withdraw(
        p: int,
        by: int,
        why: str,
        by_t: float | None = None,
        beside: tuple[float, float] | None = None,
        short: dict | None = None,
    ) -> None:
        """The announced alarm at ``p`` is not in the final alarms (batch drops it too), as
        the judgement of the alarm at ``by`` has it (:func:`withdrawn_record`; ``by_t``: the
        time of the alarm it is folded into, ``why`` "persisting"; ``beside``: the reading
        of one ``why`` "dismissed", and ``short`` its window cut short): said and recorded, so
        that no announced alarm vanishes unsaid."""
        i = p - dropped
        name = names[codes[i]]
        by_t = ts[by - dropped] if by_t is None else by_t
        run = name if exp_col is not None else None
        record = withdrawn_record(run, ts[i], by_t, why, beside, short)
        withdrawn.append(record)
        say(withdrawn_line(record))

    def rewatch_after(k: int, rows: np.ndarray, changed: bool, ended: bool) -> None:
        """Fresh statistics after the window ``rows`` (buffer indices) of the alarm at ``k``:
        the experiment's later alarms superseded (announced, so said withdrawn), its rows
        since then watched again (all of them where it has ended, ``ended``). A new change
        taken out (``changed``) starts its signature there too."""
        code = codes[k - dropped]
        later = sorted(p for p in pending if p > k and codes[p - dropped] == code)
        for p in later:
            withdraw(p, k, "inside" if p - dropped <= rows[-1] else "after")
        pending[:] = [p for p in pending if p not in later]
        alarm_rows[:] = [p for p in alarm_rows if p not in later]
        ref["start"] = dropped + int(rows[-1]) + 1
        if changed:
            ref["edge"] = ref["start"]
        queue[:] = [p for p in range(ref["start"], dropped + len(ts)) if codes[p - dropped] == code]
        flush(final=ended or codes[-1] != code)  # the experiment has ended: no row is to come

    def isolate(k: int, ended: bool = False) -> None:
        """The alarm at ``k`` judged on its window (``ended``: its experiment has no more
        rows), as batch :func:`~nnid.fault.detect.detect` judges it."""
        # the window's rows watched before it is judged (all of them once its run has ended)
        ended = ended or codes[-1] != codes[k - dropped]
        flush(final=ended, until=ts[k - dropped] + window_s)
        data = _arrays(ts, xs, us, codes, names)
        values = np.array(watched)
        trace = Trace(data["t"], run_names(names, data["experiment"], exp_col is not None),
                      values, np.zeros(len(ts), dtype=bool))  # fmt: skip
        i, code = k - dropped, codes[k - dropped]
        w, taken = ref["rewatch"], []
        # batch's rows watched on what isolated changes leave (none left after they ended)
        if w is not None and ref["code"] == code and k >= ref["start"] and w.changes:
            rows = window_rows(data, i, window_s)
            r = np.array([vals[j][0:6] for j in rows])
            verdict = rewatched_alarm(monitor, data, trace, i, window_s, w, r, values[rows, 0:6])
            if verdict is not None and verdict.dismissed:
                alarm_rows.remove(k)  # no record, so no mark in the trace either
                withdraw(k, k, "dismissed", beside=verdict.beside, short=verdict.cut_short)
                w.restart(data["t"][rows[-1]])
                rewatch_after(k, rows, changed=False, ended=ended)
                return
            if verdict is not None:  # changes that ended or changed size
                alarms.append(verdict.record)
                say(describe_alarm(verdict.record))
                w.restart(data["t"][rows[-1]], ended=verdict.ended, resized=verdict.resized)
                rewatch_after(k, rows, changed=True, ended=ended)
                return
            taken = w.fitted
        record, diag, rows = isolated_alarm(
            monitor, data, trace, i, window_s, values[:, 0:6], taken
        )
        new, change = filed(record, diag, open_, code, float(data["t"][rows[-1]]))
        if new:
            alarms.append(record)
            say(describe_alarm(record))
        else:  # the unexplained change persisting: no new record (batch's rule)
            alarm_rows.remove(k)
            withdraw(k, k, "persisting", by_t=open_[code]["t"])
        # as batch: fresh statistics after the window, isolated or not
        if ref["code"] != code or ref["rewatch"] is None:
            said_unjudged()  # the experiment before, whose rows have all been watched
            ref.update(rewatch=Rewatch(monitor), code=code)
        ref["rewatch"].restart(data["t"][rows[-1]], change)
        rewatch_after(k, rows, changed=change is not None, ended=ended)

    def said_unjudged() -> None:
        """The rows the experiment of the current :class:`Rewatch` left unjudged at its end
        (:func:`~nnid.fault.detect.unjudged_tail`, as batch has them), once it has ended."""
        if ref["rewatch"] is not None:
            name = names[ref["code"]] if exp_col is not None else None
            tail = unjudged_tail(name, ref["rewatch"])
            unjudged.extend([] if tail is None else [tail])

    def settle() -> None:
        """The current experiment has no more rows: its alarms judged in turn, each on its
        window's rows watched, and its last rows watched."""
        flush(final=True)
        while pending:
            isolate(pending.pop(0), ended=True)
            flush(final=True)

    read = [("t", col["t"])] + [
        (c, i)
        for c, i in zip((*POSE, *VELOCITY, *inputs), (*state_cols, *input_cols), strict=True)
        if i is not None
    ]
    last_t = -np.inf
    unchecked = [a for a in ANGLES if a in col]  # looked at once, when past radian_limit
    # deg/s rates beside radians: rate_slopes needs the whole attitude (a missing psi is no
    # heading of 0)
    rate_unit = all(a in col for a in ANGLES)
    # velocities and depth in one unit of length (the whole-log reader's check, on the same rows)
    depth_unit = all(c in col for c in DEPTH_UNIT_COLUMNS)
    # roll or pitch absent: whether the rates tilt the vehicle where the restoring forces read it
    level = any(a not in col for a in ("phi", "theta"))
    unit_check = rate_unit or depth_unit or level
    unit_every = max(1, round(RATE_UNIT_EVERY_S / monitor.interval))
    unit_rows = max(unit_every + 2, round(RATE_UNIT_S / monitor.interval))
    exp_first = 0  # the current experiment's first row, counted from the first row ever read

    def check_units(n: int) -> None:
        """The body rates' unit on the current experiment's latest :data:`RATE_UNIT_S` of
        rows, the newest data row ``n``, as the whole-log reader checks a whole experiment: a
        gyro in deg/s reads a force that is not there, and the stream was watched silently.
        And where roll or pitch is absent, batch's check that the vehicle stays level where
        the restoring forces read it (:func:`~nnid.datasets.preprocess.check_attitude`) on
        all the experiment's rows kept, as batch reads the whole run."""
        if level:
            j = max(exp_first - dropped, 0)
            # an angle present is not checked: it stays in the frame
            shown_cols = ["p", "q", *(a for a in ("phi", "theta") if a in col)]
            run_x = np.array(xs[j:])
            run = pd.DataFrame({"t": ts[j:], **{c: run_x[:, STATE.index(c)] for c in shown_cols}})
            if exp_col is not None:  # named in the error as batch names it
                run["experiment"] = names[codes[-1]]
            try:
                check_attitude(run, monitor.plant_.vehicle, monitor.plant_.dofs_)
            except NnidInputError as exc:
                raise _RowsRefused(exc.message, source=where, field=exc.field, row=n) from None
        i = max(exp_first, dropped + len(ts) - unit_rows, dropped) - dropped
        kept = np.array(xs[i:])
        kept[np.array(held_cells[i:])] = np.nan
        checked = (*ANGLES, *RATE_OF.values()) if rate_unit else ()
        checked += tuple(c for c in DEPTH_UNIT_COLUMNS if depth_unit and c not in checked)
        seen = pd.DataFrame({"t": ts[i:], **{c: kept[:, STATE.index(c)] for c in checked}})
        if exp_col is not None:  # named in the error as the whole-log reader names it
            seen["experiment"] = names[codes[-1]]
        try:
            if rate_unit:
                check_rate_units(seen, where, row=n)
            if depth_unit:
                check_depth_units(seen, where, row=n)
        except NnidInputError as exc:
            raise _RowsRefused.of(exc) from None

    def unchecked_tail() -> bool:
        """Whether the current experiment has rows after its last unit check."""
        return unit_check and bool(ts) and (dropped + len(ts) - exp_first) % unit_every != 0

    limits = command_limits(monitor.plant_.vehicle)  # the whole-log detect refuses beyond them

    def whole_rows() -> None:
        """The rows every buffer holds whole, and no alarm on a row beyond them."""
        whole = min(map(len, (ts, xs, us, vals, watched, codes, held_cells)))
        for buf in (ts, xs, us, vals, watched, codes, held_cells):
            del buf[whole:]
        for rows_at in (pending, alarm_rows, queue):
            rows_at[:] = [k for k in rows_at if k < dropped + whole]

    def finish(stop: str | None = None) -> DetectResult:
        """The rows watched as the result: the last experiment settled (``stop``: why the
        watch stopped before its input ended)."""
        settle()
        said_unjudged()
        if not ts:
            raise NnidInputError("has a header and no rows", source=where)
        if unkept:
            kept.append(
                f"{unkept} more note{'s' * (unkept != 1)} on the log, said on the console only"
            )
        data = _arrays(ts, xs, us, codes, names)
        values = np.array(watched)  # the model's residual r, and the statistics watched
        values[:, 0:6] = np.array(vals)[:, 0:6]
        trace = Trace(data["t"], run_names(names, data["experiment"], exp_col is not None),
                      values, np.isin(np.arange(len(ts)) + dropped, alarm_rows))  # fmt: skip
        took = time.perf_counter() - start
        return DetectResult(trace, alarms, took, withdrawn, unjudged=unjudged, dropped=dropped,
                            stopped=stop)  # fmt: skip

    try:
        for n, row in enumerate(rows):  # n: the data row from 0, as the whole-log reader counts
            decimal = dialect.get("decimal", ".")
            values = _numbers(row, read, n, where, len(header), kept_unread, decimal)
            for c in [c for c in unread if c not in values and c not in said_held]:
                said_held.add(c)
                noted(
                    f"{c}: empty cells (the first at row {n}) hold their run's last sample (before "
                    f"its first, not yet sampled: filled from it once it arrives), not masked: "
                    f"{UNREAD_BY} {c}"
                )
            for name, bounds in limits.items():
                if name in values and not bounds.holds(values[name]):
                    raise NnidInputError(
                        beyond_range_message(name, values[name], bounds),
                        source=where,
                        field=name,
                        row=n,
                    )
            for angle in [
                a for a in unchecked if abs(values[a]) > radian_limit(a, RATE_OF[a] in col) + 1e-6
            ]:
                unchecked.remove(angle)  # the rows so far and this one, as the whole log is read
                runs = [*(names[c] for c in codes), row[exp_col] if exp_col is not None else ""]
                state = [*xs, [values.get(c, 0.0) for c in STATE]]
                seen = pd.DataFrame(state, columns=list(STATE)).assign(
                    t=[*ts, values["t"]], experiment=runs
                )
                if looks_like_degrees(
                    seen[["t", "experiment", *(c for c in STATE if c in col)]], angle
                ):
                    raise _RowsRefused.of(degrees_error(seen, angle, where, n))
            t = values["t"]
            name = row[exp_col] if exp_col is not None else ""
            # held within its run, as batch holds it (nearest_samples); before the run's first
            # sample NaN, not yet sampled, not a made-up 0: its rows still kept are filled from
            # that sample once it arrives, as batch back-fills them (no residual reads them)
            hold = name == current
            for j in [j for j, c in enumerate(STATE) if c in kept_unread and c in values]:
                if hold and np.isnan(x[j]):  # the run's first sample of it
                    for earlier in xs[max(exp_first - dropped, 0) :]:
                        earlier[j] = values[STATE[j]]
            x[:] = [values.get(c, (x[i] if hold else np.nan) if c in kept_unread else 0.0)
                    for i, c in enumerate(STATE)]  # fmt: skip
            u[:] = [values[c] for c in inputs]
            if exp_col is not None and not name.strip():  # refused by the whole-log reader too
                raise NnidInputError(
                    "empty experiment label: label every row, or remove the column for a "
                    "single run",
                    source=where,
                    field="experiment",
                    row=n,
                )
            if name != current:
                if exp_col is not None:  # as the whole-log reader checks it
                    check_label(name, where, n)
                if unchecked_tail():  # the experiment that ended: its last rows too
                    check_units(n - 1)
                settle()
                stream.reset()
                current = name
                names.append(name)
                exp_first = dropped + len(ts)
            elif t <= last_t:  # the whole-log reader refuses it too (nnid.datasets.log)
                what = "duplicated" if t == last_t else "decreasing"
                raise NnidInputError(
                    f"time is {what}{f' in experiment {name!r}' if exp_col is not None else ''} "
                    f"({shown(last_t)} then {shown(t)}); t must be strictly increasing within an "
                    "experiment",
                    source=where,
                    field="t",
                    row=n,
                )
            elif t - last_t > monitor.max_interval:  # the kernel skips the interval
                noted(
                    f"t = {t:.2f} s{f' ({name})' if name else ''}: no samples for "
                    f"{t - last_t:.3g} s; that interval is not scored"
                )
            last_t = t
            if n >= RATE_ROWS and n % RATE_ROWS == 0:
                # stamps in bursts, batch's rule on the rows the current experiment has (its latest
                # RATE_WINDOW and this one), before the rate: pairs 1e-05 s apart every 0.1 s read
                # as the calibrated 0.05 s, and a difference quotient over 1e-05 s alarmed
                since = max(exp_first - dropped, len(ts) - RATE_WINDOW, 0)
                try:
                    run = current if exp_col is not None else None
                    refuse_bursts(np.append(ts[since:], t), run, MONITOR_STEPS, "t")
                except NnidInputError as exc:
                    raise _RowsRefused(exc.message, source=where, field="t", row=n) from None
                # the rate the calibration holds at, on the latest rows: a log that went from
                # 20 to 10 Hz after its first rows gave a confident thruster loss
                try:
                    monitor.check_rate(
                        np.asarray(ts[-RATE_WINDOW:]), np.asarray(codes[-RATE_WINDOW:])
                    )
                except NnidInputError as exc:
                    raise _RowsRefused.of(exc.with_source(where)) from None
            # the kernel scores no row with a value that is not finite, and reads no x, y, z
            code = stream.update(t, kernel_state(x, unread_at), u)
            ts.append(t)
            xs.append(x.copy())
            empty = [c for c in unread if c not in values]
            held_cells.append(np.isin(STATE, empty) if empty else nothing_held)
            us.append(u.copy())
            vals.append(stream.values.copy())
            watched.append(vals[-1].copy())
            codes.append(len(names) - 1)
            row_no = dropped + len(ts) - 1
            if unit_check and not unchecked_tail():  # a whole block of rows since the last check
                check_units(n)  # before this row's alarm is announced
            rewatched = ref["rewatch"] is not None and ref["code"] == codes[-1]
            # an alarm on a row that completes an earlier alarm's window, or is past it, waits for
            # that judgement: one that restarts the statistics drops it, as batch does
            held = code == 1 and not rewatched and bool(pending) and judged(pending[0])
            if rewatched and row_no >= ref["start"]:
                queue.append(row_no)  # watched on what the isolated changes leave
                if len(queue) >= block + ahead:
                    flush()
            elif code == 1 and not held:
                announce(row_no)
            while pending and judged(pending[0]):
                isolate(pending.pop(0))
            if held and not (ref["rewatch"] is not None and ref["code"] == codes[-1]):
                announce(row_no)  # no isolated change restarted the statistics: batch's alarm too
            if len(ts) > 2 * keep_rows and not pending:  # forget the older half
                cut = len(ts) - keep_rows
                if queue:  # but not the rows still to be watched, nor those their signature reads
                    cut = min(cut, queue[0] - dropped - context - 1)
                if cut > 0:
                    for buf in (ts, xs, us, vals, watched, codes, held_cells):
                        del buf[:cut]
                    dropped += cut
    except (KeyboardInterrupt, SystemExit, NnidInputError) as exc:
        whole_rows()  # an interrupt may land between one row's appends
        if stopped is not None and ts and not isinstance(exc, _RowsRefused):
            stopped(finish(_stop_note(exc, dropped + len(ts), ts[-1])))
        raise
    if unchecked_tail():
        check_units(n)
    return finish()


class _RowsRefused(NnidInputError):
    """A refusal of the rows already watched, not of one row alone: their clock (stamps in
    bursts, another rate than the calibration's) or units (deg/s rates, a depth in cm,
    angles in degrees). Their alarms would be of misread data: none are written."""

    @classmethod
    def of(cls, exc: NnidInputError) -> _RowsRefused:
        """``exc`` as a refusal of the rows watched."""
        return cls(exc.message, source=exc.source, field=exc.field, row=exc.row)


def _stop_note(exc: BaseException, rows: int, t: float) -> str:
    """Why a watch stopped before its input ended, for the outputs: ``rows`` watched, the last
    at ``t``."""
    if isinstance(exc, NnidInputError):
        at = rows if exc.row is None else exc.row
        return (
            f"stopped at row {at}: {exc} (the outputs hold the {rows} rows watched before it, "
            f"to t = {t:.3f} s)"
        )
    how = "Ctrl-C" if isinstance(exc, KeyboardInterrupt) else f"terminated, exit code {exc.code}"
    return (
        f"interrupted at row {rows}, t = {t:.3f} s ({how}): the outputs hold the {rows} rows "
        "watched before it"
    )


def _arrays(ts, xs, us, codes, names) -> dict:
    return {
        "t": np.array(ts),
        "x": np.array(xs),
        "inputs": np.array(us),
        "experiment": np.array(codes),
        "experiment_names": np.array(names, dtype=object),
    }


def value_pm(a: dict) -> str:
    """An alarm's effect size ± its standard error ("-" for either where it is missing: a
    standard error of NaN was not measured, never "nan")."""
    if a.get("value") is None:
        return "-"
    return f"{number(a['value'], 3)} ± {number(a.get('stderr'), 2)}"


def efficiency_interval(a: dict, percent: bool = False) -> str:
    """An alarm's 95 % efficiency interval, "0.41 to 0.63" (``percent``: "41 to 63 %"), or
    "not measured" where a bound is missing (a standard error of NaN)."""
    lo, hi = a.get("efficiency_low"), a.get("efficiency_high")
    if missing(lo) or missing(hi):
        return "not measured"
    if percent:
        return f"{100 * lo:.0f} to {100 * hi:.0f} %"
    return f"{lo:.2f} to {hi:.2f}"


def explained_share(a: dict) -> str | None:
    """How much of the whitened residual after an alarm its hypothesis explains, "55 %", or
    None where that was not measured."""
    explained = a.get("explained")
    return None if missing(explained) else f"{100 * explained:.0f} %"


def seen_again(a: dict) -> str | None:
    """How often the change of an alarm that is not isolated was alarmed again, taken as it
    persisting (:func:`~nnid.fault.detect.persisting`), and the latest: "3 times, last at
    81.20 s", or "no"; None for an alarm that counts no repeats (an isolated change, or one
    said ended or resized: a later alarm after it is judged as a new change), for which the
    question does not apply."""
    repeats = a.get("repeats")
    if repeats is None:
        return None
    if repeats == 0:
        return "no"
    return f"{how_often(repeats)}, last at {a['last_seen_t']:.2f} s"


def withdrawn_line(w: dict) -> str:
    """One line a person reads for an announced alarm that the alarms do not hold."""
    run = f" ({w['experiment']})" if w.get("experiment") else ""
    return f"t = {w['t']:.2f} s{run}: announced, then withdrawn: {w['reason']}"


def unjudged_line(u: dict) -> str:
    """One line a person reads for the rows at a run's end left unjudged
    (:func:`~nnid.fault.detect.unjudged_tail`): no alarm could be raised on them. Where judged
    rows lie between stretches of them, each stretch is named, and the seconds are theirs."""
    run = f" ({u['experiment']})" if u.get("experiment") else ""
    segments = u.get("segments") or [u]
    if len(segments) == 1:
        return (
            f"t = {u['from_t']:.2f}-{u['to_t']:.2f} s{run}: the run's last {u['seconds']:.2f} s "
            f"({u['samples']} samples) not judged, so no alarm could be raised there: "
            f"{UNJUDGED_SHORT}"
        )
    spans = " and ".join(f"{s['from_t']:.2f}-{s['to_t']:.2f} s" for s in segments)
    return (
        f"t = {spans}{run}: {u['seconds']:.2f} s ({u['samples']} samples) of the run's last "
        "rows not judged, the rows between judged, so no alarm could be raised there: "
        f"{UNJUDGED_SHORT}"
    )


def describe_alarm(a: dict) -> str:
    """One line a person reads for an alarm record: of one not isolated, what isolation found
    (:func:`~nnid.fault.detect.finding`) and how often it was seen again, once; the record's
    ``meaning`` says how later alarms are counted (a line of 700 characters said the count
    twice)."""
    where = f"t = {a['t']:.2f} s" + (f" ({a['experiment']})" if a.get("experiment") else "")
    if a.get("repeats"):
        where += f", seen again {seen_again(a)}"
    meaning = finding(a)
    if a.get("thruster") and a.get("efficiency") is not None:
        what = (
            f"thruster {a['thruster']} gives {100 * a['efficiency']:.0f} % of its thrust "
            f"(95 % interval {efficiency_interval(a, percent=True)})"
        )
        if a["kind"] != "thruster_loss" or a.get("resized"):  # not a loss, or a loss resized
            what = f"{meaning}: {what}"
    elif a["effect"]:
        what = f"{meaning}: {a['effect']} = {value_pm(a)}"
    else:
        what = meaning or "a change no hypothesis explains"
    # the confidence is among the hypotheses: how much of the change the named one explains
    # says whether the fault is one of them (two thrusters lost at once: 55 %, confidence 1.00);
    # an unexplained one's finding says that share itself. An alarm not judged has neither
    # (None: no hypothesis was fitted), and said "confidence 0.00, explaining 0 %"
    explained = explained_share(a)
    said = explained and not meaning.startswith(UNEXPLAINED)
    share = f", explaining {explained} of the residual" if said else ""
    confidence = "not measured" if missing(a["confidence"]) else f"{a['confidence']:.2f}"
    return f"{where}: {a['kind']}: {what}; confidence {confidence}{share}"
