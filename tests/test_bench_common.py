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
