r"""The braking tail's exact hull under a velocity loop: a few vertices whose hull holds every
point of the tail until the loop is at rest, and maps into itself when the plan shifts.

Past the horizon a plan brakes geometrically (:mod:`mpcform.mpc.constraints.braking`): the command of
interval ``H + m`` is ``rho^{m+1} u_{H-1}``. Per axis the tail's state ``z = (c, xi)`` (the last
command level, ``c_0 = u_{H-1}``, and the loop state without its velocity offset, ``xi_0 = xi_H``)
evolves as ``z+ = M z`` with ``M = [[rho, 0], [rho Gamma, Phi]]`` (``Phi``, ``Gamma``: one interval
of the loop, :class:`mpcform.mpc.velocity_loop.VelocityLoop`), and the distance still to go to the rest
point is ``L M^m z`` with ``L = [kappa dc, F_rest]`` (the commands still to come, carried ``dc``
per metre, plus the loop's free response to rest).

**The hull.** Vertex functionals ``W_0 = L``, then over M's real eigenvalues ``d_j`` in [0, 1)

.. math::
    W_{j+1} = W_j (M - d_j I) / (1 - d_j), \qquad\text{so}\qquad W_j M = d_j W_j + (1 - d_j) W_{j+1},

and the chain ends at 0 (Cayley-Hamilton: the rest point). A complex pair ``r e^{i theta}`` (at most
one per axis here) ends the chain instead with the N vertices of a regular N-gon, ``cos(pi/N) >= r``,
around the pair's orbit in its rotation coordinates: rotated by theta and shrunk by r it lies inside
its inscribed circle. Every row of ``W M`` is then a convex combination of the rows of ``W`` and 0
(:attr:`TailHull.transition`, nonnegative, rows summing to at most 1), so the distances to go
``W z`` of a state hold those of every later state: the tail's points lie in the hull of
``rest - W z`` and the rest point, and the shifted plan's hull (``z -> M z``) lies in this one.
No eigenvector is formed: nothing blows up when ``rho`` meets a pole of the loop.

**The tail points** (:class:`Tail`, :func:`braking_tail`). The rows past the horizon sit at the
points ``rest - W_k z`` (``k >= 1``; ``k = 0`` is ``y_H``, whose rows the horizon has) and at the
rest point, with one normal per item: a half-space holding at every vertex holds on the hull, so
on the whole tail to rest. Where the hull is much wider than the path (a nearly critically damped
loop's, a quadrotor's when the QPs are solved per drone) the tail's first K points are exact
samples and the hull's vertices follow K intervals later (:data:`TAIL_SAMPLES`,
:data:`CASCADE_SAMPLES`). The tail's weights over its vertices are the same for every axis, so
the 3-D points are the hull's vertices: trivially when the axes share one loop (a lag, the
second-order loop, a planar quadrotor). Where they differ (a spatial quadrotor's xy and z loops:
two groups, :func:`tail_hull`) the real chain runs over both groups' real poles at once, and each
group's complex pair gets its polygon widened P times (P groups with a pair), alone in its group:
the pairs' parts ``(a_1, .., a_P)`` average the points ``P a_g``, so they lie in the hull of those
polygons, each of which maps into itself. That is the chain's steps plus the polygons' corners
(13-16 vertices for a quadrotor), not the product of the axes' hulls (about 100). A quadrotor's
tail in a joint QP is the chord to rest (:data:`SAMPLED_STATES`), which is not shift-invariant:
the plans may need slack on the tail's rows, and the margin has to cover the
path's bend (:mod:`mpcform.mpc.constraints.braking`). Without a loop the tail is the straight segment to the
stop point ``x_H + kappa u_{H-1}``: one point.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
from scipy.optimize import linprog

from mpcform._validate import Array
from mpcform.errors import MPCFormError, ValidationError
from mpcform.mpc.constraints.braking import Braking
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.velocity_loop import VelocityLoop

REAL_TOL = 1e-9  # an eigenvalue with a smaller imaginary part is real
SAME_TOL = 1e-12  # axes whose tail systems differ by less share one hull
SAME_POLE = 1e-9  # real poles of two groups closer than this are one step of the chain
TAIL_SPREAD = 4.0
"""The hull is used once its points reach at most this many times as far past ``x_H`` as the
chord's rest point can (``kappa`` times the loop's speed gain, plus its lag). A lag's hull and an
underdamped second-order loop's reach at most about 1.4 times as far; a quadrotor's 14 (dt 0.1)
to 29 (dt 0.05) times (its slow integral pole widens the polygon), and a nearly critically damped
loop's far more (its pole pair's rotation coordinates are ill-conditioned), which would open
every encounter metres wide: those tails take exact samples first (:data:`TAIL_SAMPLES`), or keep
the chord."""
TAIL_SAMPLES = 2
"""At most this many exact points ``rest - L M^k z`` (k = 1..K) of the tail precede its hull,
which then holds ``M^K z``: the polygon's width shrinks with the poles' powers, and the points stay
closed under the shift (``L M^{K+1} = W_0 M^K M`` lies in the hull). The least K whose hull is within
:data:`TAIL_SPREAD` is used: 0 for a lag and an underdamped second-order loop, 1 for a nearly
critically damped one at dt 0.1 (at dt 0.05 it would need 3: the chord). A quadrotor's cascade
takes none in a joint QP (:data:`SAMPLED_STATES`) and up to :data:`CASCADE_SAMPLES` per drone."""
SAMPLED_STATES = 2
"""In a joint QP exact samples are taken only for loops of at most this many states (a lag's 1, a
second-order loop's 2). A quadrotor's cascade (its integral, attitude and rate states) keeps its
hull or the chord there whatever its braking time: its samples' rows touch every input of both
drones, and its joint QPs took 4-6 times as long (a slow planar swap of 20 drones, whose hull was
within reach after 2 samples, 4 times as long with their 9 tail points' rows)."""
CASCADE_SAMPLES = 40
"""With per-drone solves (decoupled mode's condensed QPs, whose rows are dense over a drone's H d
inputs anyway) a cascade's tail takes up to this many exact samples before its hull. Over dt
0.05-0.1, horizons 3-30, v_max 0.3-3 m/s and a_max 0.2 m/s^2 to the default a planar quadrotor
needs up to 15 (cf21B_500; 7-24 tail points in all), a spatial one up to 32 (18-48 points: the
two loops' hull has 13-16 vertices and is wider). The chord is not shift-invariant (the shifted
plan's ``x_H`` is a point of the curved tail, off the chord its rows held), so decoupled plans on
it crept inside their tail rows, a few millimetres a step: a planar formation of 14 quadrotors in
a steady wind came to 0.562 m against d_min 0.599 m, and kept 0.614 m with the samples at 15 %
more CPU (in a joint QP, 3.3 times as much); a spatial swap of 21 came 1.3 mm inside d_min on the
chord and kept it with the samples at 3.7 times the CPU."""


@dataclass(frozen=True, eq=False)
class Tail:
    """The braking tail's points past the horizon, the rest (stop) point last: point t of a drone
    is ``gain x_H + sum_j forced[t, j] u_j + free[t] xi_0`` per axis (``gain`` (d,) the loop's DC
    gain, ``forced`` (T, H, d), ``free`` (T, d, s) on the loop state; None without a loop)."""

    gain: Array
    forced: Array
    free: Array | None

    @property
    def count(self) -> int:
        return int(self.forced.shape[0])

    @cached_property
    def support(self) -> Array:
        """The inputs j the points depend on (u_{H-1} alone without a loop)."""
        return np.flatnonzero(np.any(self.forced != 0.0, axis=(0, 2)))

    @cached_property
    def reach_s(self) -> float:
        """How far past ``g x_H`` the points lie at most, per m/s of the largest input component [s]."""
        return float(np.abs(self.forced).sum(axis=1).max())

    def points(self, x_last: Array, u: Array, state: Array | None = None) -> Array:
        """The tail points (T, n, d) of plans ending at ``x_last`` (n, d) with inputs ``u`` (H, n, d)
        from loop ``state`` (n, d, s) (ignored without a loop)."""
        out = self.gain * x_last + np.einsum("tjd,jnd->tnd", self.forced, u)
        if self.free is not None and state is not None:
            out += np.einsum("tds,nds->tnd", self.free, state)
        return out

    def free_response(self, state: Array) -> Array:
        """``free[t] xi_0`` (T, n, d) [m] of drones in loop ``state`` (n, d, s)."""
        if self.free is None:
            return np.zeros((self.count,) + state.shape[:2])
        return np.einsum("tds,nds->tnd", self.free, state)


def planner_tail(
    braking: Braking | None, settings: MPCSettings, dim: int, loop: VelocityLoop | None = None
) -> Tail | None:
    """The tail a planner with ``settings`` writes its rows at (None without ``braking``): its
    separation rows, condensed QPs and geofence all take this one."""
    if braking is None:
        return None
    return braking_tail(braking, settings.horizon, dim, loop, settings.solves_per_drone)


@lru_cache(maxsize=64)  # a planner's parts each ask for the same tail
def braking_tail(
    braking: Braking, horizon: int, dim: int, loop: VelocityLoop | None = None, per_drone: bool = False
) -> Tail:
    """The tail points of plans over ``horizon`` steps braking with ``braking`` (module
    docstring): the stop point alone without a ``loop`` or where its axes differ, else the tail's
    first K exact points (:data:`TAIL_SAMPLES`; a cascade's :data:`CASCADE_SAMPLES` when the QPs
    are solved ``per_drone``), the hull's vertices past them and the rest point."""
    gain = np.ones(dim) if loop is None else loop.dc_gain.copy()
    rest = np.zeros((1, horizon, dim))
    rest[0, -1] = braking.kappa_s * gain  # g (x_H + kappa u_{H-1}) (+ F_rest xi_0)
    if loop is None:
        return Tail(gain, rest, None)
    rest_free = loop.rest_m[None].copy()
    chord = with_offset(Tail(gain, rest, rest_free), loop, horizon)
    found = _hull(loop, braking, dim)
    if found is None:
        return chord
    group, systems, vertices = found
    s = vertices.shape[2] - 1  # the loop's states without the velocity offset
    first = np.unique(group, return_index=True)[1]  # an axis of each group
    powers, to_state = [], []  # per axis group: Phi^k (k = 0..H), xi_H per u_j (H, s)
    for axis in first:
        phi, gamma = loop.step_state[axis, :s, :s], loop.step_input[axis, :s]
        group_powers = [np.eye(s)]
        for _ in range(horizon):
            group_powers.append(phi @ group_powers[-1])
        powers.append(group_powers[horizon])
        to_state.append(np.array([group_powers[horizon - 1 - j] @ gamma for j in range(horizon)]))

    def at(functionals: Array) -> Tail:
        """The tail's points ``rest - W z`` (W (V, G, q): per axis group), the rest point last."""
        on_inputs = np.stack(
            [f[:, 1:] @ x.T for f, x in zip(functionals.swapaxes(0, 1), to_state, strict=True)], axis=2
        )
        on_inputs[:, -1] += functionals[:, :, 0]  # and its command part, c = u_{H-1}
        forced = rest - on_inputs[:, :, group]  # (V, H, d)
        free = np.broadcast_to(rest_free, (functionals.shape[0],) + rest_free.shape[1:]).copy()
        for g, power in enumerate(powers):
            free[:, group == g, :s] -= (functionals[:, g, 1:] @ power)[:, None, :]
        tail = Tail(gain, np.concatenate([forced, rest]), np.concatenate([free, rest_free]))
        return with_offset(tail, loop, horizon)

    def times(functionals: Array, matrices: list[Array]) -> Array:
        """Each group's functionals (V, G, q) times its matrix."""
        return np.stack([f @ m for f, m in zip(functionals.swapaxes(0, 1), matrices, strict=True)], axis=1)

    reach = TAIL_SPREAD * (braking.kappa_s * loop.speed_gain + loop.lag_s)
    samples: list[Array] = []  # L M^k, k = 1..K
    sample, ahead = vertices[:1], [np.eye(m.shape[0]) for m in systems]  # L M^K, M^K
    if s <= SAMPLED_STATES:
        most = TAIL_SAMPLES
    else:  # a quadrotor's cascade
        most = CASCADE_SAMPLES if per_drone else 0
    for _ in range(most + 1):
        hull = at(np.concatenate(samples + [times(vertices[1:], ahead)]))  # past W_0 = L
        if hull.reach_s <= reach:
            return hull
        sample, ahead = times(sample, systems), [a @ m for a, m in zip(ahead, systems, strict=True)]
        samples.append(sample)
    return chord


def with_offset(tail: Tail, loop: VelocityLoop, horizon: int) -> Tail:
    """``tail`` with the velocity offset ``delta`` persistent (:mod:`mpcform.mpc.velocity_loop`): the
    plan brakes the drone's velocity over ground, so its commands brake towards ``-delta``
    (:meth:`mpcform.mpc.constraints.braking.Braking.shifted`). With ``v = u + delta`` and the loop state
    ``xi + xi_ss delta`` (``xi_ss``: :attr:`~mpcform.mpc.velocity_loop.VelocityLoop.steady_state`) the
    drone moves as a loop in still air commanded ``v``, ``x_H + H dt delta`` at the horizon, so the
    offset's column is the tail of a drone in steady flight at 1 m/s: ``g H dt + sum_j forced[t, j] +
    free[t] xi_ss`` (a lag's stop point ``H dt + kappa + tau``: a drone holding in wind, ``u = -delta``,
    rests where it is)."""
    free = tail.free.copy()  # type: ignore[union-attr]
    steady = np.einsum("tds,ds->td", free[:, :, :-1], loop.steady_state)
    free[:, :, -1] = tail.gain * horizon * loop.dt_s + tail.forced.sum(axis=1) + steady
    return Tail(tail.gain, tail.forced, free)


def _hull(loop: VelocityLoop, braking: Braking, dim: int) -> tuple[Array, list[Array], Array] | None:
    """Each axis' group (d,) (axes whose tail systems are the same), the groups' tail systems ``M``
    (q, q) and their hull's vertex functionals (V, G, q), or None when the hull cannot be built (the
    chord then stands)."""
    group = np.zeros(dim, dtype=int)
    systems: list[tuple[Array, Array]] = []  # (M, L) of each group
    for axis in range(dim):
        m, ell = tail_system(loop, braking, axis)
        same = (
            g
            for g, (m0, l0) in enumerate(systems)
            if np.allclose(m, m0, rtol=0.0, atol=SAME_TOL) and np.allclose(ell, l0, rtol=0.0, atol=SAME_TOL)
        )
        group[axis] = next(same, len(systems))
        if group[axis] == len(systems):
            systems.append((m, ell))
    try:
        return group, [m for m, _ in systems], tail_hull(systems).vertices
    except (ValidationError, MPCFormError):  # poles the construction does not cover
        return None


@dataclass(frozen=True, eq=False)
class TailHull:
    """The vertex functionals ``vertices`` (V, G, q) on the tail states ``z`` (q,) of G axis groups
    and the nonnegative ``transition`` (V, V) with ``vertices[:, g] M_g = transition vertices[:, g]``
    for every group (row sums <= 1): one set of weights places every axis' point."""

    vertices: Array
    transition: Array


def tail_system(loop: VelocityLoop, braking: Braking, axis: int) -> tuple[Array, Array]:
    """``M`` (q, q) and ``L`` (q,) of ``axis``'s tail (module docstring), ``q = 1 + s``."""
    s = loop.step_state.shape[1] - 1  # the loop's states, without the velocity offset
    phi, gamma = loop.step_state[axis, :s, :s], loop.step_input[axis, :s]
    m = np.zeros((s + 1, s + 1))
    m[0, 0], m[1:, 0], m[1:, 1:] = braking.rho, braking.rho * gamma, phi
    return m, np.concatenate([[braking.kappa_s * loop.dc_gain[axis]], loop.rest_m[axis, :s]])


def tail_hull(systems: list[tuple[Array, Array]]) -> TailHull:
    """The hull (module docstring) of the tails ``L_g M_g^k z_g`` of the axis groups ``systems``
    (``(M_g, L_g)``): one real chain over every group's real poles, then each group's complex pair
    in its polygon, widened P times when P groups have one (the hull of the P polygons, each alone
    in its group: their sum lies in it, and each maps into itself)."""
    q = systems[0][0].shape[0]
    reals, pairs = _poles(systems)
    steps = _real_chain(reals)
    rows = [np.array([rest for _, rest in systems])]
    for d in steps:
        rows.append(
            np.array(
                [w @ (m - d * np.eye(q)) / (1.0 - d) for w, (m, _) in zip(rows[-1], systems, strict=True)]
            )
        )
    last = rows.pop()  # per group: 0 without a pair, else the pair's part
    v, paired = len(rows), [g for g, pair in enumerate(pairs) if pair.size]
    parts = [_polygon(last[g], systems[g][0], pairs[g][0]) for g in paired]
    n = sum(polygon.shape[0] for polygon, _ in parts)
    vertices, lam = np.zeros((v + n, len(systems), q)), np.zeros((v + n, v + n))
    vertices[:v] = rows
    into, at = np.zeros(n), v
    for g, (polygon, rotation) in zip(paired, parts, strict=True):
        k = polygon.shape[0]
        vertices[at : at + k, g] = len(parts) * polygon
        lam[at : at + k, at : at + k] = rotation
        into[at - v : at - v + k] = _weights(polygon, last[g]) / len(parts)
        at += k
    for j, d in enumerate(steps):
        lam[j, j] = d
        if j + 1 < v:
            lam[j, j + 1] = 1.0 - d
        else:  # into the polygons: the pairs' part is a convex combination of their vertices
            lam[j, v:] = (1.0 - d) * into
    return TailHull(vertices, lam)


def _poles(systems: list[tuple[Array, Array]]) -> tuple[list[Array], list[Array]]:
    """Each group's real poles (sorted) and its complex pair (its upper pole, or none); a
    :class:`ValidationError` for poles the construction does not cover."""
    reals, pairs = [], []
    for m, _ in systems:
        eig = np.linalg.eigvals(m)
        real, pair = np.sort(eig.real[np.abs(eig.imag) <= REAL_TOL]), eig[eig.imag > REAL_TOL]
        if real.size and (real.min() < 0.0 or real.max() >= 1.0) or np.any(np.abs(pair) >= 1.0):
            raise ValidationError(
                "plant", f"the braking tail needs a stable loop with poles in [0, 1): {eig}"
            )
        if pair.size > 1:
            raise ValidationError(
                "plant", "the braking tail's hull takes at most one complex pole pair per axis"
            )
        reals.append(real)
        pairs.append(pair)
    return reals, pairs


def _real_chain(reals: list[Array]) -> list[float]:
    """The real chain's poles, fastest first: every group's real poles, each as often as the group
    that has it most."""
    steps: list[float] = []
    for real in reals:
        for d in real:
            most = max(int(np.sum(np.abs(r - d) <= SAME_POLE)) for r in reals)
            if sum(abs(d - e) <= SAME_POLE for e in steps) < most:
                steps.append(float(d))
    return sorted(steps)


def _polygon(base: Array, m: Array, pole: complex) -> tuple[Array, Array]:
    """The N vertex functionals around the pair's part ``base`` (q,) and their transition (N, N)."""
    r, theta = abs(pole), float(np.angle(pole))
    n = max(3, int(np.ceil(np.pi / np.arccos(r) - 1e-12)))
    companion = np.array([[0.0, -r * r], [1.0, 2.0 * r * np.cos(theta)]])  # (a, b) of a base + b base M
    w, vecs = np.linalg.eig(companion)
    k = int(np.argmax(w.imag))
    basis = np.column_stack([vecs[:, k].real, vecs[:, k].imag])  # companion basis = basis rot
    y0 = np.linalg.solve(basis, np.array([1.0, 0.0]))
    angles = np.arctan2(y0[1], y0[0]) + 2.0 * np.pi * np.arange(n) / n
    corners = np.linalg.norm(y0) / np.cos(np.pi / n) * np.column_stack([np.cos(angles), np.sin(angles)])
    ab = corners @ basis.T  # (N, 2)
    polygon = ab[:, :1] * base + ab[:, 1:] * (base @ m)
    rotation = np.array([_weights(polygon, row) for row in polygon @ m])
    return polygon, rotation


def _weights(polygon: Array, row: Array) -> Array:
    """Nonnegative weights (N,) summing to at most 1 with ``weights @ polygon = row`` (a small LP:
    the row lies in the polygon by construction)."""
    n = polygon.shape[0]
    res = linprog(
        np.zeros(n), A_ub=np.ones((1, n)), b_ub=[1.0], A_eq=polygon.T, b_eq=row, bounds=[(0.0, None)] * n
    )
    if res.status != 0:
        raise MPCFormError("the braking tail's polygon does not hold its own rotation")
    return np.asarray(res.x)
