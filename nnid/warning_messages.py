"""Which recorded warnings reach a person: the messages of nnid's and its data's warnings, each
once, in order; not another package's deprecation or future-change notices (torch's
forward-mode AD loads its decompositions through the deprecated ``torch.jit.script``;
typing_extensions' ``LeafSpec`` notice from inside torch), which are for the code that calls
that package, not for nnid's user. Python hides a ``DeprecationWarning`` outside ``__main__``
by default; a command records every warning, so it filters them here."""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterable
from pathlib import Path

_PACKAGE = str(Path(__file__).resolve().parent) + os.sep
_DEVELOPER = (DeprecationWarning, PendingDeprecationWarning, FutureWarning)


def warning_messages(caught: Iterable[warnings.WarningMessage]) -> list[str]:
    """The messages of ``caught`` for a person (module docstring), each once."""
    return list(
        dict.fromkeys(
            str(w.message)
            for w in caught
            if not issubclass(w.category, _DEVELOPER)
            or str(Path(w.filename).resolve()).startswith(_PACKAGE)
        )
    )
