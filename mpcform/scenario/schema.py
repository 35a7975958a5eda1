"""The scenario key schema: every table and key of a scenario file with its type, default, unit
and meaning.

:data:`SCHEMA` is the one place that lists them: :mod:`mpcform.scenario.parse` checks a file
against it and :mod:`mpcform.scenario.keys` renders it (``mpcform keys``, ``scenarios/README.md``).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from mpcform.control.base import FEEDFORWARDS
from mpcform.control.consensus import CONSENSUS_LAWS, RELATIVE_POSITIONS, ConsensusSettings
from mpcform.control.graph import GRAPH_KINDS
from mpcform.control.nullspace import OBJECTIVES, NullSpaceSettings
from mpcform.reference.keyframes import DEFAULT_SPEED_FRACTION
from mpcform.scenario.key_types import Key, Table, did_you_mean, listing, obstacle_keys
from mpcform.scenario.mpc_keys import MPC_KEYS, SOLVE_TABLE
from mpcform.sim.crazyflow import DRONES
from mpcform.sim.plant_spec import (
    CrazyflowPlantSpec,
    IdealPlantSpec,
    LagPlantSpec,
    PlantSpec,
    QuadrotorPlantSpec,
    SecondOrderPlantSpec,
)
from mpcform.sim.plants import KINDS as PLANT_KINDS
from mpcform.sim.so_rpy import MODELS, PLATFORMS

FORMAT_VERSION = 1
SHAPES = ("polygon", "ring", "line", "grid", "sphere", "explicit")
REFERENCE_KINDS = ("constant", "exponential", "mission")
CONTROLLER_KINDS = ("proportional", "tracking", "mpc", "consensus", "nullspace")
GRAPH_POINTS = ("template", "initial")


_MPC = ("mpc",)
_GOAL = ("constant", "exponential")
_MISSION = ("mission",)
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
        Key("offsets", "points", "Offsets r_i, one row per drone; their mean must be zero and no two "
            "may coincide.", "m",
            required=True, when=("explicit",)),
    ), selector="shape"),
    Table("initial", "Start: a formation state, or explicit `positions` (not both). Before the "
          "perturbation, every drone must start inside the geofence and clear of every obstacle "
          "(at least radius + clearance from its centre), and no two at one point.", (
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
        Key("v_max_z", "float", "Vertical speed bound (mpc, spatial, with v_max): the velocity set "
            "inscribed in the spheroid of semi-axes v_max, v_max, v_max_z.", "m/s", bound="> 0",
            shown_default="none (crazyflow plant: a Crazyflie's 0.7)"),
        Key("d_min", "float", "Minimum distance between two drones.", "m", bound="> 0"),
        Key("a_max", "float", "Componentwise bound on command changes (mpc; inf: none, ideal "
            "plant only).", "m/s^2", bound="> 0", inf=True,
            shown_default="1.79 (mpc: a Crazyflie's; a quadrotor plant: its own)"),
        Key("geofence_min", "bounds", "Lower corner of the allowed box (mpc; -inf: open).", "m"),
        Key("geofence_max", "bounds", "Upper corner of the allowed box (mpc; inf: open).", "m"),
        Key("downwash", "float", "Vertical separation factor kappa (spatial): pairs keep d_min "
            "horizontally and kappa d_min vertically; \"crazyswarm\": Crazyswarm's per-robot "
            "ellipsoid (radii 0.12, 0.12, 0.3 m), kappa = 0.6 m / d_min for d_min >= 0.24 m.", "",
            bound=">= 1", names=("crazyswarm",)),
        Key("tracking", "float", "Room per drone for the position controller's tracking error when "
            "the plan is flown (mpc; `mpcform run --flyable`: a Crazyflie's 0.05): pairs keep "
            "d_min + 2 tracking apart, obstacles and the geofence tracking more. `export` refuses a run "
            "planned without it.", "m", default=0.0, bound=">= 0"),
        Key("unbounded", "bool", "The run keeps no separation on purpose: an mpc run of two or more "
            "drones without d_min warns that it keeps none, unless this is true (then d_min must "
            "not be set).", default=False),
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
        *MPC_KEYS,
    ), selector="kind"),
    SOLVE_TABLE,
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
    Table("simulation", "Closed-loop simulation (zero-order hold, exact single integrator). A run "
          "estimated to need more than 4 GiB of memory (duration / dt x n x d values of time "
          "series, the MPC's rows over its horizon and drone pairs) is refused; `--max-memory` "
          "raises the limit.", (
        Key("dt", "float", "Control period (at least a microsecond).", "s", required=True, bound=">= 1e-6"),
        Key("duration", "float", "Simulated time.", "s", required=True, bound="> 0"),
        Key("lag", "float", "Removed: a velocity lag is now `[plant]` `kind = \"lag\"` with "
            "`time_constant` (an error names it).", "s", shown_default="-"),
        Key("noise", "float", "Std of seeded Gaussian position disturbances per step (a process "
            "disturbance on the true position).", "m", 0.0, bound=">= 0"),
    )),
    Table("plant", "The drone the plan is flown on; the MPC tightens its separation, obstacle and "
          "geofence rows by the plant's robust margin.", (
        Key("kind", "string", "`ideal` (the exact single integrator the planner assumes), `lag` "
            "(first-order velocity loop), `second_order` (damped velocity loop per axis) or "
            "`quadrotor` (a Crazyflie model of drone-models under a firmware-like PID cascade; "
            "`pip install mpcform[flight]`) or `crazyflow` (crazyflow's Crazyflie simulator flying "
            "the planner's full-state setpoints with the firmware's Mellinger controller; "
            "`pip install mpcform[crazyflow]`).", default=IdealPlantSpec.kind, choices=PLANT_KINDS),
        Key("time_constant", "float", "Time constant of the velocity loop.", "s",
            LagPlantSpec.time_constant_s, when=("lag",), bound="> 0"),
        Key("damping", "float", "Damping ratio of the velocity loop.", "", SecondOrderPlantSpec.damping,
            when=("second_order",), bound="> 0"),
        Key("natural_frequency", "float", "Natural frequency of the velocity loop.", "rad/s",
            SecondOrderPlantSpec.natural_frequency_rad_s, when=("second_order",), bound="> 0"),
        Key("damping_z", "float", "Damping ratio of the vertical axis.", "", when=("second_order",),
            shown_default="damping", bound="> 0"),
        Key("natural_frequency_z", "float", "Natural frequency of the vertical axis.", "rad/s",
            when=("second_order",), shown_default="natural_frequency", bound="> 0"),
        Key("platform", "string", "drone-models platform (fitted Crazyflie 2.x parameters).",
            default=QuadrotorPlantSpec.platform, when=("quadrotor",), choices=PLATFORMS),
        Key("model", "string", "drone-models model: the fitted attitude loop, with or without rotor "
            "drag (wind acts through the drag).", default=QuadrotorPlantSpec.model, when=("quadrotor",),
            choices=MODELS),
        Key("rate", "float", "Inner-loop rate: a multiple of the control rate 1 / dt.", "Hz",
            QuadrotorPlantSpec.rate_hz, when=("quadrotor",), bound="> 0"),
        Key("altitude", "float", "Height a planar (dim = 2) flight holds; with `crazyflow`, the "
            "height of the scenario's origin above the floor, by which spatial flights are lifted "
            "too (every drone must start two body radii up).", "m", QuadrotorPlantSpec.altitude_m,
            when=("quadrotor", "crazyflow"), bound=">= 0"),
        Key("drone", "string", "The Crazyflie model crazyflow simulates (first-principles "
            "dynamics of drone-models).", default=CrazyflowPlantSpec.drone, when=("crazyflow",),
            choices=DRONES),
        Key("physics_rate", "int", "crazyflow's physics rate: a multiple of `control_rate`; the "
            "true path is sampled at it.", "Hz", CrazyflowPlantSpec.physics_rate_hz,
            when=("crazyflow",), bound=">= 1"),
        Key("control_rate", "int", "Rate of the Mellinger controller and of the full-state "
            "setpoints: a multiple of 1 / dt.", "Hz", CrazyflowPlantSpec.control_rate_hz,
            when=("crazyflow",), bound=">= 1"),

        Key("measurement_noise", "float", "Std of seeded Gaussian noise on the positions the "
            "controller sees.", "m", PlantSpec.measurement_noise_m, bound=">= 0"),
        Key("margin", "float", "Robust margin per drone that tightens the MPC's rows (pairs by "
            "twice it).", "m", shown_default="from the plant, wind and a_max", bound=">= 0"),
        Key("margin_growth", "float", "How much the MPC's rows grow per control interval along "
            "the horizon, per drone (0: none).", "m", shown_default="from the wind", bound=">= 0"),
        Key("wind", "table", "`[plant.wind]`: `mean` (d numbers) [m/s], `gust_std` [m/s] (0), "
            "`gust_time` [s] (1), `gust_bound` [m/s] per axis (3 gust_std; `inf`: unclipped), "
            "`gust_field` (`per_drone` or `shared`); seeded Ornstein-Uhlenbeck gusts acting "
            "through drag (on `crazyflow`, the quadrotor's drag force on the wind, applied as "
            "crazyflow's external force).", when=("lag", "second_order", "quadrotor", "crazyflow")),
    ), required=False, selector="kind"),
    Table("obstacles", "Static obstacles; repeat the table for more, `shape` choosing each one's "
          "kind. No drone may start within an obstacle's clearance of "
          "its surface, nor may a `constant` reference's goal put one there; a moving reference "
          "(`exponential`, `mission`) may pass through obstacles: the MPC goes around them.",
          obstacle_keys(), required=False, array=True, selector="shape"),
)  # fmt: skip # the tables of keys read best with each key's text aligned under it
TABLES = {t.name: t for t in SCHEMA}


__all__ = ["SCHEMA", "TABLES", "Key", "Table", "did_you_mean", "listing"]
