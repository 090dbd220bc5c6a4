"""Reading TOML files and validating them into pydantic models with one clear error."""

from __future__ import annotations

import math
import tomllib
import unicodedata
from collections.abc import Iterable, Mapping
from numbers import Real
from pathlib import Path
from typing import Annotated, Any, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from nnid.errors import NnidInputError

Model = TypeVar("Model", bound=BaseModel)
#: keys whose value selects the variant of a table (pydantic puts that value in error paths)
_TAGS = ("kind", "model")


#: a finite number above zero (a duration, a rate, a mass)
PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]


class StrictModel(BaseModel):
    """The base of every user-written table (config, vehicle file, batch manifest): an unknown
    key is refused, NaN or inf is refused, and a value of the wrong type is refused, never
    coerced (a TOML ``true`` or ``"11.5"`` where a number belongs is a typo, not 1 or 11.5)."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True)


def shown(value: Any) -> str:
    """A value as an error message shows it: numbers plainly ("12.5", "inf"), a missing one as
    "empty (NaN)", text in quotes; never a type name such as ``np.float64(nan)``."""
    if isinstance(value, bool):
        return str(value)
    try:
        number = float(value)
    except (TypeError, ValueError):
        return repr(str(value))
    if isinstance(value, str):
        return repr(value)
    return "empty (NaN)" if math.isnan(number) else f"{number:g}"


#: the largest random seed (a config's, ``--seed``): 2³² − 1, numpy's legacy generators' and
#: most tools' range. Seeds are derived from it (NARX's per-epoch generator seed × 100 003 +
#: epoch; the simulator's seed + i, the loop's seed × 1000 + i): up to this bound each stays far
#: below torch's limit, 2⁶⁴ (2**64 overflowed torch.Generator.manual_seed, a traceback, and
#: 2**48 only at a NARX fine-tune, after the one-step fit)
MAX_SEED = 2**32 - 1

#: the widest hidden layer (a larger one is a typo that fails to allocate): the configs' cap,
#: and the models' for settings given in Python
MAX_WIDTH = 100_000

#: the family-wise significance the residual loop's F-test takes (a loop config's ``alpha``,
#: ``--alpha``, a batch manifest's ``options.alpha``): above 0.5 a "significant" effect is
#: likelier noise than not. Here, below both the config and the manifest, so each takes it
ALPHA_MIN, ALPHA_MAX = 1e-12, 0.5

#: the shortest isolation window after a fault alarm, s (``nnid detect --window``, a batch
#: manifest's ``options.window``): here, below both the CLI's runs and the manifest, so each
#: takes it
MIN_WINDOW_S = 0.5

#: the highest false-alarm target of a residual monitor, per hour (a train config's
#: ``[detect] false_alarm_per_hour``, a saved monitor's): one a second. Its thresholds are
#: fitted to the tail of rare healthy excursions; a rate above it asks for no threshold at all
MAX_FALSE_ALARMS_PER_HOUR = 3600.0


#: the Unicode categories of a character that has no place in one line of text: the control
#: characters (a line break, a tab, \x00-\x1f, \x7f-\x9f), the line and paragraph
#: separators U+2028 and U+2029, which are none, yet str.splitlines breaks at them as at \n,
#: and a lone surrogate (a name from bytes that were not UTF-8: no file can be written with it)
_NOT_ONE_LINE = ("Cc", "Zl", "Zp", "Cs")


def control_character(text: str) -> str | None:
    """The first control character of ``text`` (a line break, a tab, ``\\x00``-``\\x1f``,
    ``\\x7f`` …) or Unicode line or paragraph separator (U+2028, U+2029), or None: every
    character ``str.splitlines`` breaks at is one."""
    return next((c for c in text if unicodedata.category(c) in _NOT_ONE_LINE), None)


def one_line(name: str) -> str:
    """``name`` if it is one line of text (no :func:`control_character`), else a ValueError
    saying which: a name labels report lines and headings (a vehicle's, a run's, a model's),
    which a line break, a line separator or another control character would break."""
    control = control_character(name)
    if control is not None:
        raise ValueError(f"a name is one line of text, without {control!r}")
    return name


def visible_line(name: str) -> str:
    """``name`` if it can label reports, files and messages (a vehicle's, a model's, a reader
    config's): a visible character, on one line (:func:`one_line`), else a ValueError."""
    if not name.strip():
        raise ValueError("give a name with a visible character")
    return one_line(name)


def repeated(names: list[str]) -> list[str]:
    """The names a list gives more than once, sorted (for an error that names them)."""
    return sorted({n for n in names if names.count(n) > 1})


def checked_names(value: object, field: str) -> list[str]:
    """``value`` as a list of column names, each given once, or the error naming ``field``
    (and the entry): a setting given in Python skips the config's checks, and a list of ints
    or a nested list failed deep in a fit or a prediction ("unhashable type: 'list'"). One
    string is one name (``"tau_X"`` was split into the columns t, a, u, _ and X)."""
    if isinstance(value, str):
        return [value]
    if not isinstance(value, Iterable) or isinstance(value, (bytes, Mapping)):
        raise NnidInputError(f"a list of column names is expected, not {value!r}", field=field)
    names = list(value)
    for i, name in enumerate(names):
        if not isinstance(name, str) or not name.strip():
            raise NnidInputError(
                f"a column name (a non-empty string) is expected, not {name!r}",
                field=f"{field}.{i}",
            )
    twice = repeated(names)
    if twice:
        raise NnidInputError(f"{', '.join(twice)} named twice", field=field)
    return names


def disjoint_columns(inputs: Iterable[str], outputs: Iterable[str]) -> None:
    """Refuse a column that is both an output and an input of an input-output model, naming
    ``inputs``: the model would read the measured answer (with input delay 0 the very sample
    it predicts), in free run too. The configs' check and the models' (settings given in
    Python skip the config)."""
    read = set(inputs)
    both = [c for c in outputs if c in read]
    if both:
        raise NnidInputError(
            f"{', '.join(both)} is an output and an input: the model would read the measured "
            "answer",
            field="inputs",
        )


def adjoint_solver(adjoint: object, lm: bool, method: str) -> None:
    """Refuse adjoint gradients (``adjoint``) where the hybrid integrates with nnid's own RK4
    (``method`` "nnid_rk4", which the Levenberg-Marquardt trainer, ``lm``, needs and "auto"
    takes with it): that solver has no adjoint, and the first training batch failed after the
    whole physics fit. The config's check and the model's."""
    if not isinstance(adjoint, bool):
        raise NnidInputError(f"adjoint is true or false, not {adjoint!r}", field="adjoint")
    if adjoint and (lm or method == "nnid_rk4"):
        why = "the Levenberg-Marquardt trainer integrates" if lm else "method 'nnid_rk4' is"
        raise NnidInputError(
            f"adjoint gradients need torchdiffeq's solvers, and {why} nnid's own RK4, which "
            "has no adjoint: set adjoint = false, or use an Adam trainer with method 'auto', "
            "'rk4' or 'dopri5'",
            field="adjoint",
        )


def window_lengths(window: object, field: str = "simulation_window") -> list[int]:
    """``window`` (a length in samples, or a list of lengths) as a list of whole lengths of
    at least 2, or the error naming ``field``: the configs' check and the models' (2.5 given
    in Python was cut to 2 by ``int``). A numpy integer is a whole number."""
    many = isinstance(window, Iterable) and not isinstance(window, str | bytes | Mapping)
    lengths = list(window) if many else [window]
    whole = [
        isinstance(w, Real) and not isinstance(w, bool) and math.isfinite(w)
        and float(w).is_integer() and w >= 2
        for w in lengths
    ]  # fmt: skip
    if not lengths or not all(whole):
        raise NnidInputError(
            f"a window length is a whole number, at least 2 samples, or a list of them; "
            f"not {window!r}",
            field=field,
        )
    return [int(w) for w in lengths]


def nnid_file(data: Mapping[str, Any]) -> tuple[str, str] | None:
    """Which of nnid's TOML files ``data`` is, by the key that only it has (a config's
    ``kind``, a vehicle file's ``mass``, a reader config's ``sources``, a manifest's
    ``command``): ``("config" | "vehicle" | "columns" | "manifest", how an error names it)``;
    None when no such key, or two, tell (a stray key is then the validation's to name)."""
    kind = data.get("kind")
    found = [key for key in ("mass", "sources", "command") if key in data]
    if isinstance(kind, str) and not found:
        return "config", f"a '{kind}' config (for `nnid {kind}`)"
    if "kind" in data or len(found) != 1:
        return None
    return {
        "mass": ("vehicle", "a vehicle file (for --vehicle, or a config's vehicle)"),
        "sources": ("columns", "a reader config (for --columns)"),
        "command": ("manifest", "a batch manifest (for `nnid batch`)"),
    }[found[0]]


def refuse_other_file(data: Mapping[str, Any], expected: str, what: str, source: str) -> None:
    """Refuse one of nnid's files given where another goes (``expected``, a key of
    :func:`nnid_file`; ``what`` names it): a vehicle file given as a train config was said as
    "field 'name': is not a known field here", a config given as --vehicle as "field 'name':
    is required but missing", blaming a key of a file that is whole and of another kind."""
    found = nnid_file(data)
    if found is not None and found[0] != expected:
        raise NnidInputError(f"this is {found[1]}, not {what}", source=source)


def resolve(base: Path, path: str) -> Path:
    """A path a file names, relative to ``base`` (that file's folder) unless absolute, as the
    batch manifest and the reader config read theirs: never the current folder's, where a
    file of the same name silently won over the one beside the config. (An option's path,
    ``--data`` or ``--vehicle``, is the user's, relative to the current folder.)"""
    p = Path(path)
    return p if p.is_absolute() else base / p


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing or malformed file is an NnidInputError naming it."""
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        raise NnidInputError("file not found", source=str(path)) from None
    except IsADirectoryError:
        raise NnidInputError("is a folder, not a TOML file", source=str(path)) from None
    except OSError as err:  # no read permission: one line naming the file, not a traceback
        raise NnidInputError(f"cannot be read ({err.strerror or err})", source=str(path)) from None
    try:
        # utf-8-sig: the byte-order mark an editor on Windows writes is no TOML error
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = raw[: err.start].count(b"\n") + 1
        raise NnidInputError(
            f"is not UTF-8 text at line {line} (byte {err.start}): save it as UTF-8",
            source=str(path),
        ) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise NnidInputError(f"not valid TOML ({err})", source=str(path)) from None
    except ValueError as err:  # an integer beyond Python's digit limit
        raise NnidInputError(f"not valid TOML ({err})", source=str(path)) from None
    except RecursionError:
        raise NnidInputError("not valid TOML (nested too deep)", source=str(path)) from None


def field_path(loc: tuple, data: Any) -> str:
    """The dotted path of an error location as the user wrote it: pydantic's own steps (the
    tag of a tagged union, the member type of a plain union, validator names) are dropped by
    walking the input along the location."""
    out: list[str] = []
    node = data
    for i, step in enumerate(loc):
        if isinstance(node, dict):
            following = loc[i + 1] if i + 1 < len(loc) else None
            if step in node:
                out.append(str(step))
                node = node[step]
            elif any(node.get(t) == step for t in _TAGS) or following is not None:
                # the union's tag (written, or a default) or member name: not a key of the
                # file (a missing or unknown key is always an error's last step)
                continue
            else:
                if not str(step).startswith("function-"):
                    out.append(str(step))  # a missing key, named
                break
        elif isinstance(node, list) and isinstance(step, int) and 0 <= step < len(node):
            out.append(str(step))
            node = node[step]
        elif isinstance(node, list) and isinstance(step, str):
            continue  # the union member a list matched ("list[...]"): its index follows
        else:
            break  # a leaf: what follows is pydantic's name of a union member
    return ".".join(out)


def _written(loc: tuple, data: Any) -> bool:
    """Whether every step of ``loc`` is a key or an index the user wrote (not a name that
    pydantic gives a union member)."""
    node = data
    for step in loc:
        if isinstance(node, dict) and step in node:
            node = node[step]
        elif isinstance(node, list) and isinstance(step, int) and 0 <= step < len(node):
            node = node[step]
        else:
            return False
    return True


def _show(value: Any) -> str:
    """A value as the user wrote it (short)."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def validated(
    model: type[Model], data: dict[str, Any], source: str, context: dict[str, Any] | None = None
) -> Model:
    """``model.model_validate(data, context=context)``, or an NnidInputError naming the source
    and the field (dotted path) of the first problem."""
    try:
        return model.model_validate(data, context=context)
    except ValidationError as err:
        errors = err.errors()
        first = errors[0]
        field = field_path(tuple(first["loc"]), data)
        whole = first["type"].endswith("_type") or first["type"] == "literal_error"
        if isinstance(first.get("input"), (dict, list)) and whole:
            # a plain union (a number or a list of them; "train" or a list of bounds; a column
            # name or a table) reports each member's error in turn; the member the value's type
            # fits reaches into the value, and its error is the one that says what is wrong
            # (an element, named by its index, or a key)
            loc = tuple(first["loc"])
            if (
                isinstance(first["input"], dict)
                and loc
                and loc[-1] not in first["input"]
                and not _written(loc, data)
            ):
                field = field_path(loc[:-1], data)  # the last step names the member, no key
            for other in errors[1:]:
                if other.get("input") is first["input"] and other["type"].endswith("_type"):
                    continue  # another member refusing the whole value: no key within it
                path = field_path(tuple(other["loc"]), data)
                if path.startswith(field + "."):
                    first, field = other, path
                    break
            else:
                if isinstance(first["input"], list):
                    # a row of a matrix where a vector's number goes ("inertia.0" for text in
                    # the middle of a 3x3 tensor): the member the rows fit names the element,
                    # or the row or matrix of the wrong length
                    parent = field.rpartition(".")[0]
                    for other in errors[1:]:
                        path = field_path(tuple(other["loc"]), data)
                        leaf = not isinstance(other.get("input"), (dict, list))
                        within = path == parent or path.startswith(parent + ".")
                        if parent and within and (leaf or not other["type"].endswith("_type")):
                            first, field = other, path
                            break
        msg = first["msg"].removeprefix("Value error, ")
        inner = first.get("ctx", {}).get("error")
        table = isinstance(first.get("input"), dict)
        if table and isinstance(inner, NnidInputError) and inner.field and inner.source is None:
            # a check of a whole table (its input the table) that names the key within it at
            # fault (``experiments.2.signals.0.f1`` of a simulate config); a check of one key
            # has named it already
            loc = tuple(first["loc"])
            if loc and not _written(loc, data):
                # the last step is the union member checked (a [data] table whose kind is left
                # to its default, "vehicle"), no key of the file
                field = field_path(loc[:-1], data)
            msg, field = inner.message, ".".join(filter(None, [field, inner.field]))
        elif first["type"] == "missing":
            msg = "is required but missing"
        elif first["type"] == "extra_forbidden":
            msg = "is not a known field here"
        elif first["type"] == "union_tag_invalid":
            ctx = first.get("ctx", {})
            field = ".".join(filter(None, [field, str(ctx.get("discriminator", "")).strip("'")]))
            msg = f"'{ctx.get('tag')}' is not one of {ctx.get('expected_tags')}"
        elif first["type"] == "union_tag_not_found":
            ctx = first.get("ctx", {})
            field = ".".join(filter(None, [field, str(ctx.get("discriminator", "")).strip("'")]))
            msg = "is required but missing"
        elif first["type"] in ("model_attributes_type", "model_type", "dict_type"):
            # "Input should be a valid dictionary or object to extract fields from" says
            # nothing of TOML: `data = "log.csv"` where a [data] table goes
            msg = f"is a table ([{field}] with its keys below it), not {_show(first.get('input'))}"
        elif first["type"] == "list_type" and isinstance(first.get("input"), dict):
            values = list(first["input"].values())
            if values and all(isinstance(v, Real) and not isinstance(v, bool) for v in values):
                # `[r_g]` with x, y, z below it: a vector written as a table of named values
                shown_list = ", ".join(_show(v) for v in values)
                msg = f"is a list of values ({field} = [{shown_list}]), not a table of them"
            else:
                # `[thrusters]` where `[[thrusters]]` goes: one table where a list of them does
                msg = f"is a list of tables ([[{field}]] above each one), not one table ([{field}])"
        elif first["type"] == "finite_number":
            msg = f"must be a finite number, not {_show(first.get('input'))}"
        elif not isinstance(first.get("input"), (dict, list, type(None))):
            msg = f"{msg} (got {_show(first['input'])})"
        raise NnidInputError(msg, source=source, field=field) from None
