"""Poles and no-fly boxes flown (``tests/shape_family.py``): swaps and arena crossings through
cylinders, boxes and spheres on the ideal, lag and quadrotor plants keep d_min, every clearance
(measured with the shapes' own closed forms) and the geofence on the dense true path, and every
drone arrives, unless the loader refuses a goal inside a shape naming the obstacle."""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
from shape_family import PARTS, PLANTS, campaign, family, surface_distances

FAMILY_RUNS = 60


def test_the_family_draws_what_it_promises() -> None:
    """Its first draws cover both parts on every plant, every kind of shape (mixed in one run),
    both couplings and dt 0.05-0.1, with no start inside a clearance."""
    runs = list(family(36))
    seen = Counter((sc["name"].split("_")[2], sc.get("plant", {}).get("kind", "ideal")) for sc in runs)
    assert set(seen) == {(part, plant) for part in PARTS for plant in PLANTS}
    kinds = [{ob["shape"] for ob in sc.get("obstacles", [])} for sc in runs]
    assert set().union(*kinds) == {"sphere", "cylinder", "box"} and any(len(k) > 1 for k in kinds)
    assert {sc["controller"]["coupling"] for sc in runs} == {"joint", "decoupled"}
    assert all(0.05 <= sc["simulation"]["dt"] <= 0.1 for sc in runs)
    for sc in runs:
        start = np.asarray(sc["initial"]["positions"])
        for ob in sc.get("obstacles", []):
            assert surface_distances(ob, start).min() >= ob.get("clearance", 0.5 * sc["limits"]["d_min"])


def test_the_shapes_own_distances_are_signed() -> None:
    pole = {"shape": "cylinder", "center": [0.0, 0.0, 1.0], "radius": 0.5, "height": 2.0}
    box = {"shape": "box", "center": [0.0, 0.0], "size": [2.0, 1.0]}
    pts = np.array([[0.0, 0.0, 1.0], [1.5, 0.0, 1.0], [0.0, 0.0, 3.0], [1.5, 0.0, 3.0]])
    np.testing.assert_allclose(surface_distances(pole, pts), [-0.5, 1.0, 1.0, np.sqrt(2.0)])
    np.testing.assert_allclose(
        surface_distances(box, np.array([[0.0, 0.0], [2.0, 1.5]])), [-0.5, np.sqrt(2.0)]
    )


@pytest.mark.slow
def test_random_runs_through_poles_and_boxes_keep_every_bound_and_arrive() -> None:
    results = campaign(FAMILY_RUNS)
    refused = [r for r in results if r["refused"]]
    for r in refused:
        assert "obstacles" in r["refused"], r
    assert len(refused) <= FAMILY_RUNS // 4  # the family mostly flies
    flown = [r for r in results if not r["refused"]]
    for r in flown:
        print(r["name"], round(r["min_clearance"], 4), r["completion"], round(r["cpu_s"], 1))
    bad = [
        r
        for r in flown
        if r["completion"] < 1.0
        or r["separation_violations"]
        or r["obstacle_violations"]
        or r["library_obstacle_violations"]
        or r["geofence_violations"]
        or r["speed_violations"]
    ]
    assert bad == []
