"""Scenario files: a TOML document checked against the schema and built into a :class:`Scenario`.

Every problem in a file raises :class:`~mpcform.errors.ScenarioError` naming the key
(``controller.gain``), the value received and what was expected; :func:`load_scenario` stops
at the first one (``mpcform validate`` lists them all, see :mod:`mpcform.scenario.check`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.control.consensus import ConsensusSettings, Network
from mpcform.control.graph import Graph
from mpcform.control.laws import check_gain_dt
from mpcform.control.nullspace import NullSpaceSettings
from mpcform.errors import ScenarioError, ValidationError
from mpcform.formation.kinematics import fit_formation, forward_kinematics
from mpcform.formation.rotation import rotation_matrix
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.settings import MPCSettings
from mpcform.reference.base import ConstantReference, ExponentialReference, Reference
from mpcform.reference.keyframes import DEFAULT_SPEED_FRACTION, MissionLimits, SpeedBudget
from mpcform.reference.mission import MissionReference
from mpcform.scenario.mpc_keys import DEPRECATED, MPC_FIELDS, MPC_KEYS
from mpcform.scenario.parse import as_scenario_error, parse_keys, parse_table, parse_top_level
from mpcform.scenario.placement import check_distinct, check_extent, check_goal, check_start
from mpcform.scenario.plant import parse_plant, planned_for_its_plant
from mpcform.scenario.schema import CONSENSUS_FIELDS, NULLSPACE_FIELDS, TABLES
from mpcform.scenario.size import MAX_STEPS, REFERENCE_SAMPLES, check_drone_count, read_scenario_bytes
from mpcform.scenario.solve import solve_strategy
from mpcform.scenario.spec import ControllerSpec, Scenario, SimulationSpec
from mpcform.world.limits import Limits, crazyswarm_downwash
from mpcform.world.obstacles import Obstacle, resolve_clearances
from mpcform.world.shapes import shape_from_keys


def load_scenario(path: str | Path, *, max_memory_gib: float | None = None) -> Scenario:
    """Read and validate a scenario TOML file; raises :class:`ScenarioError` on any problem
    (``max_memory_gib``: see :func:`scenario_from_dict`)."""
    path = Path(path)
    raw = read_scenario_bytes(path)  # a regular file of at most 16 MiB
    text = scenario_text(raw)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        hint = _line_hint(text, str(exc))
        raise ScenarioError(str(path), f"TOML syntax error: {exc}{hint}") from None
    return scenario_from_dict(
        data,
        source=path,
        source_sha256=hashlib.sha256(raw).hexdigest(),
        default_name=path.stem,
        max_memory_gib=max_memory_gib,
    )


def scenario_text(raw: bytes) -> str:
    """A scenario file's bytes as text: UTF-8, a leading byte order mark (as some Windows editors
    write) dropped, undecodable bytes replaced (TOML then reports them)."""
    return raw.decode("utf-8", errors="replace").removeprefix("\ufeff")


def scenario_from_dict(
    data: Mapping[str, Any],
    *,
    source: Path | None = None,
    source_sha256: str | None = None,
    default_name: str = "scenario",
    max_memory_gib: float | None = None,
) -> Scenario:
    """Validate an already parsed scenario (the TOML document as a dict). ``max_memory_gib``: refuse
    more drones than fit within it before the template is built (:func:`check_drone_count`; None:
    no limit, and :func:`~mpcform.scenario.size.check_memory` then gives the whole estimate)."""
    top = parse_top_level(data)
    dim, seed = top["dim"], top["seed"]
    template = parse_table(data, "template", dim)
    if max_memory_gib is not None:
        sim_keys = parse_table(data, "simulation", dim)
        check_drone_count(template, sim_keys["duration"] / sim_keys["dt"], dim, max_memory_gib)
    tpl = _template(template, dim)
    init = parse_table(data, "initial", dim, tpl.n)
    start, positions = _initial(tpl, init)
    lim = parse_table(data, "limits", dim)
    limits = _limits(lim, dim)
    obstacles = resolve_clearances(_obstacles(data.get("obstacles"), dim), limits.d_min_m)  # unset: d_min / 2
    explicit = init["positions"] is not None
    check_extent(positions, "initial.positions" if explicit else "initial", "the start puts")
    check_start(positions, "initial.positions" if explicit else "initial.centroid", limits, obstacles)
    ref = parse_table(data, "reference", dim)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is what check_extent reports
        reference = _reference(tpl, start, ref, limits)
        goal = reference.start_positions_m()
    check_extent(goal, "reference", "the reference takes")
    if isinstance(reference, ConstantReference):
        field = "reference.centroid" if ref["centroid"] is not None else "reference"
        check_goal(goal, field, limits, obstacles)
    sim = SimulationSpec(**_renamed(parse_table(data, "simulation", dim), "simulation"))
    plant = parse_plant(data, dim, sim.dt_s)
    controller = _controller(parse_table(data, "controller", dim), sim.dt_s)
    controller = _decentralised_settings(controller, parse_table(data, "controller", dim), limits)
    if sim.duration_s / sim.dt_s > MAX_STEPS:
        raise ScenarioError(
            "simulation.duration",
            f"expected at most {MAX_STEPS:g} steps of dt = {sim.dt_s:g} s, got {sim.duration_s:g} s",
        )
    if sim.duration_s < sim.dt_s:
        raise ScenarioError(
            "simulation.duration",
            f"expected at least one step, dt = {sim.dt_s:g} s; got {sim.duration_s:g} s",
        )
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is what check_extent reports
        reach = reference.targets(np.linspace(0.0, sim.duration_s, REFERENCE_SAMPLES))[0]
    check_extent(reach, "reference", "the reference takes")
    if init["perturbation"] > 0.0:
        rng = np.random.default_rng([seed, 1])  # independent of the simulation noise (seed)
        positions = positions + rng.normal(0.0, init["perturbation"], positions.shape)
    positions.setflags(write=False)
    scenario = Scenario(
        name=top["name"] if top["name"] is not None else default_name,
        dim=dim,
        seed=seed,
        template=tpl,
        start=start,
        initial_positions_m=positions,
        reference=reference,
        limits=limits,
        obstacles=obstacles,
        **_graph(data, tpl, positions, seed),
        controller=controller,
        simulation=sim,
        plant=plant,
        source=source,
        source_sha256=source_sha256,
        unbounded=lim["unbounded"],
    )
    scenario = planned_for_its_plant(scenario)
    if controller.kind != "mpc":
        return scenario
    with as_scenario_error("limits"):  # e.g. limits.a_max = inf on a plant whose margin needs a bound
        scenario.robustness  # noqa: B018 - its errors name the plant's keys
    return scenario


def _template(t: dict[str, Any], dim: int) -> Template:
    shape = t["shape"]
    with as_scenario_error("template"):
        if shape != "explicit":
            tpl = _shape(t, dim)
            size_key = "template.spacing" if shape in ("line", "grid") else "template.radius"
            check_distinct(tpl.offsets, size_key)
            return tpl
        offsets = t["offsets"]
        centred, shift = Template.centred(offsets)
        if not np.allclose(shift, 0.0, atol=1e-9 * max(1.0, float(np.abs(offsets).max()))):
            raise ScenarioError(
                "template.offsets",
                f"offsets must be centred (sum r_i = 0) but their mean is {shift.tolist()}, "
                f"off by {float(np.linalg.norm(shift)):.6g} m; subtract it from every row "
                f"(centred: {np.round(centred.offsets, 12).tolist()})",
            )
        return centred  # distinct: Template.centred checks it as check_distinct does


def _shape(t: dict[str, Any], dim: int) -> Template:
    """The template of a generated ``shape`` (every shape but ``explicit``)."""
    shape = t["shape"]
    if shape in ("polygon", "ring"):
        return Template.polygon(t["n"], t["radius"], dim, t["phase"])
    if shape == "line":
        return Template.line(t["n"], t["spacing"], dim)
    if shape == "grid":
        return Template.grid(t["rows"], t["cols"], t["spacing"], dim, t["layers"])
    if dim != 3:
        raise ScenarioError("template.shape", f"'sphere' needs dim = 3, got dim = {dim}")
    return Template.sphere(t["n"], t["radius"])


def _initial(tpl: Template, init: dict[str, Any]) -> tuple[FormationState, Array]:
    """The reference's start state and the (unperturbed) start positions (n, d)."""
    if init["positions"] is not None:
        if any(init[k] is not None for k in ("centroid", "rotation", "scale")):
            raise ScenarioError(
                "initial.positions",
                "give either positions or a formation state (centroid, rotation, scale), not both",
            )
        check_distinct(np.asarray(init["positions"], dtype=float), "initial.positions", "start positions")
        with as_scenario_error("initial"):
            return fit_formation(tpl, init["positions"]).state, np.array(init["positions"])
    if init["centroid"] is None:
        raise ScenarioError(
            "initial.centroid", "missing: give centroid (with optional rotation and scale) or positions"
        )
    with as_scenario_error("initial"):
        scale = 1.0 if init["scale"] is None else init["scale"]
        start = FormationState.from_param(init["centroid"], init["rotation"], scale)
        return start, forward_kinematics(tpl, start)


