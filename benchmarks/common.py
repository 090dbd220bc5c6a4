"""Timing helpers shared by the benchmark scripts."""

from __future__ import annotations

import io
import json
import os
import platform
import subprocess
import sys
import tarfile
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any


def best_of(fn: Callable[[], object], repeats: int = 3) -> float:
    """The shortest wall time of ``repeats`` calls (the least disturbed run)."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def machine(**versions: str) -> str:
    """CPU model, core count, Python and the given package versions, for RESULTS.md."""
    cpu = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next(line.split(":", 1)[1].strip() for line in fh if "model name" in line)
    except (OSError, StopIteration):
        pass
    extra = "".join(f", {k} {v}" for k, v in versions.items())
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}{extra}"


def commit_of(rev: str, repo: Path) -> str:
    """The commit git revision ``rev`` of ``repo`` names; ValueError saying so where none."""
    found = subprocess.run(["git", "-C", str(repo), "rev-parse", "--verify", "--quiet",
                            f"{rev}^{{commit}}"], capture_output=True, text=True)  # fmt: skip
    if found.returncode != 0:
        raise ValueError(f"{rev!r} is not a git revision of {repo}")
    return found.stdout.strip()


def at_revision(rev: str, script: Path, *args: str) -> Any:
    """The JSON a benchmark ``script`` prints on its last line when run with ``args`` on the
    nnid of git revision ``rev`` (that revision's package from ``git archive``, first on the
    subprocess's path; the script and this module are this tree's)."""
    repo = script.resolve().parents[1]
    commit = commit_of(rev, repo)
    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(["git", "-C", str(repo), "archive", commit, "nnid"],
                                 check=True, capture_output=True).stdout  # fmt: skip
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(tmp, filter="data")
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([tmp, str(script.parent)])}
        # an nnid found before the archive's (a path file, a finder) would time this tree as
        # if it were the revision's; run from the archive's folder, as ``-c`` puts the working
        # directory first on the path (a run from the repository found its nnid there)
        found = subprocess.run([sys.executable, "-c", "import nnid; print(nnid.__file__)"],
                               env=env, check=True, stdout=subprocess.PIPE, text=True,
                               cwd=tmp)  # fmt: skip
        if not Path(found.stdout.strip()).resolve().is_relative_to(Path(tmp).resolve()):
            raise RuntimeError(f"the subprocess imports nnid from {found.stdout.strip()}, "
                               f"not from {rev}'s archive")  # fmt: skip
        out = subprocess.run([sys.executable, str(script), *args], env=env, check=True,
                             stdout=subprocess.PIPE, text=True).stdout  # fmt: skip
    return json.loads(out.strip().splitlines()[-1])
