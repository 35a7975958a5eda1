"""The markdown tables of the benchmark and batch commands (``mpcform.outputs.tables``): one header,
one separator, one line per row with as many cells as columns; each value in its column's format;
missing, empty and non-finite values as ``-``; pipes escaped; special formatters win."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mpcform.outputs.tables import Column, markdown_table

COLUMNS: list[Column] = [
    ("case", "case", "{}"),
    ("n", "drones", "{:d}"),
    ("ms", "step [ms]", "{:.2f}"),
    ("ratio", "ratio", "{:.1f}x"),
    ("share", "share", "{:.0%}"),
]


def _cells(line: str) -> list[str]:
    assert line.startswith("| ") and line.endswith(" |"), line
    return [c.strip() for c in line[2:-2].split(" | ")]


def test_header_separator_and_one_line_per_row() -> None:
    rows = [
        {"case": "swap", "n": 8, "ms": 0.123, "ratio": 2.25, "share": 0.5},
        {"case": "ring", "n": 1000, "ms": 12.0, "ratio": 10.0, "share": 1.0},
    ]
    lines = markdown_table(rows, COLUMNS).splitlines()
    assert len(lines) == 2 + len(rows)
    assert _cells(lines[0]) == ["case", "drones", "step [ms]", "ratio", "share"]
    assert lines[1] == "| --- | --- | --- | --- | --- |"
    assert _cells(lines[2]) == ["swap", "8", "0.12", "2.2x", "50%"]
    assert _cells(lines[3]) == ["ring", "1000", "12.00", "10.0x", "100%"]
    # every line has the same number of cell separators: the columns line up in any renderer
    assert len({line.count(" | ") for line in lines if line != lines[1]}) == 1
    assert lines[1].count("---") == len(COLUMNS)


def test_no_rows_is_header_and_separator() -> None:
    assert markdown_table([], COLUMNS).splitlines() == [
        "| case | drones | step [ms] | ratio | share |",
        "| --- | --- | --- | --- | --- |",
    ]


@pytest.mark.parametrize("missing", [None, "", [], float("nan"), float("inf"), -float("inf")])
def test_missing_empty_and_non_finite_show_as_a_dash(missing: Any) -> None:
    line = markdown_table([{"case": "a", "n": 1, "ms": missing}], COLUMNS).splitlines()[-1]
    assert _cells(line) == ["a", "1", "-", "-", "-"]  # absent keys are dashes too


def test_zero_is_a_number_not_missing() -> None:
    line = markdown_table([{"case": 0, "n": 0, "ms": 0.0, "ratio": 0.0, "share": 0.0}], COLUMNS)
    assert _cells(line.splitlines()[-1]) == ["0", "0", "0.00", "0.0x", "0%"]


def test_pipes_in_values_are_escaped() -> None:
    line = markdown_table([{"case": "a|b", "n": 2}], COLUMNS).splitlines()[-1]
    assert line.startswith("| a\\|b | 2 |")


def test_a_special_formatter_formats_its_column_even_when_missing() -> None:
    special = {"ms": lambda v: "skipped" if v is None else f"~{v:g}"}
    lines = markdown_table([{"ms": None}, {"ms": 1.5}], COLUMNS, special).splitlines()
    assert _cells(lines[2])[2] == "skipped" and _cells(lines[3])[2] == "~1.5"
    assert _cells(lines[2])[0] == "-"  # the other columns keep the usual rules


def test_python_numbers_from_numpy_results_format() -> None:
    value = float(np.median([1.0, 2.0, 4.0]))
    assert _cells(markdown_table([{"ms": value}], COLUMNS).splitlines()[-1])[2] == "2.00"


@pytest.mark.parametrize("value", [np.float64(2.0), np.int64(2), np.float64("nan")])
def test_numpy_scalars_format_like_python_numbers(value: Any) -> None:
    line = markdown_table([{"ms": value}], COLUMNS).splitlines()[-1]
    assert _cells(line)[2] == ("-" if np.isnan(value) else "2.00")
