"""The ``mpcform`` command, called through ``main(argv)``: exit codes and one-line errors."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpcform.cli.main import main
from mpcform.scenario.keys import key_reference_markdown

ROOT = Path(__file__).resolve().parents[2]
WORKED = str(ROOT / "scenarios" / "worked_example.toml")


def short_copy(tmp_path: Path, replace: tuple[str, str] = ("duration = 10.0", "duration = 0.2")) -> str:
    path = tmp_path / "scenario.toml"
    path.write_text(Path(WORKED).read_text().replace(*replace))
    return str(path)


def assert_one_line_error(
    capsys: pytest.CaptureFixture[str], status: int, *fragments: str, usage: bool = False
) -> str:
    """Exit status 2, no traceback, and one error line (after argparse's usage line if any)."""
    err = capsys.readouterr().err
    assert status == 2
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert usage or len(lines) == 1, err
    last = lines[-1]
    assert last.startswith("mpcform: error: ")
    for fragment in fragments:
        assert fragment in last
    return last


def test_run_writes_the_outputs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["run", WORKED, "--out", str(out)]) == 0
    stdout = capsys.readouterr().out
    assert "final tracking error" in stdout and str(out) in stdout
    assert {p.name for p in out.iterdir()} == {"trajectory.npz", "trajectory.csv", "summary.json"}
    summary = json.loads((out / "summary.json").read_text())
    assert summary["steps"] == 500 and summary["metrics"]["final_tracking_error"] < 1e-3


def test_run_default_out_dir_is_relative_to_the_working_directory(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    path = short_copy(tmp_path)
    monkeypatch.chdir(tmp_path)
    assert main(["run", path, "--controller", "proportional"]) == 0
    summary = json.loads((tmp_path / "results" / "worked_example" / "summary.json").read_text())
    assert summary["controller"] == "proportional" and summary["steps"] == 10


def test_run_mpc_with_solver(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("mpcform.mpc.planner")
    path = short_copy(tmp_path)
    assert main(["run", path, "--out", str(tmp_path / "o"), "--controller", "mpc",
                 "--solver", "osqp"]) == 0  # fmt: skip
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert summary["controller"] == "mpc" and summary["solver"] == "osqp"


def test_validate(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", WORKED]) == 0
    out = capsys.readouterr().out.strip()
    assert out.startswith("OK worked_example: 3 drones") and "\n" not in out


@pytest.mark.parametrize(
    ("replace", "fragments"),
    [
        (("gain = 2.0", "gian = 2.0"), ("controller.gian", "did you mean 'gain'")),
        (("gain = 2.0", "gain = 200.0"), ("controller.gain", "gain * dt")),
        (("gain = 2.0", "gain = nan"), ("controller.gain", "finite")),
        (("scale = 2.0", "scale = 0"), ("reference.scale", "> 0")),
        (("[limits]", "[limit]"), ("limit", "did you mean 'limits'")),
        (("dim = 2", 'dim = "two"'), ("dim", "'two'")),
        (("rate = 1.0", "rate = "), ("TOML syntax error", "line 24")),
    ],
)
@pytest.mark.parametrize("command", ["run", "validate"])
def test_bad_scenario_exits_2_with_one_line(
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    command: str,
    replace: tuple[str, str],
    fragments: tuple[str, ...],
) -> None:
    path = short_copy(tmp_path, replace)
    status = main([command, path, *(["--out", str(tmp_path / "o")] if command == "run" else [])])
    assert_one_line_error(capsys, status, *fragments)
    assert not (tmp_path / "o").exists()


def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status = main(["run", str(tmp_path / "missing.toml")])
    assert_one_line_error(capsys, status, "missing.toml", "no such scenario file")


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["run", WORKED, "--controller", "trackin"], ("--controller", "did you mean 'tracking'")),
        (["run", WORKED, "--solver", "osqp"], ("only to the mpc controller",)),
        (["run", WORKED, "--controller", "mpc", "--solver", "nope"], ("solver", "unknown solver")),
        (["run", str(ROOT / "scenarios" / "formation_flight_100.toml"), "--solver", "osqp"],
         ("solver: 'osqp' solves the sparse QP", "per_drone = false")),  # decoupled, per drone
    ],
)
def test_bad_overrides(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], fragments: tuple[str, ...]
) -> None:
    assert_one_line_error(capsys, main([*argv, "--out", str(tmp_path)]), *fragments)


@pytest.mark.parametrize(
    "argv", [[], ["run"], ["frobnicate"], ["run", WORKED, "--bogus"], ["validate", "a", "b"]]
)
def test_usage_errors_exit_2(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    assert_one_line_error(capsys, main(argv), usage=True)


def test_solvers_lists_backends(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solvers"]) == 0
    lines = capsys.readouterr().out.splitlines()
    names = {line.split()[0]: line.split()[1] for line in lines[1:]}
    assert names["osqp"] == "yes"
    for name in ("piqp", "casadi:osqp", "casadi:qpoases", "casadi:hpipm", "casadi:ipopt"):
        assert names[name] in ("yes", "no")
    assert all(state in ("yes", "no") for state in names.values())


def test_keys_prints_the_key_reference(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["keys"]) == 0
    assert capsys.readouterr().out == key_reference_markdown()
