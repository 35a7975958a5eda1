"""The rows each drone's DAQP call is given: reachable rows, bounds, working sets, misses, the stack."""

from __future__ import annotations

import numpy as np

from mpcform.mpc.constraints.rows import positions_of_inputs, row_ends
from mpcform.mpc.solve.working_set import (
    WORKING_MARGIN,
    misses,
    reachable_rows,
    row_values,
    separation_misses,
    separation_sets,
    stack,
    within_bounds,
)


def test_only_the_rows_that_can_be_active_are_built() -> None:
    """Rows of items within reach with ``b > -|a| e v_max dt``, by drone (item order kept), are
    kept, named by their flat ``item * R + row`` index; an item's hard first row has no slack."""
    dim, n, step_m = 2, 4, 0.1  # v_max 1, dt 0.1
    rng = np.random.default_rng(5)
    s, r = 12, 5  # items, rows per item (horizon 3)
    singles, on, hard = rng.integers(0, n, s), rng.random(s) < 0.8, rng.random(s) < 0.3
    coeffs = rng.normal(size=(s, r, dim)) * rng.uniform(0.5, 1.0, (s, r, 1))
    ends = row_ends(3)
    assert ends.tolist() == [1, 2, 1, 3, 2]
    reach = np.linalg.norm(coeffs, axis=2) * ends * step_m
    lower = -reach * rng.uniform(0.5, 1.5, (s, r))
    expect = [
        (i, item, row)
        for i in range(n)
        for item in range(s)
        for row in range(r)
        if singles[item] == i and on[item] and lower[item, row] > -reach[item, row]
    ]
    c, end, lo, soft, counts, at = reachable_rows(n, singles, coeffs, lower, hard, on, ends, step_m)
    assert c.shape[0] == len(expect) and counts.tolist() == [sum(e[0] == i for e in expect) for i in range(n)]
    for got, (_, item, row) in enumerate(expect):
        assert np.array_equal(c[got], coeffs[item, row]) and lo[got] == lower[item, row]
        assert end[got] == ends[row] and soft[got] == (row > 0 or not hard[item])
        assert at[got] == item * r + row


def test_the_rows_of_some_drones_are_those_of_their_subset() -> None:
    """With ``local`` (each drone's place among those solved, -1: not solved) the rows are those of
    the items of the solved drones renumbered by their place (``SeparationRows.subset``), in the
    same order; ``at`` names them in the items given."""
    rng = np.random.default_rng(8)
    n, s, r, dim = 6, 30, 5, 3
    singles, on, hard = rng.integers(0, n, s), rng.random(s) < 0.8, rng.random(s) < 0.3
    coeffs, lower, ends = rng.normal(size=(s, r, dim)), rng.normal(-0.1, 0.2, (s, r)), row_ends(3)
    drones = np.array([4, 0, 2])  # solved in this order: drone 4 first
    local = np.full(n, -1)
    local[drones] = np.arange(3)
    items = np.flatnonzero(local[singles] >= 0)
    got = reachable_rows(3, singles, coeffs, lower, hard, on, ends, 0.1, None, local)
    sub = reachable_rows(
        3, local[singles[items]], coeffs[items], lower[items], hard[items], on[items], ends, 0.1
    )
    for a, b in zip(got[:5], sub[:5], strict=True):
        assert np.array_equal(a, b)
    item, row = np.divmod(got[5], r)
    assert np.array_equal(items[np.divmod(sub[5], r)[0]], item) and np.array_equal(
        np.divmod(sub[5], r)[1], row
    )
    assert got[4].sum() > 0 and (local[singles[item]] >= 0).all()


