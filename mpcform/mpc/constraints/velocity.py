"""The velocity set: ``D u_{j,i} <= h`` [m/s], a polytope inscribed in the ball ``||u|| <= v_max``
(seed eq. 7's saturation as rows), or a box; squeezed along z under ``v_max_z``."""

from __future__ import annotations

import numpy as np
from scipy.spatial import HalfspaceIntersection

from mpcform._validate import Array
from mpcform.mpc.constraints.family import LimitRows
from mpcform.mpc.constraints.rows import INF, Layout, RowBlock
from mpcform.mpc.settings import MPCSettings
from mpcform.world.closest import squared_norms

INSCRIBED = 1.0 - 1e-9  # ||u||^2 below this times h^2: inside the velocity set, rounding included


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
