"""A qpsolvers solver as the per-drone backend: the same per-drone QPs as DAQP, split rounds
included, give the same plans (the acceptance of a second per-drone backend)."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import SolverError
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.per_drone import PerDroneQP
from mpcform.mpc.solve.problem import StepQP
from mpcform.mpc.solve.split import SplitQP
from mpcform.mpc.strategy import PerDroneSolve, SplitPolicy
from mpcform.reference.base import ConstantReference
from mpcform.sim.simulation import simulate
from mpcform.solvers.qpsolvers_dense import QPSolversDenseBackend
from mpcform.solvers.registry import make_per_drone_backend
from mpcform.world.limits import Limits

LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5)
DT, ROUNDS = 0.1, 8


def swap_qps(n: int, dim: int, seed: int, steps: int) -> tuple[PerDroneQP, list[StepQP]]:
    """The per-drone QPs with pair rows of a decoupled split planner (DAQP) flying a perturbed swap."""
    rng = np.random.default_rng(seed)
    angle = 2 * np.pi * np.arange(n) / n
    ring = 1.2 * np.column_stack([np.cos(angle), np.sin(angle)] + [0.3 * np.sin(angle)] * (dim - 2))
    ref = ConstantReference(Template(ring - ring.mean(axis=0)), FormationState.from_param(np.zeros(dim)))
    settings = MPCSettings(coupling="decoupled", solve=PerDroneSolve(split=SplitPolicy(ROUNDS)))
    planner = MPCPlanner(ref, DT, LIMITS, settings)
    split = planner.step_solver
    assert isinstance(split, SplitQP)
    qps: list[StepQP] = []
    solve = split.solve

    def keep(qp: StepQP) -> object:
        qps.append(qp)
        return solve(qp)

    split.solve = keep  # type: ignore[method-assign]
    simulate(planner, -ring + rng.normal(0.0, 0.3, ring.shape), steps * DT)
    return split.per_drone, [qp for qp in qps if (qp.rows.labels[:, 1] >= 0).any()]


@pytest.mark.parametrize(("n", "dim", "seed"), [(5, 2, 0), (6, 3, 1)])
def test_a_second_backend_plans_the_same_with_split_rounds(n: int, dim: int, seed: int) -> None:
    """The same per-drone QPs, split rounds on, solved with DAQP and with quadprog through qpsolvers
    (exact active-set solvers both): the plans [u | x | s] agree to 1e-6 at every step."""
    pytest.importorskip("quadprog")
    daqp_qp, qps = swap_qps(n, dim, seed, 12)
    assert qps
    other = PerDroneQP(
        dim,
        DT,
        daqp_qp.limits,
        daqp_qp.settings,
        daqp_qp.families,
        make_per_drone_backend("qpsolvers:quadprog", 4000),
    )
    rounds = []
    for qp in qps:
        a, b = SplitQP(daqp_qp, ROUNDS, None).run(qp), SplitQP(other, ROUNDS, None).run(qp)
        assert a.solution.success and b.solution.success
        assert a.solution.x is not None and b.solution.x is not None
        np.testing.assert_allclose(b.solution.x, a.solution.x, atol=1e-6, rtol=0)
        rounds.append(a.rounds)
    assert max(rounds) > 0  # the rounds ran (the multipliers drove them)


def test_a_planner_flies_with_the_qpsolvers_backend() -> None:
    pytest.importorskip("quadprog")
    tpl = Template.line(2, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0], np.pi))
    settings = MPCSettings(coupling="decoupled", solve=PerDroneSolve("qpsolvers:quadprog"))
    planner = MPCPlanner(ref, DT, LIMITS, settings)
    assert planner.solver_name == "qpsolvers:quadprog (per drone)"
    res = simulate(planner, np.array([[-1.0, 0.0], [1.0, 0.0]]), 8.0)  # the template: a swap
    assert any(i.mode == "qp" for i in res.infos)
    gaps = np.linalg.norm(res.positions_m[:, 0] - res.positions_m[:, 1], axis=1)
    assert gaps.min() >= 0.5 - 1e-6


def test_an_uninstalled_solver_is_refused_with_its_install_hint() -> None:
    with pytest.raises(SolverError, match="not installed"):
        QPSolversDenseBackend("gurobi")
