"""What one planner step did: the MPC's step record (:class:`MPCStepInfo`)."""

from __future__ import annotations

from dataclasses import dataclass

from mpcform._validate import Array
from mpcform.control.base import StepInfo
from mpcform.mpc.liveness import TieBreak
from mpcform.solvers.base import QPSolution


@dataclass(frozen=True)
class MPCStepInfo(StepInfo):
    """A planner step: the generic record (``mode`` ``fast_path`` | ``qp`` | ``fallback``, solver
    ``status``) and the solve's figures: ``iterations``, ``solve_time_s`` [s] (wall time inside
    the backend's calls of the step: every setup, update and solve, per drone or sparse), ``active_rows``,
    ``max_slack_m`` [m] with ``slack_pairs``, the drone pairs (or ``(drone, -1 - obstacle)``)
    whose separation rows needed slack, and ``qp_drones``, how many drones the QP was solved for
    (the others' groups took the fast path). Liveness (:mod:`mpcform.mpc.liveness`): ``stalled``
    drones that started to stall at this step, ``resolving`` drones whose tie-break is escalated,
    ``resolved`` escalations that ended at this step (the drone left conflict), ``unwound``
    circling drones whose escalation was reset at this step. ``lowered``: with a
    velocity loop, whether a first separation row within reach was lowered to what braking reaches
    (:func:`mpcform.mpc.safety.first_rows.hard_first_rows`). ``growth_slack_m`` [m]: in wind, how far the
    plan reaches into its rows' growth along the horizon while keeping every required distance (a
    buffer for the next steps, :func:`mpcform.mpc.safety.slack.slack_report`; not slack).
    ``wind_shift_m`` [m]: in wind, how far the wind moved the previous plan within the growth's
    window, and ``growth_exceeded``: farther than the growth per step, its premise
    (:mod:`mpcform.mpc.safety.premise`).
    ``deadline_missed``: the step ended past its deadline (``MPCSettings.step_budget_s``): its
    command, certified as any, was sent late. ``budget_cut``: the wall clock stopped the step's
    optional work (split rounds) before its count, so the plan may depend on the machine's load
    (:data:`mpcform.mpc.solve.problem.BUDGET_CUT`)."""

    iterations: int = 0
    solve_time_s: float = 0.0
    active_rows: int = 0
    max_slack_m: float = 0.0
    slack_pairs: tuple[tuple[int, int], ...] = ()
    qp_drones: int = 0
    stalled: int = 0
    resolving: int = 0
    resolved: int = 0
    unwound: int = 0
    lowered: bool = False
    growth_slack_m: float = 0.0
    wind_shift_m: float = 0.0
    growth_exceeded: bool = False
    deadline_missed: bool = False
    budget_cut: bool = False


FAST_PATH = MPCStepInfo("fast_path")
"""A fast-path step that ends no escalation (frozen: shared)."""


def pairs_of(labels: Array) -> tuple[tuple[int, int], ...]:
    """Item labels (m, 2) as sorted unique tuples."""
    return tuple(sorted({(int(a), int(b)) for a, b in labels}))


def solve_info(
    mode: str,
    sol: QPSolution,
    status: str,
    active: int,
    qp_drones: int,
    slack_m: float,
    slack_items: Array,
    tie_break: TieBreak,
    lowered: bool = False,
) -> MPCStepInfo:
    """The record of a step that called the solver (``mode`` ``qp`` or ``fallback``): the solve's
    figures, the slack ``slack_m`` [m] its items ``slack_items`` (m, 2) needed, and the tie-break's
    events of this step."""
    return MPCStepInfo(
        mode,
        status=status,
        iterations=sol.iterations,
        solve_time_s=sol.solve_time_s,
        active_rows=active,
        max_slack_m=slack_m,
        slack_pairs=pairs_of(slack_items),
        qp_drones=int(qp_drones),
        stalled=tie_break.new_stalls,
        resolving=tie_break.resolving,
        resolved=tie_break.resolved,
        unwound=tie_break.unwound,
        lowered=lowered,
    )
