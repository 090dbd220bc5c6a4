"""Train / validation / test splits that never leak across time.

By experiment (whole runs go to one part) or in contiguous blocks within each experiment
(70/15/15 by default, MATLAB's divideblock). Random samples across time are never used for
validation: neighbouring samples of a log are strongly correlated, so a random split would
report training error as validation error. A split records what went where.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from nnid.datasets.log import REPLAY_GROUP
from nnid.datasets.preprocess import experiment_rows
from nnid.errors import NnidInputError

PARTS = ("train", "validation", "test")

#: share of the samples (a fraction of the log) by which whole experiments may miss the split's
#: fractions before it is said: runs are never cut, so a share is only as fine as the runs
MISSED_SHARE = 0.1


@dataclass
class Split:
    train: pd.DataFrame
    validation: pd.DataFrame
    test: pd.DataFrame
    record: dict = field(default_factory=dict)

    def __getitem__(self, part: str) -> pd.DataFrame:
        return getattr(self, part)


def check_fractions(fractions) -> None:
    """Three non-negative fractions summing to 1, else the error naming ``fractions``."""
    if len(fractions) != 3 or min(fractions) < 0 or not np.isclose(sum(fractions), 1.0):
        raise NnidInputError(
            "split fractions must be three non-negative numbers summing to 1", field="fractions"
        )


def check_disjoint(chosen: dict[str, list[str]]) -> None:
    """No experiment named for two parts, else the error naming the later part."""
    for k, p in enumerate(PARTS):  # a run on both sides scores a fit on its own data
        for q in PARTS[k + 1 :]:
            both = [n for n in chosen.get(q) or [] if n in (chosen.get(p) or [])]
            if both:
                raise NnidInputError(
                    f"experiments {both} are named for both {p} and {q}: a part "
                    "scored on runs the fit has seen is no held-out score",
                    field=q,
                )


def split_log(
    log: pd.DataFrame,
    by: str = "block",
    fractions: tuple[float, float, float] = (0.7, 0.15, 0.15),
    assignment: dict[str, list[str]] | None = None,
) -> Split:
    """Split a log. ``by="block"``: each experiment is cut into contiguous train, validation and
    test blocks. ``by="experiment"``: whole experiments, either as ``assignment``
    (``{"train": [...], "validation": [...], "test": [...]}``) or in order of appearance until
    each part holds its fraction of the samples."""
    check_fractions(fractions)
    parts: dict[str, list[pd.DataFrame]] = {p: [] for p in PARTS}
    record: dict = {"by": by, "fractions": list(fractions), "parts": {p: [] for p in PARTS}}
    # each run's rows by position: by label, a log joined by pd.concat (labels repeated) put
    # every run's rows into each run's blocks, and a run named for one part into every part
    groups = experiment_rows(log)
    if by == "block":
        for name, pos in groups:
            part = log.iloc[pos]
            n = len(part)
            cuts = np.round(np.cumsum(fractions)[:2] * n).astype(int)
            for p, (a, b) in zip(
                PARTS, [(0, cuts[0]), (cuts[0], cuts[1]), (cuts[1], n)], strict=True
            ):
                if b > a:
                    parts[p].append(part.iloc[a:b])
                    record["parts"][p].append({"experiment": name, "rows": [int(a), int(b)]})
    elif by == "experiment":
        names = [name for name, _ in groups]
        if assignment is not None:
            # a key not a part ("val") held runs that went to no part, without a word
            extra = sorted(map(str, set(assignment) - set(PARTS)))
            if extra:
                raise NnidInputError(
                    f"assignment names {extra}, not parts of a split: the parts are "
                    f"{', '.join(PARTS)}",
                    field="assignment",
                )
            unknown = sorted(set().union(*assignment.values()) - set(names))
            if unknown:
                raise NnidInputError(
                    f"experiments {unknown} are not in the log", field="assignment"
                )
            chosen = {p: assignment.get(p, []) for p in PARTS}
            check_disjoint(chosen)
            _check_replays(log, chosen)
        else:
            if len(names) < 2:
                raise NnidInputError(
                    "splitting by experiment needs at least two experiments; use by='block'",
                    field="by",
                )
            # a replay group (copies of one run) is one unit: never on both sides
            unit = _units(log, names)
            units = list(dict.fromkeys(unit.values()))
            sizes = np.array(
                [sum(len(idx) for n, idx in groups if unit[n] == u) for u in units], dtype=float
            )
            edges = np.cumsum(fractions)[:2] * sizes.sum()
            centre = np.cumsum(sizes) - sizes / 2
            part_of = dict(zip(units, np.searchsorted(edges, centre), strict=True))
            chosen = {p: [n for n in names if part_of[unit[n]] == k] for k, p in enumerate(PARTS)}
            missed = _missed_fractions(chosen, dict(groups), fractions)
            if missed:
                record["missed"] = missed
        index = dict(groups)
        for p in PARTS:
            for name in chosen[p]:
                parts[p].append(log.iloc[index[name]])
                record["parts"][p].append({"experiment": name, "rows": [0, len(index[name])]})
    else:
        raise NnidInputError(f"unknown split '{by}'; expected 'block' or 'experiment'", field="by")
    frames = {p: (pd.concat(v) if v else log.iloc[0:0]) for p, v in parts.items()}
    record["samples"] = {p: len(f) for p, f in frames.items()}
    return Split(frames["train"], frames["validation"], frames["test"], record)


def _missed_fractions(chosen: dict, index: dict, fractions) -> str | None:
    """Where whole experiments give a part a share of the samples more than
    :data:`MISSED_SHARE` from its fraction (runs of 400, 400 and 33 samples held out 52 % for
    a validation fraction of 0.3), what to say of it; else None."""
    sizes = {p: sum(len(index[n]) for n in chosen[p]) for p in PARTS}
    total = sum(sizes.values())
    missed = [
        f"{p} {sizes[p] / total:.0%} (asked {f:.0%})"
        for p, f in zip(PARTS, fractions, strict=True)
        if abs(sizes[p] / total - f) > MISSED_SHARE
    ]
    if not missed:
        return None
    runs = [len(idx) for idx in index.values()]
    runs_said = ", ".join(map(str, runs)) if len(runs) <= 6 else f"{min(runs)} to {max(runs)}"
    return (
        f"whole experiments ({len(runs)} runs of {runs_said} samples, never cut) give the parts "
        f"{'; '.join(missed)} of the samples: name the runs of each part, or split by block"
    )


def say_missed_fractions(split: Split) -> None:
    """Warn of the split's missed fractions (:func:`_missed_fractions`), if any: called on the
    split a run keeps, not on one it tried and replaced by blocks."""
    if split.record.get("missed"):
        warnings.warn(split.record["missed"], stacklevel=3)


def _units(log: pd.DataFrame, names: list) -> dict:
    """Experiment -> the unit a split assigns whole: its replay group, else itself."""
    if REPLAY_GROUP not in log:
        return {n: n for n in names}
    group = log.groupby("experiment", sort=False)[REPLAY_GROUP].first()
    return {n: group.get(n) if isinstance(group.get(n), str) else n for n in names}


def _check_replays(log: pd.DataFrame, chosen: dict[str, list]) -> None:
    """An explicit split that puts copies of one run on both sides is refused."""
    names = [n for p in PARTS for n in chosen[p]]
    unit = _units(log, names)
    side = {}
    for p in PARTS:
        for n in chosen[p]:
            if unit[n] != n and side.setdefault(unit[n], (p, n))[0] != p:
                other = side[unit[n]]
                raise NnidInputError(
                    f"'{n}' ({p}) and '{other[1]}' ({other[0]}) are copies of one run "
                    f"({unit[n]} of the reader config): hold out the whole group or exclude it",
                    field=p,
                )
