"""The options the subcommands share: solver help, --max-memory, time budgets, and how the table
commands print (markdown, --json records, progress lines only on a terminal)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from mpcform.cli.options import (
    add_max_memory,
    add_max_work,
    add_profile,
    max_memory_gib,
    max_work,
    print_bench,
    progress,
    seconds,
    solver_help,
)
from mpcform.scenario.size import DEFAULT_MAX_MEMORY_GIB, DEFAULT_MAX_WORK
from mpcform.solvers.casadi_conic import CASADI_CONIC_PLUGINS
from mpcform.solvers.registry import DEFAULT_SOLVER, PERSISTENT_SOLVERS


def test_solver_help_names_the_backends_and_the_families() -> None:
    text = solver_help()
    for name in PERSISTENT_SOLVERS:
        assert name in text
    assert f"{DEFAULT_SOLVER} (default)" in text and "qpsolvers:<name>" in text and "casadi:<plugin>" in text
    assert all(plugin in text for plugin in CASADI_CONIC_PLUGINS) and "casadi:ipopt" in text


@pytest.mark.parametrize("text", ["0", "-1", "nan", "inf", "lots"])
def test_max_memory_must_be_a_positive_number(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="expected a number of GiB > 0"):
        max_memory_gib(text)


def test_max_memory_value() -> None:
    assert max_memory_gib("0.5") == 0.5 and max_memory_gib("64") == 64.0


def test_add_max_memory_defaults_and_parses() -> None:
    parser = argparse.ArgumentParser()
    add_max_memory(parser, "sweep run")
    assert parser.parse_args([]).max_memory == DEFAULT_MAX_MEMORY_GIB
    assert parser.parse_args(["--max-memory", "2.5"]).max_memory == 2.5
    assert "refuse a sweep run estimated" in parser.format_help()


@pytest.mark.parametrize("text", ["-1", "nan", "inf", "soon"])
def test_seconds_must_be_a_finite_number_at_least_zero(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="expected a number of seconds >= 0"):
        seconds(text)


def test_seconds_value() -> None:
    assert seconds("0") == 0.0 and seconds("60") == 60.0


def test_print_bench_prints_the_table_and_writes_the_records(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import numpy as np

    rows = [{"n": 8, "ms": np.float64(0.25)}, {"n": 16, "ms": None}]
    out = tmp_path / "rows.json"
    print_bench("| n |\n| --- |", rows, str(out))
    assert capsys.readouterr().out == "| n |\n| --- |\n"
    assert json.loads(out.read_text()) == [{"n": 8, "ms": 0.25}, {"n": 16, "ms": None}]
    print_bench("table", rows, None)  # no --json: nothing written
    assert capsys.readouterr().out == "table\n"


def test_progress_is_silent_when_stderr_is_not_a_terminal(capsys: pytest.CaptureFixture[str]) -> None:
    progress("bench: 1/3")
    assert capsys.readouterr() == ("", "")


@pytest.mark.parametrize("text", ["0", "-1", "nan", "inf", "lots"])
def test_max_work_must_be_a_positive_number(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match="expected a number of inner steps x drones > 0"):
        max_work(text)


def test_add_max_work_defaults_and_parses() -> None:
    parser = argparse.ArgumentParser()
    add_max_work(parser, "sweep run")
    assert parser.parse_args([]).max_work == DEFAULT_MAX_WORK
    assert parser.parse_args(["--max-work", "2e8"]).max_work == 2e8
    assert "refuse a sweep run whose plant takes more inner steps x drones" in parser.format_help()


def test_add_profile_takes_a_path() -> None:
    cmd = argparse.ArgumentParser()
    add_profile(cmd)
    assert cmd.parse_args([]).profile is None and cmd.parse_args(["--profile", "p.txt"]).profile == "p.txt"
    assert "top 30 functions" in cmd.format_help()
