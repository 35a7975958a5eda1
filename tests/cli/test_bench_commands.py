"""The bench and problems subcommands' wiring: the benchmark families, their options, the checks
made before a benchmark runs, and what each says as it runs (its plan within 2 s, a line per case)."""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mpcform.bench.problems import problem_files
from mpcform.cli import bench_plans as plans
from mpcform.cli.main import build_parser, main

ROOT = Path(__file__).resolve().parents[2]
SWAP = str(ROOT / "scenarios" / "swap_planar_8.toml")


def _choices(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_bench_has_one_subcommand_per_family() -> None:
    bench = _choices(build_parser())["bench"]
    assert list(_choices(bench)) == ["mpc", "solvers", "closed-loop", "scale", "split", "plant", "online"]
    problems = _choices(build_parser())["problems"]
    assert list(_choices(problems)) == ["export"]


def test_every_bench_writes_json_records() -> None:
    for name, cmd in _choices(_choices(build_parser())["bench"]).items():
        assert "--json PATH" in cmd.format_help(), name


def test_bench_mpc_defaults() -> None:
    args = build_parser().parse_args(["bench", "mpc"])
    assert args.n == [8, 16, 32, 64] and args.spatial_n == [20] and args.steps == 60
    assert args.coupling == "joint" and args.cvxpy_budget == 60.0 and args.scenarios is None


@pytest.mark.parametrize("budget", ["-1", "inf"])
def test_bench_mpc_refuses_a_bad_cvxpy_budget(budget: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "mpc", "--cvxpy-budget", budget]) == 2
    assert "expected a number of seconds >= 0" in capsys.readouterr().err


