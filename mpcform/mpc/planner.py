"""The receding-horizon planner (controller ``mpc``): problem -> QP -> solve -> first input.

Every step: targets over the horizon and the eq. 14 rollout (:mod:`mpcform.mpc.plan`); the
fast path when the rollout meets every row (it then *is* the QP's optimum); else the candidate
items (:mod:`mpcform.mpc.constraints.candidates`), their rows linearised about the guess
(:mod:`mpcform.mpc.constraints.separation`), the tie-break (:mod:`mpcform.mpc.liveness`), and a solve of the
QP over the conflicted drones' groups: the sparse QP with a backend (:mod:`mpcform.mpc.solve.sparse`),
or in decoupled mode each drone's block with DAQP (:mod:`mpcform.mpc.solve.per_drone`). The command is
certified, or replaced by the safe fallback (:mod:`mpcform.mpc.safety.certify`), and reported.

In decoupled mode the pair rows are split about the guess's midpoints, unless the rollout meets
the limit rows and the joint pair rows (and the obstacle rows) about the guess: then every pair of
the rollout stays ``d_min + margin`` apart along each segment, and the split rows are taken about
the rollout itself, which meets them exactly; so the rollout is the decoupled QP's optimum, and
the fast path (which tests the joint rows) returns the same command as a solve. A rollout that
breaks a limit row is never a linearisation point (the plan could not follow it).

With a velocity loop (``loop``, :mod:`mpcform.mpc.velocity_loop`: a linear plant's, or the quadrotor's
hover linearisation) every separation test
is on where the loop takes the drones: the rows (the forced response in the QP, the free one in
their bounds), the rollout's tests, the guess (the true path of the shifted plan) and the
certification (the interval's true chord). The cost, and so eq. 14, stay on the single
integrator; the tie-break turns only drones whose single-integrator rollout conflicts (an
encounter), not a drone whose own overshoot does (the QP brakes it). The loop state is run on
the commands sent, from rest, plus the last interval's velocity offset. Every item's first row is
then hard, lowered at most to what braking or the previous plan reaches: the first interval is
mostly the loop's free response, and a slack there would let a drone approach one partner while
another forces it.

With ``a_max`` every plan ends in its braking tail (:mod:`mpcform.mpc.constraints.braking`): the separation
and geofence rows also hold at the stop point, so the previous plan's tail stays a feasible,
certified fallback (:mod:`mpcform.mpc.prediction` gives the positions the rows are written on).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from mpcform._validate import Array, positive
from mpcform.control.base import Controller, ControlStep, feedforward_targets
from mpcform.control.laws import check_gain_dt
from mpcform.errors import ValidationError
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.candidates import CandidateSelector, qp_drones
from mpcform.mpc.constraints.limits import admitted, limit_rows, violators
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.liveness import TieBreak
from mpcform.mpc.plan import Plan, guess, merge, rollout, warm_start
from mpcform.mpc.prediction import Prediction
from mpcform.mpc.safety.certify import Certifier
from mpcform.mpc.safety.premise import GrowthPremise
from mpcform.mpc.safety.survivors import Survivors, lost_spheres, split_lost
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.factory import build_step_solvers
from mpcform.mpc.solve.problem import StepQP
from mpcform.mpc.solve.split import SplitQP
from mpcform.mpc.step_info import FAST_PATH, MPCStepInfo, solve_info
from mpcform.mpc.strategy import with_backend
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.reference.base import Reference
from mpcform.reference.subset import SubsetReference
from mpcform.solvers.base import QPBackend
from mpcform.world.limits import Limits, planning_limits, tightened
from mpcform.world.obstacles import Obstacle, resolve_clearances
from mpcform.world.shapes.shape_set import ShapeSet

SLACK_REPORT_M = 1e-6  # slack above this is reported
DEADLINE_RESERVE = 0.25
"""Share of ``step_budget_s`` no optional solver work is planned into: it is kept for what follows
the solve and for the machine's jitter (the scheduler, the garbage collector, a plant's process)."""


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
        obstacles: tuple[Obstacle, ...] = (),
        solver: str | QPBackend | None = None,
        loop: VelocityLoop | None = None,
    ) -> None:
        self.reference, self.dt_s = reference, positive("simulation.dt", dt_s)
        limits = planning_limits(limits or Limits())  # a_max: the platform's default
        settings = settings or MPCSettings()
        if solver is not None:  # the sparse strategy's backend replaced (a per-drone one refuses)
            settings = replace(settings, solve=with_backend(settings.strategy, solver, "controller.solver"))
        self.settings, self._solver_given = settings, solver
        check_gain_dt(settings.gain_per_s, dt_s)
        self.n, self.dim = reference.template.n, reference.template.dim
        obstacles = resolve_clearances(tuple(obstacles), limits.d_min_m)  # unset: d_min / 2
        limits, obstacles = tightened(limits, obstacles, 0.0, None)  # the tracking allowance, if any
        self.limits, self.obstacles = limits, obstacles
        _check_limits(self.dim, limits, self.obstacles)
        shapes = ShapeSet(self.obstacles, self.dim)  # every consumer asks these
        self.loop = _check_loop(loop, self.dim, settings)
        self._families = limit_rows(self.dim, dt_s, limits, settings, self.loop)
        self.braking = braking = Braking.of(dt_s, limits, settings.braking)  # the plans' terminal condition
        sep = Separation(self.dim, limits, settings, shapes, braking, self.loop, dt_s)
        self._separation = sep
        self._predict = predict = Prediction(dt_s, settings.horizon, self.loop, braking, sep.tail)
        self._premise = GrowthPremise.of(sep.growth, limits.tube_growth_m, predict)  # checked in wind
        grown = 0.0 if sep.growth is None else float(sep.growth[-1])  # the rows' largest growth
        self._candidates = CandidateSelector(
            self.n, dt_s, limits, settings, shapes, predict.speed_gain, predict.tail_s, grown
        )
        scale = limits.speed_scale(self.dim)  # with v_max_z: the velocity set's spheroid
        self._certifier = Certifier(dt_s, limits.v_max_mps, sep, limits.a_max_mps2, braking, scale)
        self._loop_state: Array  # the velocity loop's state (n, d, s), set by reset
        if self.loop is not None:  # certify where the loop takes the drones in the interval
            loop = self.loop
            self._certifier.drift = lambda u0: loop.first(self._loop_state, u0)
        # the sparse QP with a backend, or each drone's QP; the split rounds while a drone is stalled
        instance = solver if isinstance(solver, QPBackend) else None
        self._solver, self._stalled_solver = build_step_solvers(
            settings, self.dim, dt_s, limits, self._families, sep, loop, instance
        )
        self._splits = isinstance(self._solver, SplitQP)  # a pair's split moves both its drones
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
        # drones at rest (no states without a loop); where the loop takes them by the next step
        self._loop_state = np.zeros((self.n, self.dim, 0)) if self.loop is None else self.loop.rest(self.n)
        self._predicted: Array | None = None
        self._expected: Array | None = None  # in wind, where the last plan takes the drones

    @property
    def plan(self) -> Plan | None:
        """The plan of the last step (None before the first)."""
        return self._plan

    def lose(self, drones: Array, positions_m: Array) -> Controller:
        """Stop planning for ``drones`` (:mod:`mpcform.mpc.safety.survivors`): the planner of the others,
        which keep ``d_min`` from where the lost drones are (``positions_m`` (n, d)) and go on
        from this planner's plan."""
        lost, keep = split_lost(drones, self.n)
        if lost.size == 0 or keep.size == 0:
            return self if lost.size == 0 else Survivors(self, lost, None, len(self.obstacles))
        spheres = lost_spheres(self._check_positions(positions_m)[lost], self.limits.d_min_m)
        ref, obstacles = SubsetReference(self.reference, keep), self.obstacles + spheres
        inner = MPCPlanner(
            ref, self.dt_s, self.limits, self.settings, obstacles, self._solver_given, self.loop
        )
        inner._u_prev, inner._loop_state = self._u_prev[keep], self._loop_state[keep]
        inner._predicted = None if self._predicted is None else self._predicted[keep]
        inner._expected = None if self._expected is None else self._expected[:, keep]
        if self._plan is not None:
            inner._plan = Plan(self._plan.inputs_mps[:, keep], self._plan.positions_m[:, keep])
        return Survivors(self, lost, inner, len(self.obstacles))

    # ---- one step -------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """One receding-horizon step at time ``t_s`` [s] from the measured ``positions_m`` (n, d) [m]:
        the certified first command (n, d) [m/s] (``||u_i|| <= v_max``, no pair or obstacle closer
        than its limit along the first segment, or than it already was) and the step's information
        (mode ``fast_path`` | ``qp`` | ``fallback``, solver status, slack and the pairs that needed it,
        liveness events). With none of the QP's rows active the command is exactly eq. 14."""
        p0 = self._check_positions(positions_m)
        deadline = None if (b := self.settings.step_budget_s) is None else time.perf_counter() + b
        if self.loop is None:
            return ControlStep(*self._step(t_s, p0, deadline))
        if self._predicted is not None:  # the velocity offset of the last interval
            self._loop_state = self.loop.observe(self._loop_state, p0 - self._predicted)
        u0, info = self._step(t_s, p0, deadline)
        if self._premise is not None and self._plan is not None:
            info, self._expected = self._premise.record(info, self._moved_m, p0, self._loop_state, self._plan)
        self._predicted = p0 + self.dt_s * u0 + self.loop.first(self._loop_state, u0)
        self._loop_state = self.loop.advance(self._loop_state, u0)
        return ControlStep(u0, info)

    def _step(self, t_s: float, p0: Array, deadline: float | None) -> tuple[Array, MPCStepInfo]:
        """:meth:`step` from ``p0``, due at ``time.perf_counter() == deadline`` (None: no deadline):
        the command and the step's record."""
        st, sep = self.settings, self._separation
        k, dt, horizon = st.gain_per_s, self.dt_s, st.horizon
        targets, ff = feedforward_targets(self.reference, t_s, dt, horizon, st.feedforward)
        c = ff + k * (targets[:-1] - p0)  # u_j = c_j - k x_j is the eq. 14 rollout
        u_nom, x_nom = rollout(c, k, dt)
        x_true = self._predict.points(self._loop_state, u_nom, x_nom)  # where the rollout takes the drones
        nominal = Plan.from_relative(p0, u_nom, x_nom)  # the fast path's plan
        true_path = np.concatenate([p0[None], p0 + x_true])
        about = self._predict.guess(self._plan, p0, self._loop_state)
        off_limits = violators(self._families, p0, self._u_prev, u_nom, x_true)
        growing = sep.growing(targets[0])  # each drone's share of the rows' growth in wind
        self._moved_m = None if self._premise is None else self._premise.moved(about, self._expected, growing)
        if st.fast_path and not off_limits.any() and sep.clear(about, true_path, growing):
            return self._fast_path(nominal)
        cand = self._candidates.select(p0)
        grouped = st.fast_path and st.grouping
        if grouped or st.solves_per_drone:  # no fixed pattern: rows only within reach
            cand = cand.within_reach()
        stops = true_path[-1] if self.braking is not None and st.coupling == "decoupled" else None
        rows = sep.rows(p0, about, cand, stops, growing)  # on the true positions (the QP's: on_forced)
        values: Array | None = sep.single_values(x_true, rows)  # the rows at the rollout
        if st.coupling == "decoupled" and not off_limits.any() and sep.meets_joint(x_true, rows, values):
            # the rollout meets the limits and the joint rows: the decoupled rows are split about
            # the rollout itself, which meets them, so it is the optimum (see the module docstring)
            if st.fast_path:
                return self._fast_path(nominal)
            about = true_path
            rows, values = sep.rows(p0, about, cand, stops, growing), None
        conflicted = sep.conflicted(x_true, rows, values)
        if st.fast_path and not (off_limits | conflicted).any():
            return self._fast_path(nominal)
        blocked = sep.blocked_targets(targets[0]) if conflicted.any() else None
        turned = conflicted
        if (self.loop is not None or self.braking is not None) and conflicted.any():
            # encounters: the single integrator's conflicts within the horizon (a stop point's
            # conflict is the QP's to brake for, not one to turn away from)
            pad = 0 if sep.tail is None else sep.tail.count  # the tail's rows: not counted here
            plain = rows
            if self.loop is not None:
                about_plain = guess(self._plan, p0, horizon, self.braking)
                about_plain = np.concatenate(
                    [about_plain, np.repeat(about_plain[-1:], max(pad - 1, 0), axis=0)]
                )
                plain = sep.rows(p0, about_plain, cand, growing=growing)
            x_enc = np.concatenate([x_nom, np.repeat(x_nom[-1:], pad, axis=0)])
            turned = conflicted & sep.conflicted(x_enc, plain, tail=False)
        speed, step = None, 0.0  # with a_max: how fast the drones fly, how much that changes per step
        if self.limits.a_max_mps2 is not None:
            speed = np.sqrt(np.einsum("nd,nd->n", self._u_prev, self._u_prev))
            step = self.limits.a_max_mps2 * dt * np.sqrt(self.dim)
        to_target = targets[0] - p0
        c = self._tie_break.turn(c, turned, p0, to_target, self._plan is not None, blocked, speed, step)
        bad = off_limits | conflicted
        linked = rows.pairs[rows.pair_on]
        solver = self._solver
        if self._stalled_solver is not None and self._tie_break.resolving:
            solver = self._stalled_solver
        if solver is not self._solver or self._splits:  # a pair's split moves both its drones
            linked = rows.labels[(rows.labels[:, 1] >= 0) & rows.single_on]
        drones = qp_drones(bad, linked) if grouped else np.arange(self.n)
        qp_rows, relaxed, brake = self._predict.on_forced(rows, self._loop_state, sep.ends), False, None
        if self.loop is not None:  # every first row hard (mpc.certify.Certifier.hard_first_rows)
            qp_rows, relaxed, brake = self._certifier.hard_first_rows(
                qp_rows, self._plan, self._u_prev, horizon, self.loop.forced[1, 0]
            )
        sub = qp_rows.subset(drones, self.n, on_only=grouped)  # grouped: the pattern follows the groups
        warm = None
        if self._solver.warm_starts:
            warm = warm_start(self._plan, p0, u_nom, x_nom, self.braking)[:, :, drones]
        free = None if self.loop is None else self._predict.free(self._loop_state)[1:]  # the geofence's
        qp = StepQP(self.n, drones, p0[drones], c[:, drones], self._u_prev[drones], sub, cand.rebuilt, warm)
        if free is not None:
            qp = replace(qp, free_m=free[:, drones])
        if deadline is not None:
            qp = replace(qp, deadline_s=deadline - DEADLINE_RESERVE * (self.settings.step_budget_s or 0.0))
        sol, active = solver.solve(qp)
        late = deadline is not None and time.perf_counter() > deadline
        if late:  # the command had to be sent: the solution came too late
            sol = replace(sol, success=False, status=f"{sol.status}; past the step's deadline")
        elif not sol.success and brake is not None and free is not None:  # wind: no plan in the fence
            path = self._predict.points(self._loop_state, brake, dt * np.cumsum(brake, axis=0))
            wider = admitted(self._families, p0, free, path)
            if not np.array_equal(wider, free):
                sol, active = solver.solve(replace(qp, free_m=wider[:, drones]))
        status, solved = sol.status, None
        inside_m, inside = sep.start_shortfall(p0, rows, SLACK_REPORT_M)  # items that start too close
        if sol.success and sol.x is not None:
            u, x = merge(drones, sol.x, u_nom, x_nom)
            u0 = self._certifier.certify(p0, u[0], cand, self._u_prev)
            if u0 is not None:
                x_true = self._predict.points(self._loop_state, u, x)
                slack_m, items, growth_m = slack_report(
                    sep, sol.x, drones, x_true, rows, (inside_m, inside), relaxed, horizon, growing
                )
                mode = "qp"

                def meets(u: Array, x: Array) -> bool:  # this step's rows, to the solver's tolerance
                    y = self._predict.points(self._loop_state, u, x)
                    off = violators(self._families, p0, self._u_prev, u, y, SLACK_REPORT_M).any()
                    return not off and sep.shortfall(y, rows, SLACK_REPORT_M, joint=True)[1].shape[0] == 0

                slack = items.shape[0] > inside.shape[0] or growth_m > 0.0  # the shifted plan may avoid it
                if slack and (kept := self._certifier.kept(self._plan, p0, cand, self._u_prev, meets)):
                    (u, x), mode, status = kept, "fallback", f"{status}; previous plan (the solve left slack)"
                    u0, slack_m, items, growth_m = u[0], inside_m, inside, 0.0
                self._accept(p0, u, x)
                self._u_prev = u0.copy()  # the command sent (the solver's tolerance off)
                info = solve_info(
                    mode, sol, status, active, len(drones), slack_m, items, self._tie_break, relaxed
                )
                return u0, replace(info, growth_slack_m=growth_m)
            status, solved = status + "; command failed certification", u[0]
        u, x, note = self._certifier.fallback(self._plan, p0, cand, horizon, solved, self._u_prev)
        self._accept(p0, u, x)
        info = solve_info(
            "fallback", sol, f"{status}; {note}", 0, 0, inside_m, inside, self._tie_break, relaxed
        )
        return u[0].copy(), replace(info, deadline_missed=late)

    def _fast_path(self, nominal: Plan) -> tuple[Array, MPCStepInfo]:
        """Accept the rollout's plan: its first input is the command."""
        self._tie_break.clear()
        self._plan, self._u_prev = nominal, nominal.inputs_mps[0].copy()
        resolved = self._tie_break.resolved
        info = MPCStepInfo("fast_path", resolved=resolved) if resolved else FAST_PATH
        return nominal.inputs_mps[0].copy(), info

    def _accept(self, p0: Array, u: Array, x: Array) -> None:
        self._plan = Plan.from_relative(p0, u, x)
        self._u_prev = u[0].copy()


