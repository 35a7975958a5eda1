"""Iterated split points: every iterate meets the joint pair rows, the cost never rises and never
goes below the joint QP's optimum (Clarabel), and reaches it on small encounters. Without a_max:
the braking tail's stop-point rows (tests/mpc/test_braking.py) are not at the interval ends."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.constraints.rows import row_ends
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.problem import StepQP
from mpcform.mpc.solve.sparse import SparseSolver
from mpcform.mpc.solve.split import SplitQP
from mpcform.mpc.strategy import PerDroneSolve, SparseSolve, SplitPolicy
from mpcform.reference.base import ConstantReference
from mpcform.sim.simulation import simulate
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend
from mpcform.world.limits import Limits

LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=np.inf)  # rows at the interval ends only
DT = 0.1


def swap(n: int, dim: int, seed: int, noise_m: float = 0.3) -> tuple[ConstantReference, np.ndarray]:
    """n drones on a (tilted) ring heading for the antipode, their starts perturbed."""
    rng = np.random.default_rng(seed)
    angle = 2 * np.pi * np.arange(n) / n
    ring = 1.2 * np.column_stack([np.cos(angle), np.sin(angle)] + [0.3 * np.sin(angle)] * (dim - 2))
    start = -ring + rng.normal(0.0, noise_m, ring.shape)
    return ConstantReference(
        Template(ring - ring.mean(axis=0)), FormationState.from_param(np.zeros(dim))
    ), start


def step_qps(n: int, dim: int, seed: int, steps: int) -> tuple[MPCPlanner, list[StepQP]]:
    """The QPs of a decoupled split planner's first ``steps`` steps (pair sides in them)."""
    ref, start = swap(n, dim, seed)
    planner = MPCPlanner(
        ref, DT, LIMITS, MPCSettings(coupling="decoupled", solve=PerDroneSolve(split=SplitPolicy(200)))
    )
    qps: list[StepQP] = []
    solve = planner.step_solver.solve

    def keep(qp: StepQP) -> object:
        qps.append(qp)
        return solve(qp)

    planner.step_solver.solve = keep  # type: ignore[method-assign]
    simulate(planner, start, steps * DT)
    return planner, [qp for qp in qps if (qp.rows.labels[:, 1] >= 0).any()]


def tracking(planner: MPCPlanner, qp: StepQP, z: np.ndarray) -> tuple[float, float]:
    """``0.5 sum_j ||u_j + k x_j - c_j||^2`` of a solution ``[u | x | s]`` (x_0 = 0) and its largest slack."""
    h, m, d = planner.settings.horizon, qp.drones.shape[0], planner.dim
    nud = h * m * d
    u, x = z[:nud].reshape(h, m, d), z[nud : 2 * nud].reshape(h, m, d)
    x = np.concatenate([np.zeros((1, m, d)), x[:-1]])
    cost = 0.5 * float(np.sum((u + planner.settings.gain_per_s * x - qp.targets_mps) ** 2))
    return cost, float(z[2 * nud :].max(initial=0.0))


def joint_optimum(planner: MPCPlanner, qp: StepQP) -> float:
    """The joint QP with the same rows (same normals, the sides' bounds added), by Clarabel."""
    settings = MPCSettings(coupling="joint", solve=SparseSolve(options=SolverOptions(1e-10, 1e-10, 4000)))
    backend = make_backend("qpsolvers:clarabel", SolverOptions(1e-10, 1e-10, 4000, 0.0))
    solver = SparseSolver(
        backend, planner.dim, DT, LIMITS, settings, planner.steps.families, planner.steps.separation
    )
    joint = replace(qp, given_rows=qp.rows.joint(), on_only=None, warm=None, rebuilt=True)
    sol, _ = solver.solve(joint)
    assert sol.success and sol.x is not None
    cost, slack = tracking(planner, joint, sol.x)
    assert slack < 1e-8  # the comparison holds where the joint QP needs no slack
    return cost


