"""Planning bounds: derived once from the user's limits, tightened by the tube, naming the user's keys."""

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.world.bounds import planning_bounds
from mpcform.world.limits import DEFAULT_A_MAX_MPS2, Limits
from mpcform.world.shapes import Box, SphereObstacle


def test_the_bounds_inflate_separation_obstacles_and_the_fence_by_the_tube():
    lim = Limits(1.0, 0.5, geofence_min_m=[-5.0, -5.0], geofence_max_m=[5.0, 5.0])
    obstacles = (SphereObstacle([1.0, 0.0], 0.5, clearance_m=0.25), Box([3.0, 0.0], [1.0, 1.0], 0.1))
    same, kept_obstacles = planning_bounds(lim, obstacles)
    assert (same.d_min_m, same.tube_m, same.limits) == (0.5, 0.0, lim)  # the ideal plant: as given
    assert [o.to_keys() for o in kept_obstacles] == [o.to_keys() for o in obstacles]
    planned, inflated = planning_bounds(lim, obstacles, 0.05, 2.0)
    assert planned.d_min_m == pytest.approx(0.6) and planned.a_max_mps2 == 2.0 and planned.v_max_mps == 1.0
    np.testing.assert_allclose(planned.geofence_min_m, [-4.9, -4.9])
    np.testing.assert_allclose(planned.geofence_max_m, [4.9, 4.9])
    assert [o.clearance_m for o in inflated] == pytest.approx([0.25 + 0.1, 0.1 + 0.1])
    assert isinstance(inflated[1], Box)  # every kind grows by its clearance
    kept = planning_bounds(Limits(1.0, 0.5, a_max_mps2=1.0), (), 0.05, 2.0)[0]
    assert kept.a_max_mps2 == 1.0  # a declared a_max stays
    grown = planning_bounds(lim, obstacles, 0.05, 2.0, 0.01)[0]
    assert grown.growth_m == 0.01 and grown.d_min_m == planned.d_min_m  # the rows grow, not d_min


def test_the_tracking_allowance_adds_twice_between_drones_and_once_to_obstacles_and_the_fence():
    lim = Limits(1.0, 0.5, geofence_min_m=[-5.0, -5.0], geofence_max_m=[5.0, 5.0], tracking_m=0.05)
    obstacles = (SphereObstacle([1.0, 0.0], 0.5, clearance_m=0.25),)
    planned, inflated = planning_bounds(lim, obstacles, 0.02, None)
    assert planned.d_min_m == pytest.approx(0.5 + 2 * (0.02 + 0.05)) and planned.tube_m == pytest.approx(0.07)
    np.testing.assert_allclose(planned.geofence_max_m, [5.0 - 0.04 - 0.05] * 2)
    assert inflated[0].clearance_m == pytest.approx(0.25 + 0.04 + 0.05)
    assert planned.limits.tracking_m == 0.05  # the user's limits, as given


def test_a_max_unset_takes_the_plant_s_then_the_platform_s_and_inf_turns_it_off():
    assert planning_bounds(Limits(1.0))[0].a_max_mps2 == DEFAULT_A_MAX_MPS2
    assert DEFAULT_A_MAX_MPS2 == pytest.approx(0.5 * 9.81 * np.tan(np.radians(20)))
    assert planning_bounds(Limits(1.0), (), 0.01, 0.9)[0].a_max_mps2 == 0.9  # the plant's bound
    assert planning_bounds(Limits(1.0, a_max_mps2=np.inf))[0].a_max_mps2 is None
    assert planning_bounds(Limits(1.0, a_max_mps2=0.7))[0].a_max_mps2 == 0.7
    with pytest.raises(ValidationError, match="limits.a_max"):
        Limits(1.0, a_max_mps2=-np.inf)


@pytest.mark.parametrize(
    ("args", "field"),
    [((np.inf,), "plant.margin"), ((-0.01,), "plant.margin"), ((0.05, None, np.inf), "plant.margin_growth")],
)
def test_a_bad_derived_bound_names_the_users_key(args, field):
    with pytest.raises(ValidationError, match=rf"^{field}:"):
        planning_bounds(Limits(1.0, 0.5), (), *args)


def test_the_bounds_need_resolved_clearances_and_user_limits():
    with pytest.raises(ValidationError, match=r"obstacles\[0\]\.clearance"):
        planning_bounds(Limits(1.0, 0.5), (SphereObstacle([1.0, 0.0], 0.5),), 0.05, 2.0)
    with pytest.raises(ValidationError, match="limits: expected mpcform.Limits"):
        planning_bounds({"v_max": 1.0})  # type: ignore[arg-type]


def test_a_vertical_speed_bound_is_kept() -> None:
    lim = Limits(v_max_mps=1.0, d_min_m=0.5, v_max_z_mps=0.7, tracking_m=0.05)
    assert planning_bounds(lim, (), 0.01, None)[0].v_max_z_mps == 0.7
