"""One time scaling of the whole swarm's planned paths, from rest to rest (for flight exports).

The planned positions are a path ``P(tau)`` of the original time ``tau``: their degree-7
least-squares fit (:func:`mpcform.outputs.flight.polynomial.fit_positions`, continuous up to the jerk,
within half the export's tolerance; an interpolating spline would carry the kinks of the
held velocity commands into huge path accelerations). The export
flies ``P(s(t))`` with one ``s(t)`` for every drone, planned by ruckig as a 1-DoF motion from
``s = 0`` to ``s = tau_end``, at rest (zero speed and acceleration) at both ends. The drones keep
their relative timing, so they pass the same places together as in the plan and the planned
separation is kept along the paths.

With ``P' = dP/dtau`` etc. and ``M1, M2, M3`` the largest norms of the first three path
derivatives over all drones, the chain rule gives ``|v| <= M1 s'``,
``|a| <= M2 s'^2 + M1 s''`` and ``|j| <= M3 s'^3 + 3 M2 s' s'' + M1 s'''``; the limits of ``s``
split each budget so the retimed path stays within ``v_max``, ``a_max`` and ``j_max``.
Offline ruckig only (``Ruckig(1)`` without intermediate waypoints): nothing reaches the network.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from ruckig import InputParameter, Result, Ruckig
from ruckig import Trajectory as RuckigTrajectory

from mpcform._validate import Array, positive
from mpcform.errors import MPCFormError, ValidationError
from mpcform.outputs.flight.polynomial import PiecewisePolynomial

GRID_S = 0.002  # sampling of s(t) [s]; its inverse is interpolated on this grid
DERIVATIVE_SAMPLES = 200  # per piece, to find the largest path derivatives


@dataclass(frozen=True, eq=False)
class Retiming:
    """``s(t)`` sampled on ``t_s`` (original time ``tau_s`` at new time ``t_s``) and the path."""

    path: PiecewisePolynomial  # tau -> positions, series drone * 3 + axis
    t_s: Array  # (G,) new time grid, 0 .. duration_s
    tau_s: Array  # (G,) original time, non-decreasing
    path_bounds: tuple[float, float, float]  # M1 [m/s], M2 [m/s^2], M3 [m/s^3] in original time
    scaling_limits: tuple[float, float, float]  # limits of s', s'', s''' given to ruckig

    @property
    def duration_s(self) -> float:
        return float(self.t_s[-1])

    def original_time(self, t_s: ArrayLike) -> Array:
        """``s(t)`` [s of the plan] at new times ``t_s``."""
        return np.interp(np.asarray(t_s, dtype=float), self.t_s, self.tau_s)

    def new_time(self, tau_s: ArrayLike) -> Array:
        """``s^-1(tau)``: when the retimed flight passes the plan's time ``tau_s``."""
        return np.interp(np.asarray(tau_s, dtype=float), self.tau_s, self.t_s)

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
) -> Retiming:
    """The rest-to-rest time scaling of ``path`` (series drone * 3 + axis, starting at 0 s); a
    flight longer than ``max_duration_s`` raises :class:`ValidationError` naming the limit that
    sets the speed of the scaling, before its samples are allocated."""
    v, a, j = (
        positive(name, x)
        for name, x in (("max_speed", v_max_mps), ("max_acc", a_max_mps2), ("max_jerk", j_max_mps3))
    )
    end = path.duration_s
    dense = np.linspace(0.0, end, DERIVATIVE_SAMPLES * path.pieces + 1)
    m1, m2, m3 = (
        max(
            float(np.linalg.norm(path.evaluate(dense, r).reshape(dense.shape[0], -1, 3), axis=-1).max()), 1e-9
        )
        for r in (1, 2, 3)
    )
    speeds = (v / m1, np.sqrt(0.5 * a / m2), np.cbrt(j / (3.0 * m3)))
    sd = min(speeds)
    sdd = min(0.5 * a / m1, j / (9.0 * m2 * sd))
    sddd = j / (3.0 * m1)
    otg, inp, out = Ruckig(1), InputParameter(1), RuckigTrajectory(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [0.0], [0.0]
    inp.target_position, inp.target_velocity, inp.target_acceleration = [end], [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [sd], [sdd], [sddd]
    result = otg.calculate(inp, out)
    if result not in (Result.Working, Result.Finished):
        raise MPCFormError(f"ruckig could not time the flight: {result}")
    if out.duration > max_duration_s:
        name = ("max_speed", "max_acc", "max_jerk")[int(np.argmin(speeds))]
        raise ValidationError(
            name,
            f"at this limit the retimed flight would last {out.duration:.3g} s, above the longest "
            f"export of {max_duration_s:.3g} s for this many drones: raise it",
        )
    grid = np.append(np.arange(0.0, out.duration, GRID_S), out.duration)
    tau = np.array([out.at_time(float(x))[0][0] for x in grid])
    tau = np.clip(np.maximum.accumulate(tau), 0.0, end)
    tau[-1] = end
    return Retiming(path, grid, tau, (m1, m2, m3), (float(sd), float(sdd), float(sddd)))
