"""Command changes: ``|u_j - u_{j-1}| <= a_max dt`` per component, ``u_{-1}`` the last command."""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.rows import Layout, RowBlock


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
