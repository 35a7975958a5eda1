"""QP backends behind one interface: set up once, update the data that changes, solve.

Problem form (OSQP's): ``min 0.5 z^T P z + q^T z  s.t.  l <= A z <= u`` with ``P`` upper
triangular CSC and +-inf for absent bounds. A backend never raises inside the planning loop:
failures come back as a :class:`QPSolution` with ``success = False`` and the solver's status.

Solver names (``--solver``, scenario key ``controller.solver``, ``mpcform solvers``):

- ``osqp``, ``piqp``: persistent solver objects (set up once per sparsity pattern, then updated);
- ``qpsolvers:<name>``: any solver installed for qpsolvers, called afresh each step (warm-started
  through ``initvals`` where the wrapper uses it); a solver that needs a positive-definite P
  (quadprog) cannot take this QP, whose P is singular in the position variables;
- ``casadi:<plugin>``: casadi's conic interface with the plugins in :data:`CASADI_CONIC_PLUGINS`
  (casadi sets the solver up again on every call; never ``highs``, which segfaulted here);
- ``casadi:ipopt``: not a QP solver: ipopt on the exact non-convex separation problem that the
  QP linearises (a quality reference), which needs the problem's meaning (:class:`QPContext`).

The backends of the optional packages live in :mod:`mpcform.solvers.families` and are imported only
when one of them is asked for.
"""

from __future__ import annotations

import difflib
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from importlib.util import find_spec
from typing import Any

import numpy as np
import scipy.sparse as sp

from mpcform._validate import Array
from mpcform.errors import SolverError


@dataclass(frozen=True)
class QPSolution:
    """Primal ``x`` and dual ``y`` (None unless ``success``; ``y`` also None when the backend
    gives no duals), status text, iterations (0 when not reported) and wall time [s]."""

    x: Array | None
    y: Array | None
    success: bool
    status: str
    iterations: int
    solve_time_s: float


def failed(status: str, elapsed_s: float = 0.0, iterations: int = 0) -> QPSolution:
    """A failed solve with its reason."""
    return QPSolution(None, None, False, status, iterations, elapsed_s)


@dataclass(frozen=True)
class SolverOptions:
    """Tolerances and limits passed to the solver; ``None`` keeps the solver's own default.

    ``eps_abs`` / ``eps_rel``: absolute / relative tolerance on residuals (mapped to each
    solver's own parameters); ``max_iter``: iteration limit; ``time_limit_s``: per-solve time
    limit [s] for solvers that take one (0: none).
    """

    eps_abs: float | None = 1e-5
    eps_rel: float | None = 1e-5
    max_iter: int | None = 4000
    time_limit_s: float = 0.0


@dataclass(frozen=True)
class QPContext:
    """What the planner's QP means, for backends that need more than its matrices.

    Variables (see :mod:`mpcform.mpc.qp`): ``z = [u_0 .. u_{H-1} | x_1 .. x_H | s_1 .. s_H]``,
    inputs and positions relative to the start (``x_j = p_j - p0``), each block (H, n, d) stacked
    step-major, then one slack per step and drone (H, n). Rows ``separation_rows`` (start, stop)
    are the linearised separation rows. The exact (non-convex) separation they stand for, at every
    position step e = 1..H::

        ||W (p0_i + x_{e,i} - p0_k - x_{e,k})|| + s_{e,i} + s_{e,k} >= pair_distance_m
        ||p0_i + x_{e,i} - c_o|| + s_{e,i} >= obstacle_distance_m[o]

    for the ``pairs`` (i, k) within reach and the (``obstacle_drones[o]``, obstacle o) items,
    with ``W = diag(metric)`` (downwash scaling).
    """

    n: int
    dim: int
    horizon: int
    separation_rows: tuple[int, int]
    start_m: Array  # (n, d) p0
    pairs: Array  # (P, 2) int
    pair_distance_m: float
    metric: Array  # (d,)
    obstacle_drones: Array  # (O,) int
    obstacle_centers_m: Array  # (O, d)
    obstacle_distance_m: Array  # (O,)

    @property
    def nud(self) -> int:
        """Number of input (and of position) variables, H n d."""
        return self.horizon * self.n * self.dim

    @property
    def n_var(self) -> int:
        return 2 * self.nud + self.horizon * self.n


