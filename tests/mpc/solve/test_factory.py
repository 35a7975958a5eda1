"""The one factory of step solvers: each strategy builds what it names, nothing else."""

from __future__ import annotations

import pytest
from helpers import bounds_of

from mpcform.mpc.constraints.limits import limit_rows
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.factory import build_step_solvers
from mpcform.mpc.solve.per_drone import PerDroneQP
from mpcform.mpc.solve.sparse import SparseSolver
from mpcform.mpc.solve.split import SplitQP
from mpcform.mpc.strategy import PerDroneSolve, SparseSolve, SplitPolicy
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend

LIMITS = bounds_of(v_max_mps=1.0, d_min_m=0.5)


def build(settings: MPCSettings, backend=None):  # noqa: ANN001, ANN201 - a test helper
    families, sep = limit_rows(2, 0.1, LIMITS, settings), Separation(2, LIMITS, settings, ())
    solvers = build_step_solvers(settings, 2, 0.1, LIMITS, families, sep, None, backend)
    assert solvers.pick(False) is solvers.every and solvers.name == solvers.every.name
    assert solvers.pick(True) is (solvers.stalled or solvers.every)  # while a drone is stalled
    return solvers.every, solvers.stalled


def test_sparse_with_the_named_backend_and_options() -> None:
    solver, stalled = build(MPCSettings(solve=SparseSolve("osqp", SolverOptions(1e-6, 1e-6, 99))))
    assert isinstance(solver, SparseSolver) and stalled is None
    assert solver.name == "osqp" and solver.backend.options.max_iter == 99


def test_a_backend_instance_replaces_the_named_one() -> None:
    backend = make_backend("piqp", SolverOptions())
    solver, _ = build(MPCSettings(solve=SparseSolve("osqp")), backend)
    assert isinstance(solver, SparseSolver) and solver.backend is backend


@pytest.mark.parametrize(
    ("split", "every", "stalled"),
    [
        (SplitPolicy(), PerDroneQP, SplitQP),
        (SplitPolicy(4), SplitQP, type(None)),
        (SplitPolicy(0, 0), PerDroneQP, type(None)),
    ],
)
def test_per_drone_and_its_split_policy(split: SplitPolicy, every: type, stalled: type) -> None:
    solver, while_stalled = build(
        MPCSettings(coupling="decoupled", solve=PerDroneSolve(max_iter=77, split=split))
    )
    assert type(solver) is every and type(while_stalled) is stalled
    per = solver.per_drone if isinstance(solver, SplitQP) else solver
    assert isinstance(per, PerDroneQP) and per.backend.max_iter == 77
    if isinstance(while_stalled, SplitQP):
        assert while_stalled.per_drone is solver and while_stalled.iterations == split.stalled
    if isinstance(solver, SplitQP):
        assert solver.iterations == split.iterations and solver.name == "daqp (per drone, iterated split)"


def test_an_exact_backend_refuses_obstacles_without_a_centre() -> None:
    """casadi:ipopt replaces the obstacle rows by the distance to a centre: a box has none."""
    import numpy as np

    from mpcform.errors import ValidationError
    from mpcform.world.shapes import Box, Cylinder

    settings = MPCSettings(solve=SparseSolve("osqp"))
    pytest.importorskip("casadi")
    exact = make_backend("casadi:ipopt", SolverOptions())
    families = limit_rows(2, 0.1, LIMITS, settings)
    box = Box(np.zeros(2), np.ones(2), 0.1)
    with pytest.raises(ValidationError, match=r"controller\.solver.*box"):
        build_step_solvers(
            settings, 2, 0.1, LIMITS, families, Separation(2, LIMITS, settings, (box,)), None, exact
        )
    disc = Cylinder(np.zeros(2), 0.5, clearance_m=0.1)  # a planar cylinder: a point core
    sep = Separation(2, LIMITS, settings, (disc,))
    assert build_step_solvers(settings, 2, 0.1, LIMITS, families, sep, None, exact).every.backend is exact
