"""What the backends that set the solver up on every call share (qpsolvers, casadi).

They keep the current problem (:class:`StoredQP`), hand the solver the full symmetric ``P``
(:func:`full_symmetric`), and run C libraries that print regardless of their settings with the
process's stdout and stderr sent to ``/dev/null`` (:func:`quiet_fds`): a backend prints nothing.
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import QPBackend, QPContext, SolverOptions


def full_symmetric(P_upper: sp.spmatrix) -> sp.csc_matrix:
    """The symmetric matrix whose upper triangle is ``P_upper``."""
    upper = sp.triu(P_upper, format="csc")
    return (upper + sp.triu(upper, 1).T).tocsc()


@contextmanager
def quiet_fds() -> Iterator[None]:
    """Send the process's file descriptors 1 and 2 to ``/dev/null`` (C libraries print there),
    flushing C and Python buffers on both sides so nothing leaks out later."""
    libc = ctypes.CDLL(None)
    sys.stdout.flush()
    sys.stderr.flush()
    libc.fflush(None)
    saved = os.dup(1), os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        yield
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        libc.fflush(None)
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, devnull):
            os.close(fd)


class StoredQP(QPBackend):
    """Keeps the current problem's data; subclasses solve it from scratch each time."""

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        self._P: sp.csc_matrix | None = None
        self._context: QPContext | None = None

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        self._P, self._A = full_symmetric(P), A.copy()
        self._q, self._lo, self._hi = q.copy(), lo.copy(), hi.copy()
        self._changed_pattern()

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        if self._P is None:
            raise SolverError(self.name, "update() before setup()")
        if A_data.shape[0] != self._A.nnz:
            raise SolverError(self.name, f"A has {A_data.shape[0]} values, the pattern has {self._A.nnz}")
        self._A.data = A_data.copy()
        self._q, self._lo, self._hi = q.copy(), lo.copy(), hi.copy()

    def objective(self, x: Array) -> float:
        """``0.5 x^T P x + q^T x`` of the problem set up (for solvers that do not report it)."""
        if self._P is None:
            raise SolverError(self.name, "objective() before setup()")
        return float(0.5 * x @ (self._P @ x) + self._q @ x)

    def set_context(self, context: QPContext) -> None:
        self._context = context

    def _changed_pattern(self) -> None:
        """Hook: the sparsity pattern changed (drop what depends on it)."""
