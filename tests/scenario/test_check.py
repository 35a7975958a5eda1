"""`mpcform validate`'s checker: every problem of a file at once, each with its key and line."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from mpcform.errors import ScenarioError
from mpcform.scenario.check import Problem, check_scenario_file, locate, located_problem

ROOT = Path(__file__).resolve().parents[2]

MESSY = """\
version = 1
dim = 2
sed = 3

[template]
shape = "polygon"
n = 3
radius = -1.0

[initial]
centroid = [5.0, 5.0, 1.0]

[reference]
kind = "mission"

[[reference.keyframes]]
scale = 2.0

[[reference.keyframes]]
scale = -2.0
template = { shape = "lime", n = 3 }

[limit]
v_max = 3.0

[controller]
kind = "tracking"
gian = 2.0
gain = 200.0

[simulation]
dt = 0.02
duration = 10.0

[[obstacles]]
center = [1.0, 2.0]
radius = 1.0

[[obstacles]]
center = [1.0, 2.0]
radius = 0.0
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scenario.toml"
    path.write_text(text)
    return path


def test_valid_file_has_no_problems() -> None:
    result = check_scenario_file(ROOT / "scenarios" / "worked_example.toml")
    assert result.ok and result.scenario is not None and result.scenario.n == 3


def test_every_problem_at_once_with_its_line(tmp_path: Path) -> None:
    result = check_scenario_file(write(tmp_path, MESSY))
    assert not result.ok and result.scenario is None
    found = {(p.field, p.line) for p in result.problems}
    assert found == {
        ("sed", 3),
        ("template.radius", 8),
        ("initial.centroid", 11),
        ("reference.keyframes[1].scale", 20),
        ("reference.keyframes[1].template.shape", 21),
        ("limit", 23),
        ("controller.gian", 28),
        ("controller.gain", 29),
        ("obstacles[1].radius", 41),
    }
    messages = {p.field: p.message for p in result.problems}
    assert "did you mean 'seed'" in messages["sed"]
    assert "did you mean 'limits'" in messages["limit"]
    assert "did you mean 'gain'" in messages["controller.gian"]
    assert "gain * dt" in messages["controller.gain"]
    assert "did you mean 'line'" in messages["reference.keyframes[1].template.shape"]
    lines = [p.line for p in result.problems]
    assert lines == sorted(lines)  # in file order
    assert str(result.problems[0]) == f"line 3: sed: {messages['sed']}"


def test_syntax_error_is_one_problem(tmp_path: Path) -> None:
    result = check_scenario_file(write(tmp_path, "version = 1\ndim = \n"))
    (problem,) = result.problems
    assert "TOML syntax error" in problem.message and "line 2" in problem.message


def test_missing_file(tmp_path: Path) -> None:
    (problem,) = check_scenario_file(tmp_path / "nope.toml").problems
    assert "no such scenario file" in problem.message


def test_a_bad_dimension_still_checks_key_names(tmp_path: Path) -> None:
    text = (ROOT / "scenarios" / "worked_example.toml").read_text()
    text = text.replace("dim = 2", "dim = 4").replace("gain = 2.0", "gian = 2.0")
    fields = {p.field for p in check_scenario_file(write(tmp_path, text)).problems}
    assert {"dim", "controller.gian"} <= fields


def test_consequences_are_not_reported(tmp_path: Path) -> None:
    text = (ROOT / "scenarios" / "worked_example.toml").read_text().replace("[template]", "[templates]")
    problems = check_scenario_file(write(tmp_path, text)).problems
    assert [p.field for p in problems] == ["templates"]  # not: missing [template], unknown shape, ...


def test_bad_start_positions_are_one_problem(tmp_path: Path) -> None:
    """Not also "initial.centroid: missing" once the bad positions are set aside."""
    text = (ROOT / "scenarios" / "worked_example.toml").read_text()
    start = text[text.index("[initial]") : text.index("[reference]")]
    far = "[1e300, 0.0], [-1e300, 0.0], [0.0, 1e300]"  # its three drones
    problems = check_scenario_file(
        write(tmp_path, text.replace(start, f"[initial]\npositions = [{far}]\n\n"))
    ).problems
    assert [p.field for p in problems] == ["initial.positions"] and "magnitude" in problems[0].message


def test_every_missing_table_at_once(tmp_path: Path) -> None:
    problems = check_scenario_file(write(tmp_path, "version = 1\ndim = 2\n")).problems
    assert [p.field for p in problems] == ["template", "initial", "reference", "controller", "simulation"]
    assert all("missing table" in p.message for p in problems)


def test_an_unknown_plant_kind_is_one_problem(tmp_path: Path) -> None:
    """Not also "plant.rate: does not apply to kind = 'ideal'" for every quadrotor key after it."""
    text = (ROOT / "scenarios" / "swap_spatial_12_quadrotor_wind.toml").read_text()
    text = text.replace('kind = "quadrotor"', 'kind = "helicopter"')
    problems = check_scenario_file(write(tmp_path, text)).problems
    assert [p.field for p in problems] == ["plant.kind"]


