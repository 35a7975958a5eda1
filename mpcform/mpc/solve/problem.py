"""One step's QP over the drones it is solved for, and the interface of what solves it.

The planner turns its problem (targets, limits, separation rows about the guess) into a
:class:`StepQP`; a :class:`StepSolver` (the sparse QP with a backend, :mod:`mpcform.mpc.solve.sparse`,
or DAQP drone by drone, :mod:`mpcform.mpc.solve.per_drone`) returns the solution in the sparse QP's
layout ``[u | x | s]`` over those drones (:mod:`mpcform.mpc.constraints.rows`), and how many rows are active.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.solvers.base import QPSolution

ACTIVE_TOL = 1e-6  # a row whose multiplier exceeds this is reported active


BUDGET_CUT = "budget_cut"
"""The key of :attr:`QPSolution.extras` a step solver sets True when the wall clock (the step's
deadline, a split budget) stopped its optional work before its counted rounds: the one place the
machine's load can change a plan (reported per step and per run)."""


@dataclass(frozen=True)
class StepQP:
    """The QP of one step over ``drones`` (m,) of the ``n`` (global indices).

    ``start_m`` (m, d) their positions p0, ``targets_mps`` (H, m, d) the cost's ``c_j``,
    ``u_prev_mps`` (m, d) their last commands, ``given_rows`` the separation rows: over them (drones
    renumbered 0..m-1) when ``on_only`` is None, else over all ``n`` drones, of which :attr:`rows`
    keeps those within ``drones`` (with ``on_only``, only the items within reach), ``rebuilt``
    whether the candidate set changed this step, ``warm`` (2, H, m, d) the primal warm start
    (inputs, relative positions), None for a solver that takes none;
    ``free_m`` (S, m, d): with a velocity loop, its free response at each position the geofence
    bounds (steps 1..H, then the braking stop point), else None; ``deadline_s``: the
    ``time.perf_counter()`` after which no optional work (a split round) starts (None: none).
    """

    n: int
    drones: Array
    start_m: Array
    targets_mps: Array
    u_prev_mps: Array
    given_rows: SeparationRows
    rebuilt: bool
    warm: Array | None
    free_m: Array | None = None
    deadline_s: float | None = None
    on_only: bool | None = None

    @cached_property
    def rows(self) -> SeparationRows:
        """The separation rows over ``drones`` (renumbered 0..m-1), selected on first use (a solver
        drone by drone reads ``given_rows`` through :meth:`places` instead: no copies)."""
        if self.on_only is None:
            return self.given_rows
        return self.given_rows.subset(self.drones, self.n, self.on_only)

    def places(self) -> Array | None:
        """Each of the ``n`` drones' place among ``drones`` (-1: not among them), when
        ``given_rows`` are over all ``n`` drones (None: over ``drones`` already)."""
        if self.on_only is None:
            return None
        local = np.full(self.n, -1, dtype=np.intp)
        local[self.drones] = np.arange(self.drones.shape[0])
        return local


class StepSolver(ABC):
    """Solves the planner's QP step after step (may keep state between steps)."""

    name: str
    warm_starts: bool  # whether :meth:`solve` uses ``StepQP.warm`` (the planner builds it only then)
    splits_pairs = False  # whether it moves a decoupled pair's split point (both drones then move)

    def reset(self) -> None:  # noqa: B027 - stateless default
        """Start a new run."""

    @abstractmethod
    def solve(self, qp: StepQP) -> tuple[QPSolution, int]:
        """The solution ``[u | x | s]`` over ``qp.drones`` and the number of active rows."""
