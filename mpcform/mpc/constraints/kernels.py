"""The separation families' hot loops, compiled by numba when it is installed (:mod:`mpcform._jit`).

Each kernel is the loop form of a numpy path that stays the reference
(:meth:`mpcform.mpc.constraints.pairs.PairSeparation.rows` decoupled,
:meth:`mpcform.mpc.constraints.separation.Separation.single_values`): the same arithmetic item by
item without the temporaries, summed in the same order (:func:`dot`), so the two agree bit for bit. At 1000
drones a crossing step holds ~20,000 pairs of 21 rows each; the numpy path spent most of the step
in these rows.
"""

from __future__ import annotations

import math

import numpy as np

from mpcform import _jit
from mpcform._jit import inline, njit
from mpcform._validate import Array


@inline
def dot(x: Array, y: Array) -> float:
    """``x^T y`` of two vectors of 2 or 3 components summed as numpy's ``einsum`` sums a short
    axis (two lanes: the even terms, the odd one, then the two), so the kernels' rows equal the
    numpy path's bit for bit."""
    if x.shape[0] == 3:
        return (x[0] * y[0] + x[2] * y[2]) + x[1] * y[1]
    return x[0] * y[0] + x[1] * y[1]


@inline
def row_dot(c: Array, q: int, r: int, y: Array, i: int, j: int) -> float:
    """:func:`dot` of ``c[q, r]`` and ``y[i, j]`` (3-D arrays, no views)."""
    if c.shape[2] == 3:
        return (c[q, r, 0] * y[i, j, 0] + c[q, r, 2] * y[i, j, 2]) + c[q, r, 1] * y[i, j, 1]
    return c[q, r, 0] * y[i, j, 0] + c[q, r, 1] * y[i, j, 1]


@inline
def row_vec_dot(c: Array, q: int, r: int, y: Array) -> float:
    """:func:`dot` of ``c[q, r]`` (a 3-D array) and the vector ``y`` (no views)."""
    if c.shape[2] == 3:
        return (c[q, r, 0] * y[0] + c[q, r, 2] * y[2]) + c[q, r, 1] * y[1]
    return c[q, r, 0] * y[0] + c[q, r, 1] * y[1]


@inline
def gap_dot(c: Array, q: int, r: int, y: Array, i: int, m: Array) -> float:
    """:func:`dot` of ``c[q, r]`` (a 3-D array) and ``y[i] - m`` (no temporaries)."""
    if c.shape[2] == 3:
        return ((y[i, 0] - m[0]) * c[q, r, 0] + (y[i, 2] - m[2]) * c[q, r, 2]) + (y[i, 1] - m[1]) * c[q, r, 1]
    return (y[i, 0] - m[0]) * c[q, r, 0] + (y[i, 1] - m[1]) * c[q, r, 1]


@njit
def side_rows(
    p0: Array,
    path: Array,
    pairs: Array,
    metric: Array,
    segs: Array,
    ends: Array,
    d_min: float,
    half: float,
    grows: Array,
    grow: Array,
    stops: Array,
    coeffs: Array,
    lower: Array,
    hard: Array,
) -> None:
    """The decoupled pair rows (tail of at most one point) into ``coeffs`` (2P, R, d), ``lower``
    (2P, R) and ``hard`` (P,): per pair ``(i, k)``, the unit normal ``c`` of each guess segment's
    point of ``W (path_i - path_k)`` closest to the origin (world coordinates ``W c``; a pair
    inside ``d_min`` at the start takes its start normal on row 0), side i ``c^T (p0_i - m_e) >=
    bound_i`` and side k ``-c^T (p0_k - m_e) >= bound_k`` about the guess's midpoints ``m_e``, the
    bounds ``half + grows[side] grow`` (``grows`` empty: ``half``), the stop row (R - 2) split
    towards the ``stops`` (n, d) (empty: not) as
    :meth:`~mpcform.mpc.constraints.pairs.PairSeparation._stop_split` does."""
    if path.shape[2] == 3:  # the components' loops of a known length: unrolled
        _side_rows(
            p0, path, pairs, metric, segs, ends, d_min, half, grows, grow, stops, coeffs, lower, hard, 3
        )
    else:
        _side_rows(
            p0, path, pairs, metric, segs, ends, d_min, half, grows, grow, stops, coeffs, lower, hard, 2
        )


