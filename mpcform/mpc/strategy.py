"""How a step's QP is solved: one strategy, chosen once (scenario table ``[controller.solve]``).

``MPCSettings.coupling`` chooses the rows; the strategy how they are solved:

- :class:`SparseSolve`: the sparse QP of :mod:`mpcform.mpc.solve.sparse_qp` with a backend of
  :data:`~mpcform.solvers.registry.FAMILIES` (either coupling; decoupled rows then make one
  block-diagonal sparse QP), with its tolerances;
- :class:`PerDroneSolve` (decoupled rows only): each conflicted drone's small dense QP with a
  per-drone backend of :data:`~mpcform.solvers.registry.PER_DRONE_FAMILIES` (DAQP by default,
  :mod:`mpcform.mpc.solve.per_drone`), and the :class:`SplitPolicy` of its pair rows' split points
  (:mod:`mpcform.mpc.solve.split`).

A setting that a strategy would ignore has no place in it, so it cannot be written.
:func:`mpcform.mpc.solve.factory.build_step_solvers` is the one factory of the planner's step
solvers.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from mpcform._validate import positive
from mpcform.errors import ValidationError, shown
from mpcform.solvers.base import QPBackend, SolverOptions
from mpcform.solvers.registry import DEFAULT_PER_DRONE_SOLVER, DEFAULT_SOLVER

SOLVE_KINDS = ("sparse", "per_drone")


def _count(field_name: str, value: object, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < least:
        raise ValidationError(field_name, f"expected an integer >= {least}, got {shown(value)}")
    return value


@dataclass(frozen=True)
class SparseSolve:
    """The sparse QP with the backend ``backend`` (``mpcform solvers``) at ``options`` (absolute and
    relative tolerance, iteration and time limit per QP)."""

    backend: str = DEFAULT_SOLVER
    options: SolverOptions = field(default_factory=lambda: SolverOptions(1e-4, 1e-4, 4000, 0.0))

    def __post_init__(self) -> None:
        o = self.options
        positive("controller.solve.eps_abs", o.eps_abs)
        positive("controller.solve.eps_rel", o.eps_rel, allow_zero=True)
        _count("controller.solve.max_iter", o.max_iter, 1)
        positive("controller.solve.time_limit", o.time_limit_s, allow_zero=True)


@dataclass(frozen=True)
class SplitPolicy:
    """Rounds that move each pair row's split point from the midpoint towards the joint optimum
    (:mod:`mpcform.mpc.solve.split`): ``iterations`` at every step (0: the midpoint split), else
    ``stalled`` in the steps where a drone is stalled in conflict (:mod:`mpcform.mpc.liveness`;
    0: never); no new round starts after ``budget_s`` of a step's solve [s] (None: no limit)."""

    iterations: int = 0
    stalled: int = 20
    budget_s: float | None = None

    def __post_init__(self) -> None:
        _count("controller.solve.split_iterations", self.iterations, 0)
        _count("controller.solve.stalled_split", self.stalled, 0)
        if self.budget_s is not None:
            positive("controller.solve.split_budget", self.budget_s)


@dataclass(frozen=True)
class PerDroneSolve:
    """Each drone's dense QP with the per-drone backend ``backend`` (``daqp`` or
    ``qpsolvers:<name>``) capped at ``max_iter`` iterations, and the ``split`` policy. DAQP meets
    rows to 1e-9; it has no other tolerance to set."""

    backend: str = DEFAULT_PER_DRONE_SOLVER
    max_iter: int = 4000
    split: SplitPolicy = field(default_factory=SplitPolicy)

    def __post_init__(self) -> None:
        _count("controller.solve.max_iter", self.max_iter, 1)


SolveStrategy = SparseSolve | PerDroneSolve


def default_strategy(coupling: str) -> SolveStrategy:
    """The strategy of a coupling when none is given: per drone for ``decoupled``, else sparse."""
    return PerDroneSolve() if coupling == "decoupled" else SparseSolve()


def check_strategy(coupling: str, solve: SolveStrategy) -> None:
    """A per-drone strategy needs decoupled rows (joint pair rows couple two drones' QPs)."""
    if isinstance(solve, PerDroneSolve) and coupling != "decoupled":
        raise ValidationError(
            "controller.solve.kind",
            f"'per_drone' needs coupling = 'decoupled' (joint pair rows couple the drones), got {coupling!r}",
        )
    if not isinstance(solve, SparseSolve | PerDroneSolve):
        raise ValidationError("controller.solve", f"expected SparseSolve or PerDroneSolve, got {solve!r}")


def with_backend(solve: SolveStrategy, backend: str | QPBackend, field_name: str) -> SolveStrategy:
    """``solve`` with the sparse backend ``backend`` (``--solver``, or a backend instance); a
    per-drone strategy would ignore it: an error naming ``field_name``."""
    name = backend.name if isinstance(backend, QPBackend) else backend
    if isinstance(solve, PerDroneSolve):
        raise ValidationError(
            field_name,
            f"{name!r} solves the sparse QP, but this planner solves each drone's QP with "
            f"{solve.backend!r} ([controller.solve] kind = 'per_drone'); set kind = 'sparse' to use it",
        )
    return solve if isinstance(backend, QPBackend) else SparseSolve(backend, solve.options)


def as_sparse(solve: SolveStrategy) -> SparseSolve:
    """``solve`` as a sparse solve: itself, or for a per-drone strategy the default sparse solve at
    its iteration limit (the same rows as one sparse QP: the benchmarks' references)."""
    if isinstance(solve, SparseSolve):
        return solve
    return SparseSolve(options=replace(SparseSolve().options, max_iter=solve.max_iter))
