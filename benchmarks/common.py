"""Helpers shared by the benchmark scripts: timing, the machine, a revision's nnid, and the
free-run scores of single models and ensembles by nnid's own rules."""

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

import numpy as np
import pandas as pd


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


def scored_free_run(log: pd.DataFrame, predicted: pd.DataFrame, column: str, warmup: int):
    """RMSE of the free run ``predicted`` of ``column`` over the samples of ``log`` after its
    first ``warmup``, by the rule behind ``metrics.json`` (:func:`nnid.evaluation.evaluate.
    score_split`: each experiment of the log judged alone too): None where it diverged (not
    finite, or :data:`~nnid.evaluation.evaluate.DIVERGENCE_FACTOR` measured ranges outside),
    never a number over its finite part."""
    from nnid.evaluation.evaluate import score_split

    mask = np.arange(len(log)) >= warmup
    _, rmse, _, _, _ = score_split(log, predicted, [column], mask, lambda run: [column])
    return rmse[column]


def ensemble_free_run(
    log: pd.DataFrame,
    members: list[pd.DataFrame],
    names: list[str],
    column: str,
    warmup: int,
) -> dict[str, Any]:
    """Scores of the pointwise mean and median of members' free runs of ``column`` on ``log``
    (:func:`nnid.models.ensemble.combine_members`, the ensemble model's rule), each by
    :func:`scored_free_run`, and the mean's mean error. ``wild``: the ``names`` of the members
    whose free run diverged or left the range of the others and the data
    (:func:`nnid.models.ensemble.wild_members`); where there is one, every score is None (an
    ensemble with a wild member has diverged: a mean averages it in, a median ranks it away
    unsaid)."""
    from nnid.models.ensemble import combine_members, wild_members

    mask = np.arange(len(log)) >= warmup
    preds = np.stack([m[[column]].to_numpy(np.float64) for m in members])
    wild = [names[k] for k in wild_members(preds, log, [column], mask)]
    out: dict[str, Any] = {"wild": wild}
    for how in ("mean", "median"):
        combined = pd.DataFrame(combine_members(preds, how), columns=[column], index=log.index)
        out[how] = None if wild else scored_free_run(log, combined, column, warmup)
        if how == "mean":
            err = combined[column].to_numpy()[mask] - log[column].to_numpy(np.float64)[mask]
            out["mean_error"] = None if out[how] is None else float(np.nanmean(err))
    return out