class QPBackend(ABC):
    """One QP family, solved repeatedly. ``setup`` whenever the sparsity pattern changes.

    Class attributes say what a caller may rely on: ``warm_starts`` (``solve`` uses ``x0``),
    ``persistent`` (``update`` is cheaper than ``setup``), ``needs_context`` (call
    :meth:`set_context` before each solve).
    """

    name: str
    warm_starts: bool = False
    """Whether :meth:`solve` uses ``x0`` (callers skip building it otherwise)."""
    persistent: bool = False
    needs_context: bool = False

    def __init__(self, options: SolverOptions) -> None:
        self.options = options

    @abstractmethod
    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        """Take a new problem (copies what it keeps)."""

    @abstractmethod
    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        """New cost vector, bounds and values of A (same pattern as at setup)."""

    @abstractmethod
    def solve(self, x0: Array | None = None) -> QPSolution:
        """Solve, warm-started from ``x0`` where the backend supports it."""

    def set_context(self, context: QPContext) -> None:  # noqa: B027 - optional hook
        """The meaning of the current problem (used only by backends with ``needs_context``)."""


def _given(**values: Any) -> dict[str, Any]:
    """The keyword arguments whose value is not None."""
    return {k: v for k, v in values.items() if v is not None}


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

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        o = self.options
        extra = _given(eps_abs=o.eps_abs, eps_rel=o.eps_rel, max_iter=o.max_iter,
                       time_limit=o.time_limit_s if o.time_limit_s > 0 else None)  # fmt: skip
        solver = self._osqp.OSQP()
        solver.setup(P.copy(), q, A.copy(), lo, hi, verbose=False, polishing=True, warm_starting=True,
                     adaptive_rho=True, **extra)  # fmt: skip
        self._solver, self._nnz_a = solver, A.nnz

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
            res.x.copy() if ok else None, res.y.copy() if ok else None, ok, str(info.status),
            int(info.iter), elapsed,
        )  # fmt: skip


class PIQPBackend(QPBackend):
    """Persistent ``piqp.SparseSolver`` (proximal interior point); rows with ``l == u`` at setup
    become its equality block, the others its two-sided inequality block."""

    name = "piqp"
    persistent = True

    def __init__(self, options: SolverOptions) -> None:
        super().__init__(options)
        import piqp

        self._piqp = piqp
        self._solver: Any = None

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        self._eq = eq = lo == hi
        ids = A.copy()
        ids.data = np.arange(A.nnz, dtype=float)
        a_eq, g = ids[eq].tocsc(), ids[~eq].tocsc()
        self._eq_ids, self._g_ids = a_eq.data.astype(np.intp), g.data.astype(np.intp)
        self._a_eq, self._g = a_eq, g
        a_eq.data, g.data = A.data[self._eq_ids], A.data[self._g_ids]
        solver = self._piqp.SparseSolver()
        st, o = solver.settings, self.options
        st.verbose = False
        for key, value in _given(eps_abs=o.eps_abs, eps_rel=o.eps_rel, max_iter=o.max_iter).items():
            setattr(st, key, value)
        solver.setup(P.copy(), q, a_eq.copy(), lo[eq], g.copy(), lo[~eq], hi[~eq])
        self._solver, self._nnz_a = solver, A.nnz

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        if A_data.shape[0] != self._nnz_a:
            raise SolverError(self.name, f"A has {A_data.shape[0]} values, the pattern has {self._nnz_a}")
        self._a_eq.data, self._g.data = A_data[self._eq_ids], A_data[self._g_ids]
        eq = self._eq
        self._solver.update(c=q, A=self._a_eq, b=lo[eq], G=self._g, h_l=lo[~eq], h_u=hi[~eq])

    def solve(self, x0: Array | None = None) -> QPSolution:
        solver = self._solver
        if solver is None:
            raise SolverError(self.name, "solve() before setup()")
        start = time.perf_counter()
        status = solver.solve()
        elapsed = time.perf_counter() - start
        res = solver.result
        ok = status == self._piqp.PIQP_SOLVED and bool(np.all(np.isfinite(res.x)))
        y = np.zeros(self._eq.shape[0])
        if ok:
            y[self._eq] = res.y
            y[~self._eq] = res.z_u - res.z_l
        return QPSolution(
            np.array(res.x) if ok else None, y if ok else None, ok,
            str(status).split(".")[-1].lower(), int(res.info.iter), elapsed,
        )  # fmt: skip


