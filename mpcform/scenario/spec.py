"""Scenario files: a declarative schema of every TOML key, validated loading, and running.

The schema (:data:`SCHEMA`) is the one place that lists each table and key with its type,
default, unit and meaning: :func:`load_scenario` validates against it and
:func:`key_reference_markdown` renders it (``mpcform keys``, ``scenarios/README.md``).
Every problem in a file raises :class:`~mpcform.errors.ScenarioError` naming the key
(``controller.gain``), the value received and what was expected.
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import math
import re
import tomllib
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.control.base import FEEDFORWARDS, Controller, ProportionalController, TrackingController
from mpcform.control.consensus import (
    CONSENSUS_LAWS,
    RELATIVE_POSITIONS,
    ConsensusController,
    ConsensusSettings,
    Network,
)
from mpcform.control.graph import GRAPH_KINDS, Graph
from mpcform.control.laws import check_gain_dt
from mpcform.control.nullspace import OBJECTIVES, NullSpaceController, NullSpaceSettings
from mpcform.errors import ScenarioError, SolverError, ValidationError
from mpcform.formation.kinematics import fit_formation, forward_kinematics
from mpcform.formation.rotation import rotation_matrix
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.limits import Limits, SphereObstacle
from mpcform.mpc.settings import COUPLINGS, VELOCITY_SETS, MPCSettings
from mpcform.outputs.files import build_summary, write_outputs
from mpcform.reference.base import ConstantReference, ExponentialReference, Reference
from mpcform.reference.mission import DEFAULT_SPEED_FRACTION, MissionLimits, MissionReference, SpeedBudget
from mpcform.sim.metrics import run_metrics
from mpcform.sim.simulation import SimulationResult, simulate
from mpcform.solvers.registry import DEFAULT_SOLVER
from mpcform.solvers.registry import check_solver_name as check_backend_name

FORMAT_VERSION = 1
SHAPES = ("polygon", "ring", "line", "grid", "sphere", "explicit")
REFERENCE_KINDS = ("constant", "exponential", "mission")
CONTROLLER_KINDS = ("proportional", "tracking", "mpc", "consensus", "nullspace")
GRAPH_POINTS = ("template", "initial")


# ---- schema -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Key:
    """One scenario key.

    ``type``: ``int``, ``float``, ``bool``, ``string``, ``vector`` (d numbers), ``bounds``
    (d numbers, +-inf allowed), ``rotation`` (an angle for d = 2, a rotation vector for
    d = 3), ``points`` (rows of d numbers), ``indices`` (drone indices) or ``pairs`` (pairs
    of drone indices), ``table`` (an inline table, checked by its user) or ``tables`` (an
    array of tables). ``when`` lists the values of the table's
    selector key (``shape`` or ``kind``) the key applies to (empty: always). ``bound`` is a
    lower bound of numbers (``"> 0"``, ``">= 1"``). ``shown_default`` replaces the default in
    the docs.
    """

    name: str
    type: str
    doc: str
    unit: str = ""
    default: Any = None
    required: bool = False
    when: tuple[str, ...] = ()
    choices: tuple[Any, ...] = ()
    bound: str = ""
    shown_default: str | None = None


@dataclass(frozen=True)
class Table:
    """A scenario table (``""``: the top level); ``selector`` names the key choosing a variant."""

    name: str
    doc: str
    keys: tuple[Key, ...]
    required: bool = True
    selector: str | None = None
    array: bool = False

    def key(self, name: str) -> Key:
        return next(k for k in self.keys if k.name == name)

    @property
    def title(self) -> str:
        if not self.name:
            return "Top level"
        return f"[[{self.name}]]" if self.array else f"[{self.name}]"


_MPC_DEFAULTS = {f.name: f.default for f in dataclasses.fields(MPCSettings)}
_MPC = ("mpc",)
_GOAL = ("constant", "exponential")
_MISSION = ("mission",)
# scenario key -> MPCSettings field (the remaining mpc keys share their name with the field)
MPC_FIELDS = {"gain": "gain_per_s", "margin": "margin_m", "tie_break": "tie_break_rad",
              "time_limit": "time_limit_s"}  # fmt: skip


def _mpc_key(name: str, type_: str, doc: str, unit: str = "", **kw: Any) -> Key:
    default = _MPC_DEFAULTS[MPC_FIELDS.get(name, name)]
    return Key(name, type_, doc, unit, default, when=_MPC, **kw)


# scenario key -> ConsensusSettings / NullSpaceSettings field (others share the field's name)
CONSENSUS_FIELDS = {"gamma": "gamma_per_s", "leader_gain": "leader_gain_per_s"}
NULLSPACE_FIELDS = {"repulsion_radius": "repulsion_radius_m", "repulsion_gain": "repulsion_gain_per_s"}
_CONSENSUS_DEFAULTS = {f.name: f.default for f in dataclasses.fields(ConsensusSettings)}
_NULLSPACE_DEFAULTS = {f.name: f.default for f in dataclasses.fields(NullSpaceSettings)}


def _consensus_key(name: str, type_: str, doc: str, unit: str = "", **kw: Any) -> Key:
    default = _CONSENSUS_DEFAULTS[CONSENSUS_FIELDS.get(name, name)]
    return Key(name, type_, doc, unit, default, when=("consensus",), **kw)


def _nullspace_key(name: str, type_: str, doc: str, unit: str = "", **kw: Any) -> Key:
    default = _NULLSPACE_DEFAULTS[NULLSPACE_FIELDS.get(name, name)]
    return Key(name, type_, doc, unit, default, when=("nullspace",), **kw)


SCHEMA: tuple[Table, ...] = (
    Table("", "Scenario identity.", (
        Key("version", "int", "Scenario format version.", required=True, choices=(FORMAT_VERSION,)),
        Key("name", "string", "Run name; default output directory is `results/<name>/`.",
            shown_default="file name without .toml"),
        Key("dim", "int", "Spatial dimension: 2 (planar) or 3 (spatial).", required=True,
            choices=(2, 3)),
        Key("seed", "int", "Seed of the initial perturbation, the simulation noise and the "
            "packet losses of [graph].",
            default=0, bound=">= 0"),
    )),
    Table("template", "Formation shape: centred offsets r_i (seed eq. 10).", (
        Key("shape", "string", "Template family; `explicit` takes `offsets`.", required=True,
            choices=SHAPES),
        Key("n", "int", "Number of drones.", required=True,
            when=("polygon", "ring", "line", "sphere"), bound=">= 1"),
        Key("radius", "float", "Circumradius.", "m", 1.0, when=("polygon", "ring", "sphere"),
            bound="> 0"),
        Key("phase", "float", "Angle of the first vertex about z.", "rad", 0.0,
            when=("polygon", "ring")),
        Key("spacing", "float", "Distance between neighbours.", "m", 1.0, when=("line", "grid"),
            bound="> 0"),
        Key("rows", "int", "Grid rows (along x).", required=True, when=("grid",), bound=">= 1"),
        Key("cols", "int", "Grid columns (along y).", required=True, when=("grid",), bound=">= 1"),
        Key("layers", "int", "Grid layers (along z, spatial only).", default=1, when=("grid",),
            bound=">= 1"),
        Key("offsets", "points", "Offsets r_i, one row per drone; their mean must be zero.", "m",
            required=True, when=("explicit",)),
    ), selector="shape"),
    Table("initial", "Start: a formation state, or explicit `positions` (not both).", (
        Key("centroid", "vector", "Start centroid c.", "m",
            shown_default="required unless `positions`"),
        Key("rotation", "rotation", "Start rotation: angle (d = 2) or rotation vector (d = 3).",
            "rad", shown_default="0 (identity)"),
        Key("scale", "float", "Start scale s.", shown_default="1", bound="> 0"),
        Key("positions", "points", "Explicit start positions, one row per drone (n x d).", "m"),
        Key("perturbation", "float", "Std of seeded Gaussian offsets added to the start.", "m",
            0.0, bound=">= 0"),
    )),
    Table("reference", "Desired formation trajectory, starting at the initial formation state "
          "(or the best fit of explicit positions).", (
        Key("kind", "string", "`constant`: hold the goal; `exponential`: eq. 16 towards it; "
            "`mission`: keyframes smoothed by ruckig (jerk-limited, time-optimal per move).",
            required=True, choices=REFERENCE_KINDS),
        Key("centroid", "vector", "Goal centroid.", "m", shown_default="start centroid",
            when=_GOAL),
        Key("rotation", "rotation", "Goal rotation: angle (d = 2) or rotation vector (d = 3).",
            "rad", shown_default="start rotation", when=_GOAL),
        Key("scale", "float", "Goal scale s*.", "", shown_default="start scale", bound="> 0",
            when=_GOAL),
        Key("rate", "float", "Convergence rate lambda of eq. 16.", "1/s", required=True,
            when=("exponential",), bound="> 0"),
        Key("keyframes", "tables", "The mission's keyframes in order: `[[reference.keyframes]]` "
            "tables (keys below).", required=True, when=_MISSION),
        Key("speed_fraction", "float", "With `limits.v_max`: limits derived so that every "
            "drone's reference speed stays below speed_fraction * v_max (at most 1).",
            shown_default=f"{DEFAULT_SPEED_FRACTION:g} (with v_max)", when=_MISSION, bound="> 0"),
        Key("drone_acceleration", "float", "With `limits.v_max`: budget of the drones' "
            "along-path reference acceleration.", "m/s^2",
            shown_default="speed_fraction * limits.a_max, else speed budget per 1 s",
            when=_MISSION, bound="> 0"),
        Key("drone_jerk", "float", "With `limits.v_max`: budget of the drones' along-path "
            "reference jerk.", "m/s^3", shown_default="drone_acceleration per 0.5 s",
            when=_MISSION, bound="> 0"),
        Key("max_velocity", "table", "Explicit bounds per DOF group, e.g. `{ centroid = 2.0, "
            "scale = 0.5 }`: `centroid` [m/s] (on the norm), `rotation` [rad/s], `scale` and "
            "`blend` [1/s]; the smaller of these and the derived limits applies.",
            "per group", when=_MISSION),
        Key("max_acceleration", "table", "Explicit bounds per DOF group, as `max_velocity` "
            "(units per s^2).", "per group", when=_MISSION),
        Key("max_jerk", "table", "Explicit bounds per DOF group, as `max_velocity` (units "
            "per s^3).", "per group", when=_MISSION),
    ), selector="kind"),
    Table("reference.keyframes", "Mission keyframes (`kind = \"mission\"`), reached one after "
          "the other at rest; unset keys keep the previous keyframe's value.", (
        Key("centroid", "vector", "Centroid c.", "m", shown_default="previous"),
        Key("rotation", "rotation", "Orientation: angle (d = 2) or rotation vector (d = 3); "
            "the turn takes the shortest way (at most half a turn per keyframe).", "rad",
            shown_default="previous"),
        Key("scale", "float", "Scale s.", shown_default="previous", bound="> 0"),
        Key("hold", "float", "Time to stay at the keyframe after reaching it.", "s", 0.0,
            bound=">= 0"),
        Key("template", "table", "Switch to this template (same n; keys of [template], e.g. "
            "`{ shape = \"line\", n = 6 }`): drones are assigned optimally and blended during "
            "the move; warns when the ends are closer than sqrt(2) * d_min (CAPT)."),
    ), required=False, array=True),
    Table("limits", "Physical limits; each unset one is not enforced.", (
        Key("v_max", "float", "Speed bound per drone.", "m/s", bound="> 0"),
        Key("d_min", "float", "Minimum distance between two drones.", "m", bound="> 0"),
        Key("a_max", "float", "Componentwise bound on command changes (mpc).", "m/s^2",
            bound="> 0"),
        Key("geofence_min", "bounds", "Lower corner of the allowed box (mpc; -inf: open).", "m"),
        Key("geofence_max", "bounds", "Upper corner of the allowed box (mpc; inf: open).", "m"),
        Key("downwash", "float", "Vertical separation factor kappa (spatial, mpc).", "",
            bound=">= 1"),
    ), required=False),
    Table("controller", "Controller and its parameters; `mpcform run --controller` overrides "
          "`kind`, then keys of other kinds take their defaults.", (
        Key("kind", "string", "Controller.", required=True, choices=CONTROLLER_KINDS),
        Key("gain", "float", "Feedback gain k (eq. 4, 14; the formation gain of eq. 20 for "
            "consensus); gain * dt must be <= 1.", "1/s", 1.0,
            bound="> 0"),
        Key("feedforward", "string", "`jacobian` (J xi_dot, eq. 14) or `secant` "
            "((p*(t+dt) - p*(t))/dt, exact in discrete time).", default="jacobian",
            when=("tracking", "mpc", "nullspace"), choices=FEEDFORWARDS),
        Key("saturate", "bool", "Saturate commands at limits.v_max (eq. 7) when it is set.",
            default=True, when=("proportional", "tracking", "consensus", "nullspace")),
        _consensus_key("law", "string", "`eq20`: seed eq. 20 as printed (the centroid drifts "
                       "during scale transients); `centroid_preserving`: u_i = -k sum_j [(p_i - "
                       "p_j) - R (s_i r_i - s_j r_j)] (sum_i u_i = 0).", choices=CONSENSUS_LAWS),
        _consensus_key("gamma", "float", "Scale-estimate consensus gain gamma (eq. 20).", "1/s",
                       bound="> 0"),
        _consensus_key("leader_gain", "float", "Leader input lambda (s*(t) - s_hat_L), s*(t) "
                       "the reference's scale.", "1/s", bound="> 0"),
        _consensus_key("leaders", "indices", "Drones whose estimate follows the commanded scale.",
                       shown_default="[0]"),
        _consensus_key("initial_scale", "float", "Every scale estimate's start value.",
                       shown_default="best-fit scale of the start positions", bound="> 0"),
        _nullspace_key("objective", "string", "Secondary objective projected by N = I - J J^+ "
                       "(corrected eq. 15): `repulsion`, `energy` (smallest command with the "
                       "same formation velocity) or `none`.", choices=OBJECTIVES),
        _nullspace_key("repulsion_radius", "float", "Pairs closer than this repel.", "m",
                       shown_default="1.5 * limits.d_min", bound="> 0"),
        _nullspace_key("repulsion_gain", "float", "Repulsion gain c: push c (radius - d).", "1/s",
                       bound="> 0"),
        _nullspace_key("energy_weight", "float", "Weight w in [0, 1] of the energy objective "
                       "(1: minimum norm; shape errors are then not corrected).", bound=">= 0"),
        _mpc_key("horizon", "int", "Plan length H in steps.", bound=">= 1"),
        _mpc_key("velocity_set", "string", "Speed constraint set inscribed in the ball.",
                 choices=VELOCITY_SETS),
        _mpc_key("facets", "int", "Half-spaces of the velocity polytope (auto: 16 planar, "
                 "32 spatial).", bound=">= 4", shown_default="auto"),
        _mpc_key("slack_weight", "float", "Exact L1 penalty on separation slack.", "1/m",
                 bound="> 0"),
        _mpc_key("slack_quadratic", "float", "Quadratic slack penalty (conditioning).", "1/m^2",
                 bound=">= 0"),
        _mpc_key("margin", "float", "Tightening of separation and obstacle rows.", "m",
                 bound=">= 0"),
        _mpc_key("tie_break", "float", "Right turn of conflicted drones' desired velocities, "
                 "so symmetric swaps circulate; grows while a drone stays stalled (0: off).", "rad",
                 bound=">= 0"),
        _mpc_key("coupling", "string", "`joint` pair rows, or `decoupled` per-drone rows about "
                 "the pair midpoint (block-diagonal QP, for large swarms).", choices=COUPLINGS),
        _mpc_key("per_drone", "bool", "With `decoupled`: solve each conflicted drone's QP with DAQP "
                 "(small dense QPs, the fast way; of the solver keys only `max_iter` applies) instead "
                 "of one sparse QP with `solver`."),
        _mpc_key("grouping", "bool", "Solve only the groups of drones that hold a conflict; the others "
                 "take their eq. 14 rollout (exact)."),
        _mpc_key("fast_path", "bool", "Skip the solver when the eq. 14 rollout meets every row."),
        _mpc_key("eps_abs", "float", "Solver absolute tolerance.", bound="> 0"),
        _mpc_key("eps_rel", "float", "Solver relative tolerance.", bound=">= 0"),
        _mpc_key("max_iter", "int", "Solver iteration limit.", bound=">= 1"),
        _mpc_key("time_limit", "float", "Solver time limit per QP (0: none).", "s", bound=">= 0"),
        Key("solver", "string", "QP backend: `osqp`, `piqp`, `qpsolvers:<name>`, "
            "`casadi:<plugin>` (see `mpcform solvers`); `--solver` overrides it. Not with "
            "`decoupled` and `per_drone`.",
            when=_MPC, shown_default=f'"{DEFAULT_SOLVER}"'),
    ), selector="kind"),
    Table("graph", "Communication graph of the consensus controller, undirected, and its link "
          "effects; other controllers ignore it.", (
        Key("kind", "string", "`complete`, `ring` (i talks to i +- 1), `path`, `k_nearest`, "
            "`disk` (within `radius`) or `explicit` (`edges`).", required=True,
            choices=GRAPH_KINDS),
        Key("k", "int", "Neighbours per drone (the graph is symmetrised).", required=True,
            when=("k_nearest",), bound=">= 1"),
        Key("radius", "float", "Communication range.", "m", required=True, when=("disk",),
            bound="> 0"),
        Key("on", "string", "Positions the geometric graph is built on: template offsets r_i or "
            "the initial positions.", default="template", when=("k_nearest", "disk"),
            choices=GRAPH_POINTS),
        Key("edges", "pairs", "Undirected edges [i, j] (drone indices from 0).", required=True,
            when=("explicit",)),
        Key("allow_disconnected", "bool", "Run on a disconnected graph with a warning instead "
            "of an error (consensus cannot be reached).", default=False),
        Key("delay_steps", "int", "Whole control steps between a broadcast and its delivery.",
            default=0, bound=">= 0"),
        Key("loss_probability", "float", "Chance that one message on one directed link is lost "
            "(seeded by `seed`; a drone keeps the last value it received); below 1.",
            default=0.0, bound=">= 0"),
        Key("relative_positions", "string", "`communicated`: neighbours' positions are delayed "
            "and lost like the scale estimates; `sensed`: measured on board, always current.",
            default="communicated", choices=RELATIVE_POSITIONS),
    ), required=False, selector="kind"),
    Table("simulation", "Closed-loop simulation (zero-order hold, exact single integrator).", (
        Key("dt", "float", "Control period.", "s", required=True, bound="> 0"),
        Key("duration", "float", "Simulated time.", "s", required=True, bound="> 0"),
        Key("lag", "float", "Time constant of a first-order velocity lag (0: none).", "s", 0.0,
            bound=">= 0"),
        Key("noise", "float", "Std of seeded Gaussian position disturbances per step.", "m", 0.0,
            bound=">= 0"),
    )),
    Table("obstacles", "Static spheres (discs when planar); repeat the table for more.", (
        Key("center", "vector", "Centre.", "m", required=True),
        Key("radius", "float", "Radius.", "m", required=True, bound="> 0"),
        Key("clearance", "float", "Distance kept from the surface.", "m",
            shown_default="d_min / 2", bound=">= 0"),
    ), required=False, array=True),
)  # fmt: skip
TABLES = {t.name: t for t in SCHEMA}


# ---- parsed scenario ----------------------------------------------------------------------
@dataclass(frozen=True)
class ControllerSpec:
    """Controller ``kind`` and every parameter (defaults filled, ``mpc`` settings validated)."""

    kind: str
    gain_per_s: float
    feedforward: str
    saturate: bool
    mpc: MPCSettings
    solver: str
    consensus: ConsensusSettings | None = None
    nullspace: NullSpaceSettings | None = None


@dataclass(frozen=True)
class SimulationSpec:
    """Period ``dt_s`` [s], ``duration_s`` [s], velocity ``lag_s`` [s], ``noise_std_m`` [m]."""

    dt_s: float
    duration_s: float
    lag_s: float = 0.0
    noise_std_m: float = 0.0


@dataclass(frozen=True, eq=False)
class Scenario:
    """A validated scenario: ready-made library objects plus where it came from.

    ``start`` is the reference's initial formation state; ``initial_positions_m`` (n, d)
    includes the seeded perturbation.
    """

    name: str
    dim: int
    seed: int
    template: Template
    start: FormationState
    initial_positions_m: Array
    reference: Reference
    limits: Limits
    obstacles: tuple[SphereObstacle, ...]
    controller: ControllerSpec
    simulation: SimulationSpec
    source: Path | None = None
    source_sha256: str | None = None
    graph: Graph | None = None  # [graph] of the consensus controller (None: absent)
    network: Network = dataclasses.field(default_factory=Network)
    allow_disconnected: bool = False

    @property
    def n(self) -> int:
        """Number of drones."""
        return self.template.n

    @property
    def steps(self) -> int:
        """Number of control steps."""
        return max(1, round(self.simulation.duration_s / self.simulation.dt_s))


@dataclass(frozen=True)
class RunResult:
    """Outcome of :func:`run_scenario`: the time series, the summary dict, the output dir."""

    simulation: SimulationResult
    summary: dict[str, Any]
    out_dir: Path | None


# ---- loading ------------------------------------------------------------------------------
def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario TOML file; raises :class:`ScenarioError` on any problem."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ScenarioError(str(path), "no such scenario file") from None
    except OSError as exc:
        raise ScenarioError(str(path), f"cannot read the file: {exc.strerror}") from None
    text = raw.decode("utf-8", errors="replace")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        hint = _line_hint(text, str(exc))
        raise ScenarioError(str(path), f"TOML syntax error: {exc}{hint}") from None
    return scenario_from_dict(
        data, source=path, source_sha256=hashlib.sha256(raw).hexdigest(), default_name=path.stem
    )


def scenario_from_dict(
    data: Mapping[str, Any],
    *,
    source: Path | None = None,
    source_sha256: str | None = None,
    default_name: str = "scenario",
) -> Scenario:
    """Validate an already parsed scenario (the TOML document as a dict)."""
    top = _parse_top(data)
    dim, seed = top["dim"], top["seed"]
    tpl = _template(_table(data, "template", dim), dim)
    init = _table(data, "initial", dim, tpl.n)
    start, positions = _initial(tpl, init)
    limits = _limits(_table(data, "limits", dim), dim)
    reference = _reference(tpl, start, _table(data, "reference", dim), limits)
    sim = SimulationSpec(**_renamed(_table(data, "simulation", dim), "simulation"))
    controller = _controller(_table(data, "controller", dim), sim.dt_s)
    controller = _decentralised_settings(controller, _table(data, "controller", dim), limits)
    if sim.duration_s < sim.dt_s:
        raise ScenarioError(
            "simulation.duration", f"expected at least one step, dt = {sim.dt_s:g} s; "
            f"got {sim.duration_s:g} s",
        )  # fmt: skip
    if init["perturbation"] > 0.0:
        rng = np.random.default_rng([seed, 1])  # independent of the simulation noise (seed)
        positions = positions + rng.normal(0.0, init["perturbation"], positions.shape)
    positions.setflags(write=False)
    return Scenario(
        name=top["name"] if top["name"] is not None else default_name,
        dim=dim,
        seed=seed,
        template=tpl,
        start=start,
        initial_positions_m=positions,
        reference=reference,
        limits=limits,
        obstacles=_obstacles(data.get("obstacles"), dim),
        **_graph(data, tpl, positions, seed),
        controller=controller,
        simulation=sim,
        source=source,
        source_sha256=source_sha256,
    )


def _parse_top(data: Mapping[str, Any]) -> dict[str, Any]:
    top = TABLES[""]
    scalars = {k: v for k, v in data.items() if k not in TABLES or not k}
    for name, value in scalars.items():
        if not any(k.name == name for k in top.keys):
            is_table = isinstance(value, dict) or (
                isinstance(value, list) and value and all(isinstance(v, dict) for v in value)
            )
            what = "table" if is_table else "key"
            choices = [t.name for t in SCHEMA if t.name] if is_table else _names(top)
            raise ScenarioError(name, f"unknown {what}{_did_you_mean(name, choices)}")
    for name in TABLES:
        if name and name in data and name != "obstacles" and not isinstance(data[name], dict):
            raise ScenarioError(name, f"expected a table [{name}], got {data[name]!r}")
    values = _parse_keys(top, scalars, "", dim=2, n=None)
    name = values["name"]
    if name is not None and (not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", name)):
        raise ScenarioError("name", f"expected letters, digits, '_', '-' or '.' (it names the "
                            f"output directory), got {name!r}")  # fmt: skip
    return values


def _table(data: Mapping[str, Any], name: str, dim: int, n: int | None = None) -> dict[str, Any]:
    table = TABLES[name]
    raw = data.get(name)
    if raw is None:
        if table.required:
            raise ScenarioError(name, f"missing table [{name}] ({table.doc})")
        raw = {}
    return _parse_keys(table, raw, name, dim, n)


def _parse_keys(table: Table, raw: Mapping[str, Any], prefix: str, dim: int, n: int | None) -> dict[str, Any]:
    """Check names, types and ranges of one table's keys; fill defaults (None = unset)."""
    for name in raw:
        if not any(k.name == name for k in table.keys):
            where = f" in {table.title}" if table.name else ""
            raise ScenarioError(
                _field(prefix, name), f"unknown key{where}{_did_you_mean(name, _names(table))}"
            )
    variant = None
    if table.selector is not None:
        sel = table.key(table.selector)
        if table.selector not in raw:
            raise ScenarioError(_field(prefix, sel.name), f"missing required key ({sel.doc})")
        variant = _convert(sel, raw[sel.name], _field(prefix, sel.name), dim, n)
    out: dict[str, Any] = {}
    for key in table.keys:
        field = _field(prefix, key.name)
        applies = not key.when or variant in key.when
        if key.name not in raw:
            if key.required and applies:
                raise ScenarioError(field, f"missing required key ({key.doc})")
            out[key.name] = key.default if applies else None
        elif not applies:
            raise ScenarioError(
                field,
                f"does not apply to {table.selector} = {variant!r} "
                f"(only to {', '.join(repr(w) for w in key.when)})",
            )
        else:
            out[key.name] = _convert(key, raw[key.name], field, dim, n)
    return out