def _reference(tpl: Template, start: FormationState, ref: dict[str, Any], limits: Limits) -> Reference:
    if ref["kind"] == "mission":
        return _mission(tpl, start, ref, limits)
    with as_scenario_error("reference"):
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
        k = parse_keys(TABLES["reference.keyframes"], raw, prefix, tpl.dim, None)
        switch = None
        if k["template"] is not None:
            shape = parse_keys(TABLES["template"], k["template"], f"{prefix}.template", tpl.dim, None)
            try:
                switch = _template(shape, tpl.dim)
            except ScenarioError as exc:
                raise ScenarioError(
                    f"{prefix}.{exc.field}", str(exc).removeprefix(f"{exc.field}: ")
                ) from None
        keyframes.append(
            {
                "centroid_m": k["centroid"],
                "rotation": k["rotation"],
                "scale": k["scale"],
                "hold_s": k["hold"],
                "template": switch,
            }
        )
    derived = [key for key in ("speed_fraction", "drone_acceleration", "drone_jerk") if ref[key] is not None]
    if limits.v_max_mps is None and derived:
        raise ScenarioError(
            f"reference.{derived[0]}",
            "applies only with limits.v_max (the limits "
            "are derived from the drones' speed bound), which is unset",
        )
    try:
        budget = None
        if limits.v_max_mps is not None:
            fraction = DEFAULT_SPEED_FRACTION if ref["speed_fraction"] is None else ref["speed_fraction"]
            accel = ref["drone_acceleration"]
            if accel is None and limits.a_max_bounded:
                accel = fraction * float(limits.a_max_mps2)  # type: ignore[arg-type,operator]
            budget = SpeedBudget(limits.v_max_mps, fraction, accel, ref["drone_jerk"])
        bounds = MissionLimits(*(ref[key] or {} for key in ("max_velocity", "max_acceleration", "max_jerk")))
        return MissionReference(tpl, start, keyframes, limits=bounds, budget=budget, d_min_m=limits.d_min_m)
    except ScenarioError:
        raise
    except ValidationError as exc:
        raise ScenarioError(exc.field, str(exc).removeprefix(f"{exc.field}: ")) from None


