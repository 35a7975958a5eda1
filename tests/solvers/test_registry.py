"""The registry: every listed name builds a backend that solves a small QP to its known optimum and
has the capabilities the listing shows; names, listing, errors; solver packages stay unimported."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mpcform.cli.main import main
from mpcform.errors import SolverError
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.casadi_conic import CASADI_CONIC_PLUGINS
from mpcform.solvers.registry import (
    DEFAULT_SOLVER,
    FAMILIES,
    PERSISTENT_SOLVERS,
    check_solver_name,
    make_backend,
    solver_info,
    solver_infos,
    solver_names,
)

ROOT = Path(__file__).resolve().parents[2]

# min 0.5 (z0^2 + z1^2) - z0 - z1 + z2  s.t.  z0 + z1 = 1,  z0 <= 0.3,  -1 <= z2 <= 2,  z1 <= 5.
# P is singular (z2 is linear), as in the planner's QP; the optimum is z = (0.3, 0.7, -1).
SMALL_P = sp.csc_matrix(sp.triu(sp.diags([1.0, 1.0, 0.0])))
SMALL_Q = np.array([-1.0, -1.0, 1.0])
SMALL_A = sp.csc_matrix(np.array([[1.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]]))
SMALL_L = np.array([1.0, -np.inf, -1.0, -np.inf])
SMALL_U = np.array([1.0, 0.3, 2.0, 5.0])
SMALL_X = np.array([0.3, 0.7, -1.0])


@pytest.mark.parametrize("name", solver_names())
def test_every_usable_backend_has_its_listed_capabilities_and_solves_a_small_qp(name: str) -> None:
    info = solver_info(name)
    if not info.usable:
        pytest.skip(f"{name}: {info.note}")
    backend = make_backend(name, SolverOptions(1e-9, 1e-9, None))
    assert (backend.name, backend.warm_starts, backend.persistent) == (name, info.warm_start, info.persistent)
    if backend.needs_context:
        pytest.skip(f"{name} needs the planner's QP structure: see its own tests")
    backend.setup(SMALL_P, SMALL_Q, SMALL_A, SMALL_L, SMALL_U)
    sol = backend.solve(np.zeros(3) if backend.warm_starts else None)
    assert sol.success and sol.x is not None, sol.status
    np.testing.assert_allclose(sol.x, SMALL_X, atol=1e-5)


def test_listing_covers_every_family() -> None:
    infos = {i.name: i for i in solver_infos()}
    assert len(infos) == len(solver_infos()) == len(solver_names())
    assert {"osqp", "piqp", "casadi:ipopt", *(f"casadi:{p}" for p in CASADI_CONIC_PLUGINS)} <= set(infos)
    assert infos["piqp"].usable and infos["piqp"].persistent and infos["osqp"].warm_start
    quadprog = infos["qpsolvers:quadprog"]
    assert not quadprog.usable and "positive-definite" in quadprog.note
    assert len({f.key for f in FAMILIES}) == len(FAMILIES)  # one row per name or prefix


def test_default_solver_is_persistent_and_usable() -> None:
    assert DEFAULT_SOLVER in PERSISTENT_SOLVERS == ("osqp", "piqp")  # the bench CLIs offer these
    assert solver_info(DEFAULT_SOLVER).usable


def test_solvers_cli_lists_usability(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["solvers"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split()[:3] == ["solver", "installed", "usable"]
    rows = {line.split()[0]: line.split() for line in lines[1:]}
    assert rows["qpsolvers:quadprog"][2] == "no" and rows["piqp"][2] == "yes"


@pytest.mark.parametrize(
    ("name", "fragments"),
    [
        ("osqq", ("unknown solver", "did you mean 'osqp'")),
        ("qpsolvers:nonsense", ("unknown solver", "qpsolvers:<name>")),
        ("casadi:highs", ("unknown solver", "segfaulted")),
        ("casadi:", ("unknown solver", "casadi:<plugin> (osqp, qpoases")),
        ("piqp:", ("unknown solver", "did you mean 'piqp'")),
        ("qpsolvers:quadprog", ("positive-definite P",)),
        ("qpsolvers:gurobi", ("not installed", 'pip install "qpsolvers[gurobi]"')),
    ],
)
def test_bad_solver_is_a_solver_error(name: str, fragments: tuple[str, ...]) -> None:
    if name == "qpsolvers:gurobi" and solver_info(name).installed:
        pytest.skip("gurobi is installed here")
    with pytest.raises(SolverError) as err:
        make_backend(name, SolverOptions())
    assert err.value.solver == name
    for fragment in fragments:
        assert fragment in str(err.value)


def test_known_names_pass_the_name_check() -> None:
    for name in ("osqp", "qpsolvers:gurobi", "casadi:hpipm", "casadi:ipopt", *solver_names()):
        assert check_solver_name(name) == name


def test_missing_solver_exits_2_with_the_hint(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    name = "qpsolvers:gurobi"
    if solver_info(name).installed:
        pytest.skip("gurobi is installed here")
    scenario = str(ROOT / "scenarios" / "swap_planar_8.toml")
    assert main(["run", scenario, "--solver", name, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mpcform: error:") and "pip install" in err and len(err.splitlines()) == 1


def test_importing_the_package_imports_no_solver_package() -> None:
    code = (
        "import sys, mpcform, mpcform.solvers.registry, mpcform.mpc.planner, mpcform.cli.main\n"
        "loaded = [m for m in ('osqp', 'piqp', 'casadi', 'qpsolvers', 'daqp', 'highspy', 'clarabel')"
        " if m in sys.modules]\n"
        "assert not loaded, loaded\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