def test_an_unbounded_a_max_on_a_real_plant_is_a_problem_at_its_line(tmp_path: Path) -> None:
    """``limits.a_max = inf`` on the quadrotor: refused at its own line (it lacked FILE:LINE)."""
    text = (ROOT / "scenarios" / "swap_spatial_12_quadrotor_wind.toml").read_text()
    text = text.replace("[limits]\n", "[limits]\na_max = inf\n")
    path = write(tmp_path, text)
    (problem,) = check_scenario_file(path).problems
    line = text.splitlines().index("a_max = inf") + 1
    assert problem.text(path).startswith(f"{path}:{line}: limits.a_max: inf (no bound) applies to the ideal")


@pytest.mark.parametrize(
    ("field", "line"),
    [
        ("dim", 2),
        ("template", 5),
        ("template.radius", 8),
        ("reference.keyframes[0].scale", 17),
        ("reference.keyframes[1]", 19),
        ("reference.keyframes[1].template.n", 21),
        ("obstacles[1].radius", 41),
        ("obstacles[0]", 35),
        ("controller.horizon", None),
        ("graph.kind", None),
    ],
)
def test_locate(field: str, line: int | None) -> None:
    assert locate(MESSY, field) == line


# ---- one line per problem, memory, byte order mark ---------------------------------------------
def test_problem_text_is_file_line_key_message() -> None:
    assert Problem("sed", "unknown key", 3).text("a.toml") == "a.toml:3: sed: unknown key"
    assert Problem("limits.v_max", "needed", None).text("a.toml") == "a.toml: limits.v_max: needed"
    assert Problem("a.toml", "TOML syntax error: x").text("a.toml") == "a.toml: TOML syntax error: x"
    assert Problem("k", "two\n  lines", 1).text("a.toml") == "a.toml:1: k: two lines"


def test_a_run_too_large_is_a_problem_at_its_key(tmp_path: Path) -> None:
    text = (ROOT / "scenarios" / "worked_example.toml").read_text()
    text = text.replace("duration = 10.0", "duration = 1e9")
    path = write(tmp_path, text)
    (problem,) = check_scenario_file(path).problems
    assert problem.field == "simulation.duration" and "GiB of memory" in problem.message
    assert text.splitlines()[problem.line - 1].startswith("duration = 1e9")  # type: ignore[operator]
    assert check_scenario_file(path, max_memory_gib=None).ok
    assert check_scenario_file(path, max_memory_gib=1e6).ok


def test_the_memory_check_comes_before_any_controller_is_built(tmp_path: Path) -> None:
    text = (ROOT / "scenarios" / "swap_planar_8.toml").read_text()
    text = text.replace("horizon = 10", 'horizon = 1000000\ncoupling = "decoupled"\nhroizon = 3')
    start = time.perf_counter()
    problems = check_scenario_file(write(tmp_path, text)).problems  # dense (H d)^2 matrices: 32 TB
    assert time.perf_counter() - start < 5.0
    assert [p.field for p in problems] == ["controller.horizon", "controller.hroizon"]


def test_a_byte_order_mark_is_accepted(tmp_path: Path) -> None:
    path = tmp_path / "bom.toml"
    text = (ROOT / "scenarios" / "worked_example.toml").read_text()
    path.write_bytes(b"\xef\xbb\xbf" + text.replace("gain = 2.0", "gian = 2.0").encode())
    (problem,) = check_scenario_file(path).problems
    assert problem.field == "controller.gian"
    assert text.splitlines()[problem.line - 1].startswith("gain = 2.0")  # type: ignore[operator]


def test_located_problem_finds_the_line_of_an_error(tmp_path: Path) -> None:
    path = write(tmp_path, MESSY)
    problem = located_problem(ScenarioError("controller.gain", "too high"), path)
    assert (problem.field, problem.line, problem.message) == ("controller.gain", 29, "too high")
    assert located_problem(ScenarioError(str(path), "x"), path).line is None


def test_too_many_drones_and_a_plant_rate_too_high_are_problems_at_their_keys(tmp_path: Path) -> None:
    text = (ROOT / "scenarios" / "swap_planar_8.toml").read_text().replace("\nn = 8\n", "\nn = 1000000000\n")
    start = time.perf_counter()
    (problem,) = check_scenario_file(write(tmp_path, text)).problems
    assert time.perf_counter() - start < 5.0  # the template of 10^9 drones is never built
    assert problem.field == "template.n" and problem.message.startswith("1,000,000,000 drones would need")
    assert text.splitlines()[problem.line - 1] == "n = 1000000000"  # type: ignore[operator]
    quad = (ROOT / "scenarios" / "swap_spatial_12_quadrotor_wind.toml").read_text()
    path = write(tmp_path, quad.replace("\nrate = 500\n", "\nrate = 1000000\n"))
    (problem,) = check_scenario_file(path).problems
    assert problem.field == "plant.rate" and "--max-work N" in problem.message
    assert check_scenario_file(path, max_work=None).ok and check_scenario_file(path, max_work=2e8).ok
