"""The planner online: measured positions in, full-state setpoints out, every step within a deadline.

Every control period a swarm's loop calls :meth:`OnlineLoop.step` with the time and the positions
motion capture measured; it gets back the certified command (``||u_i|| <= v_max``, each change
within ``a_max dt``) and the interval's full-state setpoints at the setpoint rate
(:func:`mpcform.control.setpoints.interval_setpoints`: the plan's own path from the measured
positions), which a Crazyflie's ``cmdFullState`` takes as they are.

The deadline is the planner's ``step_budget_s`` (:class:`mpcform.mpc.settings.MPCSettings`): no
optional split round starts too close to it (the step reports ``budget_cut``), and a step that ends
after it still sends its certified command, reported as ``deadline_missed`` (a late command is as
safe as a late fallback, and a swarm under a tight budget keeps moving). The check is cooperative:
a solver call is bounded by its iteration cap (``controller.solve.max_iter``), not interrupted, so a
step can end later than its budget by one solver call; :attr:`OnlineStep.wall_s` records it. Joint
coupling is planned online for at most :data:`JOINT_ONLINE_MAX_DRONES` drones.

A drone that can no longer follow its setpoints (flipped, on the floor: the Crazyflie's
supervisor reports it tumbled) is given up with :meth:`OnlineLoop.lose`: the planner stops
planning for it, the others keep ``d_min`` from where it lies (:mod:`mpcform.mpc.safety.survivors`),
and its command is zero from then on (its setpoints hold it where it is: stop or land it).

A planner with neither a velocity-loop model nor a robust tube (no plant margin, no tracking
allowance) plans for the ideal single integrator, not for a drone: :class:`OnlineLoop` warns once
(:class:`IdealPlanWarning`) when built on one.
"""

from __future__ import annotations

import dataclasses
import sys
import time
import warnings
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array, finite_array, positive
from mpcform.control.base import Controller, StepInfo
from mpcform.control.setpoints import FullState, interval_setpoints, ticks_per_interval
from mpcform.errors import ValidationError, shown
from mpcform.mpc.planner import MPCPlanner
from mpcform.scenario.build import build_controller
from mpcform.scenario.spec import Scenario

GRID_TOLERANCE = 1e-6
"""How far from the loop's grid ``t0 + k dt`` a step's time may be, as a fraction of dt."""


class IdealPlanWarning(UserWarning):
    """An online loop's planner plans for the ideal single integrator (module docstring)."""


IDEAL_PLAN = (
    "online: the planner plans for an ideal drone: it models no velocity loop (a [plant] other "
    "than ideal, with controller.plant_model = true) and keeps no tracking allowance "
    "(limits.tracking = 0), so a flown drone's lag may bring it closer than d_min; plan with a "
    'Crazyflie\'s defaults: mpcform.scenario.plant.with_plant_kind(scenario, "crazyflow") (its loop '
    "model and the 0.05 m tracking allowance), or at least scenario.flyable()"
)
"""The warning's text (:class:`IdealPlanWarning`)."""


JOINT_ONLINE_MAX_DRONES = 8
"""The largest swarm planned jointly online: measured per step on a 2-core machine, joint
``swap_planar_8`` p99 23 ms; ``swap_spatial_12`` over 0.1 s on 38 of 100 steps, ``swap_spatial_20``
p99 0.56 s (one sparse QP of ~1400 variables and ~10,000 rows). Decoupled plans scale."""


@dataclass(frozen=True, eq=False)
class OnlineStep:
    """One online step: the command (n, d) [m/s] held until the next step, its ``setpoints``, the
    planner's step record, its wall and CPU time [s] and whether it missed its deadline (the
    command, certified as any, then came late)."""

    t_s: float
    command_mps: Array
    setpoints: FullState
    info: StepInfo
    wall_s: float
    cpu_s: float
    deadline_missed: bool


