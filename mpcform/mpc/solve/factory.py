"""The planner's step solvers, built once from its solve strategy (:mod:`mpcform.mpc.strategy`):
the one factory (:func:`build_step_solvers`) and the object the planner asks each step
(:class:`StepSolvers`): which solver this step takes, and which drones its rows tie together."""

from __future__ import annotations

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.per_drone import PerDroneQP
from mpcform.mpc.solve.problem import StepSolver
from mpcform.mpc.solve.sparse import SparseSolver
from mpcform.mpc.solve.split import SplitQP
from mpcform.mpc.strategy import PerDroneSolve
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.solvers.base import QPBackend
from mpcform.solvers.registry import make_backend, make_per_drone_backend
from mpcform.world.bounds import PlanningBounds


class StepSolvers:
    """The solver of every step, and while a drone is stalled (liveness) the split rounds' solver
    when they run only then (None: the same one every step)."""

    def __init__(self, every: StepSolver, stalled: StepSolver | None = None) -> None:
        self.every, self.stalled = every, stalled
        self.name, self.warm_starts = every.name, every.warm_starts

    def reset(self) -> None:
        """Start a new run."""
        self.every.reset()

    def pick(self, resolving: bool) -> StepSolver:
        """The solver of a step; ``resolving``: a drone's tie-break is escalated (it is stalled)."""
        return self.stalled if resolving and self.stalled is not None else self.every

    @staticmethod
    def linked(rows: SeparationRows, solver: StepSolver) -> Array:
        """The drone pairs (m, 2) within reach whose rows tie the two drones into one group of the
        QP: the joint pair rows, or with a solver that moves a pair's split point
        (:attr:`~mpcform.mpc.solve.problem.StepSolver.splits_pairs`) both sides of a decoupled pair."""
        if solver.splits_pairs:
            return rows.labels[(rows.labels[:, 1] >= 0) & rows.single_on]
        return rows.pairs[rows.pair_on]


def build_step_solvers(
    settings: MPCSettings,
    dim: int,
    dt_s: float,
    limits: PlanningBounds,
    families: tuple[LimitRows, ...],
    separation: Separation,
    loop: VelocityLoop | None = None,
    backend: QPBackend | None = None,
) -> StepSolvers:
    """The solver of every step and, when the split rounds run only while a drone is stalled
    (``SplitPolicy.stalled`` with no ``iterations``), the solver of those steps.

    ``backend`` replaces the sparse strategy's backend by an instance (e.g. a recording wrapper).
    """
    solve = settings.strategy
    if not isinstance(solve, PerDroneSolve):
        qp_backend = backend or make_backend(solve.backend, solve.options)
        shapes = None if separation.obstacles is None else separation.obstacles.shapes
        if qp_backend.point_obstacles_only and shapes is not None and not shapes.point_cores:
            kinds = sorted({s.kind for s in shapes.shapes if not type(s).point_core(dim)})
            raise ValidationError(
                "controller.solver",
                f"{qp_backend.name} writes the exact distance to an obstacle's centre, and a "
                f"{' or '.join(kinds)} obstacle has none here: choose another solver",
            )
        return StepSolvers(SparseSolver(qp_backend, dim, dt_s, limits, settings, families, separation, loop))
    per_drone_backend = make_per_drone_backend(solve.backend, solve.max_iter)
    per = PerDroneQP(dim, dt_s, limits, settings, families, per_drone_backend, loop)
    split = solve.split
    if split.iterations:  # the pair rows' split points iterated at every step (mpc.split)
        return StepSolvers(SplitQP(per, split.iterations, split.budget_s))
    if split.stalled:  # only while a drone is stalled (liveness)
        return StepSolvers(per, SplitQP(per, split.stalled, split.budget_s))
    return StepSolvers(per)
