"""The receding-horizon planner (controller ``mpc``): problem -> QP -> solve -> first input.

Every step: targets over the horizon and the eq. 14 rollout (:mod:`mpcform.mpc.plan`); the
fast path when the rollout meets every row (it then *is* the QP's optimum); else the candidate
items (:mod:`mpcform.mpc.candidates`), their rows linearised about the guess
(:mod:`mpcform.mpc.separation`), the tie-break (:mod:`mpcform.mpc.liveness`), and a solve of the
QP over the conflicted drones' groups: the sparse QP with a backend (:mod:`mpcform.mpc.sparse`),
or in decoupled mode each drone's block with DAQP (:mod:`mpcform.mpc.per_drone`). The command is
certified, or replaced by the safe fallback (:mod:`mpcform.mpc.certify`), and reported.

In decoupled mode the pair rows are split about the guess's midpoints, unless the rollout meets
the limit rows and the joint pair rows (and the obstacle rows) about the guess: then every pair of
the rollout stays ``d_min + margin`` apart along each segment, and the split rows are taken about
the rollout itself, which meets them exactly; so the rollout is the decoupled QP's optimum, and
the fast path (which tests the joint rows) returns the same command as a solve. A rollout that
breaks a limit row is never a linearisation point (the plan could not follow it).
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array, positive
from mpcform.control.base import Controller, ControlStep, StepInfo, feedforward_targets
from mpcform.control.laws import check_gain_dt
from mpcform.errors import ValidationError
from mpcform.mpc.candidates import CandidateSelector, qp_drones
from mpcform.mpc.certify import Certifier
from mpcform.mpc.limits import Limits, SphereObstacle
from mpcform.mpc.liveness import TieBreak
from mpcform.mpc.per_drone import PerDroneQP
from mpcform.mpc.plan import Plan, guess, rollout, warm_start
from mpcform.mpc.problem import StepQP, StepSolver
from mpcform.mpc.rows import limit_rows, violators
from mpcform.mpc.separation import Separation, SeparationRows
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.sparse import SparseSolver
from mpcform.mpc.split import SplitQP
from mpcform.reference.base import Reference
from mpcform.solvers.base import QPBackend, QPSolution, SolverOptions
from mpcform.solvers.registry import DEFAULT_SOLVER, make_backend

SLACK_REPORT_M = 1e-6  # slack above this is reported


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
        self.n, self.dim = reference.template.n, reference.template.dim
        self.obstacles = tuple(obstacles)
        _check_limits(self.dim, limits, self.obstacles, solver, settings)
        self._families = limit_rows(self.dim, dt_s, limits, settings)
        self._separation = sep = Separation(self.dim, limits, settings, self.obstacles)
        self._candidates = CandidateSelector(self.n, dt_s, limits, settings, self.obstacles)
        self._certifier = Certifier(dt_s, limits.v_max_mps, sep, limits.a_max_mps2)
        self._solver: StepSolver  # the sparse QP with a backend, or DAQP per drone
        if settings.solves_per_drone:
            self._solver = PerDroneQP(self.dim, dt_s, limits, settings, self._families)
            if settings.split_iterations:  # the pair rows' split points iterated (mpc.split)
                self._solver = SplitQP(self._solver, settings.split_iterations, settings.split_budget_s)
        else:
            st = settings
            options = SolverOptions(st.eps_abs, st.eps_rel, st.max_iter, st.time_limit_s)
            backend = solver if isinstance(solver, QPBackend) else make_backend(solver, options)
            self._solver = SparseSolver(backend, self.dim, dt_s, limits, settings, self._families, sep)
        self.solver_name = self._solver.name
        self._tie_break = TieBreak(self.n, settings.tie_break_rad, dt_s)
        self.reset(0.0, np.zeros((self.n, self.dim)))

    # ---- state ----------------------------------------------------------------------------
    def reset(self, t_s: float, positions_m: Array) -> None:
        """Forget the previous plan, the candidate set and the liveness state (a new run)."""
        self._candidates.reset()
        self._solver.reset()
        self._plan: Plan | None = None
        self._u_prev = np.zeros((self.n, self.dim))
        self._tie_break.reset()

    @property
    def plan(self) -> Plan | None:
        """The plan of the last step (None before the first)."""
        return self._plan

    # ---- one step -------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """One receding-horizon step at time ``t_s`` [s] from the measured ``positions_m`` (n, d) [m]:
        the certified first command (n, d) [m/s] (``||u_i|| <= v_max``, no pair or obstacle closer
        than its limit along the first segment, or than it already was) and the step's information
        (mode ``fast_path`` | ``qp`` | ``fallback``, solver status, slack and the pairs that needed it,
        liveness events). With none of the QP's rows active the command is exactly eq. 14."""
        p0 = self._check_positions(positions_m)
        st, sep = self.settings, self._separation
        k, dt, horizon = st.gain_per_s, self.dt_s, st.horizon
        targets, ff = feedforward_targets(self.reference, t_s, dt, horizon, st.feedforward)
        c = ff + k * (targets[:-1] - p0)  # u_j = c_j - k x_j is the eq. 14 rollout
        u_nom, x_nom = rollout(c, k, dt)
        about = guess(self._plan, p0, horizon)
        off_limits = violators(self._families, p0, self._u_prev, u_nom, x_nom)
        if st.fast_path and not off_limits.any() and sep.clear(p0, about, x_nom):
            return self._fast_path(p0, u_nom, x_nom)
        cand = self._candidates.select(p0)
        grouped = st.fast_path and st.grouping
        if grouped or st.solves_per_drone:  # no fixed pattern: rows only within reach
            cand = cand.within_reach()
        rows = sep.rows(p0, about, cand)
        values: Array | None = sep.single_values(x_nom, rows)  # the rows at the rollout
        if st.coupling == "decoupled" and not off_limits.any() and sep.meets_joint(x_nom, rows, values):
            # the rollout meets the limits and the joint rows: the decoupled rows are split about
            # the rollout itself, which meets them, so it is the optimum (see the module docstring)
            if st.fast_path:
                return self._fast_path(p0, u_nom, x_nom)
            about = np.concatenate([p0[None], p0 + x_nom])
            rows, values = sep.rows(p0, about, cand), None
        conflicted = sep.conflicted(x_nom, rows, values)
        if st.fast_path and not (off_limits | conflicted).any():
            return self._fast_path(p0, u_nom, x_nom)
        blocked = sep.blocked_targets(targets[0]) if conflicted.any() else None
        c = self._tie_break.turn(c, conflicted, p0, targets[0] - p0, self._plan is not None, blocked)
        bad = off_limits | conflicted
        linked = rows.pairs[rows.pair_on]
        if st.split_iterations:  # a pair's split moves both its drones: solved as one group
            linked = rows.labels[(rows.labels[:, 1] >= 0) & rows.single_on]
        drones = qp_drones(bad, linked) if grouped else np.arange(self.n)
        sub = rows.subset(drones, self.n, on_only=grouped)  # grouped: the pattern follows the groups
        warm = warm_start(self._plan, p0, u_nom, x_nom)[:, :, drones] if self._solver.warm_starts else None
        qp = StepQP(self.n, drones, p0[drones], c[:, drones], self._u_prev[drones], sub, cand.rebuilt, warm)
        sol, active = self._solver.solve(qp)
        status, solved = sol.status, None
        inside_m, inside = sep.start_shortfall(p0, rows)  # items that start too close
        if sol.success and sol.x is not None:
            u, x = self._merge(drones, sol.x, u_nom, x_nom)
            u0 = self._certifier.certify(p0, u[0], cand)
            if u0 is not None:
                self._accept(p0, u, x)
                info = self._qp_info(sol, sol.x, active, drones, x, rows, inside_m, inside)
                return ControlStep(u0, info)
            status, solved = status + "; command failed certification", u[0]
        u, x, note = self._certifier.fallback(self._plan, p0, cand, horizon, solved, self._u_prev)
        self._accept(p0, u, x)
        info = StepInfo("fallback", status=f"{status}; {note}", iterations=sol.iterations,
                        solve_time_s=sol.solve_time_s, max_slack_m=inside_m,
                        slack_pairs=_pairs_of(inside), **self._liveness())  # fmt: skip
        return ControlStep(u[0].copy(), info)

    def _liveness(self) -> dict[str, int]:
        """The tie-break's events of this step (StepInfo fields)."""
        tb = self._tie_break
        return {"stalled": tb.new_stalls, "resolving": tb.resolving, "resolved": tb.resolved}

    def _fast_path(self, p0: Array, u_nom: Array, x_nom: Array) -> ControlStep:
        self._tie_break.clear()
        self._accept(p0, u_nom, x_nom)
        return ControlStep(u_nom[0].copy(), StepInfo("fast_path", resolved=self._tie_break.resolved))

    def _merge(self, drones: Array, z: Array, u_nom: Array, x_nom: Array) -> tuple[Array, Array]:
        """Inputs and relative positions (H, n, d): the solution ``z``'s for ``drones``, the
        rollout's for the others."""
        horizon, m = self.settings.horizon, drones.shape[0]
        nud = horizon * m * self.dim
        u, x = u_nom.copy(), x_nom.copy()
        u[:, drones] = z[:nud].reshape(horizon, m, self.dim)
        x[:, drones] = z[nud : 2 * nud].reshape(horizon, m, self.dim)
        return u, x

    def _qp_info(
        self, sol: QPSolution, z: Array, active: int, drones: Array, x: Array, rows: SeparationRows,
        inside_m: float, inside: Array,
    ) -> StepInfo:
        """What a certified solve ``z`` reports: its solver figures and the slack it needed (the
        items whose rows positions ``x`` (H, n, d) miss, and the items ``inside`` that start
        ``inside_m`` inside their required distance)."""
        nud = self.settings.horizon * drones.shape[0] * self.dim
        slack = z[2 * nud :]
        shortfall, missed = inside_m, inside
        if slack.max(initial=0.0) > SLACK_REPORT_M / 2:
            planned, missed = self._separation.shortfall(x, rows, SLACK_REPORT_M)
            shortfall, missed = max(shortfall, planned), np.concatenate([inside, missed])
        return StepInfo(
            "qp", status=sol.status, iterations=sol.iterations, solve_time_s=sol.solve_time_s,
            active_rows=active, max_slack_m=max(shortfall, 0.0), slack_pairs=_pairs_of(missed),
            qp_drones=int(drones.shape[0]), **self._liveness(),
        )  # fmt: skip

    def _accept(self, p0: Array, u: Array, x: Array) -> None:
        self._plan = Plan.from_relative(p0, u, x)
        self._u_prev = u[0].copy()


