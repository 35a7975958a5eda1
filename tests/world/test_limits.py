"""Limits: accepted values are stored, bad ones name their field."""

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.world.limits import Limits, crazyswarm_downwash


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


def test_crazyswarm_downwash_keeps_its_ellipsoid() -> None:
    assert crazyswarm_downwash(0.24) == pytest.approx(2.5)  # the ellipsoid itself: 0.24 / 0.6 m
    assert crazyswarm_downwash(0.5) == pytest.approx(1.2)
    assert crazyswarm_downwash(0.8) == 1.0  # the sphere already holds 0.6 m vertically
    with pytest.raises(ValidationError, match="expected d_min >= 0.24 m"):
        crazyswarm_downwash(0.2)


def test_a_vertical_speed_bound_is_validated() -> None:
    with pytest.raises(ValidationError, match="limits.v_max_z"):
        Limits(v_max_mps=1.0, v_max_z_mps=0.0)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"v_max_mps": "1"}, "limits.v_max"),
        ({"d_min_m": True}, "limits.d_min"),
        ({"tracking_m": 1j}, "limits.tracking"),
    ],
)
def test_limits_take_numbers_not_what_could_be_coerced_to_them(kwargs, field) -> None:
    with pytest.raises(ValidationError, match=rf"{field}: expected a number"):
        Limits(**kwargs)
