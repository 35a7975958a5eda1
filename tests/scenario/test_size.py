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
    DEFAULT_MAX_WORK,
    GIB,
    QP_WORK_PER_WORK,
    check_drone_count,
    check_memory,
    check_work,
    estimate_memory,
    planner_work,
    plant_work,
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
    scenario = load_scenario(path)
    assert estimate_memory(scenario).total_gib < 0.05 * DEFAULT_MAX_MEMORY_GIB
    assert planner_work(scenario) < 0.1 * QP_WORK_PER_WORK * DEFAULT_MAX_WORK


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


@pytest.mark.parametrize(
    ("template", "key", "n"),
    [
        ({"shape": "polygon", "n": 10**9}, "template.n", "1,000,000,000"),
        ({"shape": "grid", "rows": 10**5, "cols": 10**5, "layers": None}, "template.rows", "10,000,000,000"),
        ({"shape": "explicit", "offsets": [[0.0, 0.0]] * 100_000}, "template.offsets", "100,000"),
    ],
    ids=["n", "grid", "offsets"],
)
def test_too_many_drones_are_refused_from_the_keys_alone(template: dict[str, Any], key: str, n: str) -> None:
    with pytest.raises(ScenarioError) as info:
        check_drone_count(template, 120.0, 2, DEFAULT_MAX_MEMORY_GIB)
    message = str(info.value)
    assert info.value.field == key and f"{n} drones would need about " in message
    assert f"(121 samples x {n} drones x 2 axes), above the limit of 4 GiB: use fewer drones" in message
    assert message.endswith("or raise the limit with --max-memory GIB")


def test_the_drone_count_check_leaves_long_runs_and_fitting_ones_to_the_estimate() -> None:
    polygon = {"shape": "polygon", "n": 8}
    check_drone_count(polygon, 1e10, 2, 4.0)  # the duration drives it: check_memory names it
    check_drone_count(polygon, float("inf"), 2, 4.0)  # the loader refuses it, naming the duration
    check_drone_count({"shape": "polygon", "n": 10**9}, 120.0, 2, 1e9)  # a limit raised far enough
    scenario = scenario_from_dict(doc(n=8))
    need = estimate_memory(scenario).series_bytes / GIB
    check_drone_count({"shape": "polygon", "n": 8}, scenario.steps, 2, need * 1.001)


def quadrotor(rate: float, n: int = 12, duration: float = 10.0) -> dict[str, Any]:
    data = doc(n=n, radius=3.0, duration=duration)
    data["plant"] = {"kind": "quadrotor", "rate": rate}
    return data


def test_the_plant_work_is_its_inner_steps_times_the_drones() -> None:
    assert plant_work(scenario_from_dict(doc())) == 0.0  # the ideal plant
    lag = doc()
    lag["plant"] = {"kind": "lag"}
    assert plant_work(scenario_from_dict(lag)) == 0.0  # exact steps at the control samples
    assert plant_work(scenario_from_dict(quadrotor(500.0))) == pytest.approx(500 * 10.0 * 12)
    assert check_work(scenario_from_dict(quadrotor(500.0))) == pytest.approx(6e4)


def test_a_plant_rate_too_high_is_refused_naming_plant_rate() -> None:
    scenario = scenario_from_dict(quadrotor(1e6))
    with pytest.raises(ScenarioError) as info:
        check_work(scenario)
    assert info.value.field == "plant.rate"
    assert str(info.value) == (
        "plant.rate: the plant would take 1.2e+08 inner steps x drones (10,000,000 steps at 1e+06 Hz over "
        f"10 s x 12 drones), above the limit of {DEFAULT_MAX_WORK:.3g} (about 0.5 ms per inner step): lower "
        "plant.rate, shorten simulation.duration or use fewer drones, or raise the limit with --max-work N"
    )
    assert check_work(scenario, max_work=1.3e8) == pytest.approx(1.2e8)


def test_a_joint_qp_too_large_for_its_steps_is_refused_before_the_run() -> None:
    """400 drones packed inside one another's d_min (every pair within reach, 2.6 GiB: under the
    memory limit) would take hours of joint QPs: refused in well under 5 s, naming the drones'
    key, unless the limit is raised; solved per drone (decoupled) the planner's work is 0."""
    packed = doc(n=400, radius=1.0, kind="mpc", coupling="joint")
    packed["template"] = {"shape": "grid", "rows": 20, "cols": 20, "spacing": 0.01}
    scenario = scenario_from_dict(packed)
    start = time.perf_counter()
    with pytest.raises(ScenarioError) as info:
        check_work(scenario)
    assert time.perf_counter() - start < 5.0
    assert info.value.field == "template.rows" and "79,800 drone pairs within reach" in str(info.value)
    assert "--max-work N" in str(info.value)
    assert check_work(scenario, max_work=planner_work(scenario) / QP_WORK_PER_WORK) == 0.0
    per_drone = scenario_from_dict(packed | {"controller": {"kind": "mpc", "coupling": "decoupled"}})
    assert per_drone.controller.mpc.solves_per_drone and planner_work(per_drone) == 0.0
