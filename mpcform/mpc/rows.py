"""The QP's rows, one unit per family: dynamics, velocity set, acceleration, geofence, separation, slack.

Variables, all drones stacked (n drones, d dims, horizon H), positions relative to the start
``p0`` (``x_j = p_j - p0``, ``x_0 = 0``)::

    z = [u_0 .. u_{H-1} | x_1 .. x_H | s_1 .. s_H]   (then y_1 .. y_H with a velocity loop)

With a velocity loop (:mod:`mpcform.mpc.loop`) ``y_e = x_e + sum_j G_{e,j} u_j`` are where the loop
takes the drones (less its free response, which is in the bounds); the separation rows are on y.

A limit's family (:class:`LimitRows`) builds its rows for the sparse QP of all drones
(:mod:`mpcform.mpc.qp`) and for one drone's dense QP over its inputs (:mod:`mpcform.mpc.per_drone`),
their bounds at each step, and the drones whose plan breaks them (the fast path's test). The
separation rows' pattern is built here; their coefficients come from the linearisation about the
guess (:mod:`mpcform.mpc.separation`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np
from scipy.spatial import HalfspaceIntersection

from mpcform._validate import Array
from mpcform.formation.geometry import squared_norms
from mpcform.mpc.loop import VelocityLoop
from mpcform.mpc.settings import MPCSettings
from mpcform.world.limits import Limits

INF = np.inf
INSCRIBED = 1.0 - 1e-9  # ||u||^2 below this times h^2: inside the velocity set, rounding included


@dataclass(frozen=True)
class Layout:
    """Sizes of the QP's variable blocks: inputs and positions (H n d each), slacks (H n), and with
    ``true_positions`` the velocity loop's positions (H n d)."""

    n: int
    dim: int
    horizon: int
    true_positions: bool = False

    @property
    def nud(self) -> int:
        return self.horizon * self.n * self.dim

    @property
    def n_slack(self) -> int:
        return self.horizon * self.n

    @property
    def n_var(self) -> int:
        return (3 if self.true_positions else 2) * self.nud + self.n_slack

    def u_cols(self) -> Array:
        """Columns (H, n, d) of the inputs u_0 .. u_{H-1}."""
        return np.arange(self.nud).reshape(self.horizon, self.n, self.dim)

    def x_cols(self) -> Array:
        """Columns (H, n, d) of the positions x_1 .. x_H."""
        return self.nud + self.u_cols()

    def s_cols(self) -> Array:
        """Columns (H, n) of the slacks s_1 .. s_H."""
        return 2 * self.nud + np.arange(self.n_slack).reshape(self.horizon, self.n)

    def y_cols(self) -> Array:
        """Columns (H, n, d) of the velocity loop's positions y_1 .. y_H (``true_positions``)."""
        return 2 * self.nud + self.n_slack + self.u_cols()

    def slack_slice(self) -> slice:
        """Where the slacks are in z."""
        return slice(2 * self.nud, 2 * self.nud + self.n_slack)


@dataclass(frozen=True)
class RowBlock:
    """Rows ``lower <= A z <= upper`` of one family: entries (row within the block, column, value)."""

    rows: Array
    cols: Array
    vals: Array
    lower: Array
    upper: Array


def dynamics_rows(lay: Layout, dt_s: float) -> RowBlock:
    """``x_{j+1} - x_j - dt u_j = 0`` (x_0 = 0)."""
    h, n, dim = lay.horizon, lay.n, lay.dim
    u_col, x_col = lay.u_cols(), lay.x_cols()
    r = np.arange(lay.nud).reshape(h, n, dim)
    rows = [r, r, r[1:]]
    cols = [x_col, u_col, x_col[:-1]]
    vals = [np.ones_like(r, float), np.full(r.shape, -dt_s), -np.ones_like(r[1:], float)]
    return RowBlock(
        np.concatenate([a.ravel() for a in rows]),
        np.concatenate([a.ravel() for a in cols]),
        np.concatenate([a.ravel() for a in vals]),
        np.zeros(lay.nud),
        np.zeros(lay.nud),
    )


def true_position_rows(lay: Layout, forced: Array) -> RowBlock:
    """``y_e - x_e - sum_{j<e} G_{e,j} u_j = 0`` with the forced response ``forced`` (H + 1, H, d)
    of :class:`mpcform.mpc.loop.VelocityLoop`."""
    h, n, dim = lay.horizon, lay.n, lay.dim
    u_col, x_col, y_col = lay.u_cols(), lay.x_cols(), lay.y_cols()
    r = np.arange(lay.nud).reshape(h, n, dim)
    e, j = np.tril_indices(h)  # row e - 1 (e = 1..H), input j < e
    u_rows = np.broadcast_to(r[e][:, :, :], (e.shape[0], n, dim))
    g = np.broadcast_to(forced[e + 1, j][:, None, :], u_rows.shape)
    return RowBlock(
        np.concatenate([r.ravel(), r.ravel(), u_rows.ravel()]),
        np.concatenate([y_col.ravel(), x_col.ravel(), u_col[j].ravel()]),
        np.concatenate([np.ones(lay.nud), -np.ones(lay.nud), -g.ravel()]),
        np.zeros(lay.nud),
        np.zeros(lay.nud),
    )


