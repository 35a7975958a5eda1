"""The receding-horizon planner (controller ``mpc``): problem -> QP -> solve -> first input.

Every step: targets over the horizon, the eq. 14 rollout, separation items culled with a k-d
tree, their rows linearised about the guess (the previous plan shifted one step, ending in a
hold; at the first step every drone holding), then either the fast path (the rollout meets every
row, so it *is* the QP's optimum) or a solve: of the sparse QP (:mod:`mpcform.mpc.qp`) with the
backend, or in decoupled mode of each conflicted drone's block with DAQP (:mod:`mpcform.mpc.per_drone`).
The command returned is certified: inside the
ball ``||u_i|| <= v_max`` and, along the first segment, no pair closer than ``d_min`` (or than it
already was). A failed or uncertifiable solve falls back to the previous plan's next input or a
hold, and is reported; the loop never raises or returns NaN for a solver's failure.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from mpcform._validate import Array, positive
from mpcform.control.base import Controller, ControlStep, StepInfo, feedforward_targets
from mpcform.control.laws import check_gain_dt, saturate
from mpcform.errors import ValidationError
from mpcform.formation.geometry import closest_on_segments, pairs_within
from mpcform.mpc.limits import Limits, SphereObstacle
from mpcform.mpc.per_drone import PerDroneQP
from mpcform.mpc.qp import MPCQP, row_ends, row_segments, velocity_set
from mpcform.mpc.settings import MPCSettings
from mpcform.reference.base import Reference
from mpcform.solvers.base import QPBackend, QPContext, QPSolution, SolverOptions
from mpcform.solvers.registry import DEFAULT_SOLVER, make_backend

CERTIFY_TOL_M = 1e-7  # separation certification tolerance [m]
SLACK_REPORT_M = 1e-6  # slack above this is reported
PER_DRONE_SOLVER = "daqp (per drone)"  # solver_name in decoupled mode with per_drone
STALL_FRACTION = 0.02  # a conflicted drone whose last command is below this fraction of its wish is stalled
STALL_GROWTH = 0.1  # the tie-break angle grows by this fraction of itself per stalled step


@dataclass(frozen=True)
class Plan:
    """Predicted inputs (H, n, d) [m/s] and positions (H + 1, n, d) [m], row 0 the start."""

    inputs_mps: Array
    positions_m: Array


@dataclass(frozen=True)
class _Candidates:
    """Items kept in the QP (fixed pattern) and which of them are within reach this step."""

    pairs: Array  # (P, 2) drone pairs i < k
    pair_on: Array  # (P,) bool
    obstacles: Array  # (O, 2) (drone, obstacle index)
    obstacle_on: Array  # (O,) bool
    rebuilt: bool

    def within_reach(self) -> _Candidates:
        """Only the items within reach this step."""
        p, o = self.pairs[self.pair_on], self.obstacles[self.obstacle_on]
        on = np.ones(p.shape[0], dtype=bool), np.ones(o.shape[0], dtype=bool)
        return _Candidates(p, on[0], o, on[1], self.rebuilt)


@dataclass(frozen=True)
class _Rows:
    """Linearised separation rows of one step, in QP order (R rows per item).

    Two-drone items (joint pairs) first, then one-drone items (decoupled pair sides, obstacles);
    ``labels`` (S, 2) names what a one-drone item reports: ``(i, k)`` or ``(i, -1 - obstacle)``.
    """

    pairs: Array  # (P, 2)
    pair_coeffs: Array  # (P, R, d)
    pair_lower: Array  # (P, R)
    pair_on: Array  # (P,)
    singles: Array  # (S,) drone index
    labels: Array  # (S, 2)
    single_coeffs: Array  # (S, R, d)
    single_lower: Array  # (S, R)
    single_on: Array  # (S,)


class MPCPlanner(Controller):
    """Receding-horizon QP tracking a formation reference under velocity and separation limits.

    With none of its rows active the first input is exactly eq. 14 (``feedforward + k (p* - p)``).
    ``solver`` names a backend (``mpcform solvers``; the default is a persistent PIQP object) or is
    a :class:`~mpcform.solvers.base.QPBackend` instance (e.g. a recording wrapper).
    """

    name = "mpc"

    def __init__(
        self,
        reference: Reference,
        dt_s: float,
        limits: Limits | None = None,
        settings: MPCSettings | None = None,
        obstacles: tuple[SphereObstacle, ...] = (),
        solver: str | QPBackend = DEFAULT_SOLVER,
    ) -> None:
        self.reference, self.dt_s = reference, positive("simulation.dt", dt_s)
        self.limits = limits = limits or Limits()
        self.settings = settings = settings or MPCSettings()
        check_gain_dt(settings.gain_per_s, dt_s)
        tpl = reference.template
        self.n, self.dim = tpl.n, tpl.dim
        self.obstacles = tuple(obstacles)
        for idx, ob in enumerate(self.obstacles):
            if ob.center_m.shape != (self.dim,):
                raise ValidationError(
                    f"obstacles[{idx}].center",
                    f"expected {self.dim} numbers, got {ob.center_m.tolist()}",
                )
        needs_reach = limits.d_min_m is not None or self.obstacles
        if needs_reach and limits.v_max_mps is None:
            raise ValidationError(
                "limits.v_max",
                "the MPC needs v_max when d_min or obstacles are set (it bounds how far drones can reach)",
            )
        if limits.downwash_kappa is not None and self.dim != 3:
            raise ValidationError(
                "limits.downwash", "downwash separation needs a spatial (dim = 3) formation"
            )
        if limits.geofence_min_m is not None and limits.geofence_min_m.shape != (self.dim,):
            raise ValidationError(
                "limits.geofence_min",
                f"expected {self.dim} numbers, got {limits.geofence_min_m.tolist()}",
            )
        self._solver: PerDroneQP | QPBackend  # the sparse QP's backend, or DAQP per drone
        if settings.solves_per_drone:
            if solver != DEFAULT_SOLVER:  # it would be ignored
                raise ValidationError("controller.solver", f"{_solver_text(solver)} solves the sparse QP, "
                                      "but decoupled mode solves each drone's QP with DAQP here; set "
                                      "controller.per_drone = false to use it")  # fmt: skip
            self._solver = PerDroneQP(self.dim, dt_s, limits, settings)
            self.solver_name = PER_DRONE_SOLVER
        else:
            options = SolverOptions(
                settings.eps_abs, settings.eps_rel, settings.max_iter, settings.time_limit_s
            )
            self._solver = solver if isinstance(solver, QPBackend) else make_backend(solver, options)
            self.solver_name = self._solver.name
        metric = np.ones(self.dim)
        if limits.downwash_kappa is not None:
            metric[2] = 1.0 / limits.downwash_kappa
        self._metric = metric
        self._segs, self._ends = row_segments(settings.horizon), row_ends(settings.horizon)
        if limits.v_max_mps is not None:
            self._vel_normals, self._vel_h = velocity_set(self.dim, settings, limits.v_max_mps)
        if self.obstacles:
            self._ob_center = np.array([o.center_m for o in self.obstacles])
            half = 0.5 * (limits.d_min_m or 0.0)
            self._ob_required = np.array(
                [o.radius_m + (half if o.clearance_m is None else o.clearance_m) for o in self.obstacles]
            )
        self.reset(0.0, np.zeros((self.n, self.dim)))

    # ---- state ----------------------------------------------------------------------------
    def reset(self, t_s: float, positions_m: Array) -> None:
        self._fresh = True  # no candidate set chosen yet
        self._qp: MPCQP | None = None
        self._qp_key = b""
        self._backend_qp: MPCQP | None = None
        self._pairs = np.empty((0, 2), dtype=np.intp)  # candidate pairs (i < k), sorted by code
        self._pair_codes = np.empty(0, dtype=np.intp)  # i * n + k
        self._obstacle_items = np.empty((0, 2), dtype=np.intp)  # (drone, obstacle)
        self._ob_codes = np.empty(0, dtype=np.intp)  # drone * m + obstacle
        self._plan: Plan | None = None
        self._u_prev = np.zeros((self.n, self.dim))
        self._stalled = np.zeros(self.n, dtype=int)  # steps in a row each drone was stalled in conflict

    @property
    def plan(self) -> Plan | None:
        """The plan of the last step (None before the first)."""
        return self._plan

    # ---- one step -------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        p0 = self._check_positions(positions_m)
        st = self.settings
        k, dt, horizon = st.gain_per_s, self.dt_s, st.horizon
        targets, ff = feedforward_targets(self.reference, t_s, dt, horizon, st.feedforward)
        c = ff + k * (targets[:-1] - p0)  # u_j = c_j - k x_j is the eq. 14 rollout
        u_nom, x_nom = _rollout(c, k, dt)
        guess = self._guess(p0)
        off_limits = self._limit_violators(p0, u_nom, x_nom)
        if st.fast_path and not off_limits.any() and self._clear_of_rows(p0, guess, x_nom):
            return self._fast_path(p0, u_nom, x_nom)
        cand = self._candidates(p0)
        grouped = st.fast_path and st.grouping
        if grouped or isinstance(self._solver, PerDroneQP):  # no fixed pattern: rows only within reach
            cand = cand.within_reach()
        rows = self._separation_rows(p0, guess, cand)
        conflicted = np.zeros(self.n, dtype=bool)
        labels = self._row_shortfall(x_nom, rows, 0.0)[1]
        conflicted[labels[labels >= 0]] = True  # drones of missed items (not obstacles: < 0)
        if st.fast_path and not (off_limits | conflicted).any():
            return self._fast_path(p0, u_nom, x_nom)
        if st.tie_break_rad > 0:  # turn the conflicted drones' wishes to the right
            c = np.where(conflicted[:, None], _turn_about_z(c, -self._tie_break_angles(conflicted, c[0])), c)
        bad = off_limits | conflicted
        drones = self._qp_drones(bad, rows) if grouped else np.arange(self.n)
        sub = _subset_rows(rows, drones, self.n, on_only=grouped)  # grouped: the pattern follows the groups
        sol, active = self._solve(drones, p0, c, sub, cand.rebuilt, u_nom, x_nom)
        nud = horizon * drones.shape[0] * self.dim
        status = sol.status
        if sol.success and sol.x is not None:
            u, x = u_nom.copy(), x_nom.copy()
            u[:, drones] = sol.x[:nud].reshape(horizon, drones.shape[0], self.dim)
            x[:, drones] = sol.x[nud : 2 * nud].reshape(horizon, drones.shape[0], self.dim)
            u0 = saturate(u[0], self.limits.v_max_mps)
            if self._certified(p0, u0, cand):
                self._accept(p0, u, x)
                slack = sol.x[2 * nud :]
                shortfall, slack_items = 0.0, tuple[tuple[int, int], ...]()
                if slack.max(initial=0.0) > SLACK_REPORT_M / 2:
                    shortfall, missed = self._row_shortfall(x, rows, SLACK_REPORT_M)
                    slack_items = tuple((int(a), int(b)) for a, b in missed)
                return ControlStep(u0, StepInfo(
                    "qp", status=status, iterations=sol.iterations, solve_time_s=sol.solve_time_s,
                    active_rows=active, max_slack_m=max(shortfall, 0.0), slack_pairs=slack_items,
                    qp_drones=int(drones.shape[0]),
                ))  # fmt: skip
            status += "; command failed certification"
        return self._fallback(p0, cand, StepInfo("fallback", status=status, iterations=sol.iterations,
                                                 solve_time_s=sol.solve_time_s))  # fmt: skip

    def _tie_break_angles(self, conflicted: Array, wish: Array) -> Array:
        """Turn angle per drone [rad]: ``tie_break``, growing by ``STALL_GROWTH`` of it for every
        step in a row that the drone has been conflicted and stalled (its last command below
        ``STALL_FRACTION`` of its wish), up to a quarter turn: a symmetric ring that the first
        angle holds in balance (16 drones swapping in decoupled mode) is broken within a few steps.
        A ``tie_break`` above a quarter turn is kept as it is."""
        stalled = conflicted & (_norms(self._u_prev) < STALL_FRACTION * _norms(wish))
        stalled &= self._plan is not None  # no command given yet: nothing has stalled
        self._stalled = np.where(stalled, self._stalled + 1, 0)
        base = self.settings.tie_break_rad
        return np.minimum(base * (1.0 + STALL_GROWTH * self._stalled), max(base, 0.5 * np.pi))

    def _fast_path(self, p0: Array, u_nom: Array, x_nom: Array) -> ControlStep:
        self._stalled[:] = 0
        self._accept(p0, u_nom, x_nom)
        return ControlStep(u_nom[0].copy(), StepInfo("fast_path"))

    def _qp_drones(self, bad: Array, rows: _Rows) -> Array:
        """Drones whose group (connected by pair rows within reach) holds a conflicted drone.

        Groups are independent blocks of the QP, so every other group's optimum is its rollout.
        """
        on = rows.pairs[rows.pair_on]
        if on.shape[0] == 0:
            return np.flatnonzero(bad)
        graph = sp.coo_matrix((np.ones(on.shape[0]), (on[:, 0], on[:, 1])), shape=(self.n, self.n))
        _, label = connected_components(graph, directed=False)
        return np.flatnonzero(np.isin(label, label[bad]))

    def _sub_qp(self, drones: Array, sub: _Rows, rebuilt: bool) -> MPCQP:
        """The QP over ``drones`` and the items of ``sub``, kept while both stay the same."""
        key = drones.tobytes() + sub.pairs.tobytes() + sub.labels.tobytes()
        if rebuilt or self._qp is None or key != self._qp_key:
            self._qp = MPCQP(
                drones.shape[0], self.dim, self.dt_s, self.limits, self.settings, sub.pairs, sub.singles
            )
            self._qp_key = key
        return self._qp

    # ---- pieces ---------------------------------------------------------------------------
    def _guess(self, p0: Array) -> Array:
        """Absolute guess positions (H + 1, n, d): the previous plan shifted, ending in a hold."""
        if self._plan is None:
            return np.broadcast_to(p0, (self.settings.horizon + 1,) + p0.shape)
        prev = self._plan.positions_m
        return np.concatenate([p0[None], prev[2:], prev[-1:]])

    def _candidates(self, p0: Array) -> _Candidates:
        """Pairs and (drone, obstacle) items within reach over the horizon.

        The QP keeps a candidate set chosen with one extra horizon of reach, so it lasts
        (hysteresis); it is rebuilt only when an item within reach is missing from it.
        """
        lim, st = self.limits, self.settings
        travel = (lim.v_max_mps or 0.0) * st.horizon * self.dt_s
        rebuilt, self._fresh = self._fresh, False
        pair_on: Array | None = np.zeros(self._pairs.shape[0], dtype=bool)
        if lim.d_min_m is not None:
            reach = lim.d_min_m * (lim.downwash_kappa or 1.0) + st.margin_m + 2.0 * travel
            need = pairs_within(p0, reach)
            need_codes = need[:, 0] * self.n + need[:, 1]
            pair_on = _mask_of(self._pair_codes, need_codes)
            if pair_on is None:
                self._pairs = pairs_within(p0, reach + 2.0 * travel)
                self._pair_codes, rebuilt = self._pairs[:, 0] * self.n + self._pairs[:, 1], True
                pair_on = _mask_of(self._pair_codes, need_codes)
        m = len(self.obstacles)
        ob_on: Array | None = np.zeros(self._obstacle_items.shape[0], dtype=bool)
        if m:
            dist = np.linalg.norm(p0[:, None, :] - self._ob_center[None], axis=-1)
            gap = (dist - self._ob_required).ravel()  # item code: drone * m + obstacle
            need_codes = np.flatnonzero(gap <= st.margin_m + travel)
            ob_on = _mask_of(self._ob_codes, need_codes)
            if ob_on is None:
                self._ob_codes, rebuilt = np.flatnonzero(gap <= st.margin_m + 2.0 * travel), True
                self._obstacle_items = np.column_stack(np.divmod(self._ob_codes, m))
                ob_on = _mask_of(self._ob_codes, need_codes)
        return _Candidates(self._pairs, pair_on, self._obstacle_items, ob_on, rebuilt)  # type: ignore[arg-type]

    def _separation_rows(self, p0: Array, guess: Array, cand: _Candidates) -> _Rows:
        """Closest-point rows about the guess for every candidate (see :mod:`mpcform.mpc.qp`)."""
        lim, margin = self.limits, self.settings.margin_m
        r, d = self._segs.shape[0], self.dim
        empty = (
            np.empty((0, 2), dtype=np.intp),
            np.empty((0, r, d)),
            np.empty((0, r)),
            np.empty(0, dtype=bool),
        )
        joint, singles = empty, [empty]
        if cand.pairs.shape[0] and lim.d_min_m is not None:
            i, k = cand.pairs[:, 0], cand.pairs[:, 1]
            rel = (guess[:, i] - guess[:, k]) * self._metric  # (H + 1, P, d), metric space
            coeffs = self._normals(rel) * self._metric  # (P, R, d), world coordinates
            if self.settings.coupling == "joint":
                lower = lim.d_min_m + margin - np.einsum("prd,pd->pr", coeffs, p0[i] - p0[k])
                joint = (cand.pairs, coeffs, lower, cand.pair_on)
            else:  # two per-drone rows about the guess's midpoint at each row's position step
                mid = 0.5 * (guess[:, i] + guess[:, k])[self._ends].transpose(1, 0, 2)  # (P, R, d)
                half = 0.5 * (lim.d_min_m + margin)
                for side, sign in ((i, 1.0), (k, -1.0)):
                    lower = half - np.einsum("prd,prd->pr", sign * coeffs, p0[side][:, None] - mid)
                    labels = np.column_stack([side, i + k - side])
                    singles.append((labels, sign * coeffs, lower, cand.pair_on))
        if cand.obstacles.shape[0]:
            drone, ob = cand.obstacles[:, 0], cand.obstacles[:, 1]
            center, required = self._ob_center[ob], self._ob_required[ob]
            coeffs = self._normals(guess[:, drone] - center)
            lower = required[:, None] + margin - np.einsum("ord,od->or", coeffs, p0[drone] - center)
            singles.append((np.column_stack([drone, -1 - ob]), coeffs, lower, cand.obstacle_on))
        labels, s_coeffs, s_lower, s_on = (np.concatenate(parts) for parts in zip(*singles, strict=True))
        return _Rows(*joint, labels[:, 0], labels, s_coeffs, s_lower, s_on)

    def _normals(self, rel: Array) -> Array:
        """Unit normals (m, R, d) per row: the direction to each guess segment's point closest to
        the origin (``rel`` (H + 1, m, d) are the guess's relative positions)."""
        d = self.dim
        closest = closest_on_segments(rel[:-1].reshape(-1, d), rel[1:].reshape(-1, d))
        dist = np.linalg.norm(closest, axis=1)
        normal = np.zeros_like(closest)
        normal[:, 0] = 1.0  # a coincident guess: any fixed unit vector is a valid normal
        ok = dist > 1e-9
        normal[ok] = closest[ok] / dist[ok, None]
        normal = normal.reshape(rel.shape[0] - 1, rel.shape[1], d)  # (H, m, d)
        return normal.transpose(1, 0, 2)[:, self._segs]

    def _clear_of_rows(self, p0: Array, guess: Array, x: Array) -> bool:
        """A cheap sufficient test that positions ``x`` (H, n, d) meet every separation row.

        A row's normal c is a unit vector with ``c^T g >= |closest point of its guess segment|
        >= max(|g_j|, |g_j+1|) - |g_j+1 - g_j|``, so ``c^T delta_e >= that - |delta_e - g_e|``.
        Before that per-segment bound, a per-drone one: drone i's guess stays within ``spread_i``
        of its start and its positions within ``spread_i`` of the guess, so an item whose start
        distance clears the requirement by the spreads of its drones is clear. No row is built.
        """
        margin, lim = self.settings.margin_m, self.limits
        pos = np.concatenate([p0[None], p0 + x])
        spread = _max_norm(guess - p0) + _max_norm(pos - guess)  # (n,) [m]
        tests: list[tuple[Array, Array, Array | float]] = []
        if lim.d_min_m is not None and self.n > 1:
            scaled = p0 * self._metric  # the metric only shrinks lengths: world spreads bound it
            i, k = pairs_within(scaled, lim.d_min_m + margin + 2.0 * spread.max()).T
            clearance = np.linalg.norm(scaled[i] - scaled[k], axis=1) - spread[i] - spread[k]
            near = clearance < lim.d_min_m + margin
            i, k = i[near], k[near]
            rel_g, rel_p = (guess[:, i] - guess[:, k]) * self._metric, (pos[:, i] - pos[:, k]) * self._metric
            tests.append((rel_g, rel_p, lim.d_min_m))
        if self.obstacles:
            gap = np.linalg.norm(p0[:, None] - self._ob_center, axis=-1) - self._ob_required - spread[:, None]
            i, m = np.nonzero(gap < margin)
            center = self._ob_center[m]
            tests.append((guess[:, i] - center, pos[:, i] - center, self._ob_required[m]))
        for g, delta, required in tests:
            g_norm = np.linalg.norm(g, axis=-1)
            seg = np.maximum(g_norm[:-1], g_norm[1:]) - np.linalg.norm(np.diff(g, axis=0), axis=-1)
            dev = np.linalg.norm(delta - g, axis=-1).max(axis=0, initial=0.0)
            if np.any(seg.min(axis=0, initial=np.inf) - dev < required + margin):
                return False
        return True

    def _limit_violators(self, p0: Array, u: Array, x: Array) -> Array:
        """Drones (n,) whose ``(u, x)`` miss a velocity, acceleration or geofence row of the QP."""
        lim = self.limits
        bad = np.zeros(self.n, dtype=bool)
        if lim.v_max_mps is not None:
            bad |= (u @ self._vel_normals.T > self._vel_h).any(axis=(0, 2))
        if lim.a_max_mps2 is not None:
            du = np.diff(np.concatenate([self._u_prev[None], u]), axis=0)
            bad |= (np.abs(du) > lim.a_max_mps2 * self.dt_s).any(axis=(0, 2))
        if lim.geofence_min_m is not None and lim.geofence_max_m is not None:
            m = self.settings.margin_m
            lo = np.minimum(lim.geofence_min_m + m - p0, 0.0)
            hi = np.maximum(lim.geofence_max_m - m - p0, 0.0)
            bad |= ((x < lo) | (x > hi)).any(axis=(0, 2))
        return bad

    def _row_shortfall(self, x: Array, rows: _Rows, tol: float) -> tuple[float, Array]:
        """Largest amount [m] by which positions ``x`` (H, n, d) miss an active separation row,
        and the labels (m, 2) of the items that miss by more than ``tol``."""
        xe = x[self._ends - 1]  # (R, n, d)
        worst, missed = -np.inf, [np.empty((0, 2), dtype=np.intp)]
        pair_rel = xe[:, rows.pairs[:, 0]] - xe[:, rows.pairs[:, 1]]
        parts = [
            (rows.pair_coeffs, rows.pair_lower, rows.pair_on, rows.pairs, pair_rel),
            (rows.single_coeffs, rows.single_lower, rows.single_on, rows.labels, xe[:, rows.singles]),
        ]
        for coeffs, lower, on, labels, rel in parts:
            if not on.any():
                continue
            short = np.where(on, (lower - np.einsum("mrd,rmd->mr", coeffs, rel)).max(axis=1), -np.inf)
            worst = max(worst, float(short.max()))
            missed.append(labels[short > tol])
        return worst, np.unique(np.concatenate(missed), axis=0)

    def _solve(
        self, drones: Array, p0: Array, c: Array, rows: _Rows, rebuilt: bool, u_nom: Array, x_nom: Array
    ) -> tuple[QPSolution, int]:
        """Solve the QP over ``drones``: per drone (decoupled with ``per_drone``), or set up (new
        pattern) or update the backend with the sparse QP. Also returns the number of active rows."""
        backend = self._solver
        if isinstance(backend, PerDroneQP):
            on = rows.single_on
            return backend.solve(
                p0[drones], c[:, drones], self._u_prev[drones], rows.singles[on], rows.single_coeffs[on],
                rows.single_lower[on], self._warm(p0, u_nom, x_nom)[0][:, drones]
            )  # fmt: skip
        qp = self._sub_qp(drones, rows, rebuilt)
        q = qp.cost_vector(c[:, drones])
        lower = np.concatenate([rows.pair_lower, rows.single_lower])
        on = np.concatenate([rows.pair_on, rows.single_on])
        lo, hi = qp.bounds(p0[drones], self._u_prev[drones], lower, on)
        a_data = qp.separation_values(rows.pair_coeffs, rows.single_coeffs)
        if self._backend_qp is not qp:
            a_matrix = qp.A.copy()
            a_matrix.data = a_data
            backend.setup(qp.P, q, a_matrix, lo, hi)
            self._backend_qp = qp
        else:
            backend.update(q, lo, hi, a_data)
        if backend.needs_context:
            backend.set_context(self._context(qp, drones, p0, rows))
        x0 = None
        if backend.warm_starts:
            warm = self._warm(p0, u_nom, x_nom)[:, :, drones]
            x0 = np.concatenate([warm.ravel(), np.zeros(qp.layout.n_slack)])
        sol = backend.solve(x0)
        active = 0 if sol.y is None else int(np.count_nonzero(np.abs(sol.y[qp.layout.nud :]) > 1e-6))
        return sol, active

    def _context(self, qp: MPCQP, drones: Array, p0: Array, rows: _Rows) -> QPContext:
        """What the QP over ``drones`` means, numbered locally (for ``casadi:ipopt``'s exact
        separation and ``casadi:hpipm``'s stages): the pairs and obstacle items within reach."""
        local = np.full(self.n, -1)
        local[drones] = np.arange(drones.shape[0])
        sides = rows.labels[:, 1] >= 0  # decoupled pair sides, global drone indices
        pairs = np.concatenate([rows.pairs[rows.pair_on], local[rows.labels[sides & rows.single_on]]])
        pairs = np.unique(np.sort(pairs[(pairs >= 0).all(axis=1)], axis=1), axis=0).reshape(-1, 2)
        ob = ~sides & rows.single_on
        obstacle = -1 - rows.labels[ob, 1]
        margin, none = self.settings.margin_m, not ob.any()
        return QPContext(
            drones.shape[0], self.dim, self.settings.horizon, (qp.sep_rows.start, qp.sep_rows.stop),
            p0[drones], pairs, (self.limits.d_min_m or 0.0) + margin, self._metric, rows.singles[ob],
            np.empty((0, self.dim)) if none else self._ob_center[obstacle],
            np.empty(0) if none else self._ob_required[obstacle] + margin,
        )  # fmt: skip

    def _certified(self, p0: Array, u0: Array, cand: _Candidates) -> bool:
        """Along ``p0 -> p0 + dt u0`` no pair (or obstacle) within reach gets closer than
        ``d_min`` (or its required clearance), or than it already was."""
        p1 = p0 + self.dt_s * u0
        checks = []
        if cand.pair_on.any() and self.limits.d_min_m is not None:
            i, k = cand.pairs[cand.pair_on].T
            checks.append(
                (
                    (p0[i] - p0[k]) * self._metric,
                    (p1[i] - p1[k]) * self._metric,
                    self.limits.d_min_m,
                )
            )
        if cand.obstacle_on.any():
            i, m = cand.obstacles[cand.obstacle_on].T
            checks.append((p0[i] - self._ob_center[m], p1[i] - self._ob_center[m], self._ob_required[m]))
        for a, b, required in checks:
            d_seg = np.linalg.norm(closest_on_segments(a, b), axis=1)
            if np.any(d_seg < np.minimum(required, np.linalg.norm(a, axis=1)) - CERTIFY_TOL_M):
                return False
        return True

    def _fallback(self, p0: Array, cand: _Candidates, info: StepInfo) -> ControlStep:
        """Previous plan's next input (scaled into the velocity set) if it certifies, else hold."""
        zero = np.zeros((1, self.n, self.dim))
        if self._plan is not None:
            u_plan = np.concatenate([self._plan.inputs_mps[1:], zero])
            u_plan[0] = saturate(u_plan[0], self.limits.v_max_mps)
            if self._certified(p0, u_plan[0], cand):
                self._accept(p0, u_plan, self.dt_s * np.cumsum(u_plan, axis=0))
                return ControlStep(u_plan[0].copy(), replace(info, status=info.status + "; previous plan"))
        hold = np.zeros((self.settings.horizon, self.n, self.dim))
        self._accept(p0, hold, hold)
        return ControlStep(hold[0], replace(info, status=info.status + "; hold"))

    def _accept(self, p0: Array, u: Array, x: Array) -> None:
        self._plan = Plan(u, np.concatenate([p0[None], p0 + x]))
        self._u_prev = u[0].copy()

    def _warm(self, p0: Array, u_nom: Array, x_nom: Array) -> Array:
        """Primal warm start (2, H, n, d): inputs and relative positions of the previous plan
        shifted one step (or of the rollout at the first step)."""
        if self._plan is None:
            return np.stack([u_nom, x_nom])
        prev = self._plan
        u = np.concatenate([prev.inputs_mps[1:], np.zeros((1, self.n, self.dim))])
        x = np.concatenate([prev.positions_m[2:], prev.positions_m[-1:]]) - p0
        return np.stack([u, x])


def _max_norm(v: Array) -> Array:
    """``max_e |v_e,i|`` over the first axis of ``v`` (T, n, d) -> (n,)."""
    return np.sqrt(np.einsum("tnd,tnd->tn", v, v).max(axis=0))


def _subset_rows(rows: _Rows, drones: Array, n: int, on_only: bool) -> _Rows:
    """The rows of the items within ``drones`` (only those within reach with ``on_only``), with
    drone indices renumbered 0..len(drones)-1."""
    if drones.shape[0] == n and not on_only:
        return rows
    local = np.full(n, -1)
    local[drones] = np.arange(drones.shape[0])
    keep_p = (local[rows.pairs] >= 0).all(axis=1) & (rows.pair_on | (not on_only))
    keep_s = (local[rows.singles] >= 0) & (rows.single_on | (not on_only))
    return _Rows(
        local[rows.pairs[keep_p]], rows.pair_coeffs[keep_p], rows.pair_lower[keep_p], rows.pair_on[keep_p],
        local[rows.singles[keep_s]], rows.labels[keep_s], rows.single_coeffs[keep_s],
        rows.single_lower[keep_s], rows.single_on[keep_s],
    )  # fmt: skip


def _rollout(c: Array, k: float, dt: float) -> tuple[Array, Array]:
    """Eq. 14 over the horizon in relative coordinates: ``u_j = c_j - k x_j``, ``x_{j+1} = x_j + dt u_j``."""
    u = np.empty_like(c)
    x = np.empty_like(c)
    xj = np.zeros(c.shape[1:])
    for j in range(c.shape[0]):
        u[j] = c[j] - k * xj
        xj = xj + dt * u[j]
        x[j] = xj
    return u, x


def _solver_text(solver: str | QPBackend) -> str:
    return repr(solver) if isinstance(solver, str) else f"the backend {solver.name!r}"


def _norms(v: Array) -> Array:
    return np.sqrt(np.einsum("...d,...d->...", v, v))


def _turn_about_z(v: Array, angle: Array) -> Array:
    """Rotate vectors (..., n, d) by ``angle`` (n,) [rad] about the world z axis (in-plane when d = 2)."""
    ca, sa = np.cos(angle), np.sin(angle)
    out = v.copy()
    out[..., 0] = ca * v[..., 0] - sa * v[..., 1]
    out[..., 1] = sa * v[..., 0] + ca * v[..., 1]
    return out


def _mask_of(codes: Array, need: Array) -> Array | None:
    """Mask of the sorted ``codes`` that occur in ``need`` (sorted); None if one is missing."""
    idx = np.searchsorted(codes, need)
    if idx.size and (idx[-1] >= codes.shape[0] or np.any(codes[idx] != need)):
        return None
    mask = np.zeros(codes.shape[0], dtype=bool)
    mask[idx] = True
    return mask
