"""The sweep subcommand's wiring: its description, options, the parsing of --seeds and --set, and
the options it shares with run."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from mpcform.cli.main import build_parser, main
from mpcform.cli.sweep_commands import SWEEP_DESCRIPTION, SWEEP_HELP, parse_seeds, parse_set
from mpcform.errors import ValidationError
from mpcform.run.sweep import DEFAULT_TOLERANCE_M

SWAP8 = str(Path(__file__).resolve().parents[2] / "scenarios" / "swap_planar_8.toml")


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


def test_parse_seeds() -> None:
    assert parse_seeds("0..3,7") == [0, 1, 2, 3, 7]
    assert parse_seeds("5") == [5] and parse_seeds("2,2,1") == [2, 1]
    for bad in ("a", "3..1", "-1", "1..x", "", "1,,2"):
        with pytest.raises(ValidationError, match="--seeds"):
            parse_seeds(bad)


def test_parse_set_reads_toml_values_and_bare_words() -> None:
    assert parse_set("controller.horizon=5,10") == ("controller.horizon", [5, 10])
    assert parse_set("controller.coupling=joint,decoupled") == ("controller.coupling", ["joint", "decoupled"])
    assert parse_set("initial.centroid=[1.0, 2.0],[0, 0]") == ("initial.centroid", [[1.0, 2.0], [0, 0]])
    assert parse_set('name="a,b",true') == ("name", ["a,b", True])
    for bad in ("=5", "controller.horizon=", "horizon", "a..b=1", "k=5,,10", "k=5,", "k= , "):
        with pytest.raises(ValidationError, match="--set"):
            parse_set(bad)


def test_a_huge_seed_range_is_refused_before_the_list_is_built() -> None:
    with pytest.raises(
        ValidationError, match=r"^--seeds: '0..100000000' lists 100,000,001 seeds or more, above"
    ):
        parse_seeds("0..100000000")


@pytest.mark.parametrize(
    ("argv", "says"),
    [
        (["--seeds", "0..100000000"], "--seeds: '0..100000000' lists 100,000,001 seeds or more"),
        (["--seeds", ""], "--seeds: expected e.g. 0..19 or 0,3,7, got ''"),
        (
            ["--seeds", "0", "--set", "controller.horizon=5,,10"],
            "--set: expected KEY=VALUE[,VALUE...] without",
        ),
        (["--seeds", "0", "--solver", "bogus"], "--solver: solver 'bogus': unknown solver"),
    ],
)
def test_bad_sweep_options_are_one_error_before_any_run(
    argv: list[str], says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sweep", SWAP8, *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"mpcform: error: {says}") and err.count("\n") == 1, err