def slack_rows(lay: Layout) -> RowBlock:
    """``s >= 0``."""
    ns = lay.n_slack
    return RowBlock(np.arange(ns), 2 * lay.nud + np.arange(ns), np.ones(ns), np.zeros(ns), np.full(ns, INF))


def separation_pattern(lay: Layout, pairs: Array, singles: Array) -> RowBlock:
    """Pattern of the separation rows (values zero; they change every step), R rows per item.

    Pairs ``(i, k)`` (P, 2) first: ``c^T (x_{e,i} - x_{e,k}) + s_{e,i} + s_{e,k} >= b``; then the
    one-drone items ``singles`` (S,) (decoupled pair sides, obstacles): ``c^T x_{e,i} + s_{e,i} >= b``;
    at the position steps e of :func:`row_ends` (on y instead of x with ``lay.true_positions``).
    """
    e = row_ends(lay.horizon)  # (R,) position index 1..H of each row (x_e)
    nr = e.shape[0]
    x_col, s_col = lay.y_cols() if lay.true_positions else lay.x_cols(), lay.s_cols()
    rows: list[Array] = [np.empty(0, dtype=np.intp)]
    cols: list[Array] = [np.empty(0, dtype=np.intp)]
    count = 0
    for drones in ([pairs[:, 0], pairs[:, 1]], [singles]):
        m = drones[0].shape[0]
        if m == 0:
            continue
        xs = [x_col[e - 1][:, i].transpose(1, 0, 2) for i in drones]  # (items, R, d) each
        ss = [s_col[e - 1][:, i].T[:, :, None] for i in drones]  # (items, R, 1) each
        cc = np.concatenate(xs + ss, axis=2)
        rows.append(np.broadcast_to(count + np.arange(m * nr).reshape(m, nr, 1), cc.shape).ravel())
        cols.append(cc.ravel())
        count += m * nr
    entries = np.concatenate(rows)
    zeros = np.zeros(entries.shape)  # values: set each step
    return RowBlock(entries, np.concatenate(cols), zeros, np.zeros(count), np.full(count, INF))


def row_ends(horizon: int) -> Array:
    """Row order per item: for segment j = 0..H-1, its end x_{j+1}, then its start x_j (j >= 1)."""
    ends = []
    for j in range(horizon):
        ends.append(j + 1)
        if j >= 1:
            ends.append(j)
    return np.array(ends, dtype=np.intp)


def row_segments(horizon: int) -> Array:
    """Segment index j of each separation row of an item (R,), matching :func:`row_ends`."""
    segs = []
    for j in range(horizon):
        segs.append(j)
        if j >= 1:
            segs.append(j)
    return np.array(segs, dtype=np.intp)


def positions_of_inputs(horizon: int, dim: int, dt_s: float) -> Array:
    """One drone's positions x_1 .. x_H from its inputs (H d, H d): ``x_e = dt sum_{j<e} u_j``."""
    return dt_s * np.kron(np.tril(np.ones((horizon, horizon))), np.eye(dim))


class LimitRows(ABC):
    """One limit's rows on every drone at every step, for the sparse and the per-drone QP."""

    fixed_bounds = False  # whether the dense rows' bounds are the same for every drone and step

    @abstractmethod
    def sparse(self, lay: Layout) -> RowBlock:
        """Rows of the sparse QP, with the bounds that stay the same from step to step."""

    def set_bounds(self, lower: Array, upper: Array, p0: Array, u_prev: Array) -> None:  # noqa: B027
        """Write this step's bounds into the family's part of the sparse QP's bounds (in place);
        ``p0`` (n, d) starts [m], ``u_prev`` (n, d) last commands [m/s]."""

    @abstractmethod
    def dense(self) -> Array:
        """Rows (m, H d) over one drone's inputs u_0 .. u_{H-1} (the per-drone QP)."""

    @abstractmethod
    def dense_bounds(self, p0: Array, u_prev: Array, inf: float) -> tuple[Array, Array]:
        """Bounds (n, m) of the dense rows for each drone; ``inf`` stands for no bound."""

    @abstractmethod
    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array) -> Array:
        """Drones (n,) whose inputs ``u`` and relative positions ``x`` (H, n, d) break a row."""


