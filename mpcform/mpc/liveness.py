"""Liveness: the tie-break that keeps symmetric encounters and blocked drones from deadlocking.

When the eq. 14 rollout breaks a separation row, the wishes (targets ``c``) of the drones
involved are turned to the right about the world z axis, so antipodal swaps circulate instead of
meeting head-on. That alone can settle into a standstill: a symmetric ring jammed at the centre
turns in balance, and a drone pressed against a sphere has its turned wish pushed back by the rows.

Stall detection: a conflicted drone is *stalled* at a step when it is away from its target
(farther than :data:`ARRIVED_M`) and its last step moved it towards its target by less than
:data:`STALL_FRACTION` of its wish's step (``|c_0| dt``; with ``a_max``, of the step it can reach,
``min(|c_0|, |u_prev| + sqrt(d) a_max dt) dt``: a drone speeding up from rest is not stalled):
whether its reference stands still or runs away from it, it is not following. With ``a_max``
a drone whose step was at least :data:`MOVING_FRACTION` of its wish's is not stalled either: it
is being deflected, not stuck (a ring circulating before its centre, slowed by its braking
tails, counted its sideways flight as stalls, and the escalated turns flew it outwards).

Resolution (the right-hand rule escalated, with hysteresis): each stalled step raises the drone's
turn by :data:`STALL_GROWTH` of the base angle (with ``a_max``, by no more than the drone can turn
its velocity ``|u_prev|`` in a step, ``sqrt(d) a_max dt / |u_prev|``: a turn that outruns the drone
would sweep its wish backwards while it is still braking); the raised turn is *kept* while the drone stays
in conflict, even when it moves again, so a ring that starts to circulate keeps circulating
instead of falling back to the base angle and jamming again. It ends (a *resolution*) only
when the drone leaves conflict. While the drone stays stuck the turn sweeps on past a quarter
turn (the wish points backwards to the right, then to the left) and round the full circle: a
drone wedged in a pocket between two spheres, or between parked drones, backs out of it, and
if any direction of motion is open to it, the sweep finds it. Once a drone is :data:`BACKOFF_M`
farther from its target than at its closest stalled step of the conflict, its escalation starts
afresh from the base angle with the rule's side switched (it heads for its target again from where
it got to, now passing the blocking drones or spheres on the other side, the side it backed out
on; a turn held for good would only orbit the target). The side is kept for the rest of the run.
The budget is the conflict's, not the side's: once the second side has spent it too, the drone's
escalation stops (its wish turned by the base angle only) until it is back within the budget, so it
stays near its path and is never carried more than :data:`BACKOFF_M` beyond its closest
stalled approach to its target in one conflict (a budget renewed per side let a drone walk
away by a metre per switch, stalling and backing off again and again). The conflict ends, and
the budget with it, when the drone's rollout no longer breaks a row.
Safety is untouched: the turn only changes the cost's targets, every row stays in the QP.

Circling: a kept turn can also carry a drone round its target at a constant distance (two
antipodal drones circling each other, their turns escalated and kept), never stalled (it moves)
and never backing off (its distance stays). A conflicted drone that has flown :data:`CIRCLING_M`
but not come :data:`PROGRESS_M` closer to its target than its best of the conflict for
:data:`WAIT_S` is *circling*: its escalation is reset (its wish turned by the base angle only,
so it heads for its target) and the count starts again. :attr:`unwound` counts the resets of
the last step.

Blocked targets: a drone whose target lies within ``d_min`` of another drone's target, with the
planner's limits (a plant's margin included), can never reach it; turning or backing off would
only carry it away. Nor can a plant that is pushed off its plan by up to its margin (the tube)
per interval hold two targets less than the tube farther apart: the pair is pushed inside its
rows and back, in conflict at every step, and turning it would only scatter a tight formation.
Such a drone is not turned and never escalates: it presses towards its target and settles as
close as the rows allow.

Limits: the rule is local and greedy. A drone backing out of a pocket can fall back into it once
it is out of conflict (then it stalls and escalates again; nothing bounds how many times), and a
goal inside a region closed by obstacles or by parked drones is never reached. The rule does not
plan around a sphere as a whole (no detour goal), so a long wall of spheres is followed slowly.
"""

from __future__ import annotations

import numpy as np

from mpcform._validate import Array

