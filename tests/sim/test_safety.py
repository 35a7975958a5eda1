"""Safety measures along straight segments: separation, obstacles, geofence, downwash metric."""

import numpy as np
import pytest

from mpcform.sim.safety import (
    TOL_M,
    downwash_metric,
    geofence_violations,
    min_separation_along,
    obstacle_metrics,
    separation_violations,
)
from mpcform.world.limits import Limits
from mpcform.world.shapes import SphereObstacle


def crossing() -> np.ndarray:
    """Two drones swapping through each other's path at right angles: they pass 0 m apart at the
    middle of their only segment, while both samples keep them 2 sqrt(2) m apart."""
    return np.array([[[-2.0, 0.0], [0.0, -2.0]], [[2.0, 0.0], [0.0, 2.0]]])


def test_separation_along_segments_sees_what_samples_miss() -> None:
    path = crossing()
    assert min_separation_along(path) == pytest.approx(0.0, abs=1e-12)
    assert separation_violations(path, 0.5) == 0  # the samples alone look fine
    assert separation_violations(path[:1], np.sqrt(8.0) + 2 * TOL_M) == 1
    assert separation_violations(path[:1], np.sqrt(8.0) + 0.5 * TOL_M) == 0  # within tolerance


def test_obstacle_clearance_and_violations_along_segments() -> None:
    path = np.array([[[-3.0, 0.9]], [[3.0, 0.9]]])  # passes 0.9 m from the centre
    ob = SphereObstacle(np.array([0.0, 0.0]), 0.5, clearance_m=0.3)
    assert ob.required_distance_m == pytest.approx(0.8)
    clearance, violations = obstacle_metrics(path, (ob,))
    assert clearance == pytest.approx(0.4) and violations == 0
    near = SphereObstacle(np.array([0.0, 0.0]), 0.5).resolved(1.0)  # clearance d_min / 2 = 0.5
    clearance, violations = obstacle_metrics(path, (near,))
    assert clearance == pytest.approx(0.4) and violations == 1
    assert obstacle_metrics(path, ()) == (None, 0)


def test_geofence_counts_samples_outside_the_box() -> None:
    lim = Limits(geofence_min_m=np.array([-1.0, -1.0]), geofence_max_m=np.array([1.0, np.inf]))
    path = np.array([[[0.0, 0.0], [0.0, 5.0]], [[1.5, 0.0], [0.0, 50.0]]])
    assert geofence_violations(path, lim) == 1
    assert geofence_violations(path, Limits()) == 0


def test_downwash_metric_scales_the_vertical() -> None:
    assert downwash_metric(Limits(downwash_kappa=2.0), 3).tolist() == [1.0, 1.0, 0.5]
    assert downwash_metric(Limits(), 3) is None
    stacked = np.array([[[0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]] * 2)
    assert min_separation_along(stacked, downwash_metric(Limits(downwash_kappa=2.0), 3)) == pytest.approx(0.5)
