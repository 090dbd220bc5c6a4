"""Where tasks run: in this process, on local worker processes, or on a Ray cluster.

Every engine has ``slots`` (how many tasks run at once) and ``run(tasks, out_root)``, which
yields each task's row as it finishes (:func:`nnid.scale.task.run_task`). Fan-out is the job
of ``concurrent.futures`` and Ray; nothing here schedules by itself.

- :class:`SerialEngine`: one task after another in this process (debugging): its threads are
  pinned at run time, so its numbers may differ from the workers' in the last bit.
- :class:`LocalEngine`: ``ProcessPoolExecutor`` with the *spawn* context (no fork of a process
  that holds torch or numba threads), each worker started with one thread for OpenMP,
  OpenBLAS, MKL, numba and torch (:data:`ONE_THREAD`); ``LocalEngine(1)`` is "one process".
  A worker that dies (killed, out of memory, a segfault) breaks the whole pool in
  ``concurrent.futures``;
  the tasks it was running are found by their start markers, each is re-run alone in a fresh
  one-worker pool, and the one that kills that worker too becomes a ``failed`` row. The
  tasks that were only waiting run on in a new pool.
- :class:`RayEngine`: ``ray.remote`` tasks of one CPU each, their workers started with the
  same one-thread environment (a Ray ``runtime_env``), no retries (a task that kills its
  worker is reported, not re-run behind the user's back), results gathered with ``ray.wait``
  as they finish. Tasks carry paths, so each worker reads its log itself: the logs and the
  output folder must be on storage every node sees (one machine, NFS, a shared volume).
"""

from __future__ import annotations

import faulthandler
import os
import shutil
import signal
import threading
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from nnid.scale.manifest import Task

#: folder (inside the output folder) of the markers of tasks running on local workers
RUNNING = ".running"
#: the error of a task whose worker process died under it
DIED = "its worker process died while running it (killed, out of memory or crashed)"


def failed_row(task: Task, error: str) -> dict[str, Any]:
    """The row of a task that ended without returning one (its worker died)."""
    return {"id": task.id, **task.inputs(), "status": "failed", "error": error,
            "seconds": None, "worker": None}  # fmt: skip


class SerialEngine:
    """Every task in this process, one after another."""

    name = "serial"
    slots = 1

    def run(self, tasks: list[Task], out_root: str | Path) -> Iterator[dict[str, Any]]:
        from nnid.scale.task import run_task

        for task in tasks:
            yield run_task(task, out_root)


#: the environment every worker process starts with: one thread for OpenMP, OpenBLAS, MKL and
#: numba, read by those libraries when they load. Pinning them later, at run time, leaves
#: results that differ in the last bit from process to process (measured on loop tasks), so
#: the workers are *started* with it
ONE_THREAD = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


@contextmanager
def kept_environ(*names: str) -> Iterator[None]:
    """The variables ``names`` of ``os.environ`` as they were before the block, after it
    (whatever the block set, changed or removed)."""
    before = {k: os.environ.get(k) for k in names}
    try:
        yield
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextmanager
def environment(values: dict[str, str]) -> Iterator[None]:
    """``values`` in ``os.environ`` for the block (worker processes started in it inherit
    them), then the previous values back."""
    with kept_environ(*values):
        os.environ.update(values)
        yield


def _pin_worker() -> None:
    """Initializer of a local worker process: torch's own thread count (the worker's own
    process, so process-wide settings are its to make)."""
    import torch

    torch.set_num_threads(1)


def _marked_run(task: Task, out_root: str) -> dict[str, Any]:
    """:func:`run_task` with a start marker that outlives a worker killed mid-task."""
    from nnid.scale.task import run_task

    marker = Path(out_root) / RUNNING / task.id
    marker.parent.mkdir(parents=True, exist_ok=True)
    marker.write_text(str(os.getpid()))
    try:
        return run_task(task, out_root)
    finally:
        marker.unlink(missing_ok=True)


def _end_workers(pool: ProcessPoolExecutor) -> None:
    """Cancel a pool's queued tasks and end its worker processes now."""
    terminate = getattr(pool, "terminate_workers", None)  # Python 3.14
    if terminate is not None:
        terminate()
        return
    # before 3.14 the pool names its processes only in a private attribute, which its
    # shutdown clears: taken first
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()


