"""The export's flags: parsed into ExportOptions with the Crazyflie's defaults; bad values refused."""

from __future__ import annotations

import argparse

import pytest

from mpcform.cli.export_flags import add_export_options, export_options
from mpcform.outputs.flight.export import ExportOptions


def parser() -> argparse.ArgumentParser:
    cmd = argparse.ArgumentParser(exit_on_error=False)
    add_export_options(cmd)
    return cmd


def test_the_defaults_are_the_librarys() -> None:
    opts = export_options(parser().parse_args([]))
    default = ExportOptions()
    assert (
        opts.limits.max_speed_mps == default.limits.max_speed_mps and opts.tolerance_m == default.tolerance_m
    )
    assert (opts.allow_untracked, opts.allow_limits, opts.fly) == (False, False, True)


def test_flags_reach_the_options() -> None:
    argv = ["--offset", "1,2,3", "--allow-untracked", "--no-flight-check", "--yaw", "formation"]
    opts = export_options(parser().parse_args(argv))
    assert opts.offset_m == (1.0, 2.0, 3.0) and opts.allow_untracked and not opts.fly
    assert opts.yaw == "formation"


@pytest.mark.parametrize("text", ["1,2", "a,b,c", "1,2,3,4"])
def test_an_offset_needs_three_numbers(text: str) -> None:
    with pytest.raises(argparse.ArgumentError, match="expected X,Y,Z"):
        parser().parse_args(["--offset", text])