class OnlineLoop:
    """An :class:`~mpcform.mpc.planner.MPCPlanner` stepped on measurements (module docstring);
    setpoints at ``setpoint_rate_hz`` (a multiple of ``1 / dt``), planar plans at ``altitude_m``.
    A planner for the ideal drone (no loop model, no margin, no tracking allowance) is warned of
    once, here (:class:`IdealPlanWarning`); joint coupling of more than
    :data:`JOINT_ONLINE_MAX_DRONES` drones is refused."""

    def __init__(
        self, planner: Controller, *, setpoint_rate_hz: float = 100.0, altitude_m: float = 1.0
    ) -> None:
        if not isinstance(planner, MPCPlanner):
            raise ValidationError("planner", f"expected an MPCPlanner, got {type(planner).__name__}")
        if planner.settings.coupling == "joint" and planner.n > JOINT_ONLINE_MAX_DRONES:
            raise ValidationError(
                "controller.coupling",
                f"joint coupling of {planner.n} drones is not planned online (its QP took 0.1-0.6 s "
                f"per step from 12 drones, past a 0.1 s period; up to {JOINT_ONLINE_MAX_DRONES} it "
                'flies): set coupling = "decoupled"',
            )
        if planner.loop is None and planner.limits.tube_m == 0.0:
            warnings.warn(IDEAL_PLAN, IdealPlanWarning, stacklevel=_outside_level())
        self._full = planner
        self.planner: Controller = planner  # after lose: the planner of the drones still flying
        self.n, self.dim = planner.n, planner.dim
        self.dt_s = planner.dt_s
        self.setpoint_rate_hz = positive("setpoint_rate", setpoint_rate_hz)
        ticks_per_interval(self.dt_s, self.setpoint_rate_hz)
        self.altitude_m = positive("altitude", altitude_m)
        self._started = False
        self._t0_s = 0.0  # the flight's first time: the steps fall on t0 + k dt
        self._last_s: float | None = None  # the last step's time (None: none since start)

    @classmethod
    def from_scenario(
        cls, scenario: Scenario, *, step_budget_s: float | None = None, setpoint_rate_hz: float = 100.0
    ) -> OnlineLoop:
        """The loop of ``scenario``'s MPC planner (its plant's velocity loop modelled, as in
        ``run``), with the deadline ``step_budget_s`` [s] (None: the scenario's
        ``controller.step_budget``); planar plans fly at the plant's ``altitude`` (1 m without)."""
        spec = scenario.controller
        if spec.kind != "mpc" or spec.mpc is None:
            raise ValidationError(
                "controller.kind", f"online planning needs the mpc controller, got {spec.kind!r}"
            )
        if step_budget_s is not None:
            mpc = dataclasses.replace(spec.mpc, step_budget_s=step_budget_s)
            scenario = dataclasses.replace(scenario, controller=dataclasses.replace(spec, mpc=mpc))
        planner = build_controller(scenario)
        altitude = float(getattr(scenario.plant, "altitude_m", 1.0))
        return cls(planner, setpoint_rate_hz=setpoint_rate_hz, altitude_m=altitude)

    def start(self, t_s: float, positions_m: ArrayLike) -> None:
        """Begin a flight at ``t_s`` [s] from ``positions_m`` (n, d): the planner of every drone,
        its plan forgotten."""
        t = _time(t_s)
        p = finite_array("positions", positions_m, (self.n, self.dim))
        self.planner = self._full
        self.planner.reset(t, p)
        self._started, self._t0_s, self._last_s = True, t, None

    def step(self, t_s: float, positions_m: ArrayLike) -> OnlineStep:
        """Plan from the measured ``positions_m`` (n, d) [m] at ``t_s`` [s]: the command to hold
        until ``t_s + dt`` and its full-state setpoints (module docstring). ``t_s`` is a real,
        finite time after the previous step's, on the flight's grid ``t0 + k dt`` (``t0`` the first
        step's, or :meth:`start`'s; within :data:`GRID_TOLERANCE` of dt); ``positions_m`` real and
        finite. A :class:`ValidationError` otherwise, before the planner is touched."""
        t = _time(t_s)
        p = finite_array("positions", positions_m, (self.n, self.dim))
        if self._started:
            self._check_on_grid(t)
        else:
            self.start(t, p)
        wall, cpu = time.perf_counter(), time.process_time()
        out = self.planner.step(t, p.copy())
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        self._last_s = t
        u = out.command_mps
        setpoints = interval_setpoints(p, u, t, self.dt_s, self.setpoint_rate_hz, self.altitude_m)
        missed = bool(getattr(out.info, "deadline_missed", False))
        return OnlineStep(t, u, setpoints, out.info, wall, cpu, missed)

    def _check_on_grid(self, t_s: float) -> None:
        last, dt = self._last_s, self.dt_s
        if last is not None and t_s <= last:
            raise ValidationError(
                "t_s",
                f"expected a time after the previous step's {last:g} s (start() begins a new "
                f"flight), got {t_s:g} s",
            )
        k = (t_s - self._t0_s) / dt
        if abs(k - round(k)) > GRID_TOLERANCE:
            raise ValidationError(
                "t_s",
                f"expected a time on the loop's grid {self._t0_s:g} s + k dt (dt = {dt:g} s), got "
                f"{t_s:g} s, {abs(k - round(k)):.3g} dt off",
            )

    def lose(self, drones: ArrayLike, positions_m: ArrayLike) -> None:
        """Stop planning for ``drones`` (lost: flipped, on the floor), the swarm at
        ``positions_m`` (n, d) [m] now (module docstring). ``drones``: integer indices in
        ``0..n-1``, or a boolean mask of length n (True: lost); anything else is refused."""
        lost = lost_indices(drones, self.n)
        p = finite_array("positions", positions_m, (self.n, self.dim))
        self.planner = self.planner.lose(lost, p)

    @property
    def lost_drones(self) -> Array:
        """The drones the loop no longer plans for (sorted)."""
        return self.planner.lost_drones


