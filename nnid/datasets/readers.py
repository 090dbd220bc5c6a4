"""Measured logs in: tables (CSV, Parquet), ROS bags and ArduPilot logs through a column map,
onto one time base.

Every reader (this one, ROS bags, ArduPilot logs) produces raw source tables and maps their
columns (names, units, frames, quaternions) through :mod:`nnid.datasets.mapping`; ``assemble``
resamples them onto a uniform time base per experiment (zero-order hold for commands, linear
interpolation for measurements) and splits experiments at gaps instead of bridging them.
Everything it does goes into the cleaning report.
"""

from __future__ import annotations

import glob
import gzip
import re
import warnings
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pandas as pd

from nnid.datasets.ardupilot import is_ardupilot_log, read_ardupilot_sources
from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.column_map import ColumnMap, Source, load_column_map
from nnid.datasets.log import (
    ANGLES,
    MAX_RUN_SAMPLES,
    PIECE_OF,
    REPLAY_GROUP,
    TIME_UNITS,
    burst_clock,
    check_time_unit,
    checked_time_unit,
    declare_time_unit,
    fine_clock_slip,
    paced_step,
    time_unit_slip,
    typical_step,
    validate_log,
    wrap_angle,
)
from nnid.datasets.mapping import file_label, label_columns, map_source
from nnid.datasets.preprocess import (
    SILENCE,
    clock_tolerance,
    longest_silence,
    run_grid,
    silence_said,
    snap_to_samples,
    unwrap_finite,
)
from nnid.datasets.rosbag import is_bag, read_bag_sources
from nnid.errors import NnidInputError


def read_table(path: str | Path, labels: Sequence[str] = ("experiment",)) -> pd.DataFrame:
    """A CSV (optionally gzipped) or Parquet file; unreadable files are an NnidInputError.
    ``labels``: the run-label columns, read from a CSV as text ("01" and "1" are two runs)."""
    path = Path(path)
    if not path.exists():
        raise NnidInputError("file not found", source=str(path))
    name = path.name.lower()
    try:
        if name.endswith(".parquet"):
            import pyarrow.parquet as pq

            names = pq.read_schema(path).names
            # pyarrow reads a name given twice as one ambiguous field: a schema dump, not a line
            refuse_repeated_names(pd.Series(names), path)
            return fresh_index(pd.read_parquet(path), names, path)
        if name.endswith((".csv", ".csv.gz", ".txt")):
            dialect = _csv_dialect(path)
            # "t, experiment, x": a space after the separator is not part of the name
            dialect["skipinitialspace"] = True
            header = pd.read_csv(path, header=None, nrows=1, dtype=str, **dialect).iloc[0]
            refuse_comment_header(header.tolist(), path)
            refuse_repeated_names(header.str.strip(), path)
            # run labels are names: "01" and "1" are two runs, not one number
            table = pd.read_csv(path, dtype=dict.fromkeys(labels, str), **dialect)
            table = table.rename(columns=lambda c: c.strip() if isinstance(c, str) else c)
            if dialect.get("decimal") == ",":
                refuse_decimal_points(table, path, labels)
            return table
    except NnidInputError:
        raise
    except Exception as err:  # pandas/pyarrow raise many types for truncated or corrupt files
        raise NnidInputError(f"cannot be read as a table ({err})", source=str(path)) from None
    if path.is_dir():
        raise NnidInputError(
            "is a folder: read a dataset folder with a reader config, --columns MAP "
            "(configs/readers/*.toml; the file names and columns are described there)",
            source=str(path),
        )
    raise NnidInputError(
        "unknown table format; expected .csv, .csv.gz or .parquet", source=str(path)
    )


def fresh_index(table: pd.DataFrame, stored: Sequence[str], path: str | Path) -> pd.DataFrame:
    """A Parquet table on the row numbers 0 … n-1, as a CSV is read. pandas restores the index
    a frame was written with: two runs joined without ``ignore_index`` kept their labels
    twice, and everything that finds a run's rows by label mixed the runs up. An unnamed
    index (row labels) is dropped; a named one stored as a column of the file (``stored``:
    the schema's names; a RangeIndex is metadata, not one) is a column written as the index,
    refused naming it rather than dropped or guessed."""
    hidden = [n for n in table.index.names if n is not None and n in stored and n not in table]
    if hidden:
        raise NnidInputError(
            f"column '{hidden[0]}' is stored as the file's index: write it as a column "
            "(df.reset_index().to_parquet(...))",
            source=str(path),
        )
    return table.reset_index(drop=True)


