"""A validated scenario: the library objects a scenario file describes (see :mod:`mpcform.scenario.load`)."""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpcform._validate import Array
from mpcform.control.consensus import ConsensusSettings, Network
from mpcform.control.graph import Graph
from mpcform.control.nullspace import NullSpaceSettings
from mpcform.formation.geometry import min_pair_distance, pairs_within
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.constraints.rows import step_growth
from mpcform.mpc.settings import MPCSettings
from mpcform.reference.base import Reference
from mpcform.scenario.reachability import TIMES, pace_warning, unreachable_warning
from mpcform.sim.plant_spec import IdealPlantSpec, PlantSpec, Robustness
from mpcform.world.bounds import PlanningBounds, planning_bounds
from mpcform.world.limits import PLATFORM_TRACKING_M, Limits
from mpcform.world.obstacles import Obstacle, resolve_clearances
from mpcform.world.world import World


@dataclass(frozen=True)
class ControllerSpec:
    """Controller ``kind`` and every parameter (defaults filled, ``mpc`` settings validated, the
    solve strategy among them); ``deprecations``: a line per key of the last release's spelling."""

    kind: str
    gain_per_s: float
    feedforward: str
    saturate: bool
    mpc: MPCSettings
    consensus: ConsensusSettings | None = None
    nullspace: NullSpaceSettings | None = None
    deprecations: tuple[str, ...] = ()


