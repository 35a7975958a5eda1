"""The time-optimal scaling against closed forms and ruckig's time-optimal 1-DoF motion."""

from __future__ import annotations

import numpy as np
import pytest
from ruckig import InputParameter, Ruckig, Trajectory

from mpcform.outputs.flight.topp import Profile, time_optimal


def _line(length_m: float, nodes: int = 201, drones: int = 1) -> tuple[tuple, float]:
    """A straight line of ``length_m`` along x, parametrised unevenly: ``P(tau) = L tau^2`` on
    [0, 1] (the scaling must not depend on the parametrisation), ``drones`` copies side by side."""
    tau = np.linspace(0.0, 1.0, nodes)
    d = np.zeros((3, nodes, drones, 3))
    d[0, :, :, 0] = (2.0 * length_m * tau)[:, None]
    d[1, :, :, 0] = 2.0 * length_m
    return (d[0], d[1], d[2]), tau[1] - tau[0]


def _ruckig_s(length_m: float, v: float, a: float, j: float) -> float:
    otg, inp, out = Ruckig(1), InputParameter(1), Trajectory(1)
    inp.current_position, inp.target_position = [0.0], [length_m]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v], [a], [j]
    otg.calculate(inp, out)
    return float(out.duration)


@pytest.mark.parametrize("length_m", [0.2, 4.0])
def test_speed_and_acceleration_alone_give_the_trapezoid(length_m: float) -> None:
    derivatives, step = _line(length_m)
    v, a = 1.0, 2.0
    exact = length_m / v + v / a if length_m >= v * v / a else 2.0 * np.sqrt(length_m / a)
    profile = time_optimal(derivatives, step, v, a, None)
    assert profile.lower_bound_s == pytest.approx(exact, rel=0.02)
    assert profile.duration_s == profile.lower_bound_s


def _check_limits(profile: Profile, derivatives: tuple, v: float, a: float) -> None:
    d1, d2, _ = derivatives
    speed = np.linalg.norm(d1, axis=-1) * np.sqrt(profile.b)[:, None]
    assert speed.max() <= v * (1 + 1e-6)
    alpha = profile.segment_acc
    for node, seg in ((slice(0, -1), alpha), (slice(1, None), alpha)):  # both ends of each segment
        acc = d2[node] * profile.b[node, None, None] + d1[node] * seg[:, None, None]
        assert np.linalg.norm(acc, axis=-1).max() <= a * (1 + 1e-5)


@pytest.mark.parametrize("length_m", [0.2, 4.0])
def test_with_jerk_within_1_3_of_ruckigs_minimum(length_m: float) -> None:
    derivatives, step = _line(length_m)
    v, a, j = 1.0, 2.0, 10.0
    profile = time_optimal(derivatives, step, v, a, j)
    best = _ruckig_s(length_m, v, a, j)
    assert profile.lower_bound_s <= best * 1.01  # without jerk: no slower than the true minimum
    assert best * 0.98 <= profile.duration_s <= 1.3 * best
    _check_limits(profile, derivatives, v, a)
    assert profile.b[0] == profile.b[-1] == 0.0  # rest to rest


def test_a_curve_keeps_every_drones_limits_with_cones_added_where_they_bind() -> None:
    tau = np.linspace(0.0, 2.0 * np.pi, 301)
    radii = np.linspace(0.5, 2.0, 12)  # 12 drones on circles: the outer one is the fastest
    d1 = np.stack(
        [-np.sin(tau)[:, None] * radii, np.cos(tau)[:, None] * radii, 0 * tau[:, None] + 0 * radii], -1
    )
    d2 = np.stack([-np.cos(tau)[:, None] * radii, -np.sin(tau)[:, None] * radii, 0 * d1[..., 0]], -1)
    d3 = np.stack([np.sin(tau)[:, None] * radii, -np.cos(tau)[:, None] * radii, 0 * d1[..., 0]], -1)
    v, a, j = 1.0, 0.8, 5.0
    profile = time_optimal((d1, d2, d3), tau[1] - tau[0], v, a, j)
    _check_limits(profile, (d1, d2, d3), v, a)
    # steady on the circle: the outer drone at v^2 / r <= a, i.e. sqrt(a r) = 1.26 > v: speed-bound
    middle = profile.b[100:200]
    assert np.sqrt(middle).max() == pytest.approx(v / radii[-1], rel=1e-3)
    assert profile.lower_bound_s < profile.duration_s < 1.3 * profile.lower_bound_s


def test_a_path_standing_still_passes_at_the_fastest_scaling() -> None:
    (d1, d2, d3), step = _line(1.0)
    profile = time_optimal((0 * d1, 0 * d2, 0 * d3), step, 1.0, 1.0, 1.0)
    assert np.isfinite(profile.duration_s) and profile.duration_s < 0.05


def test_a_jerk_limit_that_does_not_bind_gives_the_speed_and_acceleration_optimum() -> None:
    derivatives, step = _line(4.0)
    profile = time_optimal(derivatives, step, 1.0, 2.0, 1e9)  # no tangent of 1e9 / sqrt(b) to solve
    assert profile.duration_s == profile.lower_bound_s


def test_slower_nodes_keep_their_lowered_limits_and_the_rest_its_own() -> None:
    """``slower`` f at a node divides the speed limit there by f and the acceleration's by f^2."""
    derivatives, step = _line(4.0)
    v, a = 1.0, 2.0
    plain = time_optimal(derivatives, step, v, a, None)
    f = np.ones(plain.b.size)
    f[80:120] = 2.0
    slowed = time_optimal(derivatives, step, v, a, None, f)
    speed = np.linalg.norm(derivatives[0], axis=-1)[:, 0] * np.sqrt(slowed.b)
    assert speed[80:120].max() <= v / 2.0 * (1 + 1e-6) < speed.max()
    _check_limits(slowed, derivatives, v, a)
    assert plain.duration_s < slowed.duration_s < 2.0 * plain.duration_s


def test_a_smoothed_profile_changes_s_ddot_continuously_from_rest_to_rest() -> None:
    derivatives, step = _line(4.0)
    profile = time_optimal(derivatives, step, 1.0, 2.0, 10.0)
    smooth = profile.smoothed(8)
    assert smooth.b.size == 8 * (profile.b.size - 1) + 1 and smooth.b[0] == smooth.b[-1] == 0.0
    assert np.all(smooth.b >= 0.0) and np.all(smooth.b[1:-1] > 0.0)
    # s'' steps by up to a_max / L at the nodes of the profile, by an eighth of that once smoothed
    jumps = [np.abs(np.diff(p.segment_acc)).max() for p in (profile, smooth)]
    assert jumps[1] <= jumps[0] / 4.0
    assert smooth.duration_s == pytest.approx(profile.duration_s, rel=0.02)
