"""Plans flown on realistic plants (slow): the bundled MPC scenarios and the three swaps under a
velocity lag (0.1, 0.2, 0.3 s), a second-order loop and the quadrotor in gusty wind, and a seeded
random family of swaps under a lag and the quadrotor. The true, dense trajectory keeps d_min and
the obstacles; every drone arrives; commands stay within v_max."""

from __future__ import annotations

import copy
import tomllib
from importlib import metadata
from pathlib import Path

import numpy as np
import pytest
from families import swap_planar, swap_spatial

from mpcform.run.runner import run_scenario
from mpcform.scenario.load import scenario_from_dict
from mpcform.sim.completion import completion_metrics

pytestmark = pytest.mark.slow
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
FILES = {p.stem: tomllib.loads(p.read_text()) for p in SCENARIOS.glob("*.toml")}
MPC = sorted(n for n, data in FILES.items() if data["controller"]["kind"] == "mpc" and "plant" not in data)
PLANTS = {
    "lag0.1": {"kind": "lag", "time_constant": 0.1},
    "lag0.2": {"kind": "lag", "time_constant": 0.2},
    "lag0.3": {"kind": "lag", "time_constant": 0.3},
    "second_order": {"kind": "second_order", "damping": 0.7, "natural_frequency": 6.0},
    "quadrotor_wind": {"kind": "quadrotor", "wind": {"gust_std": 0.5, "gust_time": 1.0}},
}
try:
    metadata.distribution("drone-models")
    FLIGHT = True
except metadata.PackageNotFoundError:
    FLIGHT = False


GUST_TOL_M = 0.25
"""Completion's tolerance in the gusts (0.1 m in calm air): they push an arrived formation around
its goal; formation_flight_100's 100 drones, all within 0.1 m at 21 s, had 49-100 % within 0.1 m
over its last 4 s (up to 0.18 m off), whatever the tie-break did."""


def with_plant(data: dict, plant: dict) -> dict:
    data, plant = copy.deepcopy(data), copy.deepcopy(plant)
    if "wind" in plant:
        plant["wind"]["mean"] = [1.0, 0.0] + [0.0] * (data["dim"] - 2)
    data["plant"] = plant
    return data


def check(data: dict, open_reason: str | None = None) -> dict:
    """Safety always: d_min on the true path, and no slack and no lowered first row (no pair starts
    inside its distance here), unless the wind is too strong for the final formation to hold with
    the rows' growth, which the scenario warns of (``growth_warning``: formation_flight_100 in the
    gusts, 0.6 m apart against 0.685 m); completion too, unless the run is a known open one
    (``open_reason``): then its completion must still fall short, so a fix shows up as a failure to
    update the list."""
    scenario = scenario_from_dict(data)
    run = run_scenario(scenario)
    m = run.summary["metrics"]
    assert m["separation_violations_true"] == 0, (m["min_separation_true"], run.summary["plant"])
    if scenario.growth_warning() is None:
        assert m["slack_steps"] == 0 and m["lowered_first_rows"] == 0, (
            m["slack_steps"],
            m["lowered_first_rows"],
        )
    assert m.get("obstacle_violations_true", 0) == 0, m.get("min_obstacle_clearance_true")
    assert m["geofence_violations_true"] == 0
    assert m["speed_violations"] == 0  # the certified command; the true speed may exceed v_max
    assert m["max_speed_true"] is not None
    completion = m["completion"]
    if "wind" in data["plant"]:  # arrived to within the gusts' push (see GUST_TOL_M)
        completion = completion_metrics(run.simulation, GUST_TOL_M)["completion"]
    if open_reason is None:
        assert completion == 1.0, (m["completion"], completion, m["stalled_drones"])
    else:
        assert completion < 1.0, f"completes now: remove it from the open list ({open_reason})"
    return m


OPEN_RANDOM: dict[int, str] = {}  # safe, but not every drone arrives within the duration (none now)
LONGER_RANDOM_S = {3: 21.0, 5: 25.0}
"""Durations [s] given to random swaps whose last drones arrive after the family's (2 x travel + 10
s): seed 5, a decoupled crowd of 15 under a lag, completed within its 17.0 s on the machine it was
first run on and at 21.3 s on an AMD EPYC (OpenBLAS picks its kernels, and so the last bits of the
solves, by processor; a crowd's closed loop carries them on). Seed 3, a decoupled planar swap of
11 quadrotors in gusts, completes within its 14.0 s with two OpenBLAS threads but at 19.5 s with
one (CI's setting) since offset-free tracking: 12 stall events and 4 circling resets on the way."""


@pytest.mark.parametrize(("name", "plant"), [(n, p) for n in MPC for p in sorted(PLANTS)])
def test_bundled_scenario_on_a_realistic_plant(name: str, plant: str) -> None:
    if plant.startswith("quadrotor") and not FLIGHT:
        pytest.skip("needs drone-models: pip install -e '.[flight]'")
    check(with_plant(FILES[name], PLANTS[plant]))


