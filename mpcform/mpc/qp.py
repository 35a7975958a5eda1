"""The planner's sparse QP: built once per candidate set, then updated every step.

Variables, all drones stacked (n drones, d dims, horizon H), positions relative to the current
positions ``p0`` so that every variable is O(v_max H dt) and the solver's relative tolerances
mean something::

    z = [u_0 .. u_{H-1} | x_1 .. x_H | s_1 .. s_H]      x_j = p_j - p0,  x_0 = 0

with one separation slack ``s_{e,i} >= 0`` [m] per drone and position step (shared by the
drone's pair and obstacle rows at that step), so the slack keeps the problem stage-wise
sparse: a slack per pair over the whole horizon would couple all steps and fill the KKT
factor (measured: 80 ms per interior-point iteration for 20 spatial drones instead of ~1).

Cost ``0.5 sum_j ||u_j + k x_j - c_j||^2 + w1 sum slack + 0.5 w2 sum slack^2`` with
``c_j = ff_j + k (p*_j - p0)``: zero for the eq. 14 rollout, which is therefore the optimum
whenever it meets every row. Rows, in order:

- dynamics ``x_{j+1} - x_j - dt u_j = 0``;
- velocity set: inscribed polytope ``D u_{j,i} <= h`` or box;
- acceleration (optional) ``|u_j - u_{j-1}| <= a_max dt``;
- geofence (optional) ``lo <= p0 + x_j <= hi``, tightened by the margin;
- separation items (drone pairs, drone-obstacle pairs): for segment j of the guess with
  normal ``c`` (closest-point direction), ``c^T (x_{e,i} - x_{e,k}) + s_{e,i} + s_{e,k} >= b`` at both
  segment ends e = j, j + 1 (e = 0 is the fixed start and has no row);
- ``slack >= 0``.

Only the separation rows' coefficients change from step to step; the sparsity pattern is fixed
for a given candidate set, so a persistent solver takes ``update(Ax=...)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import HalfspaceIntersection

from mpcform._validate import Array
from mpcform.mpc.limits import Limits
from mpcform.mpc.settings import MPCSettings

INF = np.inf


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


@dataclass(frozen=True)
class Layout:
    """Sizes of the QP's variable blocks: inputs and positions (H n d each), slacks (H n)."""

    n: int
    dim: int
    horizon: int

    @property
    def nud(self) -> int:
        return self.horizon * self.n * self.dim

    @property
    def n_slack(self) -> int:
        return self.horizon * self.n

    @property
    def n_var(self) -> int:
        return 2 * self.nud + self.n_slack



