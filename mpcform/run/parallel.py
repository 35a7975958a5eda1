"""Process pools for benchmarks and sweeps: spawned workers with single-threaded BLAS.

Workers are started with the ``spawn`` method (no fork of a process that may hold BLAS or
solver threads) and with ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS``
set to 1 unless the caller's environment already sets them: a spawned worker imports numpy
afresh, so this reaches the workers even though the parent's numpy is already loaded. The
parent's environment is restored when the pool is closed.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextmanager
def single_threaded_env() -> Iterator[None]:
    """Set the BLAS / OpenMP thread variables to 1 (where unset) for the duration of the block."""
    added = [name for name in THREAD_VARIABLES if name not in os.environ]
    for name in added:
        os.environ[name] = "1"
    try:
        yield
    finally:
        for name in added:
            os.environ.pop(name, None)


@contextmanager
def process_pool(max_workers: int, max_tasks_per_child: int | None = None) -> Iterator[ProcessPoolExecutor]:
    """A spawned :class:`ProcessPoolExecutor` whose workers run single-threaded BLAS.

    ``max_tasks_per_child=1`` gives every task a fresh process (clean peak-memory readings).
    """
    with single_threaded_env():
        pool = ProcessPoolExecutor(
            max_workers=max_workers,
            mp_context=multiprocessing.get_context("spawn"),
            max_tasks_per_child=max_tasks_per_child,
        )
        try:
            yield pool
        finally:
            pool.shutdown(wait=True, cancel_futures=True)


def blas_threads() -> str:
    """``OPENBLAS_NUM_THREADS`` as this process sees it (``unset`` if absent), for provenance."""
    return os.environ.get("OPENBLAS_NUM_THREADS", "unset")
