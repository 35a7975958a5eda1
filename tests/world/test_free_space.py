"""The free-space regions: closed rings and plugged corridors separate, gaps a drone fits through
do not, however coarse the grid."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.world.free_space import FreeSpace
from mpcform.world.shapes import SphereObstacle


def ring(radius: float, count: int = 8) -> tuple[SphereObstacle, ...]:
    """``count`` discs of ``radius`` (clearance 0.25 m) on a circle of 2 m around the origin."""
    angles = np.linspace(0.0, 2.0 * np.pi, count + 1)[:-1]
    return tuple(SphereObstacle(2.0 * np.array([np.cos(a), np.sin(a)]), radius, 0.25) for a in angles)


def test_a_closed_ring_separates_its_pocket_and_names_every_disc() -> None:
    points = np.array([[0.0, 0.0], [5.0, 0.0]])
    space = FreeSpace(ring(0.6), None, None, points)  # neighbours 1.53 m apart, 1.7 m keep-out
    inside, outside = space.region(points)
    assert inside > 0 and outside > 0 and inside != outside
    assert space.walls(int(inside), int(outside)) == (list(range(8)), False)


@pytest.mark.parametrize("gap_m", [1e-3, 0.05])
def test_a_gap_the_drone_fits_through_is_open_on_any_grid(gap_m: float) -> None:
    """Two keep-outs of 1 m (radius 0.8 m + clearance 0.2 m) across a corridor |y| <= 2 m whose
    only passage is ``gap_m`` wide: the grid's cells are far coarser, and it stays open."""
    half = 1.0 + 0.5 * gap_m
    obstacles = (
        SphereObstacle(np.array([0.0, -half]), 0.8, 0.2),
        SphereObstacle(np.array([0.0, half]), 0.8, 0.2),
    )
    lo, hi = np.array([-6.0, -2.0]), np.array([6.0, 2.0])
    points = np.array([[-5.0, 0.0], [5.0, 0.0]])
    space = FreeSpace(obstacles, lo, hi, points)
    a, b = space.region(points)
    assert a == b > 0
    closed = FreeSpace((SphereObstacle(np.zeros(2), 2.2, 0.2),), lo, hi, points)  # a plug 0.4 m wider
    a, b = closed.region(points)
    assert a != b and closed.walls(int(a), int(b)) == ([0], True)


def test_a_sphere_plugging_a_spatial_corridor_separates_its_ends_and_open_space_does_not() -> None:
    lo, hi = np.array([-5.0, -0.5, 0.5]), np.array([5.0, 0.5, 1.5])
    plug = (SphereObstacle(np.array([0.0, 0.0, 1.0]), 0.6, 0.2),)
    points = np.array([[-4.0, 0.0, 1.0], [4.0, 0.0, 1.0]])
    a, b = FreeSpace(plug, lo, hi, points).region(points)
    assert a != b
    a, b = FreeSpace(plug, None, None, points).region(points)  # no fence: around it
    assert a == b > 0


def test_points_inside_a_keep_out_are_in_no_region_and_name_their_sphere() -> None:
    space = FreeSpace(ring(0.6), None, None, np.array([[0.0, 0.0]]))
    centre = np.array([[2.0, 0.0]])
    assert space.region(centre)[0] == 0 and space.blocker(centre)[0] == 0


def test_the_grid_stays_within_its_cell_budget() -> None:
    from mpcform.world.free_space import MAX_CELLS

    far = np.array([[-1000.0, 0.0, 0.0], [1000.0, 3.0, 1.0]])
    space = FreeSpace((SphereObstacle(np.zeros(3), 1.0, 0.1),), None, None, far)
    assert space.labels.size <= MAX_CELLS
