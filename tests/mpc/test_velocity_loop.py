"""The planner's velocity-loop model: exact against the simulated linear plants, closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.sim.plants import lag_plant, second_order_plant

DT, H = 0.1, 8


def loop_of(plant: object, dim: int = 3) -> VelocityLoop:
    groups = [(a, b, c, axes) for a, b, _, c, axes in plant.velocity_loops()]  # type: ignore[attr-defined]
    return VelocityLoop.from_groups(groups, dim, DT, H)


@pytest.mark.parametrize(
    "plant",
    [lag_plant(4, 3, 0.2), second_order_plant(4, 3, 0.7, 6.0, zeta_z=0.9, omega_z_rad_s=4.0)],
    ids=["lag", "second_order"],
)
def test_offsets_and_state_are_the_plants_own(plant: object) -> None:
    """From a moving state (the model run on the commands flown), ``p0 + x_e + offsets_e`` is where
    the exactly discretised plant is after e intervals, to rounding."""
    loop = loop_of(plant)
    rng = np.random.default_rng(3)
    u = rng.normal(size=(6 + H, 4, 3))
    plant.reset(rng.normal(size=(4, 3)))  # type: ignore[attr-defined]
    state, p = loop.rest(4), None
    for k in range(6):
        p = plant.advance(u[k], DT).p_true_m[-1]  # type: ignore[attr-defined]
        state = loop.advance(state, u[k])
    assert p is not None
    plan = u[6:]
    want = [p]
    for j in range(H):
        want.append(plant.advance(plan[j], DT).p_true_m[-1])  # type: ignore[attr-defined]
    x = np.concatenate([np.zeros((1, 4, 3)), DT * np.cumsum(plan, axis=0)])
    np.testing.assert_allclose(p + x + loop.offsets(state, plan), np.array(want), atol=1e-12, rtol=0)


def test_lag_closed_form() -> None:
    """Lag: ``F_e = tau (1 - a^e)``, ``G_{e,j} = -tau (1 - a) a^{e-1-j}`` with ``a = e^{-dt/tau}``."""
    tau = 0.2
    loop = loop_of(lag_plant(1, 2, tau), dim=2)
    a = np.exp(-DT / tau)
    np.testing.assert_allclose(loop.free_m[:, 0, 0], tau * (1 - a ** np.arange(H + 1)), atol=1e-15)
    for e in range(1, H + 1):
        want = -tau * (1 - a) * a ** (e - 1 - np.arange(e))
        np.testing.assert_allclose(loop.forced[e, :e, 1], want, atol=1e-15)
        assert not loop.forced[e, e:].any()
    assert loop.reach_factor == 1.0


def test_the_velocity_offset_is_the_last_intervals_mean_over_the_next_interval() -> None:
    """``observe`` moves the offset by ``residual / dt``; it moves the drones by ``dt delta`` in
    every interval (persistent: ``e dt delta`` at step e), and ``advance`` keeps it. Under a constant wind the
    observed lag predicts the next interval end exactly once the wind's transient has settled."""
    from mpcform.sim.wind import Wind

    loop = loop_of(lag_plant(2, 3, 0.2))
    residual = np.array([[0.01, -0.02, 0.0], [0.0, 0.0, 0.003]])
    state = loop.observe(loop.rest(2), residual)
    np.testing.assert_allclose(state[..., -1], residual / DT)
    free = loop.free(state)
    assert not free[0].any()
    steps = np.arange(1, free.shape[0])[:, None, None]
    np.testing.assert_allclose(free[1:], steps * residual, atol=1e-15)
    np.testing.assert_array_equal(loop.advance(state, np.zeros((2, 3)))[..., -1], state[..., -1])

    plant = lag_plant(1, 3, 0.2, wind=Wind(np.array([1.0, -0.5, 0.2])))
    plant.reset(np.zeros((1, 3)))
    state, u, misses = loop.rest(1), np.array([[0.5, 0.0, 0.0]]), []
    for _ in range(80):
        s = plant.advance(u, DT)
        miss = s.p_true_m[-1] - s.p_true_m[0] - DT * u - loop.first(state, u)
        misses.append(np.abs(miss).max())
        state = loop.observe(loop.advance(state, u), miss)
    assert misses[0] > 1e-3 and misses[-1] < 1e-9  # the drag's steady offset, learnt


def test_an_axis_without_a_loop_is_refused() -> None:
    a, b, c = np.array([[-5.0]]), np.array([5.0]), np.array([1.0])
    with pytest.raises(ValidationError, match="axes"):
        VelocityLoop.from_groups([(a, b, c, (0, 1))], 3, DT, H)


def test_speed_gain_is_the_step_responses_total_variation() -> None:
    """A lag never exceeds its commands (gain 1); a damped second-order loop overshoots by
    ``exp(-pi zeta / sqrt(1 - zeta^2))`` and undershoots back: gain about 1 + 2 overshoot."""
    assert loop_of(lag_plant(1, 3, 0.2)).speed_gain == pytest.approx(1.0, abs=1e-9)
    zeta = 0.7
    over = np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2))
    gain = loop_of(second_order_plant(1, 3, zeta, 6.0)).speed_gain
    assert 1 + 2 * over - 1e-3 < gain < 1 + 2 * over + 2 * over**2 + 1e-3


@pytest.mark.parametrize(
    "plant", [lag_plant(1, 3, 0.2), second_order_plant(1, 3, 0.7, 6.0)], ids=["lag", "second_order"]
)
def test_a_loop_in_its_steady_state_moves_as_its_command(plant: object) -> None:
    """``steady_state`` is the loop state a held command settles at (the lag's ``xi = 1``, the
    second-order loop's ``(1, 0)``), and from it the held command moves the drone ``e dt u``: the
    free and forced responses cancel (what the persistent offset's tail column rests on)."""
    loop = loop_of(plant)
    expected = [[1.0]] * 3 if loop.steady_state.shape[1] == 1 else [[1.0, 0.0]] * 3
    np.testing.assert_allclose(loop.steady_state, expected, atol=1e-12)
    state = loop.rest(1)
    state[0, :, :-1] = loop.steady_state
    np.testing.assert_allclose(loop.offsets(state, np.ones((H, 1, 3))), 0.0, atol=1e-12)


def test_the_cancelled_offset_is_a_low_pass_of_the_estimate() -> None:
    """From 0 at the first observation, ``delta_c`` moves by ``1 - e^{-dt / T}`` of the way to the
    deadbeat estimate each interval, so a steady offset is cancelled whole within a few ``T``."""
    from mpcform.mpc.velocity_loop import CANCEL_TIME_S

    loop = loop_of(lag_plant(2, 3, 0.2))
    assert loop.cancel_gain == pytest.approx(1.0 - np.exp(-DT / CANCEL_TIME_S))
    state = loop.observe(loop.rest(2), np.full((2, 3), 0.01))  # delta = 0.1 m/s
    offset = loop.cancelled(None, state)
    np.testing.assert_allclose(offset, loop.cancel_gain * 0.1)
    for _ in range(int(10 * CANCEL_TIME_S / DT)):
        offset = loop.cancelled(offset, state)
    np.testing.assert_allclose(offset, 0.1, rtol=1e-4)