def _pairs_of(labels: Array) -> tuple[tuple[int, int], ...]:
    """Item labels (m, 2) as sorted unique tuples."""
    return tuple(sorted({(int(a), int(b)) for a, b in labels}))


def _check_limits(
    dim: int,
    limits: Limits,
    obstacles: tuple[SphereObstacle, ...],
    solver: str | QPBackend,
    settings: MPCSettings,
) -> None:
    """The limits, obstacles and solver fit a ``dim``-dimensional formation and each other."""
    for idx, ob in enumerate(obstacles):
        if ob.center_m.shape != (dim,):
            got = ob.center_m.tolist()
            raise ValidationError(f"obstacles[{idx}].center", f"expected {dim} numbers, got {got}")
    if (limits.d_min_m is not None or obstacles) and limits.v_max_mps is None:
        raise ValidationError(
            "limits.v_max",
            "the MPC needs v_max when d_min or obstacles are set (it bounds how far drones can reach)",
        )
    if limits.downwash_kappa is not None and dim != 3:
        raise ValidationError("limits.downwash", "downwash separation needs a spatial (dim = 3) formation")
    if limits.geofence_min_m is not None and limits.geofence_min_m.shape != (dim,):
        raise ValidationError(
            "limits.geofence_min", f"expected {dim} numbers, got {limits.geofence_min_m.tolist()}"
        )
    if settings.solves_per_drone and solver != DEFAULT_SOLVER:  # it would be ignored
        text = repr(solver) if isinstance(solver, str) else f"the backend {solver.name!r}"
        raise ValidationError("controller.solver", f"{text} solves the sparse QP, but decoupled mode "
                              "solves each drone's QP with DAQP here; set controller.per_drone = false "
                              "to use it")  # fmt: skip
