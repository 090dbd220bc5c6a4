"""Output bounds of an input-output model: a saturating sensor, an overflowing tank.

A specification is None (no clamp), ``"train"`` (every output's training range) or one
``[low, high]`` per output, each a number in the output's units, None (open) or ``"train"``
(that output's training minimum or maximum). Models clamp their predictions to the resolved
bounds in every prediction mode and inside closed-loop training, so a free run cannot leave
the range the plant can reach.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
import torch

from nnid.errors import NnidInputError

Bound = float | str | None
OutputBounds = str | Sequence[Sequence[Bound]] | None
#: resolved bounds: [low, high] per output in its units, None where open
Resolved = list[list[float | None]]


def check_bounds(bounds: OutputBounds, n_out: int) -> OutputBounds:
    """Validate an ``output_bounds`` specification; returns it as lists (JSON-ready)."""
    if bounds is None:
        return None
    if isinstance(bounds, str):
        if bounds != "train":
            raise NnidInputError(
                "output_bounds is None, 'train' or [low, high] per output", field="output_bounds"
            )
        return bounds
    out = [list(b) for b in bounds]
    if len(out) != n_out or any(len(b) != 2 for b in out):
        raise NnidInputError(
            "output_bounds needs one [low, high] per output", field="output_bounds"
        )
    for pair in out:
        for i, v in enumerate(pair):
            if v is not None and v != "train":
                pair[i] = float(v)
        lo, hi = pair
        if isinstance(lo, float) and isinstance(hi, float) and not lo < hi:
            raise NnidInputError("low must be below high", field="output_bounds")
    return out


def resolve_bounds(
    spec: OutputBounds, outputs: Sequence[str], log: pd.DataFrame | None
) -> Resolved | None:
    """The bounds in the outputs' units; ``"train"`` entries take the minimum (low) or maximum
    (high) of ``log``'s column. None when there are no bounds, or while ``log`` is None and a
    ``"train"`` entry is still to be resolved. A ``"train"`` entry that resolves to a low at or
    above the high is refused (a clamp whose low exceeds its high returns the high everywhere)."""
    if spec is None:
        return None
    pairs = [["train", "train"] for _ in outputs] if spec == "train" else spec
    out: Resolved = []
    for c, pair in zip(outputs, pairs, strict=True):
        row: list[float | None] = []
        for i, v in enumerate(pair):
            if v == "train":
                if log is None:
                    return None
                col = log[c].to_numpy(np.float64)
                v = float(np.nanmin(col) if i == 0 else np.nanmax(col))
            row.append(v)
        lo, hi = row
        if lo is not None and hi is not None and not lo < hi:
            raise NnidInputError(
                f'output_bounds of {c}: low {lo:g} is not below high {hi:g} once "train" is '
                f"read from the training data ({pair[0]!r}, {pair[1]!r}); give a low below the "
                "training maximum and a high above the training minimum",
                field="output_bounds",
            )
        out.append(row)
    return out


def restored_bounds(value: object, outputs: Sequence[str]) -> Resolved | None:
    """Resolved bounds read back from a saved model: None, or one ``[low, high]`` per output,
    each a number or None (open). Anything else is a damaged file, refused at loading (it
    loaded and failed inside the first prediction)."""
    if value is None:
        return None
    if (
        not isinstance(value, list)
        or len(value) != len(outputs)
        or any(not isinstance(b, list) or len(b) != 2 for b in value)
        or any(
            v is not None and (isinstance(v, bool) or not isinstance(v, int | float))
            for b in value
            for v in b
        )
    ):
        raise ValueError(
            f"bounds are null or one [low, high] per output ({len(outputs)}), each a number or "
            f"null, not {value!r}"
        )
    return [[None if v is None else float(v) for v in b] for b in value]


def bound_arrays(resolved: Resolved, mean: torch.Tensor, std: torch.Tensor):
    """(low, high) tensors in normalised units (±inf where open) of resolved bounds."""
    lo = torch.tensor([-np.inf if b[0] is None else b[0] for b in resolved], dtype=mean.dtype)
    hi = torch.tensor([np.inf if b[1] is None else b[1] for b in resolved], dtype=mean.dtype)
    return (lo - mean) / std, (hi - mean) / std
