"""nnid: identification of underwater-vehicle dynamics from logged data."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from nnid.errors import NnidInputError

if TYPE_CHECKING:
    from nnid.models.base import NnidModel

__version__ = "0.2.0"
__all__ = ["NnidInputError", "__version__", "load_model"]


def load_model(folder: str | Path) -> NnidModel:
    """Load any saved nnid model (``model.save(dir)`` or ``nnid train --out dir``) by the kind
    its ``model.json`` names; no code runs from the files (tensors with
    ``weights_only=True``, metadata as JSON)."""
    from nnid.models.base import load_model as _load

    return _load(folder)
