"""Which recorded warnings reach a person: the messages of nnid's and its data's warnings, each
once, in order; not another package's deprecation notices (torch's forward-mode AD loads its
decompositions through the deprecated ``torch.jit.script``), which are for that package's
developers and which Python itself hides outside ``__main__``."""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from pathlib import Path

_PACKAGE = str(Path(__file__).resolve().parent)
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