@pytest.mark.parametrize(("n", "dim", "seed"), [(2, 2, 0), (3, 2, 1), (4, 3, 2), (6, 3, 3)])
def test_every_iterate_meets_the_joint_rows_and_the_cost_falls_to_no_less_than_the_joint(
    n: int, dim: int, seed: int
) -> None:
    planner, qps = step_qps(n, dim, seed, 12)
    assert qps and planner.solver_name == "daqp (per drone, iterated split)"
    split = SplitQP(planner.step_solver.per_drone, 30, None)  # type: ignore[attr-defined]
    ends = row_ends(planner.settings.horizon)
    for qp in qps:
        run = split.run(qp, record=True)
        joint = qp.rows.joint()
        i, k = joint.pairs.T
        assert len(run.positions) == run.rounds + 1
        for x in run.positions:  # (H, m, d), every round's plans, accepted or not
            rel = x[ends - 1][:, i] - x[ends - 1][:, k]  # (R, P, d)
            value = np.einsum("prd,rpd->pr", joint.pair_coeffs, rel) - joint.pair_lower
            assert value[joint.pair_on].min(initial=np.inf) >= -1e-9
        assert np.all(np.diff(run.history[:, 0]) <= 1e-12 * abs(run.history[0, 0]))  # the best never rises
        best, _ = tracking(planner, qp, run.solution.x)
        assert best >= joint_optimum(planner, qp) * (1.0 - 1e-8)


@pytest.mark.parametrize(
    ("n", "dim", "seed", "steps"), [(2, 3, 2, 8), (3, 2, 1, 8), (3, 3, 5, 8), (4, 2, 6, 5)]
)
def test_small_encounters_reach_the_joint_optimum(n: int, dim: int, seed: int, steps: int) -> None:
    """Every step's iterated split ends within 1e-4 of the joint optimum (the midpoint split is
    up to 40 % above it at the encounter's first step)."""
    planner, qps = step_qps(n, dim, seed, steps)
    split = SplitQP(planner.step_solver.per_drone, 200, None)  # type: ignore[attr-defined]
    gaps = []
    for qp in qps:
        run = split.run(qp)
        mid = run.history[0, 0]
        best, slack = tracking(planner, qp, run.solution.x)
        joint = joint_optimum(planner, qp)
        assert slack == 0.0
        gaps.append(((mid - joint) / joint, (best - joint) / joint))
    assert max(g[0] for g in gaps) > 1e-2  # the midpoint split is far from it somewhere
    assert max(g[1] for g in gaps) <= 1e-4, gaps


def test_the_planner_reports_the_rounds_and_keeps_the_pairs_apart() -> None:
    ref, start = swap(5, 2, 5)
    for rounds in (0, 20):
        st = MPCSettings(coupling="decoupled", solve=PerDroneSolve(split=SplitPolicy(rounds, stalled=0)))
        res = simulate(MPCPlanner(ref, DT, LIMITS, st), start, 4.0)
        qp = [i for i in res.infos if i.mode == "qp"]
        assert qp and all(("split" in i.status) == bool(rounds) for i in qp)
        i, k = np.triu_indices(5, 1)
        rel = res.positions_m[:, i] - res.positions_m[:, k]
        assert np.linalg.norm(rel, axis=2).min() >= LIMITS.d_min_m - 1e-9


def test_a_budget_stops_the_rounds() -> None:
    planner, qps = step_qps(4, 3, 2, 6)
    unbounded = SplitQP(planner.step_solver.per_drone, 50, None)  # type: ignore[attr-defined]
    none_left = SplitQP(planner.step_solver.per_drone, 50, 1e-9)  # type: ignore[attr-defined]
    assert any(unbounded.run(qp).rounds > 0 for qp in qps)
    assert all(none_left.run(qp).rounds == 0 for qp in qps)


