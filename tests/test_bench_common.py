"""The benchmarks' shared helpers (``benchmarks/common.py``): ``at_revision`` runs a script on a
git revision's nnid, here on a throwaway repository whose nnid is one line, so no benchmark
and no real package is imported."""

from __future__ import annotations

import subprocess
from pathlib import Path

from conftest import load_script

COMMON = Path(__file__).resolve().parents[1] / "benchmarks" / "common.py"


def _git(repo: Path, *args: str) -> None:
    subprocess.run(["git", "-C", str(repo), *args], check=True, capture_output=True)


def test_at_revision_runs_on_the_revisions_nnid_from_the_repository(tmp_path, monkeypatch):
    """Run from the repository (as ``python benchmarks/bench_x.py REV`` is), the import check
    (``python -c``, which puts the working directory first on the path) found the working
    tree's nnid, not the revision's archive, and refused every revision. The script sees the
    committed nnid, not the working tree's edit."""
    repo = tmp_path / "repo"
    (repo / "nnid").mkdir(parents=True)
    (repo / "benchmarks").mkdir()
    (repo / "nnid" / "__init__.py").write_text('REVISION = "committed"\n')
    script = repo / "benchmarks" / "probe.py"
    script.write_text("import json\nimport nnid\n\nprint(json.dumps(nnid.REVISION))\n")
    _git(repo, "init", "-q")
    _git(repo, "add", ".")
    _git(repo, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-q", "-m", "one")
    (repo / "nnid" / "__init__.py").write_text('REVISION = "working tree"\n')
    monkeypatch.syspath_prepend(str(COMMON.parent))
    common = load_script(COMMON, monkeypatch)
    monkeypatch.chdir(repo)
    assert common.at_revision("HEAD", script) == "committed"


def _scores(monkeypatch):
    monkeypatch.syspath_prepend(str(COMMON.parent))
    return load_script(COMMON, monkeypatch)


def test_ensemble_free_run_names_a_wild_member_and_scores_no_ensemble(monkeypatch):
    """The benchmarks' ensembles are scored through one helper on the library's rules: a
    member whose free run is NaN or leaves the range is named and the ensemble has no score
    (not a silent NaN, nor a mean that averages it in); a sane ensemble's score is the RMSE of
    the members' mean after the warm-up."""
    import numpy as np
    import pandas as pd

    common = _scores(monkeypatch)
    t = np.arange(200.0)
    log = pd.DataFrame({"t": t, "y": np.sin(t / 10)})
    rng = np.random.default_rng(0)
    members = [pd.DataFrame({"y": log["y"] + 0.05 * rng.standard_normal(200)}) for _ in range(3)]
    names = ["a", "b", "c"]
    sane = common.ensemble_free_run(log, members, names, "y", 20)
    mean = np.mean([m["y"] for m in members], axis=0)
    want = np.sqrt(np.mean((mean[20:] - log["y"].to_numpy()[20:]) ** 2))
    assert sane["wild"] == [] and abs(sane["mean"] - want) < 1e-12
    assert abs(sane["mean_error"] - np.mean(mean[20:] - log["y"].to_numpy()[20:])) < 1e-12
    for bad in (np.nan, 50.0):  # not finite; 25 ranges above the data
        wild = [m.copy() for m in members]
        wild[1].loc[150, "y"] = bad
        got = common.ensemble_free_run(log, wild, names, "y", 20)
        assert got["wild"] == ["b"] and got["mean"] is None and got["median"] is None
        assert common.scored_free_run(log, wild[1], "y", 20) is None
    # a NaN inside the warm-up is not scored: the member is sane
    early = [m.copy() for m in members]
    early[0].loc[5, "y"] = np.nan
    assert common.ensemble_free_run(log, early, names, "y", 20)["wild"] == []


def test_holdout_head_fold_scores_no_fitted_sample(monkeypatch):
    """``bench_nlbench.py --holdout``: the scored samples of either fold (after its warm-up)
    are never samples its fit saw; the head fold once scored 50 fitted ones."""
    import pandas as pd

    monkeypatch.syspath_prepend(str(COMMON.parent))
    nl = load_script(COMMON.parent / "bench_nlbench.py", monkeypatch)
    train = pd.DataFrame({"t": range(1024), "k": range(1024)})
    for fold in ("tail", "head"):
        fit, held = nl.holdout_parts(train, 768, 50, fold)
        assert len(fit) == 768
        assert not set(held["k"][50:]) & set(fit["k"]), fold
    assert list(nl.holdout_parts(train, 768, 50, "head")[1]["k"]) == list(range(256))