@inline
def _side_rows(
    p0: Array,
    path: Array,
    pairs: Array,
    metric: Array,
    segs: Array,
    ends: Array,
    d_min: float,
    half: float,
    grows: Array,
    grow: Array,
    stops: Array,
    coeffs: Array,
    lower: Array,
    hard: Array,
    d: int,
) -> None:
    """:func:`side_rows` in ``d`` dimensions (a constant where it is called); the dot products
    written out in :func:`dot`'s order."""
    n_p, r_n = pairs.shape[0], segs.shape[0]
    s_n = path.shape[1] - 1
    normal, rel = np.empty((s_n, d)), np.empty((s_n + 1, d))
    mid, step, delta = np.empty(d), np.empty(d), np.empty(d)
    grown, split = grows.shape[0] > 0, stops.shape[0] > 0
    for q in range(n_p):
        i, k = pairs[q, 0], pairs[q, 1]
        for j in range(s_n + 1):  # the relative guess, in the metric
            for a in range(d):
                rel[j, a] = (path[i, j, a] - path[k, j, a]) * metric[a]
        for j in range(s_n):  # each segment's closest point, its unit normal
            for a in range(d):
                delta[a] = rel[j + 1, a] - rel[j, a]
            if d == 3:
                den = (delta[0] * delta[0] + delta[2] * delta[2]) + delta[1] * delta[1]
                num = (rel[j, 0] * delta[0] + rel[j, 2] * delta[2]) + rel[j, 1] * delta[1]
            else:
                den = delta[0] * delta[0] + delta[1] * delta[1]
                num = rel[j, 0] * delta[0] + rel[j, 1] * delta[1]
            tau = -num / (den if den > 0.0 else 1.0)
            tau = min(max(tau, 0.0), 1.0)
            sq = 0.0
            for a in range(d):
                normal[j, a] = delta[a] * tau + rel[j, a]
                sq += normal[j, a] * normal[j, a]
            dist = math.sqrt(sq)
            for a in range(d):
                if dist > 1e-9:
                    normal[j, a] = normal[j, a] / dist * metric[a]
                else:
                    normal[j, a] = metric[a] if a == 0 else 0.0
        for r in range(r_n):
            for a in range(d):
                coeffs[q, r, a] = normal[segs[r], a]
        sq = 0.0
        for a in range(d):
            sq += rel[0, a] * rel[0, a]
        dist = math.sqrt(sq)
        hard[q] = dist < d_min
        if hard[q]:
            for a in range(d):
                c0 = (rel[0, a] / dist if dist > 1e-12 else (1.0 if a == 0 else 0.0)) * metric[a]
                coeffs[q, 0, a] = c0
        for r in range(r_n):
            e = ends[r]
            b_i = half + grows[i] * grow[r] if grown else half
            b_k = half + grows[k] * grow[r] if grown else half
            for a in range(d):
                mid[a] = (path[i, e, a] + path[k, e, a]) * 0.5
            if split and r == r_n - 2:  # PairSeparation._stop_split: towards the stops' midpoint
                for a in range(d):
                    step[a] = (stops[i, a] + stops[k, a]) * 0.5 - mid[a]
                along, at = row_vec_dot(coeffs, q, r, step), row_vec_dot(coeffs, q, r, mid)
                on_i, on_k = row_dot(coeffs, q, r, path, i, s_n), row_dot(coeffs, q, r, path, k, s_n)
                room = on_i - b_i - at if along > 0.0 else on_k + b_k - at
                t = min(max(room / along if along != 0.0 else 1.0, 0.0), 1.0)
                for a in range(d):
                    mid[a] = mid[a] + t * step[a]
            for a in range(d):
                coeffs[n_p + q, r, a] = -coeffs[q, r, a]
            gi, gk = gap_dot(coeffs, q, r, p0, i, mid), gap_dot(coeffs, q, r, p0, k, mid)
            lower[q, r] = b_i - gi
            lower[n_p + q, r] = b_k + gk
        if hard[q]:
            lower[q, 0] = 0.0
            lower[n_p + q, 0] = 0.0


@njit
def single_values(x_rows: Array, singles: Array, coeffs: Array, lower: Array, on: Array) -> Array:
    """``c^T x_e - b`` (S, R) of one-drone rows (``coeffs`` (S, R, d), ``lower`` (S, R)) at the
    drones' positions at each row's step ``x_rows`` (n, R, d); inf for the items not ``on``."""
    s_n, r_n, d = coeffs.shape
    value = np.empty((s_n, r_n))
    for s in range(s_n):
        i = singles[s]
        for r in range(r_n):
            if not on[s]:
                value[s, r] = np.inf
                continue
            value[s, r] = row_dot(coeffs, s, r, x_rows, i, r) - lower[s, r]
    return value


