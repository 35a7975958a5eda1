"""The sparse solver: set up on a new pattern, updated otherwise; warm start, context and active rows."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import bounds_of, crowd_and_swap

from mpcform.mpc.constraints.candidates import Candidates
from mpcform.mpc.constraints.limits import limit_rows
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.problem import StepQP
from mpcform.mpc.solve.sparse import SparseSolver
from mpcform.mpc.strategy import SparseSolve
from mpcform.solvers.base import QPBackend, QPContext, QPSolution, SolverOptions
from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle

DT = 0.1
LIMITS = bounds_of(v_max_mps=1.0, d_min_m=0.5)
OBSTACLE = SphereObstacle(np.array([0.0, 3.0]), 0.5, clearance_m=0.25)  # d_min / 2


class Recording(QPBackend):
    """Records the calls; every solve returns zeros with one multiplier above the activity tolerance."""

    name = "recording"
    needs_context = True
    warm_starts = True

    def __init__(self) -> None:
        super().__init__(SolverOptions())
        self.calls: list[str] = []
        self.x0: Any = None
        self.context: QPContext | None = None

    def setup(self, P: Any, q: Any, A: Any, lo: Any, hi: Any) -> None:
        self.calls.append("setup")
        self.n_var, self.n_rows = P.shape[0], A.shape[0]

    def update(self, q: Any, lo: Any, hi: Any, A_data: Any) -> None:
        self.calls.append("update")

    def set_context(self, context: QPContext) -> None:
        self.context = context

    def solve(self, x0: Any = None) -> QPSolution:
        self.x0 = x0
        y = np.zeros(self.n_rows)
        y[-1] = 1.0  # the last slack row
        return QPSolution(np.zeros(self.n_var), y, True, "ok", 1, 0.0)


def step_qp(
    p0: np.ndarray, sep: Separation, drones: np.ndarray, rebuilt: bool = False, warm: bool = True
) -> StepQP:
    """The QP over ``drones`` with every pair and obstacle item within reach, the guess holding."""
    n, h = p0.shape[0], sep.ends.max()
    pairs = np.array([[i, k] for i in range(n) for k in range(i + 1, n)]).reshape(-1, 2)
    obstacles = np.array([[i, 0] for i in range(n)])
    cand = Candidates(pairs, np.ones(len(pairs), bool), obstacles, np.ones(n, bool), rebuilt)
    rows: SeparationRows = sep.rows(p0, np.broadcast_to(p0, (h + 1,) + p0.shape), cand)
    sub = rows.subset(drones, n, on_only=True)
    m = drones.shape[0]
    w = np.zeros((2, h, m, 2)) if warm else None
    return StepQP(n, drones, p0[drones], np.zeros((h, m, 2)), np.zeros((m, 2)), sub, rebuilt, w)


def solver(coupling: str = "joint") -> tuple[SparseSolver, Recording, Separation]:
    st = MPCSettings(horizon=3, coupling=coupling, solve=SparseSolve())
    sep = Separation(2, LIMITS, st, (OBSTACLE,))
    backend = Recording()
    return SparseSolver(backend, 2, DT, LIMITS, st, limit_rows(2, DT, LIMITS, st), sep), backend, sep


def test_setup_once_per_pattern_then_update() -> None:
    sparse, backend, sep = solver()
    assert sparse.name == "recording" and sparse.warm_starts
    p0 = np.array([[0.0, 0.0], [0.6, 0.0], [5.0, 0.0]])
    everyone, two = np.arange(3), np.array([0, 1])
    for drones, rebuilt in ((everyone, False), (everyone, False), (two, False), (two, True), (two, False)):
        sparse.solve(step_qp(p0, sep, drones, rebuilt))
    assert backend.calls == ["setup", "update", "setup", "setup", "update"]
    sparse.reset()
    sparse.solve(step_qp(p0, sep, two))
    assert backend.calls[-1] == "setup"


def test_warm_start_and_active_rows() -> None:
    sparse, backend, sep = solver()
    p0 = np.array([[0.0, 0.0], [0.6, 0.0]])
    sol, active = sparse.solve(step_qp(p0, sep, np.arange(2)))
    assert sol.success and active == 1
    assert backend.x0 is not None and backend.x0.shape == (backend.n_var,)
    sparse.solve(step_qp(p0, sep, np.arange(2), warm=False))
    assert backend.x0 is None


def test_context_numbers_the_drones_locally() -> None:
    """Drones 1 and 2 of 3, decoupled: the pair (1, 2) becomes (0, 1); obstacle items keep their drone."""
    sparse, backend, sep = solver("decoupled")
    p0 = np.array([[9.0, 9.0], [0.0, 0.0], [0.6, 0.0]])
    sparse.solve(step_qp(p0, sep, np.array([1, 2])))
    ctx = backend.context
    assert ctx is not None and ctx.n == 2 and ctx.horizon == 3
    np.testing.assert_array_equal(ctx.pairs, [[0, 1]])
    np.testing.assert_array_equal(ctx.start_m, p0[1:])
    np.testing.assert_array_equal(ctx.obstacle_drones, [0, 1])
    np.testing.assert_allclose(ctx.obstacle_centers_m, [OBSTACLE.center_m] * 2)
    np.testing.assert_allclose(ctx.obstacle_distance_m, 0.5 + 0.25 + 2e-3)
    assert ctx.pair_distance_m == 0.5 + 2e-3


class Clocked(QPBackend):
    """PIQP, with the time spent in its setup and update calls (timed around them) and its solves
    (the time they report) summed."""

    name = "piqp+clock"

    def __init__(self) -> None:
        from mpcform.solvers.registry import make_backend

        super().__init__(SolverOptions())
        self.inner = make_backend("piqp", SolverOptions())
        self.spent_s, self.calls = 0.0, []  # type: float, list[str]
        self.warm_starts = self.inner.warm_starts

    def setup(self, P: Any, q: Any, A: Any, lo: Any, hi: Any) -> None:
        start = time.perf_counter()
        self.inner.setup(P, q, A, lo, hi)
        self.spent_s += time.perf_counter() - start
        self.calls.append("setup")

    def update(self, q: Any, lo: Any, hi: Any, A_data: Any) -> None:
        start = time.perf_counter()
        self.inner.update(q, lo, hi, A_data)
        self.spent_s += time.perf_counter() - start
        self.calls.append("update")

    def solve(self, x0: Any = None) -> QPSolution:
        sol = self.inner.solve(x0)
        self.spent_s += sol.solve_time_s
        self.calls.append("solve")
        return sol


def test_solve_time_covers_every_backend_call_of_the_step() -> None:
    """The solution's ``solve_time_s`` (the step record's) is the setup or update and the solve,
    each timed around the backend's call: at least what the backend measured inside them."""
    st = MPCSettings(horizon=3, coupling="joint", solve=SparseSolve())
    sep = Separation(2, LIMITS, st, (OBSTACLE,))
    backend = Clocked()
    sparse = SparseSolver(backend, 2, DT, LIMITS, st, limit_rows(2, DT, LIMITS, st), sep)
    p0 = np.array([[0.0, 0.0], [0.6, 0.0]])
    for expected in (["setup", "solve"], ["update", "solve"]):
        backend.spent_s, backend.calls = 0.0, []
        sol, _ = sparse.solve(step_qp(p0, sep, np.arange(2)))
        assert sol.success and backend.calls == expected
        assert backend.spent_s <= sol.solve_time_s < np.inf


