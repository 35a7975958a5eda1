"""Scenario files: bundled scenarios run, every bad input names its key, docs match the schema."""

from __future__ import annotations

import copy
import dataclasses
import math
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mpcform import MPCSettings, ScenarioError, TrackingController
from mpcform.formation.kinematics import forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.scenario.spec import (
    MPC_FIELDS,
    SCHEMA,
    TABLES,
    Scenario,
    build_controller,
    check_solver_name,
    key_reference_markdown,
    load_scenario,
    run_scenario,
    scenario_from_dict,
)
from mpcform.solvers.registry import DEFAULT_SOLVER

ROOT = Path(__file__).resolve().parents[2]
SCENARIOS = sorted((ROOT / "scenarios").glob("*.toml"))
WORKED = ROOT / "scenarios" / "worked_example.toml"
DELETE = object()


def worked_dict() -> dict[str, Any]:
    return tomllib.loads(WORKED.read_text())


def mutated(changes: dict[str, Any]) -> dict[str, Any]:
    """The worked example with ``{"table.key": value}`` changes (DELETE removes the entry)."""
    data = copy.deepcopy(worked_dict())
    for dotted, value in changes.items():
        *tables, key = dotted.split(".")
        node = data
        for t in tables:
            node = node.setdefault(t, {})
        if value is DELETE:
            del node[key]
        else:
            node[key] = value
    return data


def shortened(scenario: Scenario, duration_s: float) -> Scenario:
    return dataclasses.replace(
        scenario, simulation=dataclasses.replace(scenario.simulation, duration_s=duration_s)
    )


# ---- bundled scenarios ---------------------------------------------------------------------
def test_bundled_scenarios_exist() -> None:
    names = {p.stem for p in SCENARIOS}
    assert {"worked_example", "go_to_goal", "spatial_scale_rotation"} <= names


@pytest.mark.parametrize("path", SCENARIOS, ids=lambda p: p.stem)
def test_bundled_scenario_loads_and_runs(path: Path) -> None:
    text = path.read_text()
    assert text.startswith("#"), "every bundled scenario starts with a comment header"
    scenario = load_scenario(path)
    assert scenario.name == path.stem and scenario.source == path
    run = run_scenario(shortened(scenario, 20 * scenario.simulation.dt_s))
    sim = run.simulation
    assert sim.positions_m.shape == (21, scenario.n, scenario.dim)
    assert np.all(np.isfinite(sim.positions_m)) and np.all(np.isfinite(sim.commands_mps))
    assert run.out_dir is None
    assert run.summary["metrics"]["separation_violations"] == 0
    assert run.summary["metrics"]["speed_violations"] == 0


def test_worked_example_ends_on_eq19_with_scale_2() -> None:
    scenario = load_scenario(WORKED)
    sim = run_scenario(scenario).simulation
    root3 = math.sqrt(3.0)
    eq19 = np.array([[5.0 + 2.0, 5.0], [5.0 - 1.0, 5.0 + root3], [5.0 - 1.0, 5.0 - root3]])
    assert sim.t_s[-1] == pytest.approx(10.0)
    assert np.linalg.norm(sim.positions_m[-1] - eq19, axis=1).max() < 1e-3
    # the centroid stays at (5, 5) to machine precision
    assert np.abs(sim.positions_m.mean(axis=1) - 5.0).max() < 1e-12


def test_go_to_goal_saturates_at_start_then_converges() -> None:
    scenario = load_scenario(ROOT / "scenarios" / "go_to_goal.toml")
    sim = run_scenario(scenario).simulation
    v_max = scenario.limits.v_max_mps
    goal = np.array([20.0, 10.0, 5.0])
    u0 = sim.commands_mps[0, 0]
    assert v_max is not None and np.linalg.norm(u0) == pytest.approx(v_max)
    direction = goal - sim.positions_m[0, 0]
    assert np.allclose(u0 / v_max, direction / np.linalg.norm(direction))
    assert np.linalg.norm(sim.positions_m[-1, 0] - goal) < 1e-3


def test_spatial_scenario_reaches_the_goal_formation() -> None:
    scenario = load_scenario(ROOT / "scenarios" / "spatial_scale_rotation.toml")
    rotvec = np.array([1.0, 0.0, 1.0]) * np.pi / 8**0.5  # 90 degrees about (1, 0, 1)
    goal = FormationState.from_param([4.0, 3.0, 3.0], rotvec, 2.0)
    sim = run_scenario(scenario).simulation
    assert np.abs(sim.positions_m[-1] - forward_kinematics(scenario.template, goal)).max() < 1e-2


def test_mpc_reproduces_tracking_when_no_constraint_is_active() -> None:
    pytest.importorskip("mpcform.mpc.planner")
    scenario = shortened(load_scenario(WORKED), 1.0)
    tracking = run_scenario(scenario, controller="tracking")
    mpc = run_scenario(scenario, controller="mpc", solver="osqp")
    assert mpc.summary["controller"] == "mpc" and mpc.summary["solver"] == "osqp"
    assert tracking.summary["solver"] is None
    np.testing.assert_allclose(
        mpc.simulation.commands_mps, tracking.simulation.commands_mps, rtol=0, atol=1e-9
    )


