"""Decoupled mode with iterated split points: the joint pair rows' optimum at per-drone cost.

A joint pair row ``a^T (x_{e,i} - x_{e,k}) >= b`` (``a = W c``, :mod:`mpcform.mpc.constraints.separation`) is
split into two one-drone rows ``a^T x_{e,i} >= b_i + t`` and ``-a^T x_{e,k} >= b_k - t``, where
``b_i + b_k = b`` is the midpoint split and ``t`` the row's split shift (0: the midpoint). For
every ``t`` the two rows add up to the joint row (the slacks ``s_{e,i} + s_{e,k}`` as the joint QP
carries them): every iterate's plans meet the joint rows, so it is safe whenever it stops. The pair
rows are the only coupling, so the joint QP's optimum is ``min_t V(t)``, ``V = sum_i f_i`` the
drones' optimal costs: convex and piecewise quadratic in ``t`` (primal decomposition), with

    dV/dt_r = mu_{i,r} - mu_{k,r}        d^2V/dt^2 = sum_i S_i^T (A_i A_i^T)^-1 S_i

(``mu`` the sides' multipliers, ``A_i`` drone i's active rows over ``v``, identity Hessian, ``S_i``
its split rows' signs; :func:`~mpcform.mpc.solve.sensitivity.drone_sensitivity`). Each round takes a
step along the Newton direction in ``t`` from the best iterate and re-solves the drones whose rows
moved, warm-started; the trial becomes the best iterate if it lowers ``V`` enough (Armijo) and
needs no more slack than the midpoint split. The step length is the model's minimiser with its
curvature scaled by what the last trial showed (drones' active sets change along the way, so the
active-set Hessian underestimates it), but at least the distance to the first breakpoint (a row's
slack or multiplier reaching zero: on that piece the model is exact, so it always decreases ``V``).
It stops after ``split_iterations`` rounds, past ``split_budget_s``, less than two rounds (the
longest so far) before the step's deadline, or at convergence, and returns the best iterate.

Hard first rows stay at ``t = 0``: a close start's no-approach row (its safety argument needs
``+-c0^T W x_1 >= 0`` per drone) and, with a velocity loop, every first row. The per-drone QP takes
the hard optimum whenever it exists, so the limit is the joint optimum where it needs no slack.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ValidationError
from mpcform.mpc.constraints.separation_rows import pair_sides
from mpcform.mpc.solve.drone_solves import DroneSolves
from mpcform.mpc.solve.per_drone import PerDroneQP
from mpcform.mpc.solve.problem import BUDGET_CUT, StepQP, StepSolver
from mpcform.mpc.solve.sensitivity import Sensitivity
from mpcform.solvers.base import QPSolution

GRAD_TOL = 1e-8  # |dV/dt| below this on every row: converged
SLACK_TOL_M = 1e-9  # a trial whose drone needs more slack than the midpoint by this is rejected
SLOPE_TOL = 1e-12  # relative: a Newton step predicting less decrease than this ends the iteration
BREAK_TOL = 1e-9  # rows nearer than this to a breakpoint (slack or multiplier) do not bound the step
MIN_STEP = 1e-6  # the shortest step (a fraction of the Newton step) taken
ARMIJO = 1e-4  # sufficient decrease: V(t + s d) <= V(t) + ARMIJO s dV^T d
RIDGE = 1e-12  # relative, on the Newton system (singular where rows are redundant)
BEND_MAX = 1e6  # the largest curvature scale


@dataclass
class Iterate:
    """The drones' solves at one split ``shift`` (P, R): per drone its ``v`` (m, H d), slacks
    (m, H), cost, DAQP multipliers, separation rows (flat ``item * R + row``) and their
    multipliers ``mu``, its solve (for its sensitivity) and the sensitivities computed so far."""

    shift: Array
    v: Array
    s: Array
    cost: Array
    soft: Array
    lams: list[Array]
    rows: list[Array]
    mu: list[Array]
    solves: list[tuple[DroneSolves, int] | None] = field(default_factory=list)
    sens: dict[int, Sensitivity] = field(default_factory=dict)

    @property
    def value(self) -> float:
        return float(self.cost.sum())


@dataclass(frozen=True)
class SplitRun:
    """An iterated split solve: the best iterate's ``solution`` and active rows, the number of
    re-solve ``rounds`` after the midpoint, ``history`` (rounds + 1, 3): the best QP objective
    ``sum_i 0.5 ||v_i - c_i||^2`` (+ slack penalty) and the wall and CPU seconds after each round,
    and (when recorded) every round's positions (H, m, d)."""

    solution: QPSolution
    active: int
    rounds: int
    history: Array
    positions: list[Array]