def _convert(key: Key, value: Any, field: str, dim: int, n: int | None) -> Any:
    """The value of ``key`` as a Python or numpy object, or a ScenarioError naming ``field``."""
    unit = f" [{key.unit}]" if key.unit else ""
    if key.type == "bool":
        if not isinstance(value, bool):
            raise ScenarioError(field, f"expected true or false, got {value!r}")
        return value
    if key.type == "string":
        if not isinstance(value, str):
            raise ScenarioError(field, f"expected a string, got {value!r}")
        if key.choices and value not in key.choices:
            raise ScenarioError(field, f"expected one of {_listing(key.choices)}, got {value!r}"
                                f"{_did_you_mean(value, key.choices)}")  # fmt: skip
        return value
    if key.type in ("int", "float"):
        number = _number(value, integer=key.type == "int")
        allowed = not key.choices or number in key.choices
        if number is None or not allowed or not _in_range(key, number):
            what = "an integer" if key.type == "int" else "a finite number"
            if key.choices:
                what = f"one of {_listing(key.choices, '')}"
            raise ScenarioError(field, f"expected {what}{_range(key)}{unit}, got {value!r}")
        return number
    if key.type == "table":
        if not isinstance(value, dict):
            raise ScenarioError(field, f"expected a table {{ key = value, ... }}, got {value!r}")
        return value
    if key.type == "tables":
        if not isinstance(value, list) or not value or not all(isinstance(v, dict) for v in value):
            raise ScenarioError(field, f"expected a non-empty array of tables [[{field}]], got {value!r}")
        return value
    if key.type == "rotation" and dim == 2:
        return _convert(dataclasses.replace(key, type="float"), value, field, dim, n)
    if key.type == "rotation":
        return _array(field, value, (3,), "a rotation vector of 3 numbers [rad]")
    if key.type in ("vector", "bounds"):
        return _array(field, value, (dim,), f"a list of {dim} numbers{unit}", key.type == "bounds")
    if key.type in ("indices", "pairs"):
        return _indices(field, value, pairs=key.type == "pairs")
    rows = "rows" if n is None else f"{n} rows"
    return _array(field, value, (n, dim), f"a list of {rows} of {dim} numbers{unit}")


