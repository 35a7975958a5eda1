r"""The braking tail's exact hull under a velocity loop: a few vertices whose hull holds every
point of the tail until the loop is at rest, and maps into itself when the plan shifts.

Past the horizon a plan brakes geometrically (:mod:`mpcform.mpc.braking`): the command of
interval ``H + m`` is ``rho^{m+1} u_{H-1}``. Per axis the tail's state ``z = (c, xi)`` (the last
command level, ``c_0 = u_{H-1}``, and the loop state without its velocity offset, ``xi_0 = xi_H``)
evolves as ``z+ = M z`` with ``M = [[rho, 0], [rho Gamma, Phi]]`` (``Phi``, ``Gamma``: one interval
of the loop, :class:`mpcform.mpc.loop.VelocityLoop`), and the distance still to go to the rest
point is ``L M^m z`` with ``L = [kappa dc, F_rest]`` (the commands still to come, carried ``dc``
per metre, plus the loop's free response to rest).

**The hull.** Vertex functionals ``W_0 = L``, then over M's real eigenvalues ``d_j`` in [0, 1)

.. math::
    W_{j+1} = W_j (M - d_j I) / (1 - d_j), \qquad\text{so}\qquad W_j M = d_j W_j + (1 - d_j) W_{j+1},

and the chain ends at 0 (Cayley-Hamilton: the rest point). A complex pair ``r e^{i theta}`` (at most
one per axis here) ends the chain instead with the N vertices of a regular N-gon, ``cos(pi/N) >= r``,
around the pair's orbit in its rotation coordinates: rotated by theta and shrunk by r it lies inside
its inscribed circle. Every row of ``W M`` is then a convex combination of the rows of ``W`` and 0
(:attr:`AxisHull.transition`, nonnegative, rows summing to at most 1), so the distances to go
``W z`` of a state hold those of every later state: the tail's points lie in the hull of
``rest - W z`` and the rest point, and the shifted plan's hull (``z -> M z``) lies in this one.
No eigenvector is formed: nothing blows up when ``rho`` meets a pole of the loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from mpcform._validate import Array
from mpcform.errors import MPCFormError, ValidationError
from mpcform.mpc.braking import Braking
from mpcform.mpc.loop import VelocityLoop

REAL_TOL = 1e-9  # an eigenvalue with a smaller imaginary part is real


@dataclass(frozen=True, eq=False)
class AxisHull:
    """One axis' vertex functionals ``vertices`` (V, q) on its tail state ``z`` (q,) and the
    nonnegative ``transition`` (V, V) with ``vertices M = transition vertices`` (row sums <= 1)."""

    vertices: Array
    transition: Array


def tail_system(loop: VelocityLoop, braking: Braking, axis: int) -> tuple[Array, Array]:
    """``M`` (q, q) and ``L`` (q,) of ``axis``'s tail (module docstring), ``q = 1 + s``."""
    s = loop.step_state.shape[1] - 1  # the loop's states, without the velocity offset
    phi, gamma = loop.step_state[axis, :s, :s], loop.step_input[axis, :s]
    m = np.zeros((s + 1, s + 1))
    m[0, 0], m[1:, 0], m[1:, 1:] = braking.rho, braking.rho * gamma, phi
    return m, np.concatenate([[braking.kappa_s * loop.dc_gain[axis]], loop.rest_m[axis, :s]])


def axis_hull(m: Array, rest: Array) -> AxisHull:
    """The hull (module docstring) of the tail ``rest M^k z``."""
    eig = np.linalg.eigvals(m)
    reals = np.sort(eig.real[np.abs(eig.imag) <= REAL_TOL])
    pairs = eig[eig.imag > REAL_TOL]
    if reals.size and (reals.min() < 0.0 or reals.max() >= 1.0) or np.any(np.abs(pairs) >= 1.0):
        raise ValidationError("plant", f"the braking tail needs a stable loop with poles in [0, 1): {eig}")
    if pairs.size > 1:
        raise ValidationError("plant", "the braking tail's hull takes at most one complex pole pair per axis")
    q = m.shape[0]
    rows, steps = [rest], []
    for d in reals:  # the real chain, fastest first
        rows.append(rows[-1] @ (m - d * np.eye(q)) / (1.0 - d))
        steps.append(d)
    last = rows.pop()  # 0 without a pair, else the pair's part
    v = len(rows)
    if pairs.size == 0:
        lam = np.zeros((v, v))
        for j, d in enumerate(steps):
            lam[j, j] = d
            if j + 1 < v:
                lam[j, j + 1] = 1.0 - d
        return AxisHull(np.array(rows), lam)
    polygon, rotation = _polygon(last, m, pairs[0])
    n = polygon.shape[0]
    lam = np.zeros((v + n, v + n))
    for j, d in enumerate(steps):
        lam[j, j] = d
        if j + 1 < v:
            lam[j, j + 1] = 1.0 - d
        else:  # into the polygon: the pair's part is a convex combination of its vertices
            lam[j, v:] = (1.0 - d) * _weights(polygon, last)
    lam[v:, v:] = rotation
    return AxisHull(np.vstack([np.array(rows), polygon]), lam)


def _polygon(base: Array, m: Array, pole: complex) -> tuple[Array, Array]:
    """The N vertex functionals around the pair's part ``base`` (q,) and their transition (N, N)."""
    r, theta = abs(pole), float(np.angle(pole))
    n = max(3, int(np.ceil(np.pi / np.arccos(r) - 1e-12)))
    companion = np.array([[0.0, -r * r], [1.0, 2.0 * r * np.cos(theta)]])  # (a, b) of a base + b base M
    w, vecs = np.linalg.eig(companion)
    k = int(np.argmax(w.imag))
    basis = np.column_stack([vecs[:, k].real, vecs[:, k].imag])  # companion basis = basis rot
    y0 = np.linalg.solve(basis, np.array([1.0, 0.0]))
    angles = np.arctan2(y0[1], y0[0]) + 2.0 * np.pi * np.arange(n) / n
    corners = np.linalg.norm(y0) / np.cos(np.pi / n) * np.column_stack([np.cos(angles), np.sin(angles)])
    ab = corners @ basis.T  # (N, 2)
    polygon = ab[:, :1] * base + ab[:, 1:] * (base @ m)
    rotation = np.array([_weights(polygon, row) for row in polygon @ m])
    return polygon, rotation


def _weights(polygon: Array, row: Array) -> Array:
    """Nonnegative weights (N,) summing to at most 1 with ``weights @ polygon = row`` (a small LP:
    the row lies in the polygon by construction)."""
    n = polygon.shape[0]
    res = linprog(
        np.zeros(n), A_ub=np.ones((1, n)), b_ub=[1.0], A_eq=polygon.T, b_eq=row, bounds=[(0.0, None)] * n
    )
    if res.status != 0:
        raise MPCFormError("the braking tail's polygon does not hold its own rotation")
    return np.asarray(res.x)
