"""Every problem of a scenario file at once (``mpcform validate``), with the line of each key.

:func:`load_scenario` stops at the first :class:`ScenarioError`. :func:`check_scenario_file`
keeps going where it can:

1. every table is checked on its own against the schema (unknown keys with a did-you-mean
   hint, types, ranges, keys of another variant); a bad key is reported and set aside;
2. the remaining document is built into a scenario and a controller; each further error is
   reported, its key set aside, and the build repeated. Once a table has had such an error,
   later errors in the same table are not reported (they may be its consequences), and the
   search ends when the set-aside key was required.

Each problem names the key and, when it can be found in the text, its line.
"""

from __future__ import annotations

import copy
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpcform.errors import MPCFormError, ScenarioError, ValidationError
from mpcform.scenario.build import build_controller
from mpcform.scenario.load import load_scenario, scenario_from_dict, scenario_text
from mpcform.scenario.parse import parse_keys, parse_top_level
from mpcform.scenario.schema import SCHEMA, TABLES, Table
from mpcform.scenario.size import (
    DEFAULT_MAX_MEMORY_GIB,
    DEFAULT_MAX_WORK,
    check_memory,
    check_work,
    read_scenario_bytes,
)
from mpcform.scenario.spec import Scenario

MAX_ROUNDS = 100
_HEADER = re.compile(r"^\s*(\[\[?)\s*([A-Za-z0-9_.\- ]+?)\s*\]\]?\s*(#.*)?$")
_TOKEN = re.compile(r"([^.\[\]]+)|\[(\d+)\]")


@dataclass(frozen=True)
class Problem:
    """One problem: the scenario key (``controller.gain``), the message, the line (1-based)."""

    field: str
    message: str
    line: int | None = None

    def __str__(self) -> str:
        where = f"line {self.line}: " if self.line is not None else ""
        return f"{where}{self.field}: {self.message}"

    def text(self, path: str | Path) -> str:
        """One line: ``FILE:LINE: KEY: MESSAGE``, ``FILE: KEY: MESSAGE`` when the key has no line
        in the file (a cross-field problem, a key left at its default), or ``FILE: MESSAGE`` when
        the file itself cannot be read or parsed."""
        if self.field == str(path):
            return " ".join(f"{path}: {self.message}".split())
        where = f"{path}:{self.line}" if self.line is not None else f"{path}"
        return " ".join(f"{where}: {self.field}: {self.message}".split())


@dataclass(frozen=True)
class CheckResult:
    """The scenario when the file is valid, else None, and every problem found."""

    scenario: Scenario | None
    problems: tuple[Problem, ...]

    @property
    def ok(self) -> bool:
        """Whether the file is valid (no problem found)."""
        return not self.problems


def check_scenario_file(
    path: str | Path,
    max_memory_gib: float | None = DEFAULT_MAX_MEMORY_GIB,
    controller: str | None = None,
    max_work: float | None = DEFAULT_MAX_WORK,
) -> CheckResult:
    """Load ``path``, estimate the run's memory and its plant's work and build its controller
    (``controller`` overrides the kind); on failure, collect every problem found.
    ``max_memory_gib``, ``max_work`` None: no limit (see :mod:`mpcform.scenario.size`)."""
    path = Path(path)
    try:
        scenario = load_scenario(path, max_memory_gib=max_memory_gib)
        _check_size(scenario, max_memory_gib, max_work, controller)  # before the controller's QP
        build_controller(scenario, controller)  # e.g. the mpc controller needs limits.v_max with d_min
        return CheckResult(scenario, ())
    except ScenarioError as exc:
        if exc.field == str(path):  # unreadable file or TOML syntax: nothing more to find
            return CheckResult(None, (_problem(exc, None),))
        first = exc
    text = scenario_text(read_scenario_bytes(path))
    problems = check_document(tomllib.loads(text), path.stem, controller, max_memory_gib, max_work)
    if not problems:  # the document is valid: the memory estimate failed
        problems = [_problem(first, None)]
    located = [Problem(p.field, p.message, locate(text, p.field)) for p in problems]
    located.sort(key=lambda p: float("inf") if p.line is None else p.line)  # stable: file order
    return CheckResult(None, tuple(located))


def located_problem(exc: ScenarioError, path: str | Path) -> Problem:
    """``exc`` raised for the scenario file ``path``, with the line of its key when found."""
    path = Path(path)
    line = None
    if exc.field != str(path):
        try:
            line = locate(scenario_text(read_scenario_bytes(path)), exc.field)
        except ScenarioError:
            pass
    return _problem(exc, line)


