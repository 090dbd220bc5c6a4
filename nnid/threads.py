"""Torch's intra-op thread count for work made of many small element-wise operations."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


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
def numba_threads(n: int = 1) -> Iterator[None]:
    """Run the block with at most ``n`` numba threads for parallel kernels, then restore the
    previous count (numba keeps the count per calling thread).

    With numba's OpenMP threading layer, ``numba.set_num_threads`` also resets the OpenMP
    thread count that torch reads (measured: torch's count went from 1 to 2), so torch's count
    is put back after each change."""
    import numba

    before = numba.get_num_threads()
    torch_before = torch.get_num_threads()
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
