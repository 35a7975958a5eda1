"""Persistent solver objects: set up once per sparsity pattern, then updated in place.

``osqp`` (ADMM, warm-started) and ``piqp`` (proximal interior point). The packages are imported
when a backend is built, not with this module.

``piqp`` keeps one solver object per pattern (the recent ones, up to :data:`PATTERN_CACHE_NNZ`):
a ``setup`` with a pattern it has seen becomes an ``update`` of that object. An update solves like a
fresh setup (PIQP scales the data again and starts every solve from its own initial point; measured
on the recorded swaps: the same solution to 1e-10). ``osqp`` is set up afresh on every ``setup``:
an updated OSQP object keeps its scaling, step size and last iterate, so it would solve differently.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError
from mpcform.solvers.base import QPBackend, QPSolution, SolverOptions, given

PATTERN_CACHE_NNZ = 250_000
"""Nonzeros (of ``P`` and ``A``) of the patterns whose solver objects ``piqp`` keeps besides the
current one, the least recently used dropped first: about 75 MB at the 300 bytes per nonzero of
:mod:`mpcform.scenario.size` (a very large QP's object is not kept once its pattern changes)."""


class OSQPBackend(QPBackend):
    """Persistent ``osqp.OSQP`` object: set up once per pattern, then ``update`` + warm start."""

    name = "osqp"
    warm_starts = True
    persistent = True

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        import osqp

        self._osqp = osqp
        self._solver: Any = None
        self._nnz_a = 0
        self._own_max_iter = 0  # the setup's iteration limit, restored after a cap

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        o = self.options
        extra = given(
            eps_abs=o.eps_abs,
            eps_rel=o.eps_rel,
            max_iter=o.max_iter,
            time_limit=o.time_limit_s if o.time_limit_s > 0 else None,
        )
        solver = self._osqp.OSQP()
        solver.setup(
            P.copy(),
            q,
            A.copy(),
            lo,
            hi,
            verbose=False,
            polishing=True,
            warm_starting=True,
            adaptive_rho=True,
            **extra,
        )
        self._solver, self._nnz_a, self._own_max_iter = solver, A.nnz, int(solver.settings.max_iter)

    def limit_iterations(self, max_iter: int | None) -> None:
        if self._solver is not None:
            self._solver.update_settings(max_iter=max_iter or self._own_max_iter)

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        if A_data.shape[0] != self._nnz_a:  # OSQP would only print an error and keep the old A
            raise SolverError(self.name, f"A has {A_data.shape[0]} values, the pattern has {self._nnz_a}")
        self._solver.update(q=q, l=lo, u=hi, Ax=A_data)

    def solve(self, x0: Array | None = None) -> QPSolution:
        solver = self._solver
        if solver is None:
            raise SolverError(self.name, "solve() before setup()")
        if x0 is not None:
            solver.warm_start(x=x0)
        start = time.perf_counter()
        res = solver.solve(raise_error=False)
        elapsed = time.perf_counter() - start
        info = res.info
        ok = info.status_val in (1, 2) and res.x is not None and bool(np.all(np.isfinite(res.x)))
        return QPSolution(
            res.x.copy() if ok else None,
            res.y.copy() if ok else None,
            ok,
            str(info.status),
            int(info.iter),
            elapsed,
            float(info.obj_val) if ok else None,
            {"prim_res": float(info.prim_res), "dual_res": float(info.dual_res)},
        )


class PIQPBackend(QPBackend):
    """Persistent ``piqp.SparseSolver`` (proximal interior point); rows with ``l == u`` at setup
    become its equality block, the others its two-sided inequality block. One solver object per
    pattern (``P``, ``A`` and the equality rows), reused when the pattern comes back."""

    name = "piqp"
    persistent = True

    def __init__(self, options: SolverOptions, keep_nnz: int = PATTERN_CACHE_NNZ) -> None:
        super().__init__(options)
        import piqp

        self._piqp = piqp
        self._obj: _PIQPObject | None = None  # the current pattern's solver object
        self._objects: OrderedDict[bytes, _PIQPObject] = OrderedDict()  # least recently used first
        self.keep_nnz = keep_nnz  # nonzeros of the patterns kept besides the current one
        self._cap: int | None = None  # the iteration cap of the next solves (None: the setup's)
        self.reused = 0  # setups served by a kept solver object

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        eq = lo == hi
        key = pattern_key(P, A, eq)
        found = self._objects.pop(key, None)
        obj = self._new_object(P, q, A, lo, hi, eq) if found is None else found
        self._objects[key] = obj
        others = sum(o.nnz for o in self._objects.values()) - obj.nnz
        while others > self.keep_nnz:  # the least recently used first (never the current one)
            others -= self._objects.popitem(last=False)[1].nnz
        self._obj = obj
        if found is not None:  # set up before: an update with this data
            self.reused += 1
            if not np.array_equal(obj.p_data, P.data):
                obj.p_data = P.data.copy()
                obj.solver.update(P=P)
            self.update(q, lo, hi, A.data)

    def _new_object(
        self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array, eq: Array
    ) -> _PIQPObject:
        (a_eq, eq_ids), (g, g_ids) = row_split(A, eq), row_split(A, ~eq)
        solver = self._piqp.SparseSolver()
        st, o = solver.settings, self.options
        st.verbose = False
        for key, value in given(eps_abs=o.eps_abs, eps_rel=o.eps_rel, max_iter=o.max_iter).items():
            setattr(st, key, value)
        solver.setup(P.copy(), q, a_eq.copy(), lo[eq], g.copy(), lo[~eq], hi[~eq])
        return _PIQPObject(solver, eq, a_eq, eq_ids, g, g_ids, P.data.copy(), int(st.max_iter))

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        obj = self._current()
        nnz_a = obj.eq_ids.shape[0] + obj.g_ids.shape[0]
        if A_data.shape[0] != nnz_a:
            raise SolverError(self.name, f"A has {A_data.shape[0]} values, the pattern has {nnz_a}")
        obj.a_eq.data, obj.g.data = A_data[obj.eq_ids], A_data[obj.g_ids]
        eq = obj.eq
        obj.solver.update(c=q, A=obj.a_eq, b=lo[eq], G=obj.g, h_l=lo[~eq], h_u=hi[~eq])

    def _current(self) -> _PIQPObject:
        if self._obj is None:
            raise SolverError(self.name, "update() or solve() before setup()")
        return self._obj

    def limit_iterations(self, max_iter: int | None) -> None:
        self._cap = max_iter

    def solve(self, x0: Array | None = None) -> QPSolution:
        obj = self._current()
        solver = obj.solver
        solver.settings.max_iter = self._cap or obj.max_iter
        start = time.perf_counter()
        status = solver.solve()
        elapsed = time.perf_counter() - start
        res = solver.result
        ok = status == self._piqp.PIQP_SOLVED and bool(np.all(np.isfinite(res.x)))
        eq = obj.eq
        y = np.zeros(eq.shape[0])
        if ok:
            y[eq] = res.y
            y[~eq] = res.z_u - res.z_l
        info = res.info
        return QPSolution(
            np.array(res.x) if ok else None,
            y if ok else None,
            ok,
            str(status).split(".")[-1].lower(),
            int(info.iter),
            elapsed,
            float(info.primal_obj) if ok else None,
            {
                "primal_res": float(info.primal_res),
                "dual_res": float(info.dual_res),
                "duality_gap": float(info.duality_gap),
            },
        )


@dataclass(eq=False)
class _PIQPObject:
    """A ``piqp.SparseSolver`` set up for one pattern: its equality rows ``eq``, the equality and
    inequality blocks (``a_eq``, ``g``) and which entries of ``A``'s data fill them, ``P``'s values
    and its iteration limit."""

    solver: Any
    eq: Array
    a_eq: sp.csc_matrix
    eq_ids: Array
    g: sp.csc_matrix
    g_ids: Array
    p_data: Array
    max_iter: int  # its settings' iteration limit

    @property
    def nnz(self) -> int:
        """Nonzeros of its pattern (``P`` and ``A``)."""
        return int(self.p_data.shape[0] + self.eq_ids.shape[0] + self.g_ids.shape[0])


def pattern_key(P: sp.csc_matrix, A: sp.csc_matrix, eq: Array) -> bytes:
    """The sparsity patterns of ``P`` and ``A`` and the equality rows ``eq``, as one key."""
    parts = (np.array(P.shape + A.shape, dtype=np.int64), P.indptr, P.indices, A.indptr, A.indices)
    return b"|".join(np.ascontiguousarray(x).tobytes() for x in parts) + b"|" + np.packbits(eq).tobytes()


def row_split(A: sp.csc_matrix, rows: Array) -> tuple[sp.csc_matrix, Array]:
    """The rows ``rows`` (mask) of ``A`` as a CSC matrix with sorted indices, and the positions of
    its entries in ``A.data`` (its data is ``A.data[ids]``; explicit zeros stay entries)."""
    ids = sp.csc_matrix((np.arange(A.nnz, dtype=float), A.indices, A.indptr), shape=A.shape)
    sub = ids[rows].tocsc()
    sub.sort_indices()
    pos = sub.data.astype(np.intp)
    sub.data = A.data[pos]
    return sub, pos