def _check_loop(loop: VelocityLoop | None, dim: int, settings: MPCSettings) -> VelocityLoop | None:
    """The planner's velocity loop fits its dimension and horizon."""
    if loop is not None and loop.forced.shape[1:] != (settings.horizon, dim):
        raise ValidationError(
            "plant",
            f"the velocity loop is for {loop.forced.shape[2]} dimensions and "
            f"a horizon of {loop.forced.shape[1]}, the planner has {dim} and "
            f"{settings.horizon}",
        )
    return loop


def _check_limits(
    dim: int,
    limits: Limits,
    obstacles: tuple[Obstacle, ...],
) -> None:
    """The limits and obstacles fit a ``dim``-dimensional formation and each other."""
    for idx, ob in enumerate(obstacles):
        ob.check_dim(dim, f"obstacles[{idx}]")
    if (limits.d_min_m is not None or obstacles) and limits.v_max_mps is None:
        raise ValidationError(
            "limits.v_max",
            "the MPC needs v_max when d_min or obstacles are set (it bounds how far drones can reach)",
        )
    if limits.downwash_kappa is not None and dim != 3:
        raise ValidationError("limits.downwash", "downwash separation needs a spatial (dim = 3) formation")
    if limits.v_max_z_mps is not None and (dim != 3 or limits.v_max_mps is None):
        raise ValidationError("limits.v_max_z", "a vertical speed bound needs v_max and dim = 3")
    if limits.geofence_min_m is not None and limits.geofence_min_m.shape != (dim,):
        raise ValidationError(
            "limits.geofence_min", f"expected {dim} numbers, got {limits.geofence_min_m.tolist()}"
        )


