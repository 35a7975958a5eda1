"""Quadrotor plant on the real drone-models parameters: hover, step response, limits, rate, wind."""

from importlib import metadata

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.sim import so_rpy
from mpcform.sim.plants import concat_samples
from mpcform.sim.wind import Wind

try:  # the package is read from its files, never imported (see mpcform.sim.so_rpy)
    metadata.distribution(so_rpy.DISTRIBUTION)
except metadata.PackageNotFoundError:
    pytest.skip("needs drone-models (pip install 'mpcform[flight]')", allow_module_level=True)

from mpcform.sim.quadrotor import QuadrotorGains, QuadrotorPlant, QuadrotorSpec, inner_loop_radius  # noqa: E402

DT = 0.1


def fly(plant, commands, p0=None, planned=None):
    plant.reset(np.zeros((plant.n, plant.dim)) if p0 is None else p0)
    parts = []
    for j, u in enumerate(commands):
        parts.append(plant.advance(u, DT, None if planned is None else planned[j]))
    return concat_samples(parts)


def hold(u, steps):
    return [np.asarray(u, dtype=float)] * steps


@pytest.mark.parametrize("model", so_rpy.MODELS)
@pytest.mark.parametrize("dim", [2, 3])
def test_hover_thrust_force_equals_weight(model, dim):
    plant = QuadrotorPlant(2, dim, QuadrotorSpec(model=model))
    s = fly(plant, hold(np.zeros((2, dim)), 10))
    weight = plant.params.mass_kg * plant.params.gravity_mps2
    np.testing.assert_allclose(s.thrust_N, weight, rtol=0, atol=1e-6)
    np.testing.assert_allclose(s.p_true_m, 0.0, atol=1e-12)
    assert abs(plant.params.hover_command_N - weight) > 1e-3  # the command is weight / cmd_f_coef


def test_hover_is_recovered_after_a_disturbed_start():
    plant = QuadrotorPlant(1, 3)
    plant.reset(np.zeros((1, 3)), np.array([[0.4, -0.3, 0.5]]))
    s = concat_samples([plant.advance(np.zeros((1, 3)), DT) for _ in range(250)])
    weight = plant.params.mass_kg * plant.params.gravity_mps2
    assert s.thrust_N[-1, 0] == pytest.approx(weight, rel=1e-4)
    np.testing.assert_allclose(s.v_true_mps[-1], 0.0, atol=1e-4)


@pytest.mark.parametrize("platform", so_rpy.PLATFORMS)
def test_velocity_step_reaches_90_percent_in_the_time_the_parameters_imply(platform):
    plant = QuadrotorPlant(2, 3, QuadrotorSpec(platform=platform), samples_per_step=50)
    s = fly(plant, hold([[0.5, 0.0, 0.0], [0.0, 0.0, 0.5]], 20))
    for drone, axis, name in ((0, 0, "xy"), (1, 2, "z")):
        predicted = plant.rise_time_90_s(name)
        reached = s.t_s[np.argmax(s.v_true_mps[:, drone, axis] >= 0.45)]
        assert reached <= predicted + 0.004, (platform, name, reached, predicted)
        assert reached >= predicted - 0.004  # the linearisation is the model, not a loose bound
    if platform == "cf2x_L250":
        assert plant.rise_time_90_s("xy") == pytest.approx(0.392, abs=1e-3)
        assert plant.rise_time_90_s("z") == pytest.approx(0.370, abs=1e-3)


