"""Loading scenario files: defaults and objects, seeded perturbation, every bad input names its key."""

from __future__ import annotations

import copy
import hashlib
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from saved_runs import SCENARIOS

from mpcform import MPCSettings, ScenarioError
from mpcform.formation.kinematics import forward_kinematics
from mpcform.formation.state import FormationState
from mpcform.mpc.strategy import PerDroneSolve, SparseSolve, SplitPolicy
from mpcform.scenario.load import load_scenario, scenario_from_dict, scenario_text
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import DEFAULT_SOLVER

WORKED = SCENARIOS / "worked_example.toml"
DELETE = object()


def worked_dict() -> dict[str, Any]:
    return tomllib.loads(WORKED.read_text())


def mutated(changes: dict[str, Any]) -> dict[str, Any]:
    """The worked example with ``{"table.key": value}`` changes (DELETE removes the entry)."""
    data = copy.deepcopy(worked_dict())
    for dotted, value in changes.items():
        *tables, key = dotted.split(".")
        node = data
        for t in tables:
            node = node.setdefault(t, {})
        if value is DELETE:
            del node[key]
        else:
            node[key] = value
    return data


def test_defaults_and_objects() -> None:
    s = scenario_from_dict(mutated({"seed": DELETE, "name": DELETE}), default_name="fallback")
    assert s.name == "fallback" and s.seed == 0 and s.dim == 2 and s.n == 3
    assert s.controller.kind == "tracking" and s.controller.gain_per_s == 2.0
    assert s.controller.saturate is True and s.controller.mpc.strategy == SparseSolve(DEFAULT_SOLVER)
    assert s.controller.mpc == MPCSettings(gain_per_s=2.0)
    assert s.limits.v_max_mps == 3.0 and s.limits.a_max_mps2 is None and s.obstacles == ()
    assert s.simulation.noise_std_m == 0.0 and s.plant.ideal and s.steps == 500
    assert np.allclose(s.initial_positions_m, forward_kinematics(s.template, s.start))


def test_explicit_positions_start_from_their_best_fit() -> None:
    state = FormationState.from_param([1.0, -2.0], 0.3, 1.5)
    s0 = scenario_from_dict(worked_dict())
    positions = forward_kinematics(s0.template, state).tolist()
    s = scenario_from_dict(mutated({"initial": {"positions": positions}}))
    assert np.allclose(s.initial_positions_m, positions)
    assert np.allclose(s.start.centroid_m, [1.0, -2.0]) and s.start.scale == pytest.approx(1.5)
    assert np.allclose(s.reference.state(0.0).centroid_m, [1.0, -2.0])


def test_perturbation_is_seeded() -> None:
    a = scenario_from_dict(mutated({"initial.perturbation": 0.1, "seed": 7}))
    b = scenario_from_dict(mutated({"initial.perturbation": 0.1, "seed": 7}))
    c = scenario_from_dict(mutated({"initial.perturbation": 0.1, "seed": 8}))
    base = scenario_from_dict(worked_dict())
    assert np.array_equal(a.initial_positions_m, b.initial_positions_m)
    assert not np.array_equal(a.initial_positions_m, c.initial_positions_m)
    assert 0 < np.abs(a.initial_positions_m - base.initial_positions_m).max() < 1.0
    assert np.allclose(a.start.centroid_m, base.start.centroid_m)  # the reference is unperturbed


def test_templates_and_obstacles() -> None:
    grid = scenario_from_dict(mutated({"template": {"shape": "grid", "rows": 2, "cols": 3}}))
    assert grid.n == 6 and grid.template.name == "grid"
    data = mutated({"template": {"shape": "explicit", "offsets": [[1.0, 0.0], [-1.0, 0.0]]}})
    data["obstacles"] = [{"center": [0.0, 9.0], "radius": 0.5}, {"center": [9.0, 0.0], "radius": 1}]
    s = scenario_from_dict(data)
    assert s.n == 2 and len(s.obstacles) == 2 and s.obstacles[1].radius_m == 1.0
    d_min = s.limits.d_min_m or 0.0
    assert [o.clearance_m for o in s.obstacles] == [0.5 * d_min] * 2  # resolved when loaded
    data["obstacles"][0]["clearance"] = 0.1
    assert scenario_from_dict(data).obstacles[0].clearance_m == 0.1


