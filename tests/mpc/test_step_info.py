"""The planner's step record: a StepInfo with the solve's figures and the tie-break's events."""

from __future__ import annotations

import numpy as np

from mpcform.control.base import StepInfo
from mpcform.mpc.liveness import TieBreak
from mpcform.mpc.step_info import FAST_PATH, MPCStepInfo, pairs_of, solve_info
from mpcform.solvers.base import QPSolution


def test_the_record_is_a_step_info_with_quiet_defaults() -> None:
    assert isinstance(FAST_PATH, StepInfo) and FAST_PATH.mode == "fast_path"
    assert (FAST_PATH.max_slack_m, FAST_PATH.slack_pairs, FAST_PATH.stalled, FAST_PATH.qp_drones) == (
        0.0,
        (),
        0,
        0,
    )


def test_pairs_are_sorted_and_unique() -> None:
    assert pairs_of(np.array([[3, 1], [0, -1], [3, 1], [0, 2]])) == ((0, -1), (0, 2), (3, 1))
    assert pairs_of(np.zeros((0, 2), dtype=int)) == ()


def test_solve_info_takes_the_solution_and_the_tie_breaks_events() -> None:
    tb = TieBreak(4, 0.5, 0.1)
    tb.new_stalls, tb.resolved = 2, 1
    sol = QPSolution(np.zeros(3), None, True, "solved", 12, 0.004, 1.5)
    info = solve_info("qp", sol, "solved", 7, 3, 0.02, np.array([[1, 2]]), tb)
    assert isinstance(info, MPCStepInfo) and info.mode == "qp" and info.status == "solved"
    assert (info.iterations, info.solve_time_s, info.active_rows, info.qp_drones) == (12, 0.004, 7, 3)
    assert info.max_slack_m == 0.02 and info.slack_pairs == ((1, 2),)
    assert (info.stalled, info.resolving, info.resolved) == (2, tb.resolving, 1)
