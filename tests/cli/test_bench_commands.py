"""The bench and problems subcommands' wiring: the benchmark families, their options and the checks
made before a benchmark runs."""

from __future__ import annotations

import argparse

import pytest

from mpcform.cli.main import build_parser, main


def _choices(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_bench_has_one_subcommand_per_family() -> None:
    bench = _choices(build_parser())["bench"]
    assert list(_choices(bench)) == ["mpc", "solvers", "closed-loop", "scale", "split", "plant"]
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
