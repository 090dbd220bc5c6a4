"""Report rendering: the CPU time of each report figure and of whole HTML report pages, from
fixed, seeded inputs (no model is fitted). Run by hand:

    python benchmarks/bench_reports.py [REV]

Each row is timed with ``time.process_time`` (CPU seconds of the process, so a busy machine
slows it less than the wall clock), the median of ``--repeats`` calls (5) after one untimed
call. The inputs have the shapes the report tests draw (tests/test_report_cells.py,
tests/test_compare.py, tests/test_loop.py):

- train (hybrid): a held-out log of 2,000 samples (velocities, inputs, attitude) and a learned
  force of six DOFs, drawn as four features a DOF (``_correction_figure``), the free runs of
  the hybrid and its physics (``_free_run_figure``), and ``train_html`` of constructed hybrid
  metrics with both figures;
- compare: four models (two damping syntheses, a SINDy, a NARX) on two held-out runs of 80 s:
  ``force_figure``, ``free_run_figures`` (one figure per run and DOF), ``complexity_figure``
  and ``html_page`` of a constructed comparison;
- loop: ``free_run_figure`` (six DOFs, 60 s), ``correlation_figure`` (six DOFs) and
  ``html_page`` of docs/loop_bluerov1/loop.json with its three figures drawn, as
  ``write_loop_report`` draws them (files not written).

``REV`` (a git revision): the same rows also timed with that revision's nnid (its package from
``git archive``, in a subprocess), and the ratio REV / this tree. A function whose signature
differs there is not called as this tree calls it: its cell is "–", with why.
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import inspect
import json
import statistics
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from types import SimpleNamespace

import matplotlib
import numpy as np
import pandas as pd
from common import at_revision, commit_of, machine

from nnid.datasets.log import TAU, VELOCITY
from nnid.physics.dofs import FORCES

REPO = Path(__file__).resolve().parents[1]
LOOP_JSON = REPO / "docs" / "loop_bluerov1" / "loop.json"

#: input sizes: ``full`` is the benchmark; ``tiny`` only checks that every row runs (a test)
SIZES = {
    "full": {"dofs": 6, "samples": 2000, "runs": 2, "run_s": 80.0, "models": 4, "lags": 5000},
    "tiny": {"dofs": 1, "samples": 200, "runs": 1, "run_s": 20.0, "models": 2, "lags": 500},
}

TRAIN, COMPARE, LOOP = (f"nnid.reports.{m}_report" for m in ("train", "compare", "loop"))

#: each row: its label, and the functions it calls as ``module:name`` (their signatures are
#: compared between revisions)
ROWS = {
    "train: hybrid correction figure": [f"{TRAIN}:_correction_figure"],
    "train: hybrid free-run figure": [f"{TRAIN}:_free_run_figure"],
    "compare: force figure": [f"{COMPARE}:force_figure"],
    "compare: free-run figures (a run and DOF each)": [f"{COMPARE}:free_run_figures"],
    "compare: complexity figure": [f"{COMPARE}:complexity_figure"],
    "loop: free-run figure": [f"{LOOP}:free_run_figure"],
    "loop: correlation figure": [f"{LOOP}:correlation_figure"],
    "train report page (hybrid)": [f"{TRAIN}:train_html"],
    "compare report page": [f"{COMPARE}:html_page"],
    "loop report page (three figures)": [
        f"{LOOP}:html_page",
        f"{LOOP}:free_run_figure",
        f"{LOOP}:correlation_figure",
    ],
}


def _function(path: str) -> Callable:
    module, name = path.split(":")
    return getattr(importlib.import_module(module), name)


def hybrid_case(size: dict) -> tuple[dict, dict]:
    """A hybrid's train metrics and figures (tests/test_report_cells.py's
    ``_hybrid_figure_data``: features of size 1, a learned force quadratic in a velocity)."""
    n, dofs = size["samples"], size["dofs"]
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.05
    log = pd.DataFrame({"t": t, "experiment": "run0"})
    for k, c in enumerate([*VELOCITY, *TAU, "phi", "theta", "psi"]):
        log[c] = np.sin(t / (3 + k)) + 0.1 * rng.standard_normal(n)
    force = pd.DataFrame(dict.fromkeys(FORCES, 0.0), index=log.index)
    for k, f in enumerate(FORCES[:dofs]):
        force[f] = log[VELOCITY[k]] ** 2 + 0.1 * rng.standard_normal(n)
    hybrid = 1.1 * log[list(VELOCITY)]
    hybrid[list(VELOCITY[dofs:])] = np.nan  # the DOFs a hybrid does not predict are not drawn
    figures = {"correction": (log, force), "free_run": hybrid,
               "baseline_free_run": 0.9 * log[list(VELOCITY)]}  # fmt: skip

    def scores(total: float) -> dict:
        one = {d: total * (1 + 0.1 * k) for k, d in enumerate(VELOCITY[:dofs])}
        return {"free_run_nrmse": {**one, "total": total}, "k_step_nrmse": {**one, "total": total},
                "one_step_nrmse": {**one, "total": total}, "diverged": {}}  # fmt: skip

    shares = {d: 0.3 for d in FORCES[:dofs]}
    metrics = {
        "model": "hybrid",
        "vehicle": "minirov",
        "trainer": "adam",
        "n_params": 2118,
        "seconds": 42.0,
        "validation_used_for": "early stopping",
        "train": scores(0.2),
        "validation": scores(0.25),
        "test": scores(0.3),
        "baseline": {"model": "fossen", "validation": scores(0.5), "test": scores(0.6)},
        "correction": {
            "share_of_damping_force": {
                p: {**shares, "max": 0.3} for p in ("train", "validation", "test")
            },
            "explanation": {
                "terms": [
                    {
                        "effect": "coupled_damping.X:u*abs(u)",
                        "kind": "coupled_damping",
                        "meaning": "quadratic damping",
                        "value": -12.5,
                        "share": 0.6,
                    },
                    {
                        "effect": "current.x",
                        "kind": "current",
                        "meaning": "a current",
                        "value": 0.05,
                        "share": 0.2,
                    },
                ],
                "explained": 0.8,
                "force_rms": shares,
                "samples": n,
                "candidates": 40,
                "notes": [],
            },
        },
        "params": {
            "X_udot": {"value": -5.1, "stderr": None, "vehicle_file": -5.0},
            "X:u*abs(u)": {"value": -30.2, "stderr": None, "vehicle_file": -31.0},
        },
        "warnings": [],
    }
    return metrics, figures


def compare_case(size: dict) -> SimpleNamespace:
    """A comparison's result (:class:`nnid.pipeline.CompareResult`'s fields that the page
    reads): held-out runs of 0.5-s samples and models scaled off the measured series, as
    tests/test_compare.py's force-figure tests."""
    dofs, names = list(VELOCITY[: size["dofs"]]), [f"m{k}" for k in range(size["models"])]
    kinds = ["synthesis", "sindy", "synthesis", "narx"]
    t = np.arange(0.0, size["run_s"], 0.5)
    runs = "ab"[: size["runs"]]
    held = pd.concat([pd.DataFrame({"t": t, "experiment": e}) for e in runs], ignore_index=True)
    for k, d in enumerate(VELOCITY):
        held[d] = 0.5 * np.sin(held["t"] / (4 + k))
    measured = pd.DataFrame({f: np.sin(held["t"]) for f in FORCES}, index=held.index)
    forces = {m: (1 + 0.1 * k) * measured for k, m in enumerate(names)}
    free_runs = {m: (1 + 0.1 * k) * held[dofs] for k, m in enumerate(names)}

    def row(k: int, m: str) -> dict:
        err = {d: 0.2 + 0.05 * k for d in dofs}
        part = {"columns": dofs, "diverged": {}, "J": 1.0 + k, "J_over_J0": 0.3 + 0.1 * k,
                "J0": 10.0, **{f"{mode}_nrmse": {**err, "total": 0.2 + 0.05 * k}
                               for mode in ("free_run", "k_step", "one_step")}}  # fmt: skip
        kind = kinds[k % len(kinds)]
        out = {"name": m, "kind": kind, "trainer": "least squares", "n_params": 6 + 4 * k,
               "seconds": 0.5, "train": part, "validation": part,
               "ranked_nrmse": {mode: 0.2 + 0.05 * k for mode in ("free_run", "k_step",
                                                                   "one_step")},
               "coefficients": {f"X:u*abs(u) {j}": {"value": -10.0 * j, "stderr": 0.1}
                                for j in range(6)}}  # fmt: skip
        if kind == "sindy":
            out["sindy_path"] = [{"n_terms": j, "validation_J": 1.0 / j} for j in range(1, 9)]
        return out

    comparison = {
        "vehicle": "vt690",
        "summary": f"Use {names[0]}.",
        "models": [row(k, m) for k, m in enumerate(names)],
        "ranking": names,
        "held_out": "validation",
        "ranked_on": dofs,
        "k_step_s": 0.2,
        "train": ["c", "d"],
        "validation": list(runs),
        "warmup_s": 1.0,
        "warnings": [],
    }
    return SimpleNamespace(comparison=comparison, held_out=held, free_runs=free_runs,
                           forces=forces, measured_force=measured)  # fmt: skip


