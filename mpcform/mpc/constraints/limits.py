"""The limits' rows, one unit per limit: velocity set, acceleration, geofence.

A limit's family (:class:`LimitRows`) builds its rows for the sparse QP of all drones
(:mod:`mpcform.mpc.solve.sparse_qp`) and for one drone's dense QP over its inputs
(:mod:`mpcform.mpc.solve.per_drone`),
their bounds at each step, and the drones whose plan breaks them (the fast path's test). The
variables and their layout are in :mod:`mpcform.mpc.constraints.rows`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from scipy.spatial import HalfspaceIntersection

from mpcform._validate import Array
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.rows import INF, Layout, RowBlock, positions_of_inputs, step_growth
from mpcform.mpc.constraints.tail import Tail, planner_tail
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.world.closest import squared_norms
from mpcform.world.limits import Limits

INSCRIBED = 1.0 - 1e-9  # ||u||^2 below this times h^2: inside the velocity set, rounding included


class LimitRows(ABC):
    """One limit's rows on every drone at every step, for the sparse and the per-drone QP."""

    fixed_bounds = False  # whether the dense rows' bounds are the same for every drone and step

    @abstractmethod
    def sparse(self, lay: Layout) -> RowBlock:
        """Rows of the sparse QP, with the bounds that stay the same from step to step."""

    def set_bounds(  # noqa: B027
        self, lower: Array, upper: Array, p0: Array, u_prev: Array, free_m: Array | None = None
    ) -> None:
        """Write this step's bounds into the family's part of the sparse QP's bounds (in place);
        ``p0`` (n, d) starts [m], ``u_prev`` (n, d) last commands [m/s], ``free_m`` (S, n, d) with a
        velocity loop its free response at each bounded position (:mod:`mpcform.mpc.velocity_loop`)."""

    @abstractmethod
    def dense(self) -> Array:
        """Rows (m, H d) over one drone's inputs u_0 .. u_{H-1} (the per-drone QP)."""

    @abstractmethod
    def dense_bounds(
        self, p0: Array, u_prev: Array, inf: float, free_m: Array | None = None
    ) -> tuple[Array, Array]:
        """Bounds (n, m) of the dense rows for each drone; ``inf`` stands for no bound."""

    @abstractmethod
    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array, tol: float = 0.0) -> Array:
        """Drones (n,) whose inputs ``u`` and relative positions ``x`` (H, n, d) break a row by more
        than ``tol`` [m/s or m]."""


class VelocityRows(LimitRows):
    """Velocity set ``D u_{j,i} <= h`` [m/s] inside the ball ``||u|| <= v_max``, squeezed along z by
    ``scale`` (:meth:`mpcform.world.limits.Limits.speed_scale`; :func:`velocity_set`)."""

    fixed_bounds = True

    def __init__(
        self, dim: int, horizon: int, settings: MPCSettings, v_max_mps: float, scale: Array | None = None
    ) -> None:
        self.horizon = horizon
        self.scale = np.ones(dim) if scale is None else scale
        self._squeezed = bool(np.any(self.scale != 1.0))  # else the ball: no product per step
        self.normals, self.h_mps = velocity_set(dim, settings, v_max_mps, self.scale)

    def sparse(self, lay: Layout) -> RowBlock:
        h, n, dim, m = lay.horizon, lay.n, lay.dim, self.normals.shape[0]
        rr = np.arange(h * n * m).reshape(h, n, m, 1).repeat(dim, axis=3)
        cc = np.broadcast_to(lay.u_cols()[:, :, None, :], (h, n, m, dim))
        vv = np.broadcast_to(self.normals, (h, n, m, dim))
        return RowBlock(rr, cc, vv, np.full(h * n * m, -INF), np.full(h * n * m, self.h_mps))

    def dense(self) -> Array:
        return np.kron(np.eye(self.horizon), self.normals)

    def dense_bounds(
        self, p0: Array, u_prev: Array, inf: float, free_m: Array | None = None
    ) -> tuple[Array, Array]:
        shape = (p0.shape[0], self.horizon * self.normals.shape[0])
        return np.full(shape, -inf), np.full(shape, self.h_mps)

    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array, tol: float = 0.0) -> Array:
        """Tested on the drones with an input outside the inscribed spheroid ``||S u|| <= h`` (inside
        it, every ``D_i^T u <= ||S u|| <= h`` with ``D = D_ball S``, rounding included with the
        factor's margin)."""
        scaled = u * self.scale if self._squeezed else u
        out = squared_norms(scaled).max(axis=0, initial=0.0) > INSCRIBED * self.h_mps**2
        if out.any():
            out[out] = (u[:, out] @ self.normals.T > self.h_mps + tol).any(axis=(0, 2))
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

    def set_bounds(
        self, lower: Array, upper: Array, p0: Array, u_prev: Array, free_m: Array | None = None
    ) -> None:
        first = slice(0, p0.size)  # the rows of u_0 - u_{-1}
        lower[first] += u_prev.ravel()
        upper[first] += u_prev.ravel()

    def dense(self) -> Array:
        h = self.horizon
        return np.kron(np.eye(h) - np.eye(h, k=-1), np.eye(self.dim))

    def dense_bounds(
        self, p0: Array, u_prev: Array, inf: float, free_m: Array | None = None
    ) -> tuple[Array, Array]:
        n, shape = p0.shape[0], (p0.shape[0], self.horizon, self.dim)
        da = np.full(shape, self.step_mps)
        shift = np.zeros(shape)
        shift[:, 0] = u_prev
        return (shift - da).reshape(n, -1), (shift + da).reshape(n, -1)

    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array, tol: float = 0.0) -> Array:
        du = np.diff(np.concatenate([u_prev[None], u]), axis=0)
        return np.asarray((np.abs(du) > self.step_mps + tol).any(axis=(0, 2)))


