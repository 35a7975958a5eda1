"""The package's layout keeps its rules: layers import downwards only, no cycle, small modules and
classes, no private name across modules, a light ``import mpcform``, tests mirroring modules."""

from __future__ import annotations

import ast
import subprocess
import sys
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "mpcform"
MAX_MODULE_LINES = 400
MAX_CLASS_LINES = 250

LAYERS = (
    ("mpcform.errors", "mpcform._validate", "mpcform._jit", "mpcform._blas"),
    ("mpcform.world",),
    ("mpcform.formation",),
    ("mpcform.reference",),
    ("mpcform.control", "mpcform.solvers"),
    ("mpcform.mpc", "mpcform.sim"),
    ("mpcform.scenario",),
    ("mpcform.online",),
    ("mpcform.outputs",),
    ("mpcform.run",),
    ("mpcform.bench",),
    ("mpcform.cli",),
)
"""The pipeline, lowest first: a module may import its own layer and the layers below it."""

SIBLINGS = (("mpcform.mpc", "mpcform.sim"),)
"""Subpackages that share a layer but must not import each other (both build on mpcform.world)."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


@cache
def _tree(name: str) -> ast.Module:
    return ast.parse(MODULES[name].read_text(), filename=str(MODULES[name]))


def _resolve(name: str) -> str:
    """The module that ``name`` denotes (a module itself, or the package/module defining it)."""
    while name not in MODULES:
        name = name.rpartition(".")[0]
    return name


def imports(name: str) -> list[tuple[str, str, int]]:
    """Every mpcform import of a module (lazy ones included): (target module, imported name, line)."""
    found = []
    for node in ast.walk(_tree(name)):
        if isinstance(node, ast.Import):
            found += [(_resolve(a.name), "", node.lineno) for a in node.names if a.name.startswith("mpcform")]
        elif (
            isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("mpcform")
        ):
            module = node.module or ""
            for alias in node.names:
                sub = f"{module}.{alias.name}"
                found.append(
                    (sub, "", node.lineno) if sub in MODULES else (_resolve(module), alias.name, node.lineno)
                )
    return found


def _layer(name: str) -> int:
    for rank, prefixes in enumerate(LAYERS):
        if any(name == p or name.startswith(p + ".") for p in prefixes):
            return rank
    raise LookupError(f"{name} is in no layer of LAYERS: add its subpackage there")


def test_every_module_has_a_layer() -> None:
    for name in MODULES:
        if name != "mpcform":
            _layer(name)


def test_layers_import_downwards_only() -> None:
    upward = [
        f"{name}:{line} imports {target} (layer {_layer(target)} above {_layer(name)})"
        for name in MODULES
        if name != "mpcform"
        for target, _, line in imports(name)
        if target != "mpcform" and _layer(target) > _layer(name)
    ]
    assert not upward, "\n".join(upward)


def _in(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def test_siblings_do_not_import_each_other() -> None:
    """The planner (mpcform.mpc) and the simulators (mpcform.sim) meet only in the layers below."""
    crossing = [
        f"{name}:{line} imports {target}"
        for pair in SIBLINGS
        for a, b in (pair, pair[::-1])
        for name in MODULES
        if _in(name, a)
        for target, _, line in imports(name)
        if _in(target, b)
    ]
    assert not crossing, "\n".join(crossing)


def test_no_module_imports_the_package_root() -> None:
    """``from mpcform import X`` inside the package runs ``mpcform/__init__`` (a cycle through it)."""
    bad = [f"{n}:{line}" for n in MODULES if n != "mpcform" for t, _, line in imports(n) if t == "mpcform"]
    assert not bad, bad


def test_no_import_cycle() -> None:
    graph = {n: {t for t, _, _ in imports(n) if t != n} for n in MODULES if n != "mpcform"}
    state: dict[str, int] = {}

    def visit(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                pytest.fail("import cycle: " + " -> ".join([*path[path.index(nxt) :], nxt]))
            if nxt not in state:
                visit(nxt, [*path, nxt])
        state[node] = 2

    for name in sorted(graph):
        if name not in state:
            visit(name, [name])


def test_only_the_cli_imports_the_benchmarks() -> None:
    bad = [
        f"{n}:{line} imports {t}"
        for n in MODULES
        for t, _, line in imports(n)
        if (t.startswith("mpcform.bench") and not n.startswith(("mpcform.cli", "mpcform.bench")))
        or (t.startswith("mpcform.cli") and not n.startswith("mpcform.cli"))
    ]
    assert not bad, bad


def test_modules_and_classes_stay_small() -> None:
    big = []
    for name, path in MODULES.items():
        lines = len(path.read_text().splitlines())
        if lines > MAX_MODULE_LINES:
            big.append(f"module {name}: {lines} lines")
        for node in ast.walk(_tree(name)):
            if (
                isinstance(node, ast.ClassDef)
                and (size := node.end_lineno - node.lineno + 1) > MAX_CLASS_LINES
            ):
                big.append(f"class {name}.{node.name}: {size} lines")
    assert not big, big


def test_no_private_name_crosses_a_module() -> None:
    bad = [
        f"{n}:{line} imports {t}.{what}"
        for n in MODULES
        for t, what, line in imports(n)
        if what.startswith("_")
    ]
    assert not bad, bad


def test_import_mpcform_loads_no_heavy_dependency() -> None:
    heavy = ("matplotlib", "osqp", "piqp", "casadi", "qpsolvers", "daqp", "clarabel", "cvxpy")
    code = f"import sys, mpcform; print(','.join(m for m in {heavy!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "", f"import mpcform loaded {out.strip()}"


def test_tests_mirror_the_modules() -> None:
    """Every test module names a module of the package: tests/<sub>/test_<module>.py."""
    tests = ROOT / "tests"
    orphans = []
    for path in sorted(tests.rglob("test_*.py")):
        rel = path.relative_to(tests)
        if len(rel.parts) == 1:
            continue  # tests of the package as a whole (layout, library, README)
        target = "mpcform." + ".".join([*rel.parts[:-1], path.stem.removeprefix("test_")])
        if target not in MODULES:
            orphans.append(f"{rel} tests no module ({target})")
    assert not orphans, orphans