NOT_CENTRED = {"shape": "explicit", "offsets": [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]]}
BAD_INPUTS: list[tuple[str, dict[str, Any], str, str]] = [
    ("unknown key", {"controller.gian": 2.0}, "controller.gian", "did you mean 'gain'"),
    ("unknown top key", {"sed": 1}, "sed", "did you mean 'seed'"),
    ("unknown table", {"controler": {"kind": "tracking"}}, "controler", "mean 'controller'"),
    ("wrong type", {"controller.gain": "fast"}, "controller.gain", "got 'fast'"),
    ("bool as number", {"template.n": True}, "template.n", "integer"),
    ("float as integer", {"template.n": 3.0}, "template.n", "integer"),
    ("nan", {"controller.gain": float("nan")}, "controller.gain", "finite"),
    ("inf", {"initial.centroid": [5.0, float("inf")]}, "initial.centroid", "finite"),
    ("zero scale", {"initial.scale": 0.0}, "initial.scale", "> 0"),
    ("negative goal scale", {"reference.scale": -1.0}, "reference.scale", "> 0"),
    ("uncentred offsets", {"template": NOT_CENTRED}, "template.offsets", "off by 0.471405"),
    ("gain * dt > 1", {"controller.gain": 100.0}, "controller.gain", "gain * dt"),
    ("missing key", {"simulation.dt": DELETE}, "simulation.dt", "missing"),
    ("missing table", {"simulation": DELETE}, "simulation", "missing table"),
    ("missing version", {"version": DELETE}, "version", "missing"),
    ("bad version", {"version": 2}, "version", "got 2"),
    ("bad dim", {"dim": 4}, "dim", "got 4"),
    ("bad choice", {"controller.kind": "trackng"}, "controller.kind", "did you mean 'tracking'"),
    ("key of another kind", {"reference.kind": "constant"}, "reference.rate", "only to"),
    ("mpc key on tracking", {"controller.horizon": 5}, "controller.horizon", "'mpc'"),
    ("short vector", {"initial.centroid": [5.0]}, "initial.centroid", "2 numbers"),
    ("too few positions", {"initial": {"positions": [[0.0, 0.0]]}}, "initial.positions", "3 rows"),
    ("positions and state", {"initial.positions": [[0, 0], [1, 0], [2, 0]]}, "initial.positions", "not both"),
    ("no initial state", {"initial": {"scale": 1.0}}, "initial.centroid", "missing"),
    ("sphere in 2D", {"template": {"shape": "sphere", "n": 4}}, "template.shape", "dim = 3"),
    (
        "grid layers in 2D",
        {"template": {"shape": "grid", "rows": 2, "cols": 2, "layers": 2}},
        "template.layers",
        "one layer",
    ),
    ("obstacles not an array", {"obstacles": {"center": [0, 0], "radius": 1}}, "obstacles", "[[obstacles]]"),
    ("bad obstacle", {"obstacles": [{"center": [0, 0], "radius": 0}]}, "obstacles[0].radius", "> 0"),
    ("downwash in 2D", {"limits.downwash": 2.0}, "limits.downwash", "dim = 3"),
    ("vertical bound in 2D", {"limits.v_max_z": 0.5}, "limits.v_max_z", "dim = 3"),
    (
        "geofence order",
        {"limits.geofence_min": [0, 0], "limits.geofence_max": [0, 1]},
        "limits.geofence_max",
        "geofence_min < geofence_max",
    ),
    (
        "unknown solver",
        {"controller.kind": "mpc", "controller.solver": "osqq"},
        "controller.solver",
        "did you mean 'osqp'",
    ),
    (
        "solver ignored per drone",
        {"controller.kind": "mpc", "controller.coupling": "decoupled", "controller.solver": "osqp"},
        "controller.solver",
        'kind = "sparse"',
    ),
    (
        "per drone with joint rows",
        {"controller.kind": "mpc", "controller.solve.kind": "per_drone"},
        "controller.solve.kind",
        "coupling = 'decoupled'",
    ),
    (
        "solve without a kind",
        {"controller.kind": "mpc", "controller.solve.backend": "osqp"},
        "controller.solve.kind",
        "missing required key",
    ),
    (
        "tolerance of a per-drone solve",
        {
            "controller.kind": "mpc",
            "controller.coupling": "decoupled",
            "controller.solve.kind": "per_drone",
            "controller.solve.eps_abs": 1e-6,
        },
        "controller.solve.eps_abs",
        "does not apply to kind = 'per_drone'",
    ),
    (
        "split rounds of a sparse solve",
        {"controller.kind": "mpc", "controller.solve.kind": "sparse", "controller.solve.stalled_split": 3},
        "controller.solve.stalled_split",
        "only to 'per_drone'",
    ),
    (
        "sparse backend per drone",
        {
            "controller.kind": "mpc",
            "controller.coupling": "decoupled",
            "controller.solve.kind": "per_drone",
            "controller.solve.backend": "osqp",
        },
        "controller.solve.backend",
        "unknown per-drone solver",
    ),
    (
        "old tolerance per drone",
        {"controller.kind": "mpc", "controller.coupling": "decoupled", "controller.eps_abs": 1e-6},
        "controller.eps_abs",
        'kind = "sparse"',
    ),
    (
        "old split rounds, sparse",
        {"controller.kind": "mpc", "controller.stalled_split": 3},
        "controller.stalled_split",
        "does not apply to this sparse solve",
    ),
    (
        "old per_drone, joint rows",
        {"controller.kind": "mpc", "controller.per_drone": True},
        "controller.per_drone",
        "coupling = 'decoupled'",
    ),
    (
        "old key beside the table",
        {"controller.kind": "mpc", "controller.max_iter": 10, "controller.solve.kind": "sparse"},
        "controller.max_iter",
        "not beside",
    ),
    ("uncountable steps", {"simulation.duration": 1e308}, "simulation.duration", "at most 1e+12 steps"),
    (
        "astronomical centroid",
        {"initial.centroid": [1e300, 0.0]},
        "initial.centroid",
        "magnitude at most 1e+06",
    ),
    ("shorter than a step", {"simulation.duration": 0.01}, "simulation.duration", "one step"),
    ("path in name", {"name": "../x"}, "name", "directory"),
    ("dot name", {"name": "."}, "name", "starting with a letter, a digit or '_'"),
    ("dot dot name", {"name": ".."}, "name", "starting with a letter, a digit or '_'"),
    ("long name", {"name": "a" * 10_000}, "name", "expected at most 100 characters"),
    (
        "tiny dt",
        {"simulation.dt": 1e-300},
        "simulation.dt",
        "expected a finite number >= 1e-6 [s], got 1e-300",
    ),
    ("unbounded with d_min", {"limits.unbounded": True}, "limits.unbounded", "but d_min = 0.5"),
]


