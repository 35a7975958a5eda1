"""The geofence: every position of the plan (and of its braking tail) inside the box, tightened
by the margin and shrunk along the horizon by the rows' growth in wind."""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.rows import Layout, RowBlock, positions_of_inputs
from mpcform.mpc.constraints.tail import Tail
from mpcform.mpc.velocity_loop import VelocityLoop


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
