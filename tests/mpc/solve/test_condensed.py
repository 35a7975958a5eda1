"""A drone's condensed QP: its rows over ``v = M u`` are the rows over positions, the soft problem
carries the slacks as the first variables, and the constant rows' bounds per drone."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.mpc.constraints.limits import limit_rows
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.condensed import CondensedDroneQP, dense_bounds
from mpcform.solvers.dense import NO_BOUND
from mpcform.world.limits import Limits

LIMITS = Limits(v_max_mps=1.0, d_min_m=0.5)


@pytest.mark.parametrize("dim", [2, 3])
def test_rows_over_v_are_the_rows_over_positions(dim: int) -> None:
    """A separation row ``a^T x_e`` over ``v = M u``: ``(w_e (x) a)^T v`` equals ``a^T x_e`` with
    ``u = M^-1 v`` and ``x_e = dt sum_{j<e} u_j`` (built here from scratch)."""
    h, dt, k = 4, 0.1, 1.3
    settings = MPCSettings(horizon=h, gain_per_s=k, coupling="decoupled")
    qp = CondensedDroneQP(dim, dt, LIMITS, settings, ())
    rng = np.random.default_rng(dim)
    a, end, v = rng.normal(size=(9, dim)), rng.integers(1, h + 1, 9), rng.normal(size=h * dim)
    m = np.eye(h * dim) + k * dt * np.kron(np.tril(np.ones((h, h)), -1), np.eye(dim))
    x = dt * np.cumsum(np.linalg.solve(m, v).reshape(h, dim), axis=0)  # x_1 .. x_H
    np.testing.assert_allclose(qp._rows_v(a, end) @ v, np.einsum("kd,kd->k", a, x[end - 1]), atol=1e-13)


def test_rows_at_the_braking_tails_points_under_a_loop() -> None:
    """With a second-order loop and braking, the rows past the horizon are at the tail's points
    (:class:`mpcform.mpc.constraints.tail.Tail`), over ``v`` as over ``u``; the loop's positions before
    them."""
    from mpcform.mpc.constraints.braking import Braking
    from mpcform.mpc.constraints.tail import braking_tail
    from mpcform.mpc.velocity_loop import VelocityLoop
    from mpcform.sim.plants import second_order_plant

    h, dt, k, dim = 5, 0.1, 1.3, 3
    lim = Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=1.79)
    groups = [
        (np.asarray(a), np.asarray(b), np.asarray(c), axes)
        for a, b, _, c, axes in second_order_plant(2, dim, 0.7, 6.0).velocity_loops()
    ]
    loop = VelocityLoop.from_groups(groups, dim, dt, h)
    qp = CondensedDroneQP(dim, dt, lim, MPCSettings(horizon=h, gain_per_s=k, coupling="decoupled"), (), loop)
    tail = braking_tail(Braking.of(dt, lim), h, dim, loop)
    assert tail.count > 2 and qp._steps == h + tail.count
    rng = np.random.default_rng(7)
    v = rng.normal(size=h * dim)
    m = np.eye(h * dim) + k * dt * np.kron(np.tril(np.ones((h, h)), -1), np.eye(dim))
    u = np.linalg.solve(m, v).reshape(h, 1, dim)
    x = dt * np.cumsum(u, axis=0)
    points = np.concatenate([x + np.einsum("ejd,jnd->end", loop.forced[1:], u), tail.points(x[-1], u)])[:, 0]
    a, end = rng.normal(size=(h + tail.count, dim)), np.arange(1, h + tail.count + 1)
    np.testing.assert_allclose(qp._rows_v(a, end) @ v, np.einsum("kd,kd->k", a, points), atol=1e-12)


def test_the_soft_problem_puts_the_slacks_first() -> None:
    """Hessian diag(w2, I), cost ``w1`` per slack, each separation row's slack in its step's column,
    slacks bounded below by 0 and above by nothing."""
    h, dim = 3, 2
    st = MPCSettings(horizon=h, coupling="decoupled", slack_weight=7.0, slack_quadratic=2.0)
    qp = CondensedDroneQP(dim, 0.1, LIMITS, st, limit_rows(dim, 0.1, LIMITS, st))
    n_const = qp._const_v.shape[0]
    sep = qp._rows_v(np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([1, 3]))
    a = np.vstack([qp._const_v, sep])
    hi, lo = np.full(a.shape[0], NO_BOUND), np.zeros(a.shape[0])
    f_v = np.arange(h * dim, dtype=float)
    hess, f, rows, upper, lower = qp.soft_problem(f_v, a, hi, lo, np.array([1, 3]), np.array([1.0, 1.0]))
    assert np.array_equal(np.diag(hess), np.concatenate([np.full(h, 2.0), np.ones(h * dim)]))
    assert np.array_equal(f, np.concatenate([np.full(h, 7.0), f_v]))
    assert np.array_equal(rows[:, h:], a) and not rows[:n_const, :h].any()
    assert rows[n_const, 0] == 1.0 and rows[n_const + 1, 2] == 1.0 and rows[n_const:, :h].sum() == 2.0
    assert np.array_equal(lower[:h], np.zeros(h)) and np.all(upper[:h] == NO_BOUND)


def test_dense_bounds_per_drone() -> None:
    """The acceleration rows' bounds follow each drone's last command (a_max dt about it)."""
    lim = Limits(v_max_mps=1.0, a_max_mps2=2.0)
    st = MPCSettings(horizon=2)
    families = limit_rows(2, 0.1, lim, st)
    u_prev = np.array([[0.1, 0.0], [0.0, -0.3]])
    lo, hi = dense_bounds(families, np.zeros((2, 2)), u_prev)
    assert lo.shape == hi.shape and lo.shape[0] == 2
    assert not np.array_equal(lo[0], lo[1])  # the drones' own bounds
    assert dense_bounds((), np.zeros((3, 2)), np.zeros((3, 2)))[0].shape == (3, 0)
