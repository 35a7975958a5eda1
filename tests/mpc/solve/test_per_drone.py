"""Decoupled mode per drone (DAQP): the sparse QP's optimum, slack exactness, failures handled."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import crowd_and_swap
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.per_drone import PerDroneQP
from mpcform.mpc.strategy import SparseSolve
from mpcform.reference.base import ConstantReference
from mpcform.sim.simulation import simulate
from mpcform.solvers.base import QPBackend, QPSolution, SolverOptions
from mpcform.solvers.daqp_dense import DaqpBackend
from mpcform.solvers.registry import make_backend
from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle

# The sparse reference: Clarabel at tight tolerances (PIQP stops ~3e-6 away at any tolerance here).
# Where plans differ by more than ~1e-6 (an optimum at a vertex of the velocity polygon), the
# per-drone one has the lower cost: the comparison is by cost, plans only loosely.
ACCURATE = SparseSolve("qpsolvers:clarabel", SolverOptions(1e-10, 1e-10, 4000, 0.0))
PER_DRONE_SOLVER = "daqp (per drone)"
REFERENCE = "qpsolvers:clarabel"
PLAN_TOL = 1e-4

LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5)
VARIANTS: dict[str, tuple[int, Limits, tuple[SphereObstacle, ...], dict[str, Any]]] = {
    "planar": (2, LIMITS, (), {}),
    "spatial": (3, LIMITS, (), {}),
    "fence, acceleration, obstacle": (
        2,
        Limits(
            v_max_mps=1.0,
            d_min_m=0.5,
            a_max_mps2=3.0,
            geofence_min_m=np.array([-2.2, -1.0]),
            geofence_max_m=np.array([2.2, np.inf]),
        ),
        (SphereObstacle(np.array([0.0, -1.2]), 0.4),),
        {},
    ),
    "downwash, obstacle": (
        3,
        Limits(v_max_mps=1.0, d_min_m=0.5, downwash_kappa=2.0),
        (SphereObstacle(np.array([0.0, 0.0, -1.5]), 0.3),),
        {},
    ),
    "box, no quadratic slack term": (3, LIMITS, (), {"velocity_set": "box", "slack_quadratic": 0.0}),
    "planar, no grouping, no fast path": (2, LIMITS, (), {"grouping": False, "fast_path": False}),
}


def crowd(seed: int, n: int, dim: int) -> tuple[ConstantReference, np.ndarray]:
    """n drones at random in a small box, at least 0.6 m apart, each heading for the antipode."""
    rng = np.random.default_rng(seed)
    pts: list[np.ndarray] = []
    while len(pts) < n:
        p = rng.uniform(-1.8, 1.8, dim) * ([1.0, 0.6] + [1.0] * (dim - 2))
        if all(np.linalg.norm(p - q) >= 0.6 for q in pts):
            pts.append(p)
    start = np.array(pts)
    tpl = Template(-(start - start.mean(axis=0)))
    return ConstantReference(tpl, FormationState.from_param(-start.mean(axis=0))), start


class SparseQPs(QPBackend):
    """A backend that keeps the last sparse QP it solved, and its solution (around ``inner``)."""

    def __init__(self, inner: QPBackend) -> None:
        super().__init__(inner.options)
        self.inner, self.name, self.warm_starts = inner, inner.name, inner.warm_starts

    def setup(self, P: Any, q: Any, A: Any, lo: Any, hi: Any) -> None:
        self.P, self.A = (P + sp.triu(P, 1).T).toarray(), A.copy()
        self.q, self.lo, self.hi = q, lo, hi
        self.inner.setup(P, q, A, lo, hi)

    def update(self, q: Any, lo: Any, hi: Any, A_data: Any) -> None:
        self.q, self.lo, self.hi = q, lo, hi
        self.A.data = A_data.copy()
        self.inner.update(q, lo, hi, A_data)

    def solve(self, x0: Any = None) -> QPSolution:
        out = self.inner.solve(x0)
        self.x = out.x
        return out

    def cost_and_violation(self, z: np.ndarray) -> tuple[float, float]:
        r = self.A @ z
        return float(0.5 * z @ self.P @ z + self.q @ z), float(max(np.max(self.lo - r), np.max(r - self.hi)))


def pair(
    ref: ConstantReference, lim: Limits, obstacles: Any = (), **kw: Any
) -> tuple[MPCPlanner, MPCPlanner, SparseQPs]:
    """The planner per drone, and the same decoupled QP solved as one sparse QP to high accuracy
    (with the backend that records its QPs)."""
    per = MPCPlanner(ref, 0.1, lim, MPCSettings(coupling="decoupled", **kw), obstacles)
    sparse = MPCSettings(coupling="decoupled", solve=ACCURATE, **kw)
    qps = SparseQPs(make_backend(REFERENCE, ACCURATE.options))
    return per, MPCPlanner(ref, 0.1, lim, sparse, obstacles, solver=qps), qps


@settings(max_examples=16, deadline=None)
@given(seed=st.integers(0, 10_000), variant=st.sampled_from(sorted(VARIANTS)), n=st.integers(2, 7))
def test_per_drone_solves_the_sparse_qp(seed: int, variant: str, n: int) -> None:
    """Fed the same positions and guess, the per-drone solution is feasible for the sparse QP and
    at least as good as a high-accuracy interior point on it (so it is its optimum)."""
    dim, lim, obstacles, kw = VARIANTS[variant]
    ref, p = crowd(seed, n, dim)
    per, sparse, qps = pair(ref, lim, obstacles, **kw)
    assert per.solver_name == PER_DRONE_SOLVER and sparse.solver_name == REFERENCE
    mine = {}
    assert isinstance(per.step_solver, PerDroneQP)
    solve = per.step_solver.solve

    def keep(*args: Any) -> Any:
        out = solve(*args)
        mine["x"], mine["objective"] = out[0].x, out[0].objective
        return out

    per.step_solver.solve = keep  # type: ignore[method-assign]
    for planner in (per, sparse):
        planner.reset(0.0, p)
    for j in range(4):
        a, b = per.step(0.1 * j, p), sparse.step(0.1 * j, p)
        assert a.info.mode == b.info.mode
        if a.info.mode == "qp":
            cost, violation = qps.cost_and_violation(mine["x"])
            ref_cost, _ = qps.cost_and_violation(qps.x)
            assert violation <= 1e-8
            assert mine["objective"] == pytest.approx(cost, rel=1e-9, abs=1e-9)  # the sparse QP's objective
            assert cost <= ref_cost + 1e-9 * (1.0 + abs(ref_cost))
            assert per.plan is not None and sparse.plan is not None
            np.testing.assert_allclose(per.plan.inputs_mps, sparse.plan.inputs_mps, atol=PLAN_TOL, rtol=0)
        p = p + 0.1 * a.command_mps
        sparse.state.plan, sparse.state.u_prev = per.state.plan, per.state.u_prev  # the same guess next step


def test_a_weak_penalty_still_gives_the_hard_optimum() -> None:
    """A weak penalty (w1 below the hard QP's multipliers) would trade separation for tracking; the
    hard QP is feasible, so both solvers return its optimum without slack (the sparse one raises its
    weight and solves again)."""
    tpl = Template.line(2, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0], 0.0))
    start = np.array([[0.45, 0.0], [-0.45, 0.0]])  # separated; each wants the other's side
    lim = Limits(v_max_mps=1.0, d_min_m=0.4)
    per, sparse, _ = pair(ref, lim, slack_weight=0.05, tie_break_rad=0.0)
    a, b = per.step(0.0, start), sparse.step(0.0, start)
    assert a.info.max_slack_m == 0.0 and b.info.max_slack_m < 1e-5
    np.testing.assert_allclose(a.command_mps, b.command_mps, atol=1e-4)
    gap = np.linalg.norm(np.diff(start + 0.1 * a.command_mps, axis=0))
    assert gap >= 0.4  # no separation traded


def test_infeasible_start_separates_with_slack() -> None:
    tpl = Template.line(2, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0]))
    start = np.array([[0.0, 0.0], [0.1, 0.0]])
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=0.5, d_min_m=0.5), MPCSettings(coupling="decoupled"))
    res = simulate(planner, start, 4.0)
    assert res.infos[0].mode == "qp" and res.infos[0].max_slack_m > 0.1  # each side: half of d_min
    dist = np.linalg.norm(res.positions_m[:, 0] - res.positions_m[:, 1], axis=1)
    assert np.all(np.diff(dist) >= -1e-9) and dist[-1] >= 0.5 - 1e-6


def test_a_failed_drone_solve_falls_back(monkeypatch: pytest.MonkeyPatch) -> None:
    ref, start = crowd(3, 5, 2)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), MPCSettings(coupling="decoupled"))
    solver = planner.step_solver
    assert isinstance(solver, PerDroneQP)

    class Failing:
        @staticmethod
        def solve(*args: Any, **kwargs: Any) -> tuple[Any, ...]:
            info = {"iterations": 3, "lam": np.zeros(args[2].shape[0])}
            return np.full(args[1].shape[0], np.nan), 0.0, -6, info

    monkeypatch.setattr(solver.backend, "_daqp", Failing)
    res = simulate(planner, start, 1.0)
    failed = [i for i in res.infos if i.mode == "fallback"]
    assert failed and all("daqp: exit flag -6" in i.status for i in failed)
    assert np.all(np.isfinite(res.commands_mps))
    assert np.linalg.norm(res.commands_mps, axis=-1).max() <= 1.0 + 1e-12


class HardFeasibility:
    """DAQP, and at each drone's slack-free solve whether that QP is feasible (Clarabel): the
    decoupled QP is block-diagonal, so its hard version is feasible iff every drone's is."""

    def __init__(self, daqp: Any, nu: int) -> None:
        self.daqp, self.nu, self.steps = daqp, nu, []  # type: list[bool]

    def solve(
        self,
        H: np.ndarray,
        f: np.ndarray,
        A: np.ndarray,
        upper: np.ndarray,
        lower: np.ndarray,
        **options: Any,
    ) -> Any:
        if H.shape[0] == self.nu:  # the slack-free QP (the soft one has H more variables)
            self.steps[-1] &= self.feasible(f, A, upper, lower)
        return self.daqp.solve(H, f, A, upper, lower, **options)

    @staticmethod
    def feasible(f: np.ndarray, A: np.ndarray, upper: np.ndarray, lower: np.ndarray) -> bool:
        from qpsolvers import Problem, solve_problem

        up, down = upper < 1e29, lower > -1e29
        G = sp.csc_matrix(np.vstack([A[up], -A[down]]))
        h = np.concatenate([upper[up], -lower[down]])
        problem = Problem(sp.identity(f.shape[0], format="csc"), f, G, h)
        return bool(solve_problem(problem, solver="clarabel").found)


@pytest.mark.slow
@pytest.mark.parametrize("v_max", [1.0, 5.0, 10.0, 20.0])
def test_no_slack_where_the_drone_qps_are_feasible(v_max: float, monkeypatch: pytest.MonkeyPatch) -> None:
    """Per-drone mode at every dt in {0.1, 0.05, 0.02, 0.01} on a crowd and a swap (gain 2): wherever
    every drone's QP without slack is feasible (Clarabel), the planner's slack is at most 1e-6 m."""
    import daqp

    checked = 0
    for dt in (0.1, 0.05, 0.02, 0.01):
        for ref, start in crowd_and_swap():
            st_ = MPCSettings(horizon=8, gain_per_s=2.0, coupling="decoupled", grouping=False)
            planner = MPCPlanner(ref, dt, Limits(v_max_mps=v_max, d_min_m=0.3), st_)
            check = HardFeasibility(daqp, 8 * 2)
            solve = PerDroneQP.solve

            def counted(self: PerDroneQP, qp: Any, check: HardFeasibility = check, solve: Any = solve) -> Any:
                self.backend._daqp = check  # type: ignore[attr-defined]
                check.steps.append(True)
                return solve(self, qp)

            monkeypatch.setattr(PerDroneQP, "solve", counted)
            res = simulate(planner, start, 60 * dt)
            solved = [i for i in res.infos if i.mode != "fast_path"]
            assert planner.solver_name == PER_DRONE_SOLVER and len(solved) == len(check.steps)
            for info, feasible in zip(solved, check.steps, strict=True):
                if feasible:
                    assert info.max_slack_m <= 1e-6, (dt, info)
                    checked += 1
    assert checked > 0


def test_rows_with_a_velocity_loop_are_on_the_true_positions() -> None:
    """With a lag model the rows over v are ``a^T (x_e + sum_j G_{e,j} u_j)`` for ``u = M^-1 v``."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    tau, h, dim = 0.2, 6, 3
    lag = (np.array([[-1 / tau]]), np.array([1 / tau]), np.array([1.0]), (0, 1, 2))
    loop = VelocityLoop.from_groups([lag], dim, 0.1, h)
    st = MPCSettings(horizon=h, coupling="decoupled")
    from mpcform.mpc.constraints.limits import limit_rows

    per = PerDroneQP(dim, 0.1, LIMITS, st, limit_rows(dim, 0.1, LIMITS, st), DaqpBackend(), loop)
    rng = np.random.default_rng(5)
    v = rng.normal(size=h * dim)
    u = (per._m_inv @ v).reshape(h, dim)
    x = 0.1 * np.cumsum(u, axis=0)
    true = x + np.einsum("ejd,jd->ed", loop.forced[1:], u)
    coeffs, ends = rng.normal(size=(7, dim)), rng.integers(1, h + 1, 7)
    want = np.einsum("kd,kd->k", coeffs, true[ends - 1])
    np.testing.assert_allclose(per._rows_v(coeffs, ends) @ v, want, atol=1e-12)


def _lag_loop(dim: int, horizon: int) -> Any:
    """A first-order velocity lag of 0.2 s on every axis, at dt 0.1 s."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    lag = (np.array([[-5.0]]), np.array([5.0]), np.array([1.0]), tuple(range(dim)))
    return VelocityLoop.from_groups([lag], dim, 0.1, horizon)


def _recorded_calls(
    case: str, seed: int, n: int, duration_s: float, monkeypatch: pytest.MonkeyPatch
) -> tuple[PerDroneQP, list[tuple[Any, ...]]]:
    """The per-drone QP of a crowd of ``n`` drones (a variant of ``case``, with a 0.2 s lag loop
    if ``case`` says so) and every ``solve_each`` call of its closed loop."""
    dim, lim, obstacles, _ = VARIANTS["spatial" if "spatial" in case else case]
    ref, start = crowd(seed, n, dim)
    loop = _lag_loop(dim, 10) if "loop" in case else None
    settings = MPCSettings(coupling="decoupled", grouping=False, fast_path=False)
    planner = MPCPlanner(ref, 0.1, lim, settings, obstacles, loop=loop)
    qp = planner.step_solver
    assert isinstance(qp, PerDroneQP)
    calls: list[tuple[Any, ...]] = []
    solve_each = qp.solve_each
    monkeypatch.setattr(qp, "solve_each", lambda *args: calls.append(args) or solve_each(*args))
    simulate(planner, start, duration_s)
    monkeypatch.undo()
    return qp, calls


@pytest.mark.parametrize("case", ["planar", "fence, acceleration, obstacle", "spatial, lag loop"])
def test_a_drone_whose_target_meets_its_rows_skips_daqp_and_gets_daqps_solve(
    case: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where ``v = c`` meets every row of a drone, the drone gets it without a DAQP call: the same
    solve, multipliers and cost as DAQP's, bit for bit (per-drone bounds and a velocity loop too)."""
    from mpcform.mpc.solve import per_drone

    qp, calls = _recorded_calls(case, 0, 5, 4.0, monkeypatch)
    skipped, daqp = 0, qp.backend._daqp

    class Counted:  # DAQP, counting its calls
        calls = 0

        @staticmethod
        def solve(*args: Any, **kwargs: Any) -> Any:
            Counted.calls += 1
            return daqp.solve(*args, **kwargs)

    monkeypatch.setattr(qp.backend, "_daqp", Counted)
    for args in calls:
        before = Counted.calls
        fast = qp.solve_each(*args)
        with monkeypatch.context() as m:  # no drone meets its constant rows at v = c: DAQP for all
            m.setattr(per_drone, "within_bounds", lambda c, *_: np.zeros(c.shape[0], dtype=bool))
            middle = Counted.calls
            every = qp.solve_each(*args)
        skipped += (Counted.calls - middle) - (middle - before)
        assert np.array_equal(fast.v, every.v) and np.array_equal(fast.ok, every.ok)
        assert all(np.array_equal(a, b) for a, b in zip(fast.lams, every.lams, strict=True))
        assert np.array_equal(fast.cost, every.cost)
    assert skipped >= 10


@pytest.mark.parametrize("case", ["planar", "fence, acceleration, obstacle", "spatial, lag loop"])
def test_a_working_set_gives_the_solve_with_every_row(case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """DAQP first sees only a drone's constant rows near a bound and its separation rows near their
    bound; a solve that misses a row it did not see is solved again with all of them. Forced on
    every drone (no margin, any number of rows), the solves, flags and multipliers are
    those with every row, and some drones did miss a row of each kind and were solved again. The
    optimum is unique; multipliers of duplicate rows are not."""
    from mpcform.mpc.solve import per_drone, working_set

    qp, calls = _recorded_calls(case, 1, 6, 3.0, monkeypatch)
    missed: dict[str, list[int]] = {"misses": [], "separation_misses": []}

    def counted(name: str) -> Any:
        original = getattr(per_drone, name)

        def call(*args: Any) -> np.ndarray:
            out = original(*args)
            missed[name].append(int(out.sum()))
            return out

        return call

    for args in calls:
        every = qp.solve_each(*args)  # 6 drones: fewer than WORKING_MIN_ROWS in all, every row
        with monkeypatch.context() as m:
            m.setattr(working_set, "WORKING_MARGIN", 0.0)
            m.setattr(working_set, "WORKING_MIN_ROWS", 0)
            for name in missed:
                m.setattr(per_drone, name, counted(name))
            some = qp.solve_each(*args)
        np.testing.assert_allclose(some.v, every.v, rtol=0.0, atol=1e-9)
        assert np.array_equal(some.flags, every.flags) and np.array_equal(some.soft, every.soft)
        np.testing.assert_allclose(some.cost, every.cost, rtol=1e-12, atol=1e-12)
        for a, b in zip(some.lams, every.lams, strict=True):  # (a duplicate row's share is not unique)
            assert a.shape == b.shape and a.sum() == pytest.approx(b.sum(), rel=1e-9, abs=1e-9)
    for name, counts in missed.items():  # solved again, and many calls used working sets
        assert sum(counts) >= 3 and len(counts) >= 10, name


def test_separation_multipliers_are_each_drones_multipliers(monkeypatch: pytest.MonkeyPatch) -> None:
    """The one-pass ``separation_multipliers`` gives every drone's :meth:`multipliers`, bit for bit,
    for hard and soft (slack) solves."""
    spatial, calls = _recorded_calls("spatial, lag loop", 1, 6, 3.0, monkeypatch)
    tpl = Template.line(2, 2.0)  # a start inside d_min: soft solves
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0]))
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=0.5, d_min_m=0.5), MPCSettings(coupling="decoupled"))
    qp = planner.step_solver
    assert isinstance(qp, PerDroneQP)
    solve_each, close = qp.solve_each, []
    monkeypatch.setattr(qp, "solve_each", lambda *args: close.append(args) or solve_each(*args))
    simulate(planner, np.array([[0.0, 0.0], [0.1, 0.0]]), 1.0)
    monkeypatch.undo()
    soft = 0
    for solver, args in [(spatial, a) for a in calls] + [(qp, a) for a in close]:
        got = solver.solve_each(*args)
        soft += int(got.soft.sum())
        every = got.separation_multipliers()
        assert len(every) == got.v.shape[0]
        for j, mu in enumerate(every):
            assert np.array_equal(mu, got.multipliers(j))
            assert mu.shape[0] == got.offsets[j + 1] - got.offsets[j]
    assert soft >= 1 and len(calls) >= 10