STALL_FRACTION = 0.02  # progress per step below this fraction of the wish's step counts as stalled
STALL_GROWTH = 0.2  # the tie-break angle grows by this fraction of itself per stalled step
MOVING_FRACTION = 0.25  # with a_max, a drone whose step is this fraction of its wish's is moving
ARRIVED_M = 1e-2  # a drone this close to its target is not stalled [m]
FULL_TURN_RAD = 2.0 * np.pi
BACKOFF_M = 1.0  # how much farther from its target than its closest stall of the conflict a drone may go [m]
WAIT_S = 3.0  # how long a conflicted drone may fly without progress before its escalation is reset [s]
PROGRESS_M = 0.1  # progress: this much closer to the target than the conflict's best [m]
CIRCLING_M = 1.0  # a circling drone has flown at least this far without progress [m]


class TieBreak:
    """The turn of each conflicted drone's wish, and how far each drone's turn is escalated.

    ``stalled`` counts each drone's stalled steps in its current conflict (its escalation); the
    event counters :attr:`new_stalls` and :attr:`resolved` refer to the last step.
    """

    def __init__(self, n: int, angle_rad: float, dt_s: float = 1.0) -> None:
        self.angle_rad = angle_rad  # base angle (0 disables)
        self.dt_s = dt_s
        self.stalled = np.zeros(n)  # stalled steps in the current conflict, per drone (in growth steps)
        self.last_m: Array | None = None  # positions (n, d) at the last step
        self.stall_distance_m = np.full(n, np.inf)  # the conflict's closest stalled distance to the target
        self.sense = np.ones(n)  # +1: turn to the right, -1: to the left (after a back-off)
        self.switched = np.zeros(n, dtype=bool)  # the side switched in the current conflict
        self.new_stalls = 0  # drones that started to stall at the last step
        self.resolved = 0  # escalated drones that left conflict at the last step
        self.best_m = np.full(n, np.inf)  # the conflict's closest distance to the target
        self.idle_s = np.zeros(n)  # time since the drone last progressed (:data:`PROGRESS_M`)
        self.flown_m = np.zeros(n)  # how far it has flown since [m]
        self.unwound = 0  # circling drones whose escalation was reset at the last step

    def reset(self) -> None:
        """A new run: every drone turns to the right again."""
        self.clear()
        self.sense[:] = 1.0

    def clear(self) -> None:
        """No drone is in conflict (a step without conflict, or a new run)."""
        if self.last_m is None:  # cleared, and no turn since: nothing is stalled
            self.resolved = self.new_stalls = self.unwound = 0
            return
        self.best_m[:], self.idle_s[:], self.flown_m[:], self.unwound = np.inf, 0.0, 0.0, 0
        self.resolved = int(np.count_nonzero(self.stalled))
        self.new_stalls = 0
        self.stalled[:] = 0
        self.last_m = None
        self.stall_distance_m[:] = np.inf
        self.switched[:] = False

    @property
    def resolving(self) -> int:
        """Drones whose turn is escalated."""
        return int(np.count_nonzero(self.stalled))

    def turn(
        self,
        c: Array,
        conflicted: Array,
        p0: Array,
        to_target: Array,
        started: bool,
        blocked: Array | None = None,
        speed_mps: Array | None = None,
        step_mps: float = 0.0,
    ) -> Array:
        """Targets ``c`` (H, n, d) with the ``conflicted`` (n,) drones' turned to the right;
        ``p0`` (n, d) the positions, ``to_target`` (n, d) the way to the targets ``p* - p0``,
        ``started``: whether any command was given; ``blocked`` (n,): drones whose target no
        plan can reach (module doc), never turned; with ``a_max``, ``speed_mps`` (n,) the drones'
        last commands' speeds and ``step_mps`` the most a command's speed changes in a step
        (``sqrt(d) a_max dt``): what the stall test and the escalation measure against."""
        if self.angle_rad <= 0:
            return c
        if blocked is not None and blocked.any():
            conflicted = conflicted & ~blocked
        wish, growth = norms(c[0]), np.ones(c.shape[1])
        if speed_mps is not None:
            wish = np.minimum(wish, speed_mps + step_mps)
            turn_rad = STALL_GROWTH * self.angle_rad * speed_mps  # velocity change of a growth step
            np.divide(step_mps, turn_rad, out=growth, where=turn_rad > step_mps)
        moving = 0.0 if speed_mps is None else MOVING_FRACTION
        angles = self.angles(conflicted, wish, p0, to_target, started, growth, moving)
        return np.where(conflicted[:, None], turn_about_z(c, -self.sense * angles), c)

    def _unwind(self, conflicted: Array, distance_m: Array, flown_m: Array) -> None:
        """Reset the escalation of circling drones (module docstring), given each drone's distance
        to its target and how far it flew in the last step."""
        improved = distance_m < self.best_m - PROGRESS_M
        self.best_m = np.where(conflicted, np.where(improved, distance_m, self.best_m), np.inf)
        idle = conflicted & ~improved
        self.idle_s = np.where(idle, self.idle_s + self.dt_s, 0.0)
        self.flown_m = np.where(idle, self.flown_m + flown_m, 0.0)
        circling = (self.idle_s >= WAIT_S - 1e-9) & (self.flown_m >= CIRCLING_M) & (distance_m > PROGRESS_M)
        self.unwound = int(np.count_nonzero(circling))
        self.stalled[circling] = 0.0
        self.idle_s[circling] = self.flown_m[circling] = 0.0

    def angles(
        self,
        conflicted: Array,
        wish: Array,
        p0: Array,
        to_target: Array,
        started: bool,
        growth: Array | float = 1.0,
        moving: float = 0.0,
    ) -> Array:
        """Turn angle per drone [rad] (``wish`` (n,): the speed [m/s] a step is measured against,
        ``growth`` (n,): how much of a growth step a stalled step counts; ``moving``: a drone whose
        step was at least this fraction of its wish's is not stalled): the base angle, grown
        by ``STALL_GROWTH`` of it for every stalled step in the drone's current conflict, modulo a
        full turn (a base angle of a quarter turn or more is kept as it is); a drone past its
        back-off budget starts afresh. Counts this step (see the module docstring)."""
        distance = norms(to_target)
        stalled = conflicted & (distance > ARRIVED_M)
        flown = np.zeros(distance.shape)
        if self.last_m is not None and started:
            flown = norms(p0 - self.last_m)
            far = distance[:, None] > 0
            towards = np.divide(to_target, distance[:, None], out=np.zeros_like(p0), where=far)
            progress = np.einsum("nd,nd->n", p0 - self.last_m, towards)
            stalled &= progress < STALL_FRACTION * wish * self.dt_s
            if moving > 0.0:  # a drone deflected at speed is not stuck
                stalled &= norms(p0 - self.last_m) < moving * wish * self.dt_s
        else:
            stalled[:] = False  # no step made yet: nothing has stalled
        self.last_m = p0.copy()
        self.new_stalls = int(np.count_nonzero(stalled & (self.stalled == 0)))
        self.resolved = int(np.count_nonzero(~conflicted & (self.stalled > 0)))
        self.stalled = np.where(conflicted, self.stalled + stalled * growth, 0.0)
        closest = np.where(stalled, np.minimum(self.stall_distance_m, distance), self.stall_distance_m)
        self.stall_distance_m = np.where(conflicted, closest, np.inf)  # the conflict's closest stall
        self.switched &= conflicted
        backed_off = distance > self.stall_distance_m + BACKOFF_M  # the budget is spent
        self.stalled[backed_off] = 0  # start afresh from the base angle, or wait there
        self.sense[backed_off & ~self.switched] *= -1.0  # the other side, once per conflict
        self.switched |= backed_off
        self._unwind(conflicted, distance, flown)
        base = self.angle_rad
        if base >= 0.5 * np.pi:  # a base angle of a quarter turn or more is kept as it is
            return np.full(self.stalled.shape, base)
        return np.mod(base * (1.0 + STALL_GROWTH * self.stalled), FULL_TURN_RAD)


def norms(v: Array) -> Array:
    """Euclidean norms over the last axis."""
    return np.sqrt(np.einsum("...d,...d->...", v, v))


def turn_about_z(v: Array, angle: Array) -> Array:
    """Rotate vectors (..., n, d) by ``angle`` (n,) [rad] about the world z axis (in-plane when d = 2)."""
    ca, sa = np.cos(angle), np.sin(angle)
    out = v.copy()
    out[..., 0] = ca * v[..., 0] - sa * v[..., 1]
    out[..., 1] = sa * v[..., 0] + ca * v[..., 1]
    return out
