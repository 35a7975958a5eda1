"""The world record: limits and obstacles, the obstacles' clearances resolved on construction."""

import numpy as np

from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle
from mpcform.world.world import World


def test_a_world_resolves_its_obstacles_against_its_d_min():
    world = World(
        Limits(d_min_m=0.5), [SphereObstacle(np.zeros(2), 1.0), SphereObstacle(np.ones(2), 1.0, 0.1)]
    )
    assert isinstance(world.obstacles, tuple)
    assert [o.clearance_m for o in world.obstacles] == [0.25, 0.1]
    assert World().obstacles == () and World().limits.d_min_m is None
    assert World(obstacles=(SphereObstacle(np.zeros(2), 1.0),)).obstacles[0].clearance_m == 0.0
