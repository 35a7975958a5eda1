"""Scenario keys checked against the schema: names, types, ranges and defaults of one table.

Every problem raises :class:`~mpcform.errors.ScenarioError` naming the key (``controller.gain``),
the value received and what was expected; :func:`as_scenario_error` does the same for the
errors of the library objects built from the values.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.errors import ScenarioError, ValidationError, shown
from mpcform.scenario.schema import SCHEMA, TABLES, Key, Table, did_you_mean, listing

MAX_MAGNITUDE = 1e6
"""The largest magnitude of a vector or point component (1000 km, 1000 km/s): beyond it a
distance squared loses all precision, then overflows."""
MAX_NAME_CHARS = 100
"""The longest scenario ``name`` (a directory name: at most 255 bytes on most file systems)."""
NAME_PATTERN = r"[A-Za-z0-9_][A-Za-z0-9_.-]*"
"""What a scenario ``name`` may be: no path separator, no leading '.' or '-' (``.``, ``..``, ``-x``)."""


def parse_top_level(data: Mapping[str, Any]) -> dict[str, Any]:
    """The top-level keys (``version``, ``name``, ``dim``, ``seed``); unknown names and tables
    that are not tables raise."""
    top = TABLES[""]
    scalars = {k: v for k, v in data.items() if k not in TABLES or not k}
    for name, value in scalars.items():
        if not any(k.name == name for k in top.keys):
            is_table = isinstance(value, dict) or (
                isinstance(value, list) and value and all(isinstance(v, dict) for v in value)
            )
            what = "table" if is_table else "key"
            choices = [t.name for t in SCHEMA if t.name] if is_table else _names(top)
            raise ScenarioError(name, f"unknown {what}{did_you_mean(name, choices)}")
    for name in TABLES:
        if name and name in data and name != "obstacles" and not isinstance(data[name], dict):
            raise ScenarioError(name, f"expected a table [{name}], got {data[name]!r}")
    values = parse_keys(top, scalars, "", dim=2, n=None)
    name = values["name"]
    if name is not None and len(name) > MAX_NAME_CHARS:
        raise ScenarioError(
            "name",
            f"expected at most {MAX_NAME_CHARS} characters (it names the output directory), "
            f"got {len(name):,}: {shown(name)}",
        )
    if name is not None and (not re.fullmatch(NAME_PATTERN, name)):
        raise ScenarioError(
            "name",
            "expected letters, digits, '_', '-' or '.', starting with a letter, a digit or '_' "
            f"(it names the output directory), got {shown(name)}",
        )
    return values


def parse_table(data: Mapping[str, Any], name: str, dim: int, n: int | None = None) -> dict[str, Any]:
    """The keys of table ``name`` of ``data`` (an absent optional table: every key's default)."""
    table = TABLES[name]
    raw = data.get(name)
    if raw is None:
        if table.required:
            raise ScenarioError(name, f"missing table [{name}] ({table.doc})")
        raw = {}
    return parse_keys(table, raw, name, dim, n)


def parse_keys(table: Table, raw: Mapping[str, Any], prefix: str, dim: int, n: int | None) -> dict[str, Any]:
    """Check names, types and ranges of one table's keys; fill defaults (None = unset)."""
    for name in raw:
        if not any(k.name == name for k in table.keys):
            where = f" in {table.title}" if table.name else ""
            raise ScenarioError(
                field_name(prefix, name), f"unknown key{where}{did_you_mean(name, _names(table))}"
            )
    variant = None
    if table.selector is not None:
        sel = table.key(table.selector)
        if table.selector in raw:
            variant = _convert(sel, raw[sel.name], field_name(prefix, sel.name), dim, n)
        elif sel.default is not None:  # a selector with a default ([plant] kind = "ideal")
            variant = sel.default
        else:
            raise ScenarioError(field_name(prefix, sel.name), f"missing required key ({sel.doc})")
    out: dict[str, Any] = {}
    for key in table.keys:
        field = field_name(prefix, key.name)
        applies = not key.when or variant in key.when
        if key.name not in raw:
            if key.required and applies:
                raise ScenarioError(field, f"missing required key ({key.doc})")
            out[key.name] = key.default if applies else None
        elif not applies:
            raise ScenarioError(
                field,
                f"does not apply to {table.selector} = {variant!r} "
                f"(only to {', '.join(repr(w) for w in key.when)})",
            )
        else:
            out[key.name] = _convert(key, raw[key.name], field, dim, n)
    return out


def _convert(key: Key, value: Any, field: str, dim: int, n: int | None) -> Any:
    """The value of ``key`` as a Python or numpy object, or a ScenarioError naming ``field``."""
    unit = f" [{key.unit}]" if key.unit else ""
    if key.type == "bool":
        if not isinstance(value, bool):
            raise ScenarioError(field, f"expected true or false, got {shown(value)}")
        return value
    if key.type == "string":
        if not isinstance(value, str):
            raise ScenarioError(field, f"expected a string, got {shown(value)}")
        if key.choices and value not in key.choices:
            raise ScenarioError(
                field,
                f"expected one of {listing(key.choices)}, "
                f"got {shown(value)}{did_you_mean(value, key.choices)}",
            )
        return value
    if key.names and isinstance(value, str):
        if value not in key.names:
            hint = did_you_mean(value, key.names)
            raise ScenarioError(
                field, f"expected a number or one of {listing(key.names)}, got {shown(value)}{hint}"
            )
        return value
    if key.type in ("int", "float"):
        number = _number(value, integer=key.type == "int", allow_inf=key.inf)
        allowed = not key.choices or number in key.choices
        if number is None or not allowed or not key.within_bound(number):
            what = "an integer" if key.type == "int" else "a finite number"
            if key.choices:
                what = f"one of {listing(key.choices, '')}"
            inf = " or inf" if key.inf else ""
            raise ScenarioError(field, f"expected {what}{key.bound_text}{unit}{inf}, got {shown(value)}")
        return number
    if key.type == "table":
        if not isinstance(value, dict):
            raise ScenarioError(field, f"expected a table {{ key = value, ... }}, got {shown(value)}")
        return value
    if key.type == "tables":
        if not isinstance(value, list) or not value or not all(isinstance(v, dict) for v in value):
            raise ScenarioError(
                field, f"expected a non-empty array of tables [[{field}]], got {shown(value)}"
            )
        return value
    if key.type == "rotation" and dim == 2:
        return _convert(dataclasses.replace(key, type="float"), value, field, dim, n)
    if key.type == "rotation":
        return _array(field, value, (3,), "a rotation vector of 3 numbers [rad]")
    if key.type in ("vector", "bounds"):
        return _array(field, value, (dim,), f"a list of {dim} numbers{unit}", key.type == "bounds")
    if key.type in ("indices", "pairs"):
        return _indices(field, value, pairs=key.type == "pairs")
    rows = "rows" if n is None else f"{n} rows"
    return _array(field, value, (n, dim), f"a list of {rows} of {dim} numbers{unit}")


def _indices(field: str, value: Any, *, pairs: bool) -> tuple[Any, ...]:
    def index(v: Any) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and v >= 0

    def item(v: Any) -> bool:
        return isinstance(v, list) and len(v) == 2 and all(index(x) for x in v) if pairs else index(v)

    if not isinstance(value, list) or not all(item(v) for v in value):
        what = "a list of [i, j] pairs of drone indices" if pairs else "a list of drone indices"
        raise ScenarioError(field, f"expected {what} (integers >= 0), got {shown(value)}")
    return tuple(tuple(v) for v in value) if pairs else tuple(value)


def _number(value: Any, *, integer: bool, allow_inf: bool = False) -> float | int | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    if integer:
        return value if isinstance(value, int) else None
    return float(value) if math.isfinite(value) or (allow_inf and value == math.inf) else None


def _array(
    field: str, value: Any, shape: tuple[int | None, ...], expected: str, allow_inf: bool = False
) -> Array:
    def fits(v: Any, depth: int) -> bool:
        if depth == len(shape):
            return isinstance(v, int | float) and not isinstance(v, bool)
        size = shape[depth]
        return (
            isinstance(v, list)
            and (len(v) == size if size is not None else len(v) >= 1)
            and all(fits(x, depth + 1) for x in v)
        )

    if not fits(value, 0):
        raise ScenarioError(field, f"expected {expected}, got {shown(value)}")
    arr = np.array(value, dtype=float)
    if np.isnan(arr).any() or (not allow_inf and np.isinf(arr).any()):
        finite = "numbers (inf allowed)" if allow_inf else "finite numbers"
        raise ScenarioError(field, f"expected {finite}, got {shown(value)}")
    if np.any(np.abs(arr[np.isfinite(arr)]) > MAX_MAGNITUDE):  # squared distances must not overflow
        big = float(np.abs(arr[np.isfinite(arr)]).max())
        raise ScenarioError(field, f"expected numbers of magnitude at most {MAX_MAGNITUDE:g}, got {big:g}")
    return arr


@contextmanager
def as_scenario_error(prefix: str) -> Iterator[None]:
    """Re-raise a core ValidationError as a ScenarioError naming the scenario key."""
    try:
        yield
    except ScenarioError:
        raise
    except ValidationError as exc:
        table = TABLES["obstacles" if prefix.startswith("obstacles") else prefix]
        last = exc.field.split(" ")[0].rsplit(".", 1)[-1]
        field = field_name(prefix, last) if last in _names(table) else exc.field
        raise ScenarioError(field, str(exc).removeprefix(f"{exc.field}: ")) from None


def field_name(prefix: str, name: str) -> str:
    """The scenario key ``name`` of the table ``prefix`` (``controller.gain``; top level: ``name``)."""
    return f"{prefix}.{name}" if prefix else name


def _names(table: Table) -> list[str]:
    return [k.name for k in table.keys]
