"""The tutorials in docs/tutorials/ run end to end, as a reader would run them.

Each ```bash block of a tutorial runs in order with ``bash -e``, from the root of a copy of the
repository made of symbolic links (so ``configs/...``, ``docs/...`` and ``../shared/data/...``
resolve and the outputs land in a temporary folder). A ```bash norun block is shown, not run.
Every line of a ```text expect block that follows a bash block must appear in that block's
output: the numbers a tutorial quotes come from real runs and cannot drift from the code.
A tutorial that needs measured data says so in a ``<!-- needs: ../shared/data/NAME -->``
comment and skips with that reason when the folder is absent.

The commands run with one thread per library (:data:`nnid.scale.engines.ONE_THREAD` in their
environment), as the test processes do: on a busy machine (beside the other pytest-xdist worker)
NumPy's OpenBLAS starts a second thread that spins waiting for work (``blas_thread_server``), and
`nnid loop` on the demo log took 25 s of CPU instead of 11-12 s and 2-4x the wall time
(2026-11-30, 2 cores already loaded by other jobs; OPENBLAS_NUM_THREADS=1 alone removed it).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from nnid.scale.engines import ONE_THREAD

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


def run_block(commands: str, root: Path) -> subprocess.CompletedProcess:
    """One bash block run with ``bash -e`` from ``root``, as a reader's shell would, but with one
    thread per library (the module docstring says why)."""
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    env.update(COLUMNS="200", PYTHONWARNINGS="ignore", **ONE_THREAD)
    return subprocess.run(
        ["bash", "-e", "-c", commands], cwd=root, env=env, capture_output=True, text=True
    )


def test_the_runner_reads_blocks_and_expectations():
    text = "```bash\necho a\n```\n```text expect\na\n```\n```bash norun\nexit 1\n```\n"
    assert blocks(text) == [("echo a\n", ["a"])]


def test_the_runner_gives_the_commands_one_thread_per_library(tmp_path, monkeypatch):
    """Whatever the test process's environment says: a block's Python sees one thread in every
    BLAS pool it loads (NumPy's and SciPy's OpenBLAS) and numba's layer."""
    for name in ONE_THREAD:
        monkeypatch.delenv(name, raising=False)
    script = (
        "import json, numba, numpy, scipy.linalg, threadpoolctl; print(json.dumps({"
        "'pools': [p['num_threads'] for p in threadpoolctl.threadpool_info()], "
        "'numba': numba.config.NUMBA_NUM_THREADS}))"
    )
    run = run_block(f'python -c "{script}"\n', tmp_path)
    assert run.returncode == 0, run.stderr
    seen = json.loads(run.stdout)
    assert seen["pools"] and set(seen["pools"]) == {1} and seen["numba"] == 1, seen


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
    steps = blocks(text)
    assert steps, f"{tutorial.name} has no bash block to run"
    for commands, expected in steps:
        run = run_block(commands, root)
        output = run.stdout + run.stderr
        assert run.returncode == 0, f"{tutorial.name}: `{commands.strip()}` failed:\n{output}"
        for line in expected:
            assert line in output, f"{tutorial.name}: expected {line!r} in:\n{output}"