def test_inner_loop_is_stable_at_the_declared_rate_and_refused_otherwise():
    params = so_rpy.load_params()
    assert max(inner_loop_radius(params, QuadrotorSpec(), axis) for axis in ("xy", "z")) < 1.0
    assert inner_loop_radius(params, QuadrotorSpec(rate_hz=5.0), "xy") > 1.0  # sampled loop diverges
    with pytest.raises(ValidationError, match="quadrotor.rate_hz.*too coarse"):
        QuadrotorPlant(1, 3, QuadrotorSpec(rate_hz=20.0))
    with pytest.raises(ValidationError, match="quadrotor.rate_hz.*unstable"):
        QuadrotorPlant(1, 3, QuadrotorSpec(gains=QuadrotorGains(kv_xy_per_s=20.0)))
    plant = QuadrotorPlant(1, 3, QuadrotorSpec(rate_hz=500.0 * (1 + 1e-12)))
    plant.reset(np.zeros((1, 3)))
    assert plant.advance(np.zeros((1, 3)), DT).t_s.size == 11
    plant = QuadrotorPlant(1, 3, QuadrotorSpec(rate_hz=333.0))
    plant.reset(np.zeros((1, 3)))
    with pytest.raises(ValidationError, match="multiple of the control rate"):
        plant.advance(np.zeros((1, 3)), DT)
    assert QuadrotorPlant(1, 3).steps_per_interval(DT) == 50
    with pytest.raises(ValidationError, match="fewer than the 10 dense samples"):
        QuadrotorPlant(1, 3, QuadrotorSpec(rate_hz=50.0)).steps_per_interval(DT)


def test_thrust_and_tilt_limits_hold_under_violent_commands():
    spec = QuadrotorSpec()
    plant = QuadrotorPlant(3, 3, spec)
    commands = hold([[6.0, 0.0, 4.0], [-4.0, 4.0, -4.0], [0.0, -6.0, 0.0]], 10) + hold(
        [[-6.0, 0.0, -4.0], [4.0, -4.0, 4.0], [0.0, 6.0, 0.0]], 10
    )
    s = fly(plant, commands)
    pr = plant.params
    assert s.thrust_N.max() <= pr.acc_coef_N + pr.cmd_f_coef * pr.thrust_max_N + 1e-12
    assert s.thrust_N.min() >= pr.acc_coef_N + pr.cmd_f_coef * pr.thrust_min_N - 1e-12
    assert s.thrust_N.max() > 0.99 * pr.cmd_f_coef * pr.thrust_max_N  # the limit was reached
    q = s.quat_xyzw
    tilt = np.arccos(np.clip(1 - 2 * (q[..., 0] ** 2 + q[..., 1] ** 2), -1, 1))
    zeta = -pr.rpy_rates_coef[0] / (2 * np.sqrt(-pr.rpy_coef[0]))
    mp = np.exp(-np.pi * zeta / np.sqrt(1 - zeta**2))  # overshoot of the fitted attitude loop
    l1 = (1 + mp) / (1 - mp)  # L1 norm of its impulse response: the worst transient (a reversal)
    assert tilt.max() > spec.max_tilt_rad * (1 + mp)  # the reversals do overshoot the setpoint...
    assert tilt.max() <= spec.max_tilt_rad * l1  # ...but never beyond the linear bound
    final = tilt[-30:]  # settled on the limit
    np.testing.assert_allclose(final, spec.max_tilt_rad, rtol=1e-2)


