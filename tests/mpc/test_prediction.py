"""Where a plan takes the drones: the stop point against an independent simulation of the braking."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.tail import braking_tail
from mpcform.mpc.plan import Plan
from mpcform.mpc.prediction import Prediction
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.world.limits import Limits

DT, H, TAU = 0.1, 5, 0.3
BRAKING = Braking.of(DT, Limits(v_max_mps=1.5, a_max_mps2=1.0))
LAG = (np.array([[-1 / TAU]]), np.array([1 / TAU]), np.array([1.0]), (0, 1))


def lag_path(v0: np.ndarray, commands: np.ndarray) -> np.ndarray:
    """Positions (K + 1, n, d) of lag drones from the origin with velocity ``v0`` (n, d), each
    command (K, n, d) held for DT: the exact discretisation of ``p' = v, v' = (u - v) / tau``."""
    m = np.zeros((3, 3))
    m[0, 1], m[1, 1], m[1, 2] = 1.0, -1 / TAU, 1 / TAU
    ex = expm(m * DT)
    p, v, out = np.zeros_like(v0), v0.copy(), [np.zeros_like(v0)]
    for u in commands:
        p, v = ex[0, 0] * p + ex[0, 1] * v + ex[0, 2] * u, ex[1, 0] * p + ex[1, 1] * v + ex[1, 2] * u
        out.append(p.copy())
    return np.array(out)


def test_the_stop_point_is_where_the_braking_plan_comes_to_rest() -> None:
    rng = np.random.default_rng(3)
    u = rng.uniform(-1.0, 1.0, (H, 2, 2))
    tail = BRAKING.rho ** np.arange(1, 2000)[:, None, None] * u[-1]  # geometric braking
    x = DT * np.cumsum(u, axis=0)
    plain = Prediction(DT, H, None, BRAKING, braking_tail(BRAKING, H, 2)).points(np.zeros((2, 2, 0)), u, x)
    np.testing.assert_allclose(plain[:H], x)
    np.testing.assert_allclose(plain[-1], DT * np.concatenate([u, tail]).sum(axis=0), atol=1e-9)
    loop = VelocityLoop.from_groups([LAG], 2, DT, H)
    v0 = rng.uniform(-1.0, 1.0, (2, 2))
    state = loop.rest(2)
    state[..., 0] = v0
    true = Prediction(DT, H, loop, BRAKING, braking_tail(BRAKING, H, 2, loop)).points(state, u, x)
    path = lag_path(v0, np.concatenate([u, tail]))
    np.testing.assert_allclose(true[:H], path[1 : H + 1], atol=1e-12)  # the loop's true positions
    np.testing.assert_allclose(true[-1], path[-1], atol=1e-9)  # and where it comes to rest


def test_the_guess_ends_in_the_previous_plans_stop_point() -> None:
    u = np.tile([[0.5, -0.2]], (H, 1, 1))
    p0 = np.zeros((1, 2))
    plan = Plan.from_relative(p0, u, DT * np.cumsum(u, axis=0))
    pred = Prediction(DT, H, None, BRAKING, braking_tail(BRAKING, H, 2))
    g = pred.guess(plan, plan.positions_m[1], np.zeros((1, 2, 0)))
    assert g.shape == (H + 2, 1, 2)
    np.testing.assert_allclose(g[-1], BRAKING.stop(plan.positions_m[-1], u[-1]))
    assert pred.guess(None, p0, np.zeros((1, 2, 0))).shape == (H + 2, 1, 2)


def test_the_tail_lies_as_far_as_braking_and_the_loops_lag_take_it() -> None:
    """A lag flies no faster than its commands; its tail's points lie past ``x_H`` by the braking
    time ``kappa`` (or the tail's own reach) plus the lag ``tau``; without braking, nowhere."""
    loop = VelocityLoop.from_groups([LAG], 2, DT, H)
    tail = braking_tail(BRAKING, H, 2, loop)
    with_tail = Prediction(DT, H, loop, BRAKING, tail)
    assert with_tail.speed_gain == 1.0 and Prediction(DT, H, None, None, None).speed_gain == 1.0
    assert with_tail.tail_s == max(BRAKING.kappa_s, tail.reach_s) + TAU
    assert Prediction(DT, H, loop, None, None).tail_s == 0.0


def test_the_drift_is_the_offsets_reach_over_the_plan_and_its_tail() -> None:
    """How far the largest offset carries a drone: ``|delta|`` times the offset's longest column,
    the tail's (``H dt + kappa + tau`` for a lag's stop point); 0 at rest and without a loop."""
    loop = VelocityLoop.from_groups([LAG], 2, DT, H)
    assert BRAKING is not None
    predict = Prediction(DT, H, loop, BRAKING, braking_tail(BRAKING, H, 2, loop))
    state = loop.rest(3)
    assert predict.drift_m(state) == 0.0
    state[1, :, -1] = [0.3, 0.4]  # 0.5 m/s
    reach_s = H * DT + BRAKING.kappa_s + TAU
    assert predict.drift_m(state) == pytest.approx(0.5 * reach_s)
    assert Prediction(DT, H, None, None, None).drift_m(np.zeros((3, 2, 0))) == 0.0