class HardCheck(QPBackend):
    """PIQP, and at each step's first solve, whether the same QP without slack is feasible (Clarabel)."""

    name = "piqp+hard-check"

    def __init__(self, dim: int, weight: float) -> None:
        from mpcform.solvers.registry import make_backend

        super().__init__(SolverOptions())
        self.inner = make_backend("piqp", SolverOptions(eps_abs=1e-7, eps_rel=1e-7))
        self.dim, self.weight, self.feasible = dim, weight, []  # type: list[bool]
        self.warm_starts = self.inner.warm_starts

    def setup(self, P: Any, q: Any, A: Any, lo: Any, hi: Any) -> None:
        self.P, self.q, self.A, self.lo, self.hi = P, q, A.copy(), lo, hi
        self.inner.setup(P, q, A, lo, hi)

    def update(self, q: Any, lo: Any, hi: Any, A_data: Any) -> None:
        self.q, self.lo, self.hi = q, lo, hi
        self.A.data = np.asarray(A_data, dtype=float).copy()
        self.inner.update(q, lo, hi, A_data)

    def solve(self, x0: Any = None) -> QPSolution:
        n_var = self.P.shape[0]
        n_slack = n_var // (2 * self.dim + 1)
        if np.all(self.q[n_var - n_slack :] == self.weight):  # the step's first solve
            self.feasible.append(self.hard_feasible(n_var - n_slack, n_slack))
        return self.inner.solve(x0)

    def hard_feasible(self, keep: int, n_slack: int) -> bool:
        from qpsolvers import Problem, solve_problem

        A = self.A[:-n_slack, :keep].tocsc()  # the slack >= 0 rows dropped, slack fixed at zero
        lo, hi = self.lo[:-n_slack], self.hi[:-n_slack]
        eq = lo == hi
        up, down = ~eq & np.isfinite(hi), ~eq & np.isfinite(lo)
        G = sp.vstack([A[up], -A[down]]).tocsc()
        P = self.P[:keep, :keep]
        P = (P + P.T - sp.diags(P.diagonal())).tocsc()
        problem = Problem(P, self.q[:keep], G, np.concatenate([hi[up], -lo[down]]), A[eq].tocsc(), lo[eq])
        return bool(solve_problem(problem, solver="clarabel").found)


@pytest.mark.slow
@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
@pytest.mark.parametrize("v_max", [1.0, 5.0, 10.0, 20.0])
def test_no_slack_wherever_the_hard_qp_is_feasible(v_max: float, coupling: str) -> None:
    """Every dt in {0.1, 0.05, 0.02, 0.01} on a crowd and a swap (gain 2): wherever the QP without
    slack is feasible (Clarabel), the planner's slack is at most 1e-6 m."""
    from mpcform.mpc.planner import MPCPlanner
    from mpcform.sim.simulation import simulate

    checked = 0
    for dt in (0.1, 0.05, 0.02, 0.01):
        for ref, start in crowd_and_swap():
            st_ = MPCSettings(horizon=8, gain_per_s=2.0, coupling=coupling, solve=SparseSolve())
            backend = HardCheck(2, st_.slack_weight)
            planner = MPCPlanner(ref, dt, Limits(v_max_mps=v_max, d_min_m=0.3), st_, solver=backend)
            res = simulate(planner, start, 60 * dt)
            solved = [i for i in res.infos if i.mode != "fast_path"]
            assert len(solved) == len(backend.feasible)
            for info, feasible in zip(solved, backend.feasible, strict=True):
                if feasible:
                    assert info.max_slack_m <= 1e-6, (dt, info)
                    checked += 1
    assert checked > 0