@dataclass(frozen=True)
class SimulationSpec:
    """Period ``dt_s`` [s], ``duration_s`` [s], process disturbance ``noise_std_m`` [m]."""

    dt_s: float
    duration_s: float
    noise_std_m: float = 0.0


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated scenario: ready-made library objects plus where it came from.

    ``initial_positions_m`` (n, d) [m] are where the drones start, the seeded perturbation
    included; ``start`` is the formation state the reference starts from (the best fit of
    explicit start positions). Where the reference puts the drones at t = 0 is
    ``reference.start_positions_m()``: not the start positions when the reference does not begin
    at the start formation (a constant reference holds its goal from t = 0, as in the swaps).
    ``obstacles`` have their clearances resolved (unset: half of ``limits.d_min_m``,
    :func:`mpcform.world.obstacles.resolve_clearances`) when the scenario is made.
    """

    name: str
    dim: int
    seed: int
    template: Template
    start: FormationState
    initial_positions_m: Array
    reference: Reference
    limits: Limits
    obstacles: tuple[Obstacle, ...]
    controller: ControllerSpec
    simulation: SimulationSpec
    source: Path | None = None
    source_sha256: str | None = None
    graph: Graph | None = None  # [graph] of the consensus controller (None: absent)
    network: Network = dataclasses.field(default_factory=Network)
    allow_disconnected: bool = False
    plant: PlantSpec = dataclasses.field(default_factory=IdealPlantSpec)
    unbounded: bool = False  # limits.unbounded: no d_min on purpose (no separation_warning)

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", resolve_clearances(tuple(self.obstacles), self.limits.d_min_m))

    @property
    def n(self) -> int:
        """Number of drones."""
        return self.template.n

    @property
    def world(self) -> World:
        """The limits and the (resolved) obstacles together."""
        return World(self.limits, self.obstacles)

    def planned(self) -> tuple[PlanningBounds, tuple[Obstacle, ...]]:
        """The bounds and obstacles its MPC keeps on its plant
        (:func:`mpcform.world.bounds.planning_bounds`)."""
        rob = self.robustness
        return planning_bounds(self.limits, self.obstacles, rob.margin_m, rob.a_max_mps2, rob.growth_m)

    @functools.cached_property
    def robustness(self) -> Robustness:
        """The plant's robust margin and the acceleration bound it assumes (zero for the ideal plant;
        only what its model leaves out when the MPC models the velocity loop)."""
        spec = self.controller
        modelled = spec.kind == "mpc" and spec.mpc.plant_model
        return self.plant.robustness(self.dim, self.simulation.dt_s, self.limits.a_max_mps2, modelled)

    def flyable(self) -> Scenario:
        """This scenario planned for a Crazyflie (``mpcform run --flyable``): its
        ``limits.tracking``, or the platform's :data:`~mpcform.world.limits.PLATFORM_TRACKING_M`
        where it is 0."""
        if self.limits.tracking_m > 0.0:
            return self
        return dataclasses.replace(
            self, limits=dataclasses.replace(self.limits, tracking_m=PLATFORM_TRACKING_M)
        )

    def warnings(self, controller: str | None = None) -> list[str]:
        """The warnings for a run with ``controller`` (None: the file's): the deprecated keys of the
        file, a duration that is no whole number of steps, a mission cut short, then the plant's
        spacing and speed warnings, the goals closed off by obstacles and a reference faster than
        the limits (:mod:`mpcform.scenario.reachability`)."""
        old = list(self.controller.deprecations)
        sim = self.simulation
        flown = self.steps * sim.dt_s
        if abs(flown - sim.duration_s) > 1e-9 * max(1.0, sim.duration_s):
            old.append(
                f"simulation.duration: {sim.duration_s:g} s is not a whole number of dt = {sim.dt_s:g} s "
                f"steps; the run takes {self.steps:,} steps ({flown:g} s)"
            )
        if self.goal_after_end() is not None:
            end = self.reference.duration_s  # type: ignore[attr-defined]
            old.append(
                f"simulation.duration: the run ends at {self.simulation.duration_s:g} s, before the "
                f"reference's end at {end:g} s; completion counts the reference's final targets"
            )
        if (controller or self.controller.kind) != "mpc":
            return old
        spacing = self.spacing_warning(controller) or self.growth_warning()
        lines = (
            self.separation_warning(),
            spacing,
            self.speed_warning(),
            self.unreachable_warning(),
            self.pace_warning(),
        )
        return old + [w for w in lines if w is not None]

    def separation_warning(self) -> str | None:
        """A line when an mpc run of two or more drones keeps no separation (no ``limits.d_min``),
        unless the file says it means it (``limits.unbounded = true``)."""
        lim = self.limits
        if self.unbounded or self.n < 2 or lim.d_min_m is not None:
            return None
        speed = " and no speed bound (no v_max)" if lim.v_max_mps is None else ""
        return (
            f"limits: no d_min: the mpc run keeps no separation between the drones{speed}; set "
            "limits.d_min (and v_max), or limits.unbounded = true to run without them"
        )

    def goal_after_end(self) -> Array | None:
        """The reference's final targets (n, d) when it ends after the run (a mission longer than
        ``simulation.duration``), else None."""
        end = getattr(self.reference, "duration_s", None)
        if end is None or end <= self.simulation.duration_s:
            return None
        return self.reference.targets(np.array([end]))[0][0]

    def unreachable_warning(self) -> str | None:
        """A line naming the drones whose final targets obstacles (and the fence) close off from
        their starts, with the planner's tightening (:mod:`mpcform.scenario.reachability`)."""
        if not self.obstacles:
            return None
        rob, reference = self.robustness, self.reference
        end = max(self.simulation.duration_s, getattr(reference, "duration_s", 0.0) or 0.0)
        times = np.linspace(0.0, end, TIMES + 1)
        targets = reference.targets(times)[0]
        args = (rob.margin_m, rob.a_max_mps2, self.initial_positions_m, times, targets)
        return unreachable_warning(self.limits, self.obstacles, *args)

    def pace_warning(self) -> str | None:
        """A line when the reference's targets, sampled at every step of the run, move faster than
        ``limits.v_max`` for a drone to catch up, or change velocity faster than ``limits.a_max``
        allows (:func:`mpcform.scenario.reachability.pace_warning`)."""
        lim, dt = self.limits, self.simulation.dt_s
        field = "" if lim.a_max_mps2 is None else f"limits.a_max = {lim.a_max_mps2:g} m/s^2"
        return pace_warning(
            lim, lim.a_max_mps2, dt, self.steps, lambda t: self.reference.targets(t)[1], field
        )

    def speed_warning(self) -> str | None:
        """A line when ``limits.v_max`` exceeds the speed below which the quadrotor's margin holds
        (:func:`mpcform.sim.margin.valid_speed`); None otherwise."""
        valid, v_max = self.robustness.valid_speed_mps, self.limits.v_max_mps
        if v_max is None or not v_max > valid:
            return None
        return (
            f"plant: its margin holds for commands below {valid:.3g} m/s (beyond, drag in the "
            "strongest wind plus a_max may exceed the tilt or thrust authority) and limits.v_max "
            f"is {v_max:.3g} m/s (lower limits.v_max, limits.a_max or the wind's bound)"
        )

    def spacing_warning(self, controller: str | None = None) -> str | None:
        """A line when the MPC cannot reach the final formation: its closest pair is nearer than
        ``d_min + 2 (margin + tracking) + controller.margin``, the distance the planner keeps
        between two drones (:func:`mpcform.world.bounds.planning_bounds`, then its rows' solver margin;
        ``d_min + controller.margin`` on the ideal plant); those drones then stop short of their
        targets. None otherwise (no d_min, a controller other than ``controller`` or the file's
        ``mpc``)."""
        rob = self.robustness
        if (controller or self.controller.kind) != "mpc" or self.limits.d_min_m is None:
            return None
        keep, solver = self._kept_m()
        near = self._closer_than(keep)
        if near is None:
            return None
        closest, pair = near
        tracking = self.limits.tracking_m
        rows = f" + controller.margin {solver:.3g} m" if solver > 0 else ""
        if rob.margin_m == 0.0 and tracking == 0.0:
            return (
                f"limits.d_min: the final formation's {pair} is {closest:.3g} m apart, below "
                f"d_min = {keep - solver:.3g} m{rows}: those drones stop short of their targets (widen the "
                "formation or lower limits.d_min)"
            )
        parts = [f"margin {rob.margin_m:.3g} m"] * (rob.margin_m > 0) + [f"tracking {tracking:.3g} m"] * (
            tracking > 0
        )
        field = "plant" if rob.margin_m > 0 else "limits.tracking"
        return (
            f"{field}: the final formation's {pair} is {closest:.3g} m apart, below the "
            f"{keep:.4g} m (d_min + 2 x ({' + '.join(parts)}){rows}) the MPC keeps: those drones "
            "stop short of their targets (widen the formation, lower limits.a_max or limits.tracking, "
            "or set plant.margin)"
        )

    def growth_warning(self) -> str | None:
        """A line when, in wind, the final formation's closest pair is nearer than the distance at
        which the MPC's rows grow along the horizon: the distance it keeps plus twice the growth at
        the horizon's end (:meth:`mpcform.mpc.constraints.separation.Separation.growing`). Those drones hold
        their targets with the one-interval margin alone, and gusts may need slack there (the
        theorem's premise needs the growth). None otherwise."""
        g = self.robustness.growth_m
        if self.controller.kind != "mpc" or self.limits.d_min_m is None or g <= 0.0:
            return None
        end = step_growth(g, self.simulation.dt_s, self.controller.mpc.horizon, 1)
        keep, grown = self._kept_m()[0], 0.0 if end is None else 2.0 * float(end[-1])
        near = self._closer_than(keep + grown)
        if near is None:
            return None
        closest, pair = near
        return (
            f"plant: in this wind the final formation's {pair} is {closest:.3g} m apart, below the "
            f"{keep + grown:.4g} m ({keep:.4g} m kept + {grown:.3g} m of the rows' growth) at which the "
            "MPC's rows grow: those drones hold their targets with the one-interval margin alone, and "
            "the gusts may need slack there (widen the formation or lower the wind's bound)"
        )

    def _kept_m(self) -> tuple[float, float]:
        """The distance [m] the MPC keeps between two drones, ``d_min + 2 (margin + tracking)`` plus
        its rows' solver margin, and that margin."""
        rob = self.robustness
        planned = planning_bounds(self.limits, (), rob.margin_m, rob.a_max_mps2)[0].d_min_m
        solver = self.controller.mpc.margin_m  # the rows ask for this much more (solver tolerance)
        return (planned or 0.0) + solver, solver

    def _closer_than(self, distance_m: float) -> tuple[float, str] | None:
        """The final formation's closest distance [m] and its pair's description when some pair is
        nearer than ``distance_m`` (at that distance exactly the rows are met); None otherwise."""
        final = self.reference.targets(np.array([self.simulation.duration_s]))[0][0]
        closest = min_pair_distance(final)  # inf for one drone
        if closest >= distance_m * (1.0 - 1e-12):
            return None
        near = pairs_within(final, distance_m * (1.0 - 1e-12))
        gaps = np.linalg.norm(final[near[:, 0]] - final[near[:, 1]], axis=1)
        i, k = near[int(np.argmin(gaps))].tolist()
        more = f", {near.shape[0] - 1} more pairs closer than it" if near.shape[0] > 1 else ""
        return closest, f"closest pair (drones {i} and {k}{more})"

    @property
    def steps(self) -> int:
        """Number of control steps."""
        return max(1, round(self.simulation.duration_s / self.simulation.dt_s))