def loop_case(size: dict) -> tuple[dict, tuple, dict]:
    """A residual loop's saved result (docs/loop_bluerov1/loop.json), its held-out free runs
    (tests/test_loop.py's: 60 s at 10 Hz, 3e-4 m/s) and its correlation analyses (a residual
    that follows an input three samples late)."""
    from nnid.loop.residuals import correlation_analysis

    dofs = list(VELOCITY[: size["dofs"]])
    t = np.arange(600) * 0.1
    measured = pd.DataFrame({d: 3e-4 * np.sin(t / 7) for d in dofs})
    rng = np.random.default_rng(12345)
    e, u = rng.normal(size=(2, size["lags"]))
    c = correlation_analysis(e + 0.5 * np.roll(u, 3), {"tau_Z": u, "tau_N": -u})
    result = json.loads(LOOP_JSON.read_text())
    return result, (t, measured, 1.1 * measured, 0.9 * measured, dofs), dict.fromkeys(dofs, c)


def cases(size: dict) -> dict[str, Callable[..., object]]:
    """Each row of :data:`ROWS` as a call of its functions (in the row's order) on its inputs,
    built here, outside the timer."""
    metrics, figures = hybrid_case(size)
    result = compare_case(size)
    loop, runs, analysis = loop_case(size)
    held, dofs = result.held_out, list(VELOCITY[: size["dofs"]])

    def loop_page(page, free_run, correlation) -> str:  # as write_loop_report draws it
        pictures = {
            "Held-out free run": free_run(*runs),
            "Residual analysis before": correlation(analysis, "baseline"),
            "Residual analysis after": correlation(analysis, "augmented"),
        }
        return page(loop, pictures)

    calls = [
        lambda fig: fig(*figures["correction"]),
        lambda fig: fig(figures),
        lambda fig: fig(result.measured_force, result.forces, held),
        lambda fig: fig(held, result.free_runs, dofs),
        lambda fig: fig(result.comparison),
        lambda fig: fig(*runs),
        lambda fig: fig(analysis, "baseline"),
        lambda page: page(metrics, figures),
        lambda page: page(result),
        loop_page,
    ]
    return dict(zip(ROWS, calls, strict=True))


