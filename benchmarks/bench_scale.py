"""Fan-out of the residual loop (nnid.scale): 16 loop tasks on 16 simulated 10-minute logs,
one process (one worker, one task after another) against local worker processes and a local
Ray instance, in one run; every task's loop.json compared across the engines (all fields but
the wall time).

    python benchmarks/bench_scale.py [--tasks 16] [--minutes 10] [--workers 2] [--no-ray]

Prints a JSON record: wall times and ratios, per-task seconds, the driver's overhead (wall
time less the tasks' own seconds spread over the slots), and whether the results agree.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

from common import machine

from nnid.loop.scenarios import effect_log
from nnid.scale.batch import run_tasks
from nnid.scale.engines import LocalEngine, RayEngine
from nnid.scale.manifest import expand
from nnid.vehicle import load_vehicle

MINIROV = Path(__file__).resolve().parents[1] / "nnid" / "demo_data" / "minirov.toml"


def make_fleet(root: Path, tasks: int, minutes: float) -> Path:
    """``tasks`` dives of the minirov, each with its own upward heave efficiency."""
    vehicle = load_vehicle(MINIROV)
    for i in range(tasks):
        eta = 0.5 + 0.4 * i / max(tasks - 1, 1)
        log = effect_log(vehicle, [("thruster_installation.w.neg", eta)], duration=60 * minutes,
                         n_experiments=6, speed=(0.15, 0.4), seed=100 + i)  # fmt: skip
        log.to_parquet(root / f"dive{i:02d}.parquet", index=False)
    (root / "minirov.toml").write_text(MINIROV.read_text())
    manifest = root / "manifest.toml"
    manifest.write_text('command = "loop"\nvehicle = "minirov.toml"\ndata = ["dive*.parquet"]\n')
    return manifest


def results(out: Path, rows: list[dict]) -> dict[str, dict]:
    found = {}
    for row in rows:
        data = json.loads((out / row["id"] / "loop.json").read_text())
        data.pop("seconds")
        found[row["id"]] = data
    return found


def _differ(a, b, path: str = "") -> list[str]:
    """The paths at which two JSON values differ."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [p for k in sorted(set(a) | set(b), key=str)
                for p in _differ(a.get(k), b.get(k), f"{path}/{k}")]  # fmt: skip
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [p for i, (x, y) in enumerate(zip(a, b, strict=True))
                for p in _differ(x, y, f"{path}[{i}]")]  # fmt: skip
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def _relative(a, b) -> float:
    """The largest relative difference between the numbers of two JSON values (inf where
    anything else differs)."""
    if isinstance(a, dict) and isinstance(b, dict):
        if set(a) != set(b):
            return float("inf")
        return max((_relative(a[k], b[k]) for k in a), default=0.0)
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return float("inf")
        return max((_relative(x, y) for x, y in zip(a, b, strict=True)), default=0.0)
    if isinstance(a, float) and isinstance(b, float):
        return abs(a - b) / max(abs(a), abs(b)) if a != b else 0.0
    return 0.0 if a == b else float("inf")


def measure(name: str, engine, tasks, out: Path) -> dict:
    start = time.perf_counter()
    result = run_tasks(tasks, out, engine, resume=False)
    wall = time.perf_counter() - start
    own = [r["seconds"] for r in result.rows]
    return {
        "engine": name,
        "wall_s": wall,
        "slots": result.slots,
        "ok": sum(r["status"] == "ok" for r in result.rows),
        "task_s_median": statistics.median(own),
        "task_s_sum": sum(own),
        "overhead_s": wall - sum(own) / result.slots,
        "_rows": result.rows,
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tasks", type=int, default=16)
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-ray", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        manifest = make_fleet(root, args.tasks, args.minutes)
        tasks = expand(manifest)
        runs = [measure("one process", LocalEngine(1), tasks, root / "serial")]
        runs.append(measure("local", LocalEngine(args.workers), tasks, root / "local"))
        if not args.no_ray:
            import ray

            start = time.perf_counter()
            ray.init(num_cpus=args.workers, include_dashboard=False, log_to_driver=False,
                     configure_logging=False)  # fmt: skip
            init_s = time.perf_counter() - start
            try:
                runs.append(measure("ray", RayEngine(), tasks, root / "ray"))
                runs[-1]["ray_init_s"] = init_s
            finally:
                ray.shutdown()
        reference = results(root / "serial", runs[0]["_rows"])
        base = runs[0]["wall_s"]
        local = runs[1]["wall_s"]
        for run, folder in zip(runs, ("serial", "local", "ray"), strict=False):
            run["speedup_vs_serial"] = base / run["wall_s"]
            run["wall_vs_local"] = run["wall_s"] / local
            found = results(root / folder, run.pop("_rows"))
            run["identical_loop_json"] = found == reference
            run["max_relative_difference"] = max(
                (_relative(found[i], reference[i]) for i in reference), default=0.0
            )
            run["differences"] = [
                f"{i}: {p}" for i in reference for p in _differ(found[i], reference[i])
            ][:10]
        import nnid

        print(
            json.dumps(
                {
                    "machine": machine(nnid=nnid.__version__),
                    "date": time.strftime("%Y-%m-%d"),
                    "tasks": args.tasks,
                    "minutes_per_log": args.minutes,
                    "runs": runs,
                },
                indent=2,
            )
        )


if __name__ == "__main__":
    main()