def check_document(
    data: dict[str, Any],
    default_name: str = "scenario",
    controller: str | None = None,
    max_memory_gib: float | None = DEFAULT_MAX_MEMORY_GIB,
    max_work: float | None = DEFAULT_MAX_WORK,
) -> list[Problem]:
    """Every problem of a parsed scenario document (the TOML as a dict); [] when valid
    (``controller`` overrides the controller kind; ``max_memory_gib``, ``max_work``: see
    :func:`check_scenario_file`)."""
    doc = copy.deepcopy(data)
    problems: list[Problem] = []
    tainted: set[str] = set()
    _sweep(lambda: parse_top_level(doc), doc, problems, TABLES[""], 2, tainted)
    dim = doc.get("dim") if doc.get("dim") in (2, 3) and not isinstance(doc.get("dim"), bool) else None
    for table, raw, prefix in _tables(doc):
        if dim is None:  # types of vectors depend on dim: check the key names only
            _unknown_keys(table, raw, prefix, problems)
        else:
            _sweep(_key_check(table, raw, prefix, dim), doc, problems, table, dim, tainted)
    renamed = {
        m.group(1) for p in problems if (m := re.search(r"unknown table; did you mean '(\w+)'", p.message))
    }
    for table in SCHEMA:  # every missing table at once (the build stops at the first)
        name = table.name
        if table.required and name and "." not in name and name not in doc and name not in renamed:
            problems.append(_problem(ScenarioError(name, f"missing table [{name}] ({table.doc})"), None))
    reported = {p.field for p in problems}
    for _ in range(MAX_ROUNDS):
        try:
            scenario = scenario_from_dict(doc, default_name=default_name, max_memory_gib=max_memory_gib)
            _check_size(scenario, max_memory_gib, max_work, controller)
            build_controller(scenario, controller)
            break
        except ValidationError as exc:
            name = _table_of(exc.field)
            consequence = exc.field in reported or name in tainted or exc.field in renamed
            if not consequence:
                problems.append(_problem(exc, None))
                reported.add(exc.field)
            tainted.add(name)
            if not (_remove(doc, exc.field) or _replace_table(doc, name, dim or 2)):
                break
        except MPCFormError as exc:  # an error without a field: report it and stop
            problems.append(Problem("scenario", str(exc)))
            break
    return problems


def locate(text: str, field: str) -> int | None:
    """The 1-based line of ``field`` (``obstacles[1].radius``) in the TOML ``text``, if found."""
    tokens = _tokens(field)
    if not tokens:
        return None
    lines = text.splitlines()
    sections: list[tuple[tuple[str | int, ...], int]] = [((), 0)]  # (table path, first line index)
    counts: dict[str, int] = {}
    for k, line in enumerate(lines):
        match = _HEADER.match(line)
        if match is None:
            continue
        name = match.group(2).replace(" ", "")
        path: tuple[str | int, ...] = tuple(name.split("."))
        if match.group(1) == "[[":
            counts[name] = counts.get(name, -1) + 1
            path = (*path, counts[name])
        sections.append((path, k))
    best: tuple[int, int] | None = None  # (matched tokens, section index)
    for s, (path, _) in enumerate(sections):
        if len(path) <= len(tokens) and tuple(tokens[: len(path)]) == path:
            if best is None or len(path) > best[0]:
                best = (len(path), s)
    if best is None:
        return None
    used, s = best
    start = sections[s][1]
    if used == len(tokens):
        return start + 1 if s > 0 else None
    stop = sections[s + 1][1] if s + 1 < len(sections) else len(lines)
    key = re.compile(rf'^\s*"?{re.escape(str(tokens[used]))}"?\s*=')
    for k in range(start + (1 if s > 0 else 0), stop):
        if key.match(lines[k]):
            return k + 1
    return None


# ---- helpers ------------------------------------------------------------------------------
def _check_size(
    scenario: Scenario, max_memory_gib: float | None, max_work: float | None, controller: str | None
) -> None:
    if max_memory_gib is not None:
        check_memory(scenario, max_memory_gib, controller)
    if max_work is not None:
        check_work(scenario, max_work, controller)