def _limits(lim: dict[str, Any], dim: int) -> Limits:
    if lim["unbounded"] and lim["d_min"] is not None:
        raise ScenarioError(
            "limits.unbounded", f"true says the run keeps no d_min, but d_min = {lim['d_min']:g}"
        )
    for key in ("downwash", "v_max_z"):
        if lim[key] is not None and dim != 3:
            raise ScenarioError(f"limits.{key}", f"applies only when dim = 3, got dim = {dim}")
    if lim["v_max_z"] is not None and lim["v_max"] is None:
        raise ScenarioError("limits.v_max_z", "bounds the vertical part of limits.v_max: set v_max too")
    if lim["downwash"] == "crazyswarm":
        if lim["d_min"] is None:
            raise ScenarioError("limits.downwash", "'crazyswarm' needs limits.d_min")
        with as_scenario_error("limits"):
            lim = lim | {"downwash": crazyswarm_downwash(lim["d_min"])}
    with as_scenario_error("limits"):
        return Limits(**_renamed(lim, "limits"))


_MPC_KEYS = {k.name for k in MPC_KEYS if k.name != "solve" and k.name not in DEPRECATED}


def _controller(c: dict[str, Any], dt_s: float) -> ControllerSpec:
    deprecations: list[str] = []
    solve = solve_strategy(c, c["coupling"], deprecations) if c["kind"] == "mpc" else None
    with as_scenario_error("controller"):
        check_gain_dt(c["gain"], dt_s)
        given = {MPC_FIELDS.get(k, k): v for k, v in c.items() if k in _MPC_KEYS and v is not None}
        feedforward = c["feedforward"] or "jacobian"
        mpc = MPCSettings(**{**given, "gain_per_s": c["gain"], "feedforward": feedforward, "solve": solve})
    saturate = True if c["saturate"] is None else c["saturate"]
    return ControllerSpec(c["kind"], c["gain"], feedforward, saturate, mpc, deprecations=tuple(deprecations))


