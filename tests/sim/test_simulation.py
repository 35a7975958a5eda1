"""Closed-loop simulation: go-to-goal against eq. 5 and its discrete form, velocity lag, noise."""

import numpy as np
import pytest

from mpcform.control.base import Controller, ControlStep, StepInfo
from mpcform.control.consensus import ConsensusController, ConsensusSettings
from mpcform.control.graph import Graph
from mpcform.control.laws import go_to_goal_closed_form, go_to_goal_discrete
from mpcform.control.tracking import ProportionalController
from mpcform.errors import MPCFormError, ValidationError
from mpcform.formation.geometry import min_segment_distance
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.reference.base import ConstantReference
from mpcform.sim.plant_spec import LagPlantSpec
from mpcform.sim.plants import IdealPlant
from mpcform.sim.simulation import SimulationResult, simulate
from mpcform.sim.trajectory import Trajectory
from mpcform.world.limits import Limits

P0, GOAL, GAIN = np.array([1.0, -2.0, 0.5]), np.array([4.0, 2.0, -1.0]), 1.5
SINGLE = Template(np.zeros((1, 3)))
GOAL_REFERENCE = ConstantReference(SINGLE, FormationState.from_param(GOAL))


class ConstantCommand(Controller):
    """Applies one fixed command (n, d) forever; optionally a bad one."""

    name = "constant"

    def __init__(self, command, dt_s=0.05):
        self.command = np.asarray(command, dtype=float)
        self.reference = ConstantReference(
            Template(np.zeros(self.command.shape)),
            FormationState.from_param(np.zeros(self.command.shape[1])),
        )
        self.dt_s = dt_s

    def step(self, t_s, positions_m):
        return ControlStep(self.command.copy(), StepInfo("law"))


def go_to_goal(dt, duration=4.0, v_max=None, **kwargs):
    ctrl = ProportionalController(GOAL_REFERENCE, GAIN, dt, v_max_mps=v_max)
    return simulate(ctrl, P0[None, :], duration, **kwargs)


def closed_form_error(dt):
    run = go_to_goal(dt)
    return np.abs(run.positions_m[:, 0] - go_to_goal_closed_form(P0, GOAL, GAIN, run.t_s)).max()


def test_go_to_goal_is_exactly_the_discrete_law():
    run = go_to_goal(0.02)
    expected = go_to_goal_discrete(P0, GOAL, GAIN, 0.02, run.t_s.size - 1)
    np.testing.assert_allclose(run.positions_m[:, 0], expected, atol=1e-12)
    # and (1 - k dt)^j written out
    factor = (1 - GAIN * 0.02) ** np.arange(run.t_s.size)
    np.testing.assert_allclose(run.positions_m[:, 0], GOAL + np.outer(factor, P0 - GOAL), atol=1e-12)


def test_go_to_goal_converges_to_eq_5_at_first_order():
    errors = [closed_form_error(dt) for dt in (0.04, 0.02, 0.01)]
    assert errors[0] < 0.2
    for coarse, fine in zip(errors, errors[1:], strict=False):
        assert 1.8 <= coarse / fine <= 2.2


def test_saturated_go_to_goal_flies_straight_at_v_max():
    run = go_to_goal(0.02, duration=10.0, v_max=1.0)
    speeds = np.linalg.norm(run.commands_mps[:, 0], axis=1)
    far = GAIN * np.linalg.norm(GOAL - run.positions_m[:-1, 0], axis=1) > 1.0
    assert far[:100].all() and not far[-1]
    np.testing.assert_allclose(speeds[far], 1.0, rtol=1e-12)
    assert speeds.max() <= 1.0 + 1e-12
    # every position stays on the segment P0 -> GOAL (eq. 7 keeps the direction)
    rel = run.positions_m[:, 0] - P0
    along = rel @ (GOAL - P0) / np.linalg.norm(GOAL - P0) ** 2
    np.testing.assert_allclose(rel, np.outer(along, GOAL - P0), atol=1e-12)
    assert np.all(np.diff(along) >= 0) and 1 - 1e-3 < along[-1] <= 1.0  # no overshoot


