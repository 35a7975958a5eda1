"""The scenario spec: a frozen scenario with read-only positions, its drone and step counts."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from saved_runs import SCENARIOS

from mpcform.scenario.load import load_scenario

WORKED = SCENARIOS / "worked_example.toml"


def test_scenario_is_frozen() -> None:
    s = load_scenario(WORKED)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.name = "other"  # type: ignore[misc]
    with pytest.raises(ValueError):
        s.initial_positions_m[0, 0] = 1.0


@pytest.mark.parametrize(("duration_s", "steps"), [(10.0, 500), (0.05, 2), (0.001, 1)])
def test_drones_and_steps(duration_s: float, steps: int) -> None:
    s = load_scenario(WORKED)
    short = dataclasses.replace(s, simulation=dataclasses.replace(s.simulation, duration_s=duration_s))
    assert short.n == 3 and short.steps == steps


def test_spacing_warning_when_the_plant_margin_exceeds_the_final_spacing() -> None:
    """formation_flight_100 ends at a spacing of 0.6 m with d_min 0.5: a 0.3 s lag (margin a_max dt
    tau per axis, 0.0757 m in the plane) keeps 0.651 m plus the rows' 2 mm, a 0.1 s lag 0.552 m;
    the tracking allowance 0.602 m, which it cannot reach (flown with --flyable, 24 drones ended
    0.10-0.14 m short; at a spacing of 0.605 m every drone arrives)."""
    import tomllib

    from mpcform.scenario.load import scenario_from_dict

    data = tomllib.loads((SCENARIOS / "formation_flight_100.toml").read_text())
    assert scenario_from_dict(data).spacing_warning() is None  # the ideal plant
    data["plant"] = {"kind": "lag", "time_constant": 0.1}
    assert scenario_from_dict(data).spacing_warning() is None
    data["plant"] = {"kind": "lag", "time_constant": 0.3}
    assert scenario_from_dict(data).spacing_warning() is None  # the loop modelled: no margin
    data["controller"]["plant_model"] = False
    slow = scenario_from_dict(data)
    text = slow.spacing_warning()
    keep = 0.5 + 2 * slow.robustness.margin_m + 0.002
    assert text is not None and "0.6 m apart" in text and f"{keep:.4g} m" in text
    assert abs(keep - 0.653) < 5e-4 and "+ controller.margin 0.002 m" in text
    assert slow.spacing_warning("tracking") is None  # only the MPC keeps the margin
    ideal = scenario_from_dict(tomllib.loads((SCENARIOS / "formation_flight_100.toml").read_text()))
    text = ideal.flyable().spacing_warning()  # 0.6 m: d_min + 2 x 0.05, but the rows ask 2 mm more
    assert text is not None and "below the 0.602 m (d_min + 2 x (tracking 0.05 m) + controller.margin" in text
    mpc = dataclasses.replace(ideal.controller.mpc, margin_m=0.0)
    exact = dataclasses.replace(ideal, controller=dataclasses.replace(ideal.controller, mpc=mpc))
    assert exact.flyable().spacing_warning() is None  # exactly the distance kept: reachable
    wide = dataclasses.replace(ideal, limits=dataclasses.replace(ideal.limits, tracking_m=0.08))
    text = wide.spacing_warning()
    assert text is not None and text.startswith("limits.tracking: ") and "(tracking 0.08 m)" in text


def test_spacing_warning_on_the_ideal_plant_when_d_min_exceeds_the_final_spacing() -> None:
    import tomllib

    from mpcform.scenario.load import scenario_from_dict

    data = tomllib.loads((SCENARIOS / "swap_planar_8.toml").read_text())
    assert scenario_from_dict(data).spacing_warning() is None
    data["limits"]["d_min"] = 3.0  # the goal's neighbours are 2.3 m apart
    text = scenario_from_dict(data).spacing_warning()
    assert text is not None and text.startswith("limits.d_min: ") and "2.3 m apart, below d_min = 3 m" in text
    closest = 2.0 * 3.0 * np.sin(np.pi / 8)  # the goal: a ring of 8 drones, radius 3 m

    def at(d_min: float) -> str | None:
        return scenario_from_dict(data | {"limits": data["limits"] | {"d_min": d_min}}).spacing_warning()

    text = at(closest - 1e-3)  # d_min is met, the rows' 2 mm more are not
    assert text is not None and "+ controller.margin 0.002 m: those drones stop short" in text
    assert at(closest - 3e-3) is None


def test_a_modelled_loop_keeps_only_the_winds_margin() -> None:
    """With the velocity loop in the MPC's rows a linear plant's margin is its wind part plus the
    bend of the true path within an interval (``chord_margin``): a few millimetres in still air."""
    import tomllib

    from mpcform.scenario.load import scenario_from_dict
    from mpcform.sim.margin import chord_margin

    data = tomllib.loads((SCENARIOS / "swap_planar_8.toml").read_text())
    margins = {}
    for wind in (False, True):
        for model in (False, True):
            data["plant"] = {"kind": "lag", "time_constant": 0.2}
            if wind:
                data["plant"]["wind"] = {"mean": [1.0, 0.0], "gust_std": 0.5}
            data["controller"]["plant_model"] = model
            margins[wind, model] = scenario_from_dict(data).robustness.margin_m
    plant = scenario_from_dict(data).plant.build(1, 2)
    bend = float(np.linalg.norm(chord_margin(plant, 0.1, scenario_from_dict(data).robustness.a_max_mps2)))
    assert margins[False, True] == pytest.approx(bend, rel=1e-12) and 0.001 < bend < 0.005
    assert margins[False, False] > 0.04 and bend < margins[True, True] < margins[True, False]


def test_speed_warning_when_v_max_exceeds_the_quadrotors_valid_speed() -> None:
    """The windy swap flies at v_max 1 m/s; its quadrotor margin holds below 0.954 m/s in the
    strongest wind (drag plus a_max within the 20 degree tilt): one warning, only for the MPC;
    at v_max 0.9 m/s, or in still air (valid below 3.87 m/s), none."""
    import tomllib
    from importlib import metadata

    try:
        metadata.distribution("drone-models")
    except metadata.PackageNotFoundError:
        pytest.skip("needs drone-models: pip install -e '.[flight]'")
    from mpcform.scenario.load import scenario_from_dict

    data = tomllib.loads((SCENARIOS / "swap_spatial_12_quadrotor_wind.toml").read_text())
    text = scenario_from_dict(data).speed_warning()
    assert text is not None and "below 0.954 m/s" in text and "limits.v_max is 1 m/s" in text
    assert scenario_from_dict(data).warnings() == [text]
    assert scenario_from_dict(data).warnings("tracking") == []
    data["limits"]["v_max"] = 0.9
    assert scenario_from_dict(data).warnings() == []
    data["limits"]["v_max"] = 1.0
    del data["plant"]["wind"]
    assert scenario_from_dict(data).speed_warning() is None


def test_a_mission_cut_short_is_said_and_its_final_targets_counted() -> None:
    full = load_scenario(SCENARIOS / "mission_spatial.toml")
    assert full.goal_after_end() is None
    assert not any(w.startswith("simulation.duration") for w in full.warnings())
    short = dataclasses.replace(full, simulation=dataclasses.replace(full.simulation, duration_s=3.0))
    goal = short.goal_after_end()
    end = full.reference.duration_s  # type: ignore[attr-defined]
    assert goal is not None and np.array_equal(goal, full.reference.targets(np.array([end]))[0][0])
    assert any(
        w.startswith("simulation.duration: the run ends at 3 s, before the reference's end")
        for w in short.warnings()
    )


def test_a_duration_that_is_no_whole_number_of_steps_is_said() -> None:
    s = load_scenario(WORKED)  # dt 0.02
    odd = dataclasses.replace(s, simulation=dataclasses.replace(s.simulation, duration_s=1.05))
    assert odd.steps == 52 and not any("whole number" in w for w in s.warnings())
    want = "simulation.duration: 1.05 s is not a whole number of dt = 0.02 s steps; the run takes 52 steps"
    assert f"{want} (1.04 s)" in odd.warnings()


def test_a_flyable_swap_keeps_d_min_plus_twice_the_tracking_allowance_along_its_path() -> None:
    from mpcform.formation.geometry import min_segment_distance
    from mpcform.run.runner import run_scenario
    from mpcform.world.limits import PLATFORM_TRACKING_M

    scenario = load_scenario(SCENARIOS / "swap_planar_8.toml")
    flyable = scenario.flyable()
    assert flyable.limits.tracking_m == PLATFORM_TRACKING_M and scenario.limits.tracking_m == 0.0
    assert flyable.flyable() is flyable  # a file's own allowance is kept
    run = run_scenario(flyable)
    pos = run.simulation.positions_m
    closest = min(min_segment_distance(a, b) for a, b in zip(pos[:-1], pos[1:], strict=True))
    d_min = scenario.limits.d_min_m
    assert closest >= d_min + 2 * PLATFORM_TRACKING_M - 1e-6 and run.summary["metrics"]["completion"] == 1.0
    assert run.summary["limits"]["tracking"] == PLATFORM_TRACKING_M


def test_growth_warning_names_the_drones_whose_rows_do_not_grow_in_wind() -> None:
    """formation_flight_100 ends 0.6 m apart: under a 0.1 s lag in strong gusts (1 m/s, 0.5 s) the
    MPC keeps about 0.55 m, and its rows grow along the horizon only for drones whose targets are
    at least that plus twice the growth at the horizon's end apart: none here, so the gusts may
    need slack. The planner's own shares (``Separation.growing``) agree; calm air and gentle gusts
    warn of nothing."""
    import math
    import tomllib

    from mpcform.mpc.constraints.rows import GROWTH_TIME_S
    from mpcform.scenario.build import build_controller
    from mpcform.scenario.load import scenario_from_dict

    data = tomllib.loads((SCENARIOS / "formation_flight_100.toml").read_text())
    data["plant"] = {"kind": "lag", "time_constant": 0.1}
    assert scenario_from_dict(data).growth_warning() is None  # calm air: no growth
    data["plant"]["wind"] = {"mean": [1.0, 0.0], "gust_std": 1.0, "gust_time": 0.5}
    spec = scenario_from_dict(data)
    g, dt, h = spec.robustness.growth_m, spec.simulation.dt_s, spec.controller.mpc.horizon
    keep = 0.5 + 2 * spec.robustness.margin_m + spec.controller.mpc.margin_m
    grown = keep + 2 * g * min(h, math.ceil(GROWTH_TIME_S / dt))
    assert 0.6 < grown and spec.spacing_warning() is None  # reachable, but not with growth
    text = spec.growth_warning()
    assert text is not None and text.startswith("plant: in this wind the final formation's closest pair")
    assert f"below the {grown:.4g} m" in text and "0.6 m apart" in text
    assert any(text in w for w in spec.warnings())
    final = spec.reference.targets(np.array([spec.simulation.duration_s]))[0][0]
    planner = build_controller(spec)
    np.testing.assert_array_equal(planner.steps.separation.growing(final), np.zeros(100))
    data["plant"]["wind"] = {"mean": [0.3, 0.0], "gust_std": 0.05}  # gentler: the rows grow
    gentle = scenario_from_dict(data)
    assert gentle.growth_warning() is None
    np.testing.assert_array_equal(build_controller(gentle).steps.separation.growing(final), np.ones(100))


def test_an_mpc_run_without_d_min_says_it_keeps_no_separation() -> None:
    """An empty [limits] table (no v_max, no d_min) warns once, unless limits.unbounded says so."""
    import tomllib

    from mpcform.scenario.load import scenario_from_dict

    data = tomllib.loads(WORKED.read_text())
    data["controller"] = {"kind": "mpc"}
    data["limits"] = {}
    (line,) = [w for w in scenario_from_dict(data).warnings() if w.startswith("limits:")]
    assert line == (
        "limits: no d_min: the mpc run keeps no separation between the drones and no speed bound "
        "(no v_max); set limits.d_min (and v_max), or limits.unbounded = true to run without them"
    )
    data["limits"] = {"v_max": 2.0}
    (line,) = [w for w in scenario_from_dict(data).warnings() if w.startswith("limits:")]
    assert "keeps no separation between the drones;" in line and "speed" not in line
    data["limits"] = {"unbounded": True}
    assert scenario_from_dict(data).separation_warning() is None
    data["limits"] = {}
    assert scenario_from_dict(data).warnings("tracking") == []  # only the mpc keeps d_min
    data["template"] = {"shape": "polygon", "n": 1, "radius": 1.0}
    assert scenario_from_dict(data).separation_warning() is None  # one drone: nothing to separate
