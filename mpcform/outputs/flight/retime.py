"""One time scaling of the whole swarm's planned paths, from rest to rest (for flight exports).

The planned positions are a path ``P(tau)`` of the original time ``tau``: their degree-7
least-squares fit (:func:`mpcform.outputs.flight.polynomial.fit_positions`, continuous up to the jerk,
within half the export's tolerance; an interpolating spline would carry the kinks of the
held velocity commands into huge path accelerations). The export flies ``P(s(t))`` with one
``s(t)`` for every drone, at rest at both ends: the drones keep their relative timing, so they pass
the same places together as in the plan and the planned separation is kept along the paths.
``s(t)`` is the time-optimal scaling under the speed, acceleration and jerk limits
(:mod:`mpcform.outputs.flight.topp`): fast wherever the path allows it. :func:`minimum_time_s`
bounds the minimum time from below; the tests hold the scaling within 1.3 times it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike
from ruckig import InputParameter, Result, Ruckig
from ruckig import Trajectory as RuckigTrajectory
from scipy.integrate import trapezoid

from mpcform._validate import Array, positive
from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs.flight.polynomial import PiecewisePolynomial
from mpcform.outputs.flight.topp import time_optimal

GRID_S = 0.002  # sampling of s(t) [s]; its inverse is interpolated on this grid
SMOOTHING = 8  # sub-nodes per node of the smoothed scaling (topp.Profile.smoothed)
NODE_SPACING_S = 0.05  # plan time between the scaling's nodes [s], at most
NODES_PER_PIECE = 8  # at least, so that the limits hold between nodes too
MIN_NODES, MAX_NODES = 40, 4000
LENGTH_SAMPLES = 200  # per piece, for the drones' path lengths


@dataclass(frozen=True, eq=False)
class Retiming:
    """``s(t)`` sampled on ``t_s`` (original time ``tau_s`` at new time ``t_s``) and the path."""

    path: PiecewisePolynomial  # tau -> positions, series drone * 3 + axis
    t_s: Array  # (G,) new time grid, 0 .. duration_s
    tau_s: Array  # (G,) original time, non-decreasing
    tau_nodes_s: Array  # (K + 1,) the scaling's nodes in the original time
    slower: Array  # (K + 1,) >= 1: the limits were lowered at each node as a slow-down by it would

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1])

    def original_time(self, t_s: ArrayLike) -> Array:
        """``s(t)`` [s of the plan] at new times ``t_s``."""
        return np.interp(np.asarray(t_s, dtype=float), self.t_s, self.tau_s)

    def new_time(self, tau_s: ArrayLike) -> Array:
        """``s^-1(tau)``: when the retimed flight passes the plan's time ``tau_s``."""
        return np.interp(np.asarray(tau_s, dtype=float), self.tau_s, self.t_s)

    def slowed(self, factor: float) -> Retiming:
        """The same scaling ``factor`` times slower: speeds over ``factor``, accelerations over its
        square, jerks over its cube."""
        return replace(self, t_s=self.t_s * factor)

    def slower_where(self, t_s: Array, factor: Array) -> Array:
        """The nodes' slow-downs (:attr:`slower`) times the largest of ``factor`` (>= 1) at the new
        times ``t_s`` whose original time lies nearest each node: for :func:`retime` again."""
        nearest = np.rint(np.interp(self.original_time(t_s), self.tau_nodes_s, np.arange(self.slower.size)))
        local = np.ones_like(self.slower)
        np.maximum.at(local, nearest.astype(int), factor)
        return self.slower * local

    def positions(self, t_s: ArrayLike) -> Array:
        """Retimed positions ``P(s(t))`` (T, n, 3) [m]."""
        tau = self.original_time(t_s)
        return self.path.evaluate(tau).reshape(tau.shape[0], -1, 3)