# ---- parsing -------------------------------------------------------------------------------
def test_defaults_and_objects() -> None:
    s = scenario_from_dict(mutated({"seed": DELETE, "name": DELETE}), default_name="fallback")
    assert s.name == "fallback" and s.seed == 0 and s.dim == 2 and s.n == 3
    assert s.controller.kind == "tracking" and s.controller.gain_per_s == 2.0
    assert s.controller.saturate is True and s.controller.solver == DEFAULT_SOLVER
    assert s.controller.mpc == MPCSettings(gain_per_s=2.0)
    assert s.limits.v_max_mps == 3.0 and s.limits.a_max_mps2 is None and s.obstacles == ()
    assert s.simulation.lag_s == 0.0 and s.steps == 500
    assert np.allclose(s.initial_positions_m, forward_kinematics(s.template, s.start))


def test_explicit_positions_start_from_their_best_fit() -> None:
    state = FormationState.from_param([1.0, -2.0], 0.3, 1.5)
    s0 = scenario_from_dict(worked_dict())
    positions = forward_kinematics(s0.template, state).tolist()
    s = scenario_from_dict(mutated({"initial": {"positions": positions}}))
    assert np.allclose(s.initial_positions_m, positions)
    assert np.allclose(s.start.centroid_m, [1.0, -2.0]) and s.start.scale == pytest.approx(1.5)
    assert np.allclose(s.reference.state(0.0).centroid_m, [1.0, -2.0])


def test_perturbation_is_seeded() -> None:
    a = scenario_from_dict(mutated({"initial.perturbation": 0.1, "seed": 7}))
    b = scenario_from_dict(mutated({"initial.perturbation": 0.1, "seed": 7}))
    c = scenario_from_dict(mutated({"initial.perturbation": 0.1, "seed": 8}))
    base = scenario_from_dict(worked_dict())
    assert np.array_equal(a.initial_positions_m, b.initial_positions_m)
    assert not np.array_equal(a.initial_positions_m, c.initial_positions_m)
    assert 0 < np.abs(a.initial_positions_m - base.initial_positions_m).max() < 1.0
    assert np.allclose(a.start.centroid_m, base.start.centroid_m)  # the reference is unperturbed


def test_templates_and_obstacles() -> None:
    grid = scenario_from_dict(mutated({"template": {"shape": "grid", "rows": 2, "cols": 3}}))
    assert grid.n == 6 and grid.template.name == "grid"
    data = mutated({"template": {"shape": "explicit", "offsets": [[1.0, 0.0], [-1.0, 0.0]]}})
    data["obstacles"] = [{"center": [0.0, 9.0], "radius": 0.5}, {"center": [9.0, 0.0], "radius": 1}]
    s = scenario_from_dict(data)
    assert s.n == 2 and len(s.obstacles) == 2 and s.obstacles[1].radius_m == 1.0


def test_build_controller_overrides() -> None:
    s = load_scenario(WORKED)
    assert isinstance(build_controller(s), TrackingController)
    assert build_controller(s, "proportional").name == "proportional"
    with pytest.raises(ScenarioError, match="did you mean 'tracking'") as err:
        build_controller(s, "trackin")
    assert err.value.field == "controller.kind"
    with pytest.raises(ScenarioError, match="only to the mpc controller"):
        build_controller(s, "tracking", solver="osqp")


@pytest.mark.parametrize("name", ["osqp", "piqp", "qpsolvers:clarabel", "casadi:qpoases", "casadi:ipopt"])
def test_solver_names(name: str) -> None:
    assert check_solver_name(name) == name


