"""The controller interface: feedforward targets and the check of measured positions."""

import numpy as np
import pytest

from mpcform.control.base import Controller, ControlStep, StepInfo, feedforward_targets
from mpcform.errors import ValidationError
from mpcform.formation.kinematics import drone_velocities, forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.base import ExponentialReference

DT = 0.02


def spinning_reference(dim):
    tpl = Template.polygon(4, 1.5, dim=dim)
    rot = (0.2, 1.7) if dim == 2 else ([0.0, 0.0, 0.2], [0.4, -0.3, 1.0])
    start = FormationState.from_param(np.ones(dim), rot[0], 1.0)
    goal = FormationState.from_param(-np.ones(dim), rot[1], 1.5)
    return ExponentialReference(tpl, start, goal, 0.7)


class Hold(Controller):
    """The smallest controller: zero commands after checking the positions."""

    name = "hold"

    def __init__(self, reference):
        self.reference, self.dt_s = reference, DT

    def step(self, t_s, positions_m):
        return ControlStep(np.zeros_like(self._check_positions(positions_m)), StepInfo("law"))


def test_feedforward_targets_shapes():
    ref = spinning_reference(3)
    for kind in ("jacobian", "secant"):
        pos, ff = feedforward_targets(ref, 0.0, DT, 5, kind)
        assert pos.shape == (6, 4, 3) and ff.shape == (5, 4, 3)
        np.testing.assert_allclose(pos[0], forward_kinematics(ref.template, ref.state(0.0)))


def test_feedforward_targets_are_the_jacobian_or_the_secant():
    ref, t = spinning_reference(2), 0.3
    pos, jac = feedforward_targets(ref, t, DT, 3, "jacobian")
    _, sec = feedforward_targets(ref, t, DT, 3, "secant")
    for j in range(3):
        tj = t + j * DT
        np.testing.assert_allclose(pos[j], forward_kinematics(ref.template, ref.state(tj)), atol=1e-12)
        np.testing.assert_allclose(jac[j], drone_velocities(ref.template, ref.state(tj), ref.velocity(tj)))
    np.testing.assert_allclose(sec, np.diff(pos, axis=0) / DT)


def test_default_reset_is_stateless():
    ctrl = Hold(spinning_reference(2))
    ctrl.reset(0.0, np.zeros((4, 2)))
    np.testing.assert_array_equal(ctrl.step(0.0, np.ones((4, 2))).command_mps, 0.0)


@pytest.mark.parametrize("positions", [np.zeros((2, 2)), np.zeros((4, 3)), np.full((4, 2), np.nan)])
def test_step_rejects_bad_positions(positions):
    with pytest.raises(ValidationError, match="positions"):
        Hold(spinning_reference(2)).step(0.0, positions)