def test_result_shapes_and_progress():
    calls = []
    run = go_to_goal(0.1, duration=1.0, t0_s=2.0, progress=lambda j, n: calls.append((j, n)))
    assert run.t_s.shape == (11,) and run.positions_m.shape == (11, 1, 3)
    assert run.commands_mps.shape == (10, 1, 3) and run.reference_m.shape == (11, 1, 3)
    assert len(run.infos) == run.step_times_s.size == 10 and run.controller == "proportional"
    np.testing.assert_allclose(run.t_s, 2.0 + 0.1 * np.arange(11))
    np.testing.assert_allclose(run.reference_m, np.broadcast_to(GOAL, (11, 1, 3)))
    assert calls == [(j, 10) for j in range(1, 11)]
    assert isinstance(run, Trajectory) and (run.n, run.dim, run.steps) == (1, 3, 10)


def test_scale_estimates_are_recorded_at_every_sample_for_the_controllers_that_keep_them():
    ring = Template.polygon(8)
    doubling = ConstantReference(ring, FormationState.from_param([0.0, 0.0], 0.0, 2.0))
    settings = ConsensusSettings(gamma_per_s=3.0, leader_gain_per_s=3.0)  # leader 0, dt 0.05
    run = simulate(ConsensusController(doubling, Graph.ring(8), 0.05, settings), ring.offsets, 1.0)
    s_hat = run.scale_estimates
    assert s_hat is not None and s_hat.shape == (21, 8)
    # eq. 20's estimates by hand: all start at the best fit 1; the leader moves first,
    # s_0 += dt lambda (s* - s_0), and its ring neighbours 1 and 7 follow one step later
    np.testing.assert_array_equal(s_hat[0], 1.0)
    np.testing.assert_allclose(s_hat[1], [1.15, *[1.0] * 7], rtol=0, atol=1e-15)
    np.testing.assert_allclose(s_hat[2, [1, 7]], 1.0 + 0.05 * 3.0 * 0.15, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(s_hat[2, 2:7], 1.0)
    replay = ConsensusController(doubling, Graph.ring(8), 0.05, settings)  # the same steps, by hand
    replay.reset(0.0, run.positions_m[0])
    for j in range(run.steps):
        np.testing.assert_array_equal(s_hat[j], replay.scale_estimates)  # row j: s_hat(t_j)
        replay.step(float(run.t_s[j]), run.positions_m[j])
    np.testing.assert_array_equal(s_hat[-1], replay.scale_estimates)
    assert go_to_goal(0.1, duration=0.3).scale_estimates is None  # a controller without estimates


def test_result_keeps_one_record_per_step():
    run = go_to_goal(0.1, duration=0.3)
    fields = (run.t_s, run.positions_m, run.commands_mps, run.reference_m)
    with pytest.raises(ValidationError, match="3 step infos and step times, got 2"):
        SimulationResult(*fields, run.infos[:2], run.step_times_s, run.controller)
    with pytest.raises(ValidationError, match=r"got 3 and shape \(2,\)"):
        SimulationResult(*fields, run.infos, run.step_times_s[:2], run.controller)
    with pytest.raises(ValidationError, match="trajectory"):
        SimulationResult(run.t_s[:-1], *fields[1:], run.infos, run.step_times_s, run.controller)


def test_lag_is_the_exact_first_order_response():
    """From rest under a constant u: p(t) = p0 + u (t - tau (1 - e^{-t/tau}))."""
    u, tau = np.array([[1.0, -2.0], [0.5, 0.0]]), 0.3
    run = simulate(ConstantCommand(u), np.zeros((2, 2)), 2.0, plant=LagPlantSpec(time_constant_s=tau))
    t = run.t_s[:, None, None]
    np.testing.assert_allclose(run.positions_m, u * (t - tau * (1 - np.exp(-t / tau))), atol=1e-12)
    dense = run.true
    assert dense is not None and dense.t_s.shape == (10 * run.steps + 1,)
    t = dense.t_s[:, None, None]
    np.testing.assert_allclose(dense.positions_m, u * (t - tau * (1 - np.exp(-t / tau))), atol=1e-12)
    np.testing.assert_allclose(dense.velocities_mps, u * (1 - np.exp(-t / tau)), atol=1e-12)


def test_go_to_goal_with_lag_stays_finite_and_converges():
    run = go_to_goal(0.02, duration=20.0, plant=LagPlantSpec(time_constant_s=0.1))
    assert np.all(np.isfinite(run.positions_m))
    assert np.linalg.norm(run.positions_m[-1, 0] - GOAL) < 1e-6
    lagless = go_to_goal(0.02, duration=20.0)
    assert not np.allclose(run.positions_m, lagless.positions_m)


def test_the_ideal_plant_gives_straight_segments_through_every_sample():
    run = go_to_goal(0.05, duration=2.0, noise_std_m=0.01, seed=3)
    dense = run.true
    assert dense is not None
    np.testing.assert_array_equal(dense.t_s[::10], run.t_s)  # the control samples, exactly
    np.testing.assert_array_equal(dense.positions_m[::10], run.positions_m)
    frac = (dense.t_s[1:11] - run.t_s[0]) / (run.t_s[1] - run.t_s[0])
    straight = run.positions_m[0] + frac[:, None, None] * (run.positions_m[1] - run.positions_m[0])
    np.testing.assert_allclose(dense.positions_m[1:10], straight[:-1], atol=0.05)  # up to the kick
    np.testing.assert_allclose(dense.velocities_mps[:10], np.broadcast_to(run.commands_mps[0], (10, 1, 3)))


def test_noise_is_seeded():
    runs = [go_to_goal(0.05, duration=2.0, noise_std_m=0.01, seed=s) for s in (7, 7, 8)]
    np.testing.assert_array_equal(runs[0].positions_m, runs[1].positions_m)
    assert not np.allclose(runs[0].positions_m, runs[2].positions_m)
    assert not np.allclose(runs[0].positions_m, go_to_goal(0.05, duration=2.0).positions_m)


def test_noise_has_the_requested_spread():
    run = simulate(ConstantCommand(np.zeros((2, 3))), np.zeros((2, 3)), 100.0, noise_std_m=0.1)
    steps = np.diff(run.positions_m, axis=0).ravel()  # 2000 steps x 6 coordinates
    assert steps.std() == pytest.approx(0.1, rel=0.03)
    assert abs(steps.mean()) < 5 * 0.1 / np.sqrt(steps.size)


@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_bad_command_stops_the_run(bad):
    with pytest.raises(MPCFormError, match="constant"):
        simulate(ConstantCommand([[bad, 0.0]]), np.zeros((1, 2)), 1.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"initial_positions_m": np.zeros((2, 3))}, "initial.positions"),
        ({"initial_positions_m": [[0.0, np.nan, 0.0]]}, "initial.positions"),
        ({"duration_s": 0.0}, "simulation.duration"),
        ({"noise_std_m": -1.0}, "simulation.noise"),
    ],
)
def test_bad_simulation_input_is_rejected(kwargs, match):
    args = {"initial_positions_m": P0[None, :], "duration_s": 1.0} | kwargs
    with pytest.raises(ValidationError, match=match):
        simulate(ProportionalController(GOAL_REFERENCE, GAIN, 0.1), **args)


