"""Whole runs: every bundled scenario runs, the worked examples end where the seed says, overrides."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from saved_runs import SCENARIOS, shortened

from mpcform._validate import Array
from mpcform.formation.kinematics import forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.mpc.strategy import as_sparse
from mpcform.run.runner import describe, run_scenario
from mpcform.scenario.load import load_scenario
from mpcform.solvers.base import QPBackend, QPSolution
from mpcform.solvers.registry import make_backend

BUNDLED = sorted(SCENARIOS.glob("*.toml"))
WORKED = SCENARIOS / "worked_example.toml"


def test_bundled_scenarios_exist() -> None:
    names = {p.stem for p in BUNDLED}
    assert {"worked_example", "go_to_goal", "spatial_scale_rotation"} <= names


@pytest.mark.parametrize("path", BUNDLED, ids=lambda p: p.stem)
def test_bundled_scenario_loads_and_runs(path: Path) -> None:
    text = path.read_text()
    assert text.startswith("#"), "every bundled scenario starts with a comment header"
    scenario = load_scenario(path)
    assert scenario.name == path.stem and scenario.source == path
    run = run_scenario(shortened(scenario, 20))
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
    scenario = load_scenario(SCENARIOS / "go_to_goal.toml")
    sim = run_scenario(scenario).simulation
    v_max = scenario.limits.v_max_mps
    goal = np.array([20.0, 10.0, 5.0])
    u0 = sim.commands_mps[0, 0]
    assert v_max is not None and np.linalg.norm(u0) == pytest.approx(v_max)
    direction = goal - sim.positions_m[0, 0]
    assert np.allclose(u0 / v_max, direction / np.linalg.norm(direction))
    assert np.linalg.norm(sim.positions_m[-1, 0] - goal) < 1e-3


def test_spatial_scenario_reaches_the_goal_formation() -> None:
    scenario = load_scenario(SCENARIOS / "spatial_scale_rotation.toml")
    rotvec = np.array([1.0, 0.0, 1.0]) * np.pi / 8**0.5  # 90 degrees about (1, 0, 1)
    goal = FormationState.from_param([4.0, 3.0, 3.0], rotvec, 2.0)
    sim = run_scenario(scenario).simulation
    assert np.abs(sim.positions_m[-1] - forward_kinematics(scenario.template, goal)).max() < 1e-2


def test_mpc_reproduces_tracking_when_no_constraint_is_active() -> None:
    pytest.importorskip("mpcform.mpc.planner")
    scenario = shortened(load_scenario(WORKED), 50)  # 1 s; without a_max (the default ramps a start)
    scenario = dataclasses.replace(scenario, limits=dataclasses.replace(scenario.limits, a_max_mps2=np.inf))
    tracking = run_scenario(scenario, controller="tracking")
    mpc = run_scenario(scenario, controller="mpc", solver="osqp")
    assert mpc.summary["controller"] == "mpc" and mpc.summary["solver"] == "osqp"
    assert tracking.summary["solver"] is None
    np.testing.assert_allclose(
        mpc.simulation.commands_mps, tracking.simulation.commands_mps, rtol=0, atol=1e-9
    )


class Renamed(QPBackend):
    """Solves with ``inner`` under another name (no registered backend is called that)."""

    name = "renamed osqp"

    def __init__(self, inner: QPBackend) -> None:
        super().__init__(inner.options)
        self.inner, self.warm_starts, self.solves = inner, inner.warm_starts, 0

    def setup(self, P: sp.csc_matrix, q: Array, A: sp.csc_matrix, lo: Array, hi: Array) -> None:
        self.inner.setup(P, q, A, lo, hi)

    def update(self, q: Array, lo: Array, hi: Array, A_data: Array) -> None:
        self.inner.update(q, lo, hi, A_data)

    def solve(self, x0: Array | None = None) -> QPSolution:
        self.solves += 1
        return self.inner.solve(x0)


def test_a_backend_instance_drives_the_mpc_as_its_name_would() -> None:
    pytest.importorskip("osqp")
    scenario = shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), 20)
    options = as_sparse(scenario.controller.mpc.strategy).options
    by_name = run_scenario(scenario, solver="osqp")
    backend = Renamed(make_backend("osqp", options))
    by_instance = run_scenario(scenario, solver=backend)
    assert by_instance.summary["solver"] == "renamed osqp" and backend.solves > 0
    np.testing.assert_array_equal(by_instance.simulation.commands_mps, by_name.simulation.commands_mps)


def test_describe_names_drones_template_reference_controller_and_steps() -> None:
    assert describe(load_scenario(WORKED)) == (
        "worked_example: 3 drones, planar polygon template, ExponentialReference, "
        "tracking controller, 500 steps of 0.02 s"
    )


def test_the_summary_records_the_plants_wind(tmp_path: Path) -> None:
    from mpcform.outputs.rundata import load_run

    sc = shortened(load_scenario(SCENARIOS / "swap_spatial_12_quadrotor_wind.toml"), 3)
    wind = run_scenario(sc, tmp_path).summary["plant"]["wind"]
    assert wind["mean_mps"] == sc.plant.wind.mean_mps.tolist() and wind["gust_std_mps"] == 0.5
    assert wind["gust_bound_mps"] == [1.5, 1.5, 1.5] and wind["gust_field"] == sc.plant.wind.gust_field
    saved = load_run(tmp_path).wind
    assert saved is not None and saved[1] == 0.5
    np.testing.assert_array_equal(saved[0], sc.plant.wind.mean_mps)
    calm = run_scenario(shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), 2)).summary["plant"]
    assert "wind" not in calm