class MPCQP:
    """The QP of one candidate set of separation items (drone pairs and drone-obstacle pairs).

    ``pairs`` (P, 2) and ``obstacle_items`` (O, 2) = (drone, obstacle index) fix the sparsity
    pattern. Call :meth:`bounds_and_cost` and :meth:`separation_rows` each step.
    """

    def __init__(
        self,
        n: int,
        dim: int,
        dt_s: float,
        limits: Limits,
        settings: MPCSettings,
        pairs: Array,
        singles: Array,
    ) -> None:
        h = settings.horizon
        self.layout = lay = Layout(n, dim, h)
        self.dt_s, self.limits, self.settings = dt_s, limits, settings
        k = settings.gain_per_s
        nud = lay.nud
        u_col = np.arange(nud).reshape(h, n, dim)
        x_col = nud + u_col  # x_{j+1} for j = 0..H-1
        blocks: list[tuple[Array, Array, Array]] = []  # (row, col, value) per row group
        lower: list[Array] = []
        upper: list[Array] = []
        count = {"rows": 0, "nnz": 0}

        def add(rows: Array, cols: Array, vals: Array, lo: Array, hi: Array) -> tuple[slice, slice]:
            """Append a row group (rows numbered from 0 within it); return its row and entry slices."""
            r0, e0 = count["rows"], count["nnz"]
            blocks.append((r0 + rows.ravel(), cols.ravel(), np.broadcast_to(vals, rows.shape).ravel()))
            lower.append(lo)
            upper.append(hi)
            count["rows"] += lo.shape[0]
            count["nnz"] += rows.size
            return slice(r0, count["rows"]), slice(e0, count["nnz"])

        # dynamics: x_{j+1} - x_j - dt u_j = 0
        r = np.arange(nud).reshape(h, n, dim)
        rows = [r, r, r[1:]]
        cols = [x_col, u_col, x_col[:-1]]
        vals = [np.ones_like(r, float), np.full(r.shape, -dt_s), -np.ones_like(r[1:], float)]
        add(
            np.concatenate([a.ravel() for a in rows]),
            np.concatenate([a.ravel() for a in cols]),
            np.concatenate([a.ravel() for a in vals]),
            np.zeros(nud),
            np.zeros(nud),
        )
        # velocity set
        vmax = limits.v_max_mps
        if vmax is not None:
            normals, vel_h = velocity_set(dim, settings, vmax)
            m = normals.shape[0]
            rr = np.arange(h * n * m).reshape(h, n, m, 1).repeat(dim, axis=3)
            cc = np.broadcast_to(u_col[:, :, None, :], (h, n, m, dim))
            vv = np.broadcast_to(normals, (h, n, m, dim))
            add(rr, cc, vv, np.full(h * n * m, -INF), np.full(h * n * m, vel_h))
        # acceleration: |u_j - u_{j-1}| <= a_max dt (u_{-1} is the last applied command)
        self.acc_rows: slice | None = None
        if limits.a_max_mps2 is not None:
            da = limits.a_max_mps2 * dt_s
            rr = np.concatenate([r.ravel(), r[1:].ravel()])
            cc = np.concatenate([u_col.ravel(), u_col[:-1].ravel()])
            vv = np.concatenate([np.ones(nud), -np.ones(nud - n * dim)])
            self.acc_rows = add(rr, cc, vv, np.full(nud, -da), np.full(nud, da))[0]
        # geofence on positions
        self.fence_rows: slice | None = None
        if limits.geofence_min_m is not None:
            self.fence_rows = add(np.arange(nud), x_col, np.ones(nud), np.zeros(nud), np.zeros(nud))[0]
        # separation items: rows (item, segment end/start) with d (+d) coefficients and a slack
        e = row_ends(h)  # (R,) position index 1..H of each row (x_e)
        nr = e.shape[0]
        row_start, entry_start = count["rows"], count["nnz"]
        s_col = 2 * nud + np.arange(h * n).reshape(h, n)  # s_{e,i} for e = 1..H
        for drones in ([pairs[:, 0], pairs[:, 1]], [singles]):
            m = drones[0].shape[0]
            if m == 0:
                continue
            xs = [x_col[e - 1][:, i].transpose(1, 0, 2) for i in drones]  # (items, R, d) each
            ss = [s_col[e - 1][:, i].T[:, :, None] for i in drones]  # (items, R, 1) each
            cc = np.concatenate(xs + ss, axis=2)
            rr = np.broadcast_to(np.arange(m * nr).reshape(m, nr, 1), cc.shape)
            add(rr, cc, np.zeros(cc.shape), np.zeros(m * nr), np.full(m * nr, INF))
        self.sep_rows = slice(row_start, count["rows"])
        self._sep_entries = slice(entry_start, count["nnz"])
        # slack >= 0
        ns = lay.n_slack
        add(np.arange(ns), 2 * nud + np.arange(ns), np.ones(ns), np.zeros(ns), np.full(ns, INF))

        rows_all = np.concatenate([b[0] for b in blocks])
        cols_all = np.concatenate([b[1] for b in blocks])
        self._coo_vals = np.concatenate([b[2] for b in blocks]).astype(float)
        row0 = count["rows"]
        ids = sp.csc_matrix(
            (np.arange(1, rows_all.shape[0] + 1, dtype=float), (rows_all, cols_all)),
            shape=(row0, lay.n_var),
        )
        ids.sort_indices()
        self._perm = ids.data.astype(np.intp) - 1
        self.A = sp.csc_matrix((self._coo_vals[self._perm], ids.indices, ids.indptr), shape=ids.shape)
        self.l0 = np.concatenate(lower)
        self.u0 = np.concatenate(upper)
        # cost: 0.5 ||u_j + k x_j - c_j||^2 (x_0 = 0), slack weights
        diag_u = np.ones(nud)
        diag_x = np.full(nud, k * k)
        diag_x[-n * dim :] = 0.0  # x_H does not enter the cost
        cross = sp.coo_matrix(
            (np.full(nud - n * dim, k), (np.arange(n * dim, nud), nud + np.arange(nud - n * dim))),
            shape=(lay.n_var, lay.n_var),
        )
        diag = np.concatenate([diag_u, diag_x, np.full(ns, settings.slack_quadratic)])
        self.P = sp.triu(sp.diags(diag) + cross, format="csc")
        self.P.sort_indices()
        # rows of inactive items stay in the pattern with a bound no plan can reach (finite, so
        # interior-point backends do not drop them): |c^T (x_i - x_k)| <= 2 v_max H dt
        self._off_lower = -(2.0 * (vmax or 0.0) * h * dt_s + 1.0)
        self._u_col, self._x_col = u_col, x_col

    def cost_vector(self, c: Array) -> Array:
        """Linear cost term for targets ``c_j = ff_j + k (p*_j - p0)`` (H, n, d)."""
        lay, k = self.layout, self.settings.gain_per_s
        q = np.empty(lay.n_var)
        q[: lay.nud] = -c.ravel()
        q[lay.nud : 2 * lay.nud - lay.n * lay.dim] = -k * c[1:].ravel()
        q[2 * lay.nud - lay.n * lay.dim : 2 * lay.nud] = 0.0
        q[2 * lay.nud :] = self.settings.slack_weight
        return q

    def bounds(self, p0: Array, u_prev: Array, sep_lower: Array, sep_active: Array) -> tuple[Array, Array]:
        """Row bounds for start positions p0 (n, d), last command u_prev, separation lower bounds
        (items, R) and the mask of items whose rows are on (items,)."""
        lo, hi = self.l0.copy(), self.u0.copy()
        if self.acc_rows is not None:
            first = slice(self.acc_rows.start, self.acc_rows.start + p0.size)
            lo[first] += u_prev.ravel()
            hi[first] += u_prev.ravel()
        lim = self.limits
        if self.fence_rows is not None and lim.geofence_min_m is not None and lim.geofence_max_m is not None:
            margin, shape = self.settings.margin_m, (self.layout.horizon,) + p0.shape
            # a drone outside the fence may stay or move inwards, never further out
            lo[self.fence_rows] = np.broadcast_to(
                np.minimum(lim.geofence_min_m + margin - p0, 0.0), shape
            ).ravel()
            hi[self.fence_rows] = np.broadcast_to(
                np.maximum(lim.geofence_max_m - margin - p0, 0.0), shape
            ).ravel()
        sep = np.where(sep_active[:, None], sep_lower, self._off_lower)
        lo[self.sep_rows] = sep.ravel()
        return lo, hi

    def separation_values(self, coeffs_pairs: Array, coeffs_singles: Array) -> Array:
        """CSC data of A for row coefficients (P, R, d) of the pairs and (S, R, d) of the singles."""
        vals = self._coo_vals.copy()
        parts = []
        if coeffs_pairs.shape[0]:
            ones = np.ones(coeffs_pairs.shape[:2] + (2,))
            parts.append(np.concatenate([coeffs_pairs, -coeffs_pairs, ones], axis=2).ravel())
        if coeffs_singles.shape[0]:
            ones = np.ones(coeffs_singles.shape[:2] + (1,))
            parts.append(np.concatenate([coeffs_singles, ones], axis=2).ravel())
        if parts:
            vals[self._sep_entries] = np.concatenate(parts)
        return vals[self._perm]


def row_ends(horizon: int) -> Array:
    """Row order per item: for segment j = 0..H-1, its end x_{j+1}, then its start x_j (j >= 1)."""
    ends = []
    for j in range(horizon):
        ends.append(j + 1)
        if j >= 1:
            ends.append(j)
    return np.array(ends, dtype=np.intp)


def row_segments(horizon: int) -> Array:
    """Segment index j of each separation row of an item (R,), matching :func:`_row_ends`."""
    segs = []
    for j in range(horizon):
        segs.append(j)
        if j >= 1:
            segs.append(j)
    return np.array(segs, dtype=np.intp)
