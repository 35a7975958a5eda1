"""The QP's variables and its structural rows: dynamics, the loop's positions, separation pattern, slack.

Variables, all drones stacked (n drones, d dims, horizon H), positions relative to the start
``p0`` (``x_j = p_j - p0``, ``x_0 = 0``)::

    z = [u_0 .. u_{H-1} | x_1 .. x_H | s_1 .. s_H]   (then y_1 .. y_H with a velocity loop)

With a velocity loop (:mod:`mpcform.mpc.velocity_loop`) ``y_e = x_e + sum_j G_{e,j} u_j`` are where the loop
takes the drones (less its free response, which is in the bounds); the separation rows are on y.

The limits' rows are one unit per limit (:mod:`mpcform.mpc.constraints.limits`). The separation rows'
pattern is built here; their coefficients come from the linearisation about the guess
(:mod:`mpcform.mpc.constraints.separation`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.velocity_loop import VelocityLoop

INF = np.inf
GROWTH_TIME_S = 0.2
"""How long [s] of the horizon the rows keep growing by the plant's disturbance reach
(:func:`step_growth`). With 0.6 s (about the time a quadrotor's velocity loop takes to answer)
a decoupled formation of 15 quadrotors turning in gusts (``tests/fz_s9191_72.toml``) jammed:
no drone arrived; with 0.3 s a decoupled swap of 11 (the flight acceptance's random seed 3)
arrived at 17.2 s instead of 6.9 s. With 0.2 s they arrive at 14.7 and 8.6 s, without slack in
the first and with 8 slack steps instead of 18 in the second."""


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
    of :class:`mpcform.mpc.velocity_loop.VelocityLoop`."""
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


def separation_pattern(
    lay: Layout, pairs: Array, singles: Array, tail: int = 0, support: Array | None = None
) -> RowBlock:
    """Pattern of the separation rows (values zero; they change every step), R rows per item.

    Pairs ``(i, k)`` (P, 2) first: ``c^T (x_{e,i} - x_{e,k}) + s_{e,i} + s_{e,k} >= b``; then the
    one-drone items ``singles`` (S,) (decoupled pair sides, obstacles): ``c^T x_{e,i} + s_{e,i} >= b``;
    at the position steps e of :func:`row_ends` (on y instead of x with ``lay.true_positions``).
    With the braking tail's ``tail`` points (:mod:`mpcform.mpc.constraints.tail`, each ``g x_H + sum_j F_j
    u_j``
    over the inputs ``support``) steps H + 1 .. H + tail are those points (with the step-H
    slack): their rows' entries on the inputs come after all the others, pairs then singles, per
    item, tail row, input and drone.
    """
    h = lay.horizon
    e = row_ends(h, tail)  # (R,) position index 1..H (then the tail points) of each row
    nr = e.shape[0]
    x_col, s_col = lay.y_cols() if lay.true_positions else lay.x_cols(), lay.s_cols()
    if tail:
        x_col = np.concatenate([x_col, np.repeat(lay.x_cols()[-1:], tail, axis=0)])
        s_col = np.concatenate([s_col, np.repeat(s_col[-1:], tail, axis=0)])
    rows: list[Array] = [np.empty(0, dtype=np.intp)]
    cols: list[Array] = [np.empty(0, dtype=np.intp)]
    extra_rows, extra_cols = [], []
    count = 0
    at_tail = tail_rows(h, tail)
    for drones in ([pairs[:, 0], pairs[:, 1]], [singles]):
        m = drones[0].shape[0]
        if m == 0:
            continue
        xs = [x_col[e - 1][:, i].transpose(1, 0, 2) for i in drones]  # (items, R, d) each
        ss = [s_col[e - 1][:, i].T[:, :, None] for i in drones]  # (items, R, 1) each
        cc = np.concatenate(xs + ss, axis=2)
        row_ids = count + np.arange(m * nr).reshape(m, nr, 1)
        rows.append(np.broadcast_to(row_ids, cc.shape).ravel())
        cols.append(cc.ravel())
        if tail and support is not None:  # the tail rows' input entries (items, tail, J, d per drone)
            uu = np.concatenate([lay.u_cols()[support][:, i].transpose(1, 0, 2) for i in drones], axis=2)
            uu = np.broadcast_to(uu[:, None], (m, tail) + uu.shape[1:])
            extra_rows.append(np.broadcast_to(row_ids[:, at_tail, :, None], uu.shape).ravel())
            extra_cols.append(uu.ravel())
        count += m * nr
    entries = np.concatenate(rows + extra_rows)
    zeros = np.zeros(entries.shape)  # values: set each step
    return RowBlock(entries, np.concatenate(cols + extra_cols), zeros, np.zeros(count), np.full(count, INF))


def tail_rows(horizon: int, tail: int) -> Array:
    """Indices among an item's rows of the braking tail's points (the stop point last)."""
    return 2 * horizon - 1 + np.arange(tail) if tail else np.empty(0, dtype=np.intp)


def row_ends(horizon: int, tail: int = 0) -> Array:
    """Row order per item: for segment j = 0..H-1, its end x_{j+1}, then its start x_j (j >= 1);
    then with the braking tail's ``tail`` points, each of them (H + 1 .. H + tail) and its start x_H."""
    ends = []
    for j in range(horizon):
        ends.append(j + 1)
        if j >= 1:
            ends.append(j)
    if tail:
        ends += [horizon + 1 + t for t in range(tail)] + [horizon]
    return np.array(ends, dtype=np.intp)


def step_growth(growth_m: float, dt_s: float, horizon: int, tail: int = 0) -> Array | None:
    r"""Per-drone tightening (H + T + 1,) [m] of the rows at position steps ``e = 0 .. H + T``
    (then the braking tail's T points): ``growth_m min(e - 1, E)``, ``E = min(H, ceil(GROWTH_TIME_S
    / dt))``; None for no growth.

    Constraint tightening along the horizon (Chisci, Rossiter and Zappa, Automatica 37(7), 2001):
    when the disturbance moves every position of the shifted plan by at most ``growth_m`` per drone
    and interval, a plan that meets its rows at step k leaves the shifted plan meeting the next
    step's rows at every step up to E (``e + 1`` had one growth more than ``e`` needs), the
    first rows included, so none has to be lowered; rows beyond E (and the tail) may be missed by one
    growth, which the plan has E steps to win back: a plan may reach into the growth there, which is
    not slack (:func:`mpcform.mpc.safety.slack.slack_report`). Without wind the growth is 0 and nothing
    changes."""
    if growth_m <= 0.0:
        return None
    cap = min(horizon, math.ceil(GROWTH_TIME_S / dt_s - 1e-9))
    return growth_m * np.clip(np.arange(horizon + tail + 1) - 1, 0, cap).astype(float)


def row_segments(horizon: int, tail: int = 0) -> Array:
    """Segment index j of each separation row of an item (R,), matching :func:`row_ends` (the
    tail's rows: segment H)."""
    segs = []
    for j in range(horizon):
        segs.append(j)
        if j >= 1:
            segs.append(j)
    if tail:
        segs += [horizon] * (tail + 1)
    return np.array(segs, dtype=np.intp)


def positions_of_inputs(horizon: int, dim: int, dt_s: float) -> Array:
    """One drone's positions x_1 .. x_H from its inputs (H d, H d): ``x_e = dt sum_{j<e} u_j``."""
    return dt_s * np.kron(np.tril(np.ones((horizon, horizon))), np.eye(dim))


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
