"""Completion: drones at the reference's final value, when, and which stalled (any controller)."""

import numpy as np
import pytest

from mpcform.sim.completion import STALL_WINDOW_S, completion_metrics
from mpcform.sim.trajectory import Trajectory


def line_run(final: list[float], t_end: float = 10.0) -> Trajectory:
    """Two planar drones sampled at 1 s: drone 0 arrives at t = 4 s, drone 1 ends at ``final``."""
    t = np.arange(0.0, t_end + 0.5, 1.0)
    p = np.zeros((t.size, 2, 2))
    p[:, 0, 0] = np.minimum(t, 4.0)
    p[:, 1, 0] = np.interp(t, [0.0, t_end], [0.0, final[0]])
    p[:, 1, 1] = final[1]
    ref = np.zeros_like(p)
    ref[:, 0, 0], ref[:, 1, 0] = 4.0, 4.0
    return Trajectory(t, p, np.zeros((t.size - 1, 2, 2)), ref)


def test_complete_run_says_when() -> None:
    m = completion_metrics(line_run([4.0, 0.0]))
    assert m == {
        "completion": 1.0,
        "incomplete_drones": [],
        "incomplete_distances_m": [],
        "stalled_drones": 0,
        "time_to_complete": 10.0,
    }
    m = completion_metrics(line_run([4.05, 0.0]), tol_m=0.1)
    assert m["completion"] == 1.0 and m["time_to_complete"] == pytest.approx(10.0)


def test_short_drone_is_incomplete_and_stalled_only_if_it_stopped() -> None:
    moving = completion_metrics(line_run([3.0, 0.0]))  # still moving 0.3 m/s at the end
    assert moving == {
        "completion": 0.5,
        "incomplete_drones": [1],
        "incomplete_distances_m": [1.0],
        "stalled_drones": 0,
        "time_to_complete": None,
    }
    run = line_run([3.0, 0.0])
    p = run.positions_m.copy()
    p[-int(STALL_WINDOW_S) - 1 :, 1] = p[-1, 1]  # held still over the last window
    stuck = completion_metrics(Trajectory(run.t_s, p, run.commands_mps, run.reference_m))
    assert stuck["incomplete_drones"] == [1] and stuck["stalled_drones"] == 1


def test_a_goal_after_the_run_is_what_completion_counts() -> None:
    """A mission cut short by ``duration``: the drones at the reference's value at the run's end
    are not at its final targets."""
    t = np.linspace(0.0, 1.0, 11)
    p = np.zeros((11, 2, 2))
    traj = Trajectory(t, p, np.zeros((10, 2, 2)), p.copy())
    assert completion_metrics(traj)["completion"] == 1.0
    goal = np.array([[5.0, 0.0], [0.0, 0.05]])
    got = completion_metrics(traj, goal_m=goal)
    assert got["completion"] == 0.5 and got["time_to_complete"] is None