class SplitQP(StepSolver):
    """The per-drone QPs with their pair rows' split points iterated towards the joint optimum.

    ``iterations``: rounds after the midpoint solve; ``budget_s``: wall time of a step's solve
    after which no new round starts (None: none)."""

    warm_starts = True
    splits_pairs = True

    def __init__(self, per_drone: PerDroneQP, iterations: int, budget_s: float | None) -> None:
        self.per_drone, self.iterations, self.budget_s = per_drone, iterations, budget_s
        self.name = f"{per_drone.backend.name} (per drone, iterated split)"

    def reset(self) -> None:
        self.per_drone.reset()

    def solve(self, qp: StepQP) -> tuple[QPSolution, int]:
        run = self.run(qp)
        return run.solution, run.active

    def run(self, qp: StepQP, record: bool = False) -> SplitRun:
        """Iterate the split of ``qp``'s pair rows (see the module docstring); ``record`` keeps
        every round's positions."""
        t0, c0 = time.perf_counter(), time.process_time()
        step_qp = SplitStep(self.per_drone, qp)
        m = qp.start_m.shape[0]
        warm = np.zeros_like(qp.targets_mps) if qp.warm is None else qp.warm[0]
        best = step_qp.solve(np.arange(m), step_qp.midpoint(), warm, None)
        history = [(best.value, time.perf_counter() - t0, time.process_time() - c0)]
        seen = [step_qp.positions(best)] if record else []
        bend, direction, rounds, cut = 1.0, None, 0, False
        frozen = np.zeros(best.shift.shape, dtype=bool)  # rows kept where they are until a step succeeds
        budget_end = np.inf if self.budget_s is None else t0 + self.budget_s
        round_s, deadline = 2.0 * history[0][1], qp.deadline_s or np.inf  # a solve and a direction
        while rounds < self.iterations and np.isfinite(best.value):  # (a failed midpoint: no rounds)
            if (now := time.perf_counter()) >= budget_end or now + 2.0 * round_s > deadline:
                cut = True  # the split budget spent, or no time for a round and what follows the solve
                break
            if (direction := step_qp.direction(best) if rounds == 0 else direction) is None:
                break  # converged
            newton, slope, longest = direction
            size = min(1.0, max(longest, 1.0 / bend))  # the model's minimiser, its curvature scaled
            trial = step_qp.solve(None, best.shift + size * newton, step_qp.inputs(best), best)
            rounds += 1
            if record:
                seen.append(step_qp.positions(trial))
            change = trial.value - best.value
            if np.isfinite(change):  # the curvature seen: V(best + a d) = V + a slope - a^2 bend slope / 2
                bend = float(np.clip(2.0 * (change - size * slope) / (-slope * size**2), 1.0, BEND_MAX))
            else:
                bend = 4.0 / size
            if change <= ARMIJO * size * slope:
                best, frozen[:] = trial, False
                direction = step_qp.direction(best)
            elif size <= longest:  # failed where the model is exact: drone QPs DAQP cannot solve
                failed = np.flatnonzero(~np.isfinite(trial.cost))  # there: the others move on
                if not failed.size:
                    break
                frozen |= step_qp.rows_of(failed)
                direction, bend = step_qp.direction(best, frozen), 1.0
            round_s = max(round_s, time.perf_counter() - now)  # its solve and next direction
            history.append((best.value, time.perf_counter() - t0, time.process_time() - c0))
        sol, active = step_qp.solution(best)
        if sol.success and self.iterations:
            sol = replace(sol, status=f"{sol.status}; split {rounds} rounds")
        if cut:
            sol = replace(sol, extras={**sol.extras, BUDGET_CUT: True})
        hist = np.array(history)
        hist[:, 0] += step_qp.c_sq
        return SplitRun(sol, active, rounds, hist, seen)


