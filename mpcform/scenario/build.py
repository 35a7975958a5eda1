"""The controller a scenario asks for: the one factory for runs, ``problems export`` and benchmarks."""

from __future__ import annotations

from mpcform.control.base import Controller
from mpcform.control.consensus import ConsensusController, ConsensusSettings
from mpcform.control.graph import GRAPH_KINDS
from mpcform.control.nullspace import NullSpaceController, NullSpaceSettings
from mpcform.control.tracking import ProportionalController, TrackingController
from mpcform.errors import ScenarioError, SolverError, ValidationError
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.strategy import with_backend
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.scenario.parse import as_scenario_error
from mpcform.scenario.schema import CONTROLLER_KINDS, did_you_mean, listing
from mpcform.scenario.spec import Scenario
from mpcform.solvers.base import QPBackend
from mpcform.solvers.registry import check_solver_name


def build_controller(
    scenario: Scenario, kind: str | None = None, solver: str | QPBackend | None = None
) -> Controller:
    """The scenario's controller; ``kind`` and ``solver`` override the file (CLI flags).

    ``solver`` is a backend name (checked like the ``controller.solver`` key) or a
    :class:`~mpcform.solvers.base.QPBackend` instance the MPC planner solves with as it is
    (e.g. a recording wrapper). The MPC planner keeps the limits tightened by the plant's robust
    margin (:func:`mpcform.world.bounds.planning_bounds`; nothing changes for the ideal plant).
    """
    spec = scenario.controller
    kind = spec.kind if kind is None else kind
    if kind not in CONTROLLER_KINDS:
        raise ScenarioError(
            "controller.kind",
            f"expected one of {listing(CONTROLLER_KINDS)}, "
            f"got {kind!r}{did_you_mean(kind, CONTROLLER_KINDS)}",
        )
    solver_name = solver.name if isinstance(solver, QPBackend) else solver
    if solver is not None and kind != "mpc":
        raise ScenarioError(
            "controller.solver",
            f"a solver ({solver_name!r}) applies only to the mpc controller, this run uses {kind!r}",
        )
    ref, dt, limits = scenario.reference, scenario.simulation.dt_s, scenario.limits
    v_max = limits.v_max_mps if spec.saturate else None
    with as_scenario_error("controller"):
        if kind == "proportional":
            return ProportionalController(ref, spec.gain_per_s, dt, v_max)
        if kind == "tracking":
            return TrackingController(ref, spec.gain_per_s, dt, v_max, spec.feedforward)
        if kind == "nullspace":
            settings = spec.nullspace or NullSpaceSettings(spec.gain_per_s, spec.feedforward)
            return NullSpaceController(ref, dt, settings, v_max)
        if kind == "consensus":
            if scenario.graph is None:
                raise ScenarioError(
                    "graph",
                    "missing table [graph]: the consensus controller needs a "
                    f"communication graph (kind = {listing(GRAPH_KINDS)})",
                )
            consensus = spec.consensus or ConsensusSettings(spec.gain_per_s)
            return ConsensusController(
                ref, scenario.graph, dt, consensus, v_max, scenario.network, scenario.allow_disconnected
            )
    from mpcform.mpc.planner import MPCPlanner

    backend: str | QPBackend | None = None
    if solver is not None:
        backend = solver if isinstance(solver, QPBackend) else check_solver_key(solver, "solver")
        check_sparse_solver(spec.mpc, "solver", backend)
    rob = scenario.robustness
    with as_scenario_error("plant"):
        planned, obstacles = scenario.planned()
    loop = None
    if rob.loop and spec.mpc.plant_model:
        loop = VelocityLoop.from_groups(list(rob.loop), scenario.dim, dt, spec.mpc.horizon)
    with as_scenario_error("controller"):
        planner: Controller = MPCPlanner(ref, dt, planned, spec.mpc, obstacles, backend, loop)
    return planner


def check_solver_key(name: str, field: str = "controller.solver") -> str:
    """Return ``name`` if it names a QP backend; else raise a :class:`ScenarioError` naming the
    scenario key ``field`` (where :func:`mpcform.solvers.registry.check_solver_name` raises a SolverError)."""
    try:
        return check_solver_name(name)
    except SolverError as exc:
        raise ScenarioError(field, str(exc)) from None


def check_sparse_solver(mpc: MPCSettings, field: str, solver: str | QPBackend) -> None:
    """A sparse backend named for a planner that solves per drone would be ignored: an error
    naming ``field`` (:func:`mpcform.mpc.strategy.with_backend`)."""
    try:
        with_backend(mpc.strategy, solver, field)
    except ValidationError as exc:
        raise ScenarioError(field, str(exc).removeprefix(f"{exc.field}: ")) from None
