"""The sweep subcommand's wiring: its description, options and the options it shares with run."""

from __future__ import annotations

import argparse

import pytest

from mpcform.cli.main import build_parser, main
from mpcform.cli.sweep_commands import SWEEP_DESCRIPTION, SWEEP_HELP
from mpcform.run.sweep import DEFAULT_TOLERANCE_M


def _commands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_sweep_has_a_description_and_max_memory() -> None:
    commands = _commands()
    sweep = commands["sweep"]
    assert sweep.description == SWEEP_DESCRIPTION
    assert "--max-memory" in sweep.format_help() and "--tol" in sweep.format_help()
    for command in ("run", "validate"):
        assert "--max-memory GIB" in commands[command].format_help()


def test_sweep_defaults() -> None:
    args = build_parser().parse_args(["sweep", "a.toml"])
    assert args.scenario == "a.toml" and args.jobs == 1 and args.executor == "process"
    assert args.tol == DEFAULT_TOLERANCE_M and args.set == [] and args.seeds is None
    assert SWEEP_HELP in build_parser().format_help()


def test_sweep_collects_every_set_and_checks_max_memory(capsys: pytest.CaptureFixture[str]) -> None:
    args = build_parser().parse_args(
        ["sweep", "a.toml", "--set", "controller.horizon=5,10", "--set", "seed=1,2", "--jobs", "2"]
    )
    assert args.set == ["controller.horizon=5,10", "seed=1,2"] and args.jobs == 2
    assert main(["sweep", "a.toml", "--max-memory", "0"]) == 2
    assert "expected a number of GiB > 0" in capsys.readouterr().err
