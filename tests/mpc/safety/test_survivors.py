"""Stop planning for lost drones (mpcform.mpc.safety.survivors, MPCPlanner.lose)."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.formation.geometry import min_segment_distance
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.safety.survivors import EVERY_DRONE_LOST, Survivors, lost_spheres, split_lost
from mpcform.mpc.settings import MPCSettings
from mpcform.reference.base import ConstantReference
from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle

DT, D_MIN, V_MAX = 0.1, 0.5, 1.0


def _planner(n: int = 6, coupling: str = "joint", obstacles: tuple = ()) -> tuple[MPCPlanner, np.ndarray]:
    """An antipodal swap on a ring of radius 2 (the planner's default a_max)."""
    tpl = Template.polygon(n, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0]))
    limits = Limits(v_max_mps=V_MAX, d_min_m=D_MIN)
    planner = MPCPlanner(ref, DT, limits, MPCSettings(coupling=coupling), obstacles)
    return planner, -tpl.offsets.copy()


def _fly(planner, p: np.ndarray, steps: int, lose_at: dict[int, list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Exact single integrator; at step k the drones ``lose_at[k]`` are lost (they stop moving)."""
    ctrl, pos, cmd = planner, [p.copy()], []
    planner.reset(0.0, p)
    for k in range(steps):
        if k in lose_at:
            ctrl = ctrl.lose(lose_at[k], p)
        u = ctrl.step(k * DT, p).command_mps
        p = p + DT * u
        pos.append(p.copy())
        cmd.append(u)
    return np.array(pos), np.array(cmd)


@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
def test_the_others_avoid_a_lost_drone_and_arrive(coupling: str) -> None:
    planner, p0 = _planner(coupling=coupling)
    pos, cmd = _fly(planner, p0, 300, {18: [0]})
    assert np.all(cmd[18:, 0] == 0.0)  # drone 0 is commanded zero once lost
    assert np.all(pos[19:, 0] == pos[18, 0]) and np.linalg.norm(pos[18, 0]) < 1.0  # lost mid-swap
    seg = min(min_segment_distance(a, b) for a, b in zip(pos[:-1], pos[1:], strict=True))
    assert seg >= D_MIN - 1e-6  # every pair, the lost drone included, along every segment
    assert np.abs(np.diff(cmd[:, 1:], axis=0)).max() <= planner.limits.a_max_mps2 * DT + 1e-9  # no jump
    assert np.linalg.norm(cmd, axis=-1).max() <= V_MAX * (1 + 1e-12)
    goal = -p0
    np.testing.assert_allclose(pos[-1, 1:], goal[1:], atol=0.05)  # the others complete


def test_losses_nest_and_records_name_drones_in_the_swarms_numbering() -> None:
    obstacle = SphereObstacle(np.array([0.0, 5.0]), 0.3)
    planner, p0 = _planner(obstacles=(obstacle,))
    p = p0 * 0.5
    first = planner.lose([4, 1], p)
    assert isinstance(first, Survivors) and first.lost_drones.tolist() == [1, 4]
    assert first.keep.tolist() == [0, 2, 3, 5] and len(first.inner.obstacles) == 3
    second = first.lose([2, 4], p)  # 4 is lost already
    assert second.lost_drones.tolist() == [1, 2, 4] and first.lost_drones.tolist() == [1, 4]
    assert second.lose([], p) is second and planner.lose([], p) is planner
    # inner labels: (drone, -1 - obstacle); obstacle 0 is the scenario's, 1 and 2 the lost drones 1, 4
    assert first._label(0, -1) == (0, -1)
    assert first._label(1, -2) == (1, 2) and first._label(3, -3) == (4, 5)
    assert first._label(0, 2) == (0, 3)
    nothing = second.lose([0, 3, 5], p)
    out = nothing.step(0.0, p)
    assert out.info is EVERY_DRONE_LOST and np.all(out.command_mps == 0.0)
    assert nothing.lost_drones.tolist() == list(range(6))


def test_a_planner_without_d_min_needs_no_spheres_and_bad_ids_are_refused() -> None:
    assert lost_spheres(np.zeros((2, 2)), None) == ()
    (a, b) = lost_spheres(np.array([[1.0, 0.0], [0.0, 2.0]]), 0.6)
    assert a.radius_m == a.clearance_m == 0.3 and np.array_equal(b.center_m, [0.0, 2.0])
    lost, keep = split_lost([3, 1, 3], 5)
    assert lost.tolist() == [1, 3] and keep.tolist() == [0, 2, 4]
    planner, p0 = _planner()
    for bad in ([6], [-1]):
        with pytest.raises(ValidationError, match=r"drones: expected drone indices in 0\.\.5"):
            planner.lose(bad, p0)
        with pytest.raises(ValidationError, match=r"drones: expected drone indices in 0\.\.5"):
            planner.lose([1], p0).lose(bad, p0)  # in the swarm's numbering, not the survivors'
    with pytest.raises(ValidationError, match="positions"):
        planner.lose([1], p0).lose([2], p0[:3])