class VelocityRows(LimitRows):
    """Velocity set ``D u_{j,i} <= h`` [m/s] inside the ball ``||u|| <= v_max`` (:func:`velocity_set`)."""

    fixed_bounds = True

    def __init__(self, dim: int, horizon: int, settings: MPCSettings, v_max_mps: float) -> None:
        self.horizon = horizon
        self.normals, self.h_mps = velocity_set(dim, settings, v_max_mps)

    def sparse(self, lay: Layout) -> RowBlock:
        h, n, dim, m = lay.horizon, lay.n, lay.dim, self.normals.shape[0]
        rr = np.arange(h * n * m).reshape(h, n, m, 1).repeat(dim, axis=3)
        cc = np.broadcast_to(lay.u_cols()[:, :, None, :], (h, n, m, dim))
        vv = np.broadcast_to(self.normals, (h, n, m, dim))
        return RowBlock(rr, cc, vv, np.full(h * n * m, -INF), np.full(h * n * m, self.h_mps))

    def dense(self) -> Array:
        return np.kron(np.eye(self.horizon), self.normals)

    def dense_bounds(self, p0: Array, u_prev: Array, inf: float) -> tuple[Array, Array]:
        shape = (p0.shape[0], self.horizon * self.normals.shape[0])
        return np.full(shape, -inf), np.full(shape, self.h_mps)

    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array) -> Array:
        """Tested on the drones with an input outside the inscribed ball ``||u|| <= h`` (inside it,
        every ``D_i^T u <= ||u|| <= h``, rounding included with the factor's margin)."""
        out = squared_norms(u).max(axis=0, initial=0.0) > INSCRIBED * self.h_mps**2
        if out.any():
            out[out] = (u[:, out] @ self.normals.T > self.h_mps).any(axis=(0, 2))
        return out


class AccelerationRows(LimitRows):
    """``|u_j - u_{j-1}| <= a_max dt`` per component, ``u_{-1}`` the last applied command."""

    def __init__(self, dim: int, horizon: int, dt_s: float, a_max_mps2: float) -> None:
        self.dim, self.horizon = dim, horizon
        self.step_mps = a_max_mps2 * dt_s  # largest change per step [m/s]

    def sparse(self, lay: Layout) -> RowBlock:
        nud, n, dim = lay.nud, lay.n, lay.dim
        r, u_col = np.arange(nud).reshape(lay.horizon, n, dim), lay.u_cols()
        rr = np.concatenate([r.ravel(), r[1:].ravel()])
        cc = np.concatenate([u_col.ravel(), u_col[:-1].ravel()])
        vv = np.concatenate([np.ones(nud), -np.ones(nud - n * dim)])
        return RowBlock(rr, cc, vv, np.full(nud, -self.step_mps), np.full(nud, self.step_mps))

    def set_bounds(self, lower: Array, upper: Array, p0: Array, u_prev: Array) -> None:
        first = slice(0, p0.size)  # the rows of u_0 - u_{-1}
        lower[first] += u_prev.ravel()
        upper[first] += u_prev.ravel()

    def dense(self) -> Array:
        h = self.horizon
        return np.kron(np.eye(h) - np.eye(h, k=-1), np.eye(self.dim))

    def dense_bounds(self, p0: Array, u_prev: Array, inf: float) -> tuple[Array, Array]:
        n, shape = p0.shape[0], (p0.shape[0], self.horizon, self.dim)
        da = np.full(shape, self.step_mps)
        shift = np.zeros(shape)
        shift[:, 0] = u_prev
        return (shift - da).reshape(n, -1), (shift + da).reshape(n, -1)

    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array) -> Array:
        du = np.diff(np.concatenate([u_prev[None], u]), axis=0)
        return np.asarray((np.abs(du) > self.step_mps).any(axis=(0, 2)))


class GeofenceRows(LimitRows):
    """``lo <= p0 + x_j <= hi``: the box tightened by the margin; a drone outside it may stay or
    move inwards, never further out."""

    def __init__(
        self, dim: int, horizon: int, dt_s: float, min_m: Array, max_m: Array, margin_m: float
    ) -> None:
        self.dim, self.horizon, self.dt_s, self.margin_m = dim, horizon, dt_s, margin_m
        self.min_m, self.max_m = min_m, max_m  # the fence (d,) [m]

    def box(self, p0: Array) -> tuple[Array, Array]:
        """Bounds (n, d) on each drone's relative positions x."""
        lo = np.minimum(self.min_m + self.margin_m - p0, 0.0)
        hi = np.maximum(self.max_m - self.margin_m - p0, 0.0)
        return lo, hi

    def sparse(self, lay: Layout) -> RowBlock:
        nud = lay.nud
        return RowBlock(np.arange(nud), lay.x_cols(), np.ones(nud), np.zeros(nud), np.zeros(nud))

    def set_bounds(self, lower: Array, upper: Array, p0: Array, u_prev: Array) -> None:
        lo, hi = self.box(p0)
        shape = (self.horizon,) + p0.shape
        lower[:] = np.broadcast_to(lo, shape).ravel()
        upper[:] = np.broadcast_to(hi, shape).ravel()

    def dense(self) -> Array:
        return positions_of_inputs(self.horizon, self.dim, self.dt_s)

    def dense_bounds(self, p0: Array, u_prev: Array, inf: float) -> tuple[Array, Array]:
        n, h = p0.shape[0], self.horizon
        lo_h, hi_h = (np.repeat(b[:, None], h, axis=1).reshape(n, -1) for b in self.box(p0))
        return lo_h, hi_h

    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array) -> Array:
        lo, hi = self.box(p0)
        return np.asarray(((x < lo) | (x > hi)).any(axis=(0, 2)))


