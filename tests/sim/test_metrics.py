"""Run metrics on a hand-built run whose distances, speeds and errors are known by hand; the
best-fit scale on exact formations and on the worked example."""

import dataclasses

import numpy as np
import pytest
from helpers import random_state, random_template
from saved_runs import SCENARIOS, shortened

from mpcform.control.base import StepInfo
from mpcform.formation.kinematics import forward_kinematics
from mpcform.mpc.step_info import MPCStepInfo
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario
from mpcform.sim.metrics import (
    command_speeds_mps,
    fitted_scales,
    min_separations_m,
    run_metrics,
    tracking_cost_m2s,
    tracking_errors_m,
)
from mpcform.sim.simulation import SimulationResult
from mpcform.world.limits import Limits
from mpcform.world.world import World

# Three planar drones A, B, C over four samples (dt = 1 s).
# p0 -> p1: A (0,0) -> (2,1) and B (2,0) -> (0,0) pass each other: their relative position runs
# from (-2, 0) to (2, 1), closest to the origin at (-2/17, 8/17), 2 / sqrt(17) ~ 0.485 apart.
# p1 -> p2: C descends to (0, 0.6), 0.6 above B. p3 holds p2.
POSITIONS = np.array(
    [
        [[0.0, 0.0], [2.0, 0.0], [0.0, 3.0]],  # AB 2, AC 3, BC sqrt(13)
        [[2.0, 1.0], [0.0, 0.0], [0.0, 3.0]],  # AB sqrt(5), AC sqrt(8), BC 3
        [[2.0, 1.0], [0.0, 0.0], [0.0, 0.6]],  # AB sqrt(5), AC sqrt(4.16), BC 0.6
        [[2.0, 1.0], [0.0, 0.0], [0.0, 0.6]],
    ]
)
REFERENCE = POSITIONS.copy()
REFERENCE[0, 0] += [0.3, 0.4]  # A is 0.5 m off at t = 0
REFERENCE[3, 2] += [0.0, 0.1]  # C is 0.1 m off at the end
RESULT = SimulationResult(
    t_s=np.arange(4.0),
    positions_m=POSITIONS,
    commands_mps=np.diff(POSITIONS, axis=0),  # speeds (sqrt5, 2, 0), (0, 0, 2.4), 0
    reference_m=REFERENCE,
    infos=(
        MPCStepInfo("qp", max_slack_m=0.01),
        StepInfo("fast_path"),
        MPCStepInfo(
            "fallback", max_slack_m=0.2, growth_slack_m=0.03, wind_shift_m=0.02, growth_exceeded=True
        ),
    ),
    step_times_s=np.array([0.003, 0.001, 0.005]),
    controller="test",
)


def test_tracking_and_separation_metrics():
    m = run_metrics(RESULT)
    assert m["final_tracking_error"] == pytest.approx(0.1)
    assert m["max_tracking_error"] == pytest.approx(0.5)
    assert m["min_separation"] == pytest.approx(0.6)
    assert m["min_separation_segments"] == pytest.approx(2 / np.sqrt(17))
    assert m["max_speed"] == pytest.approx(2.4)
    assert m["separation_violations"] == 0 and m["speed_violations"] == 0


@pytest.mark.parametrize(
    ("d_min", "violations"),
    [
        (0.5, 0),
        (1.0, 2),  # BC at samples 2 and 3
        (2.0, 2),  # pairs exactly at d_min (AB at sample 0) are not violations
        (2.1, 5),  # sample 0: AB; 2 and 3: AC, BC
        (2.3, 8),  # sample 0: AB; 1: AB; 2 and 3: AB, AC, BC
    ],
)
def test_separation_violations_count_sample_pairs(d_min, violations):
    assert run_metrics(RESULT, World(Limits(d_min_m=d_min)))["separation_violations"] == violations


# speeds above v_max over the (step, drone) pairs; B flies at exactly 2 m/s: no violation
@pytest.mark.parametrize(("v_max", "violations"), [(3.0, 0), (2.4, 0), (2.0, 2), (1.0, 3)])
def test_speed_violations_count_step_drones(v_max, violations):
    assert run_metrics(RESULT, World(Limits(v_max_mps=v_max)))["speed_violations"] == violations