@pytest.mark.slow
@pytest.mark.alone
def test_every_run_of_the_random_families_completes_safely_with_split_rounds() -> None:
    """The first 80 runs of ``tests/families.py``, all decoupled with 10 split rounds per step: no
    separation, approach or obstacle violation, every drone ends within 0.1 m of its target."""
    from families import family, outcomes

    runs = list(family(1, 80))
    for sc in runs:
        sc["controller"].update(coupling="decoupled", solve={"kind": "per_drone", "split_iterations": 10})
    bad = []
    for sc, out in zip(runs, outcomes(runs), strict=True):
        checks = ("separation_violations", "approached", "unseparated", "obstacle_violations")
        if any(out[k] for k in checks) or out["completion"] < 1.0 or not out["finite_times"]:
            bad.append((sc["name"], out))
    assert not bad


def test_a_newton_step_keeps_frozen_rows_put() -> None:
    """After a drone's QP fails, its rows are frozen and the Newton step solves for the others
    only (the step once indexed the Hessian out of bounds when a frozen row sorted last)."""
    from mpcform.mpc.solve.split import SplitStep

    planner, qps = step_qps(6, 3, 3, 6)
    checked = 0
    for qp in qps:
        step_qp = SplitStep(planner.step_solver.per_drone, qp)
        m = qp.start_m.shape[0]
        best = step_qp.solve(np.arange(m), step_qp.midpoint(), np.zeros_like(qp.targets_mps), None)
        free = step_qp.direction(best)
        if free is None:
            continue
        moving = np.flatnonzero(np.abs(free[0]).max(axis=1) > 0)  # pairs whose split moves
        last = int(qp.rows.singles[step_qp.first[moving[-1]]])  # a drone of the last pair that moves
        frozen = step_qp.rows_of(np.array([last]))
        got = step_qp.direction(best, frozen)
        if got is not None:
            assert np.all(got[0][frozen] == 0.0) and got[1] < 0.0
        checked += 1
    assert checked


def test_the_newton_model_matches_finite_differences_of_the_drone_solves() -> None:
    """A drone's sensitivity (its optimum's and its multipliers' derivatives in its separation
    rows' bounds, and the inactive rows' rates) against re-solves with one active row's bound moved
    by +-h: the optimum is piecewise linear in the bounds, exact while the active set holds."""
    from mpcform.mpc.solve.split import SplitStep

    planner, qps = step_qps(4, 3, 2, 6)
    qp, h = qps[0], 1e-6
    step = SplitStep(planner.step_solver.per_drone, qp)
    m = qp.start_m.shape[0]
    it = step.solve(np.arange(m), step.midpoint(), np.zeros_like(qp.targets_mps), None)
    checked = 0
    for i in range(m):
        sens = step.sensitivity(it, i)
        assert sens is not None
        for a, row_id in enumerate(sens.active):
            item, row = divmod(int(it.rows[i][row_id]), step.r)
            pair = step.pair_of[item]
            if pair < 0 or not step.splittable[pair, row] or sens.hessian[a, a] >= 1e4:
                continue  # (a large curvature: a dependent row, GRAM_EPS; its multiplier is not unique)
            sign, moved = step.sign[item], []
            for delta in (h, -h):
                shift = step.midpoint()
                shift[pair, row] = delta  # this side's bound moves by sign * delta
                moved.append(step.solve(np.array([i]), shift, np.zeros_like(qp.targets_mps), it))
            up, down = moved
            dv = (up.v[i] - down.v[i]) / (2 * h * sign)
            np.testing.assert_allclose(dv, sens.dv[:, a], atol=1e-6 * max(1.0, np.abs(sens.dv).max()))
            dmu = (up.mu[i][row_id] - down.mu[i][row_id]) / (2 * h * sign)
            assert dmu == pytest.approx(sens.hessian[a, a], rel=1e-5, abs=1e-6)
            dcost = (up.cost[i] - down.cost[i]) / (2 * h * sign)
            assert dcost == pytest.approx(it.mu[i][row_id], rel=1e-5, abs=1e-7)
            rows_off = np.concatenate([sens.const_rows[sens.const_off], sens.sep_rows])  # the inactive rows
            assert rows_off.shape[0] == sens.slack.shape[0]
            np.testing.assert_allclose(sens.rate(dv), rows_off @ dv, rtol=1e-12, atol=1e-12)
            checked += 1
    assert checked >= 2
