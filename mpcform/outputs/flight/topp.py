r"""Time-optimal time scaling of a swarm's path under speed, acceleration and jerk limits.

Every drone flies ``P_i(s(t))`` with one scaling ``s(t)`` of the plan's time (so the drones pass
the same places together, :mod:`mpcform.outputs.flight.retime`). On nodes ``tau_k = k dtau`` the
unknowns are ``b_k = s'^2`` and, per segment, the constant ``s'' = alpha_k = (b_{k+1} - b_k) /
(2 dtau)``; with ``P', P'', P'''`` the path's derivatives in the plan's time the chain rule gives

.. math::
    v = P' \sqrt{b}, \quad a = P'' b + P' \alpha, \quad
    j = \sqrt{b}\,(P''' b + 3 P'' \alpha) + P' \dddot s,

so ``|v| <= v_max`` is a bound on ``b_k`` and ``|a| <= a_max`` a second-order cone in ``b`` (at
both ends of each segment), and the duration ``sum_k 2 dtau / (sqrt(b_k) + sqrt(b_{k+1}))`` is
convex (two rotated cones per segment): the time-optimal scaling under speed and acceleration is a
convex program (Verscheure et al., "Time-optimal path tracking for robots: a convex optimization
approach", IEEE TAC 2009), and its duration a lower bound on the minimum under all three limits
(:attr:`Profile.lower_bound_s`). The jerk is not convex in ``b``: with the third derivative of
``s`` taken as ``(alpha_k - alpha_{k-1}) sqrt(b_k) / dtau`` (from rest before the first segment
and after the last) it reads ``|Y_k(b)| <= j / sqrt(b_k)``, ``Y`` linear in ``b``, and ``j /
sqrt(b)`` is convex, so each of its tangents lies below it: the cone ``|Y_k(b)| <= its tangent
at b_bar`` is safe. The first round takes a ladder of tangents below the speed-and-acceleration
optimum, each later one the tangent at the previous solution, until the duration settles
(sequential convex programming: every round is feasible and none slower than the one before; exact
at the fixed point). Cones are added per drone and node where they bind (the largest derivatives
first, then every violated one), so a hundred drones cost about what a few do. Solved by clarabel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse

from mpcform._validate import Array
from mpcform.errors import MPCFormError

S_DOT_MAX = 100.0
"""The fastest the scaling runs through the plan (plan seconds per second): where the drones
barely move (a plan's slow approach to its goals) the flight passes in 1/100 of the plan's time."""
LADDER = 8  # the first jerk round's tangents per node, each a quarter of the one before
JERK_ROUNDS = 4  # later rounds (the jerk's tangents at the previous solution), at most
SETTLED = 5e-3  # relative change of the duration at which the rounds stop
TANGENT_FLOOR = 1e-3
"""The jerk's tangents are taken no lower than this share of the largest ``b`` (any tangent of the
convex ``j / sqrt(b)`` lies below it, so each is safe; a tangent at nearly 0 would be ill-conditioned)."""
FIRST_CONES = 4  # drones per node whose cones enter first (by each derivative's size)


@dataclass(frozen=True, eq=False)
class Profile:
    """``b = s'^2`` (K + 1,) on nodes ``dtau_s`` apart; ``lower_bound_s``: the minimum duration
    under the speed and acceleration limits alone (module docstring)."""

    dtau_s: float
    b: Array
    lower_bound_s: float

    @property
    def segment_acc(self) -> Array:
        """``s''`` (K,) on each segment."""
        return np.diff(self.b) / (2.0 * self.dtau_s)

    @property
    def node_times_s(self) -> Array:
        """When the flight passes each node (K + 1,) [s]."""
        return np.concatenate([[0.0], np.cumsum(_segment_times(self.b, self.dtau_s))])

    @property
    def duration_s(self) -> float:
        return float(_segment_times(self.b, self.dtau_s).sum())

    def smoothed(self, sub: int) -> Profile:
        """``b`` on nodes ``dtau_s / sub`` apart (``sub`` even), averaged over one node interval:
        ``s''`` then changes continuously, across each node over the interval that the jerk rows
        assume (a constant ``s''`` per segment steps the acceleration at every node, and a fit of
        the flight adds jerk there). ``b`` is continued as an odd function beyond the ends, so the
        flight still starts and ends at rest with the same ``s''``."""
        fine = np.interp(np.arange(sub * (self.b.size - 1) + 1) / sub, np.arange(self.b.size), self.b)
        h = sub // 2
        odd = np.concatenate([-fine[h:0:-1], fine, -fine[-2 : -h - 2 : -1]])
        box = np.convolve(odd, np.full(sub + 1, 1.0 / (sub + 1)), mode="valid")
        box[[0, -1]] = 0.0
        return Profile(self.dtau_s / sub, np.maximum(box, 0.0), self.lower_bound_s)


def _segment_times(b: Array, dtau: float) -> Array:
    """Each segment's duration at constant ``s''``: ``2 dtau / (sqrt(b_k) + sqrt(b_{k+1}))``."""
    root = np.sqrt(np.maximum(b, 0.0))
    return 2.0 * dtau / np.maximum(root[:-1] + root[1:], 1e-300)