@pytest.mark.parametrize(
    ("changes", "field", "fragment"), [c[1:] for c in BAD_INPUTS], ids=[c[0] for c in BAD_INPUTS]
)
def test_bad_input_names_the_field(changes: dict[str, Any], field: str, fragment: str) -> None:
    with pytest.raises(ScenarioError) as err:
        scenario_from_dict(mutated(changes))
    assert err.value.field == field
    assert str(err.value).startswith(f"{field}: ")
    assert fragment in str(err.value)
    assert "\n" not in str(err.value)


def test_a_name_of_100_characters_is_a_name() -> None:
    assert scenario_from_dict(mutated({"name": "a" * 100})).name == "a" * 100


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
def test_a_device_is_refused_before_it_is_read(device: str) -> None:
    start = time.perf_counter()
    with pytest.raises(ScenarioError, match="is a character device, not a regular file") as err:
        load_scenario(device)
    assert err.value.field == device and "at most 16 MiB" in str(err.value)
    assert time.perf_counter() - start < 1.0


def test_a_file_above_16_mib_is_refused_from_its_size(tmp_path: Path) -> None:
    big = tmp_path / "big.toml"
    with big.open("wb") as f:
        f.truncate(2**30)  # sparse: 1 GiB of size, no block on disk
    with pytest.raises(ScenarioError, match=r"is 1 GiB \(1,073,741,824 bytes\); expected a scenario file"):
        load_scenario(big)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ScenarioError, match="no such scenario file") as err:
        load_scenario(path)
    assert err.value.field == str(path)