def _indices(field: str, value: Any, *, pairs: bool) -> tuple[Any, ...]:
    def index(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and v >= 0

    def item(v: Any) -> bool:
        return isinstance(v, list) and len(v) == 2 and all(index(x) for x in v) if pairs else index(v)

    if not isinstance(value, list) or not all(item(v) for v in value):
        what = "a list of [i, j] pairs of drone indices" if pairs else "a list of drone indices"
        raise ScenarioError(field, f"expected {what} (integers >= 0), got {value!r}")
    return tuple(tuple(v) for v in value) if pairs else tuple(value)


def _number(value: Any, *, integer: bool) -> float | int | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    if integer:
        return value if isinstance(value, int) else None
    return float(value) if math.isfinite(value) else None


def _array(
    field: str, value: Any, shape: tuple[int | None, ...], expected: str, allow_inf: bool = False
) -> Array:
    def fits(v: Any, depth: int) -> bool:
        if depth == len(shape):
            return isinstance(v, int | float) and not isinstance(v, bool)
        size = shape[depth]
        return (
            isinstance(v, list)
            and (len(v) == size if size is not None else len(v) >= 1)
            and all(fits(x, depth + 1) for x in v)
        )

    if not fits(value, 0):
        raise ScenarioError(field, f"expected {expected}, got {value!r}")
    arr = np.array(value, dtype=float)
    if np.isnan(arr).any() or (not allow_inf and np.isinf(arr).any()):
        finite = "numbers (inf allowed)" if allow_inf else "finite numbers"
        raise ScenarioError(field, f"expected {finite}, got {value!r}")
    return arr


# ---- building library objects --------------------------------------------------------------
@contextmanager
def _as_scenario_error(prefix: str) -> Iterator[None]:
    """Re-raise a core ValidationError as a ScenarioError naming the scenario key."""
    try:
        yield
    except ScenarioError:
        raise
    except ValidationError as exc:
        table = TABLES["obstacles" if prefix.startswith("obstacles") else prefix]
        last = exc.field.split(" ")[0].rsplit(".", 1)[-1]
        field = _field(prefix, last) if last in _names(table) else exc.field
        raise ScenarioError(field, str(exc).removeprefix(f"{exc.field}: ")) from None


def _template(t: dict[str, Any], dim: int) -> Template:
    shape = t["shape"]
    with _as_scenario_error("template"):
        if shape in ("polygon", "ring"):
            return Template.polygon(t["n"], t["radius"], dim, t["phase"])
        if shape == "line":
            return Template.line(t["n"], t["spacing"], dim)
        if shape == "grid":
            return Template.grid(t["rows"], t["cols"], t["spacing"], dim, t["layers"])
        if shape == "sphere":
            if dim != 3:
                raise ScenarioError("template.shape", f"'sphere' needs dim = 3, got dim = {dim}")
            return Template.sphere(t["n"], t["radius"])
        offsets = t["offsets"]
        centred, shift = Template.centred(offsets)
        if not np.allclose(shift, 0.0, atol=1e-9 * max(1.0, float(np.abs(offsets).max()))):
            raise ScenarioError(
                "template.offsets",
                f"offsets must be centred (sum r_i = 0) but their mean is {shift.tolist()}, "
                f"off by {float(np.linalg.norm(shift)):.6g} m; subtract it from every row "
                f"(centred: {np.round(centred.offsets, 12).tolist()})",
            )
        return centred


def _initial(tpl: Template, init: dict[str, Any]) -> tuple[FormationState, Array]:
    """The reference's start state and the (unperturbed) start positions (n, d)."""
    if init["positions"] is not None:
        if any(init[k] is not None for k in ("centroid", "rotation", "scale")):
            raise ScenarioError("initial.positions", "give either positions or a formation state "
                                "(centroid, rotation, scale), not both")  # fmt: skip
        with _as_scenario_error("initial"):
            return fit_formation(tpl, init["positions"]).state, np.array(init["positions"])
    if init["centroid"] is None:
        raise ScenarioError("initial.centroid", "missing: give centroid (with optional rotation "
                            "and scale) or positions")  # fmt: skip
    with _as_scenario_error("initial"):
        scale = 1.0 if init["scale"] is None else init["scale"]
        start = FormationState.from_param(init["centroid"], init["rotation"], scale)
        return start, forward_kinematics(tpl, start)


def _reference(tpl: Template, start: FormationState, ref: dict[str, Any], limits: Limits) -> Reference:
    if ref["kind"] == "mission":
        return _mission(tpl, start, ref, limits)
    with _as_scenario_error("reference"):
        rotation = (
            start.rotation_body_to_world
            if ref["rotation"] is None
            else rotation_matrix(tpl.dim, ref["rotation"], "reference.rotation")
        )
        goal = FormationState(
            start.centroid_m if ref["centroid"] is None else ref["centroid"],
            rotation,
            start.scale if ref["scale"] is None else ref["scale"],
        )
        if ref["kind"] == "constant":
            return ConstantReference(tpl, goal)
        return ExponentialReference(tpl, start, goal, ref["rate"])


def _mission(tpl: Template, start: FormationState, ref: dict[str, Any], limits: Limits) -> Reference:
    """A ruckig mission: keyframe tables, explicit DOF-group limits and a budget from v_max."""
    keyframes = []
    for i, raw in enumerate(ref["keyframes"]):
        prefix = f"reference.keyframes[{i}]"
        k = _parse_keys(TABLES["reference.keyframes"], raw, prefix, tpl.dim, None)
        switch = None
        if k["template"] is not None:
            shape = _parse_keys(TABLES["template"], k["template"], f"{prefix}.template", tpl.dim, None)
            try:
                switch = _template(shape, tpl.dim)
            except ScenarioError as exc:
                raise ScenarioError(
                    f"{prefix}.{exc.field}", str(exc).removeprefix(f"{exc.field}: ")
                ) from None
        keyframes.append({"centroid_m": k["centroid"], "rotation": k["rotation"], "scale": k["scale"],
                          "hold_s": k["hold"], "template": switch})  # fmt: skip
    derived = [key for key in ("speed_fraction", "drone_acceleration", "drone_jerk") if ref[key] is not None]
    if limits.v_max_mps is None and derived:
        raise ScenarioError(f"reference.{derived[0]}", "applies only with limits.v_max (the limits "
                            "are derived from the drones' speed bound), which is unset")  # fmt: skip
    try:
        budget = None
        if limits.v_max_mps is not None:
            fraction = DEFAULT_SPEED_FRACTION if ref["speed_fraction"] is None else ref["speed_fraction"]
            accel = ref["drone_acceleration"]
            if accel is None and limits.a_max_mps2 is not None:
                accel = fraction * limits.a_max_mps2
            budget = SpeedBudget(limits.v_max_mps, fraction, accel, ref["drone_jerk"])
        bounds = MissionLimits(*(ref[key] or {} for key in ("max_velocity", "max_acceleration", "max_jerk")))
        return MissionReference(tpl, start, keyframes, limits=bounds, budget=budget, d_min_m=limits.d_min_m)
    except ScenarioError:
        raise
    except ValidationError as exc:
        raise ScenarioError(exc.field, str(exc).removeprefix(f"{exc.field}: ")) from None


def _limits(lim: dict[str, Any], dim: int) -> Limits:
    if lim["downwash"] is not None and dim != 3:
        raise ScenarioError("limits.downwash", f"applies only when dim = 3, got dim = {dim}")
    with _as_scenario_error("limits"):
        return Limits(**_renamed(lim, "limits"))


_MPC_KEYS = {k.name for k in TABLES["controller"].keys if k.when == _MPC and k.name != "solver"}


def _controller(c: dict[str, Any], dt_s: float) -> ControllerSpec:
    with _as_scenario_error("controller"):
        check_gain_dt(c["gain"], dt_s)
        given = {MPC_FIELDS.get(k, k): v for k, v in c.items() if k in _MPC_KEYS and v is not None}
        feedforward = c["feedforward"] or "jacobian"
        mpc = MPCSettings(**{**given, "gain_per_s": c["gain"], "feedforward": feedforward})
    solver = check_solver_name(c["solver"] or DEFAULT_SOLVER)
    if c["solver"] is not None:
        _check_sparse_solver(mpc, "controller.solver", solver)
    saturate = True if c["saturate"] is None else c["saturate"]
    return ControllerSpec(c["kind"], c["gain"], feedforward, saturate, mpc, solver)


def _decentralised_settings(spec: ControllerSpec, c: dict[str, Any], limits: Limits) -> ControllerSpec:
    """Fill the consensus and null-space settings (defaults for keys of other kinds)."""

    def given(fields: dict[str, str], when: str) -> dict[str, Any]:
        keys = {k.name for k in TABLES["controller"].keys if k.when == (when,)}
        return {fields.get(k, k): v for k, v in c.items() if k in keys and v is not None}

    nullspace = given(NULLSPACE_FIELDS, "nullspace")
    if nullspace.get("objective") == "repulsion" and "repulsion_radius_m" not in nullspace:
        if limits.d_min_m is None:
            raise ScenarioError("controller.repulsion_radius", "missing: set it, or limits.d_min "
                                "(the default radius is 1.5 * d_min)")  # fmt: skip
        nullspace["repulsion_radius_m"] = 1.5 * limits.d_min_m
    with _as_scenario_error("controller"):
        return dataclasses.replace(
            spec,
            consensus=ConsensusSettings(spec.gain_per_s, **given(CONSENSUS_FIELDS, "consensus")),
            nullspace=NullSpaceSettings(spec.gain_per_s, spec.feedforward, **nullspace),
        )


def _graph(data: Mapping[str, Any], tpl: Template, positions: Array, seed: int) -> dict[str, Any]:
    """The Scenario fields of an optional [graph] table: graph, network, allow_disconnected."""
    if data.get("graph") is None:
        return {}
    g = _table(data, "graph", tpl.dim, tpl.n)
    with _as_scenario_error("graph"):
        kind = g["kind"]
        if kind in ("complete", "ring", "path"):
            graph = getattr(Graph, kind)(tpl.n)
        elif kind == "explicit":
            graph = Graph.from_edges(tpl.n, g["edges"])
        else:
            points = tpl.offsets if g["on"] == "template" else positions
            if kind == "k_nearest":
                graph = Graph.k_nearest(points, g["k"])
            else:
                graph = Graph.disk(points, g["radius"])
        network = Network(g["delay_steps"], g["loss_probability"], seed, g["relative_positions"])
    return {"graph": graph, "network": network, "allow_disconnected": g["allow_disconnected"]}


def _obstacles(raw: Any, dim: int) -> tuple[SphereObstacle, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list) or not all(isinstance(o, dict) for o in raw):
        raise ScenarioError("obstacles", f"expected an array of tables [[obstacles]], got {raw!r}")
    out = []
    for i, item in enumerate(raw):
        prefix = f"obstacles[{i}]"
        o = _parse_keys(TABLES["obstacles"], item, prefix, dim, None)
        with _as_scenario_error(prefix):
            out.append(SphereObstacle(o["center"], o["radius"], o["clearance"]))
    return tuple(out)


_ATTRS = {
    "limits": {"v_max": "v_max_mps", "d_min": "d_min_m", "a_max": "a_max_mps2",
               "geofence_min": "geofence_min_m", "geofence_max": "geofence_max_m",
               "downwash": "downwash_kappa"},
    "simulation": {"dt": "dt_s", "duration": "duration_s", "lag": "lag_s", "noise": "noise_std_m"},
}  # fmt: skip


def _renamed(values: dict[str, Any], table: str) -> dict[str, Any]:
    return {_ATTRS[table][k]: v for k, v in values.items()}


# ---- controllers, solvers, running ----------------------------------------------------------
def check_solver_name(name: str, field: str = "controller.solver") -> str:
    """A solver name as a scenario key (see :func:`mpcform.solvers.base.check_solver_name`)."""
    try:
        return check_backend_name(name)
    except SolverError as exc:
        raise ScenarioError(field, str(exc)) from None


def build_controller(scenario: Scenario, kind: str | None = None, solver: str | None = None) -> Controller:
    """The scenario's controller; ``kind`` and ``solver`` override the file (CLI flags)."""
    spec = scenario.controller
    kind = spec.kind if kind is None else kind
    if kind not in CONTROLLER_KINDS:
        raise ScenarioError("controller.kind", f"expected one of {_listing(CONTROLLER_KINDS)}, "
                            f"got {kind!r}{_did_you_mean(kind, CONTROLLER_KINDS)}")  # fmt: skip
    if solver is not None and kind != "mpc":
        raise ScenarioError("controller.solver", f"a solver ({solver!r}) applies only to the mpc "
                            f"controller, this run uses {kind!r}")  # fmt: skip
    ref, dt, limits = scenario.reference, scenario.simulation.dt_s, scenario.limits
    v_max = limits.v_max_mps if spec.saturate else None
    with _as_scenario_error("controller"):
        if kind == "proportional":
            return ProportionalController(ref, spec.gain_per_s, dt, v_max)
        if kind == "tracking":
            return TrackingController(ref, spec.gain_per_s, dt, v_max, spec.feedforward)
        if kind == "nullspace":
            settings = spec.nullspace or NullSpaceSettings(spec.gain_per_s, spec.feedforward)
            return NullSpaceController(ref, dt, settings, v_max)
        if kind == "consensus":
            if scenario.graph is None:
                raise ScenarioError("graph", "missing table [graph]: the consensus controller needs a "
                                    f"communication graph (kind = {_listing(GRAPH_KINDS)})")  # fmt: skip
            consensus = spec.consensus or ConsensusSettings(spec.gain_per_s)
            return ConsensusController(ref, scenario.graph, dt, consensus, v_max, scenario.network,
                                       scenario.allow_disconnected)  # fmt: skip
    from mpcform.mpc.planner import MPCPlanner

    name = spec.solver
    if solver is not None:
        name = check_solver_name(solver, "solver")
        _check_sparse_solver(spec.mpc, "solver", name)
    with _as_scenario_error("controller"):
        planner: Controller = MPCPlanner(ref, dt, limits, spec.mpc, obstacles=scenario.obstacles, solver=name)
    return planner


def _check_sparse_solver(mpc: MPCSettings, field: str, solver: str) -> None:
    """A solver named for a planner that solves per drone would be ignored: an error."""
    if mpc.solves_per_drone:
        raise ScenarioError(field, f"{solver!r} solves the sparse QP, but this scenario solves each "
                            "drone's QP with DAQP (controller.coupling = \"decoupled\", per_drone = "
                            "true); set controller.per_drone = false to use it")  # fmt: skip


def run_scenario(
    scenario: Scenario,
    out_dir: str | Path | None = None,
    controller: str | None = None,
    solver: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RunResult:
    """Simulate, compute the metrics and, when ``out_dir`` is given, write the output files.

    ``controller`` and ``solver`` override the scenario's controller kind and QP backend;
    ``progress(step, steps)`` is called after every step (e.g. :class:`mpcform.cli.progress.ProgressBar`).
    """
    ctrl = build_controller(scenario, controller, solver)
    sim = scenario.simulation
    result = simulate(
        ctrl, scenario.initial_positions_m, sim.duration_s,
        lag_s=sim.lag_s, noise_std_m=sim.noise_std_m, seed=scenario.seed, progress=progress,
    )  # fmt: skip
    limits = scenario.limits
    is_mpc = (controller or scenario.controller.kind) == "mpc"
    summary = build_summary(
        scenario=scenario.name,
        n=scenario.n,
        dim=scenario.dim,
        dt_s=sim.dt_s,
        controller=ctrl.name,
        solver=getattr(ctrl, "solver_name", None) if is_mpc else None,  # "daqp (per drone)" if so
        v_max_mps=limits.v_max_mps,
        d_min_m=limits.d_min_m,
        seed=scenario.seed,
        scenario_file=scenario.source,
        scenario_sha256=scenario.source_sha256,
        metrics=run_metrics(result, limits.v_max_mps, limits.d_min_m),
        steps=result.commands_mps.shape[0],
    )
    path = None if out_dir is None else write_outputs(Path(out_dir), result, summary)
    return RunResult(result, summary, path)


def describe(scenario: Scenario) -> str:
    """One line: drones, template, reference, controller, steps."""
    space = "planar" if scenario.dim == 2 else "spatial"
    sim = scenario.simulation
    return (
        f"{scenario.name}: {scenario.n} drone{'s' * (scenario.n != 1)}, {space} "
        f"{scenario.template.name} template, {type(scenario.reference).__name__}, "
        f"{scenario.controller.kind} controller, {scenario.steps} steps of {sim.dt_s:g} s"
    )


# ---- key reference -------------------------------------------------------------------------
def key_reference_markdown() -> str:
    """Every scenario key as markdown tables (key, type, default, unit, meaning), per table."""
    lines = ["All lengths in metres, angles in radians, times in seconds.", ""]
    for table in SCHEMA:
        need = "required" if table.required else "optional"
        lines += [f"### {table.title}", "", f"{table.doc} ({need})", ""]
        lines += ["| key | type | default | unit | meaning |", "| --- | --- | --- | --- | --- |"]
        for key in table.keys:
            doc = key.doc
            if key.when:
                doc += f" Only with `{table.selector}` = {_listing(key.when, '`')}."
            cells = (f"`{key.name}`", _type_text(key), _default_text(key), key.unit, doc)
            lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        lines.append("")
    return "\n".join(lines)


def _type_text(key: Key) -> str:
    base = {
        "int": "integer", "float": "float", "bool": "boolean", "string": "string",
        "vector": "d numbers", "bounds": "d numbers (+-inf allowed)",
        "rotation": "float (d = 2) or 3 numbers (d = 3)", "points": "n rows of d numbers",
        "table": "inline table", "tables": "array of tables",
        "indices": "list of integers >= 0", "pairs": "list of [i, j] integer pairs",
    }[key.type]  # fmt: skip
    if key.choices:
        quote = '"' if key.type == "string" else ""
        return f"{base}: {_listing(key.choices, quote)}"
    return base + _range(key)


def _default_text(key: Key) -> str:
    if key.required:
        return "required"
    if key.shown_default is not None:
        return key.shown_default
    if key.default is None:
        return "unset"
    if isinstance(key.default, bool):
        return str(key.default).lower()
    if isinstance(key.default, str):
        return f'"{key.default}"'
    return f"{key.default:g}"


def _range(key: Key) -> str:
    return f" {key.bound}" if key.bound else ""


def _in_range(key: Key, x: float) -> bool:
    if not key.bound:
        return True
    op, low = key.bound.split()
    return x > float(low) if op == ">" else x >= float(low)


# ---- small helpers -------------------------------------------------------------------------
def _field(prefix: str, name: str) -> str:
    return f"{prefix}.{name}" if prefix else name


def _names(table: Table) -> list[str]:
    return [k.name for k in table.keys]


def _listing(values: tuple[Any, ...], quote: str = "'") -> str:
    return ", ".join(f"{quote}{v}{quote}" for v in values)


def _did_you_mean(word: str, choices: Any) -> str:
    close = difflib.get_close_matches(word, [str(c) for c in choices], n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def _line_hint(text: str, message: str) -> str:
    match = re.search(r"line (\d+)", message)
    lines = text.splitlines()
    if match is None or not 1 <= int(match.group(1)) <= len(lines):
        return ""
    return f": {lines[int(match.group(1)) - 1].strip()!r}"