class SplitStep:
    """One step's split problem: the pair sides of ``qp.rows`` (side i ``first``, side k ``second``,
    matched per pair), which rows may move, and the drones' solves at a split."""

    def __init__(self, per_drone: PerDroneQP, qp: StepQP) -> None:
        self.pd, self.qp, rows = per_drone, qp, qp.rows
        self.m, self.r = qp.start_m.shape[0], rows.single_lower.shape[1]
        self.ok, self.flags = np.ones(self.m, dtype=bool), np.zeros(self.m, dtype=int)  # each drone's last
        self.first, self.second = first, second = pair_sides(rows.labels)
        self.splittable = np.repeat(rows.single_on[first][:, None], self.r, axis=1)
        self.splittable[rows.single_hard[first], 0] = False
        self.pair_of = np.full(rows.singles.shape[0], -1)  # item -> its pair, side sign
        self.pair_of[first], self.pair_of[second] = np.arange(first.shape[0]), np.arange(second.shape[0])
        self.sign = np.zeros(rows.singles.shape[0])
        self.sign[first], self.sign[second] = 1.0, -1.0
        self.c_sq = 0.5 * float(np.sum(qp.targets_mps**2))
        self.iterations, self.time_s = 0, 0.0

    def midpoint(self) -> Array:
        return np.zeros(self.splittable.shape)

    def lower(self, shift: Array) -> Array:
        """The one-drone rows' lower bounds (S, R) at split ``shift`` (P, R)."""
        if not shift.any():  # the midpoint
            return self.qp.rows.single_lower
        low = self.qp.rows.single_lower.copy()
        low[self.first] += shift
        low[self.second] -= shift
        return low

    def solve(self, drones: Array | None, shift: Array, warm_u: Array, base: Iterate | None) -> Iterate:
        """Solve ``drones`` (None: those whose rows differ from ``base``'s) at ``shift``; the
        others keep ``base``'s solves."""
        qp, rows, r, pd = self.qp, self.qp.rows, self.r, self.pd
        if drones is None:
            if base is None:
                raise ValidationError("split", "re-solving the moved drones needs their last iterate")
            moved, changed = np.zeros(self.m, dtype=bool), (shift != base.shift).any(axis=1)
            moved[rows.singles[self.first[changed]]] = moved[rows.singles[self.second[changed]]] = True
            drones = np.flatnonzero(moved)
        local = np.full(self.m, -1)
        local[drones] = np.arange(drones.shape[0])
        keep = np.flatnonzero(local[rows.singles] >= 0)
        sel = slice(None) if keep.shape[0] == rows.singles.shape[0] else keep  # every item: no copies
        got = pd.solve_each(
            qp.start_m[drones],
            qp.targets_mps[:, drones],
            qp.u_prev_mps[drones],
            local[rows.singles[sel]],
            rows.single_coeffs[sel],
            self.lower(shift)[sel],
            warm_u[:, drones],
            rows.single_hard[sel],
            rows.single_on[sel],
            None if qp.free_m is None else qp.free_m[:, drones],
        )
        self.iterations, self.time_s = self.iterations + got.iterations, self.time_s + got.time_s
        it = self._copy(base, shift, drones)
        it.v[drones], it.s[drones], it.cost[drones], it.soft[drones] = got.v, got.s, got.cost, got.soft
        item, row = np.divmod(got.rows, r)
        flat, cuts = keep[item] * r + row, got.offsets.tolist()  # global flat indices, per drone:
        rows_at = [flat[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
        ok, mu = got.ok, got.separation_multipliers()
        for j, i in enumerate(drones.tolist()):
            it.rows[i], it.lams[i], it.mu[i] = rows_at[j], got.lams[j], mu[j]
            it.solves[i] = (got, j) if ok[j] else None
        it.cost[drones[~ok]] = np.inf
        self.ok[drones], self.flags[drones] = ok, got.flags  # the last solves, for a failed midpoint's report
        if base is not None:  # a trial may not need more slack than the midpoint (the joint rows hold)
            more = got.s.max(axis=1, initial=0.0) > base.s[drones].max(axis=1, initial=0.0) + SLACK_TOL_M
            it.cost[drones[more]] = np.inf
        return it

    def _copy(self, base: Iterate | None, shift: Array, drones: Array) -> Iterate:
        """``base``'s solves (or empty ones) at a new ``shift``, those of ``drones`` to be overwritten."""
        m = self.m
        if base is None:
            nu, h = self.pd.settings.horizon * self.pd.dim, self.pd.settings.horizon
            empty: list[Array] = [np.empty(0)] * m
            return Iterate(
                shift,
                np.zeros((m, nu)),
                np.zeros((m, h)),
                np.zeros(m),
                np.zeros(m, dtype=bool),
                list(empty),
                [np.empty(0, np.intp)] * m,
                list(empty),
                [None] * m,
            )
        redone = set(drones.tolist())
        return Iterate(
            shift,
            base.v.copy(),
            base.s.copy(),
            base.cost.copy(),
            base.soft.copy(),
            list(base.lams),
            list(base.rows),
            list(base.mu),
            list(base.solves),
            {i: v for i, v in base.sens.items() if i not in redone},
        )

    def sensitivity(self, it: Iterate, i: int) -> Sensitivity | None:
        """Drone i's sensitivity in ``it`` (computed once; None for a failed solve)."""
        if i not in it.sens and it.solves[i] is not None:
            got, j = it.solves[i]  # type: ignore[misc]
            it.sens[i] = self.pd.sensitivity(got, j)
        return it.sens.get(i)

    def positions(self, it: Iterate) -> Array:
        """The iterate's relative positions (H, m, d)."""
        x = self.pd.inputs_positions(it.v)[1]
        return x.reshape(self.m, self.pd.settings.horizon, -1).transpose(1, 0, 2)

    def inputs(self, it: Iterate) -> Array:
        """The iterate's inputs (H, m, d): the warm start of a re-solve."""
        u = self.pd.inputs_positions(it.v)[0]
        return u.reshape(self.m, self.pd.settings.horizon, -1).transpose(1, 0, 2)

    def rows_of(self, drones: Array) -> Array:
        """The split rows (P, R) of pairs with a side on one of ``drones``."""
        singles = self.qp.rows.singles
        sides = np.isin(singles[self.first], drones) | np.isin(singles[self.second], drones)
        return np.repeat(sides[:, None], self.r, axis=1)

    def direction(self, it: Iterate, frozen: Array | None = None) -> tuple[Array, float, float] | None:  # noqa: C901
        """The Newton step (P, R) in the split from ``it`` on its active sets, its slope ``dV^T
        step``, and the fraction of it to the first breakpoint (a row's slack or multiplier
        reaching zero, 1 at most); None at convergence."""
        shape, r = self.splittable.shape, self.r
        blocks, moves = [], []
        offsets = np.zeros(self.m + 1, dtype=np.intp)
        np.cumsum([ids.shape[0] for ids in it.rows], out=offsets[1:])
        mu = np.concatenate(it.mu)
        if np.abs(mu).max(initial=0.0) <= 0.5 * GRAD_TOL:  # each dV/dt_r = mu_i - mu_k: converged
            return None
        all_pair, all_row, all_sign, all_ok = self._split_rows(np.concatenate(it.rows))
        at = (all_pair[all_ok], all_row[all_ok])  # every drone's rows, in drone order
        weights = all_sign[all_ok] * mu[all_ok]  # summed in order, as np.add.at
        grad = np.bincount(all_pair[all_ok] * r + all_row[all_ok], weights, shape[0] * r).reshape(shape)
        if np.abs(grad).max(initial=0.0) <= GRAD_TOL:  # converged: no sensitivity needed
            return None
        owner = np.repeat(np.arange(self.m), np.diff(offsets))[all_ok]
        for i in np.unique(owner[grad[at] != 0.0]):  # the drones of rows with a gradient: the others stay put
            rows_i = slice(offsets[i], offsets[i + 1])
            pair, row, sign, ok = all_pair[rows_i], all_row[rows_i], all_sign[rows_i], all_ok[rows_i]
            sens = self.sensitivity(it, int(i))
            if sens is not None:
                use = ok[sens.active]
                act = sens.active[use]
                blocks.append((pair[act] * r + row[act], sign[act], sens.hessian[use][:, use]))
                moves.append((sens, pair, row, sign, ok))
        if not blocks:
            return None
        used = np.unique(np.concatenate([b[0] for b in blocks]))
        if frozen is not None:
            used = used[~frozen.ravel()[used]]
            if not used.size:
                return None
        n_used, entries, values = used.shape[0], [], []
        for flat, sign, k in blocks:  # frozen entries stay put: their rows and columns drop out
            at = np.minimum(np.searchsorted(used, flat), n_used - 1)
            keep = used[at] == flat
            at, sign = at[keep], sign[keep]
            entries.append((at[:, None] * n_used + at).ravel())
            values.append((np.outer(sign, sign) * k[np.ix_(keep, keep)]).ravel())
        hess = np.bincount(np.concatenate(entries), np.concatenate(values), n_used**2)  # in order, as +=
        hess = hess.reshape(n_used, n_used)
        g = grad.ravel()[used]
        newton = np.zeros(shape)
        ridge = RIDGE * max(1.0, float(np.abs(np.diag(hess)).max(initial=0.0)))
        newton.ravel()[used] = np.linalg.solve(hess + ridge * np.eye(used.shape[0]), -g)
        slope = float(g @ newton.ravel()[used])
        if slope >= -SLOPE_TOL * (1.0 + abs(it.value)):  # no decrease left above rounding
            return None
        longest = 1.0
        for sens, pair, row, sign, ok in moves:
            db = np.zeros(pair.shape[0])
            db[ok] = sign[ok] * newton[pair[ok], row[ok]]
            dv = sens.dv @ db[sens.active]
            rate = sens.rate(dv)
            on = sens.sep_index >= 0
            rate[on] -= db[sens.sep_index[on]]
            for have, change in ((sens.slack, rate), (sens.dual, sens.ddual @ db[sens.active])):
                shrink = (change < 0.0) & (have > BREAK_TOL)
                longest = min(longest, float((have[shrink] / -change[shrink]).min(initial=1.0)))
        return newton, slope, max(longest, MIN_STEP)

    def _split_rows(self, ids: Array) -> tuple[Array, Array, Array, Array]:
        """For a drone's rows (flat ``item * R + row``): their pair, row, side sign, and whether
        they are a split row that moves."""
        item, row = np.divmod(ids, self.r)
        pair = self.pair_of[item]
        ok = pair >= 0
        ok[ok] = self.splittable[pair[ok], row[ok]]
        return pair, row, self.sign[item], ok

    def solution(self, it: Iterate) -> tuple[QPSolution, int]:
        """The iterate as the planner's solution ``[u | x | s]`` and its number of active rows."""
        ok = np.isfinite(it.cost) | self.ok
        return self.pd.solution(it.v, it.s, ok, self.flags, it.lams, self.iterations, self.time_s, it.cost)
