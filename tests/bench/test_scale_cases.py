"""The scale scenarios: constant density, reference speeds inside v_max, head-on crossing halves, and a
200-drone decoupled crossing that keeps its separation."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.bench.scale_cases import LIMITS, SPACING_M, crossing_case, formation_case, make_case
from mpcform.errors import ValidationError
from mpcform.formation.geometry import min_pair_distance, min_segment_distance
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import mode_settings


def test_cases_have_constant_density_and_reference_speeds_below_v_max() -> None:
    for n in (10, 100, 101, 1000):
        ref, p0 = formation_case(n)
        assert p0.shape == (n, 3) and min_pair_distance(ref.template.offsets) == pytest.approx(SPACING_M)
        _, vel = ref.targets(np.linspace(0.0, 3.0, 4))
        assert np.linalg.norm(vel, axis=-1).max() < 0.6 * LIMITS.v_max_mps
        ref, p0 = crossing_case(n)
        assert p0.shape == (n, 3) and min_pair_distance(p0) >= SPACING_M - 1e-9
        _, vel = ref.targets(np.array([0.0, 1.0]))
        assert np.allclose(np.abs(vel[..., 0]), 0.5) and np.allclose(vel[..., 1:], 0.0)
        # the halves fly head-on: n // 2 drones along +x, the rest (one more when n is odd) along -x
        assert (vel[0, :, 0] > 0).sum() == n // 2 and vel[0, :, 0].sum() == -0.5 * (n % 2)


def test_unknown_scenario_and_too_small_crossing_are_errors() -> None:
    assert make_case("crossing", 2)[1].shape == (2, 3)
    with pytest.raises(ValidationError, match="scenario"):
        make_case("nope", 4)
    with pytest.raises(ValidationError, match="at least 2 drones"):
        crossing_case(1)


def test_decoupled_crossing_of_200_drones_keeps_separation_along_segments() -> None:
    ref, p = crossing_case(200, gap_m=0.9)  # fronts close enough to conflict at once
    planner = MPCPlanner(ref, 0.1, LIMITS, mode_settings("decoupled", 3))
    planner.reset(0.0, p)
    modes = []
    for j in range(10):
        out = planner.step(0.1 * j, p)
        p_next = p + 0.1 * out.command_mps
        assert min_segment_distance(p, p_next) >= LIMITS.d_min_m * (1 - 1e-9)
        assert np.linalg.norm(out.command_mps, axis=1).max() <= LIMITS.v_max_mps * (1 + 1e-9)
        modes.append(out.info.mode)
        p = p_next
    assert modes.count("qp") >= 5 and "fallback" not in modes
