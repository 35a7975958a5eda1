"""Some drones of a formation reference (mpcform.reference.subset)."""

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.base import ExponentialReference
from mpcform.reference.subset import SubsetReference


def _reference() -> ExponentialReference:
    tpl = Template.polygon(5, 2.0)
    start = FormationState.from_param([0.0, 0.0])
    goal = FormationState.from_param([3.0, -1.0], 0.7, 1.3)
    return ExponentialReference(tpl, start, goal, 0.8)


def test_targets_are_the_parents_columns() -> None:
    parent = _reference()
    sub = SubsetReference(parent, [0, 2, 3])
    t = np.linspace(0.0, 4.0, 9)
    pos, vel = parent.targets(t)
    sub_pos, sub_vel = sub.targets(t)
    assert np.array_equal(sub_pos, pos[:, [0, 2, 3]]) and np.array_equal(sub_vel, vel[:, [0, 2, 3]])
    assert sub.template.n == 3 and sub.template.dim == 2
    np.testing.assert_allclose(sub.template.offsets.mean(axis=0), 0.0, atol=1e-15)
    np.testing.assert_array_equal(sub.start_positions_m(), parent.start_positions_m()[[0, 2, 3]])


@pytest.mark.parametrize("keep", [[], [2, 1], [0, 0], [-1], [5], [[0, 1]]])
def test_bad_drone_sets_are_refused(keep: list) -> None:
    with pytest.raises(ValidationError, match="drones"):
        SubsetReference(_reference(), keep)