class GeofenceRows(LimitRows):
    """``lo <= p0 + x_j <= hi``: the box tightened by the margin; a drone outside it may stay or
    move inwards, never further out. With braking the ``tail``'s points too
    (:mod:`mpcform.mpc.constraints.tail`:
    the box is convex, so the whole tail stays in it when they do). With a
    velocity ``loop`` the rows are on where it takes the drones, ``y_e``: its forced response in
    the rows, its free response in the bounds (see :meth:`_boxes`)."""

    def __init__(
        self,
        dim: int,
        horizon: int,
        dt_s: float,
        min_m: Array,
        max_m: Array,
        margin_m: float,
        tail: Tail | None = None,
        loop: VelocityLoop | None = None,
        growth: Array | None = None,
    ) -> None:
        self.dim, self.horizon, self.dt_s, self.margin_m = dim, horizon, dt_s, margin_m
        self.min_m, self.max_m = min_m, max_m  # the fence (d,) [m]
        self.tail, self.loop = tail, loop
        self.steps = horizon + (0 if tail is None else tail.count)  # x_1 .. x_H, then the tail's points
        self.grow: Array | float = 0.0 if growth is None else growth[1:, None, None]  # (S, 1, 1) [m]

    def box(self, p0: Array) -> tuple[Array, Array]:
        """Bounds (..., n, d) on each drone's relative positions x (``p0`` (..., n, d): with a loop,
        the starts moved by the free response); with the rows' growth (:func:`step_growth`) one
        box per bounded position (S, n, d)."""
        lo = np.minimum(self.min_m + self.margin_m + self.grow - p0, 0.0)
        hi = np.maximum(self.max_m - self.margin_m - self.grow - p0, 0.0)
        return lo, hi

    def _boxes(self, p0: Array, free_m: Array | None) -> tuple[Array, Array]:
        """Bounds (S, n, d) at each bounded position. With a loop, on the forced response: the box
        less the free response; only at the first step (which a command barely moves) may the
        free response carry a drone out, later the plan must bring it back."""
        if free_m is None:
            shape = (self.steps,) + p0.shape
            return tuple(np.broadcast_to(b, shape) for b in self.box(p0))  # type: ignore[return-value]
        lo, hi = (b - free_m for b in self.box(p0))
        lo[0], hi[0] = (b if b.ndim == 2 else b[0] for b in self.box(p0 + free_m[0]))
        return lo, hi

    def sparse(self, lay: Layout) -> RowBlock:
        nud, nd = lay.nud, lay.n * lay.dim
        at = lay.y_cols() if lay.true_positions else lay.x_cols()
        rows, cols, vals = np.arange(nud), at.ravel(), np.ones(nud)
        if self.tail is not None:  # the tail's points: g x_H + sum_j F_j u_j, g the loop's DC gain
            t, support = self.tail, self.tail.support
            point = nud + np.arange(t.count * nd).reshape(t.count, 1, nd)
            on_u = np.broadcast_to(lay.u_cols()[support].reshape(1, -1, nd), (t.count, support.size, nd))
            f = np.tile(t.forced[:, support], (1, 1, lay.n))  # (T, J, n d)
            rows = np.concatenate([rows, point.ravel(), np.broadcast_to(point, f.shape).ravel()])
            x_last = np.broadcast_to(lay.x_cols()[-1].ravel(), (t.count, nd))
            cols = np.concatenate([cols, x_last.ravel(), on_u.ravel()])
            vals = np.concatenate([vals, np.tile(t.gain, t.count * lay.n), f.ravel()])
        m = self.steps * nd
        return RowBlock(rows, cols, vals, np.zeros(m), np.zeros(m))

    def set_bounds(
        self, lower: Array, upper: Array, p0: Array, u_prev: Array, free_m: Array | None = None
    ) -> None:
        lo, hi = self._boxes(p0, free_m)
        lower[:], upper[:] = lo.ravel(), hi.ravel()

    def dense(self) -> Array:
        h, d = self.horizon, self.dim
        x = positions_of_inputs(h, d, self.dt_s)
        if self.loop is not None:  # + sum_j G_{e,j} u_j per axis
            forced = self.loop.forced[1:]  # (H, H, d)
            x = x + np.einsum("ejd,dc->edjc", forced, np.eye(d)).reshape(h * d, h * d)
        if self.tail is None:
            return x
        t = self.tail
        on_u = np.einsum("tjd,dc->tdjc", t.forced, np.eye(d)).reshape(t.count * d, h * d)
        points = np.tile(t.gain[:, None] * positions_of_inputs(h, d, self.dt_s)[-d:], (t.count, 1)) + on_u
        return np.vstack([x, points])

    def dense_bounds(
        self, p0: Array, u_prev: Array, inf: float, free_m: Array | None = None
    ) -> tuple[Array, Array]:
        n = p0.shape[0]
        lo, hi = self._boxes(p0, free_m)
        return lo.transpose(1, 0, 2).reshape(n, -1), hi.transpose(1, 0, 2).reshape(n, -1)

    def violators(self, p0: Array, u_prev: Array, u: Array, x: Array, tol: float = 0.0) -> Array:
        """``x`` (H, n, d), or (H + T, n, d) with the tail's points already in it (and with a loop
        the true positions, :meth:`mpcform.mpc.prediction.Prediction.points`)."""
        lo, hi = self.box(p0)
        if self.tail is not None and x.shape[0] == self.horizon:
            x = np.concatenate([x, self.tail.points(x[-1], u)])
        return np.asarray(((x < lo - tol) | (x > hi + tol)).any(axis=(0, 2)))


