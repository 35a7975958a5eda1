"""The braking tail's hull: exact transition, every tail point inside, checked against the loop's
own interval response; tight along the path for a lag."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.optimize import linprog

from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.tail import TailHull, braking_tail, tail_hull, tail_system
from mpcform.mpc.prediction import Prediction
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.sim.plants import Plant, lag_plant, second_order_plant
from mpcform.world.limits import Limits

PLANTS = {
    "lag 0.3 s": lambda: lag_plant(2, 3, 0.3),
    "lag 0.1 s": lambda: lag_plant(2, 3, 0.1),
    "second order": lambda: second_order_plant(2, 3, 0.7, 6.0),
    "second order, nearly critical": lambda: second_order_plant(2, 3, 0.994, 6.0),
}


def _loop_of(plant: Plant, dt: float, horizon: int = 10) -> VelocityLoop:
    """The planner's model of ``plant``'s velocity loops."""
    groups = [(np.asarray(a), np.asarray(b), np.asarray(c), ax) for a, b, _, c, ax in plant.velocity_loops()]
    return VelocityLoop.from_groups(groups, plant.dim, dt, horizon)


def _axis_hull(m: np.ndarray, rest: np.ndarray) -> TailHull:
    """One axis' hull, vertices (V, q)."""
    hull = tail_hull([(m, rest)])
    return TailHull(hull.vertices[:, 0], hull.transition)


def _loop(plant_name: str, dt: float) -> VelocityLoop:
    return _loop_of(PLANTS[plant_name](), dt)