@njit
def reachable_rows(
    n: int,
    singles: Array,
    coeffs: Array,
    lower: Array,
    hard: Array,
    on: Array,
    ends: Array,
    step_m: float,
    reach_steps: Array,
    local: Array,
) -> tuple[Array, Array, Array, Array, Array, Array]:
    """:func:`mpcform.mpc.solve.working_set.reachable_rows` in two passes (keep in item order,
    then place by drone: the items' rows are read once): ``hard``, ``on``, ``local`` empty for
    none; ``step_m`` negative for no speed limit."""
    s_n, r_n, d = coeffs.shape
    counts = np.zeros(n, dtype=np.intp)
    owner = singles if local.shape[0] == 0 else local[singles]  # each item's drone among the n
    kept_c, kept_at = np.empty((s_n * r_n, d)), np.empty(s_n * r_n, dtype=np.intp)  # touched: the kept
    m = 0
    for s in range(s_n):
        if not ((on.shape[0] == 0 or on[s]) and owner[s] >= 0):
            continue
        for r in range(r_n):
            ok = True
            if step_m >= 0.0:
                sq = 0.0
                for a in range(d):
                    sq += coeffs[s, r, a] * coeffs[s, r, a]
                ok = lower[s, r] > -(math.sqrt(sq) * (reach_steps[r] * step_m))
            if ok:
                for a in range(d):
                    kept_c[m, a] = coeffs[s, r, a]
                kept_at[m] = s * r_n + r
                m += 1
                counts[owner[s]] += 1
    place = np.zeros(n, dtype=np.intp)
    for i in range(1, n):
        place[i] = place[i - 1] + counts[i - 1]
    sep_c, sep_end, sep_lo = np.empty((m, d)), np.empty(m, dtype=ends.dtype), np.empty(m)
    soft, at = np.empty(m, dtype=np.bool_), np.empty(m, dtype=np.intp)
    for t in range(m):
        f = kept_at[t]
        s, r = f // r_n, f % r_n
        j = place[owner[s]]
        place[owner[s]] += 1
        for a in range(d):
            sep_c[j, a] = kept_c[t, a]
        sep_end[j], sep_lo[j], at[j] = ends[r], lower[s, r], f
        soft[j] = r > 0 or (hard.shape[0] > 0 and not hard[s])
    return sep_c, sep_end, sep_lo, soft, counts, at


@njit
def near_bounds(values: Array, warm: Array, b_lo: Array, b_hi: Array, busy: Array, margin: float) -> Array:
    """:func:`mpcform.mpc.solve.working_set.working_sets`' rows (m, c) within ``margin`` of a bound
    (or beyond) at ``values`` (n, c) (row ``busy[j]``) or at ``warm`` (m, c) (row j), bounds ``b_lo``,
    ``b_hi`` (n or 1, c), without the gathered copies."""
    m, c = busy.shape[0], values.shape[1]
    near = np.empty((m, c), dtype=np.bool_)
    one = b_lo.shape[0] == 1
    for j in range(m):
        i = busy[j]
        b = 0 if one else i
        for r in range(c):
            lo, hi, x, w = b_lo[b, r], b_hi[b, r], values[i, r], warm[j, r]
            near[j, r] = min(x - lo, hi - x) < margin or min(w - lo, hi - w) < margin
    return near


@njit
def item_least(values: Array, split: Array, stop: int) -> Array:
    """Each item's least row value (S,) of ``values`` (S, R), over its first ``stop`` rows where
    ``split`` (a drone pair's side), else over all (``Separation._least``)."""
    s_n, r_n = values.shape
    least = np.full(s_n, np.inf)
    for s in range(s_n):
        for r in range(stop if split[s] else r_n):
            least[s] = min(least[s], values[s, r])
    return least


@njit
def joint_least(values: Array, first: Array, second: Array) -> float:
    """The least joint row value: the sum of a pair's two sides' values, side i's rows ``first``
    and side k's ``second`` (the same pair order) of ``values`` (S, R) (``Separation.meets_joint``)."""
    least = np.inf
    for q in range(first.shape[0]):
        for r in range(values.shape[1]):
            least = min(least, values[first[q], r] + values[second[q], r])
    return least


def warm_up() -> None:
    """Compile (or load from numba's cache) every kernel for the argument types the planner passes,
    then turn them on (:data:`mpcform._jit.USE`)."""
    if not _jit.AVAILABLE or _jit.USE:
        return
    f, i, b = np.zeros, np.zeros(2, dtype=np.intp), np.ones(1, dtype=bool)
    pairs, segs = np.array([[0, 1]], dtype=np.intp), np.zeros(2, dtype=np.intp)
    rows = np.empty((2, 2, 3)), np.empty((2, 2)), np.empty(1, dtype=bool)
    for grows, stops in ((f(0), f((0, 3))), (f(2), f((2, 3)))):
        side_rows(f((2, 3)), f((2, 3, 3)), pairs, f(3), segs, i, 0.5, 0.25, grows, f(2), stops, *rows)
    single_values(f((2, 2, 3)), i[:1], f((1, 2, 3)), f((1, 2)), b)
    reachable_rows(2, i[:1], f((1, 2, 3)), f((1, 2)), b, b, i, 0.1, f(2), i[:0])
    item_least(f((1, 2)), b, 1)
    near_bounds(f((2, 2)), f((1, 2)), f((1, 2)), f((1, 2)), i[:1], 0.1)
    joint_least(f((2, 2)), i[:1], i[:1])
    _jit.USE = True
