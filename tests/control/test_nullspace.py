"""Null-space secondary objectives (corrected eq. 15): zero formation velocity, objectives, scenario."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from mpcform import (
    ExponentialReference,
    FormationState,
    NullSpaceController,
    NullSpaceSettings,
    ScenarioError,
    Template,
    TrackingController,
    ValidationError,
    simulate,
)
from mpcform.control.nullspace import project_secondary, repulsion_velocity
from mpcform.formation.geometry import min_pair_distance
from mpcform.formation.kinematics import fit_formation, formation_jacobian, forward_kinematics, jacobian_pinv
from mpcform.run.runner import run_scenario
from mpcform.scenario.build import build_controller
from mpcform.scenario.load import load_scenario, scenario_from_dict
from tests.helpers import random_state, random_template

ROOT = Path(__file__).resolve().parents[2]
SPATIAL = ROOT / "scenarios" / "spatial_nullspace_repulsion.toml"


def assert_no_formation_velocity(jac: np.ndarray, secondary: np.ndarray) -> None:
    """``J^+ N u_sec = 0`` and ``J^T N u_sec = 0`` relative to the size of the contribution."""
    v = secondary.reshape(-1)
    scale = max(1.0, float(np.abs(v).max()))
    assert np.abs(jacobian_pinv(jac).matrix @ v).max() < 1e-12 * scale
    assert np.abs(jac.T @ v).max() < 1e-12 * scale * max(1.0, float(np.abs(jac).max()))
    assert np.abs(secondary.sum(axis=0)).max() < 1e-12 * scale  # the centroid does not move


# ---- the projection -------------------------------------------------------------------------
@given(st.integers(0, 2**32 - 1), st.integers(1, 9), st.sampled_from([2, 3]))
def test_secondary_has_zero_formation_velocity(seed: int, n: int, dim: int) -> None:
    rng = np.random.default_rng(seed)
    tpl = random_template(rng, n, dim)
    jac = formation_jacobian(tpl, random_state(rng, dim))
    assert_no_formation_velocity(jac, project_secondary(jac, rng.normal(size=(n, dim))))


@pytest.mark.parametrize(
    ("template", "rank"),
    [
        (Template.line(5, 1.0, 3), 6),
        (Template.line(2, 1.0, 3), 6),
        (Template.line(4, 1.0, 2), 4),
        (Template(np.zeros((1, 3))), 3),
        (Template.polygon(4, 1.0, 3), 7),
    ],
    ids=["collinear-3d", "two-drones-3d", "collinear-2d", "one-drone", "planar-square-in-3d"],
)
def test_rank_deficient_jacobians(template: Template, rank: int) -> None:
    rng = np.random.default_rng(7)
    jac = formation_jacobian(template, random_state(rng, template.dim))
    assert jacobian_pinv(jac).rank == rank
    u_sec = rng.normal(size=(template.n, template.dim))
    secondary = project_secondary(jac, u_sec)
    assert_no_formation_velocity(jac, secondary)
    # the null space is as large as it should be: d n - rank
    n_dims = template.n * template.dim - rank
    shape = (template.n, template.dim)
    projector = np.column_stack(
        [project_secondary(jac, e.reshape(shape)).ravel() for e in np.eye(shape[0] * shape[1])]
    )
    assert np.linalg.matrix_rank(projector, tol=1e-9) == n_dims  # a projector: singular values 0 or 1


def test_repulsion_velocity() -> None:
    p = np.array([[0.0, 0.0], [0.6, 0.0], [5.0, 0.0], [5.0, 0.0]])
    u = repulsion_velocity(p, radius_m=1.0, gain_per_s=2.0)
    np.testing.assert_allclose(u[0], [-0.8, 0.0])  # 2 * (1 - 0.6) away from drone 1
    np.testing.assert_allclose(u[1], [0.8, 0.0])
    np.testing.assert_array_equal(u[2:], 0.0)  # coincident drones have no direction: skipped
    np.testing.assert_allclose(u.sum(axis=0), 0.0)
    np.testing.assert_array_equal(repulsion_velocity(p[:1], 1.0, 1.0), 0.0)


# ---- the controller ---------------------------------------------------------------------------
def spatial_case() -> tuple[Template, ExponentialReference, np.ndarray]:
    tpl = Template.sphere(8)
    start = np.array([[x, y, 0.0] for x in (0.0, 0.7) for y in (0.0, 0.7, 1.4, 2.1)])
    goal = FormationState.from_param([0.35, 1.05, 3.0], [0.0, 0.0, 0.4], 1.5)
    return tpl, ExponentialReference(tpl, fit_formation(tpl, start).state, goal, 0.5), start


@pytest.mark.parametrize("objective", ["repulsion", "energy"])
def test_centroid_moves_exactly_as_under_eq14(objective: str) -> None:
    tpl, ref, start = spatial_case()
    settings = NullSpaceSettings(
        objective=objective, repulsion_radius_m=1.0, repulsion_gain_per_s=2.0, energy_weight=0.5
    )
    ns = simulate(NullSpaceController(ref, 0.02, settings), start, 6.0)
    tracking = simulate(TrackingController(ref, 1.0, 0.02), start, 6.0)
    np.testing.assert_allclose(ns.positions_m.mean(axis=1), tracking.positions_m.mean(axis=1), atol=1e-12)
    assert not np.allclose(ns.positions_m, tracking.positions_m)  # the secondary term did act


def test_every_step_secondary_has_zero_formation_velocity() -> None:
    tpl, ref, start = spatial_case()
    ctrl = NullSpaceController(ref, 0.02, NullSpaceSettings(objective="repulsion", repulsion_radius_m=1.0))
    p = start.copy()
    active = 0
    for j in range(200):
        step = ctrl.step(0.02 * j, p)
        np.testing.assert_allclose(step.command_mps, ctrl.last_primary_mps + ctrl.last_secondary_mps)
        assert_no_formation_velocity(ctrl.last_jacobian, ctrl.last_secondary_mps)
        active += bool(np.abs(ctrl.last_secondary_mps).max() > 1e-6)
        p = p + 0.02 * step.command_mps
    assert active > 50


def test_repulsion_keeps_the_take_off_separated() -> None:
    scenario = load_scenario(SPATIAL)
    ctrl = build_controller(scenario)
    assert isinstance(ctrl, NullSpaceController) and ctrl.settings.objective == "repulsion"
    nullspace = run_scenario(scenario)
    tracking = run_scenario(scenario, controller="tracking")
    d_min = scenario.limits.d_min_m
    assert tracking.summary["metrics"]["min_separation"] < 0.35  # eq. 14 alone passes 0.34 m
    metrics = nullspace.summary["metrics"]
    assert d_min is not None and metrics["min_separation"] > d_min and metrics["separation_violations"] == 0
    assert metrics["final_tracking_error"] < 1e-3  # the feedback still reaches the formation
    np.testing.assert_allclose(
        nullspace.simulation.positions_m.mean(axis=1),
        tracking.simulation.positions_m.mean(axis=1),
        atol=1e-12,
    )


def test_energy_objective_gives_the_minimum_norm_command_with_the_same_formation_velocity() -> None:
    tpl, ref, start = spatial_case()
    jac = formation_jacobian(tpl, fit_formation(tpl, start).state)
    pinv = jacobian_pinv(jac).matrix
    tracking = TrackingController(ref, 1.0, 0.02).step(0.0, start).command_mps.reshape(-1)
    full = NullSpaceController(ref, 0.02, NullSpaceSettings(objective="energy")).step(0.0, start)
    u = full.command_mps.reshape(-1)
    np.testing.assert_allclose(pinv @ u, pinv @ tracking, atol=1e-12)
    np.testing.assert_allclose(u, jac @ (pinv @ tracking), atol=1e-12)  # u = J J^+ u_14
    assert np.linalg.norm(u) < np.linalg.norm(tracking)
    zero = NullSpaceController(ref, 0.02, NullSpaceSettings(objective="energy", energy_weight=0.0))
    np.testing.assert_allclose(zero.step(0.0, start).command_mps.reshape(-1), tracking, atol=1e-14)


def test_no_objective_is_eq14_and_saturation_is_counted() -> None:
    tpl, ref, start = spatial_case()
    plain = simulate(NullSpaceController(ref, 0.02), start, 1.0)
    tracking = simulate(TrackingController(ref, 1.0, 0.02), start, 1.0)
    np.testing.assert_array_equal(plain.positions_m, tracking.positions_m)
    settings = NullSpaceSettings(objective="repulsion", repulsion_radius_m=1.0)
    capped = simulate(NullSpaceController(ref, 0.02, settings, v_max_mps=0.5), start, 1.0)
    assert np.linalg.norm(capped.commands_mps, axis=-1).max() <= 0.5 * (1 + 1e-12)
    assert capped.infos[0].saturated > 0 and capped.infos[0].mode == "law"


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"objective": "repulsion"}, "controller.repulsion_radius"),
        ({"objective": "comfort"}, "controller.objective"),
        ({"energy_weight": 1.5}, "controller.energy_weight"),
        ({"energy_weight": -0.1}, "controller.energy_weight"),
        ({"repulsion_gain_per_s": 0.0}, "controller.repulsion_gain"),
        ({"feedforward": "magic"}, "controller.feedforward"),
        ({"gain_per_s": 0.0}, "controller.gain"),
    ],
)
def test_settings_validation(kwargs: dict[str, Any], field: str) -> None:
    with pytest.raises(ValidationError) as err:
        NullSpaceSettings(**kwargs)
    assert err.value.field == field


def test_gain_dt_is_checked() -> None:
    tpl, ref, _ = spatial_case()
    with pytest.raises(ValidationError, match="gain \\* dt"):
        NullSpaceController(ref, 0.5, NullSpaceSettings(gain_per_s=3.0))


# ---- scenario keys ------------------------------------------------------------------------------
def spatial_dict(**controller: Any) -> dict[str, Any]:
    data = tomllib.loads(SPATIAL.read_text())
    data["controller"] = {"kind": "nullspace", **controller}
    return data


def test_repulsion_radius_defaults_to_one_and_a_half_d_min() -> None:
    s = scenario_from_dict(spatial_dict(objective="repulsion"))
    settings = s.controller.nullspace
    assert settings is not None and settings.repulsion_radius_m == pytest.approx(0.75)
    data = spatial_dict(objective="repulsion")
    del data["limits"]["d_min"]
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(data)
    assert err.value.field == "controller.repulsion_radius" and "d_min" in str(err.value)
    plain = scenario_from_dict(spatial_dict())
    assert plain.controller.nullspace is not None and plain.controller.nullspace.objective == "none"


@pytest.mark.parametrize(
    ("controller", "field", "fragment"),
    [
        ({"energy_weight": 2.0}, "controller.energy_weight", "[0, 1]"),
        ({"objective": "energi"}, "controller.objective", "did you mean 'energy'"),
        ({"gamma": 1.0}, "controller.gamma", "'consensus'"),
    ],
)
def test_scenario_errors_name_the_key(controller: dict[str, Any], field: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(spatial_dict(**controller))
    assert err.value.field == field and fragment in str(err.value)


def test_other_controllers_run_the_nullspace_scenario() -> None:
    scenario = load_scenario(SPATIAL)
    assert build_controller(scenario, "tracking").name == "tracking"
    start = forward_kinematics(scenario.template, scenario.start)
    assert fit_formation(scenario.template, start).residual_rms_m < 1e-12
    assert min_pair_distance(scenario.initial_positions_m) == pytest.approx(0.7)
