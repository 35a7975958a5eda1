"""Ideal, lag and second-order plants: exact discretisation against a fine RK4, the ideal's
straight segments, seeding of wind and noise, the interface's checks."""

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.sim.plants import (
    DRAG_PER_S,
    IdealPlant,
    concat_samples,
    lag_plant,
    second_order_plant,
)
from mpcform.sim.wind import Wind

RNG = np.random.default_rng(11)
P0 = RNG.normal(size=(4, 3))
V0 = RNG.normal(size=(4, 3))
COMMANDS = RNG.normal(size=(6, 4, 3))


def rk4(f, x, h, steps):
    for _ in range(steps):
        k1 = f(x)
        k2 = f(x + 0.5 * h * k1)
        k3 = f(x + 0.5 * h * k2)
        k4 = f(x + h * k3)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def reference_run(rhs, x0, samples, dt=0.1, fine=100):
    """Integrate x' = rhs(x, u, w) with u held per interval, w held per sub-step (from samples)."""
    x, out = x0.copy(), [x0[..., 0].copy()]
    m = samples[0].t_s.size - 1
    for u, s in zip(COMMANDS, samples, strict=True):
        for i in range(m):
            w = np.zeros((4, 3)) if s.wind_mps is None else s.wind_mps[i]
            x = rk4(lambda z, u=u, w=w: rhs(z, u, w), x, dt / m / fine, fine)
            out.append(x[..., 0].copy())
    return np.array(out)


def drive(plant, dt=0.1):
    plant.reset(P0, V0)
    return [plant.advance(u, dt) for u in COMMANDS]


@pytest.mark.parametrize("wind", [None, Wind([1.0, -0.5, 0.2], gust_std_mps=0.5, gust_time_s=0.3)])
def test_lag_is_exact(wind):
    tau = 0.2
    samples = drive(lag_plant(4, 3, tau, wind=wind, seed=1))
    x0 = np.stack([P0, V0], axis=-1)

    def rhs(x, u, w):
        return np.stack([x[..., 1], (u - x[..., 1]) / tau + DRAG_PER_S * w], axis=-1)

    ref = reference_run(rhs, x0, samples)
    got = concat_samples(samples).p_true_m
    np.testing.assert_allclose(got, ref, atol=1e-11, rtol=0)


def test_lag_matches_the_simulators_closed_form():
    tau, dt = 0.3, 0.1
    plant = lag_plant(4, 3, tau)
    plant.reset(P0, V0)
    s = plant.advance(COMMANDS[0], dt)
    decay = np.exp(-dt / tau)
    np.testing.assert_allclose(
        s.p_true_m[-1], P0 + dt * COMMANDS[0] + (V0 - COMMANDS[0]) * tau * (1 - decay), atol=1e-14
    )
    np.testing.assert_allclose(s.v_true_mps[-1], COMMANDS[0] + (V0 - COMMANDS[0]) * decay, atol=1e-14)


@pytest.mark.parametrize("wind", [None, Wind([0.5, 0.0, -1.0], gust_std_mps=0.4, gust_time_s=0.2)])
def test_second_order_is_exact_with_its_own_vertical_pair(wind):
    zeta, w_n, zeta_z, w_z = 0.7, 6.0, 0.9, 4.0
    samples = drive(second_order_plant(4, 3, zeta, w_n, zeta_z=zeta_z, omega_z_rad_s=w_z, wind=wind, seed=2))
    x0 = np.stack([P0, V0, np.zeros_like(P0)], axis=-1)
    z = np.array([zeta, zeta, zeta_z])
    w = np.array([w_n, w_n, w_z])

    def rhs(x, u, wind_mps):
        v, a = x[..., 1], x[..., 2]
        return np.stack([v, a + DRAG_PER_S * wind_mps, w**2 * (u - v) - 2 * z * w * a], axis=-1)

    ref = reference_run(rhs, x0, samples)
    np.testing.assert_allclose(concat_samples(samples).p_true_m, ref, atol=1e-11, rtol=0)


