"""One rest-to-rest time scaling: the path is kept, both ends at rest, limits met along the path."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs.flight import retime as retime_module
from mpcform.outputs.flight.polynomial import fit_positions
from mpcform.outputs.flight.retime import minimum_time_s, retime


def _path():  # two drones crossing at 1 m/s for 4 s, with a turn
    t = np.linspace(0.0, 4.0, 81)
    a = np.stack([t - 2.0, 0.3 * np.sin(t), np.ones_like(t)], axis=-1)
    b = np.stack([2.0 - t, -0.3 * np.sin(t), np.ones_like(t)], axis=-1)
    return t, np.stack([a, b], axis=1)


def test_rest_to_rest_within_the_limits() -> None:
    t, p = _path()
    path = fit_positions(t, p, 1e-4).polynomial
    timing = retime(path, 0.5, 1.0, 5.0)
    assert timing.duration_s > 4.0 / 0.5 * 0.99  # no faster than the speed limit allows
    tt = timing.t_s
    tau = timing.tau_s
    assert tau[0] == 0.0 and tau[-1] == pytest.approx(4.0) and np.all(np.diff(tau) >= 0)
    pos = timing.positions(tt)
    vel = np.gradient(pos, tt, axis=0)
    acc = np.gradient(vel, tt, axis=0)
    assert np.linalg.norm(vel, axis=-1).max() <= 0.5 * 1.01
    assert np.linalg.norm(acc[5:-5], axis=-1).max() <= 1.0 * 1.05
    assert np.linalg.norm(vel[[0, -1]], axis=-1).max() < 1e-3  # at rest at both ends
    # one scaling for both drones: the relative timing, hence the distances along the path, are kept
    for x in (0.5, 1.7, 3.2):
        k = np.searchsorted(tau, x)
        assert np.allclose(pos[k], path.evaluate(tau[k]).reshape(2, 3))
    assert timing.new_time(timing.original_time(3.0)) == pytest.approx(3.0, abs=1e-6)


def test_tighter_limits_take_longer() -> None:
    t, p = _path()
    path = fit_positions(t, p, 1e-4).polynomial
    assert retime(path, 0.25, 1.0, 5.0).duration_s > retime(path, 0.5, 1.0, 5.0).duration_s


@pytest.mark.parametrize(
    ("limits", "field"),
    [((1e-6, 1.0, 5.0), "max_speed"), ((0.5, 1e-9, 5.0), "max_acc"), ((0.5, 1.0, 1e-12), "max_jerk")],
)
def test_a_flight_too_long_is_refused_naming_the_limit_that_slows_it(
    limits: tuple[float, float, float], field: str
) -> None:
    path = fit_positions(*_path(), 1e-4).polynomial
    with pytest.raises(
        ValidationError, match=rf"^{field}: at this limit the retimed flight would last .* s, above"
    ):
        retime(path, *limits, max_duration_s=100.0)  # before its 2 ms grid (50 GiB at 1e-6 m/s) is allocated
    assert retime(path, 0.5, 1.0, 5.0, max_duration_s=100.0).duration_s < 100.0


def test_close_to_the_minimum_time_without_a_slow_end() -> None:
    """Within 1.3 times a lower bound on the minimum time, and no final stretch below 5 % of the
    speed limit over 0.5 s, on a plan that creeps to its goal for its last half (the old
    one-motion scaling took 2-3 times)."""
    t = np.linspace(0.0, 8.0, 161)
    x = np.where(t < 4.0, t / 4.0, 1.0 + 0.05 * (1.0 - np.exp(-(t - 4.0))))  # 1 m, then 5 cm slowly
    p = np.stack([x, 0 * t, np.ones_like(t)], axis=-1)[:, None]
    path = fit_positions(t, p, 1e-4).polynomial
    v, a, j = 1.0, 1.79, 30.0
    timing = retime(path, v, a, j)
    floor = minimum_time_s(path, v, a, j)
    assert floor <= timing.duration_s <= 1.3 * floor
    tt = timing.t_s
    speed = np.linalg.norm(np.gradient(timing.positions(tt), tt, axis=0), axis=-1)[:, 0]
    fast = np.nonzero(speed >= 0.05 * v)[0]
    assert tt[-1] - tt[fast[-1]] <= 0.5


def test_the_minimum_time_takes_every_limit_alone_and_survives_an_unsolved_scaling(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A long, gentle path whose jerk alone sets the bound: (32 L / j)^(1/3) for its length L; and
    a scaling program that does not solve leaves the other bounds (it used to stop the export)."""
    t = np.linspace(0.0, 40.0, 401)
    p = np.stack([0.05 * t, 0 * t, np.ones_like(t)], axis=-1)[:, None]  # 2 m over 40 s of plan
    path = fit_positions(t, p, 1e-4).polynomial
    v, a, j = 10.0, 10.0, 0.01  # jerk-bound: (32 * 2 / 0.01)^(1/3) = 18.6 s
    assert minimum_time_s(path, v, a, j) >= 0.999 * np.cbrt(32.0 * 2.0 / j)

    def fails(*args, **kwargs):
        raise MPCFormError("the time scaling's convex program ended MaxIterations")

    monkeypatch.setattr(retime_module, "time_optimal", fails)
    assert minimum_time_s(path, v, a, j) >= 0.999 * np.cbrt(32.0 * 2.0 / j)


def test_a_local_slow_down_slows_only_around_its_times() -> None:
    """Factors at new times land on the nodes nearest their original times (times the nodes'
    earlier ones); retimed with them, the flight is slower there and as fast elsewhere."""
    t, p = _path()
    path = fit_positions(t, p, 1e-4).polynomial
    timing = retime(path, 0.5, 1.0, 5.0)
    assert np.all(timing.slower == 1.0) and timing.slower.shape == timing.tau_nodes_s.shape
    middle = timing.new_time(2.0)
    at = np.array([middle - 0.2, middle, middle + 0.2])
    slower = timing.slower_where(at, np.array([1.5, 1.5, 1.5]))
    near = np.abs(timing.tau_nodes_s - 2.0) < 0.3
    assert np.all(slower[~near] == 1.0) and 2 <= np.count_nonzero(slower == 1.5) <= 3
    again = retime(path, 0.5, 1.0, 5.0, slower=slower)
    assert timing.duration_s < again.duration_s
    speed = [
        np.linalg.norm(np.gradient(r.positions(r.t_s), r.t_s, axis=0), axis=-1).max(axis=1)
        for r in (timing, again)
    ]
    assert speed[1][np.argmin(np.abs(again.original_time(again.t_s) - 2.0))] <= 0.5 / 1.5 * 1.01
    assert speed[1].max() == pytest.approx(speed[0].max(), rel=0.02)  # elsewhere at the speed limit