def time_optimal(
    derivatives: tuple[Array, Array, Array],
    dtau_s: float,
    v_max: float,
    a_max: float,
    j_max: float | None,
    slower: Array | None = None,
) -> Profile:
    """The scaling of a path whose derivatives ``(P', P'', P''')`` (each (K + 1, n, 3)) are
    sampled ``dtau_s`` apart, at rest at both ends, within the limits (module docstring; without
    ``j_max``, under speed and acceleration alone); ``slower`` (K + 1,) >= 1 lowers the limits at
    each node as a uniform slow-down by its factor would (the speed by it, the acceleration by
    its square, the jerk by its cube)."""
    d1, d2, d3 = derivatives
    f = np.ones(d1.shape[0]) if slower is None else np.asarray(slower, dtype=float)
    v_nodes, a_nodes = v_max / f, a_max / f**2
    j_nodes = np.full_like(f, np.inf) if j_max is None else j_max / f**3
    speed2 = np.einsum("kia,kia->ki", d1, d1).max(axis=1)
    upper = np.minimum(S_DOT_MAX**2, v_nodes**2 / np.maximum(speed2, 1e-300))
    program = _Program(d1, d2, d3, dtau_s, upper, a_nodes, j_nodes)
    b = program.solve(None)
    lower = float(_segment_times(b, dtau_s).sum())
    if j_max is None or program.jerk_ok(b):  # the jerk limit does not bind
        return Profile(dtau_s, b, lower)
    # the first jerk tangents: a ladder from the speed-and-acceleration optimum down to a quarter
    # of the one constant scaling that keeps every limit (a tangent far above the optimum alone
    # would pin b near 0, and each later round grows b at most 3 times)
    peaks = [max(float(np.linalg.norm(d, axis=-1).max()), 1e-300) for d in derivatives]
    steady = min(
        S_DOT_MAX,
        v_nodes.min() / peaks[0],
        np.sqrt(0.5 * a_nodes.min() / peaks[1]),
        np.cbrt(j_nodes.min() / (3.0 * peaks[2])),
    )
    ladder = b[None] * 4.0 ** -np.arange(LADDER)[:, None]
    ladder[1:][ladder[1:] < 0.25 * steady**2] = np.nan
    b = program.solve(ladder)
    duration = float(_segment_times(b, dtau_s).sum())
    for _ in range(JERK_ROUNDS):
        try:
            b_next = program.solve(b[None])
        except MPCFormError:  # a later round that stalls keeps the last one (feasible, not slower)
            break
        b, new = b_next, float(_segment_times(b_next, dtau_s).sum())
        if abs(new - duration) <= SETTLED * new:
            break
        duration = new
    return Profile(dtau_s, b, lower)


