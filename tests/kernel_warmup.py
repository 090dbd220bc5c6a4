"""Compile nnid's numba kernels into their on-disk cache before pytest-xdist starts its workers.

A kernel (``@njit(cache=True)``) is compiled on its first call in any process whose cache
lacks it. On a fresh clone that was every process that got there first: both xdist workers,
and each subprocess a test starts (a CLI run, an ensemble's member processes, a process pool's
or Ray's workers), side by side, compiling the same kernels. The whole set takes about 80 s of
CPU to compile and 1 s to load (2026-11-29, on the loaded 2-core CI machine); the shipped-config
ensemble test took 129 s and 76 s on a cold cache, 68 s and 43 s on a warm one.

:func:`warm` compiles them once, in parallel processes that each own whole kernel modules
(a callee in another module, ``compiled._rhs`` under the fault kernels, may be
compiled by two of them: both write the same cache entry), before the workers start; every later
process loads them. Only the time changes: what a process loads is the machine code it would
have compiled. The signatures below are the argument types nnid's call sites pass (read from
a full run's cache index, 2026-11-29): a kernel compiles its callees (``_fly_batch`` its
``_fly`` and ``_integrate``) with the types it passes them. A signature no call site uses any
more costs its compilation and nothing else; a call site whose types changed compiles its
kernel where it runs, as before this warm-up.

Run as a script, it compiles the kernel modules named on its command line.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import time
from pathlib import Path

#: seconds each kernel module takes to compile in one process on the CI machine (measured
#: 2026-11-29 under load); they only balance the processes, their values matter little
COMPILE_SECONDS = {
    "nnid.fault.kernel": 31,
    "nnid.physics.compiled": 27,
    "nnid.models.hybrid_kernel": 17,
    "nnid.models.narx_kernel": 9,
    "nnid.trainers.recursive": 3,
}


def signatures() -> dict[str, list[tuple[str, tuple]]]:
    """Per kernel module, the (kernel, argument types) each of nnid's call sites compiles."""
    from numba import types as nt

    f, i, flag = nt.float64, nt.int64, nt.boolean

    def a(ndim: int, dtype=f, readonly: bool = False) -> nt.Array:
        return nt.Array(dtype, ndim, "C", readonly=readonly)

    f1, f2, f3, i1, i2 = a(1), a(2), a(3), a(1, i), a(2, i)
    # nnid.physics.compiled.form_args
    form_args = (f2, f2, f2, f2, f2, i2, f2, f1, f1, f, f)
    form = nt.Tuple(form_args)
    # the fault monitor's actuation (FaultMonitor.act_) and the hybrid's NetArrays
    act = nt.Tuple((i1, f2, f2, f2, i1, f1, f1, f2, f1, f1, f))
    net = nt.Tuple((f1, i1, f1, f1))
    window = (f2, f3, f, i, i, f, form, net, flag, f3)
    narx = (f3, f3, f3, f2, f1, f2, f2, i, i1, i1, *(f1,) * 5, i1, flag, f1, f1, flag, f1, f1)
    return {
        "nnid.fault.kernel": [
            ("update", (f, f1, f1, f1, f1, f1, form, f2, f1, act, f1, f2, f2, f1, f2, f2)),
            ("watch", (f, f1, f2, f1, f1, f2, f2, f1, f2)),
            # the times are a read-only slice of the log's column
            (
                "run_blocks",
                (i1, a(1, readonly=True), f2, f2, f1, form, f2, f1, act, f1, f2, f2, f2),
            ),
        ],
        "nnid.physics.compiled": [
            ("_fly_batch", (f2, f2, i1, f, i, f2, f, form, f3, f3)),
            ("_integrate", (f1, f2, f, i, *form_args, f2)),
            ("_integrate_serial", (f2, f3, f, i, *form_args, f3)),
            ("_integrate_batch", (f2, f3, f, i, *form_args, f3)),
            ("_rhs", (f1, f1, *form_args, f1, f2)),
        ],
        "nnid.models.hybrid_kernel": [("_serial", window), ("_parallel", window)],
        "nnid.models.narx_kernel": [("_runs", narx)],
        "nnid.trainers.recursive": [
            ("_rls", (f2, f1, i, f, f, f1, f2, f2)),
            ("_gradient", (f2, f1, i, f, f2, flag, f1, f2)),
        ],
    }


def compile_modules(modules: list[str]) -> None:
    """Compile (or load from the cache) every kernel of ``modules`` for its signatures."""
    table = signatures()
    for name in modules:
        module = importlib.import_module(name)
        for kernel, types in table[name]:
            getattr(module, kernel).compile(types)


def cached(name: str) -> bool:
    """Whether every kernel of module ``name`` loads from the cache for its signatures (False
    where numba's dispatcher has no cache to ask)."""
    module = importlib.import_module(name)
    for kernel, types in signatures()[name]:
        dispatcher = getattr(module, kernel)
        cache = getattr(dispatcher, "_cache", None)
        if cache is None or cache.load_overload(types, dispatcher.targetctx) is None:
            return False
    return True


def parts(modules: list[str], n: int) -> list[list[str]]:
    """``modules`` in at most ``n`` groups of about equal compile time, longest first (each
    module whole: its kernels compile their callees in that module)."""
    groups: list[list[str]] = [[] for _ in range(max(1, min(n, len(modules))))]
    load = [0.0] * len(groups)
    for name in sorted(modules, key=COMPILE_SECONDS.get, reverse=True):
        k = load.index(min(load))
        groups[k].append(name)
        load[k] += COMPILE_SECONDS[name]
    return groups


#: the warm-up's limit (s): a cold compile of every module takes ~50 s idle, ~110 s loaded
WARM_TIMEOUT_S = 600.0


def warm(n: int) -> tuple[float, list[str]]:
    """Compile the kernels the cache lacks in ``n`` processes side by side; the seconds it
    took and, for each process that failed, the end of what it said (a failure costs only
    time: the kernels it did not compile are compiled where they are first called)."""
    import nnid

    start = time.perf_counter()
    todo = [name for name in COMPILE_SECONDS if not cached(name)]
    root = str(Path(nnid.__file__).resolve().parents[1])  # the nnid the workers import
    # no empty entry: it would put the working directory on the path
    paths = [root, *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(paths))
    procs = [
        subprocess.Popen(
            [sys.executable, __file__, *group],
            env=env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for group in (parts(todo, n) if todo else [])
    ]
    failed = []
    for proc in procs:
        try:  # a hung compile must not hold the session before any worker starts
            _, err = proc.communicate(
                timeout=max(1.0, WARM_TIMEOUT_S - (time.perf_counter() - start))
            )
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            failed.append(f"{' '.join(proc.args[2:])}: stopped after {WARM_TIMEOUT_S:.0f} s")
            continue
        if proc.returncode != 0:
            said = (err.strip().splitlines() or ["no output"])[-1]
            failed.append(f"{' '.join(proc.args[2:])}: {said}")
    return time.perf_counter() - start, failed


if __name__ == "__main__":
    compile_modules(sys.argv[1:])
