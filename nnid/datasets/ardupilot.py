"""ArduPilot / ArduSub logs in, through ``pymavlink`` (the ``ardupilot`` extra).

Two formats:

- ``.tlog``: MAVLink telemetry as a ground station records it. ``file`` names a MAVLink message
  (``ATTITUDE``, ``SERVO_OUTPUT_RAW``, ``SCALED_PRESSURE``); its fields are columns as MAVLink
  defines them (``roll`` in rad, ``servo1_raw`` in µs, ``time_boot_ms`` in ms).
- ``.bin``: the autopilot's own dataflash log. ``file`` names a dataflash message (``ATT``,
  ``RCOU``, ``BARO``, ``IMU``); columns are its fields after pymavlink's scaling (``Roll`` in
  degrees, ``C1`` in µs, ``TimeUS`` in µs).

A message type with several instances (``IMU`` of each IMU, ``SERVO_OUTPUT_RAW`` of each port)
is named with its instance, as pymavlink does: ``file = "IMU[0]"``. Array fields are expanded
as ``name.0``, ``name.1``... Each row also has

- ``t_boot``: time since the autopilot booted, in seconds, from ``time_boot_ms`` (``.tlog``),
  else a since-boot ``time_usec`` (``.tlog``, e.g. ``SERVO_OUTPUT_RAW``; its 32-bit wrap every
  71.6 minutes is undone), or ``TimeUS`` (``.bin``); absent for messages that carry none;
- ``t_recv``: in a ``.tlog``, the time the ground station received the message (UNIX seconds);
  in a ``.bin``, pymavlink's clock for the message (UNIX seconds when the log has GPS time,
  else seconds since boot);
- ``src_system``, ``src_component`` (``.tlog`` only): the MAVLink sender; a message type
  from several senders is refused (their messages would be interleaved).

Use ``time = "t_boot"`` for the autopilot's clock (one clock for every message type), or
``time = "t_recv"``. The experiment is the log's file stem unless the column map names an
experiment column. Each table then goes through :func:`nnid.datasets.mapping.map_source`.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import tempfile
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.column_map import ColumnMap, Source
from nnid.datasets.mapping import map_message_sources
from nnid.errors import NnidInputError

ARDUPILOT_SUFFIXES = (".bin", ".tlog")
_MISSING = "reading ArduPilot logs needs the 'ardupilot' extra: pip install 'nnid[ardupilot]'"
_INSTANCE = re.compile(r"^(?P<name>[A-Za-z0-9_]+)\[(?P<instance>[^\]]+)\]$")


def is_ardupilot_log(path: str | Path) -> bool:
    """A dataflash ``.bin`` or a telemetry ``.tlog`` file."""
    return Path(path).suffix.lower() in ARDUPILOT_SUFFIXES


def _open(path: Path) -> Any:
    """A pymavlink reader of ``path`` (indexed, so reading a few message types is fast)."""
    try:
        from pymavlink import DFReader, mavutil
    except ImportError:
        raise NnidInputError(_MISSING, source=str(path)) from None
    if path.stat().st_size == 0:
        raise NnidInputError("the log is empty", source=str(path))
    # the classes directly, not mavutil.mavlink_connection, which treats paths containing
    # '/bin/' as programs to run
    if path.suffix.lower() == ".bin":
        return DFReader.DFReader_binary(str(path))
    return mavutil.mavmmaplog(str(path))


def _types_present(log: Any) -> list[str]:
    return sorted(
        name
        for name, mtype in log.name_to_id.items()
        if mtype is not None and log.counts[mtype] > 0 and name not in ("FMT", "BAD_DATA")
    )


def _instance_field(msg: Any) -> str | None:
    fmt = getattr(msg, "fmt", None)  # dataflash message
    return fmt.instance_field if fmt is not None else getattr(msg, "_instance_field", None)


def _row(msg: Any, tlog: bool) -> dict[str, Any]:
    row: dict[str, Any] = {}
    for key, value in msg.to_dict().items():
        if key == "mavpackettype":
            continue
        if isinstance(value, list | tuple) or type(value).__name__ == "array":
            row.update({f"{key}.{i}": v for i, v in enumerate(value)})
        else:
            row[key] = value
    row["t_recv"] = float(msg._timestamp)
    if tlog:
        row["src_system"] = msg.get_srcSystem()
        row["src_component"] = msg.get_srcComponent()
    return row


def _boot_time(raw: pd.DataFrame) -> pd.Series | None:
    """Seconds since boot from ``time_boot_ms``, ``TimeUS`` or a since-boot ``time_usec``."""
    if "time_boot_ms" in raw:
        return pd.to_numeric(raw["time_boot_ms"]) * 1e-3
    if "TimeUS" in raw:
        return pd.to_numeric(raw["TimeUS"]) * 1e-6
    if "time_usec" in raw:
        us = pd.to_numeric(raw["time_usec"]).to_numpy(dtype=np.float64)
        if us.size and us.max() < 1e12:  # since boot, not a UNIX stamp
            wraps = np.concatenate([[0], np.cumsum(_wraps(us))])
            return pd.Series(us + wraps * 2.0**32, index=raw.index) * 1e-6
    return None


#: how many typical steps the step across a uint32 wrap may span (messages dropped there)
WRAP_STEPS = 10


def _wraps(us: np.ndarray) -> np.ndarray:
    """Where each step of a since-boot microsecond clock ``us`` wraps uint32 (SERVO_OUTPUT_RAW
    wraps every 71.6 minutes): the earlier value near 2^32 and the later small, the step
    across within :data:`WRAP_STEPS` typical steps. A reboot is no wrap (counting any drop
    over 2^31 as one read a reboot after 35.8 minutes of uptime as a wrap, and added 71.6
    minutes to the new boot)."""
    steps = np.diff(us)
    ahead = steps[steps > 0]
    if not ahead.size:
        return np.zeros(steps.size, dtype=bool)
    across = (2.0**32 - us[:-1]) + us[1:]  # the step, were it a wrap
    return (us[:-1] < 2.0**32) & (us[1:] >= 0) & (across <= WRAP_STEPS * np.median(ahead))


def _add_boot_time(raw: pd.DataFrame) -> None:
    """``t_boot``: seconds since boot, where the message type carries a boot clock."""
    if (boot := _boot_time(raw)) is not None:
        raw["t_boot"] = boot


@contextlib.contextmanager
def _captured(buf: io.StringIO) -> Iterator[None]:
    """Keep what pymavlink prints in ``buf``: Python's streams and file descriptor 2, where its
    C indexer writes about bad bytes."""
    with tempfile.TemporaryFile() as tmp:
        try:
            saved: int | None = os.dup(2)
            os.dup2(tmp.fileno(), 2)
        except OSError:
            saved = None
        try:
            with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
                yield
        finally:
            if saved is not None:
                os.dup2(saved, 2)
                os.close(saved)
            tmp.seek(0)
            buf.write(tmp.read().decode(errors="replace"))


def _read_types(path: Path, names: list[str]) -> tuple[dict[str, list[dict]], list[str]]:
    """Rows of every wanted message type and what pymavlink wrote to stdout/stderr."""
    wanted = {}
    for n in names:
        match = _INSTANCE.match(n) or _INSTANCE.match(f"{n}[*]")
        if match is None:
            raise NnidInputError(
                f"'{n}' is not a message type; write e.g. 'ATTITUDE', 'RCOU' or 'IMU[0]'",
                source=str(path),
            )
        wanted[n] = match
    types = {m["name"] for m in wanted.values()}
    tlog = path.suffix.lower() == ".tlog"
    chatter = io.StringIO()
    rows: dict[str, list[dict]] = {n: [] for n in names}
    instances: dict[str, set[str]] = {t: set() for t in types}
    with _captured(chatter):
        log = _open(path)
        try:
            present = _types_present(log)
            if not present:
                raise NnidInputError(
                    f"holds no complete {'MAVLink' if tlog else 'dataflash'} message "
                    "(empty, truncated, or not such a log)",
                    source=str(path),
                )
            missing = sorted(types - set(present))
            if missing:
                raise NnidInputError(
                    f"message type '{missing[0]}' is not in the log; its message types are "
                    f"{', '.join(present) or '(none)'}",
                    source=str(path),
                )
            kwargs = {} if tlog else {"strict": True}
            while (msg := log.recv_match(type=set(types), **kwargs)) is not None:
                mtype = msg.get_type()
                if mtype not in types:
                    continue
                field = _instance_field(msg)
                inst = None if field is None else str(getattr(msg, field))
                if inst is not None:
                    instances[mtype].add(inst)
                row = None
                for name, match in wanted.items():
                    if match["name"] != mtype or match["instance"] not in ("*", inst):
                        continue
                    row = row or _row(msg, tlog)
                    rows[name].append(row)
        finally:
            with contextlib.suppress(Exception):
                log.close()
    for name, match in wanted.items():
        seen = sorted(instances[match["name"]])
        if match["instance"] == "*" and len(seen) > 1:
            raise NnidInputError(
                f"message type '{name}' has several instances ({', '.join(seen)}); "
                f"name one, e.g. '{name}[{seen[0]}]'",
                source=str(path),
            )
        if tlog:
            _refuse_senders(path, name, rows[name])
        if match["instance"] != "*" and not rows[name]:
            raise NnidInputError(
                f"message type '{match['name']}' has no instance {match['instance']}; "
                + (f"its instances are {', '.join(seen)}" if seen else "it has no instances"),
                source=str(path),
            )
    return rows, [line for line in chatter.getvalue().splitlines() if line.strip()]


def _refuse_senders(path: Path, name: str, rows: list[dict]) -> None:
    """One sender per message type of a ``.tlog``: the ATTITUDE of two systems (a vehicle and
    a companion, two vehicles on one link) was interleaved into one source, read as one
    vehicle's. Refused naming each sender (system/component) and its message count."""
    senders = Counter((r["src_system"], r["src_component"]) for r in rows)
    if len(senders) > 1:
        (sys_id, comp_id), _ = senders.most_common(1)[0]
        said = ", ".join(f"{s}/{c} ({n} messages)" for (s, c), n in sorted(senders.items()))
        raise NnidInputError(
            f"message type '{name}' comes from {len(senders)} senders (system/component: "
            f"{said}): their messages would be interleaved into one source; keep one sender's "
            f"(e.g. mavlogdump.py --source-system {sys_id} --source-component {comp_id} "
            f"-o one.tlog {path.name})",
            source=str(path),
        )


