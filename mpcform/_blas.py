"""scipy's bundled OpenBLAS held to one thread for a call (:func:`one_thread`).

OpenBLAS runs even a small LAPACK call (``solve_triangular`` of a 30 x 30 matrix) on its thread
pool, whose threads then spin, waiting for more work, for about 0.1 s: a planner built just before
its first step paid that CPU time (and a slower main thread beside it on a shared core) in its
first steps. One thread gives the same results bit for bit (OpenBLAS splits the right-hand sides'
columns between its threads). Without scipy's OpenBLAS (another BLAS, another platform) it does
nothing.
"""

from __future__ import annotations

import ctypes
import glob
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import cache


@cache
def _set_local_threads() -> Callable[[int], int] | None:
    """OpenBLAS's ``openblas_set_num_threads_local`` (it returns the previous count) of the library
    scipy ships, or None."""
    import scipy

    pattern = os.path.join(os.path.dirname(scipy.__file__), os.pardir, "scipy.libs", "libscipy_openblas*")
    for path in sorted(glob.glob(pattern)):
        try:
            setter = ctypes.CDLL(path).openblas_set_num_threads_local
        except (OSError, AttributeError):
            continue
        setter.restype, setter.argtypes = ctypes.c_int, [ctypes.c_int]
        return setter
    return None


@contextmanager
def one_thread() -> Iterator[None]:
    """Within it, scipy's OpenBLAS calls from this thread run on one thread (then the count before)."""
    setter = _set_local_threads()
    if setter is None:
        yield
        return
    previous = setter(1)
    try:
        yield
    finally:
        setter(previous)