def limit_rows(
    dim: int, dt_s: float, limits: Limits, settings: MPCSettings, loop: VelocityLoop | None = None
) -> tuple[LimitRows, ...]:
    """The families the limits ask for, in the QP's row order: velocity, acceleration, geofence
    (on the ``loop``'s positions with one; shrunk along the horizon by the rows' growth,
    :func:`mpcform.mpc.constraints.rows.step_growth`)."""
    h = settings.horizon
    families: list[LimitRows] = []
    if limits.v_max_mps is not None:
        families.append(VelocityRows(dim, h, settings, limits.v_max_mps, limits.speed_scale(dim)))
    if limits.a_max_mps2 is not None:
        families.append(AccelerationRows(dim, h, dt_s, limits.a_max_mps2))
    if limits.geofence_min_m is not None and limits.geofence_max_m is not None:
        fence = limits.geofence_min_m, limits.geofence_max_m
        braking = Braking.of(dt_s, limits, settings.braking)
        tail = planner_tail(braking, settings, dim, loop)
        growth = step_growth(limits.tube_growth_m, dt_s, h, 0 if tail is None else tail.count)
        families.append(GeofenceRows(dim, h, dt_s, *fence, settings.margin_m, tail, loop, growth))
    return tuple(families)


def violators(
    families: tuple[LimitRows, ...], p0: Array, u_prev: Array, u: Array, x: Array, tol: float = 0.0
) -> Array:
    """Drones (n,) whose ``(u, x)`` miss a velocity, acceleration or geofence row by more than ``tol``."""
    if len(families) == 1:
        return families[0].violators(p0, u_prev, u, x, tol)
    bad = np.zeros(p0.shape[0], dtype=bool)
    for family in families:
        bad |= family.violators(p0, u_prev, u, x, tol)
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


def velocity_set(
    dim: int, settings: MPCSettings, v_max_mps: float, scale: Array | None = None
) -> tuple[Array, float]:
    """Rows ``D u <= h`` [m/s] of the velocity set: the polytope inscribed in the ball, or for
    ``box`` the cube ``|u_a| <= v_max / sqrt(d)`` (rows ``+-e_a``); with per-axis ``scale`` (d,)
    the same set of ``S u`` (``D S``): inscribed in the spheroid ``||S u|| <= v_max``."""
    if settings.velocity_set == "box":
        normals, h = np.vstack([np.eye(dim), -np.eye(dim)]), v_max_mps / np.sqrt(dim)
    else:
        normals, h_rel = velocity_polytope(dim, settings.facets)
        h = h_rel * v_max_mps
    return (normals if scale is None else normals * scale), h


def admitted(families: tuple[LimitRows, ...], p0: Array, free_m: Array, path_m: Array) -> Array:
    """The free response ``free_m`` (S, n, d) the geofence's bounds are written with, moved so that
    from the second position on they admit ``path_m`` (S, n, d), where a plan that needs no solve
    takes the drones (:meth:`mpcform.mpc.safety.certify.Certifier.braking_plans`): wind the loop did not
    foresee can leave no plan inside the fence, and the QP stays feasible (as the first rows, whose
    bounds are lowered to the same plan). Without a geofence: ``free_m``."""
    fence = next((f for f in families if isinstance(f, GeofenceRows)), None)
    if fence is None:
        return free_m
    lo, hi = fence.box(p0)
    out = free_m.copy()
    forced = path_m[1:] - free_m[1:]
    out[1:] = np.clip(free_m[1:], lo - forced, hi - forced)
    return out
