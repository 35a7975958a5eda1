"""Keyframes, explicit DOF-group limits and the speed budget: validation and derived values."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.formation.rotation import rotation_matrix
from mpcform.formation.template import Template
from mpcform.reference.keyframes import (
    JERK_TIME_S,
    RISE_TIME_S,
    Keyframe,
    MissionLimits,
    SpeedBudget,
    as_keyframe,
    centroid_of,
    rotation_of,
)


def test_keyframes_keep_unset_fields_and_freeze_arrays() -> None:
    kf = Keyframe(centroid_m=[1, 2, 3], rotation=0.5, hold_s=2)
    assert kf.scale is None and kf.template is None and kf.hold_s == 2.0
    assert kf.centroid_m is not None and kf.centroid_m.dtype == float
    with pytest.raises(ValueError, match="read-only"):
        kf.centroid_m[0] = 0.0


def test_limits_are_read_only_tables_with_inf_for_missing_groups() -> None:
    limits = MissionLimits({"scale": 2}, max_jerk={"rotation": 3.0})
    assert limits.get(0, "scale") == 2.0 and limits.get(2, "rotation") == 3.0
    assert limits.get(1, "scale") == np.inf and limits.get(0, "centroid") == np.inf
    with pytest.raises(TypeError):
        limits.max_velocity["scale"] = 5.0  # type: ignore[index]


def test_speed_budget_defaults_and_overrides() -> None:
    v, a, j = SpeedBudget(3.0).budgets
    assert v == 0.8 * 3.0 and a == v / RISE_TIME_S and j == a / JERK_TIME_S
    assert SpeedBudget(3.0, 0.5, 0.25, 4.0).budgets == (1.5, 0.25, 4.0)
    assert SpeedBudget(3.0, 1.0, 0.25).budgets == (3.0, 0.25, 0.25 / JERK_TIME_S)


def test_tables_become_keyframes_and_errors_name_the_keyframe() -> None:
    kf = Keyframe(scale=2.0)
    assert as_keyframe(kf, 0) is kf
    assert as_keyframe({"scale": 2.0, "hold_s": 1.0}, 4).hold_s == 1.0
    with pytest.raises(ValidationError, match=r"reference\.keyframes\[4\]\.scale: expected"):
        as_keyframe({"scale": -1.0}, 4)
    with pytest.raises(ValidationError, match=r"reference\.keyframes\[1\]: bad keyframe fields \['spin'\]"):
        as_keyframe({"spin": 1.0}, 1)
    with pytest.raises(ValidationError, match=r"reference\.keyframes\[2\]: expected a Keyframe"):
        as_keyframe([1.0], 2)  # type: ignore[arg-type]


def test_centroids_and_rotations_are_checked_against_the_dimension() -> None:
    c = np.array([1.0, 2.0])
    assert centroid_of(c, 2, "here") is c
    with pytest.raises(ValidationError, match="here: expected 3 numbers .*spatial.*got 2"):
        centroid_of(c, 3, "here")
    np.testing.assert_array_equal(rotation_of(np.array(0.3), 2, "rot"), rotation_matrix(2, 0.3))
    np.testing.assert_array_equal(
        rotation_of(np.array([0.0, 0.2, 0.0]), 3, "rot"), rotation_matrix(3, [0, 0.2, 0])
    )
    with pytest.raises(ValidationError, match=r"rot: expected an angle \[rad\] \(planar\)"):
        rotation_of(np.zeros(3), 2, "rot")
    with pytest.raises(ValidationError, match=r"rot: expected a rotation vector"):
        rotation_of(np.array(0.3), 3, "rot")
    with pytest.raises(ValidationError, match="rot"):
        rotation_of(np.array([1e300, 0.0, 0.0]), 3, "rot")  # NaN matrix: rejected, no warning


@pytest.mark.parametrize(
    ("build", "field"),
    [
        (lambda: MissionLimits({"scale": 0.0}), r"reference\.max_velocity\.scale"),
        (lambda: MissionLimits(max_jerk={"rotation": -1.0}), r"reference\.max_jerk\.rotation"),
        (lambda: MissionLimits(max_acceleration={"blend": np.inf}), r"reference\.max_acceleration\.blend"),
        (lambda: MissionLimits({"spin": 1.0}), r"reference\.max_velocity\.spin: unknown DOF group"),
        (lambda: MissionLimits({"scale": True}), r"reference\.max_velocity\.scale"),
        (lambda: MissionLimits(max_velocity=1.0), r"reference\.max_velocity: expected a table"),
        (lambda: SpeedBudget(0.0), r"limits\.v_max"),
        (lambda: SpeedBudget(2.0, 1.5), r"reference\.speed_fraction"),
        (lambda: SpeedBudget(2.0, 0.8, -1.0), r"reference\.drone_acceleration"),
        (lambda: SpeedBudget(2.0, 0.8, 1.0, np.nan), r"reference\.drone_jerk"),
        (lambda: Keyframe(centroid_m=[np.nan, 0.0]), r"keyframe\.centroid"),
        (lambda: Keyframe(centroid_m=[1.0, 2.0, 3.0, 4.0]), r"keyframe\.centroid: expected 2 or 3"),
        (lambda: Keyframe(rotation=[[0.0]]), r"keyframe\.rotation"),
        (lambda: Keyframe(template="line"), r"keyframe\.template: expected a Template"),
    ],
)
def test_bad_limits_and_keyframes_raise_validation_errors(build: Any, field: str) -> None:
    with pytest.raises(ValidationError, match=field):
        build()


def test_keyframe_templates_are_kept() -> None:
    line = Template.line(4, 1.0)
    assert Keyframe(template=line).template is line