def retime(
    path: PiecewisePolynomial,
    v_max_mps: float,
    a_max_mps2: float,
    j_max_mps3: float,
    *,
    max_duration_s: float = np.inf,
    slower: Array | None = None,
) -> Retiming:
    """The time-optimal rest-to-rest scaling of ``path`` (series drone * 3 + axis, from 0 s); a
    flight longer than ``max_duration_s`` raises :class:`ValidationError` naming the limit that
    sets its length, before its samples are allocated. ``slower`` (from
    :meth:`Retiming.slower_where`) lowers the limits at the nodes."""
    v, a, j = (
        positive(name, x)
        for name, x in (("max_speed", v_max_mps), ("max_acc", a_max_mps2), ("max_jerk", j_max_mps3))
    )
    end = path.duration_s
    floors = _duration_floors(path, v, a, j)
    _refuse_longer(float(max(floors)), max_duration_s, floors)
    tau_nodes, derivatives = _nodes(path)
    nodes = tau_nodes.shape[0]
    slower = np.ones(nodes) if slower is None else slower
    profile = time_optimal(derivatives, end / (nodes - 1), v, a, j, slower).smoothed(SMOOTHING)
    duration = profile.duration_s
    _refuse_longer(duration, max_duration_s, floors)
    t_fine = profile.node_times_s
    tau_fine = np.linspace(0.0, end, t_fine.shape[0])
    grid = np.append(np.arange(0.0, duration, GRID_S), duration)
    k = np.clip(np.searchsorted(t_fine, grid, side="right") - 1, 0, t_fine.shape[0] - 2)
    since = grid - t_fine[k]  # constant s'' on each sub-segment: s is quadratic in t there
    tau = tau_fine[k] + np.sqrt(profile.b[k]) * since + 0.5 * profile.segment_acc[k] * since**2
    tau = np.clip(np.maximum.accumulate(tau), 0.0, end)
    tau[-1] = end
    return Retiming(path, grid, tau, tau_nodes, slower)


def minimum_time_s(
    path: PiecewisePolynomial, v_max_mps: float, a_max_mps2: float, j_max_mps3: float
) -> float:
    """A lower bound on the shortest rest-to-rest flight along ``path`` within the limits: the
    largest of the time-optimal flight under speed and acceleration alone (with its limits held at
    the nodes, :data:`NODE_SPACING_S` of the plan apart), ruckig's time-optimal straight flight
    over the farthest drone's distance from start to end (the motion projected on that line starts
    and ends at rest within all three limits) and the longest path under each limit alone."""
    bound = max(_duration_floors(path, v_max_mps, a_max_mps2, j_max_mps3))
    tau, derivatives = _nodes(path)
    step = path.duration_s / (tau.shape[0] - 1)
    try:
        bound = max(bound, time_optimal(derivatives, step, v_max_mps, a_max_mps2, None).lower_bound_s)
    except MPCFormError:  # the scaling's program did not solve: the other bounds stand
        pass
    ends = path.evaluate(np.array([0.0, path.duration_s])).reshape(2, -1, 3)
    otg, inp, out = Ruckig(1), InputParameter(1), RuckigTrajectory(1)
    inp.current_position = [0.0]
    inp.target_position = [float(np.linalg.norm(ends[1] - ends[0], axis=-1).max())]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [v_max_mps], [a_max_mps2], [j_max_mps3]
    if otg.calculate(inp, out) in (Result.Working, Result.Finished):
        bound = max(bound, float(out.duration))
    return bound


def _nodes(path: PiecewisePolynomial) -> tuple[Array, tuple[Array, Array, Array]]:
    """The scaling's nodes in the plan's time and the path's first three derivatives there."""
    wanted = max(np.ceil(path.duration_s / NODE_SPACING_S), NODES_PER_PIECE * path.pieces)
    nodes = int(np.clip(wanted, MIN_NODES, MAX_NODES)) + 1
    tau = np.linspace(0.0, path.duration_s, nodes)
    d1, d2, d3 = (path.evaluate(tau, r).reshape(nodes, -1, 3) for r in (1, 2, 3))
    return tau, (d1, d2, d3)


def _duration_floors(path: PiecewisePolynomial, v: float, a: float, j: float) -> tuple[float, float, float]:
    """Shortest rest-to-rest times over the longest drone's path length ``L`` under each limit
    alone: ``L / v``, ``2 sqrt(L / a)`` and ``(32 L / j)^(1/3)``."""
    dense = np.linspace(0.0, path.duration_s, LENGTH_SAMPLES * path.pieces + 1)
    speed = np.linalg.norm(path.evaluate(dense, 1).reshape(dense.shape[0], -1, 3), axis=-1)
    length = float(trapezoid(speed, dense, axis=0).max())
    return length / v, 2.0 * np.sqrt(length / a), float(np.cbrt(32.0 * length / j))


def _refuse_longer(duration_s: float, max_duration_s: float, floors: tuple[float, float, float]) -> None:
    if duration_s > max_duration_s:
        name = ("max_speed", "max_acc", "max_jerk")[int(np.argmax(floors))]
        raise ValidationError(
            name,
            f"at this limit the retimed flight would last {duration_s:.3g} s, above the longest "
            f"export of {max_duration_s:.3g} s for this many drones: raise it",
        )