def read_log(path: str | Path) -> pd.DataFrame:
    """Read a CSV or Parquet log (by suffix) as every command reads a table
    (:func:`read_table`: its dialects and header checks) and validate it."""
    path = Path(path)
    if path.exists() and not path.name.lower().endswith((".parquet", ".csv", ".csv.gz")):
        raise NnidInputError(
            "unknown log format; expected .csv, .csv.gz or .parquet", source=str(path)
        )
    return validate_log(read_table(path), source=str(path))


def refuse_repeated_names(header: pd.Series, path: str | Path) -> None:
    """A header that names a column twice is refused: pandas would rename the second of a CSV
    ('u', 'u.1') and one of the two would be used unseen, pyarrow cannot read either of a
    Parquet file's. Empty names (a trailing separator, pandas's "Unnamed: k") are not names."""
    seen: dict[str, int] = {}
    for k, column in enumerate(header, start=1):
        if pd.isna(column):
            continue
        if column in seen:
            raise NnidInputError(
                f"the header names column '{column}' twice (columns {seen[column]} and {k}): "
                "which one is meant is ambiguous; keep one",
                source=str(path),
            )
        seen[column] = k


def refuse_comment_header(header: Sequence[object], path: str | Path) -> None:
    """A first line starting with '#' is refused, naming it: it was read as the header, and
    every contract column was said missing (t first) without a word of the line read."""
    first = header[0] if len(header) else None
    if isinstance(first, str) and first.strip().startswith("#"):
        line = ",".join("" if pd.isna(c) else str(c) for c in header)
        raise NnidInputError(
            f"line 1 ({line[:60]!r}) is a comment, read as the header: the first line of a "
            "CSV log names its columns (t, experiment, u, …); move the comment out of the file "
            "(a dataset card beside it)",
            source=str(path),
        )


def refuse_decimal_points(table: pd.DataFrame, path: str | Path, labels: Sequence[str]) -> None:
    """In a CSV of decimal commas (:func:`csv_dialect`), the first cell written with a decimal
    point, named by its column and row: pandas reads that column as text, and it was refused
    as such at row 0, not at the cell. A column of text of its own (not numbers but for the
    point cells) is left to the log's checks; as --follow, the point is refused, not read."""
    for col in table.columns:
        if col in labels or not pd.api.types.is_string_dtype(table[col]):
            continue
        cells = table[col].dropna().astype(str).str.strip()
        point = cells.str.contains(".", regex=False).to_numpy()
        rest = pd.to_numeric(cells[~point].str.replace(",", ".", regex=False), errors="coerce")
        if point.any() and not rest.isna().any():
            row = int(cells.index[np.flatnonzero(point)[0]])
            raise NnidInputError(
                f"value {cells[row]!r} has a decimal point, but this file's decimal mark is a "
                "comma (its separator is ';' and its first row writes decimal commas): write "
                "every number of the file with one mark",
                source=str(path),
                field=str(col),
                row=row,
            )


def _csv_dialect(path: Path) -> dict:
    """The dialect (:func:`csv_dialect`) of a CSV file from its first two lines."""
    opener = gzip.open if path.name.lower().endswith(".gz") else open
    try:
        with opener(path, "rt", errors="replace") as f:
            head = [f.readline(), f.readline()]
    except (OSError, EOFError):
        return {}  # pandas says what is wrong with the file
    return csv_dialect(*head)


def csv_dialect(header: str, row: str) -> dict:
    """The separator (comma, semicolon or tab) of a CSV from its header line, and the decimal
    comma that a semicolon-separated file from a European locale uses (seen in its first
    ``row``): pandas's ``sep`` and ``decimal``, none for a comma-separated file."""
    counts = {sep: header.count(sep) for sep in (",", ";", "\t")}
    sep = max(counts, key=counts.get)
    if counts[sep] == 0 or sep == ",":
        return {}
    decimal = "," if sep == ";" and "," in row else "."
    return {"sep": sep, "decimal": decimal}