def test_solver_and_timing_metrics():
    m = run_metrics(RESULT, World(Limits(3.0, 0.5)))
    assert (m["qp_solves"], m["fast_path_steps"], m["solver_failures"]) == (2, 1, 1)
    assert m["max_slack"] == pytest.approx(0.2) and m["slack_steps"] == 2
    assert m["max_growth_slack"] == pytest.approx(0.03) and m["growth_slack_steps"] == 1
    assert m["max_wind_shift"] == pytest.approx(0.02) and m["growth_exceeded_steps"] == 1
    assert set(m["step_time_ms"]) == {"qp", "fast_path", "fallback"}
    assert m["step_time_ms"]["qp"] == pytest.approx({"median": 3.0, "p90": 3.0, "max": 3.0})
    assert m["step_time_ms"]["fallback"]["max"] == pytest.approx(5.0)


def test_single_drone_has_no_separation():
    single = SimulationResult(
        np.arange(2.0),
        np.zeros((2, 1, 2)),
        np.zeros((1, 1, 2)),
        np.zeros((2, 1, 2)),
        (StepInfo("law"),),
        np.array([0.001]),
        "test",
    )
    m = run_metrics(single, World(Limits(1.0, 0.5)))
    assert m["min_separation"] is None and m["min_separation_segments"] is None
    assert m["separation_violations"] == 0 and m["qp_solves"] == 0


def test_series_are_the_per_sample_values_behind_the_metrics():
    errors = np.zeros((4, 3))
    errors[0, 0], errors[3, 2] = 0.5, 0.1
    np.testing.assert_allclose(tracking_errors_m(RESULT), errors, atol=1e-15)
    np.testing.assert_allclose(min_separations_m(RESULT), [2.0, np.sqrt(5.0), 0.6, 0.6])
    speeds = [[np.sqrt(5.0), 2.0, 0.0], [0.0, 0.0, 2.4], [0.0, 0.0, 0.0]]
    np.testing.assert_allclose(command_speeds_mps(RESULT), speeds)
    m = run_metrics(RESULT)
    assert m["max_tracking_error"] == tracking_errors_m(RESULT).max()
    assert m["min_separation"] == min_separations_m(RESULT).min()
    assert m["max_speed"] == command_speeds_mps(RESULT).max()


def test_tracking_cost_is_the_trapezoid_of_the_squared_errors():
    # squared errors 0.25, 0, 0, 0.01 at t = 0, 1, 2, 3 s
    assert tracking_cost_m2s(RESULT) == pytest.approx(0.5 * 0.25 + 0.5 * 0.01, rel=1e-12)
    slower = dataclasses.replace(RESULT, t_s=2.0 * RESULT.t_s)
    assert tracking_cost_m2s(slower) == pytest.approx(2.0 * tracking_cost_m2s(RESULT), rel=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_fitted_scales_recover_exact_formations(dim):
    rng = np.random.default_rng(dim)
    template = random_template(rng, 5, dim)
    states = [random_state(rng, dim) for _ in range(4)]
    positions = np.stack([forward_kinematics(template, s) for s in states])
    shifted = template.offsets + 3.0  # offsets are centred before the fit
    np.testing.assert_allclose(fitted_scales(shifted, positions), [s.scale for s in states], rtol=1e-9)


def test_scale_follows_the_worked_example():
    scenario = shortened(load_scenario(SCENARIOS / "worked_example.toml"), 200)
    sim = run_scenario(scenario).simulation
    fitted = fitted_scales(np.asarray(scenario.template.offsets), sim.positions_m)
    scale_ref = scenario.reference.profile(sim.t_s).scale
    assert np.allclose(fitted, scale_ref, atol=0.02)  # s(t) = 2 - e^-t, tracked within O(dt)
    assert fitted[-1] == pytest.approx(2.0 - np.exp(-sim.t_s[-1]), abs=1e-2)
