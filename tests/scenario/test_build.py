"""The controller factory: kind and solver overrides, solver names as scenario keys, backend instances."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from saved_runs import SCENARIOS

from mpcform import MPCSettings, ScenarioError, TrackingController
from mpcform.mpc.strategy import PerDroneSolve
from mpcform.scenario.build import build_controller, check_solver_key
from mpcform.scenario.load import load_scenario
from mpcform.scenario.spec import Scenario
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend

WORKED = SCENARIOS / "worked_example.toml"


def per_drone(scenario: Scenario) -> Scenario:
    """``scenario`` with the MPC in decoupled mode, each drone's QP solved by DAQP."""
    mpc = MPCSettings(gain_per_s=scenario.controller.gain_per_s, coupling="decoupled", solve=PerDroneSolve())
    return dataclasses.replace(scenario, controller=dataclasses.replace(scenario.controller, mpc=mpc))


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
    assert check_solver_key(name) == name


def test_an_unknown_solver_names_the_scenario_key() -> None:
    with pytest.raises(ScenarioError, match="did you mean 'osqp'") as err:
        check_solver_key("osqq")
    assert err.value.field == "controller.solver"
    with pytest.raises(ScenarioError) as err:
        build_controller(load_scenario(WORKED), "mpc", solver="osqq")
    assert err.value.field == "solver"  # the override (--solver), not the file's key


def test_a_backend_instance_is_used_as_it_is() -> None:
    pytest.importorskip("osqp")
    s = load_scenario(WORKED)
    backend = make_backend("osqp", SolverOptions())
    backend.name = "not a registered name"  # no name check for an instance
    planner = build_controller(s, "mpc", solver=backend)
    assert getattr(planner, "solver_name", None) == "not a registered name"
    with pytest.raises(ScenarioError, match="'not a registered name'.* only to the mpc controller"):
        build_controller(s, "tracking", solver=backend)


def test_a_solver_for_a_planner_solving_per_drone_is_an_error() -> None:
    pytest.importorskip("osqp")
    s = per_drone(load_scenario(WORKED))
    assert build_controller(s, "mpc").name == "mpc"
    for solver in ("osqp", make_backend("osqp", SolverOptions())):
        with pytest.raises(ScenarioError, match="'osqp' solves the sparse QP.*set kind = 'sparse'") as err:
            build_controller(s, "mpc", solver=solver)
        assert err.value.field == "solver"


BRAKE = """version = 1
name = "brake"
dim = 2
[template]
shape = "explicit"
offsets = [[-0.35, 0.0], [0.35, 0.0]]
[initial]
positions = [[-5.0, 0.0], [0.35, 0.0]]
[reference]
kind = "constant"
centroid = [0.0, 0.0]
rotation = 0.0
scale = 1.0
[limits]
v_max = 2.0
d_min = 0.5
[controller]
kind = "mpc"
gain = 2.0
horizon = 10
[simulation]
dt = 0.1
duration = 6.0
"""


@pytest.mark.parametrize(
    ("plant", "modelled"), [("lag", True), ("second_order", True), ("quadrotor", True), ("ideal", False)]
)
def test_the_planner_models_the_plants_velocity_loop(plant: str, modelled: bool, tmp_path: Path) -> None:
    """A lag, second-order or quadrotor plant (its hover linearisation) gives the planner its
    velocity loop (``plant_model = false``: none); the ideal plant gives none."""
    from importlib import metadata

    try:
        metadata.distribution("drone-models")
    except metadata.PackageNotFoundError:
        if plant == "quadrotor":
            pytest.skip("needs drone-models: pip install -e '.[flight]'")
    path, table = tmp_path / "brake.toml", f'[plant]\nkind = "{plant}"\n'
    path.write_text(BRAKE + table)
    planner = build_controller(load_scenario(path))
    assert (planner.loop is not None) == modelled  # type: ignore[attr-defined]
    path.write_text(BRAKE.replace('kind = "mpc"', 'kind = "mpc"\nplant_model = false') + table)
    assert build_controller(load_scenario(path)).loop is None  # type: ignore[attr-defined]


def test_a_braking_drone_keeps_d_min_on_a_lag_with_the_loop_model_and_its_braking_profile(
    tmp_path: Path,
) -> None:
    """A drone flying in at 2 m/s onto its goal 0.7 m from a parked partner, lag 0.3 s: it keeps
    d_min 0.5 m and arrives with the velocity loop in the rows, and also planned as a single
    integrator, since it approaches on its braking profile (``mpc.plan.braking_error``: before it,
    eq. 14's braking at k v_max = 4 m/s^2 overshot into the partner, to 0.393 m, 54 true samples)."""
    from mpcform.run.runner import run_scenario

    lag = '[plant]\nkind = "lag"\ntime_constant = 0.3\n'
    path = tmp_path / "brake.toml"
    results = []
    for flag in ("false", "true"):
        path.write_text(BRAKE.replace('kind = "mpc"', f'kind = "mpc"\nplant_model = {flag}') + lag)
        results.append(run_scenario(load_scenario(path)).summary["metrics"])
    without, with_loop = results
    assert without["min_separation_true"] >= 0.5 and without["separation_violations_true"] == 0
    assert with_loop["min_separation_true"] >= 0.5 and with_loop["separation_violations_true"] == 0
    assert with_loop["completion"] == 1.0