# ---- registry -------------------------------------------------------------------------------
BACKENDS: dict[str, type[QPBackend]] = {"osqp": OSQPBackend, "piqp": PIQPBackend}
"""The persistent backends, by name (the other families are built by :func:`make_backend`)."""
DEFAULT_SOLVER = "piqp"
"""Chosen on measurements (see README, "Solvers", and ``mpcform bench solvers``): the separation
rows make the QP degenerate for ADMM (OSQP needs hundreds of iterations on swaps and stops at a
loose objective), an interior point needs about 14 and is the fastest solver that succeeds on
every recorded problem at every accuracy."""

CASADI_CONIC_PLUGINS = ("osqp", "qpoases", "proxqp", "daqp", "piqp", "ipqp", "hpipm")
"""casadi conic plugins offered as ``casadi:<plugin>`` (``highs`` segfaulted: never offered)."""
QPSOLVERS_KNOWN = (
    "clarabel", "copt", "cvxopt", "daqp", "ecos", "gurobi", "highs", "hpipm", "jaxopt_osqp",
    "kvxopt", "mosek", "nppro", "osqp", "pdhcg", "piqp", "proxqp", "pyqpmad", "qpalm", "qpax",
    "qpoases", "qpswift", "qtqp", "quadprog", "scs", "sip",
)  # fmt: skip
"""Solvers qpsolvers (4.13) can call, installed or not."""
QPSOLVERS_LISTED = ("clarabel", "daqp", "highs", "osqp", "piqp", "proxqp", "quadprog", "scs")
"""qpsolvers solvers always listed by ``mpcform solvers`` (those of the ``solvers`` extra)."""
QPSOLVERS_WARM = frozenset(
    {"cvxopt", "daqp", "hpipm", "kvxopt", "nppro", "osqp", "pdhcg", "proxqp", "pyqpmad", "qpalm", "scs"}
)
"""qpsolvers wrappers that pass ``initvals`` to the solver (the others ignore it, with a warning)."""
NEEDS_POSITIVE_DEFINITE = {
    "qpsolvers:quadprog": "needs a positive-definite P; this QP's P is singular in the position variables",
}
"""Backends that cannot take this problem class, with the reason."""
CASADI_WARM = frozenset({"osqp", "proxqp"})
CASADI_NOTES = {
    "hpipm": "; the QP passed in stage order (not with an acceleration limit)",
    "daqp": "; proximal regularisation (P is singular)",
    "ipqp": "; QR factorisation (P is singular)",
    "qpoases": "; sparse mode",
}


@dataclass(frozen=True)
class SolverInfo:
    """One backend as ``mpcform solvers`` lists it.

    ``usable``: installed and able to take this problem class; ``note``: the install hint when
    missing, the reason when unsupported, otherwise what the backend is.
    """

    name: str
    installed: bool
    usable: bool
    warm_start: bool
    persistent: bool
    note: str


def _installed(module: str) -> bool:
    return find_spec(module) is not None


def _qpsolvers_available() -> list[str]:
    if not _installed("qpsolvers"):
        return []
    import qpsolvers

    return list(qpsolvers.available_solvers)


def _casadi_has(kind: str, plugin: str) -> bool:
    if not _installed("casadi"):
        return False
    import casadi

    try:
        return bool(casadi.has_conic(plugin) if kind == "conic" else casadi.has_nlpsol(plugin))
    except RuntimeError:
        return False


