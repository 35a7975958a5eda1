"""Shared drawing pieces: the formation's skeleton, drone colours and marker sizes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from mpcform.outputs.drawing import PER_DRONE_MAX, drone_colours, formation_edges, marker_scale  # noqa: E402


def test_formation_edges_are_the_minimum_spanning_tree() -> None:
    offsets = np.array([[0.0, 0.0], [1.0, 0.0], [2.0, 0.0], [2.0, 1.0]])
    assert formation_edges(offsets) == [(0, 1), (1, 2), (2, 3)]
    assert formation_edges(offsets[:1]) == []


def test_colours_and_markers_follow_the_swarm_size() -> None:
    few = drone_colours(PER_DRONE_MAX)
    assert len(set(few)) == PER_DRONE_MAX and all(isinstance(c, str) for c in few)
    many = drone_colours(PER_DRONE_MAX + 1)
    assert len(many) == PER_DRONE_MAX + 1 and not isinstance(many[0], str)  # a colour map
    assert marker_scale(1) == marker_scale(20) == 1.0
    assert marker_scale(40) == pytest.approx(0.5) and marker_scale(100) == pytest.approx(0.3)
