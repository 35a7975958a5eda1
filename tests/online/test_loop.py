"""The online loop: the planner's own command from measurements, its setpoints, and the deadline."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.online.loop import IdealPlanWarning, OnlineLoop, step_time_stats
from mpcform.scenario.build import build_controller
from mpcform.scenario.load import load_scenario
from mpcform.scenario.plant import with_plant_kind

SCENARIOS = Path(__file__).resolve().parents[2] / "scenarios"


def _fly(loop: OnlineLoop, p: np.ndarray, steps: int) -> list:
    out = []
    for k in range(steps):
        s = loop.step(k * loop.dt_s, p)
        p = p + loop.dt_s * s.command_mps  # the ideal plant
        out.append(s)
    return out


def test_commands_are_the_planners_and_setpoints_start_at_the_measurement() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop, ref = OnlineLoop.from_scenario(sc), build_controller(sc)
    ref.reset(0.0, sc.initial_positions_m)
    p = sc.initial_positions_m.copy()
    for k in range(30):
        s = loop.step(k * sc.simulation.dt_s, p)
        np.testing.assert_array_equal(s.command_mps, ref.step(k * sc.simulation.dt_s, p.copy()).command_mps)
        np.testing.assert_array_equal(s.setpoints.pos_m[0, :, :2], p)
        assert np.all(s.setpoints.pos_m[..., 2] == 1.0) and not s.deadline_missed
        p = p + sc.simulation.dt_s * s.command_mps + 0.01 * np.sin(k + np.arange(16.0)).reshape(8, 2)


def test_a_planner_for_an_ideal_drone_is_warned_of_once() -> None:
    """No loop model and no tracking allowance: one warning, naming both and the fix, at
    construction (none while it flies); a Crazyflie's loop model and tracking allowance
    (``with_plant_kind(..., "crazyflow")``), or the allowance alone, are not warned of."""
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    with pytest.warns(IdealPlanWarning) as record:
        loop = OnlineLoop.from_scenario(sc)
        _fly(loop, sc.initial_positions_m.copy(), 3)
    assert len(record) == 1 and record[0].filename == __file__
    text = str(record[0].message)
    named = (
        "ideal drone",
        "controller.plant_model",
        "limits.tracking",
        'with_plant_kind(scenario, "crazyflow")',
    )
    assert all(part in text for part in named), text
    crazyflie = with_plant_kind(sc, "crazyflow")
    for planned in (crazyflie, sc.flyable()):
        with warnings.catch_warnings():
            warnings.simplefilter("error", IdealPlanWarning)
            OnlineLoop.from_scenario(planned)
    modelled = OnlineLoop.from_scenario(crazyflie).planner
    assert modelled.loop is not None and modelled.limits.limits.tracking_m == 0.05


def test_a_missed_deadline_still_sends_the_certified_command() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loops = OnlineLoop.from_scenario(sc), OnlineLoop.from_scenario(sc)
    p = sc.initial_positions_m.copy()
    for k in range(12):  # under way, both alike
        a, b = (loop.step(k * loop.dt_s, p) for loop in loops)
        np.testing.assert_array_equal(a.command_mps, b.command_mps)
        p = p + loops[0].dt_s * a.command_mps
    planner = loops[1].planner  # from now on no step can end in time
    planner.settings = dataclasses.replace(planner.settings, step_budget_s=1e-9)
    on_time, late = (loop.step(12 * loop.dt_s, p) for loop in loops)
    assert late.deadline_missed and not on_time.deadline_missed and late.info.mode == on_time.info.mode
    np.testing.assert_array_equal(late.command_mps, on_time.command_mps)  # sent late, not replaced
    assert np.linalg.norm(late.command_mps) > 1.0  # the swarm keeps moving
    assert step_time_stats([late])["deadline_miss_share"] == 1.0


def test_decoupled_20_drones_meet_a_100_ms_deadline() -> None:
    sc = load_scenario(SCENARIOS / "swap_spatial_20.toml")
    mpc = dataclasses.replace(sc.controller.mpc, coupling="decoupled", solve=None)
    sc = dataclasses.replace(sc, controller=dataclasses.replace(sc.controller, mpc=mpc))
    loop = OnlineLoop.from_scenario(sc, step_budget_s=sc.simulation.dt_s)
    steps = _fly(loop, sc.initial_positions_m.copy(), 40)
    assert step_time_stats(steps)["deadline_miss_share"] <= 0.01


def test_online_planning_needs_the_mpc() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    tracking = dataclasses.replace(sc, controller=dataclasses.replace(sc.controller, kind="tracking"))
    with pytest.raises(ValidationError, match="controller.kind"):
        OnlineLoop.from_scenario(tracking)
    with pytest.raises(ValidationError, match="setpoint_rate"):
        OnlineLoop.from_scenario(sc, setpoint_rate_hz=15.0)


def test_a_lost_drone_is_commanded_zero_and_a_new_flight_plans_for_every_drone() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    p = sc.initial_positions_m.copy()
    for s in _fly(loop, p, 10):
        p = p + loop.dt_s * s.command_mps
    loop.lose([3], p)
    assert loop.lost_drones.tolist() == [3]
    after = loop.step(10 * loop.dt_s, p)
    assert np.all(after.command_mps[3] == 0.0) and np.linalg.norm(after.command_mps[[2, 4]]) > 0.5
    np.testing.assert_array_equal(after.setpoints.pos_m[:, 3, :2], np.broadcast_to(p[3], (10, 2)))
    with pytest.raises(ValidationError, match="drones"):
        loop.lose([8], p)
    loop.start(0.0, sc.initial_positions_m)
    assert loop.lost_drones.size == 0 and np.linalg.norm(loop.step(0.0, p).command_mps[3]) > 0.0


@pytest.mark.parametrize(
    ("drones", "fragment"),
    [
        ([1.5], "got [1.5]"),
        ([1.0], "got [1.0]"),
        ([True, False, False, False, False, False], "a boolean mask of shape (6,)"),
        ([8], "index 8 is out of range"),
        ([-1], "index -1 is out of range"),
        ([[1, 2]], "got [[1, 2]]"),
        (["1"], "got ['1']"),
    ],
)
def test_lose_takes_indices_or_a_mask_of_length_n(drones: object, fragment: str) -> None:
    """A mask is never read as indices (it lost drones 0 and 1), a float never rounded."""
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    p = sc.initial_positions_m.copy()
    loop.step(0.0, p)
    with pytest.raises(ValidationError) as info:
        loop.lose(drones, p)  # type: ignore[arg-type]
    message = str(info.value)
    assert message.startswith("drones: expected integer drone indices in 0..7 or a boolean mask of length 8")
    assert fragment in message and loop.lost_drones.size == 0


def test_lose_by_mask_is_lose_by_indices() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    p = sc.initial_positions_m.copy()
    by_mask, by_index = OnlineLoop.from_scenario(sc), OnlineLoop.from_scenario(sc)
    for loop in (by_mask, by_index):
        loop.step(0.0, p)
    by_mask.lose(np.arange(8) == 5, p)
    by_index.lose(np.int64(5), p)
    assert by_mask.lost_drones.tolist() == by_index.lost_drones.tolist() == [5]
    by_mask.lose([], p)
    assert by_mask.lost_drones.tolist() == [5]


@pytest.mark.parametrize(
    ("times", "fragment"),
    [
        ((0.0, float("nan")), "t_s: expected a finite time [s], got nan"),
        ((0.0, float("inf")), "t_s: expected a finite time [s], got inf"),
        (
            (0.0, -5.0),
            "t_s: expected a time after the previous step's 0 s (start() begins a new flight), got -5 s",
        ),
        (
            (0.0, 0.1, 0.1),
            "t_s: expected a time after the previous step's 0.1 s (start() begins a new flight), got 0.1 s",
        ),
        (
            (0.0, 0.15),
            "t_s: expected a time on the loop's grid 0 s + k dt (dt = 0.1 s), got 0.15 s, 0.5 dt off",
        ),
        (("0",), "t_s: expected a real number of seconds, got '0'"),
        ((True,), "t_s: expected a real number of seconds, got True"),
        ((1j,), "t_s: expected a real number of seconds, got 1j"),
    ],
)
def test_step_takes_finite_increasing_times_on_the_loops_grid(times: tuple, fragment: str) -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    assert loop.dt_s == 0.1
    p = sc.initial_positions_m.copy()
    *good, bad = times
    for t in good:
        loop.step(t, p)
    with pytest.raises(ValidationError) as info:
        loop.step(bad, p)
    assert str(info.value) == fragment


def test_step_allows_a_skipped_period_and_a_grid_from_the_first_step() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    p = sc.initial_positions_m.copy()
    for t in (7.05, 7.15, 7.45, 7.55 + 1e-9):  # a missed period is no error; rounding is within the grid
        assert loop.step(t, p).t_s == t
    loop.start(0.0, p)
    loop.step(0.0, p)


def test_step_refuses_complex_or_non_finite_positions() -> None:
    sc = load_scenario(SCENARIOS / "swap_planar_8.toml")
    loop = OnlineLoop.from_scenario(sc)
    p = sc.initial_positions_m.copy()
    with pytest.raises(ValidationError, match=r"^positions: expected real numbers of shape \(8, 2\)"):
        loop.step(0.0, p + 1e-3j)
    bad = p.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValidationError, match=r"^positions: expected finite numbers"):
        loop.step(0.0, bad)
    with pytest.raises(ValidationError, match=r"^positions: expected shape \(8, 2\), got shape \(8, 3\)"):
        loop.step(0.0, np.zeros((8, 3)))


def test_joint_coupling_of_a_large_swarm_is_refused_online() -> None:
    sc = load_scenario(SCENARIOS / "swap_spatial_12.toml")  # coupling = "joint" (the default)
    with pytest.raises(ValidationError, match='controller.coupling.*coupling = "decoupled"'):
        OnlineLoop.from_scenario(sc)
    mpc = dataclasses.replace(sc.controller.mpc, coupling="decoupled", solve=None)
    decoupled = dataclasses.replace(sc, controller=dataclasses.replace(sc.controller, mpc=mpc))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdealPlanWarning)
        assert OnlineLoop.from_scenario(decoupled).n == 12
