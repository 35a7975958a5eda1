"""The compiled kernels against their numpy paths (:mod:`mpcform.mpc.constraints.kernels`): the
same rows, values and selections to rounding, on random pairs with every branch (growth, stop
splits, close starts, coincident guesses, a downwash metric), and the same plans in flight."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform import _jit
from mpcform.mpc.constraints import kernels
from mpcform.mpc.constraints.pairs import PairSeparation
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve import working_set

pytest.importorskip("numba")


@pytest.fixture
def numpy_path(monkeypatch: pytest.MonkeyPatch):
    """``both(fn)``: ``fn()`` with the kernels off, then on."""

    kernels.warm_up()

    def both(fn):
        monkeypatch.setattr(_jit, "USE", False)
        plain = fn()
        monkeypatch.setattr(_jit, "USE", True)
        return plain, fn()

    return both


def _case(seed: int, n: int, dim: int, horizon: int, tail: int):
    rng = np.random.default_rng(seed)
    p0 = rng.uniform(-1.5, 1.5, (n, dim))
    steps = rng.normal(0.0, 0.08, (n, horizon + tail, dim))
    path = np.concatenate([p0[:, None], p0[:, None] + np.cumsum(steps, axis=1)], axis=1)
    path[1, :] = path[0, :]  # a coincident guess: any fixed unit normal
    i, k = np.triu_indices(n, 1)
    return rng, p0, np.ascontiguousarray(path), np.column_stack([i, k]).astype(np.intp)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("tail", [0, 1])
def test_side_rows_match_numpy(numpy_path, seed: int, tail: int) -> None:
    dim, horizon = (3, 5) if seed % 2 else (2, 3)
    rng, p0, path, pairs = _case(seed, 9, dim, horizon, tail)
    metric = np.ones(dim)
    if dim == 3 and seed % 4 == 1:
        metric[2] = 1.0 / 2.5  # downwash
    settings = MPCSettings(horizon=horizon, coupling="decoupled")
    unit = PairSeparation(0.6, metric, settings, tail, rng.uniform(0.0, 0.01, horizon + 2 * tail + horizon))
    unit.grow = rng.uniform(0.0, 0.01, unit.ends.shape)
    on = rng.random(pairs.shape[0]) < 0.8
    stops = rng.uniform(-1.5, 1.5, (9, dim)) if tail else None
    grows = rng.integers(0, 2, 9).astype(float) if seed % 3 else None
    plain, fast = numpy_path(lambda: unit.rows(p0, path, pairs, on, stops, grows)[1])
    assert plain[4][: pairs.shape[0]].any()  # some pairs start inside d_min: their hard rows
    for a, b in zip(plain, fast, strict=True):
        assert a.shape == b.shape and a.dtype == b.dtype
        np.testing.assert_allclose(b, a, rtol=0.0, atol=1e-14)  # bit for bit here (kernels.dot)


@pytest.mark.parametrize("seed", range(4))
def test_values_and_reachable_rows_match_numpy(numpy_path, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, s, r, d = 7, 40, 9, 3
    singles = rng.integers(0, n, s).astype(np.intp)
    coeffs = rng.normal(size=(s, r, d))
    lower = rng.normal(0.0, 2.0, (s, r))
    on = rng.random(s) < 0.7
    hard = rng.random(s) < 0.3
    ends = np.arange(1, r + 1, dtype=np.intp)
    x_rows = rng.normal(size=(n, r, d))
    plain = np.einsum("srd,srd->sr", coeffs, x_rows[singles]) - lower
    plain[~on] = np.inf
    np.testing.assert_array_equal(kernels.single_values(x_rows, singles, coeffs, lower, on), plain)
    places = np.array([1, -1, 0, 3, -1, 2, 4], dtype=np.intp)  # 5 of the 7 drones solved
    cases = ((0.3, hard, on, None), (None, None, None, None), (0.1, None, on, None), (0.3, hard, on, places))
    for step_m, hard_, on_, local in cases:
        m = n if local is None else 5
        a, b = numpy_path(
            lambda step_m=step_m, hard_=hard_, on_=on_, local=local, m=m: working_set.reachable_rows(
                m, singles, coeffs, lower, hard_, on_, ends, step_m, ends * 1.5, local
            )
        )
        for u, v in zip(a, b, strict=True):
            assert u.shape == v.shape
            np.testing.assert_array_equal(u, v)


def test_a_flight_compiles_nothing_after_the_warm_up() -> None:
    """Every kernel call of a crossing's steps (decoupled, braking stop splits) has a type the
    warm-up compiled: nothing is compiled within a flight."""
    from mpcform.bench.scale_cases import DT_S, LIMITS, make_case
    from mpcform.mpc.planner import MPCPlanner

    ref, p = make_case("crossing", _jit.MIN_DRONES)
    planner = MPCPlanner(ref, DT_S, LIMITS, MPCSettings(coupling="decoupled"))
    names = ("side_rows", "single_values", "reachable_rows")
    before = {f: list(getattr(kernels, f).signatures) for f in names}
    planner.reset(0.0, p)
    for k in range(4):
        out = planner.step(k * DT_S, p)
        p = p + DT_S * out.command_mps
    assert {f: list(getattr(kernels, f).signatures) for f in names} == before


@pytest.mark.parametrize("stop", [9, 6, 0])
def test_least_values_match_numpy(stop: int) -> None:
    rng = np.random.default_rng(stop)
    values = rng.normal(size=(40, 9))
    values[3] = np.inf  # an item out of reach
    split = rng.random(40) < 0.6
    plain = values.min(axis=1, initial=np.inf)
    plain[split] = values[split, :stop].min(axis=1, initial=np.inf)
    np.testing.assert_array_equal(kernels.item_least(values, split, stop), plain)
    first, second = np.arange(0, 20), np.arange(20, 40)
    assert kernels.joint_least(values, first, second) == (values[first] + values[second]).min(initial=np.inf)
    assert kernels.joint_least(values, first[:0], second[:0]) == np.inf


@pytest.mark.parametrize("per_drone_bounds", [True, False])
def test_working_sets_match_numpy(numpy_path, per_drone_bounds: bool) -> None:
    """The constant rows near a bound at ``v = c`` or at the warm start, compiled and by numpy."""
    rng = np.random.default_rng(3)
    n, c, nu = 300, 40, 6
    const_v, warm = rng.normal(size=(c, nu)), rng.normal(size=(n, nu))
    const_c = rng.normal(size=(n, c))
    b_lo = -np.abs(rng.normal(1.0, 1.0, (n if per_drone_bounds else 1, c)))
    b_hi = np.abs(rng.normal(1.0, 1.0, (n if per_drone_bounds else 1, c)))
    busy = np.sort(rng.choice(n, 200, replace=False))
    a, b = numpy_path(lambda: working_set.working_sets(const_v, const_c, warm, b_lo, b_hi, busy))
    assert a is not None and b is not None and 0 < a.sum() < a.size
    np.testing.assert_array_equal(a, b)