def solver_names() -> list[str]:
    """Every name :func:`solver_infos` lists, in its order."""
    qps = sorted(set(QPSOLVERS_LISTED) | set(_qpsolvers_available()))
    return [*BACKENDS, *(f"qpsolvers:{s}" for s in qps), *(f"casadi:{p}" for p in CASADI_CONIC_PLUGINS),
            "casadi:ipopt"]  # fmt: skip


def check_solver_name(name: str) -> str:
    """Return ``name`` if it names a backend (installed or not), else raise :class:`SolverError`
    listing the accepted forms, with a did-you-mean hint."""
    family, sep, rest = name.partition(":")
    qps = set(QPSOLVERS_KNOWN) | set(_qpsolvers_available())
    if (
        name in BACKENDS
        or (family == "qpsolvers" and rest in qps)
        or (family == "casadi" and rest in (*CASADI_CONIC_PLUGINS, "ipopt"))
    ):
        return name
    close = difflib.get_close_matches(name, solver_names() + [f"qpsolvers:{s}" for s in qps], n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    why = "casadi's highs plugin segfaulted on this QP class; " if name == "casadi:highs" else ""
    raise SolverError(
        name,
        f"unknown solver; {why}expected osqp, piqp, qpsolvers:<name> (one of {', '.join(sorted(qps))}), "
        f"casadi:<plugin> ({', '.join(CASADI_CONIC_PLUGINS)}) or casadi:ipopt{hint}",
    )


def solver_info(name: str) -> SolverInfo:
    """Whether ``name`` is installed and usable here (raises :class:`SolverError` if unknown)."""
    check_solver_name(name)
    family, _, rest = name.partition(":")
    if name in BACKENDS:
        installed = _installed(name)
        what = "persistent ADMM object (update + warm start)" if name == "osqp" else (
            "persistent proximal interior point (update)")  # fmt: skip
        return SolverInfo(name, installed, installed, BACKENDS[name].warm_starts, True,
                          what if installed else f"not installed: pip install {name}")  # fmt: skip
    if family == "qpsolvers":
        installed = _installed("qpsolvers") and rest in _qpsolvers_available()
        warm = rest in QPSOLVERS_WARM
        if not installed:
            note = f'not installed: pip install "qpsolvers[{rest}]" (or "mpcform[solvers]")'
        elif name in NEEDS_POSITIVE_DEFINITE:
            note = f"unsupported: {NEEDS_POSITIVE_DEFINITE[name]}"
        else:
            note = f"qpsolvers, set up every call{', warm start via initvals' if warm else ', cold'}"
        usable = installed and name not in NEEDS_POSITIVE_DEFINITE
        return SolverInfo(name, installed, usable, warm, False, note)
    kind = "nlpsol" if rest == "ipopt" else "conic"
    installed = _casadi_has(kind, rest)
    if not installed:
        note = "not installed: pip install casadi (the PyPI wheels include this plugin)"
    elif rest == "ipopt":
        note = "exact non-convex separation problem (NLP), a quality reference; slow"
    else:
        note = f"casadi conic interface, set up every call{CASADI_NOTES.get(rest, '')}"
    warm = rest in CASADI_WARM or rest == "ipopt"
    return SolverInfo(name, installed, installed, warm, False, note)


def solver_infos() -> list[SolverInfo]:
    """Every backend this package knows: installed or not, usable or not (``mpcform solvers``)."""
    return [solver_info(name) for name in solver_names()]


def make_backend(name: str, options: SolverOptions) -> QPBackend:
    """The backend called ``name`` (see ``mpcform solvers``).

    Raises :class:`SolverError` for an unknown name, a solver that is not installed (with the
    install hint) or one that cannot take this problem class.
    """
    info = solver_info(name)
    if not info.installed:
        raise SolverError(name, info.note)
    if not info.usable:
        raise SolverError(name, info.note)
    if name in BACKENDS:
        return BACKENDS[name](options)
    from mpcform.solvers.families import CasadiConicBackend, CasadiIpoptBackend, QPSolversBackend

    family, _, rest = name.partition(":")
    if family == "qpsolvers":
        return QPSolversBackend(rest, options)
    if rest == "ipopt":
        return CasadiIpoptBackend(options)
    return CasadiConicBackend(rest, options)