def _bridged(at: np.ndarray, t_ok: np.ndarray, longest: float) -> np.ndarray:
    """Where on the grid (``at``, snapped to the source's samples, :func:`snap_to_samples`) a
    column with defined samples only at ``t_ok`` has a value: on one, or between two at most
    ``longest`` apart (not before the first, nor after the last)."""
    if not t_ok.size:
        return np.zeros(at.size, dtype=bool)
    nxt = np.searchsorted(t_ok, at, side="right")  # the first defined sample after
    prev = nxt - 1
    before, after = t_ok[np.clip(prev, 0, None)], t_ok[np.clip(nxt, 0, t_ok.size - 1)]
    inside = (prev >= 0) & (nxt < t_ok.size)
    return (at == before) | (inside & (after - before <= longest))


def _resample(
    t_src: np.ndarray,
    values: np.ndarray,
    grid: np.ndarray,
    method: str,
    tolerance: float,
    circular: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Values on ``grid``, the source's times sorted and unique, and the grid with each time
    within ``tolerance`` of a source time set to it (:func:`snap_to_samples`): a grid time
    that is a logged time to rounding takes that sample's value, a held command included,
    never the one before.

    Columns flagged in ``circular`` (angles) are interpolated unwrapped and wrapped back to
    [-π, π), so a step across ±π is not interpolated through zero.
    """
    order = np.argsort(t_src, kind="stable")  # out of order, repeated: said at mapping
    t_src, values = t_src[order], values[order]
    if method == "hold":  # a repeated stamp: the later command is the one in force
        t_src, back = np.unique(t_src[::-1], return_index=True)
        keep = len(order) - 1 - back
    else:  # a measurement: the first
        t_src, keep = np.unique(t_src, return_index=True)
    values = values[keep]
    at = grid.copy()  # the log's own t stays the uniform grid
    snap_to_samples(at, t_src, tolerance)
    idx = np.searchsorted(t_src, at, side="right") - 1
    if method == "hold":
        out = values[np.clip(idx, 0, len(t_src) - 1)]
    else:
        wrap = np.zeros(values.shape[1], bool) if circular is None else circular
        out = np.full((at.size, values.shape[1]), np.nan)
        typical = float(np.median(np.diff(t_src))) if t_src.size > 1 else np.inf
        for k in range(values.shape[1]):
            # an undefined sample (a zero quaternion's angles) is bridged where its neighbours
            # are close, and stays a gap (for nnid.datasets.gaps) where they are not: np.unwrap
            # carried one NaN into every later sample of the run
            ok = np.isfinite(values[:, k])
            if ok.any():
                v = unwrap_finite(values[:, k])[ok] if wrap[k] else values[ok, k]
                out[:, k] = np.interp(at, t_src[ok], v)
            if not ok.all():
                out[~_bridged(at, t_src[ok], SILENCE * typical), k] = np.nan
        out = np.where(wrap, wrap_angle(out), out)
    return out, t_src, at


def assemble(
    tables: list[tuple[Source, pd.DataFrame]], cmap: ColumnMap, report: CleaningReport
) -> pd.DataFrame:
    """Put mapped source tables onto one time base per experiment, splitting at gaps."""
    experiments = sorted(set().union(*(set(df["experiment"]) for _, df in tables)), key=_natural)
    kept = [e for e in experiments if cmap.keeps(e)]
    if len(kept) < len(experiments):
        report.add(
            "select",
            f"{len(experiments) - len(kept)} of {len(experiments)} experiments "
            "left out by include/exclude",
        )
    pieces = []
    for exp in kept:
        parts = [(s, df[df["experiment"] == exp]) for s, df in tables]
        parts = [(s, df) for s, df in parts if len(df)]
        if len(parts) < len(tables):
            lacking = [s.file for s, df in tables if not (df["experiment"] == exp).any()]
            report.add(
                "skip experiment",
                f"'{exp}': no data in {', '.join(lacking)}",
                sum(len(df) for _, df in parts),
            )
            continue
        start = max(df["t"].min() for _, df in parts)
        # a command logged on change holds until the next one: only measured (linear)
        # sources bound the end of the window
        linear = [df for s, df in parts if s.method == "linear"] or [df for _, df in parts]
        stop = min(df["t"].max() for df in linear)
        # ... unless the commands stop while the run goes on: a stale command is not held
        for s, df in parts:
            if s.method == "hold" and s.hold_timeout is not None:
                last = float(df["t"].max()) + s.hold_timeout
                if last < stop:
                    report.add(
                        "cut stale hold",
                        f"'{exp}': {s.file} ends {stop - last:.2f} s "
                        f"before the run (+{s.hold_timeout} s timeout): run cut there",
                    )
                    stop = last
        step = _clock(parts, cmap, exp)
        rate = cmap.rate or 1.0 / step
        if stop <= start:
            spans = ", ".join(
                f"{s.file} {df['t'].min():.6g}-{df['t'].max():.6g} s" for s, df in parts
            )
            report.add(
                "skip experiment",
                f"'{exp}': the sources do not overlap in time ({spans})",
                sum(len(df) for _, df in parts),
            )
            continue
        _say_trim(parts, start, stop, exp, report)
        samples = (stop - start) * rate
        if samples > MAX_RUN_SAMPLES:
            raise NnidInputError(
                f"{rate:g} Hz over the {stop - start:.4g} s of '{exp}' is {samples:.3g} samples, "
                f"more than the {MAX_RUN_SAMPLES:.0e} a run may hold: is rate in Hz?",
                source=cmap.name,
                field="rate",
            )
        # relative times: a grid built on UNIX epochs (~1.7e9 s) jitters by ~1e-7 s. The end
        # to the clock's rounding at stop: no more than a source logged there is snapped by
        # (the finest unit read rounds the most: ns since the epoch)
        end = max(
            clock_tolerance(np.array([stop]), start, rate, s.ticks_per_second()) for s, _ in parts
        )
        grid = run_grid(stop - start, rate, end)
        columns: dict[str, np.ndarray] = {}
        valid = np.ones(grid.size, dtype=bool)
        for source, df in parts:
            names = [c for c in df.columns if c not in ("t", "experiment")]
            t_abs = df["t"].to_numpy(np.float64)
            tolerance = clock_tolerance(t_abs, start, rate, source.ticks_per_second())
            values, t_src, at = _resample(
                t_abs - start,
                df[names].to_numpy(np.float64),
                grid,
                source.method,
                tolerance,
                np.isin(names, ANGLES),
            )
            columns.update(dict(zip(names, values.T, strict=True)))
            if source.method == "hold" and source.hold_timeout is not None:
                # inside the run a held command is held over a silence (the end is cut
                # above): said, with how long, as the timeout declares such values stale
                last = np.searchsorted(t_src, at, side="right") - 1
                age = at - t_src[np.clip(last, 0, None)]
                # a run cut at the last command + hold_timeout ends on a sample aged the
                # timeout to the clock's rounding: held as the timeout allows, not stale
                stale = (last >= 0) & (age > source.hold_timeout + tolerance)
                if stale.any():
                    report.add(
                        "stale hold",
                        f"'{exp}': {source.file} is silent for up to {age[stale].max():.3g} s "
                        f"inside the run (hold_timeout {source.hold_timeout:g} s): its last "
                        f"value is held over those {int(stale.sum())} samples",
                    )
            if cmap.gap and source.method == "linear":
                gaps = np.flatnonzero(np.diff(t_src) > cmap.gap)
                for g in gaps:
                    valid &= ~((at > t_src[g]) & (at < t_src[g + 1]))
            else:
                _say_silences(source, t_src, grid, exp, report)
        segments = _runs(valid)
        if not segments:
            why = (
                f"{stop - start:.3g} s at {rate:g} Hz is under two samples"
                if grid.size < 2
                else f"every sample falls in a gap longer than gap = {cmap.gap:g} s"
            )
            report.add("skip experiment", f"'{exp}': {why}", sum(len(df) for _, df in parts))
            continue
        # every grid sample not in a piece is said: a gap's own, and a lone sample between
        # two gaps (a tail logged after a silence), which is no piece and was lost unsaid
        lost = grid.size - sum(b - a for a, b in segments)
        if lost:
            lone = len(_runs(valid, shortest=1)) - len(segments)
            report.add(
                "split at gaps",
                f"'{exp}': {len(segments)} piece{'s' if len(segments) > 1 else ''} (gaps > "
                f"{cmap.gap} s are not interpolated"
                + (f"; {lone} lone sample(s) between gaps dropped" if lone else "")
                + ")",
                lost,
            )
        for k, (a, b) in enumerate(segments):
            # a piece keeps the run's clock (from its first piece's first sample, so a run
            # not cut starts at 0 as before), as mask_gaps's do: restarted at 0, the hole
            # between two pieces was in the cleaning report only, not in the log
            t = grid[a:b] - grid[segments[0][0]]
            piece = pd.DataFrame({"t": t} | {c: v[a:b] for c, v in columns.items()})
            piece.insert(1, "experiment", exp if len(segments) == 1 else f"{exp}#{k}")
            if len(segments) > 1:  # a piece, told by this column (short_piece), not its label
                piece[PIECE_OF] = exp
            pieces.append(piece)
        report.add(
            "resample",
            f"'{exp}': {grid.size} samples at {rate:g} Hz "
            f"({', '.join(f'{s.file}: {s.method}' for s, _ in parts)})",
        )
    if not pieces:
        why = [s.detail for s in report.steps if s.step in ("select", "skip experiment")]
        shown_why = "; ".join(why[:3]) + ("; ..." if len(why) > 3 else "")
        raise NnidInputError(
            "no experiment left after selection and alignment" + (f" ({shown_why})" if why else ""),
            source=cmap.name,
        )
    log = pd.concat(pieces, ignore_index=True)
    if all(s.declares_clock() for s in cmap.sources):
        # every clock in seconds as declared: the grid is too (rate is in Hz), and a 1-Hz
        # one is not refused as milliseconds (validate_log's guess is skipped)
        log, _ = declare_time_unit(log, "s")
        said = "every source's clock is declared (time_unit or row_clock): t not guessed at"
        report.add("time unit", said, columns=["t"])
    else:  # the guess, naming the reader config's declaration (--time-unit is refused here)
        check_time_unit(log, cmap.name, DECLARE_SOURCE_TIME_UNIT)
    if cmap.replays:
        runs = list(dict.fromkeys(log["experiment"]))
        origin = log.groupby("experiment", sort=False)[PIECE_OF].first() if PIECE_OF in log else {}
        whole = {e: origin.get(e) if pd.notna(origin.get(e)) else e for e in runs}
        group = {e: cmap.replay_group(str(whole[e])) for e in runs}
        log[REPLAY_GROUP] = log["experiment"].map(group)
        for label in dict.fromkeys(g for g in group.values() if g):
            members = [e for e in runs if group[e] == label]
            report.add(
                "replay group",
                f"{label}: {len(members)} experiments are copies of one run "
                f"({', '.join(members)}); a split keeps them on one side",
            )
    return log


#: how the unit of a reader config's clock is declared, named where the guess refuses its log
DECLARE_SOURCE_TIME_UNIT = (
    "if it is, declare every source's time_unit in the reader config (s, ms, us, ns), or set "
    "a source's time_scale (0.001 for milliseconds)"
)


def _clock(parts: list[tuple[Source, pd.DataFrame]], cmap: ColumnMap, exp: str) -> float:
    """The sample period of an experiment's fastest measured source (the time base when the
    config gives no ``rate``): its typical step (:func:`~nnid.datasets.log.typical_step`, so
    120 Hz stamped in ms, 8, 8, 9 ms, is gridded at 120 Hz, not its median's 125), its clock
    checked for seconds: milliseconds without a ``time_scale`` would make a run a thousand
    times longer. Commands logged on change and row clocks are not judged: their steps are
    the commands' or the config's."""
    timed = [(s, df) for s, df in parts if s.method == "linear" and not s.row_clock]
    steps = []
    for s, df in timed or parts:
        t = np.unique(df["t"].to_numpy())
        steps.append((typical_step(t, np.inf), s, t))
    step, source, t = min(steps, key=lambda x: x[0])
    # the unit and burst checks read the median step, as check_time_unit and the logged
    # rate do: a burst's is the step inside it, which burst_clock sets against the pace
    median = float(np.median(np.diff(t))) if t.size > 1 else np.inf
    overall = paced_step(np.diff(t)) if t.size > 1 else np.inf
    if not np.isfinite(step):
        raise NnidInputError(
            f"no source of '{exp}' has two distinct time stamps: give rate", source=cmap.name,
            field="rate",
        )  # fmt: skip
    i = cmap.sources.index(source)
    # declared or not: a clock in hours read as seconds (or seconds declared as milliseconds)
    # made a grid of tens of kHz, refused later as a savgol_window or warmup_s too long
    unit = source.time_unit or next(
        (u for u, (_, n) in TIME_UNITS.items() if np.isclose(n * source.time_scale, 1.0)), None
    )
    scaled = source.declares_clock() or source.time_scale != 1.0
    fine = fine_clock_slip(median, unit or "s", scaled, overall) if timed else None
    if fine:
        key = "time_unit" if source.time_unit else "time_scale"
        fix = (
            'declare its time_unit = "s"'
            if fine[1]
            else "set its time_scale to convert it to seconds (3600 for hours, 60 for minutes)"
        )
        if fine[1] != (key == "time_unit"):  # one clock declaration: the other key goes
            fix += f" in place of its {key}"
        raise NnidInputError(
            f"source '{source.file}': {fine[0]}; {fix}",
            source=cmap.name,
            field=f"sources.{i}.{key}",
        )
    slip = time_unit_slip(t) if timed and not source.declares_clock() else None
    if slip:
        raise NnidInputError(
            f"source '{source.file}': {slip}: set its time_scale (0.001 for milliseconds), "
            'or declare its time_unit (s, ms, us, ns: "s" for a logger stepping by whole '
            "seconds)",
            source=cmap.name,
            field=f"sources.{i}.time_scale",
        )
    # a median step inside a burst is no sample period: a grid at it was refused downstream
    # as hours read as seconds
    burst = burst_clock(median, overall) if cmap.rate is None else None
    if burst:
        raise NnidInputError(
            f"source '{source.file}': {burst}: its median step is no sample period to make "
            "the time base of; give rate (Hz), the rate of the log to make",
            source=cmap.name,
            field="rate",
        )
    return step


def _say_trim(
    parts: list[tuple[Source, pd.DataFrame]],
    start: float,
    stop: float,
    exp: str,
    report: CleaningReport,
) -> None:
    """Say the rows of each source outside the span the run keeps (``start`` to ``stop``, the
    times all its sources share): an IMU logging 40 s before the first command lost them
    without a word. A command's row in force at ``start`` is held into the run, not lost."""
    outside = []
    for s, df in parts:
        t = df["t"].to_numpy(np.float64)
        before, after = int((t < start).sum()), int((t > stop).sum())
        if s.method == "hold" and before and not (t == start).any():
            before -= 1  # the last command before the start is the one in force there
        if before or after:
            outside.append((s.file, before, after))
    if outside:
        # said, not counted in rows_removed: the runs' values do not change, and reports
        # pinned on the shared logs (rows_removed == 0) keep their totals
        said = ", ".join(f"{f} {b} rows before it and {a} after" for f, b, a in outside)
        report.add(
            "trim to common span",
            f"'{exp}': the run keeps the {stop - start:.6g} s all its sources share (t = "
            f"{start:.12g} to {stop:.12g} s as logged); left out: {said}",
        )


def _runs(mask: np.ndarray, shortest: int = 2) -> list[tuple[int, int]]:
    """The (start, stop) of each run of True in ``mask`` at least ``shortest`` long (a piece
    of a run needs two samples)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(int), [0]])))
    pairs = zip(edges[::2], edges[1::2], strict=True)
    return [(int(a), int(b)) for a, b in pairs if b - a >= shortest]


def _natural(name: str) -> tuple[list[int | str], str]:
    """Sort key of file and run names: their numbers as numbers (run2 before run10), then the
    name itself, which orders names whose numbers are equal (run01, run1): without it their
    order was the file system's listing, or a set's."""
    return [int(s) if s.isdigit() else s for s in re.split(r"(\d+)", name)], name


def _say_silences(
    source: Source, t_src: np.ndarray, grid: np.ndarray, exp, report: CleaningReport
) -> None:
    """Say what the time base makes up where a source is silent for :data:`SILENCE` of its
    typical intervals: a measured source interpolated over a hole (no ``gap`` set to split the
    run there; a warning and the cleaning report), or a command held past its last sample (no
    ``hold_timeout`` to cut it; the cleaning report). Before, 400 rows became 801 samples
    without a word."""
    steps = np.diff(t_src)
    if not steps.size:
        return
    typical = max(float(np.median(steps)), float(np.median(np.diff(grid))) if grid.size > 1 else 0)
    if source.method == "linear":
        hole = longest_silence(t_src, typical)
        if hole is not None:
            said = silence_said(f"'{exp}': {source.file}", t_src, *hole, " after the run's start")
            report.add("interpolated over a silence", said)
            warnings.warn(said, stacklevel=4)
    elif source.hold_timeout is None and grid[-1] - t_src[-1] > SILENCE * typical:
        # only recorded: a command logged on change holds until the next one by design, and
        # a log that ends on a held command looks the same as one whose commands stopped
        report.add(
            "held past its end",
            f"'{exp}': {source.file} ends {grid[-1] - t_src[-1]:.3g} s before the run: its last "
            "value is held to the end (hold_timeout would cut the run where it goes stale)",
        )


def read_table_sources(
    cmap: ColumnMap, root: Path, report: CleaningReport
) -> list[tuple[Source, pd.DataFrame]]:
    """Every source of a column map read from the tables under ``root``, mapped, not assembled."""
    tables = []
    for i, source in enumerate(cmap.sources):
        # a file of that very name is itself ("run [1].csv" as a pattern matched nothing, and a
        # star took in other files); else the pattern, under the folder as it is named
        exact = root / source.file
        files = (
            [str(exact)]
            if exact.is_file()
            else sorted(glob.glob(str(Path(glob.escape(str(root))) / source.file)), key=_natural)
        )
        if not files:
            raise NnidInputError(
                f"no file matches '{source.file}' under {root}",
                source=cmap.name,
                field=f"sources.{i}.file",
            )
        if cmap.experiment == "file":  # two files of one run would be merged, samples lost
            seen: dict[str, str] = {}
            for f in files:
                other = seen.setdefault(file_label(f), f)
                if other != f:
                    raise NnidInputError(
                        f"'{source.file}' matches {other} and {f}, which both name run "
                        f"'{file_label(f)}' under experiment = \"file\" (a run is the file's "
                        "name without its suffix): give the files distinct names, or name the "
                        "run with a column",
                        source=cmap.name,
                        field=f"sources.{i}.file",
                    )
        frames = [
            map_source(
                read_table(f, label_columns(cmap.experiment)),
                source,
                f,
                cmap.experiment,
                cmap.drop_nonfinite,
                report,
            )
            for f in files
        ]
        if cmap.experiment != "file":
            _refuse_overlapping_files(frames, files, cmap, i)
        tables.append((source, pd.concat(frames, ignore_index=True)))
        report.add(
            "read", f"{source.file}: {sum(len(f) for f in frames)} rows from {len(files)} files"
        )
    return tables


def _refuse_overlapping_files(
    frames: list[pd.DataFrame], files: list[str], cmap: ColumnMap, i: int
) -> None:
    """Files of one source joined into one experiment must follow each other in time
    (consecutive slices of one session): two whose spans overlap (dives each restarting at
    t = 0) were interleaved into one run, or the rows at their common stamps dropped, as each
    file's clock was only checked alone. Refused, naming both files and the experiment."""
    spans: dict[str, list[tuple[float, float, str]]] = {}
    for f, df in zip(files, frames, strict=True):
        for exp, t in df.groupby("experiment", sort=False)["t"]:
            spans.setdefault(exp, []).append((float(t.min()), float(t.max()), f))
    for exp, found in spans.items():
        found.sort()
        end, last = found[0][1], found[0][2]
        for start, stop, f in found[1:]:
            if start < end:  # a file starting where the one before ends is a slice after it
                run = (
                    f"experiment '{exp}'" if cmap.experiment else "the one run (no experiment key)"
                )
                raise NnidInputError(
                    f"'{cmap.sources[i].file}' matches {last} and {f}, whose times overlap in "
                    f"{run}, over {start:.6g}-{min(end, stop):.6g} s: joined, two runs would be "
                    'interleaved; make each file its own run (experiment = "file"), or name '
                    "the column that tells them apart (experiment = ...)",
                    source=cmap.name,
                    field=f"sources.{i}.file",
                )
            if stop > end:
                end, last = stop, f


def read_mapped(
    cmap: ColumnMap, root: Path, report: CleaningReport | None = None
) -> tuple[pd.DataFrame, CleaningReport]:
    """Read every source of a column map under ``root`` and assemble the log."""
    report = report or CleaningReport(source=cmap.name)
    return assemble(read_table_sources(cmap, root, report), cmap, report), report


def _log_reader(
    path: Path,
) -> tuple[str, str, Callable[[Path, ColumnMap, CleaningReport], list]] | None:
    """The source reader for a bag or an ArduPilot log at ``path``, else None (a table)."""
    if is_bag(path):
        return "ROS bag", "topics", read_bag_sources
    if is_ardupilot_log(path):
        return "ArduPilot log", "message types", read_ardupilot_sources
    return None


def load_log(
    path: str | Path,
    columns: str | Path | None = None,
    time_unit: str | None = None,
    time_unit_field: str = "time_unit",
) -> tuple[pd.DataFrame, CleaningReport]:
    """A log file in the contract, or any table/folder read through a column map.

    ``columns`` is the reader config (``--columns MAP.toml``); with it, ``path`` is the data
    root or file the config's sources are found under. A ROS bag (``.bag``, ``.db3``, ``.mcap``
    or a ROS 2 bag folder) or an ArduPilot log (``.bin``, ``.tlog``) needs the config, whose
    sources name topics or message types. ``time_unit`` declares the unit of a contract log's
    ``t`` (one of :data:`~nnid.datasets.log.TIME_UNITS`): converted to seconds, said in the
    cleaning report, and not guessed from its steps; a reader config gives its sources' units
    itself (each source's ``time_unit`` or ``time_scale``). ``time_unit_field``: what an error
    about it names (the CLI option or the config key). Returns the validated log and the
    cleaning report.
    """
    if time_unit is not None:
        checked_time_unit(time_unit, time_unit_field)
        if columns is not None or _log_reader(Path(path)) is not None:
            # one mechanism per reader: two scalings of one clock would multiply
            how = f"the reader config {columns}" if columns is not None else "its reader config"
            raise NnidInputError(
                f"declares the time unit of a log in nnid's columns; {how} gives each "
                "source's unit with its time_unit (s, ms, us, ns) or time_scale (0.001 for "
                "milliseconds)",
                field=time_unit_field,
            )
    special = _log_reader(Path(path))
    if special is not None:
        kind, what, read_sources = special
        if columns is None:
            raise NnidInputError(
                f"a {kind} needs a reader config (--columns MAP.toml) naming the {what} to read "
                "and the log columns they become",
                source=str(path),
            )
        cmap = load_column_map(columns)
        report = CleaningReport(source=str(path))
        with _config_named(cmap, columns):
            df = assemble(read_sources(path, cmap, report), cmap, report)
        return validate_log(df, source=mapped_source(path, columns)), report
    if columns is None:
        report = CleaningReport(source=str(path))
        df = read_table(path)
        report.add("read", f"{len(df)} rows, contract columns as given")
        if time_unit is not None:
            df, said = declare_time_unit(df, time_unit)
            report.add("time unit", said, columns=["t"])
        return validate_log(df, source=str(path)), report
    cmap = load_column_map(columns)
    root = Path(path)
    if root.is_file():
        cmap = cmap.model_copy(
            update={"sources": [s.model_copy(update={"file": root.name}) for s in cmap.sources]}
        )
        root = root.parent
    with _config_named(cmap, columns):
        df, report = read_mapped(cmap, root)
    return validate_log(df, source=mapped_source(path, columns)), report


def mapped_source(path: str | Path, columns: str | Path | None) -> str:
    """How an error names a log read from ``path`` (a file, or the root a reader config's
    sources are found under) through the reader config ``columns`` (None: read as it is).
    Not the config's ``name``, which heads the cleaning report and names no file."""
    return str(path) if columns is None else f"{path} (through {columns})"


@contextmanager
def _config_named(cmap: ColumnMap, columns: str | Path) -> Iterator[None]:
    """An error the reading says against the reader config (by its ``name``) names the
    config's file, where the field it names can be found."""
    try:
        yield
    except NnidInputError as exc:
        if exc.source != cmap.name:
            raise
        raise NnidInputError(
            exc.message, source=str(columns), field=exc.field, row=exc.row
        ) from None
