"""The receding-horizon planner (controller ``mpc``): problem -> QP -> solve -> first input.

Every step: targets over the horizon, the eq. 14 rollout, separation items culled with a k-d
tree, their rows linearised about the guess (the previous plan shifted one step, ending in a
hold; at the first step every drone holding), then either the fast path (the rollout meets every
row, so it *is* the QP's optimum) or a solve. The command returned is certified: inside the
ball ``||u_i|| <= v_max`` and, along the first segment, no pair closer than ``d_min`` (or than it
already was). A failed or uncertifiable solve falls back to the previous plan's next input or a
hold, and is reported; the loop never raises or returns NaN for a solver's failure.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, positive
from mpcform.controllers import ControlStep, Controller, StepInfo, feedforward_targets
from mpcform.errors import ValidationError
from mpcform.geometry import closest_on_segments, pairs_within
from mpcform.laws import check_gain_dt, saturate
from mpcform.limits import Limits, SphereObstacle
from mpcform.mpc_qp import MPCQP, row_segments
from mpcform.mpc_settings import MPCSettings
from mpcform.reference import Reference
from mpcform.solvers import DEFAULT_SOLVER, SolverOptions, make_backend

CERTIFY_TOL_M = 1e-7  # separation certification tolerance [m]
SLACK_REPORT_M = 1e-6  # slack above this is reported


@dataclass(frozen=True)
class Plan:
    """Predicted inputs (H, n, d) [m/s] and positions (H + 1, n, d) [m], row 0 the start."""

    inputs_mps: Array
    positions_m: Array


@dataclass(frozen=True)
class _Items:
    """Separation items of one step: pairs and (drone, obstacle) with their row data."""

    coeffs: Array  # (m, R, d) row normals (metric applied)
    lower: Array  # (m, R) row lower bounds on c^T (x_i - x_k) (+ slack)
    active: Array  # (m,) bool


class MPCPlanner(Controller):
    """Receding-horizon QP tracking a formation reference under velocity and separation limits.

    With none of its rows active the first input is exactly eq. 14 (``feedforward + k (p* - p)``).
    ``solver`` names a backend (``mpcform solvers``); the default is a persistent PIQP object.
    """

    name = "mpc"

    def __init__(
        self,
        reference: Reference,
        dt_s: float,
        limits: Limits | None = None,
        settings: MPCSettings | None = None,
        obstacles: tuple[SphereObstacle, ...] = (),
        solver: str = DEFAULT_SOLVER,
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
                raise ValidationError(f"obstacles[{idx}].center", f"expected {self.dim} numbers, got {ob.center_m.tolist()}")
        needs_reach = limits.d_min_m is not None or self.obstacles
        if needs_reach and limits.v_max_mps is None:
            raise ValidationError("limits.v_max", "the MPC needs v_max when d_min or obstacles are set (it bounds how far drones can reach)")
        if limits.downwash_kappa is not None and self.dim != 3:
            raise ValidationError("limits.downwash", "downwash separation needs a spatial (dim = 3) formation")
        if limits.geofence_min_m is not None and limits.geofence_min_m.shape != (self.dim,):
            raise ValidationError("limits.geofence_min", f"expected {self.dim} numbers, got {limits.geofence_min_m.tolist()}")
        self.solver_name = solver
        self._backend = make_backend(
            solver, SolverOptions(settings.eps_abs, settings.eps_rel, settings.max_iter, settings.time_limit_s)
        )
        metric = np.ones(self.dim)
        if limits.downwash_kappa is not None:
            metric[2] = 1.0 / limits.downwash_kappa
        self._metric = metric
        self._segs = row_segments(settings.horizon)
        if self.obstacles:
            self._ob_center = np.array([o.center_m for o in self.obstacles])
            half = 0.5 * (limits.d_min_m or 0.0)
            self._ob_required = np.array(
                [o.radius_m + (half if o.clearance_m is None else o.clearance_m) for o in self.obstacles]
            )
        self.reset(0.0, np.zeros((self.n, self.dim)))

    # ---- state ----------------------------------------------------------------------------
    def reset(self, t_s: float, positions_m: Array) -> None:
        self._qp: MPCQP | None = None
        self._backend_qp: MPCQP | None = None
        self._pair_codes = np.empty(0, dtype=np.intp)
        self._ob_codes = np.empty(0, dtype=np.intp)
        self._plan: Plan | None = None
        self._z: Array | None = None
        self._u_prev = np.zeros((self.n, self.dim))

    @property
    def plan(self) -> Plan | None:
        """The plan of the last step (None before the first)."""
        return self._plan

    # ---- one step -------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        p0 = self._check_positions(positions_m)
        st, lim = self.settings, self.limits
        k, dt, horizon = st.gain_per_s, self.dt_s, st.horizon
        targets, ff = feedforward_targets(self.reference, t_s, dt, horizon, st.feedforward)
        c = ff + k * (targets[:-1] - p0)  # u_j = c_j - k x_j is the eq. 14 rollout
        u_nom, x_nom = _rollout(c, k, dt)
        guess = self._guess(p0)
        pairs, obs, rebuilt = self._candidates(p0)
        qp = self._qp
        if qp is None or rebuilt:
            qp = self._qp = MPCQP(self.n, self.dim, dt, lim, st, pairs, obs)
        pair_rows = self._pair_rows(p0, guess, pairs)
        ob_rows = self._obstacle_rows(p0, guess, obs)
        if st.fast_path and self._meets_rows(qp, p0, u_nom, x_nom, pairs, obs, pair_rows, ob_rows):
            self._accept(p0, u_nom, x_nom, z=None)
            return ControlStep(u_nom[0].copy(), StepInfo("fast_path"))
        lower = np.concatenate([pair_rows.lower, ob_rows.lower])
        active = np.concatenate([pair_rows.active, ob_rows.active])
        q = qp.cost_vector(c)
        lo, hi = qp.bounds(p0, self._u_prev, lower, active)
        a_data = qp.separation_values(pair_rows.coeffs, ob_rows.coeffs)
        if self._backend_qp is not qp:
            a_matrix = qp.A.copy()
            a_matrix.data = a_data
            self._backend.setup(qp.P, q, a_matrix, lo, hi)
            self._backend_qp = qp
        else:
            self._backend.update(q, lo, hi, a_data)
        sol = self._backend.solve(self._warm(p0, qp, u_nom, x_nom, rebuilt))
        lay = qp.layout
        if sol.success and sol.x is not None:
            u = sol.x[: lay.nud].reshape(horizon, self.n, self.dim)
            x = sol.x[lay.nud : 2 * lay.nud].reshape(horizon, self.n, self.dim)
            slack = sol.x[2 * lay.nud :]
            u0 = saturate(u[0], lim.v_max_mps)
            if self._certified(p0, u0, pairs, obs, pair_rows.active, ob_rows.active):
                self._accept(p0, u, x, z=sol.x)
                n_eq = lay.nud
                info = StepInfo(
                    "qp", status=sol.status, iterations=sol.iterations, solve_time_s=sol.solve_time_s,
                    active_rows=int(np.count_nonzero(np.abs(sol.y[n_eq:]) > 1e-6)) if sol.y is not None else 0,
                    max_slack_m=float(slack.max(initial=0.0)),
                    slack_pairs=self._slack_items(slack, pairs, obs),
                )  # fmt: skip
                return ControlStep(u0, info)
            status = f"{sol.status}; command failed certification"
        else:
            status = sol.status
        return self._fallback(p0, pairs, obs, pair_rows.active, ob_rows.active, status, sol.iterations, sol.solve_time_s)

    # ---- pieces ---------------------------------------------------------------------------
    def _guess(self, p0: Array) -> Array:
        """Absolute guess positions (H + 1, n, d): the previous plan shifted, ending in a hold."""
        if self._plan is None:
            return np.broadcast_to(p0, (self.settings.horizon + 1,) + p0.shape)
        prev = self._plan.positions_m
        return np.concatenate([p0[None], prev[2:], prev[-1:]])

    def _candidates(self, p0: Array) -> tuple[Array, Array, bool]:
        """Candidate pairs (P, 2) and (drone, obstacle) items (O, 2); True when the pattern changed.

        Items within reach this step must be candidates; a new set is chosen with one extra
        horizon of reach so that it lasts (hysteresis), and the QP is rebuilt only then.
        """
        lim, st = self.limits, self.settings
        travel = (lim.v_max_mps or 0.0) * st.horizon * self.dt_s
        rebuilt = self._qp is None
        pairs = _decode(self._pair_codes, self.n)
        if lim.d_min_m is not None:
            reach = lim.d_min_m * (lim.downwash_kappa or 1.0) + st.margin_m + 2.0 * travel
            need = _codes(pairs_within(p0, reach), self.n)
            if not np.isin(need, self._pair_codes).all():
                self._pair_codes = _codes(pairs_within(p0, reach + 2.0 * travel), self.n)
                pairs, rebuilt = _decode(self._pair_codes, self.n), True
        obs = _decode(self._ob_codes, max(len(self.obstacles), 1))
        if self.obstacles:
            gap = np.linalg.norm(p0[:, None, :] - self._ob_center[None], axis=-1) - self._ob_required
            near = lambda r: np.flatnonzero((gap <= r).ravel())  # noqa: E731 - drone * m + obstacle
            need = near(st.margin_m + travel)
            if not np.isin(need, self._ob_codes).all():
                self._ob_codes = near(st.margin_m + 2.0 * travel)
                obs, rebuilt = _decode(self._ob_codes, len(self.obstacles)), True
        return pairs, obs, rebuilt

    def _pair_rows(self, p0: Array, guess: Array, pairs: Array) -> _Items:
        lim = self.limits
        if pairs.shape[0] == 0 or lim.d_min_m is None:
            return _empty_items(self._segs.shape[0], self.dim)
        i, k = pairs[:, 0], pairs[:, 1]
        rel = (guess[:, i] - guess[:, k]) * self._metric  # (H + 1, P, d) in the metric's space
        start_rel = (p0[i] - p0[k]) * self._metric
        travel = lim.v_max_mps * self.settings.horizon * self.dt_s  # type: ignore[operator]
        active = np.linalg.norm(start_rel, axis=1) <= lim.d_min_m + self.settings.margin_m + 2.0 * travel
        return self._rows(rel, start_rel, np.full(pairs.shape[0], lim.d_min_m), active, self._metric)

    def _obstacle_rows(self, p0: Array, guess: Array, obs: Array) -> _Items:
        if obs.shape[0] == 0:
            return _empty_items(self._segs.shape[0], self.dim)
        i, m = obs[:, 0], obs[:, 1]
        center = self._ob_center[m]
        rel = guess[:, i] - center
        start_rel = p0[i] - center
        travel = self.limits.v_max_mps * self.settings.horizon * self.dt_s  # type: ignore[operator]
        required = self._ob_required[m]
        active = np.linalg.norm(start_rel, axis=1) - required <= self.settings.margin_m + travel
        return self._rows(rel, start_rel, required, active, np.ones(self.dim))

    def _rows(self, rel: Array, start_rel: Array, required: Array, active: Array, metric: Array) -> _Items:
        """Closest-point normals per guess segment, applied at both segment ends."""
        st = self.settings
        closest = closest_on_segments(rel[:-1].reshape(-1, self.dim), rel[1:].reshape(-1, self.dim))
        dist = np.linalg.norm(closest, axis=1)
        fallback = np.zeros_like(closest)
        fallback[:, 0] = 1.0  # coincident guess: any fixed unit vector is a valid normal
        normal = np.where(dist[:, None] > 1e-9, closest / np.maximum(dist, 1e-300)[:, None], fallback)
        normal = normal.reshape(rel.shape[0] - 1, rel.shape[1], self.dim)  # (H, m, d)
        if st.tie_break_rad > 0:
            slack_ok = dist.reshape(normal.shape[:2]) * np.cos(st.tie_break_rad) >= required + st.margin_m
            normal = np.where(slack_ok[..., None], _turn_about_z(normal, st.tie_break_rad), normal)
        coeffs = normal.transpose(1, 0, 2)[:, self._segs] * metric  # (m, R, d) on world coordinates
        lower = required[:, None] + st.margin_m - np.einsum("mrd,md->mr", coeffs, start_rel / metric)
        return _Items(coeffs, lower, active)

    def _meets_rows(
        self, qp: MPCQP, p0: Array, u: Array, x: Array, pairs: Array, obs: Array, pr: _Items, orows: _Items
    ) -> bool:
        lim = self.limits
        if lim.v_max_mps is not None and (u @ qp.vel_normals.T).max() > qp.vel_h:
            return False
        if lim.a_max_mps2 is not None:
            du = np.diff(np.concatenate([self._u_prev[None], u]), axis=0)
            if np.abs(du).max() > lim.a_max_mps2 * self.dt_s:
                return False
        if lim.geofence_min_m is not None and lim.geofence_max_m is not None:
            p = p0 + x
            m = self.settings.margin_m
            lo = np.minimum(lim.geofence_min_m + m, p0)
            hi = np.maximum(lim.geofence_max_m - m, p0)
            if np.any(p < lo) or np.any(p > hi):
                return False
        ends = qp.ends - 1
        if pr.active.any():
            rel = x[ends][:, pairs[:, 0]] - x[ends][:, pairs[:, 1]]  # (R, P, d)
            val = np.einsum("mrd,rmd->mr", pr.coeffs, rel)
            if np.any(val[pr.active] < pr.lower[pr.active]):
                return False
        if orows.active.any():
            val = np.einsum("mrd,rmd->mr", orows.coeffs, x[ends][:, obs[:, 0]])
            if np.any(val[orows.active] < orows.lower[orows.active]):
                return False
        return True

    def _certified(self, p0: Array, u0: Array, pairs: Array, obs: Array, pair_on: Array, ob_on: Array) -> bool:
        """Along ``p0 -> p0 + dt u0`` no active pair gets closer than min(d_min, its start distance)."""
        p1 = p0 + self.dt_s * u0
        if pair_on.any() and self.limits.d_min_m is not None:
            i, k = pairs[pair_on, 0], pairs[pair_on, 1]
            a, b = (p0[i] - p0[k]) * self._metric, (p1[i] - p1[k]) * self._metric
            d_seg = np.linalg.norm(closest_on_segments(a, b), axis=1)
            if np.any(d_seg < np.minimum(self.limits.d_min_m, np.linalg.norm(a, axis=1)) - CERTIFY_TOL_M):
                return False
        if ob_on.any():
            i, m = obs[ob_on, 0], obs[ob_on, 1]
            center = self._ob_center[m]
            a, b = p0[i] - center, p1[i] - center
            d_seg = np.linalg.norm(closest_on_segments(a, b), axis=1)
            if np.any(d_seg < np.minimum(self._ob_required[m], np.linalg.norm(a, axis=1)) - CERTIFY_TOL_M):
                return False
        return True

    def _fallback(
        self, p0: Array, pairs: Array, obs: Array, pair_on: Array, ob_on: Array, status: str, iters: int, time_s: float
    ) -> ControlStep:
        """Previous plan's next input (scaled into the velocity set) if it certifies, else hold."""
        if self._plan is not None:
            prev = self._plan
            u_next = saturate(prev.inputs_mps[min(1, prev.inputs_mps.shape[0] - 1)], self.limits.v_max_mps)
            if self._certified(p0, u_next, pairs, obs, pair_on, ob_on):
                u_plan = np.concatenate([prev.inputs_mps[1:], np.zeros((1, self.n, self.dim))])
                u_plan[0] = u_next
                self._accept(p0, u_plan, self.dt_s * np.cumsum(u_plan, axis=0), z=None)
                return ControlStep(u_next, StepInfo("fallback", status=f"{status}; previous plan", iterations=iters, solve_time_s=time_s))
        hold = np.zeros((self.settings.horizon, self.n, self.dim))
        self._accept(p0, hold, hold, z=None)
        return ControlStep(hold[0], StepInfo("fallback", status=f"{status}; hold", iterations=iters, solve_time_s=time_s))

    def _accept(self, p0: Array, u: Array, x: Array, z: Array | None) -> None:
        self._plan = Plan(u, np.concatenate([p0[None], p0 + x]))
        self._u_prev = u[0].copy()
        self._z = z

    def _warm(self, p0: Array, qp: MPCQP, u_nom: Array, x_nom: Array, rebuilt: bool) -> Array:
        """Primal warm start: the previous plan shifted one step (or the rollout), zero slack."""
        lay = qp.layout
        z = np.zeros(lay.n_var)
        if self._plan is None:
            u, x = u_nom, x_nom
        else:
            prev = self._plan
            u = np.concatenate([prev.inputs_mps[1:], np.zeros((1, self.n, self.dim))])
            pos = np.concatenate([prev.positions_m[2:], prev.positions_m[-1:]])
            x = pos - p0
        z[: lay.nud] = u.ravel()
        z[lay.nud : 2 * lay.nud] = x.ravel()
        return z

    def _slack_items(self, slack: Array, pairs: Array, obs: Array) -> tuple[tuple[int, int], ...]:
        big = np.flatnonzero(slack > SLACK_REPORT_M)
        out = []
        for s in big:
            if s < pairs.shape[0]:
                out.append((int(pairs[s, 0]), int(pairs[s, 1])))
            else:
                drone, ob = obs[s - pairs.shape[0]]
                out.append((int(drone), -1 - int(ob)))
        return tuple(out)


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


def _turn_about_z(v: Array, angle: float) -> Array:
    """Rotate vectors (..., d) by ``angle`` about the world z axis (in-plane when d = 2)."""
    ca, sa = np.cos(angle), np.sin(angle)
    out = v.copy()
    out[..., 0] = ca * v[..., 0] - sa * v[..., 1]
    out[..., 1] = sa * v[..., 0] + ca * v[..., 1]
    return out


def _codes(pairs: Array, n: int) -> Array:
    return np.sort(pairs[:, 0] * n + pairs[:, 1])


def _decode(codes: Array, n: int) -> Array:
    return np.column_stack([codes // n, codes % n]).astype(np.intp)


def _empty_items(rows: int, dim: int) -> _Items:
    return _Items(np.empty((0, rows, dim)), np.empty((0, rows)), np.empty(0, dtype=bool))