@pytest.mark.parametrize("seed", range(1, 6))
def test_a_tight_formation_in_gusts_keeps_d_min_for_every_gust_seed(seed: int) -> None:
    """formation_flight_100 ends at 0.6 m spacing, 0.022 m above its tightened distance: the gusts
    keep pressing its rows. Every first row is hard under a loop, so no drone approaches one partner
    because another forces a slack (seeds 2 and 3 came to 0.425 and 0.449 m with slack there); the
    completion at the last sample varies with the gusts (0.89 to 1.0 over seeds 0 to 5)."""
    if not FLIGHT:
        pytest.skip("needs drone-models: pip install -e '.[flight]'")
    data = with_plant(FILES["formation_flight_100"], PLANTS["quadrotor_wind"]) | {"seed": seed}
    m = run_scenario(scenario_from_dict(data)).summary["metrics"]
    assert m["separation_violations_true"] == 0, m["min_separation_true"]
    assert m["speed_violations"] == 0


def test_a_decoupled_quadrotor_formation_in_a_steady_wind_needs_no_slack() -> None:
    """The file's formation crept inside its braking tail's rows on the chord (0.562 m against d_min
    0.599 m, 101 steps with slack); with the tail's exact samples its plans stay recursively
    feasible: no slack, no lowered first row, d_min on the true path, every drone arrived."""
    if not FLIGHT:
        pytest.skip("needs drone-models: pip install -e '.[flight]'")
    data = tomllib.loads((Path(__file__).with_name("quadrotor_formation_steady_wind.toml")).read_text())
    m = run_scenario(scenario_from_dict(data)).summary["metrics"]
    assert m["separation_violations_true"] == 0, m["min_separation_true"]
    assert m["slack_steps"] == 0 and m["lowered_first_rows"] == 0 and m["completion"] == 1.0


def _completion_run(index: int, growth_m: float | None = None) -> dict:
    """Run ``index`` of the completion family (``growth_m``: its ``plant.margin_growth``)."""
    import completion_family

    data = completion_family.scenario(np.random.default_rng([completion_family.SEED, index]), index)
    if growth_m is not None:
        data["plant"]["margin_growth"] = growth_m
    return run_scenario(scenario_from_dict(data)).summary["metrics"]


def test_a_quadrotor_swap_in_gusts_keeps_d_min_without_slack_with_the_rows_grown() -> None:
    """``completion_306`` (16 planar quadrotors, joint, gusts at the family's bound): without the
    rows' growth along the horizon the gusts made the shifted plan infeasible, and the plans' slack
    spent the margin: 0.663 m against d_min 0.680 m, slack on 114 steps, 52 lowered first rows.
    Grown, it needs no slack and lowers no first row."""
    if not FLIGHT:
        pytest.skip("needs drone-models: pip install -e '.[flight]'")
    m = _completion_run(306)
    assert m["separation_violations_true"] == 0, m["min_separation_true"]
    assert m["slack_steps"] == 0 and m["lowered_first_rows"] == 0 and m["completion"] == 1.0


def test_the_rows_growth_takes_the_slack_of_a_quadrotor_swap_in_gusts() -> None:
    """``completion_42`` (10 planar quadrotors, joint, horizon 7 at dt 0.08): 14 slack steps
    without the growth (``plant.margin_growth = 0``); with it none and no lowered first row. Before
    offset-free tracking its plans reached into the growth past its first E = 3 steps on 6 steps (up
    to 47 mm of the pair's 95 mm there, on an AMD EPYC); now that the plan carries the wind's offset
    (mpcform.mpc.velocity_loop) they need none of it (0 steps)."""
    if not FLIGHT:
        pytest.skip("needs drone-models: pip install -e '.[flight]'")
    grown, plain = _completion_run(42), _completion_run(42, 0.0)
    assert grown["separation_violations_true"] == 0 and grown["lowered_first_rows"] == 0
    assert grown["slack_steps"] == 0 < plain["slack_steps"], (grown["slack_steps"], plain["slack_steps"])
    assert plain["growth_slack_steps"] == 0


@pytest.mark.parametrize("seed", range(12))
def test_random_swaps_under_a_lag_and_the_quadrotor(seed: int) -> None:
    rng = np.random.default_rng(1000 + seed)
    data = (swap_planar if seed % 2 else swap_spatial)(rng, seed)
    data["controller"]["horizon"] = 10
    while len(data["template"]["offsets"]) > 20:  # n up to 20
        data = (swap_planar if seed % 2 else swap_spatial)(rng, seed)
    plant = PLANTS["lag0.2"] if seed % 3 or not FLIGHT else PLANTS["quadrotor_wind"]
    if seed in LONGER_RANDOM_S:
        data["simulation"]["duration"] = LONGER_RANDOM_S[seed]
    check(with_plant(data, plant), OPEN_RANDOM.get(seed))


@pytest.mark.parametrize("seed", range(12, 62))
def test_random_swaps_under_a_lag_keep_d_min(seed: int) -> None:
    """50 more random swaps of the same generator under a 0.2 s lag: the velocity-loop rows keep
    every true separation (6 of them broke it with the single integrator's rows); completion is
    not asserted (4 of these decoupled crowds and rings are still converging at the end)."""
    rng = np.random.default_rng(1000 + seed)
    data = (swap_planar if seed % 2 else swap_spatial)(rng, seed)
    data["controller"]["horizon"] = 10
    while len(data["template"]["offsets"]) > 20:
        data = (swap_planar if seed % 2 else swap_spatial)(rng, seed)
    m = run_scenario(scenario_from_dict(with_plant(data, PLANTS["lag0.2"]))).summary["metrics"]
    assert m["separation_violations_true"] == 0, m["min_separation_true"]
    assert m["speed_violations"] == 0
