"""nnid: identification of underwater-vehicle dynamics from logged data."""

from nnid.errors import NnidInputError

__version__ = "0.1.0"
__all__ = ["NnidInputError", "__version__"]
