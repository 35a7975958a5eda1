"""Limits: accepted values are stored, bad ones name their field; the tube tightens them."""

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.world.limits import DEFAULT_A_MAX_MPS2, Limits, crazyswarm_downwash, planning_limits, tightened
from mpcform.world.shapes import SphereObstacle


def test_limits_store_validated_values():
    lim = Limits(v_max_mps=3, d_min_m=0.5, geofence_min_m=[-1, -1, 0], geofence_max_m=[1, 1, np.inf])
    assert (lim.v_max_mps, lim.d_min_m, lim.a_max_mps2) == (3.0, 0.5, None)
    assert isinstance(lim.v_max_mps, float)
    np.testing.assert_array_equal(lim.geofence_max_m, [1.0, 1.0, np.inf])
    assert Limits(downwash_kappa=1.0).downwash_kappa == 1.0
    assert Limits().v_max_mps is None


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"v_max_mps": -1.0}, "limits.v_max"),
        ({"v_max_mps": 0.0}, "limits.v_max"),
        ({"v_max_mps": np.nan}, "limits.v_max"),
        ({"d_min_m": -0.5}, "limits.d_min"),
        ({"a_max_mps2": "fast"}, "limits.a_max"),
        ({"downwash_kappa": 0.5}, "limits.downwash"),
        ({"downwash_kappa": -2.0}, "limits.downwash"),
        ({"geofence_min_m": [0.0, 0.0]}, "limits.geofence"),
        ({"geofence_min_m": [0.0, 0.0], "geofence_max_m": [1.0, 0.0]}, "limits.geofence"),
        ({"geofence_min_m": [2.0, 0.0], "geofence_max_m": [1.0, 1.0]}, "limits.geofence"),
        ({"geofence_min_m": [0.0, 0.0], "geofence_max_m": [1.0, 1.0, 1.0]}, "limits.geofence"),
        ({"geofence_min_m": [0.0, np.nan], "geofence_max_m": [1.0, 1.0]}, "limits.geofence_min"),
        ({"geofence_min_m": [[0.0]], "geofence_max_m": [[1.0]]}, "limits.geofence_min"),
    ],
)
def test_bad_limits_are_rejected(kwargs, match):
    with pytest.raises(ValidationError, match=match):
        Limits(**kwargs)


def test_tightened_limits_inflate_separation_obstacles_and_the_fence_by_the_tube():

    lim = Limits(1.0, 0.5, geofence_min_m=[-5.0, -5.0], geofence_max_m=[5.0, 5.0])
    obstacles = (SphereObstacle([1.0, 0.0], 0.5, clearance_m=0.25), SphereObstacle([3.0, 0.0], 0.5, 0.1))
    same = tightened(lim, obstacles, 0.0, None)
    assert same[0] is lim and same[1] is obstacles  # the ideal plant: the very same objects
    planned, inflated = tightened(lim, obstacles, 0.05, 2.0)
    assert planned.d_min_m == pytest.approx(0.6) and planned.a_max_mps2 == 2.0 and planned.v_max_mps == 1.0
    np.testing.assert_allclose(planned.geofence_min_m, [-4.9, -4.9])
    np.testing.assert_allclose(planned.geofence_max_m, [4.9, 4.9])
    assert [o.clearance_m for o in inflated] == pytest.approx([0.25 + 0.1, 0.1 + 0.1])
    kept = tightened(Limits(1.0, 0.5, a_max_mps2=1.0), (), 0.05, 2.0)[0]
    assert kept.a_max_mps2 == 1.0  # a declared a_max stays
    grown = tightened(lim, obstacles, 0.05, 2.0, 0.01)[0]
    assert grown.tube_growth_m == 0.01 and grown.d_min_m == planned.d_min_m  # the rows grow, not d_min
    assert tightened(grown, (), 0.0, None)[0].tube_growth_m == 0.01  # kept when tightened again
    with pytest.raises(ValidationError, match="limits.tube_growth"):
        tightened(lim, obstacles, 0.05, 2.0, -0.01)


def test_the_tracking_allowance_adds_twice_between_drones_and_once_to_obstacles_and_the_fence():
    lim = Limits(1.0, 0.5, geofence_min_m=[-5.0, -5.0], geofence_max_m=[5.0, 5.0], tracking_m=0.05)
    obstacles = (SphereObstacle([1.0, 0.0], 0.5, clearance_m=0.25),)
    planned, inflated = tightened(lim, obstacles, 0.02, None)
    assert planned.d_min_m == pytest.approx(0.5 + 2 * (0.02 + 0.05)) and planned.tube_m == pytest.approx(0.07)
    np.testing.assert_allclose(planned.geofence_max_m, [5.0 - 0.04 - 0.05] * 2)
    assert inflated[0].clearance_m == pytest.approx(0.25 + 0.04 + 0.05)
    assert planned.tracking_m == 0.0 and tightened(planned, inflated, 0.0, None)[0] is planned  # applied once


def test_planning_limits_take_the_platform_a_max_and_inf_turns_it_off():
    assert (
        planning_limits(Limits(1.0)).a_max_mps2
        == DEFAULT_A_MAX_MPS2
        == pytest.approx(0.5 * 9.81 * np.tan(np.radians(20)))
    )
    assert planning_limits(Limits(1.0, a_max_mps2=np.inf)).a_max_mps2 is None
    assert planning_limits(Limits(1.0, a_max_mps2=0.7)).a_max_mps2 == 0.7
    with pytest.raises(ValidationError, match="limits.a_max"):
        Limits(1.0, a_max_mps2=-np.inf)


def test_tightened_needs_resolved_clearances():
    with pytest.raises(ValidationError, match=r"obstacles\[0\]\.clearance"):
        tightened(Limits(1.0, 0.5), (SphereObstacle([1.0, 0.0], 0.5),), 0.05, 2.0)


def test_crazyswarm_downwash_keeps_its_ellipsoid() -> None:
    assert crazyswarm_downwash(0.24) == pytest.approx(2.5)  # the ellipsoid itself: 0.24 / 0.6 m
    assert crazyswarm_downwash(0.5) == pytest.approx(1.2)
    assert crazyswarm_downwash(0.8) == 1.0  # the sphere already holds 0.6 m vertically
    with pytest.raises(ValidationError, match="expected d_min >= 0.24 m"):
        crazyswarm_downwash(0.2)


def test_a_vertical_speed_bound_is_validated_and_kept_when_tightened() -> None:
    with pytest.raises(ValidationError, match="limits.v_max_z"):
        Limits(v_max_mps=1.0, v_max_z_mps=0.0)
    lim = Limits(v_max_mps=1.0, d_min_m=0.5, v_max_z_mps=0.7, tracking_m=0.05)
    assert tightened(lim, (), 0.01, None)[0].v_max_z_mps == 0.7
