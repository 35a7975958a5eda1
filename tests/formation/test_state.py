"""Formation state xi = (c, R, s): construction, immutability and validation."""

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.formation.rotation import rotation_matrix
from mpcform.formation.state import FormationState


def test_from_param_planar():
    state = FormationState.from_param([1.0, 2.0], 0.5, 2.0)
    assert state.dim == 2 and state.scale == 2.0
    np.testing.assert_array_equal(state.centroid_m, [1.0, 2.0])
    np.testing.assert_allclose(state.rotation_body_to_world, rotation_matrix(2, 0.5))
    assert float(state.rotation_param) == pytest.approx(0.5)


def test_from_param_spatial_defaults_to_identity():
    state = FormationState.from_param([1.0, 2.0, 3.0])
    assert state.dim == 3 and state.scale == 1.0
    np.testing.assert_array_equal(state.rotation_body_to_world, np.eye(3))
    np.testing.assert_allclose(
        FormationState.from_param([0, 0, 0], [0.0, 0.0, 0.4]).rotation_param, [0.0, 0.0, 0.4]
    )


def test_arrays_are_read_only_copies():
    centroid = np.array([1.0, 2.0])
    state = FormationState(centroid, np.eye(2), 1.0)
    centroid[0] = 9.0
    assert state.centroid_m[0] == 1.0
    with pytest.raises(ValueError):
        state.rotation_body_to_world[0, 0] = 2.0
    with pytest.raises(AttributeError):
        state.scale = 3.0


def test_repr_names_the_fields():
    text = repr(FormationState.from_param([5.0, 5.0], 0.25, 1.5))
    assert "centroid_m=[5.0, 5.0]" in text and "rotation=0.25" in text and "scale=1.5" in text


@pytest.mark.parametrize(
    ("centroid", "rotation", "scale", "match"),
    [
        ([0.0, 0.0], np.eye(2), 0.0, "state.scale"),
        ([0.0, 0.0], np.eye(2), -1.0, "state.scale"),
        ([0.0, 0.0], np.eye(2), np.nan, "state.scale"),
        ([0.0, np.nan], np.eye(2), 1.0, "state.centroid"),
        ([0.0], np.eye(2), 1.0, "state.centroid"),
        ([0.0, 0.0, 0.0, 0.0], np.eye(2), 1.0, "state.centroid"),
        ([[0.0, 0.0]], np.eye(2), 1.0, "state.centroid"),
        ([0.0, 0.0], np.eye(3), 1.0, "state.rotation"),
        ([0.0, 0.0], np.diag([1.0, -1.0]), 1.0, "state.rotation"),
        ([0.0, 0.0, 0.0], np.diag([-1.0, -1.0, -1.0]), 1.0, "state.rotation"),
        ([0.0, 0.0, 0.0], 2.0 * np.eye(3), 1.0, "state.rotation"),
        ([0.0, 0.0, 0.0], np.full((3, 3), np.nan), 1.0, "state.rotation"),
    ],
)
def test_bad_states_are_rejected(centroid, rotation, scale, match):
    with pytest.raises(ValidationError, match=match):
        FormationState(centroid, rotation, scale)


@pytest.mark.parametrize(
    ("centroid", "rotation", "match"),
    [([0.0, 0.0], [0.1, 0.2, 0.3], "state.rotation"), ([0.0, 0.0, 0.0], 0.3, "state.rotation")],
)
def test_from_param_rejects_mismatched_rotation(centroid, rotation, match):
    with pytest.raises(ValidationError, match=match):
        FormationState.from_param(centroid, rotation)
