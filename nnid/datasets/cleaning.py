"""The cleaning report: every step that changed a log, what it did and why, with counts.

Readers and preprocessing append to it; it is returned with the log and written next to outputs
(JSON for machines, Markdown for people), so nothing is resampled, filtered or removed silently.
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass, field
from pathlib import Path

from nnid.serialization import write_json, write_text

_QUOTED = re.compile(r"'[^']*'")
_NUMBER = re.compile(r"(?<![\w.])-?\d+(?:\.\d+)?(?:e[-+]?\d+)?")


@dataclass
class Step:
    step: str
    detail: str
    rows_removed: int = 0
    columns: list[str] = field(default_factory=list)


def _saved_step(s: object) -> bool:
    """Whether ``s`` is a :class:`Step` as :meth:`CleaningReport.to_dict` writes it."""
    if not isinstance(s, dict) or not all(isinstance(s.get(k), str) for k in ("step", "detail")):
        return False
    rows, columns = s.get("rows_removed", 0), s.get("columns", [])
    counted = isinstance(rows, int) and not isinstance(rows, bool)
    return counted and isinstance(columns, list) and all(isinstance(c, str) for c in columns)


@dataclass
class CleaningReport:
    source: str = ""
    steps: list[Step] = field(default_factory=list)

    def add(self, step: str, detail: str, rows_removed: int = 0, columns=()) -> None:
        self.steps.append(Step(step, detail, int(rows_removed), list(columns)))

    @property
    def rows_removed(self) -> int:
        return sum(s.rows_removed for s in self.steps)

    def summary(self, repeated: int = 3) -> list[str]:
        """One line per step, except that a step repeated for more than ``repeated`` runs
        with the same wording becomes one line with the run count and the range of each
        number in it (the per-run detail stays in :meth:`to_dict`)."""
        groups: dict[tuple[str, str], list[tuple[Step, list[float]]]] = {}
        for s in self.steps:
            template = _NUMBER.sub("#", _QUOTED.sub("'…'", s.detail))
            values = [float(v) for v in _NUMBER.findall(_QUOTED.sub("", s.detail))]
            groups.setdefault((s.step, template), []).append((s, values))
        lines = []
        for (step, template), members in groups.items():
            removed = sum(m.rows_removed for m, _ in members)
            tail = f" ({removed} rows removed)" if removed else ""
            if len(members) <= repeated:
                lines += [f"{step}: {m.detail}" + (f" ({m.rows_removed} rows removed)"
                          if m.rows_removed else "") for m, _ in members]  # fmt: skip
                continue
            columns = list(zip(*(v for _, v in members), strict=False))
            text = template.replace("'…': ", "").replace("'…'", "each")
            for values in columns:
                lo, hi = min(values), max(values)
                text = text.replace("#", f"{lo:g}" if lo == hi else f"{lo:g}-{hi:g}", 1)
            lines.append(f"{step} in {len(members)} runs: {text}{tail}")
        return lines

    def to_dict(self) -> dict:
        return {
            "source": self.source,
            "rows_removed": self.rows_removed,
            "steps": [asdict(s) for s in self.steps],
        }

    @classmethod
    def from_dict(cls, value: object) -> CleaningReport:
        """The inverse of :meth:`to_dict` (a saved model's fit report), checked: a file edited
        by hand is refused at loading (TypeError), never a report that fails when read."""
        steps = value.get("steps") if isinstance(value, dict) else None
        if not isinstance(value, dict) or not isinstance(steps, list):
            raise TypeError("the fit report is not a mapping with a list of steps")
        report = cls(source=str(value.get("source", "")))
        for s in steps:
            if not _saved_step(s):
                raise TypeError(f"a step of the fit report is not one: {s!r:.80}")
            rows, columns = s.get("rows_removed", 0), s.get("columns", [])
            report.add(s["step"], s["detail"], rows, columns)
        return report

    def to_markdown(self) -> str:
        lines = [
            f"# Cleaning report: {self.source}",
            "",
            "| step | what and why | rows removed |",
            "|---|---|---|",
        ]
        lines += [f"| {s.step} | {s.detail} | {s.rows_removed} |" for s in self.steps]
        lines += ["", f"Rows removed in total: {self.rows_removed}."]
        return "\n".join(lines) + "\n"

    def write(self, directory: str | Path, stem: str = "cleaning") -> tuple[Path, Path]:
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        js, md = directory / f"{stem}.json", directory / f"{stem}.md"
        write_json(js, self.to_dict())
        write_text(md, self.to_markdown())
        return js, md