class LocalEngine:
    """Local worker processes (``concurrent.futures``, spawn context); ``workers`` defaults
    to the number of cores."""

    name = "local"

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers

    @property
    def slots(self) -> int:
        return self.workers or os.cpu_count() or 1

    def _pool(
        self, tasks: list[Task], out_root: str, workers: int
    ) -> Iterator[dict[str, Any] | list[Task]]:
        """Rows as tasks finish; if the pool breaks, a last item: the unfinished tasks."""
        ctx = get_context("spawn")
        pool = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_pin_worker)
        interrupted = False
        try:
            # the pool starts its processes as tasks are submitted: all of them here
            with environment(ONE_THREAD):
                futures = {pool.submit(_marked_run, t, out_root): t for t in tasks}
            while futures:
                done, _ = wait(futures, return_when=FIRST_COMPLETED)
                broken = []
                for future in done:
                    task = futures.pop(future)
                    error = future.exception()
                    if isinstance(error, BrokenProcessPool):
                        broken.append(task)
                    elif error is not None:  # run_task catches its own: a pickling failure
                        yield failed_row(task, f"{type(error).__name__}: {error}")
                    else:
                        yield future.result()
                if broken:
                    yield broken + list(futures.values())
                    return
        except BaseException:
            # interrupted (Ctrl-C, the CLI's SIGTERM, a caller that stops reading the rows):
            # a plain shutdown would wait for every queued task to run
            _end_workers(pool)
            interrupted = True
            raise
        finally:
            # an interrupted pool's ended workers are waited for; once every task has its row
            # the idle workers exit in the background: a worker's interpreter takes seconds to
            # tear down torch and numba, and the caller has nothing left to wait for
            pool.shutdown(wait=interrupted)

    def run(self, tasks: list[Task], out_root: str | Path) -> Iterator[dict[str, Any]]:
        out_root = str(out_root)
        marks = Path(out_root) / RUNNING
        shutil.rmtree(marks, ignore_errors=True)
        pending = list(tasks)
        while pending:
            unfinished: list[Task] = []
            for item in self._pool(pending, out_root, min(self.slots, len(pending))):
                if isinstance(item, list):
                    unfinished = item
                else:
                    yield item
            if not unfinished:
                break
            running = {p.name for p in marks.iterdir()} if marks.is_dir() else set()
            suspects = [t for t in unfinished if t.id in running] or unfinished
            pending = [t for t in unfinished if t not in suspects]
            shutil.rmtree(marks, ignore_errors=True)
            for task in suspects:  # alone, so a second death names its task
                for item in self._pool([task], out_root, 1):
                    yield failed_row(task, DIED) if isinstance(item, list) else item
                shutil.rmtree(marks, ignore_errors=True)
        shutil.rmtree(marks, ignore_errors=True)


class RayEngine:
    """Ray tasks of one CPU each on the cluster at ``address`` (``"auto"``, ``"ray://..."``
    or ``"host:port"``); ``None`` or ``"local"`` starts a local Ray (``num_cpus`` CPUs). A
    Ray already initialised in this process is used as it is and left running."""

    name = "ray"

    def __init__(self, address: str | None = "auto", num_cpus: int | None = None) -> None:
        self.address = address
        self.num_cpus = num_cpus
        self._cpus: int | None = None  # the cluster's CPUs, read when a run starts

    @property
    def slots(self) -> int:
        if self._cpus is not None:
            return self._cpus
        import ray

        return int(ray.cluster_resources().get("CPU", 1)) if ray.is_initialized() else 1

    def run(self, tasks: list[Task], out_root: str | Path) -> Iterator[dict[str, Any]]:
        if not tasks:  # every task finished earlier: no cluster to reach
            return
        # the workers' own working folder is not this one (another node, Ray's session folder)
        out_root = Path(out_root).absolute()
        ray = _import_ray()
        with ray_session(ray, self.address, self.num_cpus):
            self._cpus = int(ray.cluster_resources().get("CPU", 1))
            try:
                remote = ray.remote(
                    num_cpus=1, max_retries=0, runtime_env={"env_vars": ONE_THREAD}
                )(_ray_task)
                refs = {remote.remote(t, str(out_root)): t for t in tasks}
                while refs:
                    done, _ = ray.wait(list(refs), num_returns=1)
                    for ref in done:
                        task = refs.pop(ref)
                        try:
                            yield ray.get(ref)
                        except ray.exceptions.RayError as exc:
                            yield failed_row(task, _ray_error(exc))
            finally:
                shutil.rmtree(Path(out_root) / RUNNING, ignore_errors=True)


def _ray_task(task: Task, out_root: str) -> dict[str, Any]:
    """A task on a Ray worker; the row names the node it ran on."""
    import ray

    row = _marked_run(task, out_root)
    row["node"] = ray.get_runtime_context().get_node_id()[:12]
    return row


def _ray_error(exc: Exception) -> str:
    """One line for a Ray failure: a dead worker said as such."""
    import ray

    if isinstance(exc, ray.exceptions.WorkerCrashedError | ray.exceptions.NodeDiedError):
        return DIED
    first = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {first[0] if first else ''}"


