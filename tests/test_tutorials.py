"""The tutorials in docs/tutorials/ run end to end, as a reader would run them.

Each ```bash block of a tutorial runs in order with ``bash -e``, from the root of a copy of the
repository made of symbolic links (so ``configs/...``, ``docs/...`` and ``../shared/data/...``
resolve and the outputs land in a temporary folder). A ```bash norun block is shown, not run.
Every line of a ```text expect block that follows a bash block must appear in that block's
output: the numbers a tutorial quotes come from real runs and cannot drift from the code.
A tutorial that needs measured data says so in a ``<!-- needs: ../shared/data/NAME -->``
comment and skips with that reason when the folder is absent.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TUTORIALS = sorted((REPO / "docs" / "tutorials").glob("*.md"))
BLOCK = re.compile(r"```(bash|text)([^\n]*)\n(.*?)```", re.S)


def blocks(text: str) -> list[tuple[str, list[str]]]:
    """(commands, expected lines) of each bash block to run, in order."""
    out: list[tuple[str, list[str]]] = []
    for kind, info, body in BLOCK.findall(text):
        flags = info.split()
        if kind == "bash" and "norun" not in flags:
            out.append((body, []))
        elif kind == "text" and "expect" in flags:
            assert out, "an expect block must follow a bash block"
            out[-1][1].extend(line.strip() for line in body.splitlines() if line.strip())
    return out


def test_the_runner_reads_blocks_and_expectations():
    text = "```bash\necho a\n```\n```text expect\na\n```\n```bash norun\nexit 1\n```\n"
    assert blocks(text) == [("echo a\n", ["a"])]


@pytest.mark.parametrize("tutorial", TUTORIALS, ids=[t.stem for t in TUTORIALS])
def test_tutorial_runs_end_to_end(tutorial, tmp_path):
    text = tutorial.read_text()
    for need in re.findall(r"<!-- needs: (\S+) -->", text):
        if not (REPO / need).exists():
            pytest.skip(f"{need} is absent (measured data read from ../shared only)")
    root = tmp_path / "nnid"
    root.mkdir()
    for entry in REPO.iterdir():
        if entry.name not in (".git", ".venv", "out"):
            (root / entry.name).symlink_to(entry)
    shared = REPO.parent / "shared"
    if shared.exists():
        (tmp_path / "shared").symlink_to(shared)
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    env.update(COLUMNS="200", PYTHONWARNINGS="ignore")
    steps = blocks(text)
    assert steps, f"{tutorial.name} has no bash block to run"
    for commands, expected in steps:
        run = subprocess.run(
            ["bash", "-e", "-c", commands], cwd=root, env=env, capture_output=True, text=True
        )
        output = run.stdout + run.stderr
        assert run.returncode == 0, f"{tutorial.name}: `{commands.strip()}` failed:\n{output}"
        for line in expected:
            assert line in output, f"{tutorial.name}: expected {line!r} in:\n{output}"