def test_constant_wind_leaves_no_steady_velocity_error():
    plant = QuadrotorPlant(2, 3, wind=Wind(np.array([1.0, -0.5, 0.3])))
    s = fly(plant, hold([[0.5, 0.0, 0.0], [0.0, 0.0, 0.0]], 300))
    u = np.array([[0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    early = np.abs(s.v_true_mps[np.searchsorted(s.t_s, 1.0)] - u).max()
    assert early > 0.02  # the wind does push
    np.testing.assert_allclose(s.v_true_mps[-1], u, atol=1e-4)  # integral action removes it


def test_planar_flight_holds_its_altitude_and_returns_the_plane():
    plant = QuadrotorPlant(
        2, 2, QuadrotorSpec(altitude_m=1.5), wind=Wind(np.array([0.5, 0.5]), gust_std_mps=0.3)
    )
    plant.reset(np.zeros((2, 2)))
    heights = []
    for j in range(40):
        s = plant.advance(np.array([[1.0, 0.0], [0.0, -1.0]]) * np.sign(np.sin(j / 5)), DT)
        heights.append(plant.positions_3d_m[:, 2])
    assert (
        s.p_true_m.shape == (11, 2, 2) and s.v_true_mps.shape == (11, 2, 2) and s.wind_mps.shape == (11, 2, 2)
    )
    assert np.abs(np.array(heights) - 1.5).max() < 0.02


def test_planned_positions_pull_the_drone_onto_the_plan():
    wind = Wind(np.array([1.0, 0.0, 0.0]), gust_std_mps=0.5)
    u = np.array([[0.5, 0.2, 0.0]])
    plan = u * DT * np.arange(60)[:, None, None]  # the planner's single-integrator positions
    drift = []
    for planned in (None, plan):
        s = fly(QuadrotorPlant(1, 3, wind=wind, seed=4), hold(u, 60), planned=planned)
        ideal = s.t_s[:, None, None] * u
        drift.append(np.abs(s.p_true_m - ideal).max())
    assert drift[1] < 0.5 * drift[0]


def test_a_full_state_setpoint_feeds_the_acceleration_forward():
    """A drone swinging along x (0.5 m, 2 rad/s: up to 1 m/s and 2 m/s^2), given its full state
    every 20 ms: followed with the acceleration fed forward it stays within 2.5 cm after the start;
    fed forward through the velocity command instead (the export check's old way) its position
    reference ran ahead of the plan, and it lagged by over 3.5 cm."""
    amp, w, dt, steps = 0.5, 2.0, 0.02, 200
    t = dt * np.arange(steps)
    state = np.zeros((3, steps, 1, 3))  # position, velocity, acceleration
    state[:, :, 0, 0] = amp * np.array([1.0 - np.cos(w * t), w * np.sin(w * t), w * w * np.cos(w * t)])
    errors = []
    for full_state in (True, False):
        plant = QuadrotorPlant(1, 3)
        plant.reset(state[0, 0])
        parts = []
        for k in range(steps):
            pos, vel, acc = state[:, k]
            if full_state:
                parts.append(plant.follow(pos, vel, acc, dt))
            else:
                parts.append(plant.advance(vel + acc / plant.spec.gains.kv_xy_per_s, dt, pos))
        s = concat_samples(parts)
        late = s.t_s > 2.0
        errors.append(np.abs(s.p_true_m[late, 0, 0] - amp * (1.0 - np.cos(w * s.t_s[late]))).max())
    assert errors[0] < 0.025 < 0.035 < errors[1]


def test_a_full_state_setpoint_without_acceleration_is_a_velocity_command():
    u, p = np.array([[0.4, -0.2, 0.1]]), np.array([[0.1, 0.0, 1.0]])
    a, b = QuadrotorPlant(1, 3), QuadrotorPlant(1, 3)
    a.reset(p)
    b.reset(p)
    for _ in range(5):
        sa, sb = a.follow(p, u, np.zeros((1, 3)), DT), b.advance(u, DT, p)
        np.testing.assert_array_equal(sa.p_true_m, sb.p_true_m)


def test_wind_and_noise_streams_are_deterministic_per_seed():
    wind = Wind(np.array([1.0, 0.0]), gust_std_mps=0.5)

    def run(seed):
        plant = QuadrotorPlant(3, 2, wind=wind, noise_std_m=0.01, seed=np.random.SeedSequence(seed))
        plant.reset(np.zeros((3, 2)))
        return [plant.advance(np.full((3, 2), 0.3), DT) for _ in range(5)]

    a, b, c = run(1), run(1), run(2)
    assert all(
        np.array_equal(x.p_true_m, y.p_true_m) and np.array_equal(x.p_measured_m, y.p_measured_m)
        for x, y in zip(a, b, strict=True)
    )
    assert not np.array_equal(a[-1].p_true_m, c[-1].p_true_m)
    assert not np.array_equal(a[-1].wind_mps[:, 0], a[-1].wind_mps[:, 1])  # per-drone gusts


def test_samples_carry_attitude_and_thrust():
    plant = QuadrotorPlant(4, 3, samples_per_step=25)
    s = fly(plant, hold(np.full((4, 3), 0.2), 3))
    assert s.t_s.size == 3 * 25 + 1 and s.quat_xyzw.shape == (76, 4, 4) and s.thrust_N.shape == (76, 4)
    np.testing.assert_allclose(np.linalg.norm(s.quat_xyzw, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.diff(s.t_s), DT / 25, atol=1e-12)
