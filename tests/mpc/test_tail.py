"""The braking tail's hull: exact transition, every tail point inside, checked against the loop's
own interval response; tight along the path for a lag."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from mpcform.mpc.braking import Braking
from mpcform.mpc.loop import VelocityLoop
from mpcform.mpc.tail import axis_hull, tail_system
from mpcform.sim.plants import lag_plant, second_order_plant
from mpcform.world.limits import Limits

PLANTS = {
    "lag 0.3 s": lambda: lag_plant(2, 3, 0.3),
    "lag 0.1 s": lambda: lag_plant(2, 3, 0.1),
    "second order": lambda: second_order_plant(2, 3, 0.7, 6.0),
}


def _loop(plant_name: str, dt: float) -> VelocityLoop:
    groups = [
        (np.asarray(a), np.asarray(b), np.asarray(c), axes)
        for a, b, _, c, axes in PLANTS[plant_name]().velocity_loops()
    ]
    return VelocityLoop.from_groups(groups, 3, dt, 10)


def _quadrotor_loop(dt: float) -> VelocityLoop:
    from mpcform.sim.quadrotor import QuadrotorPlant, QuadrotorSpec

    groups = [
        (np.asarray(a), np.asarray(b), np.asarray(c), axes)
        for a, b, _, c, axes in QuadrotorPlant(2, 3, QuadrotorSpec()).velocity_loops()
    ]
    return VelocityLoop.from_groups(groups, 3, dt, 10)


def _remaining(loop: VelocityLoop, braking: Braking, axis: int, z: np.ndarray, steps: int) -> np.ndarray:
    """The distance still to go (steps,) from each of the tail's first positions, by the loop's own
    interval response (``dt c + F_1 xi + G_{1,0} c``) summed until it has died out."""
    s = loop.step_state.shape[1] - 1
    c, xi = z[0], np.concatenate([z[1:], [0.0]])  # no velocity offset
    moves = []
    for _ in range(4000):
        command = braking.rho * c
        moves.append(loop.dt_s * command + loop.free_m[1, axis] @ xi + loop.forced[1, 0, axis] * command)
        xi = loop.step_state[axis] @ xi + loop.step_input[axis] * command
        c = command
    assert s + 1 == z.shape[0]
    return np.cumsum(np.array(moves)[::-1])[::-1][:steps]


def _inside(points: np.ndarray, x: np.ndarray) -> bool:
    """``x`` (d,) in the hull of ``points`` (V, d) and the origin."""
    k = points.shape[0]
    res = linprog(
        np.zeros(k), A_ub=np.ones((1, k)), b_ub=[1.0], A_eq=points.T, b_eq=x, bounds=[(0, None)] * k
    )
    return res.status == 0


CASES = [
    (name, dt, v, a)
    for name in PLANTS
    for dt in (0.05, 0.1)
    for v, a in ((1.0, 1.79), (0.5, 1.79), (2.0, 1.0))
]


@pytest.mark.parametrize(("plant", "dt", "v_max", "a_max"), CASES)
def test_every_tail_point_lies_in_the_hull_and_the_hull_holds_its_shift(
    plant: str, dt: float, v_max: float, a_max: float
) -> None:
    """W M = transition W exactly (nonnegative, rows summing to at most 1); for random tail states of
    three axes the distances still to go, from the loop's own response, lie in the hull of the
    vertices and the rest point at every step."""
    loop = _loop(plant, dt)
    braking = Braking.of(dt, Limits(v_max_mps=v_max, a_max_mps2=a_max))
    m, rest = tail_system(loop, braking, 0)
    hull = axis_hull(m, rest)
    assert hull.transition.min() >= -1e-12 and hull.transition.sum(axis=1).max() <= 1.0 + 1e-9
    np.testing.assert_allclose(hull.vertices @ m, hull.transition @ hull.vertices, atol=1e-9)
    np.testing.assert_allclose(hull.vertices[0], rest)
    rng = np.random.default_rng([int(dt * 100), int(v_max * 10)])
    for _ in range(5):
        z = rng.normal(size=(m.shape[0], 3))  # three axes, the same loop
        togo = np.column_stack([_remaining(loop, braking, 0, z[:, a], 40) for a in range(3)])
        np.testing.assert_allclose(togo[0], rest @ z, atol=1e-9)  # L is the distance to rest
        for k in range(40):
            assert _inside(hull.vertices @ z, togo[k]), (k, togo[k])


def test_the_quadrotors_tail_hull_is_exact_but_loose() -> None:
    """The quadrotor's integral pole (0.95 per step at dt 0.1) widens its pair's polygon: exact, but
    vertices up to 0.8 m beyond the rest point per m/s in steady flight."""
    loop = _quadrotor_loop(0.1)
    braking = Braking.of(0.1, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    for axis in (0, 2):
        m, rest = tail_system(loop, braking, axis)
        hull = axis_hull(m, rest)
        np.testing.assert_allclose(hull.vertices @ m, hull.transition @ hull.vertices, atol=1e-9)
        assert hull.transition.min() >= -1e-12 and hull.transition.sum(axis=1).max() <= 1.0 + 1e-9
    steady = np.concatenate(
        [[1.0], np.linalg.solve(np.eye(m.shape[0] - 1) - m[1:, 1:], m[1:, 0] / braking.rho)]
    )
    assert np.abs(axis_hull(*tail_system(loop, braking, 0)).vertices @ steady).max() > 0.5


@pytest.mark.parametrize("tau", [0.1, 0.3])
def test_a_lags_hull_is_its_path_in_steady_flight(tau: float) -> None:
    """From steady flight a lag's tail runs straight to rest: its hull's vertices lie between the
    rest point and ``y_H`` (3 of them, rest included: one more than the chord)."""
    groups = [
        (np.asarray(a), np.asarray(b), np.asarray(c), axes)
        for a, b, _, c, axes in lag_plant(2, 3, tau).velocity_loops()
    ]
    loop = VelocityLoop.from_groups(groups, 3, 0.1, 10)
    braking = Braking.of(0.1, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    m, rest = tail_system(loop, braking, 0)
    hull = axis_hull(m, rest)
    togo = hull.vertices @ np.array([1.0, 1.0])  # command 1 m/s, velocity 1 m/s
    assert hull.vertices.shape[0] == 2 and np.all(togo > 0.0) and np.all(togo <= togo[0] + 1e-12)
