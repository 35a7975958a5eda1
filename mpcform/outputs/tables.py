"""Markdown tables for the benchmark and batch commands (one format everywhere)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

Column = tuple[str, str, str]
"""``(record key, column title, format string)``."""


def markdown_table(
    rows: Sequence[Mapping[str, Any]],
    columns: Sequence[Column],
    special: Mapping[str, Callable[[Any], str]] | None = None,
) -> str:
    """``rows`` as a markdown table; missing, empty or non-finite entries show as ``-``.
    ``special`` maps a key to its own cell formatter."""
    special = special or {}

    def cell(row: Mapping[str, Any], key: str, fmt: str) -> str:
        value = row.get(key)
        if key in special:
            return special[key](value)
        if (
            value is None
            or (isinstance(value, str | list) and len(value) == 0)
            or (isinstance(value, float) and not np.isfinite(value))
        ):
            return "-"
        return fmt.format(value).replace("|", "\\|")

    lines = ["| " + " | ".join(title for _, title, _ in columns) + " |", "|" + " --- |" * len(columns)]
    lines += ["| " + " | ".join(cell(r, k, f) for k, _, f in columns) + " |" for r in rows]
    return "\n".join(lines)
