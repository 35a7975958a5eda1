"""The memory estimate of a run: what it counts, the refusals naming their key, fast on huge inputs."""

from __future__ import annotations

import time
import tomllib
from typing import Any

import numpy as np
import pytest
from saved_runs import SCENARIOS

from mpcform.errors import ScenarioError
from mpcform.formation.geometry import pairs_within
from mpcform.scenario.load import load_scenario, scenario_from_dict
from mpcform.scenario.size import (
    BYTES_PER_NONZERO,
    BYTES_PER_STEP,
    BYTES_PER_VALUE,
    DEFAULT_MAX_MEMORY_GIB,
    GIB,
    check_memory,
    estimate_memory,
)


def doc(n: int = 5, radius: float = 1.5, duration: float = 10.0, **controller: Any) -> dict[str, Any]:
    """A planar polygon holding still (constant reference) under ``controller`` (default: tracking)."""
    return {
        "version": 1,
        "dim": 2,
        "template": {"shape": "polygon", "n": n, "radius": radius},
        "initial": {"centroid": [0.0, 0.0]},
        "reference": {"kind": "constant"},
        "limits": {"v_max": 1.0, "d_min": 0.5},
        "controller": {"kind": "tracking", **controller},
        "simulation": {"dt": 0.1, "duration": duration},
    }


def test_time_series_follow_steps_drones_and_axes() -> None:
    est = estimate_memory(scenario_from_dict(doc(n=7, duration=2.0)))
    assert est.steps == 20 and est.horizon is None and est.horizon_bytes == est.pair_bytes == 0.0
    assert est.series_bytes == 21 * (7 * 2 * BYTES_PER_VALUE[True] + BYTES_PER_STEP[True])
    without = estimate_memory(scenario_from_dict(doc(n=7, duration=2.0)), files=False)
    assert without.series_bytes < est.series_bytes


def test_the_mpc_counts_candidate_pairs_as_the_planner_would() -> None:
    s = scenario_from_dict(doc(n=40, radius=12.0, kind="mpc", horizon=5))  # neighbours 1.9 m apart
    est = estimate_memory(s)
    reach = 0.5 + s.controller.mpc.margin_m + 4.0 * 1.0 * 5 * 0.1  # d_min + margin + 4 v_max H dt
    assert est.pairs == pairs_within(s.initial_positions_m, reach).shape[0] == 40
    assert est.pair_bytes == BYTES_PER_NONZERO * est.pairs * (2 * 5 - 1) * (2 * 2 + 2)
    assert estimate_memory(s, controller="tracking").horizon is None  # --controller overrides the kind


def test_a_swap_counts_the_pairs_where_the_straight_ways_cross() -> None:
    s = load_scenario(SCENARIOS / "swap_planar_8.toml")  # every straight way crosses the centre
    assert estimate_memory(s).pairs == 8 * 7 // 2


def test_the_per_drone_qps_grow_with_the_square_of_the_horizon() -> None:
    small, large = (
        estimate_memory(scenario_from_dict(doc(kind="mpc", horizon=h, coupling="decoupled")))
        for h in (50, 100)
    )
    assert large.horizon_bytes / small.horizon_bytes == pytest.approx(4.0, rel=0.05)


@pytest.mark.parametrize("path", sorted(SCENARIOS.glob("*.toml")), ids=lambda p: p.stem)
def test_bundled_scenarios_stay_far_below_the_default_limit(path: Any) -> None:
    assert estimate_memory(load_scenario(path)).total_gib < 0.05 * DEFAULT_MAX_MEMORY_GIB


@pytest.mark.parametrize(
    ("data", "key", "fragment"),
    [
        (doc(duration=1e9), "simulation.duration", "10,000,000,001 samples x 5 drones x 2 axes"),
        (doc(kind="mpc", horizon=1_000_000), "controller.horizon", "horizon of 1,000,000 steps"),
        (doc(n=5000, kind="mpc"), "template.n", "about 12,497,500 drone pairs"),
    ],
    ids=["duration", "horizon", "drones"],
)
def test_huge_runs_are_refused_fast_naming_their_key(data: dict[str, Any], key: str, fragment: str) -> None:
    scenario = scenario_from_dict(data)
    start = time.perf_counter()
    with pytest.raises(ScenarioError) as info:
        check_memory(scenario)
    assert time.perf_counter() - start < 1.0
    message = str(info.value)
    assert info.value.field == key and fragment in message
    assert "above the limit of 4 GiB" in message and "--max-memory GIB" in message


def test_a_higher_limit_lets_the_run_through() -> None:
    scenario = scenario_from_dict(doc(kind="mpc", horizon=1_000_000))
    need = estimate_memory(scenario).total_gib
    assert need > DEFAULT_MAX_MEMORY_GIB
    assert check_memory(scenario, max_gib=need * 1.01).total_bytes == pytest.approx(need * GIB)


def test_the_key_of_the_drones_follows_the_template_shape() -> None:
    data = tomllib.loads((SCENARIOS / "formation_flight_100.toml").read_text())
    data["limits"]["d_min"] = 100.0  # every pair within reach: the pairs dominate
    with pytest.raises(ScenarioError) as info:
        check_memory(scenario_from_dict(data), max_gib=1e-3)
    assert info.value.field == "template.rows"
    angles = 2 * np.pi * np.arange(30) / 30
    data = doc(kind="mpc")
    offsets = np.column_stack([np.cos(angles), np.sin(angles)])
    data["template"] = {"shape": "explicit", "offsets": offsets.tolist()}
    data["limits"]["d_min"] = 100.0
    with pytest.raises(ScenarioError) as info:
        check_memory(scenario_from_dict(data), max_gib=1e-3)
    assert info.value.field == "template.offsets" and "435 drone pairs" in str(info.value)