def cpu_ms(fn: Callable[[], object], repeats: int, warm: bool) -> float:
    """Median CPU milliseconds of ``repeats`` calls of ``fn`` (after an untimed one if
    ``warm``: the first figure of a process also loads fonts)."""
    if warm:
        fn()
    times = []
    for _ in range(repeats):
        t0 = time.process_time()
        fn()
        times.append(time.process_time() - t0)
    return 1e3 * statistics.median(times)


def signatures() -> dict[str, str]:
    """Every function of :data:`ROWS` with its signature, or why there is none."""
    out = {}
    for path in {p for paths in ROWS.values() for p in paths}:
        try:
            out[path] = str(inspect.signature(_function(path)))
        except (ImportError, AttributeError) as exc:
            out[path] = f"missing ({exc})"
    return out


def measure(tiny: bool, repeats: int, other: bool = False) -> dict:
    """Each row's CPU milliseconds, the signatures of its functions, and where nnid was
    imported from. ``other``: the nnid is another revision's, where a row that fails (a
    function it lacks, another signature) is said in its cell; this tree's failure raises."""
    import nnid

    rows = {}
    for label, call in cases(SIZES["tiny" if tiny else "full"]).items():
        try:
            fns = [_function(p) for p in ROWS[label]]
            rows[label] = {"ms": cpu_ms(partial(call, *fns), repeats, warm=not tiny)}
        except Exception as exc:
            if not other:
                raise
            rows[label] = {"why": f"{type(exc).__name__}: {exc}"[:160]}
    return {"rows": rows, "signatures": signatures(), "nnid": nnid.__file__}


