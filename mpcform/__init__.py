"""mpcform: receding-horizon velocity planning for drone formations (centroid, rotation, scale).

The public API is re-exported here; :class:`MPCPlanner` is imported lazily on first use.
"""

from __future__ import annotations

from importlib import metadata
from typing import Any

from mpcform.control.consensus import ConsensusController, ConsensusSettings, Network
from mpcform.control.graph import Graph
from mpcform.control.nullspace import NullSpaceController, NullSpaceSettings
from mpcform.control.tracking import ProportionalController, TrackingController
from mpcform.errors import MPCFormError, ScenarioError, ValidationError
from mpcform.formation.kinematics import (
    fit_formation,
    formation_jacobian,
    forward_kinematics,
    jacobian_pinv,
    nullspace_projector,
)
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.strategy import PerDroneSolve, SparseSolve, SplitPolicy
from mpcform.reference.base import ConstantReference, ExponentialReference
from mpcform.reference.keyframes import Keyframe, MissionLimits, SpeedBudget
from mpcform.reference.mission import MissionReference
from mpcform.run.heap import keep_heap
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario
from mpcform.sim.metrics import run_metrics
from mpcform.sim.simulation import simulate
from mpcform.solvers.base import SolverOptions
from mpcform.world.limits import Limits
from mpcform.world.shapes import Box, Cylinder, Sphere, SphereObstacle
from mpcform.world.world import World

try:
    __version__ = metadata.version("mpcform")
except metadata.PackageNotFoundError:
    __version__ = "0+unknown"

__all__ = [
    "Box",
    "ConsensusController",
    "ConsensusSettings",
    "ConstantReference",
    "Cylinder",
    "ExponentialReference",
    "FormationState",
    "Graph",
    "Keyframe",
    "Limits",
    "MPCFormError",
    "MPCPlanner",
    "MPCSettings",
    "MissionLimits",
    "MissionReference",
    "Network",
    "NullSpaceController",
    "NullSpaceSettings",
    "PerDroneSolve",
    "ProportionalController",
    "ScenarioError",
    "SolverOptions",
    "SparseSolve",
    "SpeedBudget",
    "Sphere",
    "SphereObstacle",
    "SplitPolicy",
    "Template",
    "TrackingController",
    "ValidationError",
    "World",
    "__version__",
    "fit_formation",
    "formation_jacobian",
    "forward_kinematics",
    "jacobian_pinv",
    "keep_heap",
    "load_scenario",
    "nullspace_projector",
    "run_metrics",
    "run_scenario",
    "simulate",
]


def __getattr__(name: str) -> Any:
    """Import :class:`MPCPlanner` (and its solver dependencies) only when it is used."""
    if name == "MPCPlanner":
        from mpcform.mpc.planner import MPCPlanner

        return MPCPlanner
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
