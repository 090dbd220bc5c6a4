"""Reading TOML files and validating them into pydantic models with one clear error."""

from __future__ import annotations

from pathlib import Path
from typing import Any, TypeVar

import tomllib
from pydantic import BaseModel, ValidationError

from nnid.errors import NnidInputError

Model = TypeVar("Model", bound=BaseModel)


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; a missing or malformed file is an NnidInputError naming it."""
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError:
        raise NnidInputError("file not found", source=str(path)) from None
    except tomllib.TOMLDecodeError as err:
        raise NnidInputError(f"not valid TOML ({err})", source=str(path)) from None


def validated(model: type[Model], data: dict[str, Any], source: str) -> Model:
    """``model.model_validate(data)``, or an NnidInputError naming the source and the field
    (dotted path) of the first problem."""
    try:
        return model.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        field = ".".join(str(p) for p in first["loc"] if not str(p).startswith("function-"))
        msg = first["msg"].removeprefix("Value error, ")
        if first["type"] == "missing":
            msg = "is required but missing"
        elif first["type"] == "extra_forbidden":
            msg = "is not a known field of this file"
        raise NnidInputError(msg, source=source, field=field) from None
