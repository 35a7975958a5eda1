"""References: drone targets and their velocities (finite differences), limits, clamping."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import random_state, random_template
from hypothesis import given
from hypothesis import strategies as st

from mpcform.errors import ValidationError
from mpcform.formation.kinematics import drone_velocities, forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.reference.base import (
    ROW_ADD_MIN_N,
    ConstantReference,
    ExponentialReference,
    Reference,
    add_per_time,
    spin_world,
)

H = 1e-5
TIMES = np.array([0.05, 0.3, 1.0, 2.5, 6.0])


def random_reference(seed, dim, rate=0.8):
    """An exponential reference changing centroid, rotation and scale at once."""
    rng = np.random.default_rng(seed)
    tpl = random_template(rng, 5, dim)
    return ExponentialReference(tpl, random_state(rng, dim), random_state(rng, dim), rate)


def assert_same_state(a, b, atol=1e-12):
    np.testing.assert_allclose(a.centroid_m, b.centroid_m, atol=atol)
    np.testing.assert_allclose(a.rotation_body_to_world, b.rotation_body_to_world, atol=atol)
    assert a.scale == pytest.approx(b.scale, abs=atol)


@given(st.integers(0, 2**32 - 1), st.sampled_from([2, 3]))
def test_target_velocities_are_derivatives_of_target_positions(seed, dim):
    ref = random_reference(seed, dim)
    pos, vel = ref.targets(TIMES)
    assert pos.shape == vel.shape == (TIMES.size, 5, dim)
    plus, _ = ref.targets(TIMES + H)
    minus, _ = ref.targets(TIMES - H)
    np.testing.assert_allclose(vel, (plus - minus) / (2 * H), atol=1e-7)


@given(st.integers(0, 2**32 - 1), st.sampled_from([2, 3]))
def test_targets_are_the_formation_of_the_reference_state(seed, dim):
    """p* = f(xi_d(t)) (eq. 13) and p_dot* = J(xi_d) xi_dot_d (eq. 14 feedforward)."""
    ref = random_reference(seed, dim)
    pos, vel = ref.targets(TIMES)
    for j, t in enumerate(TIMES):
        state = ref.state(t)
        np.testing.assert_allclose(pos[j], forward_kinematics(ref.template, state), atol=1e-12)
        expected = drone_velocities(ref.template, state, ref.velocity(t))
        np.testing.assert_allclose(vel[j], expected, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_exponential_reference_starts_at_start_and_tends_to_goal(dim):
    ref = random_reference(11, dim)
    assert_same_state(ref.state(0.0), ref.start)
    assert_same_state(ref.state(60.0), ref.goal, atol=1e-9)
    np.testing.assert_allclose(ref.velocity(60.0), 0.0, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_negative_times_are_clamped(dim):
    ref = random_reference(5, dim)
    assert_same_state(ref.state(-3.0), ref.state(0.0), atol=0.0)
    for got, expected in zip(ref.targets([-1.0, -0.1]), ref.targets([0.0, 0.0]), strict=True):
        np.testing.assert_array_equal(got, expected)


@pytest.mark.parametrize("times", [np.nan, [0.0, np.inf], [1.0 + 2.0j], "0", [[0.0, 1.0]]])
def test_targets_refuse_times_that_are_no_real_finite_numbers(times):
    """A NaN time gave NaN positions; a complex one lost its imaginary part."""
    rng = np.random.default_rng(3)
    tpl = random_template(rng, 4, 2)
    references = [random_reference(7, 2), ConstantReference(tpl, random_state(rng, 2))]
    for ref in references:
        with pytest.raises(ValidationError, match=r"^times_s: expected (real|finite) times \[s\]"):
            ref.targets(times)


def test_scale_follows_eq_16():
    tpl = Template.polygon(3)
    start = FormationState.from_param([5.0, 5.0], 0.0, 1.0)
    ref = ExponentialReference(tpl, start, FormationState.from_param([5.0, 5.0], 0.0, 2.0), 1.5)
    for t in TIMES:
        s = 2.0 + (1.0 - 2.0) * np.exp(-1.5 * t)
        assert ref.state(t).scale == pytest.approx(s, rel=1e-14)
        np.testing.assert_allclose(ref.velocity(t), [0, 0, 0, 1.5 * (2.0 - s)], atol=1e-14)


def test_planar_rotation_takes_the_short_way():
    tpl = Template.polygon(3)
    start = FormationState.from_param([0.0, 0.0], 3.0)
    ref = ExponentialReference(tpl, start, FormationState.from_param([0.0, 0.0], -3.0), 1.0)
    # from 3 rad to -3 rad the short way is +(2 pi - 6) rad, through pi
    assert ref.velocity(0.0)[2] == pytest.approx(2 * np.pi - 6.0)
    assert float(ref.state(60.0).rotation_param) == pytest.approx(-3.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_constant_reference_holds_the_goal(dim):
    tpl = Template.polygon(4, dim=dim)
    goal = random_state(np.random.default_rng(1), dim)
    pos, vel = ConstantReference(tpl, goal).targets([0.0, 1.0, 7.5])
    np.testing.assert_allclose(pos, np.broadcast_to(forward_kinematics(tpl, goal), pos.shape))
    np.testing.assert_array_equal(vel, 0.0)


@pytest.mark.parametrize(("dim", "n"), [(2, 4), (3, 20), (3, 300)])
def test_constant_reference_targets_are_the_general_sum_bit_for_bit(dim, n):
    """Its targets, computed once, are the eq. 13 sum of :meth:`Reference.targets` at every time
    (signed zeros included) and fresh arrays each call."""
    rng = np.random.default_rng(n)
    held = ConstantReference(random_template(rng, n, dim), random_state(rng, dim))
    for times in ([0.0], 2.5 + 0.1 * np.arange(11), np.linspace(0.0, 9.0, 101)):
        mine, general = held.targets(times), Reference.targets(held, times)
        assert [a.tobytes() for a in mine] == [a.tobytes() for a in general]
    first, again = held.targets([0.0, 1.0]), held.targets([0.0, 1.0])
    assert not np.shares_memory(first[0], again[0])


def test_a_constant_reference_with_its_own_profile_gets_that_profiles_targets():
    """A subclass that moves the centroid (as a test of the planner does) is not held at the goal."""

    class Drifting(ConstantReference):
        def profile(self, times_s):
            v = np.ones((len(times_s), 2))
            return replace(super().profile(times_s), centroid_m=times_s[:, None] * v, centroid_velocity_mps=v)

    drifting = Drifting(Template.polygon(4, dim=2), FormationState.from_param(np.zeros(2)))
    pos, vel = drifting.targets([0.0, 2.0])
    np.testing.assert_allclose(pos[1] - pos[0], 2.0)
    np.testing.assert_allclose(vel, 1.0)


@pytest.mark.parametrize(
    ("build", "match"),
    [
        (lambda tpl, p, s: ExponentialReference(tpl, p, p, 0.0), "reference.rate"),
        (lambda tpl, p, s: ExponentialReference(tpl, p, p, -1.0), "reference.rate"),
        (lambda tpl, p, s: ExponentialReference(tpl, s, p, 1.0), "reference.start"),
        (lambda tpl, p, s: ExponentialReference(tpl, p, s, 1.0), "reference"),
        (lambda tpl, p, s: ConstantReference(tpl, s), "reference"),
        (lambda tpl, p, s: ConstantReference(tpl, [0.0, 0.0]), "reference"),
    ],
)
def test_bad_references_are_rejected(build, match):
    planar, spatial = FormationState.from_param([0.0, 0.0]), FormationState.from_param([0.0] * 3)
    with pytest.raises(ValidationError, match=match):
        build(Template.polygon(3), planar, spatial)


def test_start_positions_are_the_targets_at_time_zero() -> None:
    tpl = Template.polygon(4, 2.0)
    start = FormationState.from_param([1.0, 2.0], 0.5, 1.0)
    goal = FormationState.from_param([5.0, 0.0], 0.0, 2.0)
    moving = ExponentialReference(tpl, start, goal, 1.0)
    assert np.allclose(moving.start_positions_m(), forward_kinematics(tpl, start))
    held = ConstantReference(tpl, goal)
    assert np.allclose(held.start_positions_m(), forward_kinematics(tpl, goal))  # a constant one: its goal
    assert held.start_positions_m().shape == (4, 2)


def test_a_swap_starts_away_from_its_reference() -> None:
    from mpcform.scenario.load import load_scenario  # the scenario layer, for its bundled swap

    s = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "swap_planar_8.toml")
    assert np.allclose(s.initial_positions_m, -s.reference.start_positions_m())  # p_i(0) = -r_i, p*_i = r_i


@given(st.integers(0, 10_000))
def test_spin_is_numpys_cross_product_bitwise(seed):
    """``omega x q`` component by component: the same bits as ``np.cross`` (signed zeros included)."""
    rng = np.random.default_rng(seed)
    omega, q = rng.normal(size=(4, 3)), rng.normal(size=(4, 6, 3)) * rng.uniform(1e-3, 1e3, (4, 6, 1))
    omega[0], q[1, :, 2] = 0.0, -0.0  # zero rates and zero components
    spin = spin_world(omega, q)
    assert spin.tobytes() == np.cross(omega[:, None, :], q).tobytes()


@pytest.mark.parametrize("n", [3, ROW_ADD_MIN_N, 1000])
@pytest.mark.parametrize("dim", [2, 3])
def test_add_per_time_is_the_broadcast_add_bitwise(n: int, dim: int) -> None:
    """Below and from ``ROW_ADD_MIN_N`` drones (repeated rows), and on a non-contiguous array."""
    rng = np.random.default_rng(n)
    a, b = rng.normal(size=(11, n, dim)) * 1e3, rng.normal(size=(11, dim))
    got = a.copy()
    add_per_time(got, b)
    assert got.tobytes() == (a + b[:, None, :]).tobytes()
    strided = a.transpose(1, 0, 2).copy().transpose(1, 0, 2)  # the same values, not C-contiguous
    add_per_time(strided, b)
    assert np.array_equal(strided, a + b[:, None, :])
