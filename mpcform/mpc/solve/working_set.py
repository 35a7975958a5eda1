"""Which rows each drone's DAQP call is given (:mod:`mpcform.mpc.solve.per_drone`).

A drone's QP is strictly convex, so its optimum is unique: the optimum of a relaxation (some rows
left out) that meets every left-out row is the optimum, and DAQP's multipliers of the left-out
rows are zero, as for inactive rows. Four selections use this:

- :func:`reachable_rows`: a separation row that every reachable position meets is never given;
- :func:`within_bounds`: a drone whose unconstrained optimum ``v = c`` meets every row (its constant
  rows, then its separation rows) needs no call;
- :func:`working_sets` and :func:`separation_sets`: in a call with many rows, each drone is first
  given only its rows near their bound (at ``v = c`` or at its warm start);
- :func:`misses` and :func:`separation_misses` find the solves that miss a row left out: those
  drones are solved again with every row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform import _jit
from mpcform._validate import Array
from mpcform.world.closest import vector_norms

WORKING_MARGIN = 0.1  # rows this close to a bound [m/s or m] go to DAQP first
WORKING_MIN_ROWS = 5000  # ... in a call whose drones to solve times constant rows reach this (the
# selection costs ~100 us a call: below it, measured, the swaps of 8-16 drones ran 3-26 % slower)


def reachable_rows(
    n: int,
    singles: Array,
    coeffs: Array,
    lower: Array,
    hard: Array | None,
    on: Array | None,
    ends: Array,
    step_m: float | None,
    reach_steps: Array | None = None,
    local: Array | None = None,
) -> tuple[Array, Array, Array, Array, Array, Array]:
    """The separation rows that can be active, sorted by drone (item order kept within a drone):
    their coefficients ``a`` (K, d), position steps, lower bounds and whether they have a slack
    (not an item's hard first row); the number of rows per drone; and which they are (K,), as
    flat ``item * R + row`` indices (items ``singles`` (S,), ``coeffs`` (S, R, d), ``lower`` (S, R),
    rows at position steps ``ends`` (R,), ``reach_steps`` (R,) longest steps away: ``ends`` by default;
    the braking stop point is farther, :mod:`mpcform.mpc.constraints.braking`); ``local`` (N,): the
    items' drones' places among the ``n`` drones solved (-1: not solved, its items left out), for
    ``singles`` that index N drones (None: ``singles`` are the places).

    A row ``a^T x_e + s_e >= b`` that every reachable ``x_e`` meets (``b <= -|a| e step_m``, the
    longest step ``step_m`` = v_max dt, since the velocity set lies in the ball; None: no limit) is
    left out, the optimum unchanged. The rows over ``v`` are built later, drone by drone into
    DAQP's buffer (:meth:`PerDroneQP._rows_v`). Compiled with numba when it is installed
    (:func:`mpcform.mpc.constraints.kernels.reachable_rows`).
    """
    if _jit.USE:
        from mpcform.mpc.constraints import kernels

        no = np.empty(0, dtype=bool)
        limit = -1.0 if step_m is None else step_m
        reach = ends.astype(float) if reach_steps is None else reach_steps
        hard_, on_ = no if hard is None else hard, no if on is None else on
        local_ = np.empty(0, dtype=np.intp) if local is None else local
        c = np.ascontiguousarray  # the one layout the kernel is compiled for
        args = (c(singles), c(coeffs), c(lower), c(hard_), c(on_), c(ends), float(limit), c(reach, float))
        return kernels.reachable_rows(n, *args, c(local_, np.intp))
    keep = np.ones(lower.shape, dtype=bool)
    if on is not None:
        keep &= on[:, None]
    if local is not None:
        singles = local[singles]
        keep &= (singles >= 0)[:, None]
    if step_m is not None:
        keep &= lower > -(vector_norms(coeffs) * ((ends if reach_steps is None else reach_steps) * step_m))
    order = np.argsort(singles, kind="stable")
    rows = ends.shape[0]
    at = (order[:, None] * rows + np.arange(rows))[keep[order]]  # flat (item, row) indices
    item, r = np.divmod(at, rows)
    soft = r > 0
    if hard is not None:
        soft |= ~hard[item]
    counts = np.bincount(singles[item], minlength=n).astype(np.intp)
    sep_c = np.take(coeffs.reshape(-1, coeffs.shape[2]), at, axis=0)
    return sep_c, ends[r], np.take(lower.reshape(-1), at), soft, counts, at


def row_values(x_of_v: Array, v: Array, sep_c: Array, at_x: Array) -> Array:
    """The separation rows' values ``a^T x_e`` (K,) at the drones' ``v`` (n, H d) (positions
    ``x = x_of_v v``, (n S, d) drone by drone, S positions each; row k on ``x[at_x[k]]``, i.e.
    ``drone S + e - 1``)."""
    x = (v @ x_of_v.T).reshape(-1, sep_c.shape[1])
    return np.einsum("kd,kd->k", sep_c, np.take(x, at_x, axis=0))


def within_bounds(values: Array, b_lo: Array, b_hi: Array) -> Array:
    """Which drones (n,) meet all their constant rows: ``values`` (n, c) within the bounds ``b_lo``,
    ``b_hi`` (n or 1, c)."""
    return np.asarray(((values >= b_lo) & (values <= b_hi)).all(axis=1))


def working_sets(
    const_v: Array, const_c: Array, warm: Array, b_lo: Array, b_hi: Array, busy: Array
) -> Array | None:
    """DAQP's first rows among the constant rows ``const_v`` (c, H d) for the drones ``busy`` (m,):
    those within :data:`WORKING_MARGIN` of a bound (or beyond) at ``v = c`` (the rows' values
    ``const_c`` (n, c)) or at the warm start ``warm`` (n, H d, over v), (m, c); None (every row)
    below :data:`WORKING_MIN_ROWS` rows in all. Bounds ``b_lo``, ``b_hi`` (n or 1, c)."""
    if not busy.shape[0] or busy.shape[0] * const_v.shape[0] < WORKING_MIN_ROWS:
        return None
    at_warm = warm[busy] @ const_v.T
    if _jit.USE:
        from mpcform.mpc.constraints import kernels

        c = np.ascontiguousarray  # the one layout the kernel is compiled for
        return kernels.near_bounds(c(const_c), c(at_warm), c(b_lo), c(b_hi), c(busy, np.intp), WORKING_MARGIN)
    lo, hi = (b[busy] if b.shape[0] > 1 else b for b in (b_lo, b_hi))
    at_c = const_c[busy]
    near = np.minimum(at_c - lo, hi - at_c) < WORKING_MARGIN
    return np.asarray(near | (np.minimum(at_warm - lo, hi - at_warm) < WORKING_MARGIN))


def separation_sets(at_c: Array, at_warm: Array, lower: Array) -> Array:
    """DAQP's first separation rows (K,): those within :data:`WORKING_MARGIN` of their lower bound
    ``lower`` (or below it) at ``v = c`` (values ``at_c``) or at the warm start (``at_warm``)."""
    return np.asarray((at_c - lower < WORKING_MARGIN) | (at_warm - lower < WORKING_MARGIN))


def misses(const_v: Array, v: Array, given: Array, b_lo: Array, b_hi: Array, some: Array) -> Array:
    """Which solves ``v`` (drones ``some``, H d) miss a constant row (``const_v``, bounds ``b_lo``,
    ``b_hi`` (n or 1, c)) that DAQP was not ``given`` (drones, c)."""
    vals = v @ const_v.T
    lo, hi = (b[some] if b.shape[0] > 1 else b for b in (b_lo, b_hi))
    return np.asarray((((vals < lo) | (vals > hi)) & ~given).any(axis=1))


def separation_misses(values: Array, lower: Array, given: Array, owner: Array, n: int) -> Array:
    """Which of ``n`` drones (n,) miss a separation row (values ``values`` (K,) at their solves,
    lower bounds ``lower``, rows of drones ``owner``) that DAQP was not ``given`` (K,)."""
    missed = np.zeros(n, dtype=bool)
    missed[owner[(values < lower) & ~given]] = True
    return missed


@dataclass(frozen=True)
class Stack:
    """The working-set drones' rows for DAQP, one drone after the other: drone j's rows are
    ``a[starts[j]:starts[j + 1]]`` (its constant rows, then its separation rows)."""

    a: Array  # (rows, H d)
    lo: Array  # (rows,)
    hi: Array
    starts: list[int]  # (drones + 1,)
    full: Array  # (rows,) each row's place in the drones' multipliers over all their rows, concatenated
    full_starts: list[int]  # (drones + 1,) drone j's multipliers over all its rows


def stack(
    const_v: Array,
    near: Array,
    b_lo: Array,
    b_hi: Array,
    some: Array,
    sep_a: Array,
    sep_lo: Array,
    sep_drone: Array,
    sep_local: Array,
    n_sep: Array,
    inf: float,
) -> Stack:
    """The rows of drones ``some`` (m,): their constant rows ``near`` (m, c) of ``const_v`` (c, H d),
    bounds ``b_lo``, ``b_hi`` (n or 1, c), and separation rows ``sep_a`` (G, H d) with lower bounds
    ``sep_lo`` (upper ``inf``), of drone ``sep_drone`` (G,) (into ``some``, ascending), number
    ``sep_local`` among that drone's ``n_sep`` (m,) separation rows."""
    m, c = near.shape
    jc, rc = np.nonzero(near)  # drone by drone, rows in order
    kc, ks = np.bincount(jc, minlength=m), np.bincount(sep_drone, minlength=m)
    starts = np.zeros(m + 1, dtype=np.intp)
    np.cumsum(kc + ks, out=starts[1:])
    at_c = starts[jc] + np.arange(jc.shape[0]) - (np.cumsum(kc) - kc)[jc]
    at_s = starts[sep_drone] + kc[sep_drone] + np.arange(sep_drone.shape[0]) - (np.cumsum(ks) - ks)[sep_drone]
    a, lo, hi = np.empty((starts[-1], const_v.shape[1])), np.empty(starts[-1]), np.full(starts[-1], inf)
    a[at_c], a[at_s], lo[at_s] = const_v[rc], sep_a, sep_lo
    b = some[jc] if b_lo.shape[0] > 1 else np.zeros_like(jc)
    lo[at_c], hi[at_c] = b_lo[b, rc], b_hi[b, rc]
    full_starts = np.zeros(m + 1, dtype=np.intp)
    np.cumsum(c + n_sep, out=full_starts[1:])
    full = np.empty(starts[-1], dtype=np.intp)
    full[at_c], full[at_s] = full_starts[jc] + rc, full_starts[sep_drone] + c + sep_local
    return Stack(a, lo, hi, starts.tolist(), full, full_starts.tolist())
