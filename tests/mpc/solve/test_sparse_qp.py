"""The sparse QP: eq. 14 tracking cost, the rollout meets its rows, separation values land right."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import bounds_of

from mpcform.mpc.constraints.limits import limit_rows
from mpcform.mpc.constraints.rows import row_ends
from mpcform.mpc.plan import rollout
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.sparse_qp import MPCQP

DT = 0.1
FENCE = {"geofence_min_m": [-9.0, -9.0], "geofence_max_m": [9.0, 9.0]}
LIMITS = bounds_of(v_max_mps=2.0, d_min_m=0.5, a_max_mps2=50.0, **FENCE)


def qp(n: int, settings: MPCSettings, pairs: np.ndarray, singles: np.ndarray) -> MPCQP:
    return MPCQP(n, 2, DT, LIMITS, settings, pairs, singles, limit_rows(2, DT, LIMITS, settings))


def test_cost_is_the_tracking_cost_plus_the_slack_penalty() -> None:
    st = MPCSettings(horizon=4, gain_per_s=2.0, slack_weight=7.0, slack_quadratic=3.0)
    m = qp(3, st, np.empty((0, 2), int), np.empty(0, int))
    rng = np.random.default_rng(1)
    u, x, c = (rng.normal(size=(4, 3, 2)) for _ in range(3))
    s = rng.uniform(0, 1, (4, 3))
    z = np.concatenate([u.ravel(), x.ravel(), s.ravel()])
    full = m.P + m.P.T - np.diag(m.P.diagonal())
    qp_cost = 0.5 * z @ full @ z + m.cost_vector(c) @ z + 0.5 * np.sum(c**2)
    x_from_0 = np.concatenate([np.zeros((1, 3, 2)), x[:-1]])  # x_0 = 0 .. x_{H-1}: x_H is not in the cost
    want = 0.5 * np.sum((u + 2.0 * x_from_0 - c) ** 2) + 7.0 * s.sum() + 0.5 * 3.0 * np.sum(s**2)
    assert qp_cost == pytest.approx(want, rel=1e-12)


def test_the_rollout_meets_every_row() -> None:
    st = MPCSettings(horizon=5)
    m = qp(2, st, np.array([[0, 1]]), np.empty(0, int))
    p0 = np.array([[0.0, 0.0], [3.0, 0.0]])
    u, x = rollout(np.full((5, 2, 2), 0.5), st.gain_per_s, DT)
    z = np.concatenate([u.ravel(), x.ravel(), np.zeros(10)])
    lo, hi = m.bounds(p0, u[0], np.zeros((1, row_ends(5).shape[0])), np.array([True]))
    vals = m.separation_values(np.zeros((1, row_ends(5).shape[0], 2)), np.zeros((0, 9, 2)))
    m.A.data = vals
    r = m.A @ z
    assert np.all(r >= lo - 1e-12) and np.all(r <= hi + 1e-12)
    x[2, 0, 0] += 0.1  # breaks the dynamics
    r = m.A @ np.concatenate([u.ravel(), x.ravel(), np.zeros(10)])
    assert np.any(r < lo - 1e-6) or np.any(r > hi + 1e-6)


def test_separation_rows_by_hand() -> None:
    """Horizon 1, a pair (0, 1) and a single (drone 1): ``c^T (x_0 - x_1) + s_0 + s_1``, ``a^T x_1 + s_1``."""
    st = MPCSettings(horizon=1)
    m = qp(2, st, np.array([[0, 1]]), np.array([1]))
    c, a = np.array([[[0.6, 0.8]]]), np.array([[[-1.0, 0.0]]])
    m.A.data = m.separation_values(c, a)
    u, x, s = np.zeros((1, 2, 2)), np.array([[[1.0, 2.0], [3.0, 5.0]]]), np.array([0.25, 0.5])
    r = (m.A @ np.concatenate([u.ravel(), x.ravel(), s]))[m.sep_rows]
    np.testing.assert_allclose(r, [0.6 * (1 - 3) + 0.8 * (2 - 5) + 0.75, -3.0 + 0.5])
    lo, _ = m.bounds(np.zeros((2, 2)), np.zeros((2, 2)), np.array([[0.1], [0.2]]), np.array([True, False]))
    assert lo[m.sep_rows][0] == 0.1
    assert lo[m.sep_rows][1] == -(2.0 * 2.0 * 1 * DT + 1.0)  # off: a bound no plan reaches


def test_limit_bounds_follow_the_start_and_the_last_command() -> None:
    """a_max dt = 5 m/s, fence +-9 m: the first acceleration rows move with u_prev, the fence rows with p0."""
    st = MPCSettings(horizon=2, margin_m=0.0)
    m = qp(1, st, np.empty((0, 2), int), np.empty(0, int))
    none = np.zeros((0, 3)), np.zeros(0, bool)
    lo_a, hi_a = m.bounds(np.zeros((1, 2)), np.zeros((1, 2)), *none)
    lo_b, hi_b = m.bounds(np.array([[1.0, -1.0]]), np.array([[0.5, -0.25]]), *none)
    changed = np.flatnonzero((lo_a != lo_b) | (hi_a != hi_b))
    # u_0 - u_{-1} (2 components), the fence rows of x_1, x_2 and the stop point (2 each: braking)
    assert changed.size == 2 + 6
    np.testing.assert_allclose(lo_b[changed], [-4.5, -5.25, -10.0, -8.0, -10.0, -8.0, -10.0, -8.0])
    np.testing.assert_allclose(hi_b[changed], [5.5, 4.75, 8.0, 10.0, 8.0, 10.0, 8.0, 10.0])


def test_separation_rows_with_a_velocity_loop_carry_its_forced_response() -> None:
    """With a lag model the QP has the loop's positions ``y_e = x_e + sum_j G_{e,j} u_j`` (equality
    rows), and a pair row is ``c^T (y_{e,i} - y_{e,k})``, a single's ``a^T y_{e,i}``."""
    from mpcform.mpc.velocity_loop import VelocityLoop

    h, tau = 3, 0.2
    loop = VelocityLoop.from_groups(
        [(np.array([[-1 / tau]]), np.array([1 / tau]), np.array([1.0]), (0, 1))], 2, DT, h
    )
    st = MPCSettings(horizon=h)
    m = MPCQP(3, 2, DT, LIMITS, st, np.array([[0, 2]]), np.array([1]), limit_rows(2, DT, LIMITS, st), loop)
    rng = np.random.default_rng(2)
    r = row_ends(h).shape[0]
    c, a = rng.normal(size=(1, r, 2)), rng.normal(size=(1, r, 2))
    m.A.data = m.separation_values(c, a)
    u = rng.normal(size=(h, 3, 2))
    x = DT * np.cumsum(u, axis=0)
    y = x + np.einsum("ejd,jnd->end", loop.forced[1:], u)
    z = np.concatenate([u.ravel(), x.ravel(), np.zeros(3 * h), y.ravel()])
    lo, hi = m.bounds(np.zeros((3, 2)), u[0], np.zeros((2, r)), np.array([False, False]))
    rows = m.A @ z
    eq = lo == hi  # dynamics and the loop's positions: met
    np.testing.assert_allclose(rows[eq], lo[eq], atol=1e-12)
    got = rows[m.sep_rows]
    e = row_ends(h) - 1
    pair, single = np.einsum("rd,rd->r", c[0], y[e, 0] - y[e, 2]), np.einsum("rd,rd->r", a[0], y[e, 1])
    want = np.concatenate([pair, single])
    np.testing.assert_allclose(got, want, atol=1e-12)