def _replace_table(doc: dict[str, Any], name: str, dim: int) -> bool:
    """Set aside a broken table so that the tables after it can be checked: drop an optional
    table, replace a required one by a valid stub (once); False for [template] and the top level."""
    if name in ("limits", "graph", "obstacles"):
        return doc.pop(name, None) is not None
    stubs: dict[str, dict[str, Any]] = {
        "initial": {"centroid": [0.0] * dim},
        "reference": {"kind": "constant"},
        "controller": {"kind": "tracking"},
        "simulation": {"dt": 0.1, "duration": 1.0},
    }
    if name not in stubs or doc.get(name) == stubs[name]:
        return False
    doc[name] = stubs[name]
    return True


def _sweep(
    parse: Any, doc: dict[str, Any], problems: list[Problem], table: Table, dim: int, tainted: set[str]
) -> None:
    """Call ``parse`` until it passes, reporting each offending key and setting it aside.

    A bad key without a default marks its table ``tainted`` (a build error there, such as the
    alternative key then missing, is its consequence); a bad number or vector of that kind is
    replaced by a neutral placeholder (so the later build can go on), other bad keys are removed
    (defaults apply). A
    bad selector (``plant.kind``) ends the table's sweep: which of its keys apply is unknown.
    """
    for _ in range(MAX_ROUNDS):
        try:
            parse()
            return
        except ScenarioError as exc:
            if any(p.field == exc.field for p in problems):
                return
            problems.append(_problem(exc, None))
            name = _tokens(exc.field)[-1] if _tokens(exc.field) else None
            if name is not None and name == table.selector:  # which keys apply is unknown now
                tainted.add(_table_of(exc.field))
                return
            key = next((k for k in table.keys if k.name == name), None)
            placeholder = None
            if key is not None and key.default is None:  # no default takes its place
                tainted.add(_table_of(exc.field))  # the build's errors in its table follow from it
                if key.type in ("vector", "float"):
                    placeholder = [0.0] * dim if key.type == "vector" else 1.0
            if not _remove(doc, exc.field, placeholder):
                return


def _tables(doc: dict[str, Any]) -> list[tuple[Table, dict[str, Any], str]]:
    """(table schema, raw table, key prefix) of every table present in ``doc``."""
    out = []
    for table in SCHEMA:
        if not table.name:
            continue
        if table.name == "reference.keyframes":
            ref = doc.get("reference")
            items = ref.get("keyframes") if isinstance(ref, dict) else None
        elif table.array:
            items = doc.get(table.name)
        else:
            raw: Any = doc
            for part in table.name.split("."):  # [controller.solve] inside [controller]
                raw = raw.get(part) if isinstance(raw, dict) else None
            if isinstance(raw, dict):
                out.append((table, raw, table.name))
            continue
        if isinstance(items, list):
            for i, item in enumerate(items):
                if isinstance(item, dict):
                    out.append((table, item, f"{table.name}[{i}]"))
                    if table.name == "reference.keyframes" and isinstance(item.get("template"), dict):
                        out.append((TABLES["template"], item["template"], f"{table.name}[{i}].template"))
    return out


def _unknown_keys(table: Table, raw: dict[str, Any], prefix: str, problems: list[Problem]) -> None:
    names = [k.name for k in table.keys]
    for name in list(raw):
        if name not in names:
            try:  # the schema's own message (with its did-you-mean hint)
                parse_keys(table, {name: raw[name]}, prefix, 2, None)
            except ScenarioError as exc:
                problems.append(_problem(exc, None))
            del raw[name]


def _key_check(table: Table, raw: dict[str, Any], prefix: str, dim: int) -> Any:
    return lambda: parse_keys(table, raw, prefix, dim, None)


def _table_of(field: str) -> str:
    """The top-level table of a field (``obstacles[1].radius`` -> ``obstacles``; top level: '')."""
    head = field.split(".")[0].split("[")[0]
    return head if head in TABLES else ""


def _tokens(field: str) -> list[str | int]:
    return [int(idx) if idx else name for name, idx in _TOKEN.findall(field)]


def _remove(doc: dict[str, Any], field: str, placeholder: Any = None) -> bool:
    """Delete (or replace by ``placeholder``) the value at ``field``; False when it is not there."""
    tokens = _tokens(field)
    node: Any = doc
    for token in tokens[:-1]:
        try:
            node = node[token]
        except (KeyError, IndexError, TypeError):
            return False
    last = tokens[-1] if tokens else None
    if isinstance(node, dict) and isinstance(last, str) and last in node:
        if placeholder is None:
            del node[last]
        else:
            node[last] = placeholder
        return True
    return False


def _problem(exc: ValidationError, line: int | None) -> Problem:
    return Problem(exc.field, str(exc).removeprefix(f"{exc.field}: "), line)
