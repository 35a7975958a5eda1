"""One receding-horizon step, problem -> QP -> solve -> outcome, over the planner's parts.

:class:`StepPipeline` holds what a planner is built of (the limit families, the separation
families, the prediction, the candidates, the certifier, the step solvers, the tie-break) and its
:class:`PlanState`, and runs a step (:meth:`StepPipeline.run`): the eq. 14 rollout
(:class:`~mpcform.mpc.plan.Nominal`); the fast path when it meets every row (it then *is* the QP's
optimum); else the items the rollout conflicts with (:class:`~mpcform.mpc.constraints.separation.Conflict`),
the tie-break, the QP over the conflicted drones' groups and its outcome, certified or fallen back
(:mod:`mpcform.mpc.safety`). The planner (:mod:`mpcform.mpc.planner`) builds it and carries the
velocity loop's observation and the growth's premise around it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from mpcform._validate import Array
from mpcform.control.base import feedforward_targets
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.constraints.candidates import CandidateSelector, qp_drones
from mpcform.mpc.constraints.limits import admitted, inwards, limit_rows, turned_inwards, violators
from mpcform.mpc.constraints.separation import Conflict, Separation, rollout_meets
from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.liveness import TieBreak
from mpcform.mpc.plan import Nominal, Plan, braking_error, guess, merge, rollout, warm_start
from mpcform.mpc.prediction import Prediction, rest_command
from mpcform.mpc.safety.certify import Certifier
from mpcform.mpc.safety.premise import GrowthPremise
from mpcform.mpc.safety.slack import SLACK_REPORT_M, slack_report
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.factory import build_step_solvers
from mpcform.mpc.solve.problem import BUDGET_CUT, StepQP, StepSolver
from mpcform.mpc.step_info import FAST_PATH, MPCStepInfo, solve_info
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.reference.base import Reference
from mpcform.solvers.base import QPBackend, QPSolution
from mpcform.world.bounds import PlanningBounds
from mpcform.world.shapes.shape_set import ShapeSet

DEADLINE_RESERVE = 0.25
"""Share of ``step_budget_s`` no optional solver work is planned into: it is kept for what follows
the solve and for the machine's jitter (the scheduler, the garbage collector, a plant's process)."""


@dataclass
class PlanState:
    """What a planner carries from one step to the next: its last ``plan`` (None before the
    first), the last command ``u_prev`` (n, d) [m/s], the velocity loop's state ``loop_state``
    (n, d, s) (no states without a loop) and, in wind, where the last plan takes the drones
    ``expected`` and how far the wind moved the shifted plan ``moved_m``
    (:class:`~mpcform.mpc.safety.premise.GrowthPremise`); with a loop, the velocity offset (n, d)
    [m/s] the commands cancel ``offset_mps``
    (:meth:`~mpcform.mpc.velocity_loop.VelocityLoop.cancelled`; None before the first observation)."""

    plan: Plan | None
    u_prev: Array
    loop_state: Array
    expected: Array | None = None
    moved_m: float | None = None
    offset_mps: Array | None = None


class StepPipeline:
    """The parts of a planner of ``reference`` (n drones) at ``dt_s`` [s] with its (planning)
    ``limits``, ``settings``, obstacle ``shapes`` and velocity ``loop``, and its state; ``backend``:
    a backend instance for the sparse strategy (None: the strategy's own)."""

    def __init__(
        self,
        reference: Reference,
        dt_s: float,
        limits: PlanningBounds,
        settings: MPCSettings,
        shapes: ShapeSet,
        loop: VelocityLoop | None,
        backend: QPBackend | None,
    ) -> None:
        self.reference, self.dt_s, self.limits, self.settings, self.loop = (
            reference,
            dt_s,
            limits,
            settings,
            loop,
        )
        self.n, self.dim = reference.template.n, reference.template.dim
        self.families = limit_rows(self.dim, dt_s, limits, settings, loop)
        self.braking = braking = Braking.of(dt_s, limits, settings.braking)  # the plans' terminal condition
        self.separation = sep = Separation(self.dim, limits, settings, shapes, braking, loop, dt_s)
        self.predict = predict = Prediction(dt_s, settings.horizon, loop, braking, sep.tail)
        self.premise = GrowthPremise.of(sep.growth, limits.growth_m, predict)  # checked in wind
        grown = 0.0 if sep.growth is None else float(sep.growth[-1])  # the rows' largest growth
        self.candidates = CandidateSelector(
            self.n, dt_s, limits, settings, shapes, predict.speed_gain, predict.tail_s, grown
        )
        scale = limits.speed_scale(self.dim)  # with v_max_z: the velocity set's spheroid
        self.certifier = Certifier(dt_s, limits.v_max_mps, sep, limits.a_max_mps2, braking, scale)
        self.state = PlanState(None, np.zeros((self.n, self.dim)), np.zeros((self.n, self.dim, 0)))
        if loop is not None:  # certify where the loop takes the drones in the interval
            state = self.state
            self.certifier.drift = lambda u0: loop.first(state.loop_state, u0)
            self.certifier.rest_command = lambda: rest_command(state.loop_state)
        # the sparse QP with a backend, or each drone's QP; the split rounds while a drone is stalled
        self.solvers = build_step_solvers(settings, self.dim, dt_s, limits, self.families, sep, loop, backend)
        self.tie_break = TieBreak(self.n, settings.tie_break_rad, dt_s)
        self.reset()

    def reset(self) -> None:
        """Forget the previous plan, the candidate set and the liveness state (a new run): drones at
        rest."""
        self.candidates.reset()
        self.solvers.reset()
        self.tie_break.reset()
        rest = np.zeros((self.n, self.dim, 0)) if self.loop is None else self.loop.rest(self.n)
        self.state.plan, self.state.u_prev, self.state.loop_state = None, np.zeros((self.n, self.dim)), rest
        self.state.expected = self.state.moved_m = self.state.offset_mps = None

    def run(self, t_s: float, p0: Array, deadline: float | None) -> tuple[Array, MPCStepInfo]:
        """The step at ``t_s`` from ``p0``, due at ``time.perf_counter() == deadline`` (None: none):
        the rollout, the fast path when it meets every row, else the conflicts, the tie-break, the
        solve over the conflicted drones' groups and its outcome (certified, kept or fallen back)."""
        st, sep = self.settings, self.separation
        nom = self._nominal(t_s, p0)
        if st.fast_path and not nom.off_limits.any() and sep.clear(nom.guess, nom.true_path, nom.growing):
            return self._fast_path(nom.plan)
        conflict = self._conflicts(p0, nom)
        if conflict is None:  # the rollout is the QP's optimum
            return self._fast_path(nom.plan)
        c = self._turn(p0, nom, conflict)
        solver = self.solvers.pick(self.tie_break.resolving > 0)
        grouped = st.fast_path and st.grouping
        bad = nom.off_limits | conflict.conflicted
        drones = qp_drones(bad, self.solvers.linked(conflict.rows, solver)) if grouped else np.arange(self.n)
        qp, relaxed, brake = self._step_qp(p0, nom, c, conflict, drones, deadline)
        sol, active = solver.solve(qp)
        if not sol.success and brake is not None:  # wind: no plan in the fence
            sol, active = solve_in_wider_fence(self, solver, qp, p0, brake, sol, active)
        u0, info = self._outcome(p0, nom, conflict, drones, sol, active, relaxed)
        return u0, timed(info, sol, deadline)

    def _nominal(self, t_s: float, p0: Array) -> Nominal:
        """The step's eq. 14 rollout from ``p0``, where it takes the drones, the guess the rows are
        linearised about, and the drones the rollout takes off a limit (:class:`Nominal`)."""
        st, k, dt = self.settings, self.settings.gain_per_s, self.dt_s
        targets, ff = feedforward_targets(self.reference, t_s, dt, st.horizon, st.feedforward)
        error = braking_error(targets[:-1] - p0, k, self.limits.a_max_mps2, self.limits.v_max_mps)
        c = ff + k * error  # u_j = c_j - k x_j is the eq. 14 rollout
        cancel, delta = None, self.state.offset_mps
        if delta is not None and delta.any():  # offset-free: the cost on v = u + delta
            cancel = cost_shift(delta, k, dt, st.horizon)
            c = c - cancel
        u_nom, x_nom = rollout(c, k, dt)
        x_true = self.predict.points(
            self.state.loop_state, u_nom, x_nom
        )  # where the rollout takes the drones
        about = self.predict.guess(self.state.plan, p0, self.state.loop_state)
        growing = self.separation.growing(targets[0])  # each drone's share of the rows' growth in wind
        self.state.moved_m = (
            None if self.premise is None else self.premise.moved(about, self.state.expected, growing)
        )
        return Nominal(
            targets,
            c,
            u_nom,
            x_nom,
            x_true,
            Plan.from_relative(p0, u_nom, x_nom),  # the fast path's plan
            np.concatenate([p0[None], p0 + x_true]),
            about,
            violators(self.families, p0, self.state.u_prev, u_nom, x_true),
            growing,
            cancel,
        )

    def _conflicts(self, p0: Array, nom: Nominal) -> Conflict | None:
        """The candidate items, their rows about the guess and the drones whose rollout misses one;
        None when the rollout is the QP's optimum (the fast path). In decoupled mode a rollout that
        meets the limits and the joint rows is split about itself (module docstring)."""
        st, sep = self.settings, self.separation
        cand = self.candidates.select(p0, self.predict.drift_m(self.state.loop_state))
        if (st.fast_path and st.grouping) or st.solves_per_drone:  # no fixed pattern: within reach
            cand = cand.within_reach()
        stops = nom.true_path[-1] if self.braking is not None and st.coupling == "decoupled" else None
        if st.fast_path and not nom.off_limits.any():  # most pairs clear: build only the others' rows
            if rollout_meets(sep, p0, nom.guess, nom.true_path, nom.x_true, cand, stops, nom.growing):
                return None
        rows = sep.rows(p0, nom.guess, cand, stops, nom.growing)  # on the true positions (QP: on_forced)
        values: Array | None = sep.single_values(nom.x_true, rows)  # the rows at the rollout
        split = st.coupling == "decoupled" and not nom.off_limits.any()
        if split and sep.meets_joint(nom.x_true, rows, values):
            if st.fast_path:
                return None
            rows, values = sep.rows(p0, nom.true_path, cand, stops, nom.growing), None
        conflicted = sep.conflicted(nom.x_true, rows, values)
        if st.fast_path and not (nom.off_limits | conflicted).any():
            return None
        return Conflict(cand, rows, conflicted)

    def _turn(self, p0: Array, nom: Nominal, conflict: Conflict) -> Array:
        """The rollout's targets ``c`` turned by the tie-break for the drones in an encounter
        (:mod:`mpcform.mpc.liveness`); with a loop or braking, only the single integrator's
        conflicts within the horizon count (a stop point's is the QP's to brake for)."""
        sep, conflicted = self.separation, conflict.conflicted
        blocked = sep.blocked_targets(nom.targets[0]) if conflicted.any() else None
        turned = conflicted
        if (self.loop is not None or self.braking is not None) and conflicted.any():
            plain = None  # the single integrator's guess: with a loop, not the rows' own
            if self.loop is not None:
                plain = guess(self.state.plan, p0, self.settings.horizon, self.braking)
            turned = conflicted & sep.encounters(p0, conflict, nom.x, plain, nom.growing)
        speed, step = speeds(self.state.u_prev, self.limits.a_max_mps2, self.dt_s)
        to_target = nom.targets[0] - p0
        wish = nom.c if nom.cancel is None else nom.c + nom.cancel  # turned over ground
        c = self.tie_break.turn(
            wish, turned, p0, to_target, self.state.plan is not None, blocked, speed, step
        )
        return c if nom.cancel is None else (nom.c if c is wish else c - nom.cancel)  # back to commands

    def _step_qp(
        self, p0: Array, nom: Nominal, c: Array, conflict: Conflict, drones: Array, deadline: float | None
    ) -> tuple[StepQP, bool, Array | None]:
        """The QP over ``drones``, whether a hard first row was lowered, and with a loop the braking
        plan the first rows were lowered to (:meth:`mpcform.mpc.safety.certify.Certifier.hard_first_rows`)."""
        qp_rows, relaxed, brake = (
            self.predict.on_forced(conflict.rows, self.state.loop_state, self.separation.ends),
            False,
            None,
        )
        if self.loop is not None:  # every first row hard
            qp_rows, relaxed, brake = self.certifier.hard_first_rows(
                qp_rows, self.state.plan, self.state.u_prev, self.settings.horizon, self.loop.forced[1, 0]
            )
        grouped = self.settings.fast_path and self.settings.grouping  # the pattern follows the groups
        warm = None
        if self.solvers.warm_starts:
            rest = None if self.loop is None else rest_command(self.state.loop_state)
            warm = warm_start(self.state.plan, p0, nom.u, nom.x, self.braking, rest)[:, :, drones]
        qp = StepQP(
            self.n,
            drones,
            p0[drones],
            c[:, drones],
            self.state.u_prev[drones],
            qp_rows,  # over all drones: the QP's own selected when a solver asks (StepQP.rows)
            conflict.cand.rebuilt,
            warm,
            on_only=grouped,
        )
        if self.loop is not None:  # the geofence's free response
            qp = replace(qp, free_m=self.predict.free(self.state.loop_state)[1:][:, drones])
        if deadline is not None:
            qp = replace(qp, deadline_s=deadline - DEADLINE_RESERVE * (self.settings.step_budget_s or 0.0))
        return qp, relaxed, brake

    def _outcome(
        self,
        p0: Array,
        nom: Nominal,
        conflict: Conflict,
        drones: Array,
        sol: QPSolution,
        active: int,
        relaxed: bool,
    ) -> tuple[Array, MPCStepInfo]:
        """The command and the record of a step that called the solver: the solve's certified
        command, the previous plan where it avoids the slack the solve left, else the fallback."""
        sep, cand, rows = self.separation, conflict.cand, conflict.rows
        status, solved = sol.status, None
        inside_m, inside = sep.start_shortfall(p0, rows, SLACK_REPORT_M)  # items that start too close
        if sol.success and sol.x is not None:
            u, x = merge(drones, sol.x, nom.u, nom.x)
            u0 = self.certifier.certify(p0, u[0], cand, self.state.u_prev)
            if u0 is not None:
                x_true = self.predict.points(self.state.loop_state, u, x)
                start = (inside_m, inside)
                horizon = self.settings.horizon
                slack_m, items, growth_m = slack_report(
                    sep, sol.x, drones, x_true, rows, start, relaxed, horizon, nom.growing
                )
                mode = "qp"
                slack = items.shape[0] > inside.shape[0] or growth_m > 0.0  # the shifted plan may avoid it
                meets = meets_rows(self, p0, rows)
                if slack and (
                    kept := self.certifier.kept(self.state.plan, p0, cand, self.state.u_prev, meets)
                ):
                    (u, x), mode, status = kept, "fallback", f"{status}; previous plan (the solve left slack)"
                    u0, slack_m, items, growth_m = u[0], inside_m, inside, 0.0
                self._accept(p0, u, x)
                self.state.u_prev = u0.copy()  # the command sent (the solver's tolerance off)
                info = solve_info(
                    mode, sol, status, active, len(drones), slack_m, items, self.tie_break, relaxed
                )
                return u0, replace(info, growth_slack_m=growth_m)
            status, solved = status + "; command failed certification", u[0]
        horizon = self.settings.horizon
        u, x, note = self.certifier.fallback(self.state.plan, p0, cand, horizon, solved, self.state.u_prev)
        self._accept(p0, u, x)
        info = solve_info(
            "fallback", sol, f"{status}; {note}", 0, 0, inside_m, inside, self.tie_break, relaxed
        )
        return u[0].copy(), info

    def _fast_path(self, nominal: Plan) -> tuple[Array, MPCStepInfo]:
        """Accept the rollout's plan: its first input is the command."""
        self.tie_break.clear()
        self.state.plan, self.state.u_prev = nominal, nominal.inputs_mps[0].copy()
        resolved = self.tie_break.resolved
        info = MPCStepInfo("fast_path", resolved=resolved) if resolved else FAST_PATH
        return nominal.inputs_mps[0].copy(), info

    def _accept(self, p0: Array, u: Array, x: Array) -> None:
        self.state.plan = Plan.from_relative(p0, u, x)
        self.state.u_prev = u[0].copy()


def timed(info: MPCStepInfo, sol: QPSolution, deadline: float | None) -> MPCStepInfo:
    """``info`` with whether the step ended past its ``deadline`` (its certified command is sent
    late) and whether the wall clock cut the solve's optional work (:data:`BUDGET_CUT`)."""
    late = deadline is not None and time.perf_counter() > deadline
    cut = bool(sol.extras.get(BUDGET_CUT, False))
    return replace(info, deadline_missed=late, budget_cut=cut) if late or cut else info


def speeds(u_prev: Array, a_max_mps2: float | None, dt_s: float) -> tuple[Array | None, float]:
    """With ``a_max``, how fast the drones fly (n,) and how much that can change per step (the
    tie-break's, :mod:`mpcform.mpc.liveness`); else None and 0."""
    if a_max_mps2 is None:
        return None, 0.0
    return np.sqrt(np.einsum("nd,nd->n", u_prev, u_prev)), a_max_mps2 * dt_s * np.sqrt(u_prev.shape[1])


def cost_shift(offset_mps: Array, k: float, dt_s: float, horizon: int) -> Array:
    """What the cost's ``c`` (H, n, d) loses to an estimated velocity offset ``offset_mps`` (n, d)
    held over the plan (offset-free tracking, Pannocchia and Rawlings 2003): the cost tracks the
    reference on the velocity over ground ``v_j = u_j + delta`` and the displacement
    ``x_j + j dt delta``, ``||v_j - ff_j - k (p*_j - p0 - x_j - j dt delta)||^2``, so
    ``c_j - delta (1 + k j dt)``, and the unconstrained first command is ``ff + k (p* - p) -
    delta`` (eq. 14 less the offset)."""
    return (1.0 + k * dt_s * np.arange(horizon))[:, None, None] * offset_mps[None]


def meets_rows(steps: StepPipeline, p0: Array, rows: SeparationRows) -> Callable[[Array, Array], bool]:
    """Whether a plan (inputs, relative positions) from ``p0`` meets this step's limit rows and
    separation ``rows``, to the solver's tolerance."""

    def meets(u: Array, x: Array) -> bool:
        y = steps.predict.points(steps.state.loop_state, u, x)
        off = violators(steps.families, p0, steps.state.u_prev, u, y, SLACK_REPORT_M).any()
        return not off and steps.separation.shortfall(y, rows, SLACK_REPORT_M, joint=True)[1].shape[0] == 0

    return meets


def solve_in_wider_fence(
    steps: StepPipeline, solver: StepSolver, qp: StepQP, p0: Array, brake: Array, sol: QPSolution, active: int
) -> tuple[QPSolution, int]:
    """In wind the loop did not foresee (or a Crazyflie's sag at speed) no plan may be left inside
    the fence: the QP again with the fence's bounds widened to admit the braking plan turned back
    into the fence (:func:`mpcform.mpc.constraints.limits.turned_inwards`), then if that fails the
    braking plan itself (:func:`mpcform.mpc.constraints.limits.admitted`)."""
    state, cert = steps.state, steps.certifier
    free = steps.predict.free(state.loop_state)[1:]

    def path(u: Array) -> Array:
        return steps.predict.points(state.loop_state, u, steps.dt_s * np.cumsum(u, axis=0))

    plans, brake_path = [brake], path(brake)
    inward = inwards(steps.families, p0, brake_path)
    if cert.a_step_mps is not None and inward.any():
        rest = rest_command(state.loop_state)
        back = turned_inwards(brake, state.u_prev, rest, inward, cert.a_step_mps, cert.within_limits)
        plans.insert(0, back)
    spent = sol.solve_time_s
    for plan in plans:
        wider = admitted(steps.families, p0, free, brake_path if plan is brake else path(plan))
        if np.array_equal(wider, free):
            continue
        again, got = solver.solve(replace(qp, free_m=wider[:, qp.drones]))
        spent += again.solve_time_s
        sol, active = replace(again, solve_time_s=spent), got  # every solve's time
        if sol.success:
            break
    return sol, active