def _quadrotor(dim: int, platform: str = "cf2x_L250") -> Plant:
    from mpcform.sim.quadrotor import QuadrotorPlant, QuadrotorSpec

    return QuadrotorPlant(2, dim, QuadrotorSpec(platform=platform))


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
    hull = _axis_hull(m, rest)
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
    loop = _loop_of(_quadrotor(3), 0.1)
    braking = Braking.of(0.1, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    for axis in (0, 2):
        m, rest = tail_system(loop, braking, axis)
        hull = _axis_hull(m, rest)
        np.testing.assert_allclose(hull.vertices @ m, hull.transition @ hull.vertices, atol=1e-9)
        assert hull.transition.min() >= -1e-12 and hull.transition.sum(axis=1).max() <= 1.0 + 1e-9
    steady = np.concatenate(
        [[1.0], np.linalg.solve(np.eye(m.shape[0] - 1) - m[1:, 1:], m[1:, 0] / braking.rho)]
    )
    assert np.abs(_axis_hull(*tail_system(loop, braking, 0)).vertices @ steady).max() > 0.5


@pytest.mark.parametrize("tau", [0.1, 0.3])
def test_a_lags_hull_is_its_path_in_steady_flight(tau: float) -> None:
    """From steady flight a lag's tail runs straight to rest: its hull's vertices lie between the
    rest point and ``y_H`` (3 of them, rest included: one more than the chord)."""
    loop = _loop_of(lag_plant(2, 3, tau), 0.1)
    braking = Braking.of(0.1, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    m, rest = tail_system(loop, braking, 0)
    hull = _axis_hull(m, rest)
    togo = hull.vertices @ np.array([1.0, 1.0])  # command 1 m/s, velocity 1 m/s
    assert hull.vertices.shape[0] == 2 and np.all(togo > 0.0) and np.all(togo <= togo[0] + 1e-12)


def _true_path(plant: Plant, xi0: np.ndarray, commands: np.ndarray, dt: float) -> np.ndarray:
    """Positions (K + 1, n, d) from the origin of drones whose loops (per axis group ``xi' = A xi +
    B u``, ``p' = c^T xi``, the plant's own) start in ``xi0`` (n, d, k), each command (K, n, d) held
    for ``dt``: the exact discretisation of the plant's loops, independent of :class:`VelocityLoop`."""
    out = np.zeros((commands.shape[0] + 1,) + xi0.shape[:2])
    for a, b, _, c, axes in plant.velocity_loops():
        a, b, c, axes = np.asarray(a), np.asarray(b), np.asarray(c), list(axes)
        k = a.shape[0]
        m = np.zeros((k + 2, k + 2))
        m[0, 1 : k + 1], m[1 : k + 1, 1 : k + 1], m[1 : k + 1, k + 1] = c, a, b
        ex = expm(m * dt)
        start = xi0[:, axes, :k]
        z = np.concatenate(
            [np.zeros(start.shape[:2] + (1,)), start, np.zeros(start.shape[:2] + (1,))], axis=2
        )
        for step, u in enumerate(commands):
            z[..., -1] = u[:, axes]
            z = z @ ex.T
            out[step + 1][:, axes] = z[..., 0]
    return out


@pytest.mark.parametrize(
    ("plant", "dt", "horizon"),
    [(p, dt, h) for p in PLANTS for dt, h in ((0.1, 10), (0.05, 7)) if "critical" not in p or dt == 0.1],
)
def test_the_tail_points_hold_the_drones_true_path_to_rest(plant: str, dt: float, horizon: int) -> None:
    """For random loop states and plans of three drones in 3-D, every position of the true path from
    ``y_H`` to rest (the plan, then its geometric braking, integrated exactly) lies in the hull of
    ``y_H`` and the tail's points, the last of which is the rest point; the chord alone (``y_H``
    and the rest point) misses many of them. A nearly critical loop's tail starts with exact samples."""
    braking = Braking.of(dt, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    loop = _loop_of(PLANTS[plant](), dt, horizon)
    tail = braking_tail(braking, horizon, 3, loop)
    assert tail.count == 2 if plant.startswith("lag") else tail.count > 2  # the chord: 1
    rng = np.random.default_rng(int(100 * dt) + horizon)
    k = loop.step_state.shape[1] - 1
    missed = checked = 0
    for _ in range(2):
        u = rng.uniform(-1.0, 1.0, (horizon, 3, 3))
        state = np.concatenate([0.5 * rng.normal(size=(3, 3, k)), np.zeros((3, 3, 1))], axis=2)
        x = dt * np.cumsum(u, axis=0)
        planned = Prediction(dt, horizon, loop, braking, tail).points(state, u, x)  # (H + T, n, d)
        brake = braking.rho ** np.arange(1, 3000)[:, None, None] * u[-1]
        path = _true_path(PLANTS[plant](), state[..., :k], np.concatenate([u, brake]), dt)[horizon:]
        np.testing.assert_allclose(planned[horizon - 1], path[0], atol=1e-9)  # y_H
        np.testing.assert_allclose(planned[-1], path[-1], atol=1e-9)  # the rest point
        for drone in range(3):
            hull = planned[horizon - 1 :, drone]
            for p in path[:300:3, drone]:  # the first 30 s (at dt 0.1), where the tail moves
                assert _in_hull(hull, p)
                missed += not _in_hull(hull[[0, -1]], p)
                checked += 1
    assert missed > checked / 10  # the chord is not enough (24 % of them for the 0.3 s lag at dt 0.1)


@pytest.mark.parametrize(
    ("platform", "dim", "dt", "horizon"),
    [
        ("cf2x_L250", 2, 0.05, 7),
        ("cf21B_500", 2, 0.1, 10),
        ("cf2x_L250", 3, 0.1, 10),
        ("cf21B_500", 3, 0.05, 7),
    ],
)
def test_a_quadrotors_tail_per_drone_samples_then_holds_its_true_path(
    platform: str, dim: int, dt: float, horizon: int
) -> None:
    """Solved per drone, a quadrotor's tail takes exact samples before its hull (in a joint QP: the
    chord, one point); a spatial one's hull holds its xy and z loops at once. Every position of its
    true path from ``y_H`` to rest lies in the hull of ``y_H`` and the tail's points, as for the
    loops above."""
    plant = _quadrotor(dim, platform)
    loop = _loop_of(plant, dt, horizon)
    braking = Braking.of(dt, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    tail = braking_tail(braking, horizon, dim, loop, per_drone=True)
    assert braking_tail(braking, horizon, dim, loop).count == 1 and tail.count > 9
    rng = np.random.default_rng(7)
    k = loop.step_state.shape[1] - 1
    for _ in range(2):
        u = rng.uniform(-1.0, 1.0, (horizon, 2, dim))
        state = np.concatenate([0.2 * rng.normal(size=(2, dim, k)), np.zeros((2, dim, 1))], axis=2)
        planned = Prediction(dt, horizon, loop, braking, tail).points(state, u, dt * np.cumsum(u, axis=0))
        brake = braking.rho ** np.arange(1, 3000)[:, None, None] * u[-1]
        path = _true_path(plant, state[..., :k], np.concatenate([u, brake]), dt)[horizon:]
        np.testing.assert_allclose(planned[horizon - 1], path[0], atol=1e-9)  # y_H
        np.testing.assert_allclose(planned[-1], path[-1], atol=1e-9)  # the rest point
        for drone in range(2):
            hull = planned[horizon - 1 :, drone]
            assert all(_in_hull(hull, p) for p in path[: int(6.0 / dt) : 2, drone])


def test_a_spatial_quadrotors_hull_shares_one_transition_over_its_xy_and_z_loops() -> None:
    """The xy and z loops' tails differ (two groups); one real chain over both groups' poles and
    their two polygons give vertices with one nonnegative transition for both (rows summing to at
    most 1), as many as the chain's steps and the polygons' corners, not their product."""
    loop = _loop_of(_quadrotor(3), 0.05)
    braking = Braking.of(0.05, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    systems = [tail_system(loop, braking, axis) for axis in (0, 2)]
    assert not np.allclose(systems[0][0], systems[1][0])
    hull = tail_hull(systems)
    assert hull.transition.min() >= -1e-12 and hull.transition.sum(axis=1).max() <= 1.0 + 1e-9
    for g, (m, rest) in enumerate(systems):
        np.testing.assert_allclose(hull.vertices[:, g] @ m, hull.transition @ hull.vertices[:, g], atol=1e-9)
        np.testing.assert_allclose(hull.vertices[0, g], rest)
    assert hull.vertices.shape[0] < 20


def _in_hull(points: np.ndarray, x: np.ndarray) -> bool:
    """``x`` (d,) in the convex hull of ``points`` (V, d) (to 1e-9 m)."""
    k = points.shape[0]
    a_eq = np.vstack([points.T, np.ones((1, k))])
    res = linprog(np.zeros(k), A_eq=a_eq, b_eq=np.append(x, 1.0), bounds=[(0, None)] * k)
    if res.status == 0:
        return True
    near = linprog(  # the nearest combination: within 1e-9 m counts (the LP's tolerance)
        np.concatenate([np.zeros(k), np.ones(2 * x.shape[0])]),
        A_eq=np.hstack(
            [
                a_eq,
                np.vstack([np.eye(x.shape[0]), np.zeros((1, x.shape[0]))]),
                np.vstack([-np.eye(x.shape[0]), np.zeros((1, x.shape[0]))]),
            ]
        ),
        b_eq=np.append(x, 1.0),
        bounds=[(0, None)] * (k + 2 * x.shape[0]),
    )
    return bool(near.status == 0 and near.fun <= 1e-9)


def test_without_a_loop_or_in_a_joint_qp_a_quadrotors_tail_is_its_stop_point() -> None:
    """The single integrator's tail is straight: one point, ``x_H + kappa u_{H-1}``. In a joint QP
    a spatial quadrotor's tail is the chord to rest (one point, the rest point). A planar one's
    hull alone reaches 14 times as far as its chord and needs more than ``TAIL_SAMPLES`` exact
    samples first (their rows made its joint QPs 4-6 times slower): the chord too."""
    braking = Braking.of(0.1, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    plain = braking_tail(braking, 10, 3)
    rng = np.random.default_rng(1)
    u, x_last = rng.normal(size=(10, 2, 3)), rng.normal(size=(2, 3))
    assert plain.count == 1 and plain.support.tolist() == [9] and plain.reach_s == braking.kappa_s
    np.testing.assert_array_equal(plain.points(x_last, u)[0], braking.stop(x_last, u[-1]))
    quad = _loop_of(_quadrotor(3), 0.1)
    chord = braking_tail(braking, 10, 3, quad)
    assert chord.count == 1 and chord.free is not None
    np.testing.assert_allclose(chord.free[0, :, :-1], quad.rest_m[:, :-1])  # the offset's: with_offset
    loop = _loop_of(_quadrotor(2), 0.1)
    assert braking_tail(braking, 10, 2, loop).count == 1  # 3 samples would be needed: the chord
    # a slower swarm brakes sooner: 2 samples would do, but the rows of 9 tail points made a
    # 20-drone planar swap of the flight acceptance take 4 times as long (SAMPLED_STATES): the chord
    slow = Braking.of(0.1, Limits(v_max_mps=0.54, a_max_mps2=1.79))
    planar15 = _loop_of(_quadrotor(2), 0.1, 15)
    assert braking_tail(slow, 15, 2, planar15).count == 1


@pytest.mark.parametrize("plant", [*PLANTS, "quadrotor planar", "quadrotor spatial"])
@pytest.mark.parametrize("per_drone", [False, True])
def test_a_drone_holding_against_a_persistent_offset_rests_where_it_is(plant: str, per_drone: bool) -> None:
    """With the velocity offset ``delta`` persistent (:func:`with_offset`), a drone in steady state
    holding against it (every command ``-delta``, the loop state ``-xi_ss delta``) has its horizon
    and every tail point (hull vertices or chord) at its start, and one flying steadily at ``v``
    over ground (commands ``v - delta``) stops where the still-air plan of ``v`` does."""
    if plant.startswith("quadrotor"):
        dim = 2 if plant.endswith("planar") else 3
        loop = _loop_of(_quadrotor(dim), 0.1)
    else:
        dim, loop = 3, _loop(plant, 0.1)
    braking = Braking.of(0.1, Limits(v_max_mps=1.0, a_max_mps2=1.79))
    assert braking is not None
    tail = braking_tail(braking, 10, dim, loop, per_drone)
    delta = np.array([[0.3, -0.2, 0.1][:dim]])

    def at(v: np.ndarray, offset: np.ndarray) -> np.ndarray:
        state = loop.rest(1)
        state[0, :, :-1] = (v - offset).T * loop.steady_state  # in steady flight on commands v - delta
        state[0, :, -1] = offset
        u = np.broadcast_to(v - offset, (10, 1, dim))
        x = 0.1 * np.cumsum(u, axis=0)
        return np.concatenate([x + loop.offsets(state, u)[1:], tail.points(x[-1], u, state)])

    np.testing.assert_allclose(at(np.zeros((1, dim)), delta), 0.0, atol=1e-9)
    v = np.array([[0.4, 0.1, -0.2][:dim]])
    np.testing.assert_allclose(at(v, delta), at(v, np.zeros((1, dim))), atol=1e-9)