class _Program:
    """The convex program of :func:`time_optimal`: cones added where they bind."""

    def __init__(self, d1: Array, d2: Array, d3: Array, dtau: float, upper: Array, a: Array, j: Array):
        self.d, self.dtau, self.upper = (d1, d2, d3), dtau, upper
        self.limit = {"acc_out": a, "acc_in": a, "jerk": j}
        nodes, n = d1.shape[:2]
        self.nodes = nodes
        self.factor = np.arange(nodes)  # whose sqrt(b) scales a node's jerk (the ends: their neighbour's)
        self.factor[0], self.factor[-1] = 1, nodes - 2
        if n <= FIRST_CONES:
            first = np.ones((nodes, n), dtype=bool)
        else:
            first = np.zeros((nodes, n), dtype=bool)
            for d in (d1, d2, d3):
                top = np.argsort(-np.linalg.norm(d, axis=-1), axis=1)[:, :FIRST_CONES]
                np.put_along_axis(first, top, True, axis=1)
        self.active = {kind: first.copy() for kind in self.limit}

    def solve(self, tangents: Array | None) -> Array:
        """``b`` without jerk cones (``tangents`` None), else with the jerk's tangents at
        ``tangents`` (L, K + 1) (NaN: none)."""
        kinds = ("acc_out", "acc_in") if tangents is None else ("acc_out", "acc_in", "jerk")
        for _ in range(self.nodes):  # each round adds at least one violated cone
            b = self._solve_active(kinds, tangents)
            grew = False
            for kind in kinds:
                norms = np.linalg.norm(self._values(kind, b), axis=-1)
                if kind == "jerk":
                    norms *= np.sqrt(b[self.factor])[:, None]
                late = (norms > self.limit[kind][:, None] * (1.0 + 1e-6)) & ~self.active[kind]
                if late.any():
                    self.active[kind] |= late
                    grew = True
            if not grew:
                return b
        raise MPCFormError("the time scaling did not settle on its binding cones")

    def jerk_ok(self, b: Array) -> bool:
        """Whether ``b`` keeps every drone's jerk at every node within the limit."""
        scale = np.sqrt(b[self.factor])[:, None]
        norms = scale * np.linalg.norm(self._values("jerk", b), axis=-1)
        return bool(np.all(norms <= self.limit["jerk"][:, None] * (1 + 1e-6)))

    def _coefficients(self, kind: str) -> tuple[Array, Array, Array]:
        """Per node k and drone i, the vectors (K + 1, n, 3) multiplying ``b_{k-1}, b_k, b_{k+1}``
        in the acceleration, or in the jerk over ``sqrt(b)``: ``P''' b_k + 3 P'' (alpha_{k-1} +
        alpha_k) / 2 + P' (alpha_k - alpha_{k-1}) / dtau`` (no ``alpha`` before the first node or
        after the last: the drones are at rest there)."""
        d1, d2, d3 = self.d
        h = 2.0 * self.dtau
        before, here, after = np.zeros_like(d1), np.zeros_like(d1), np.zeros_like(d1)
        if kind != "jerk":  # P'' b_k + P' alpha, the segment after node k's alpha or the one before's
            here += d2
            if kind == "acc_out":
                here[:-1] -= d1[:-1] / h
                after[:-1] += d1[:-1] / h
            else:
                here[1:] += d1[1:] / h
                before[1:] -= d1[1:] / h
            return before, here, after
        p, q = 1.5 * d2, d1 / self.dtau
        here += d3
        before[1:] -= (p - q)[1:] / h  # alpha_{k-1} = (b_k - b_{k-1}) / h
        here[1:] += (p - q)[1:] / h
        after[:-1] += (p + q)[:-1] / h  # alpha_k = (b_{k+1} - b_k) / h
        here[:-1] -= (p + q)[:-1] / h
        return before, here, after

    def _values(self, kind: str, b: Array) -> Array:
        before, here, after = self._coefficients(kind)
        padded = np.concatenate([[0.0], b, [0.0]])
        return (
            before * padded[:-2, None, None]
            + here * padded[1:-1, None, None]
            + after * padded[2:, None, None]
        )

    def _solve_active(self, kinds: tuple[str, ...], tangents: Array | None) -> Array:
        import clarabel  # imported when an export is retimed, not with the package

        k1 = self.nodes
        rows, cols, vals, rhs = [np.array([0, 1])], [np.array([0, k1 - 1])], [np.ones(2)], [np.zeros(2)]
        cones: list = [clarabel.ZeroConeT(2)]
        eye = np.arange(k1)  # 0 <= b_k <= upper_k
        rows += [2 + eye, 2 + k1 + eye]
        cols += [eye, eye]
        vals += [-np.ones(k1), np.ones(k1)]
        rhs += [np.zeros(k1), self.upper]
        cones.append(clarabel.NonnegativeConeT(2 * k1))
        start = 2 + 2 * k1
        top = 0.0 if tangents is None else float(np.nanmax(tangents))
        for kind in kinds:
            k_all, i_all = np.nonzero(self.active[kind])
            coef = self._coefficients(kind)
            levels = [None] if kind != "jerk" or tangents is None else list(tangents)
            for level in levels:
                k, i = k_all, i_all
                bound = self.limit[kind][k]
                if level is not None:  # |Y| <= j / sqrt(b) by its tangent at ``bar``
                    bar = np.maximum(level[self.factor[k]], TANGENT_FLOOR * top + 1e-12)
                    use = np.isfinite(level[self.factor[k]])
                    k, i, bar = k[use], i[use], bar[use]
                    bound = 1.5 * self.limit[kind][k] / np.sqrt(bar)
                base = start + 4 * np.arange(k.shape[0])
                for shift, block in zip((-1, 0, 1), coef, strict=True):
                    col = k + shift
                    ok = (col >= 0) & (col < k1)
                    for axis in range(3):
                        rows.append(base[ok] + 1 + axis)
                        cols.append(col[ok])
                        vals.append(block[k[ok], i[ok], axis])
                if level is not None:
                    rows.append(base)
                    cols.append(self.factor[k])
                    vals.append(0.5 * self.limit[kind][k] / bar**1.5)
                cone_rhs = np.zeros((k.shape[0], 4))
                cone_rhs[:, 0] = bound
                rhs.append(cone_rhs.ravel())
                cones += [clarabel.SecondOrderConeT(4)] * k.shape[0]
                start += 4 * k.shape[0]
        # the duration: c_k <= sqrt(b_k) and d_k >= 2 dtau / (c_k + c_{k+1}), as rotated cones
        # (c = 0 at rest at both ends: equalities, so that every cone has an interior)
        seg, inner = np.arange(k1 - 1), np.arange(1, k1 - 1)
        c, d = k1 + eye, 2 * k1 + seg
        at = start + 3 * (inner - 1)  # ||(2 c_k, b_k - 1)|| <= b_k + 1
        rows += [at, at + 1, at + 2]
        cols += [inner, c[inner], inner]
        vals += [-np.ones(k1 - 2), -2.0 * np.ones(k1 - 2), -np.ones(k1 - 2)]
        rhs.append(np.tile([1.0, 0.0, -1.0], k1 - 2))
        at = (
            start + 3 * (k1 - 2) + 3 * seg
        )  # ||(2 sqrt(2 dtau), d_k - e_k)|| <= d_k + e_k, e_k = c_k + c_{k+1}
        for col, sign in ((d, 1.0), (c[:-1], -1.0), (c[1:], -1.0)):
            rows += [at, at + 2]
            cols += [col, col]
            vals += [-np.ones(k1 - 1), sign * np.ones(k1 - 1)]
        rhs.append(np.tile([0.0, 2.0 * np.sqrt(2.0 * self.dtau), 0.0], k1 - 1))
        cones += [clarabel.SecondOrderConeT(3)] * (2 * k1 - 3)
        at = start + 3 * (2 * k1 - 3)
        rows.append(np.array([at, at + 1]))
        cols.append(c[[0, -1]])
        vals.append(np.ones(2))
        rhs.append(np.zeros(2))
        cones.append(clarabel.ZeroConeT(2))
        width = 3 * k1 - 1
        a = sparse.csc_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
            shape=(start + 3 * (2 * k1 - 3) + 2, width),
        )
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        q = np.concatenate([np.zeros(2 * k1), np.ones(k1 - 1)])
        solver = clarabel.DefaultSolver(
            sparse.csc_matrix((width, width)), q, a, np.concatenate(rhs), cones, settings
        )
        solution = solver.solve()
        if str(solution.status) not in ("Solved", "AlmostSolved"):
            raise MPCFormError(f"the time scaling's convex program ended {solution.status}")
        b = np.clip(np.asarray(solution.x)[:k1], 0.0, self.upper)
        b[[0, -1]] = 0.0  # at rest (the zero cone holds them to the solver's tolerance)
        return b