# ---- bad input -----------------------------------------------------------------------------
NOT_CENTRED = {"shape": "explicit", "offsets": [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]}
BAD_INPUTS: list[tuple[str, dict[str, Any], str, str]] = [
    ("unknown key", {"controller.gian": 2.0}, "controller.gian", "did you mean 'gain'"),
    ("unknown top key", {"sed": 1}, "sed", "did you mean 'seed'"),
    ("unknown table", {"controler": {"kind": "tracking"}}, "controler", "mean 'controller'"),
    ("wrong type", {"controller.gain": "fast"}, "controller.gain", "got 'fast'"),
    ("bool as number", {"template.n": True}, "template.n", "integer"),
    ("float as integer", {"template.n": 3.0}, "template.n", "integer"),
    ("nan", {"controller.gain": float("nan")}, "controller.gain", "finite"),
    ("inf", {"initial.centroid": [5.0, float("inf")]}, "initial.centroid", "finite"),
    ("zero scale", {"initial.scale": 0.0}, "initial.scale", "> 0"),
    ("negative goal scale", {"reference.scale": -1.0}, "reference.scale", "> 0"),
    ("uncentred offsets", {"template": NOT_CENTRED}, "template.offsets", "off by 0.471405"),
    ("gain * dt > 1", {"controller.gain": 100.0}, "controller.gain", "gain * dt"),
    ("missing key", {"simulation.dt": DELETE}, "simulation.dt", "missing"),
    ("missing table", {"simulation": DELETE}, "simulation", "missing table"),
    ("missing version", {"version": DELETE}, "version", "missing"),
    ("bad version", {"version": 2}, "version", "got 2"),
    ("bad dim", {"dim": 4}, "dim", "got 4"),
    ("bad choice", {"controller.kind": "trackng"}, "controller.kind", "did you mean 'tracking'"),
    ("key of another kind", {"reference.kind": "constant"}, "reference.rate", "only to"),
    ("mpc key on tracking", {"controller.horizon": 5}, "controller.horizon", "'mpc'"),
    ("short vector", {"initial.centroid": [5.0]}, "initial.centroid", "2 numbers"),
    ("too few positions", {"initial": {"positions": [[0.0, 0.0]]}}, "initial.positions", "3 rows"),
    ("positions and state", {"initial.positions": [[0, 0], [1, 0], [2, 0]]}, "initial.positions",
     "not both"),
    ("no initial state", {"initial": {"scale": 1.0}}, "initial.centroid", "missing"),
    ("sphere in 2D", {"template": {"shape": "sphere", "n": 4}}, "template.shape", "dim = 3"),
    ("grid layers in 2D", {"template": {"shape": "grid", "rows": 2, "cols": 2, "layers": 2}},
     "template.layers", "one layer"),
    ("obstacles not an array", {"obstacles": {"center": [0, 0], "radius": 1}}, "obstacles",
     "[[obstacles]]"),
    ("bad obstacle", {"obstacles": [{"center": [0, 0], "radius": 0}]}, "obstacles[0].radius",
     "> 0"),
    ("downwash in 2D", {"limits.downwash": 2.0}, "limits.downwash", "dim = 3"),
    ("geofence order", {"limits.geofence_min": [0, 0], "limits.geofence_max": [0, 1]},
     "limits.geofence_max", "geofence_min < geofence_max"),
    ("unknown solver", {"controller.kind": "mpc", "controller.solver": "osqq"},
     "controller.solver", "did you mean 'osqp'"),
    ("solver ignored per drone", {"controller.kind": "mpc", "controller.coupling": "decoupled",
                                  "controller.solver": "osqp"}, "controller.solver", "per_drone = false"),
    ("shorter than a step", {"simulation.duration": 0.01}, "simulation.duration", "one step"),
    ("path in name", {"name": "../x"}, "name", "directory"),
]  # fmt: skip


@pytest.mark.parametrize(("changes", "field", "fragment"), [c[1:] for c in BAD_INPUTS],
                         ids=[c[0] for c in BAD_INPUTS])  # fmt: skip
def test_bad_input_names_the_field(changes: dict[str, Any], field: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(mutated(changes))
    assert err.value.field == field
    assert str(err.value).startswith(f"{field}: ")
    assert fragment in str(err.value)
    assert "\n" not in str(err.value)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ScenarioError, match="no such scenario file") as err:
        load_scenario(path)
    assert err.value.field == str(path)


def test_toml_syntax_error_gives_the_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("version = 1\ndim = 2\n[controller]\ngain = \n")
    with pytest.raises(ScenarioError, match="line 4") as err:
        load_scenario(path)
    assert "TOML syntax error" in str(err.value) and "'gain ='" in str(err.value)


def test_toml_nan_literal(tmp_path: Path) -> None:
    path = tmp_path / "nan.toml"
    path.write_text(WORKED.read_text().replace("gain = 2.0", "gain = nan"))
    with pytest.raises(ScenarioError, match="expected a finite number > 0") as err:
        load_scenario(path)
    assert err.value.field == "controller.gain"


# ---- schema and docs -----------------------------------------------------------------------
def test_committed_key_reference_matches_the_schema() -> None:
    text = (ROOT / "scenarios" / "README.md").read_text()
    committed = text.split("<!-- keys:start -->\n", 1)[1].split("<!-- keys:end -->", 1)[0]
    assert committed == key_reference_markdown(), "regenerate with `mpcform keys`"


def test_every_key_is_documented_and_every_mpc_setting_has_a_key() -> None:
    for table in SCHEMA:
        for key in table.keys:
            assert key.doc and key.type, (table.name, key.name)
            assert f"`{key.name}`" in key_reference_markdown()
    mpc_keys = {k.name for k in TABLES["controller"].keys if "mpc" in k.when or not k.when}
    settings = {MPC_FIELDS.get(k, k) for k in mpc_keys} - {"kind", "solver"}
    assert settings == {f.name for f in dataclasses.fields(MPCSettings)}


def test_scenario_is_frozen() -> None:
    s = load_scenario(WORKED)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.name = "other"  # type: ignore[misc]
    with pytest.raises(ValueError):
        s.initial_positions_m[0, 0] = 1.0