def read_ardupilot_sources(
    path: str | Path, cmap: ColumnMap, report: CleaningReport
) -> list[tuple[Source, pd.DataFrame]]:
    """Each source of ``cmap`` read from the ``.bin``/``.tlog`` at ``path``, through ``map_source``.

    ``source.file`` is a message type, optionally with an instance (``IMU[1]``). Returns
    ``(source, mapped table)`` pairs ready for :func:`nnid.datasets.readers.assemble`.
    """
    path = Path(path)
    if not path.is_file():
        raise NnidInputError("file not found", source=str(path))
    try:
        rows, chatter = _read_types(path, list(dict.fromkeys(s.file for s in cmap.sources)))
    except NnidInputError:
        raise
    except Exception as err:  # pymavlink raises many types for truncated or corrupt logs
        raise NnidInputError(
            f"cannot be read as an ArduPilot {path.suffix} log; it may be truncated or corrupt "
            f"({type(err).__name__}: {err})",
            source=str(path),
        ) from None
    if chatter:
        report.add(
            "reader warnings", f"{path}: pymavlink said '{chatter[0]}' ({len(chatter)} lines)"
        )
    return map_message_sources(
        rows,
        cmap,
        path,
        path.stem,
        report,
        "message '{}' has no complete messages in the log",
        _add_boot_time,
    )
