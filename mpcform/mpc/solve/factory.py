"""The one factory of the planner's step solvers, from its solve strategy (:mod:`mpcform.mpc.strategy`)."""

from __future__ import annotations

from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.per_drone import PerDroneQP
from mpcform.mpc.solve.problem import StepSolver
from mpcform.mpc.solve.sparse import SparseSolver
from mpcform.mpc.solve.split import SplitQP
from mpcform.mpc.strategy import PerDroneSolve
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.solvers.base import QPBackend
from mpcform.solvers.registry import make_backend, make_per_drone_backend
from mpcform.world.limits import Limits


def build_step_solvers(
    settings: MPCSettings,
    dim: int,
    dt_s: float,
    limits: Limits,
    families: tuple[LimitRows, ...],
    separation: Separation,
    loop: VelocityLoop | None = None,
    backend: QPBackend | None = None,
) -> tuple[StepSolver, StepSolver | None]:
    """The solver of every step and, when the split rounds run only while a drone is stalled
    (``SplitPolicy.stalled`` with no ``iterations``), the solver of those steps (else None).

    ``backend`` replaces the sparse strategy's backend by an instance (e.g. a recording wrapper).
    """
    solve = settings.strategy
    if not isinstance(solve, PerDroneSolve):
        qp_backend = backend or make_backend(solve.backend, solve.options)
        return SparseSolver(qp_backend, dim, dt_s, limits, settings, families, separation, loop), None
    per_drone_backend = make_per_drone_backend(solve.backend, solve.max_iter)
    per = PerDroneQP(dim, dt_s, limits, settings, families, per_drone_backend, loop)
    split = solve.split
    if split.iterations:  # the pair rows' split points iterated at every step (mpc.split)
        return SplitQP(per, split.iterations, split.budget_s), None
    if split.stalled:  # only while a drone is stalled (liveness)
        return per, SplitQP(per, split.stalled, split.budget_s)
    return per, None