def test_toml_syntax_error_gives_the_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.toml"
    path.write_text("version = 1\ndim = 2\n[controller]\ngain = \n")
    with pytest.raises(ScenarioError, match="line 4") as err:
        load_scenario(path)
    assert "TOML syntax error" in str(err.value) and "'gain ='" in str(err.value)


def test_toml_nan_literal(tmp_path: Path) -> None:
    path = tmp_path / "nan.toml"
    path.write_text(WORKED.read_text().replace("gain = 2.0", "gain = nan"))
    with pytest.raises(ScenarioError, match="expected a finite number > 0") as err:
        load_scenario(path)
    assert err.value.field == "controller.gain"


def test_a_byte_order_mark_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "bom.toml"
    raw = b"\xef\xbb\xbf" + WORKED.read_bytes()
    path.write_bytes(raw)
    s = load_scenario(path)
    assert s.n == 3 and s.source_sha256 == hashlib.sha256(raw).hexdigest()  # the hash of the file as it is
    assert scenario_text(raw) == WORKED.read_text()


def test_the_solve_table_and_the_old_keys_give_the_same_strategy_with_one_deprecation_line_each() -> None:
    new = scenario_from_dict(
        mutated(
            {
                "controller.kind": "mpc",
                "controller.coupling": "decoupled",
                "controller.solve.kind": "per_drone",
                "controller.solve.split_iterations": 4,
                "controller.solve.max_iter": 99,
            }
        )
    )
    old = scenario_from_dict(
        mutated(
            {
                "controller.kind": "mpc",
                "controller.coupling": "decoupled",
                "controller.split_iterations": 4,
                "controller.max_iter": 99,
            }
        )
    )
    assert new.controller.mpc == old.controller.mpc
    assert new.controller.mpc.strategy == PerDroneSolve(max_iter=99, split=SplitPolicy(iterations=4))
    assert new.warnings() == [] or all("deprecated" not in w for w in new.warnings())
    lines = [w for w in old.warnings() if "deprecated" in w]
    assert lines == [
        "controller.max_iter is deprecated: write [controller.solve] max_iter = 99",
        "controller.split_iterations is deprecated: write [controller.solve] split_iterations = 4",
    ]
    sparse = scenario_from_dict(
        mutated({"controller.kind": "mpc", "controller.solver": "osqp", "controller.eps_abs": 1e-6})
    )
    assert sparse.controller.mpc.strategy == SparseSolve("osqp", SolverOptions(1e-6, 1e-4, 4000, 0.0))


def test_scenario_from_dict_refuses_too_many_drones_before_building_the_template() -> None:
    data = tomllib.loads((SCENARIOS / "swap_planar_8.toml").read_text())
    data["template"]["n"] = 10**9  # a polygon of 10^9 drones would allocate gigabytes
    start = time.perf_counter()
    with pytest.raises(ScenarioError, match=r"^template.n: 1,000,000,000 drones would need about"):
        scenario_from_dict(data, max_memory_gib=4.0)
    assert time.perf_counter() - start < 1.0


def test_downwash_crazyswarm_is_the_ellipsoid_of_crazyswarm() -> None:
    doc = tomllib.loads((SCENARIOS / "swap_spatial_12.toml").read_text())
    doc["limits"]["downwash"] = "crazyswarm"
    limits = scenario_from_dict(doc).world.limits
    assert limits.downwash_kappa == pytest.approx(0.6 / doc["limits"]["d_min"])  # 0.24 / 0.6 m per pair
    doc["limits"]["downwash"] = "crazyswarn"
    with pytest.raises(ScenarioError, match=r"^limits.downwash: .* did you mean 'crazyswarm'"):
        scenario_from_dict(doc)
    doc["limits"] |= {"downwash": "crazyswarm", "d_min": 0.2}
    with pytest.raises(ScenarioError, match=r"^limits.downwash: .* expected d_min >= 0.24 m"):
        scenario_from_dict(doc)


def test_a_vertical_speed_bound_needs_v_max_and_is_recorded() -> None:
    doc = tomllib.loads((SCENARIOS / "swap_spatial_12.toml").read_text())
    doc["limits"]["v_max_z"] = 0.5
    assert scenario_from_dict(doc).limits.v_max_z_mps == 0.5
    del doc["limits"]["v_max"]
    with pytest.raises(ScenarioError, match=r"^limits.v_max_z: .* set v_max too"):
        scenario_from_dict(doc)
