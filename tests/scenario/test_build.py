"""The controller factory: kind and solver overrides, solver names as scenario keys, backend instances."""

from __future__ import annotations

import dataclasses

import pytest
from saved_runs import SCENARIOS

from mpcform import MPCSettings, ScenarioError, TrackingController
from mpcform.scenario.build import build_controller, check_solver_key
from mpcform.scenario.load import load_scenario
from mpcform.scenario.spec import Scenario
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend

WORKED = SCENARIOS / "worked_example.toml"


def per_drone(scenario: Scenario) -> Scenario:
    """``scenario`` with the MPC in decoupled mode, each drone's QP solved by DAQP."""
    mpc = MPCSettings(gain_per_s=scenario.controller.gain_per_s, coupling="decoupled", per_drone=True)
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
        with pytest.raises(ScenarioError, match="'osqp' solves the sparse QP.*per_drone = false") as err:
            build_controller(s, "mpc", solver=solver)
        assert err.value.field == "solver"
