"""Moves between keyframes: turns, the per-DOF limits (budget split), ruckig planning and its errors."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_state, random_template
from scipy.spatial.transform import Rotation

from mpcform.errors import ValidationError
from mpcform.formation.rotation import geodesic, rotation_matrix
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.keyframes import Keyframe, MissionLimits, SpeedBudget
from mpcform.reference.mission import MissionReference
from mpcform.reference.moves import dof_limits, plan_move, turn

ROTATION_LIMITS = MissionLimits({"rotation": 0.7}, {"rotation": 0.9}, {"rotation": 1.1})


# ---- turns --------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(4))
def test_turns_below_half_a_turn_are_the_geodesic(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for dim in (2, 3):
        r0, r1 = random_state(rng, dim).rotation_body_to_world, random_state(rng, dim).rotation_body_to_world
        axis, phi = turn(r0, r1)
        want_axis, want_phi = geodesic(r0, r1)
        np.testing.assert_array_equal(axis, want_axis)
        assert phi == want_phi < np.pi


@pytest.mark.parametrize("angle", [np.pi, -np.pi])
def test_half_turns_pick_a_deterministic_axis(angle: float) -> None:
    planar = MissionReference(
        Template.polygon(3),
        FormationState.from_param([0.0, 0.0]),
        [Keyframe(rotation=angle)],
        limits=ROTATION_LIMITS,
    )
    omega = planar.profile(np.linspace(0.0, planar.duration_s, 3000)).omega_world_radps
    assert omega.min() >= 0.0 and omega.max() > 0.0  # counter-clockwise either way
    for start in ([0.0, 0.0, 0.0], [0.3, -0.2, 0.1]):
        s0 = FormationState.from_param([0.0, 0.0, 0.0], start)
        goal = (Rotation.from_rotvec(start) * Rotation.from_rotvec([0.0, angle, 0.0])).as_rotvec()
        ref = MissionReference(Template.sphere(5), s0, [Keyframe(rotation=goal)], limits=ROTATION_LIMITS)
        w = ref.profile(np.linspace(0.0, ref.duration_s, 3000)).omega_world_radps
        body_axis = s0.rotation_body_to_world.T @ w[np.argmax(np.linalg.norm(w, axis=1))]
        np.testing.assert_allclose(body_axis / np.linalg.norm(body_axis), [0.0, 1.0, 0.0], atol=1e-6)
        np.testing.assert_allclose(
            ref.state(ref.duration_s).rotation_body_to_world,
            Rotation.from_rotvec(goal).as_matrix(),
            atol=1e-12,
        )


def test_half_turn_axes_have_a_positive_leading_component() -> None:
    r0 = rotation_matrix(3, [0.3, -0.2, 0.1])
    for axis in ([0.0, -1.0, 0.0], [1.0, -2.0, 0.5]):
        a = np.array(axis) / np.linalg.norm(axis)
        got, phi = turn(r0, r0 @ rotation_matrix(3, np.pi * a))
        assert phi == np.pi
        np.testing.assert_allclose(got, a * np.sign(a[np.flatnonzero(a)[0]]), atol=1e-9)
    assert turn(np.eye(2), -np.eye(2))[0].tolist() == [1.0]


# ---- per-DOF limits -----------------------------------------------------------------------------
def test_the_budget_gives_every_moving_dof_the_same_normalised_rate() -> None:
    """``v_k = |Delta_k| V / K`` with ``K = max_i K_i``; resting DOFs get 1 (ruckig needs a limit)."""
    offsets = Template.polygon(3, 2.0).offsets  # |r_i| = 2 m
    x0, x1 = np.array([0.0, 0.0, 0.0, 1.0, 0.0]), np.array([3.0, 4.0, 0.5, 1.5, 0.0])
    budget = SpeedBudget(2.0, 0.5)  # V = 1 m/s, A = 1 m/s^2, J = 2 m/s^3
    k_max = 5.0 + (0.5 + 1.5 * 0.5) * 2.0  # ||Delta c|| + (|Delta s| + s_hi |Delta phi|) max|rho|
    limits = dof_limits(x0, x1, offsets, offsets, MissionLimits(), budget)
    for lim, total in zip(limits, budget.budgets, strict=True):
        np.testing.assert_allclose(lim[:4], np.abs(x1 - x0)[:4] * total / k_max, rtol=1e-14)
        assert lim[4] == 1.0
    # the centroid's share is its norm, not each axis
    assert np.hypot(*limits[0][:2]) == pytest.approx(5.0 / k_max)


def test_explicit_limits_and_the_budget_the_smaller_wins() -> None:
    offsets = Template.polygon(3, 1.0).offsets
    x0, x1 = np.array([0.0, 0.0, 0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.0, 3.0, 0.0])
    explicit = MissionLimits({"scale": 0.1}, {"scale": 10.0}, {"scale": 10.0})
    vel, acc, jerk = dof_limits(x0, x1, offsets, offsets, explicit, SpeedBudget(1.0, 1.0))
    assert vel[3] == 0.1  # explicit (budget: 1 m/s over a 1 m lever arm = 1 /s)
    assert acc[3] == pytest.approx(1.0) and jerk[3] == pytest.approx(2.0)  # derived
    assert dof_limits(x0, x1, offsets, offsets, explicit, None)[1][3] == 10.0


def test_centroid_limit_bounds_the_norm_not_each_axis() -> None:
    """A diagonal move reaches the centroid speed limit in norm, not sqrt(3) times it."""
    limits = MissionLimits({"centroid": 2.0}, {"centroid": 1.0}, {"centroid": 1.0})
    start = FormationState.from_param(np.zeros(3))
    ref = MissionReference(
        Template.sphere(4), start, [Keyframe(centroid_m=[20.0, 20.0, 20.0])], limits=limits
    )
    speed = np.linalg.norm(ref.profile(np.linspace(0.0, ref.duration_s, 3000)).centroid_velocity_mps, axis=1)
    assert speed.max() == pytest.approx(2.0, rel=1e-9)


@pytest.mark.parametrize("seed", range(8))
def test_random_missions_with_derived_limits_stay_below_the_budget(seed: int) -> None:
    rng = np.random.default_rng(seed)
    dim, n = (2, 3)[seed % 2], 3 + seed % 4
    tpl = random_template(rng, n, dim)
    start = random_state(rng, dim)
    frames = []
    for _ in range(3):
        state = random_state(rng, dim)
        switch = random_template(rng, n, dim) if rng.random() < 0.4 else None
        frames.append(Keyframe(state.centroid_m, state.rotation_param, state.scale, template=switch))
    budget = SpeedBudget(rng.uniform(0.5, 5.0), rng.uniform(0.2, 1.0))
    ref = MissionReference(tpl, start, frames, budget=budget, d_min_m=None)
    speed = np.linalg.norm(ref.targets(np.linspace(0.0, ref.duration_s, 4000))[1], axis=-1)
    assert speed.max() <= budget.budgets[0] * (1 + 1e-9)


# ---- planning -----------------------------------------------------------------------------------
def test_a_planned_move_is_rest_to_rest_on_the_target() -> None:
    offsets = Template.polygon(4).offsets
    x0, x1 = np.array([0.0, 0.0, 0.0, 1.0, 0.0]), np.array([2.0, -1.0, 0.4, 1.2, 0.0])
    traj = plan_move(0, x0, x1, offsets, offsets, MissionLimits(), SpeedBudget(1.0))
    start, end = traj.at_time(0.0), traj.at_time(traj.duration)
    np.testing.assert_allclose(start[0], x0, atol=1e-12)
    np.testing.assert_allclose(end[0], x1, atol=1e-9)
    np.testing.assert_allclose([start[1], start[2], end[1], end[2]], 0.0, atol=1e-9)


def test_a_moving_dof_without_a_limit_names_the_missing_limit() -> None:
    offsets = Template.polygon(3).offsets
    x0, x1 = np.array([0.0, 0.0, 0.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.0, 2.0, 0.0])
    with pytest.raises(ValidationError, match=r"reference\.max_velocity\.scale: keyframe 3 moves"):
        plan_move(3, x0, x1, offsets, offsets, MissionLimits({"centroid": 1.0}), None)


def test_ruckig_failures_become_validation_errors() -> None:
    tiny = MissionLimits({"scale": 1e-300}, {"scale": 1e-300}, {"scale": 1e-300})
    start = FormationState.from_param([0.0, 0.0])
    with pytest.raises(ValidationError, match=r"reference\.keyframes\[1\]\.scale"):
        MissionReference(
            Template.polygon(3), start, [Keyframe(hold_s=1.0), Keyframe(scale=1e300)], limits=tiny
        )