def limit_rows(dim: int, dt_s: float, limits: Limits, settings: MPCSettings) -> tuple[LimitRows, ...]:
    """The families the limits ask for, in the QP's row order: velocity, acceleration, geofence."""
    h = settings.horizon
    families: list[LimitRows] = []
    if limits.v_max_mps is not None:
        families.append(VelocityRows(dim, h, settings, limits.v_max_mps))
    if limits.a_max_mps2 is not None:
        families.append(AccelerationRows(dim, h, dt_s, limits.a_max_mps2))
    if limits.geofence_min_m is not None and limits.geofence_max_m is not None:
        fence = limits.geofence_min_m, limits.geofence_max_m
        families.append(GeofenceRows(dim, h, dt_s, *fence, settings.margin_m))
    return tuple(families)


def violators(families: tuple[LimitRows, ...], p0: Array, u_prev: Array, u: Array, x: Array) -> Array:
    """Drones (n,) whose ``(u, x)`` miss a velocity, acceleration or geofence row."""
    if len(families) == 1:
        return families[0].violators(p0, u_prev, u, x)
    bad = np.zeros(p0.shape[0], dtype=bool)
    for family in families:
        bad |= family.violators(p0, u_prev, u, x)
    return bad


def velocity_polytope(dim: int, facets: int | None) -> tuple[Array, float]:
    """Unit normals D (M, d) and h <= 1 with ``{D u <= h}`` inscribed in the unit ball.

    Planar: a regular M-gon, ``h = cos(pi / M)``. Spatial: M directions on a Fibonacci sphere;
    h is 1 / (largest vertex radius of ``{D u <= 1}``), so every vertex lies in the ball.
    """
    if dim == 2:
        m = facets or 16
        ang = 2.0 * np.pi * (np.arange(m) + 0.5) / m
        return np.column_stack([np.cos(ang), np.sin(ang)]), float(np.cos(np.pi / m))
    m = facets or 32
    i = np.arange(m) + 0.5
    z = 1.0 - 2.0 * i / m
    phi = np.pi * (1.0 + 5**0.5) * i
    rho = np.sqrt(1.0 - z * z)
    normals = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])
    verts = HalfspaceIntersection(np.column_stack([normals, -np.ones(m)]), np.zeros(3)).intersections
    return normals, float(1.0 / np.linalg.norm(verts, axis=1).max())


def velocity_set(dim: int, settings: MPCSettings, v_max_mps: float) -> tuple[Array, float]:
    """Rows ``D u <= h`` [m/s] of the velocity set: the inscribed polytope, or for ``box`` the
    cube ``|u_a| <= v_max / sqrt(d)`` (rows ``+-e_a``)."""
    if settings.velocity_set == "box":
        return np.vstack([np.eye(dim), -np.eye(dim)]), v_max_mps / np.sqrt(dim)
    normals, h_rel = velocity_polytope(dim, settings.facets)
    return normals, h_rel * v_max_mps


def position_table(m_inv: Array, h: int, dim: int, dt_s: float, loop: VelocityLoop | None) -> Array:
    """The table (H, H d) of ``w_e (x) 1_d`` per position step e, rows over ``v``.

    ``x_e = dt sum_{j<e} u_j = (sum_{j<e} dt M^-1[(j, .), :]) v`` and ``M^-1 = T (x) I_d``, so
    ``x_e = (w_e (x) I_d) v`` and ``a^T x_e = (w_e (x) a)^T v``. With a velocity ``loop`` the rows
    are on its positions, ``+ sum_j G_{e,j} u_j`` with ``u_j = sum_m T[j, m] v_m`` (per axis)."""
    nu = h * dim
    x_v = dt_s * np.cumsum(m_inv.reshape(h, dim, nu), axis=0)
    table = np.einsum("echc->ehc", x_v.reshape(h, dim, h, dim)).reshape(h, nu)
    if loop is not None:
        t = m_inv.reshape(h, dim, h, dim)[:, 0, :, 0]
        table += np.einsum("ejd,jm->emd", loop.forced[1:], t).reshape(h, nu)
    return table