def slack_report(
    sep: Separation,
    z: Array,
    drones: Array,
    x: Array,
    rows: SeparationRows,
    start: tuple[float, Array],
    relaxed: bool,
    horizon: int,
    growing: Array | None = None,
) -> tuple[float, Array, float]:
    """The slack a certified solve ``z`` of ``drones`` over ``horizon`` steps needed [m] and its
    items (m, 2): those whose rows the positions ``x`` (H or H + 1, n, d) miss by more than
    :data:`SLACK_REPORT_M`, and the items that ``start`` (shortfall [m], items) inside their
    required distance; then how far [m] the positions reach into the rows' growth in wind
    (``growing``, :meth:`SeparationRows.ungrown`) while keeping every required distance: the growth
    is a buffer for the next steps, not a distance to keep, so that is not slack (0 otherwise)."""
    nud = horizon * drones.shape[0] * x.shape[2]
    slack = z[2 * nud : 2 * nud + horizon * drones.shape[0]]
    shortfall, missed = start
    if relaxed or slack.max(initial=0.0) > SLACK_REPORT_M / 2:
        planned, late = sep.shortfall(x, rows, SLACK_REPORT_M, joint=True)
        if late.shape[0] and growing is not None:  # into the growth only?
            bare = rows.ungrown(growing, sep.row_growth)
            if sep.shortfall(x, bare, SLACK_REPORT_M, joint=True)[1].shape[0] == 0:
                return max(shortfall, 0.0), missed, planned
        if late.shape[0]:  # a miss within the solver's tolerance is not slack
            shortfall, missed = max(shortfall, planned), np.concatenate([missed, late])
    return max(shortfall, 0.0), missed, 0.0
