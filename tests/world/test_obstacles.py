"""Obstacles: accepted values are stored, bad ones name their field; the clearance resolves once."""

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.reference.base import ConstantReference
from mpcform.world.limits import Limits
from mpcform.world.obstacles import require_resolved, resolve_clearances
from mpcform.world.shapes import SphereObstacle
from mpcform.world.shapes.shape_set import ShapeSet


def test_sphere_obstacle():
    obs = SphereObstacle([1.0, 2.0, 3.0], 0.5)
    np.testing.assert_array_equal(obs.center_m, [1.0, 2.0, 3.0])
    assert obs.radius_m == 0.5 and obs.clearance_m is None
    assert SphereObstacle([0.0, 0.0], 1.0, clearance_m=0.0).clearance_m == 0.0


def test_resolving_fills_in_half_of_d_min_once():
    obstacles = (SphereObstacle([1.0, 2.0], 0.5), SphereObstacle([3.0, 4.0], 1.0, clearance_m=0.1))
    resolved = resolve_clearances(obstacles, 0.6)
    assert [o.clearance_m for o in resolved] == [0.5 * 0.6, 0.1]  # unset clearance: half of d_min
    assert resolved[1] is obstacles[1]  # a set clearance: the same obstacle
    assert resolve_clearances(resolved, 2.0)[0] is resolved[0]  # resolving again changes nothing
    assert resolve_clearances(obstacles[:1], None)[0].clearance_m == 0.0  # no d_min: none
    assert resolved[0].required_distance_m == 0.5 + 0.5 * 0.6  # the same arithmetic as before


def test_a_shape_set_keeps_radius_plus_clearance_from_a_spheres_centre():
    obstacles = resolve_clearances(
        (SphereObstacle([1.0, 2.0], 0.5), SphereObstacle([3.0, 4.0], 1.0, clearance_m=0.1)), 0.6
    )
    shapes = ShapeSet(obstacles, 2)
    np.testing.assert_array_equal(shapes.centers_m, [[1.0, 2.0], [3.0, 4.0]])
    np.testing.assert_array_equal(shapes.required_m, [0.5 + 0.3, 1.0 + 0.1])
    assert ShapeSet((), 2).required_m.shape == (0,)


def test_consumers_refuse_unresolved_clearances():
    unset = SphereObstacle([1.0, 2.0], 0.5)
    with pytest.raises(ValidationError, match="obstacles.clearance"):
        ShapeSet((unset,), 2)
    with pytest.raises(ValidationError, match=r"obstacles\[1\]\.clearance"):
        require_resolved((unset.resolved(0.5), unset))
    assert require_resolved([unset.resolved(None)])[0].clearance_m == 0.0


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (([0.0, np.nan], 1.0), "obstacles.center"),
        (([[0.0, 0.0]], 1.0), "obstacles.center"),
        (([0.0, 0.0], 0.0), "obstacles.radius"),
        (([0.0, 0.0], 1.0, -0.1), "obstacles.clearance"),
    ],
)
def test_bad_obstacles_are_rejected(args, match):
    with pytest.raises(ValidationError, match=match):
        SphereObstacle(*args)


def test_the_python_entry_points_resolve_unset_clearances_as_the_loader_does():
    tpl = Template.polygon(3, radius=1.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0], 0.0, 1.0))
    unset = SphereObstacle([5.0, 0.0], 1.0)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.4), obstacles=(unset,))
    assert planner.obstacles[0].clearance_m == 0.5 * 0.4 and unset.clearance_m is None
