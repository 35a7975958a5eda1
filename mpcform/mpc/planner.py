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
certification (the interval's true chord). The cost stays on the single integrator, plus the
loop's estimated velocity offset ``delta`` held over the plan (offset-free tracking): the
command is eq. 14 less the estimate's low-pass ``delta_c`` when nothing is active, eq. 14 itself
while no offset is estimated (:mod:`mpcform.mpc.velocity_loop`); the tie-break turns only drones whose
single-integrator rollout conflicts (an encounter), not a drone whose own overshoot does (the
QP brakes it). The loop state is run on
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

from mpcform import _jit
from mpcform._validate import Array, positive
from mpcform.control.base import Controller, ControlStep
from mpcform.control.laws import check_gain_dt
from mpcform.errors import ValidationError, shown
from mpcform.mpc.pipeline import PlanState, StepPipeline
from mpcform.mpc.plan import Plan
from mpcform.mpc.safety.survivors import Survivors, lost_spheres, split_lost
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.problem import StepSolver
from mpcform.mpc.strategy import with_backend
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.reference.base import Reference
from mpcform.reference.subset import SubsetReference
from mpcform.solvers.base import QPBackend
from mpcform.world.bounds import PlanningBounds, planning_bounds
from mpcform.world.limits import Limits
from mpcform.world.obstacles import Obstacle, require_resolved, resolve_clearances
from mpcform.world.shapes.shape_set import ShapeSet


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
        limits: Limits | PlanningBounds | None = None,
        settings: MPCSettings | None = None,
        obstacles: tuple[Obstacle, ...] = (),
        solver: str | QPBackend | None = None,
        loop: VelocityLoop | None = None,
    ) -> None:
        self.reference, self.dt_s = reference, positive("simulation.dt", dt_s)
        settings = settings or MPCSettings()
        if not isinstance(settings, MPCSettings):
            raise ValidationError("settings", f"expected mpcform.MPCSettings, got {shown(settings)}")
        if solver is not None:  # the sparse strategy's backend replaced (a per-drone one refuses)
            settings = replace(settings, solve=with_backend(settings.strategy, solver, "controller.solver"))
        self.settings, self._solver_given = settings, solver
        check_gain_dt(settings.gain_per_s, dt_s)
        self.n, self.dim = reference.template.n, reference.template.dim
        if isinstance(limits, PlanningBounds):  # derived by the caller, its obstacles with them
            obstacles = require_resolved(obstacles)
        else:  # the user's limits: the tracking allowance, if any, and a_max's default
            user = Limits() if limits is None else limits
            limits, obstacles = planning_bounds(
                user, resolve_clearances(obstacles, getattr(user, "d_min_m", None))
            )
        self.limits, self.obstacles = limits, obstacles
        _check_limits(self.dim, limits, self.obstacles)
        self.loop = _check_loop(loop, self.dim, settings)
        instance = solver if isinstance(solver, QPBackend) else None
        shapes = ShapeSet(self.obstacles, self.dim)  # every consumer asks these
        self._steps = StepPipeline(reference, self.dt_s, limits, settings, shapes, self.loop, instance)
        if self.n >= _jit.MIN_DRONES and _jit.AVAILABLE:  # now, not within a flight's first step
            from mpcform.mpc.constraints.kernels import warm_up

            warm_up()
        self.braking, self.solver_name = self._steps.braking, self._steps.solvers.name
        self.reset(0.0, np.zeros((self.n, self.dim)))

    # ---- state ----------------------------------------------------------------------------
    def reset(self, t_s: float, positions_m: Array) -> None:
        """Forget the previous plan, the candidate set and the liveness state (a new run)."""
        self._steps.reset()
        self._predicted: Array | None = None  # with a loop, where the last command takes the drones

    @property
    def steps(self) -> StepPipeline:
        """What the planner is built of and runs each step (:mod:`mpcform.mpc.pipeline`)."""
        return self._steps

    @property
    def state(self) -> PlanState:
        """What the planner carries from one step to the next
        (:class:`~mpcform.mpc.pipeline.PlanState`)."""
        return self._steps.state

    @property
    def step_solver(self) -> StepSolver:
        """The solver of every step (:mod:`mpcform.mpc.solve`)."""
        return self._steps.solvers.every

    @property
    def plan(self) -> Plan | None:
        """The plan of the last step (None before the first)."""
        return self._steps.state.plan

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
        mine, theirs = self.state, inner.state
        theirs.u_prev, theirs.loop_state = mine.u_prev[keep], mine.loop_state[keep]
        theirs.offset_mps = None if mine.offset_mps is None else mine.offset_mps[keep]
        inner._predicted = None if self._predicted is None else self._predicted[keep]
        theirs.expected = None if mine.expected is None else mine.expected[:, keep]
        if mine.plan is not None:
            theirs.plan = Plan(mine.plan.inputs_mps[:, keep], mine.plan.positions_m[:, keep])
        return Survivors(self, lost, inner, len(self.obstacles))

    # ---- one step -------------------------------------------------------------------------
    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """One receding-horizon step at time ``t_s`` [s] from the measured ``positions_m`` (n, d) [m]:
        the certified first command (n, d) [m/s] (``||u_i|| <= v_max``, no pair or obstacle closer
        than its limit along the first segment, or than it already was) and the step's information
        (mode ``fast_path`` | ``qp`` | ``fallback``, solver status, slack and the pairs that needed it,
        liveness events). With none of the QP's rows active the command is exactly eq. 14 (with a
        velocity loop's offset estimate, eq. 14 less its low-pass ``delta_c``)."""
        p0 = self._check_positions(positions_m)
        deadline = None if (b := self.settings.step_budget_s) is None else time.perf_counter() + b
        if self.loop is None:
            return ControlStep(*self._steps.run(t_s, p0, deadline))
        state, premise = self.state, self._steps.premise
        if self._predicted is not None:  # the velocity offset of the last interval
            state.loop_state = self.loop.observe(state.loop_state, p0 - self._predicted)
            state.offset_mps = self.loop.cancelled(state.offset_mps, state.loop_state)
        u0, info = self._steps.run(t_s, p0, deadline)
        if premise is not None and state.plan is not None:
            info, state.expected = premise.record(info, state.moved_m, p0, state.loop_state, state.plan)
        self._predicted = p0 + self.dt_s * u0 + self.loop.first(state.loop_state, u0)
        state.loop_state = self.loop.advance(state.loop_state, u0)
        return ControlStep(u0, info)


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
    limits: PlanningBounds,
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
