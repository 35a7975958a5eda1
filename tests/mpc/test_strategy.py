"""Solve strategies: each field checked with the scenario key it comes from, the coupling's
default, the per-drone strategy refusing a sparse backend, and the sparse view of a strategy."""

import pytest

from mpcform.errors import ValidationError
from mpcform.mpc.strategy import (
    PerDroneSolve,
    SparseSolve,
    SplitPolicy,
    as_sparse,
    check_strategy,
    default_strategy,
    with_backend,
)
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import DEFAULT_PER_DRONE_SOLVER, DEFAULT_SOLVER, make_backend


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: SparseSolve(options=SolverOptions(0.0, 1e-4, 10)), "controller.solve.eps_abs"),
        (lambda: SparseSolve(options=SolverOptions(1e-4, -1.0, 10)), "controller.solve.eps_rel"),
        (lambda: SparseSolve(options=SolverOptions(1e-4, 1e-4, 0)), "controller.solve.max_iter"),
        (lambda: SparseSolve(options=SolverOptions(1e-4, 1e-4, 9, -1.0)), "controller.solve.time_limit"),
        (lambda: PerDroneSolve(max_iter=0), "controller.solve.max_iter"),
        (lambda: PerDroneSolve(max_iter=True), "controller.solve.max_iter"),
        (lambda: SplitPolicy(iterations=-1), "controller.solve.split_iterations"),
        (lambda: SplitPolicy(iterations=2.0), "controller.solve.split_iterations"),  # type: ignore[arg-type]
        (lambda: SplitPolicy(stalled=-1), "controller.solve.stalled_split"),
        (lambda: SplitPolicy(budget_s=0.0), "controller.solve.split_budget"),
    ],
)
def test_bad_fields_name_their_key(make, match):
    with pytest.raises(ValidationError, match=match):
        make()


def test_the_defaults_are_the_last_releases():
    sparse, per_drone = SparseSolve(), PerDroneSolve()
    assert sparse.backend == DEFAULT_SOLVER and sparse.options == SolverOptions(1e-4, 1e-4, 4000, 0.0)
    assert per_drone.backend == DEFAULT_PER_DRONE_SOLVER == "daqp" and per_drone.max_iter == 4000
    assert per_drone.split == SplitPolicy(
        0, 20, None
    )  # 20 stalled rounds since the default a_max (10 before)
    assert default_strategy("decoupled") == per_drone and default_strategy("joint") == sparse


def test_per_drone_needs_decoupled_rows():
    check_strategy("decoupled", PerDroneSolve())
    check_strategy("joint", SparseSolve())
    check_strategy("decoupled", SparseSolve())  # the decoupled rows as one sparse QP
    with pytest.raises(ValidationError, match="controller.solve.kind.*decoupled"):
        check_strategy("joint", PerDroneSolve())


def test_a_sparse_backend_replaces_the_sparse_one_and_a_per_drone_strategy_refuses_it():
    tight = SparseSolve("osqp", SolverOptions(1e-6, 1e-6, 100))
    assert with_backend(tight, "piqp", "--solver") == SparseSolve("piqp", tight.options)
    backend = make_backend("piqp", tight.options)
    assert with_backend(tight, backend, "--solver") is tight  # the instance goes to the factory
    with pytest.raises(ValidationError, match="--solver.*'osqp' solves the sparse QP.*'daqp'"):
        with_backend(PerDroneSolve(), "osqp", "--solver")
    with pytest.raises(ValidationError, match="'piqp' solves the sparse QP"):
        with_backend(PerDroneSolve(), backend, "solver")


def test_as_sparse_keeps_a_sparse_strategy_and_the_per_drone_iteration_limit():
    tight = SparseSolve("osqp", SolverOptions(1e-6, 1e-6, 100))
    assert as_sparse(tight) is tight
    assert as_sparse(PerDroneSolve(max_iter=77)) == SparseSolve(options=SolverOptions(1e-4, 1e-4, 77, 0.0))