class _DroneZeroFalls(IdealPlant):
    """The exact single integrator whose drone 0 stops for good at 1.8 s (it fell): lost."""

    def _advance(self, u, dt, planned):
        if self.t_s >= 1.8 - 1e-9:
            u = u.copy()
            u[0] = 0.0
        return super()._advance(u, dt, planned)

    @property
    def lost_drones(self):
        return np.array([0] if self.t_s >= 1.8 - 1e-9 else [], dtype=int)


def test_the_planner_stops_planning_for_a_drone_the_plant_lost() -> None:
    tpl = Template.polygon(6, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param([0.0, 0.0]))
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5))
    res = simulate(planner, -tpl.offsets, 30.0, plant=_DroneZeroFalls(6, 2))
    assert res.plant_events["planning_stopped_s"] == {0: pytest.approx(1.8)}
    assert np.all(res.commands_mps[18:, 0] == 0.0)  # commanded zero after the step that saw it lost
    pos = res.positions_m
    assert min(min_segment_distance(a, b) for a, b in zip(pos[:-1], pos[1:], strict=True)) >= 0.5 - 1e-6
    np.testing.assert_allclose(pos[-1, 1:], tpl.offsets[1:], atol=0.05)
    kept = simulate(ProportionalController(ref, 0.1, 1.0), -tpl.offsets, 1.0, plant=_DroneZeroFalls(6, 2))
    assert "planning_stopped_s" not in kept.plant_events  # a law keeps commanding every drone