@pytest.mark.parametrize("extra", [["--rounds", "0", "-1"], ["--steps", "0"]])
def test_bench_split_refuses_negative_rounds_before_running(
    extra: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bench", "split", *extra]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and "--rounds must be >= 0 and --steps >= 1" in captured.err


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (
            ["--n", "2", "--duration", "-1"],
            "--duration: expected a flight time >= 0.1 s (one control interval), got -1",
        ),
        (["--duration", "nan"], "--duration: expected a flight time >= 0.1 s"),
        (["--rate", "0"], "--rate: expected a finite inner-loop rate > 0 [Hz], got 0"),
        (["--n", "0"], "--n: expected an integer >= 1, got 0"),
        (["--repeats", "0"], "--repeats: expected an integer >= 1, got 0"),
        (
            ["--duration", "1e9"],
            "--duration: the plant would take 1e+13 inner steps x drones (500 Hz x 1e+09 s x 20",
        ),
        (["--rate", "1e9"], "--rate: the plant would take 2.4e+11 inner steps x drones"),
    ],
)
def test_bench_plant_refuses_bad_sizes_before_running(
    argv: list[str], says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bench", "plant", *argv]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.startswith(f"mpcform: error: {says}") and captured.err.count("\n") == 1, captured.err


def test_bench_mpc_without_cases_is_one_error(capsys: pytest.CaptureFixture[str]) -> None:
    """``--n 0 --spatial-n --scenarios --cvxpy-budget 0`` divided by zero (issue 38)."""
    assert main(["bench", "mpc", "--n", "0", "--spatial-n", "--scenarios", "--cvxpy-budget", "0"]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("mpcform: error: --n/--spatial-n/--steps: expected swaps of >= 2 drones")
        and "\n" == err[-1]
    )


def test_problems_export_writes_into_the_working_directory_by_default(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Not into the installed package's problems/ (in a checkout's root: the bundled one)."""
    monkeypatch.chdir(tmp_path)
    swap = str(Path(__file__).resolve().parents[2] / "scenarios" / "swap_planar_8.toml")
    assert main(["problems", "export", swap, "--per-scenario", "1"]) == 0
    assert [p.parent for p in (tmp_path / "problems").rglob("*") if p.is_file()]
    assert "to problems" in capsys.readouterr().out


def test_every_bench_help_says_what_it_measures_and_its_defaults() -> None:
    for name, cmd in _choices(_choices(build_parser())["bench"]).items():
        text = cmd.format_help()
        assert cmd.description and cmd.description in " ".join(text.split()), name
    plant = _choices(_choices(build_parser())["bench"])["plant"].format_help()
    assert (
        "drones (default: 20)" in plant and "(default: None)" not in plant and "(default: False)" not in plant
    )


def test_bench_online_refuses_bad_sizes(capsys) -> None:
    joint = ["--coupling", "joint", "--n", "20"]  # the online loop refuses a joint swarm this large
    bad = (
        (["--n", "1"], "--n"),
        (["--steps", "0"], "--steps"),
        (["--budget", "0"], "--budget"),
        (joint, "--coupling"),
    )
    for argv, flag in bad:
        assert main(["bench", "online", *argv]) == 2
        assert f"mpcform: error: {flag}" in capsys.readouterr().err


@pytest.mark.parametrize("bench", ["scale", "online"])
def test_a_bad_profile_path_is_one_line_naming_the_option_before_any_case(
    bench: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for path, why in ((tmp_path, "is a directory"), (tmp_path / "missing" / "p.txt", "does not exist")):
        assert main(["bench", bench, "--n", "4", "--steps", "1", "--profile", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("mpcform: error: --profile: ") and why in err and err.count("\n") == 1
        assert f"bench {bench}: " not in err  # no plan, no case
    assert not (tmp_path / "missing").exists()


SMALLEST = {  # each benchmark's smallest real run, and its number of cases
    "mpc": (["--n", "4", "6", "--spatial-n", "--scenarios", "--steps", "3", "--cvxpy-budget", "0"], 2),
    "solvers": (["--solvers", "piqp", "--settings", "default", "--modes", "cold", "--no-exact"], 2),
    "closed-loop": ([SWAP, "--solvers", "piqp", "--duration", "0.2"], 1),
    "scale": (
        [
            "--n",
            "4",
            "8",
            "--steps",
            "2",
            "--scenario",
            "formation",
            "--monolithic-budget",
            "0",
            "--in-process",
        ],
        2,
    ),
    "split": (["--scenarios", SWAP, "--rounds", "0", "1", "--steps", "3"], 1),
    "plant": (["--n", "2", "--duration", "0.2", "--repeats", "2"], 2),
    "online": (["--n", "4", "6", "--steps", "3"], 2),
}


@pytest.fixture(scope="module")
def two_problems(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("problems")
    for f in problem_files(ROOT / "problems")[:2]:
        (out / f.parent.name).mkdir(exist_ok=True)
        shutil.copy(f, out / f.parent.name / f.name)
    return out


def _import_floor_s(env: dict[str, str]) -> float:
    """How long this machine, now, takes to start the interpreter and import the command."""
    start = time.monotonic()
    subprocess.run([sys.executable, "-c", "import mpcform.cli.main"], env=env, check=True)
    return time.monotonic() - start


@pytest.mark.parametrize("name", list(SMALLEST))
def test_every_bench_says_its_plan_within_2_s_then_a_line_per_case(
    name: str, two_problems: Path, tmp_path: Path
) -> None:
    """The plan within 2 s of the process's start (on a machine so loaded that importing the
    command alone takes over 1.5 s, within 0.5 s of that import), then one line per case."""
    argv, cases = SMALLEST[name]
    if name == "solvers":
        argv = [*argv, "--problems", str(two_problems)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    limit = max(2.0, _import_floor_s(env) + 0.5)
    start = time.monotonic()
    proc = subprocess.Popen(
        [sys.executable, "-m", "mpcform.cli.main", "bench", name, *argv, "--json", str(tmp_path / "r.json")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    assert proc.stderr is not None and proc.stdout is not None
    first = proc.stderr.readline()
    took = time.monotonic() - start
    rest, out = proc.stderr.read(), proc.stdout.read()  # the tables are far below a pipe's buffer
    proc.wait(timeout=60)
    assert proc.returncode == 0, first + rest
    assert took < limit, f"first line after {took:.2f} s (limit {limit:.2f} s): {first!r}"
    assert first.startswith(f"bench {name}: ") and "time: " in first, first
    lines = [first, *rest.splitlines()]
    assert all(line.startswith(f"bench {name}: ") for line in lines), lines
    seen = [m.groups() for line in lines if (m := re.match(rf"bench {name}: (\d+)/(\d+) \S", line))]
    assert seen == [(str(i), str(cases)) for i in range(1, cases + 1)], lines
    assert "elapsed" in lines[-2] and lines[-1].startswith(f"bench {name}: done: ")
    assert "|" in out and f"bench {name}:" not in out  # stdout: the table alone
    assert (tmp_path / "r.json").read_text().startswith("[")


def test_every_bench_help_names_the_run_time_of_its_defaults() -> None:
    for name, cmd in _choices(_choices(build_parser())["bench"]).items():
        text = " ".join(cmd.format_help().split())
        assert f"Run time of the defaults on a 2-core machine: {plans.RUN_TIMES[name]}." in text, name