def lost_indices(drones: ArrayLike, n: int) -> Array:
    """The drones of ``drones`` as sorted indices: integer indices in ``0..n-1`` (a number: one),
    or a boolean mask of length ``n``; a :class:`ValidationError` naming ``drones`` otherwise (a
    mask is never read as indices, a float such as 1.5 never rounded)."""
    d = np.asarray(drones)
    expected = f"expected integer drone indices in 0..{n - 1} or a boolean mask of length {n}"
    if d.dtype.kind == "b":
        if d.shape != (n,):
            raise ValidationError("drones", f"{expected}: got a boolean mask of shape {d.shape}")
        return np.flatnonzero(d)
    if d.size == 0 and d.ndim == 1:
        return np.empty(0, dtype=int)
    if d.dtype.kind not in "iu" or d.ndim > 1:
        raise ValidationError("drones", f"{expected}, got {shown(drones)}")
    idx = np.unique(np.atleast_1d(d).astype(int))
    if idx[0] < 0 or idx[-1] >= n:
        bad = int(idx[0] if idx[0] < 0 else idx[-1])
        raise ValidationError("drones", f"{expected}: index {bad} is out of range")
    return idx


def _outside_level() -> int:
    """The ``stacklevel`` of its caller's first caller outside this module (the user's line,
    whether it built the loop or called :meth:`OnlineLoop.from_scenario`)."""
    frame, level = sys._getframe(1), 1
    while frame.f_back is not None and frame.f_code.co_filename == __file__:
        frame, level = frame.f_back, level + 1
    return level


def _time(t_s: object) -> float:
    """``t_s`` as a float: a real, finite number (not a bool, a string or a complex number)."""
    if isinstance(t_s, bool) or not isinstance(t_s, int | float | np.integer | np.floating):
        raise ValidationError("t_s", f"expected a real number of seconds, got {shown(t_s)}")
    if not np.isfinite(t_s):
        raise ValidationError("t_s", f"expected a finite time [s], got {t_s}")
    return float(t_s)


def step_time_stats(steps: list[OnlineStep]) -> dict[str, float]:
    """Median, p99 and max of the steps' wall and CPU times [s], and the share that missed its
    deadline."""
    wall = np.array([s.wall_s for s in steps])
    cpu = np.array([s.cpu_s for s in steps])
    out: dict[str, float] = {}
    for name, arr in (("wall", wall), ("cpu", cpu)):
        out |= {
            f"{name}_p50_s": float(np.median(arr)),
            f"{name}_p99_s": float(np.quantile(arr, 0.99)),
            f"{name}_max_s": float(arr.max()),
        }
    return out | {"deadline_miss_share": float(np.mean([s.deadline_missed for s in steps]))}
