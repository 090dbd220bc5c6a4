"""ROS 1 and ROS 2 bags in, through the ``rosbags`` package (the ``ros`` extra).

With a bag, each ``[[sources]]`` entry of the reader config names a TOPIC in ``file``
(``file = "/imu/data"``). Every message of that topic becomes one row whose columns are the
message's fields as dotted paths, with

- nested messages flattened: ``angular_velocity.x``, ``pose.pose.position.x``;
- times and durations (``builtin_interfaces/Time``, ROS 1 ``time``) as float seconds:
  ``header.stamp``;
- arrays expanded element by element: ``data.0``, ``data.1``, ``channels.0.values.2``
  (arrays longer than :data:`MAX_ARRAY` elements, such as images, are left out);
- ``t_recv``: the time the recorder received the message (s, the bag's own timestamp).

The raw table then goes through :func:`nnid.datasets.mapping.map_source` like any table, so the
units, frames and quaternions of the column map apply unchanged. The experiment is the bag's
stem (``run_3.bag`` -> ``run_3``) unless the column map names an experiment column.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from nnid.datasets.cleaning import CleaningReport
from nnid.datasets.column_map import ColumnMap, Source
from nnid.datasets.mapping import map_message_sources
from nnid.errors import NnidInputError

MAX_ARRAY = 256
"""Arrays with more elements than this are not expanded into columns."""

BAG_SUFFIXES = (".bag", ".db3", ".mcap")
_TIME_TYPES = ("builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration")
_MISSING = "reading ROS bags needs the 'ros' extra: pip install 'nnid[ros]'"


def is_bag(path: str | Path) -> bool:
    """A ROS 1 ``.bag``, a ROS 2 ``.db3``/``.mcap`` file, or a ROS 2 bag folder."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in BAG_SUFFIXES


def _any_reader(path: Path) -> Any:
    """rosbags' AnyReader class, or the NnidInputError that says how to install it."""
    try:
        from rosbags.highlevel import AnyReader
    except ImportError:
        raise NnidInputError(_MISSING, source=str(path)) from None
    return AnyReader


def _default_typestore() -> Any:
    """Message definitions for ROS 2 bags that do not carry their own."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(getattr(Stores, "LATEST", Stores.ROS2_HUMBLE))


def ros_seconds(sec: int, nanosec: int) -> float:
    """A ROS time (whole seconds and nanoseconds) as float seconds, rounded once: nanoseconds
    since the epoch (~1.7e18) as one float were rounded to 256 ns before their division, and
    two receive times 10 ms apart differed from 10 ms by more than the grid snaps over."""
    return sec + nanosec * 1e-9


def flatten_message(msg: Any, prefix: str = "", out: dict[str, Any] | None = None) -> dict:
    """One deserialized message as ``{dotted.field.path: value}`` (see the module docstring)."""
    out = {} if out is None else out
    if getattr(msg, "__msgtype__", None) in _TIME_TYPES:
        out[prefix.rstrip(".")] = ros_seconds(msg.sec, msg.nanosec)
        return out
    if dataclasses.is_dataclass(msg):
        for f in dataclasses.fields(msg):
            if not f.name.startswith("__"):
                flatten_message(getattr(msg, f.name), f"{prefix}{f.name}.", out)
        return out
    name = prefix.rstrip(".")
    if isinstance(msg, np.ndarray) and msg.dtype.kind in "biuf":
        if msg.size <= MAX_ARRAY:
            out.update({f"{prefix}{i}": v for i, v in enumerate(msg.ravel().tolist())})
        return out
    if isinstance(msg, np.ndarray | list | tuple):
        if len(msg) <= MAX_ARRAY:
            for i, item in enumerate(msg):
                flatten_message(item, f"{prefix}{i}.", out)
        return out
    if isinstance(msg, np.generic):
        msg = msg.item()
    out[name] = msg
    return out


def _read_topics(path: Path, topics: list[str]) -> dict[str, list[dict[str, Any]]]:
    """Flattened rows of every message on ``topics``; NnidInputError for unreadable bags."""
    any_reader = _any_reader(path)
    rows: dict[str, list[dict[str, Any]]] = {t: [] for t in topics}
    try:
        with any_reader([path], default_typestore=_default_typestore()) as reader:
            present = sorted({c.topic for c in reader.connections})
            missing = [t for t in topics if t not in present]
            if missing:
                raise NnidInputError(
                    f"topic '{missing[0]}' is not in the bag; its topics are "
                    f"{', '.join(present) or '(none)'}",
                    source=str(path),
                )
            wanted = [c for c in reader.connections if c.topic in rows]
            # a ROS 2 bag before Iron carries no message definitions: a type outside rosbags'
            # store (mavros_msgs) failed at its first message as a bare KeyError
            known = reader.typestore.fielddefs
            unknown = next((c for c in wanted if c.msgtype not in known), None)
            if unknown is not None:
                raise NnidInputError(
                    f"topic '{unknown.topic}': type {unknown.msgtype} has no definition in the "
                    "bag nor in rosbags' type store (a ROS 2 bag recorded before Iron carries "
                    "none)",
                    source=str(path),
                )
            for conn, stamp, data in reader.messages(connections=wanted):
                row = flatten_message(reader.deserialize(data, conn.msgtype))
                row["t_recv"] = ros_seconds(*divmod(stamp, 10**9))
                rows[conn.topic].append(row)
    except NnidInputError:
        raise
    except Exception as err:  # rosbags raises many types for truncated or corrupt bags
        hint = (
            "; a ROS 1 bag whose recording was cut short can be repaired with 'rosbag reindex'"
            if path.suffix.lower() == ".bag"
            else ""
        )
        raise NnidInputError(
            f"cannot be read as a ROS bag ({type(err).__name__}: {err}){hint}", source=str(path)
        ) from None
    return rows


def read_bag_sources(
    path: str | Path, cmap: ColumnMap, report: CleaningReport
) -> list[tuple[Source, pd.DataFrame]]:
    """Each source of ``cmap`` read from the bag at ``path`` and mapped by ``map_source``.

    ``source.file`` is a topic name. Returns ``(source, mapped table)`` pairs ready for
    :func:`nnid.datasets.readers.assemble`.
    """
    path = Path(path)
    if not path.exists():
        raise NnidInputError("file not found", source=str(path))
    rows = _read_topics(path, list(dict.fromkeys(s.file for s in cmap.sources)))
    stem = path.name if path.is_dir() else path.stem
    return map_message_sources(rows, cmap, path, stem, report, "topic '{}' has no messages")
