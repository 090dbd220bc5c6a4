"""The cleaning report: every step that changed a log, what it did and why, with counts.

Readers and preprocessing append to it; it is returned with the log and written next to outputs
(JSON for machines, Markdown for people), so nothing is resampled, filtered or removed silently.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path


@dataclass
class Step:
    step: str
    detail: str
    rows_removed: int = 0
    columns: list[str] = field(default_factory=list)


@dataclass
class CleaningReport:
    source: str = ""
    steps: list[Step] = field(default_factory=list)

    def add(self, step: str, detail: str, rows_removed: int = 0, columns=()) -> None:
        self.steps.append(Step(step, detail, int(rows_removed), list(columns)))

    @property
    def rows_removed(self) -> int:
        return sum(s.rows_removed for s in self.steps)

    def to_dict(self) -> dict:
        return {
            "source": self.source,
            "rows_removed": self.rows_removed,
            "steps": [asdict(s) for s in self.steps],
        }

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
        js.write_text(json.dumps(self.to_dict(), indent=2))
        md.write_text(self.to_markdown())
        return js, md
