"""Thread counts (torch, numba, BLAS) for work made of many small operations, each set for a
block and restored after it: the library never changes process-wide state.

Torch's and BLAS's counts are the process's, so those blocks are not thread-safe: two
threads running them at once restore each other's counts wrongly. Numba keeps its count per
calling thread, but its OpenMP layer resets torch's (:func:`numba_threads`), so its block is
not thread-safe either. Fits run in separate processes (:mod:`nnid.scale`), not threads."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch
from threadpoolctl import threadpool_limits


@contextmanager
def torch_threads(n: int = 1) -> Iterator[None]:
    """Run the block with ``n`` torch threads, then restore the previous count.

    Small tensors stepped through time (a free run, an RK4 rollout, element-wise physics on
    ~10⁴ rows) gain nothing from more threads and lose much on a loaded machine (6× per call
    measured on 2 busy cores)."""
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@contextmanager
def blas_threads(n: int = 1) -> Iterator[None]:
    """Run the block with at most ``n`` threads in each BLAS library loaded so far (NumPy's and
    SciPy's OpenBLAS, MKL), then restore each one's previous count.

    Small products (``dgemv`` on matrices of a few columns) gain nothing from a second thread,
    which spins waiting for work (``blas_thread_server``): the whole `nnid demo` took 12.7-42.7 s
    of user CPU in 3 runs with OpenBLAS's default 2 threads against 9.0-10.2 s in 4 with one
    (2 cores, load 2.9-3.5, 2026-11-30). Its findings were the same; its numbers repeat bit for
    bit at one thread count but moved by up to 1e-11 (relative) between the two. A library
    loaded inside the block keeps its own count."""
    with threadpool_limits(limits=n, user_api="blas"):
        yield


@contextmanager
def numba_threads(n: int = 1) -> Iterator[None]:
    """Run the block with at most ``n`` numba threads for parallel kernels, then restore the
    previous count (numba keeps the count per calling thread).

    With numba's OpenMP threading layer, ``numba.set_num_threads`` also resets the OpenMP
    thread count that torch reads (measured: torch's count went from 1 to 2), so torch's count
    is put back after each change. Numba's first call in a process starts that layer and
    resets the count too, so torch's is read before it: read after, a task's
    ``torch_threads(1)`` ran on every numba thread in a fresh process."""
    import numba

    torch_before = torch.get_num_threads()
    before = numba.get_num_threads()
    numba.set_num_threads(max(1, min(n, numba.config.NUMBA_NUM_THREADS)))
    torch.set_num_threads(torch_before)
    try:
        yield
    finally:
        numba.set_num_threads(before)
        torch.set_num_threads(torch_before)


@contextmanager
def torch_threads_kept() -> Iterator[None]:
    """Run a numba ``parallel=True`` kernel without changing torch's thread count.

    The first parallel launch in a process starts numba's OpenMP threading layer, which resets
    the OpenMP thread count that torch reads: a fault monitor's first fit moved a user's
    ``torch.set_num_threads(1)`` to 2. The library never changes process-wide state, so the
    count is put back after the kernel."""
    before = torch.get_num_threads()
    try:
        yield
    finally:
        if torch.get_num_threads() != before:
            torch.set_num_threads(before)