def _rows(seed: int, n: int = 5, h: int = 4, dim: int = 3) -> tuple[np.ndarray, ...]:
    """Random separation rows of ``n`` drones over positions ``x = x_of_v v`` (v = u here)."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 6, n)
    owner = np.repeat(np.arange(n), counts)
    sep_c, sep_end = rng.normal(size=(owner.shape[0], dim)), rng.integers(1, h + 1, owner.shape[0])
    return positions_of_inputs(h, dim, 0.1), rng.normal(size=(n, h * dim)), sep_c, sep_end, owner


def test_row_values_are_each_rows_normal_times_its_drones_position() -> None:
    """``a^T x_e`` of each row, against the positions computed drone by drone, step by step."""
    x_of_v, v, sep_c, sep_end, owner = _rows(1)
    h, dim = 4, 3
    got = row_values(x_of_v, v, sep_c, owner * h + sep_end - 1)
    for k, (i, e) in enumerate(zip(owner, sep_end, strict=True)):
        x_e = 0.1 * v[i].reshape(h, dim)[:e].sum(axis=0)  # x_e = dt sum_{j<e} u_j
        assert abs(got[k] - sep_c[k] @ x_e) < 1e-12


def test_a_drone_is_within_bounds_when_all_its_constant_rows_hold() -> None:
    """Bounds shared by every drone (one row) or per drone; a bound itself holds."""
    values = np.array([[0.0, 1.0], [0.5, 2.5], [1.0, 2.0], [-1.0, -1.5]])
    b_lo, b_hi = np.array([[-1.0, -1.0]]), np.array([[1.0, 2.0]])
    assert within_bounds(values, b_lo, b_hi).tolist() == [True, False, True, False]
    b_lo_n = np.repeat(b_lo, 4, axis=0)
    b_lo_n[3] = -2.0
    assert within_bounds(values, b_lo_n, b_hi).tolist() == [True, False, True, True]


def test_working_sets_and_misses() -> None:
    """The rows near their bound at the wish or the warm start are given; a drone misses when a
    row not given is violated at its solve, never for a given one."""
    lower = np.zeros(5)
    at_c = np.array([-1.0, 0.5 * WORKING_MARGIN, 1.0, 1.0, 2.0])
    at_warm = np.array([1.0, 1.0, 0.5 * WORKING_MARGIN, 1.0, 2.0])
    given = separation_sets(at_c, at_warm, lower)
    assert given.tolist() == [True, True, True, False, False]
    owner = np.array([0, 0, 1, 1, 2])
    at_v = np.array([-5.0, 1.0, -5.0, -1e-12, 0.0])  # drone 0 violates a given row only
    assert separation_misses(at_v, lower, given, owner, 4).tolist() == [False, True, False, False]
    const_v, v = np.eye(2), np.array([[0.5, 3.0], [0.5, 3.0]])
    b_lo, b_hi = np.zeros((1, 2)), np.ones((1, 2))
    given_c = np.array([[False, True], [False, False]])
    assert misses(const_v, v, given_c, b_lo, b_hi, np.array([0, 1])).tolist() == [False, True]


def test_the_stack_holds_each_drones_rows_and_places_their_multipliers() -> None:
    """Drone j's block is its given constant rows (with its own or the shared bounds), then its
    given separation rows; ``full`` sends each row to its place among all the drone's rows."""
    rng = np.random.default_rng(3)
    n, c, nu = 6, 7, 4
    const_v, some = rng.normal(size=(c, nu)), np.array([1, 2, 4, 5])
    near = rng.random((some.shape[0], c)) < 0.4
    n_sep = np.array([3, 0, 5, 2])  # every separation row of each drone of some
    chosen = [np.flatnonzero(rng.random(k) < 0.6) for k in n_sep.tolist()]
    sep_drone = np.concatenate([np.full(len(t), j) for j, t in enumerate(chosen)]).astype(np.intp)
    sep_local = np.concatenate(chosen).astype(np.intp)
    sep_a, sep_lo = rng.normal(size=(sep_drone.shape[0], nu)), rng.normal(size=sep_drone.shape[0])
    for b_lo in (rng.normal(size=(1, c)), rng.normal(size=(n, c))):
        b_hi = b_lo + 1.0
        stk = stack(const_v, near, b_lo, b_hi, some, sep_a, sep_lo, sep_drone, sep_local, n_sep, 1e30)
        for j, i in enumerate(some.tolist()):
            rows, mine = slice(stk.starts[j], stk.starts[j + 1]), sep_drone == j
            b = i if b_lo.shape[0] > 1 else 0
            assert np.array_equal(stk.a[rows], np.vstack([const_v[near[j]], sep_a[mine]]))
            assert np.array_equal(stk.lo[rows], np.concatenate([b_lo[b, near[j]], sep_lo[mine]]))
            assert np.array_equal(stk.hi[rows], np.concatenate([b_hi[b, near[j]], np.full(mine.sum(), 1e30)]))
            place = stk.full[rows] - stk.full_starts[j]
            assert stk.full_starts[j + 1] - stk.full_starts[j] == c + n_sep[j]
            assert np.array_equal(place, np.concatenate([np.flatnonzero(near[j]), c + sep_local[mine]]))