def test_the_braking_tails_rows_sit_at_its_points_under_a_second_order_loop() -> None:
    """A second-order loop's tail has several points (each ``g x_H + sum_j F_j u_j``, its free part
    in the bounds): the separation rows there are ``c^T`` of those points, and the fence's rows are
    the points themselves (:class:`mpcform.mpc.constraints.tail.Tail`)."""
    from mpcform.mpc.constraints.braking import Braking
    from mpcform.mpc.constraints.tail import braking_tail
    from mpcform.mpc.velocity_loop import VelocityLoop
    from mpcform.sim.plants import second_order_plant

    h = 4
    groups = [
        (np.asarray(a), np.asarray(b), np.asarray(c), axes)
        for a, b, _, c, axes in second_order_plant(3, 2, 0.7, 6.0).velocity_loops()
    ]
    loop = VelocityLoop.from_groups(groups, 2, DT, h)
    lim = bounds_of(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=1.79, **FENCE)
    st = MPCSettings(horizon=h)
    tail = braking_tail(Braking.of(DT, lim), h, 2, loop)
    assert tail.count > 2
    families = limit_rows(2, DT, lim, st, loop)
    m = MPCQP(3, 2, DT, lim, st, np.array([[0, 2]]), np.array([1]), families, loop, tail)
    rng = np.random.default_rng(4)
    ends = row_ends(h, tail.count)
    c, a = rng.normal(size=(1, ends.shape[0], 2)), rng.normal(size=(1, ends.shape[0], 2))
    m.A.data = m.separation_values(c, a)
    u = rng.normal(size=(h, 3, 2))
    x = DT * np.cumsum(u, axis=0)
    y = x + np.einsum("ejd,jnd->end", loop.forced[1:], u)
    rows = m.A @ np.concatenate([u.ravel(), x.ravel(), np.zeros(3 * h), y.ravel()])
    points = np.concatenate([y, tail.points(x[-1], u)])  # (H + T, n, d), no free response
    e = ends - 1
    pair, single = (
        np.einsum("rd,rd->r", c[0], points[e, 0] - points[e, 2]),
        np.einsum("rd,rd->r", a[0], points[e, 1]),
    )
    np.testing.assert_allclose(rows[m.sep_rows], np.concatenate([pair, single]), atol=1e-12)
    fence = next(r for f, r in m._families if type(f).__name__ == "GeofenceRows")
    np.testing.assert_allclose(rows[fence], points.ravel(), atol=1e-12)
    dense = families[-1].dense() @ u.transpose(1, 0, 2).reshape(3, -1).T  # (S d, n): drone by drone
    np.testing.assert_allclose(dense.T.reshape(3, -1, 2), points.transpose(1, 0, 2), atol=1e-12)