def test_steady_wind_offsets_the_linear_plants_by_their_mean_delay():
    wind = Wind([1.0, 0.0])
    for plant, delay in (
        (lag_plant(1, 2, 0.25, wind=wind), 0.25),
        (second_order_plant(1, 2, 0.7, 6.0, wind=wind), 2 * 0.7 / 6.0),
    ):
        plant.reset(np.zeros((1, 2)))
        for _ in range(100):
            s = plant.advance(np.array([[0.5, 0.0]]), 0.1)
        np.testing.assert_allclose(s.v_true_mps[-1, 0], [0.5 + delay * DRAG_PER_S, 0.0], atol=1e-9)


def test_ideal_plant_is_straight_segments_bitwise():
    plant = IdealPlant(4, 3)
    samples = drive(plant, dt=0.05)
    p = P0
    for u, s in zip(COMMANDS, samples, strict=True):
        frac = np.linspace(0.0, 0.05, 11)
        assert np.array_equal(s.p_true_m, p + frac[:, None, None] * u)
        assert np.array_equal(s.p_true_m[-1], p + 0.05 * u)  # the single integrator's own update
        assert np.array_equal(s.v_true_mps, np.broadcast_to(u, s.p_true_m.shape))
        p = p + 0.05 * u
    assert samples[-1].t_s[-1] == pytest.approx(0.3)


def test_samples_are_dense_with_both_ends_and_concatenate():
    plant = lag_plant(4, 3, 0.1, samples_per_step=12)
    samples = drive(plant)
    assert all(s.t_s.size == 13 and s.p_true_m.shape == (13, 4, 3) for s in samples)
    joined = concat_samples(samples)
    assert joined.t_s.size == 6 * 12 + 1
    np.testing.assert_allclose(np.diff(joined.t_s), 0.1 / 12)
    assert np.array_equal(joined.p_true_m[12], samples[1].p_true_m[0])
    assert joined.wind_mps is None and joined.quat_xyzw is None
    with pytest.raises(ValidationError, match="samples"):
        concat_samples([])


def test_noise_and_wind_have_their_own_seeded_streams():
    wind = Wind([0.0, 0.0, 0.0], gust_std_mps=0.5)

    def run(seed, wind=wind, noise=0.01):
        plant = lag_plant(4, 3, 0.2, wind=wind, noise_std_m=noise, seed=np.random.SeedSequence(seed))
        return drive(plant)

    a, b, c = run(3), run(3), run(4)
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.p_measured_m, y.p_measured_m) and np.array_equal(x.wind_mps, y.wind_mps)
    assert not np.array_equal(a[-1].p_measured_m, c[-1].p_measured_m)
    noise_a = [s.p_measured_m - s.p_true_m[-1] for s in a]
    noise_still = [s.p_measured_m - s.p_true_m[-1] for s in run(3, wind=None)]
    np.testing.assert_allclose(noise_a, noise_still, atol=1e-15)  # the wind draws do not shift the noise
    quiet = run(3, noise=0.0)
    assert all(np.array_equal(s.p_measured_m, s.p_true_m[-1]) for s in quiet)
    plant = lag_plant(4, 3, 0.2, wind=wind, noise_std_m=0.01, seed=3)
    first = drive(plant)
    again = drive(plant)  # reset restarts both streams
    assert np.array_equal(first[-1].p_measured_m, again[-1].p_measured_m)


def test_plant_checks_its_inputs():
    plant = lag_plant(2, 2, 0.2)
    with pytest.raises(ValidationError, match="plant.positions"):
        plant.reset(np.zeros((3, 2)))
    plant.reset(np.zeros((2, 2)))
    with pytest.raises(ValidationError, match="plant.command"):
        plant.advance(np.full((2, 2), np.nan), 0.1)
    with pytest.raises(ValidationError, match="plant.dt"):
        plant.advance(np.zeros((2, 2)), 0.0)
    with pytest.raises(ValidationError, match="plant.tau"):
        lag_plant(2, 2, 0.0)
    with pytest.raises(ValidationError, match="plant.samples_per_step"):
        lag_plant(2, 2, 0.1, samples_per_step=5)
    with pytest.raises(ValidationError, match="wind.mean"):
        lag_plant(2, 2, 0.1, wind=Wind([1.0, 0.0, 0.0]))
    with pytest.raises(ValidationError, match="plant.dim"):
        lag_plant(2, 4, 0.1)
