"""mpcform: receding-horizon velocity planning for drone formations (centroid, rotation, scale).

The public API is re-exported here; :class:`MPCPlanner` is imported lazily on first use.
"""

from __future__ import annotations

from importlib import metadata
from typing import Any

from mpcform.consensus import ConsensusController, ConsensusSettings, Network
from mpcform.controllers import ProportionalController, TrackingController
from mpcform.errors import MPCFormError, ScenarioError, ValidationError
from mpcform.graph import Graph
from mpcform.kinematics import (
    fit_formation,
    formation_jacobian,
    forward_kinematics,
    jacobian_pinv,
    nullspace_projector,
)
from mpcform.limits import Limits, SphereObstacle
from mpcform.metrics import run_metrics
from mpcform.mission import Keyframe, MissionLimits, MissionReference, SpeedBudget
from mpcform.mpc_settings import MPCSettings
from mpcform.nullspace import NullSpaceController, NullSpaceSettings
from mpcform.reference import ConstantReference, ExponentialReference
from mpcform.scenario import load_scenario, run_scenario
from mpcform.simulation import simulate
from mpcform.state import FormationState
from mpcform.template import Template

try:
    __version__ = metadata.version("mpcform")
except metadata.PackageNotFoundError:
    __version__ = "0+unknown"

__all__ = [
    "ConsensusController",
    "ConsensusSettings",
    "ConstantReference",
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
    "ProportionalController",
    "ScenarioError",
    "SpeedBudget",
    "SphereObstacle",
    "Template",
    "TrackingController",
    "ValidationError",
    "__version__",
    "fit_formation",
    "formation_jacobian",
    "forward_kinematics",
    "jacobian_pinv",
    "load_scenario",
    "nullspace_projector",
    "run_metrics",
    "run_scenario",
    "simulate",
]


def __getattr__(name: str) -> Any:
    """Import :class:`MPCPlanner` (and its solver dependencies) only when it is used."""
    if name == "MPCPlanner":
        from mpcform.planner import MPCPlanner

        return MPCPlanner
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