def _import_ray(tune: bool = False):
    """The ``ray`` module (with Ray Tune where ``tune``: a sweep), or one error saying how to
    install it."""
    from nnid.errors import NnidInputError

    def missing(what: str) -> NnidInputError:
        return NnidInputError(
            f"{what} is not installed: pip install 'nnid[ray]' (or leave out --address to run "
            "on local processes)",
            field="--address",
        )

    try:
        import ray
    except ImportError:
        raise missing("Ray") from None
    if tune:
        try:  # ``pip install ray`` without [tune] lacks Tune's dependencies
            import ray.tune
        except ImportError as exc:
            raise missing(f"Ray Tune ({exc})") from None
    return ray


#: the ``--address`` that starts a new Ray on this machine (the only one whose CPUs we set)
LOCAL_RAY = "local"


def ray_init(ray, address: str | None, num_cpus: int | None = None, **kwargs: Any) -> None:
    """``ray.init`` at ``address`` (``num_cpus`` only where it starts a new Ray), quiet; an
    address where no Ray answers (``auto`` with no cluster, a mistyped ``host:port``) is one
    error naming ``--address``, not Ray's traceback."""
    from nnid.errors import NnidInputError

    try:
        ray.init(
            address=address,
            num_cpus=num_cpus if address in (None, LOCAL_RAY) else None,
            include_dashboard=False,
            log_to_driver=False,
            configure_logging=False,
            **kwargs,
        )
    # Ray says no cluster at the address with ConnectionError, one that does not answer in
    # time with RuntimeError, a malformed address (a port out of range) with ValueError
    except (ConnectionError, RuntimeError, ValueError) as exc:
        first = str(exc).strip().splitlines()
        raise NnidInputError(
            f"Ray could not start or connect at "
            f"{'a new local Ray' if address in (None, LOCAL_RAY) else repr(address)} "
            f"({first[0] if first else type(exc).__name__}): start a cluster (ray start "
            "--head) and give its address, 'local' for a new one here, or leave out --address "
            "to run on local processes",
            field="--address",
        ) from None


@contextmanager
def ray_session(
    ray, address: str | None, num_cpus: int | None = None, **kwargs: Any
) -> Iterator[None]:
    """Ray for the block. A Ray already initialised in this process is used as it is and left
    running; else :func:`ray_init` starts or reaches one (``kwargs``: its job's settings),
    shut down after the block, and what ``ray.init`` changed for the whole process is put
    back, which ``ray.shutdown`` does not: its SIGTERM handler (``sys.exit(15)``, which
    replaced a user's handler and the CLI's exit 143 for good), ``PYTHONBREAKPOINT`` (a
    later ``breakpoint()`` went to Ray's debugger) and the faulthandler it enables; the
    handler only where the block ends on the main thread, the only one that may set it."""
    if ray.is_initialized():
        yield
        return
    # signal handlers are set only from the main thread (Ray sets its own only there too)
    main = threading.current_thread() is threading.main_thread()
    sigterm = signal.getsignal(signal.SIGTERM) if main else None
    faults = faulthandler.is_enabled()
    try:
        with kept_environ("PYTHONBREAKPOINT"):
            ray_init(ray, address, num_cpus, **kwargs)  # Ray's handler is set before it connects
            try:
                yield
            finally:
                ray.shutdown()
    finally:
        # None: a handler set outside Python, which cannot be set back. A generator holding
        # the block may be finalised on another thread (the cyclic collector runs on any),
        # where signal.signal raises and left the faulthandler on: Ray's handler stays then
        on_main = threading.current_thread() is threading.main_thread()
        if sigterm is not None and on_main:
            signal.signal(signal.SIGTERM, sigterm)
        if not faults:
            faulthandler.disable()


def engine_for(address: str | None, workers: int | None = None, tune: bool = False):
    """The engine a command line asks for: local processes without ``address``, else Ray at
    ``address`` (``auto``, ``local`` or a Ray address; ``tune``: Ray Tune too). ``workers``
    sets the CPUs of a new local Ray; a cluster's CPUs are its own, so there it is refused."""
    from nnid.errors import NnidInputError

    if address is None:
        return LocalEngine(workers)
    if workers is not None and address != LOCAL_RAY:
        raise NnidInputError(
            f"--workers sets the CPUs of local processes or of a new local Ray (--address "
            f"{LOCAL_RAY}); a Ray cluster at --address {address} uses its own CPUs: leave out "
            "one of the two",
            field="--workers",
        )
    _import_ray(tune)
    return RayEngine(address, num_cpus=workers)