def _decentralised_settings(spec: ControllerSpec, c: dict[str, Any], limits: Limits) -> ControllerSpec:
    """Fill the consensus and null-space settings (defaults for keys of other kinds)."""

    def given(fields: dict[str, str], when: str) -> dict[str, Any]:
        keys = {k.name for k in TABLES["controller"].keys if k.when == (when,)}
        return {fields.get(k, k): v for k, v in c.items() if k in keys and v is not None}

    nullspace = given(NULLSPACE_FIELDS, "nullspace")
    if nullspace.get("objective") == "repulsion" and "repulsion_radius_m" not in nullspace:
        if limits.d_min_m is None:
            raise ScenarioError(
                "controller.repulsion_radius",
                "missing: set it, or limits.d_min (the default radius is 1.5 * d_min)",
            )
        nullspace["repulsion_radius_m"] = 1.5 * limits.d_min_m
    with as_scenario_error("controller"):
        return dataclasses.replace(
            spec,
            consensus=ConsensusSettings(spec.gain_per_s, **given(CONSENSUS_FIELDS, "consensus")),
            nullspace=NullSpaceSettings(spec.gain_per_s, spec.feedforward, **nullspace),
        )


def _graph(data: Mapping[str, Any], tpl: Template, positions: Array, seed: int) -> dict[str, Any]:
    """The Scenario fields of an optional [graph] table: graph, network, allow_disconnected."""
    if data.get("graph") is None:
        return {}
    g = parse_table(data, "graph", tpl.dim, tpl.n)
    with as_scenario_error("graph"):
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


def _obstacles(raw: Any, dim: int) -> tuple[Obstacle, ...]:
    if raw is None:
        return ()
    if not isinstance(raw, list) or not all(isinstance(o, dict) for o in raw):
        raise ScenarioError("obstacles", f"expected an array of tables [[obstacles]], got {raw!r}")
    out = []
    for i, item in enumerate(raw):
        prefix = f"obstacles[{i}]"
        o = parse_keys(TABLES["obstacles"], item, prefix, dim, None)
        with as_scenario_error(prefix):
            shape = shape_from_keys(o)
            shape.check_dim(dim, prefix)
            out.append(shape)
    return tuple(out)


_ATTRS = {
    "limits": {
        "v_max": "v_max_mps",
        "d_min": "d_min_m",
        "a_max": "a_max_mps2",
        "geofence_min": "geofence_min_m",
        "geofence_max": "geofence_max_m",
        "downwash": "downwash_kappa",
        "tracking": "tracking_m",
        "v_max_z": "v_max_z_mps",
    },
    "simulation": {"dt": "dt_s", "duration": "duration_s", "noise": "noise_std_m"},
}


def _renamed(values: dict[str, Any], table: str) -> dict[str, Any]:
    return {_ATTRS[table][k]: v for k, v in values.items() if k in _ATTRS[table]}


def _line_hint(text: str, message: str) -> str:
    match = re.search(r"line (\d+)", message)
    lines = text.splitlines()
    if match is None or not 1 <= int(match.group(1)) <= len(lines):
        return ""
    return f": {lines[int(match.group(1)) - 1].strip()!r}"