def _cell(row: dict) -> str:
    return f"{row['ms']:.1f}" if "ms" in row else f"– ({row['why']})"


def table(now: dict, rev: str | None = None, before: dict | None = None) -> list[str]:
    """The Markdown table: figure, ms now and, with a revision, ms at it and the ratio. A
    revision's cell is "–" where a function's signature differs there or its call failed."""
    head = "| figure | ms now |" + (f" ms at {rev} | {rev} / now |" if before else "")
    lines = [head, "|---|---|" + ("---|---|" if before else "")]
    for label, paths in ROWS.items():
        mine = now["rows"][label]
        line = f"| {label} | {_cell(mine)} |"
        if before:
            theirs = before["rows"][label]
            for path in paths:
                then, here = before["signatures"].get(path), now["signatures"].get(path)
                if then != here:  # called as this tree calls it, it would not be the same call
                    name = path.split(":")[1]
                    theirs = {"why": f"{name}{then} at {rev}, {name}{here} now"}
                    break
            ratio = (f"{theirs['ms'] / mine['ms']:.2f}" if "ms" in theirs and "ms" in mine
                     else "–")  # fmt: skip
            line += f" {_cell(theirs)} | {ratio} |"
        lines.append(line)
    return lines


def parser() -> argparse.ArgumentParser:
    """The command line: an optional revision to compare with, the repeats, tiny inputs."""
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument("rev", nargs="?", help="a git revision whose nnid is timed too")
    ap.add_argument("--repeats", type=int, default=5, help="timed calls a row (default: 5)")
    ap.add_argument("--tiny", action="store_true",
                    help="one DOF, one run, short series: checks every row runs, times "
                         "nothing worth reporting")  # fmt: skip
    # the subprocess on another revision's nnid prints its numbers as JSON: not for a person
    ap.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    return ap


def main(argv: list[str] | None = None) -> None:
    ap = parser()
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f"--repeats {args.repeats}: at least one timed call is needed")
    if args.json:
        print(json.dumps(measure(args.tiny, args.repeats, other=True)))
        return
    commit = None
    if args.rev:
        try:
            commit = commit_of(args.rev, REPO)
        except ValueError as exc:
            ap.error(str(exc))
    now = measure(args.tiny, args.repeats)
    before = None
    if args.rev:
        flags = ["--json", "--repeats", str(args.repeats), *(["--tiny"] if args.tiny else [])]
        before = at_revision(args.rev, Path(__file__), *flags)
    print(f"machine: {machine(matplotlib=matplotlib.__version__)}; date {datetime.date.today()}")
    print(f"CPU ms (time.process_time), median of {args.repeats}"
          + (f"; {args.rev} is {commit[:10]}" if commit else "")
          + ("; tiny inputs" if args.tiny else ""))  # fmt: skip
    print("\n".join(table(now, args.rev, before)))


if __name__ == "__main__":
    main(sys.argv[1:])
