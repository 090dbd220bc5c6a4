"""Strict JSON for every file nnid writes (ARCHITECTURE.md "JSON outputs").

Every JSON output is strict: no NaN or Infinity (an unmeasured or undefined number is ``null``),
NumPy scalars and arrays become plain numbers and lists, and each file carries
``schema_version``. Writing goes through a temporary file, synced to the disk, and a rename,
so a failed run (or a power loss) never leaves half a file behind.
"""

from __future__ import annotations

import json
import math
import os
import uuid
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from nnid.errors import NnidInputError

#: the version of every JSON contract nnid writes (model.json, metrics.json, comparison.json,
#: loop.json); raised when a required key changes meaning or disappears
SCHEMA_VERSION = 1


def jsonable(value: Any) -> Any:
    """``value`` as plain JSON types: non-finite floats become None, NumPy scalars Python
    numbers, arrays and tuples lists, mapping keys strings."""
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, np.bool_):
        return int(value)
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return v if math.isfinite(v) else None
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, set, frozenset)):
        return [jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def json_float(value: float | None) -> float:
    """A number read from strict JSON: null (an undefined number) is NaN again."""
    return float("nan") if value is None else float(value)


#: the tag that keeps a non-finite number through strict JSON, where null would read back as
#: NaN whatever it was (an infinite validation error of a diverged run is no undefined one)
FLOAT_TAG = "$float"
_NON_FINITE = {"inf": math.inf, "-inf": -math.inf, "nan": math.nan}


def exact_float(value: float) -> float | dict[str, str]:
    """``value`` as strict JSON without loss: a finite number as itself, inf, −inf and NaN as
    ``{"$float": "inf"}`` (``"-inf"``, ``"nan"``); :func:`read_exact_float` reads it back."""
    v = float(value)
    return v if math.isfinite(v) else {FLOAT_TAG: repr(v)}


def read_exact_float(value: Any, what: str = "a number") -> float:
    """Inverse of :func:`exact_float` after a JSON round trip, checked (TypeError naming
    ``what``): a number, null (NaN: an undefined number, as files wrote every non-finite one
    before the tag), or the tag of inf, −inf or NaN."""
    if isinstance(value, dict) and set(value) == {FLOAT_TAG}:
        tagged = value[FLOAT_TAG]
        if isinstance(tagged, str) and tagged in _NON_FINITE:
            return _NON_FINITE[tagged]
        raise TypeError(f"{what}: {tagged!r} is not inf, -inf or nan")
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"{what} is not a number: {value!r}")
    return float(value)


def dumps(value: Any, indent: int | None = 2) -> str:
    """Strict JSON text of ``value`` (see :func:`jsonable`)."""
    return json.dumps(jsonable(value), indent=indent, allow_nan=False)


def write_json(path: str | Path, value: Any, versioned: bool = True) -> Path:
    """Write ``value`` as strict JSON, atomically; a mapping gets ``schema_version`` first."""
    if versioned and isinstance(value, Mapping):
        value = {"schema_version": SCHEMA_VERSION, **value}
    return write_text(path, dumps(value) + "\n")


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) atomically (:func:`write_atomic`)."""
    return write_atomic(path, lambda fh: fh.write(text.encode("utf-8")))


def write_atomic(path: str | Path, write: Callable[[BinaryIO], object]) -> Path:
    """Call ``write`` on a binary temporary file in ``path``'s folder, then rename it to
    ``path``: a reader (or a crash) never meets half a file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    # os.open with 0o666, not mkstemp (0o600 whatever the umask): the file keeps the user's
    # umask once renamed into place, as open() would give it, so a shared folder stays readable
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0)
    while True:
        tmp = path.parent / f".{path.name}.{uuid.uuid4().hex[:12]}"
        try:
            fd = os.open(tmp, flags, 0o666)
            break
        except FileExistsError:  # another writer's name: drawn again
            continue
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            # on the disk before the rename: after a power loss, a rename that reached it
            # before the data left an empty file in place of the old one
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _sync_folder(path.parent)
    return path


def _sync_folder(folder: Path) -> None:
    """Flush ``folder``'s entries (a rename into it) to the disk, where the system lets a
    folder be opened and synced (Windows opens none)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:  # a file system that syncs no folder (some network mounts)
        pass
    finally:
        os.close(fd)


def read_json(path: str | Path) -> Any:
    """Parse a JSON file (NaN and Infinity refused, as a number too large for a float, which
    Python reads as inf: nnid never writes them)."""

    def refuse(token: str) -> Any:
        raise ValueError(f"'{token}' is not strict JSON")

    huge: list[_Huge] = []

    def finite(token: str) -> float | _Huge:
        value = float(token)
        if math.isfinite(value):
            return value
        huge.append(_Huge(token))  # found below, to name where it stands
        return huge[-1]

    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise NnidInputError(f"is not valid JSON ({exc})", source=str(path)) from None
    except OSError as exc:  # a folder in its place, no permission
        raise NnidInputError(f"cannot be read ({exc.strerror})", source=str(path)) from None
    try:
        value = json.loads(text, parse_constant=refuse, parse_float=finite)
        where = _where(value, huge[0]) if huge else None
    except ValueError as exc:  # JSONDecodeError is a ValueError
        raise NnidInputError(f"is not valid JSON ({exc})", source=str(path)) from None
    except RecursionError:
        raise NnidInputError("is not valid JSON (nested too deep)", source=str(path)) from None
    if huge:
        raise NnidInputError(
            f"{huge[0].token} is too large for a number (it reads as infinite): a finite number "
            "is expected",
            source=str(path),
            field=where or None,
        )
    return value


class _Huge:
    """A JSON number too large for a float (1e999: Python reads it as inf), as parsed."""

    def __init__(self, token: str) -> None:
        self.token = token


def _where(value: Any, target: _Huge) -> str | None:
    """The dotted key path to ``target`` in parsed JSON (list items by index; "" at the top),
    or None."""
    if value is target:
        return ""
    if not isinstance(value, dict | list):
        return None
    for key, item in value.items() if isinstance(value, dict) else enumerate(value):
        found = _where(item, target)
        if found is not None:
            return f"{key}.{found}" if found else str(key)
    return None
