"""Solver backends: each solves the recorded problems it supports and agrees with the reference,
the planner gives the same first input with each of them, names/listing/errors, no printing."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from mpcform.bench.problems import RecordedQP, load_problem, problem_files
from mpcform.cli.main import main
from mpcform.errors import SolverError
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.limits import Limits
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.reference.base import ConstantReference
from mpcform.sim.simulation import simulate
from mpcform.solvers.base import (
    CASADI_CONIC_PLUGINS,
    QPBackend,
    SolverOptions,
    check_solver_name,
    make_backend,
    solver_info,
    solver_infos,
)
from mpcform.solvers.families import exact_separation_residual, full_symmetric

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Case:
    """A backend under test: its tolerances on the relative objective gap to the reference, on the
    primal residual and on the planner's first input [m/s], the eps it is given, and how many of
    the small recorded problems it solves (slow backends take one)."""

    name: str
    objective: float
    residual: float
    first_input: float
    eps: float = 1e-7
    problems: int = 3
    all_sizes: bool = False


CASES = (
    Case("piqp", 1e-8, 1e-8, 1e-5, all_sizes=True),
    Case("osqp", 1e-5, 1e-5, 2e-3, eps=1e-6),
    Case("qpsolvers:clarabel", 1e-8, 1e-8, 1e-5, all_sizes=True),
    Case("qpsolvers:daqp", 1e-8, 1e-8, 1e-5, problems=1),
    Case("qpsolvers:highs", 1e-6, 1e-8, 1e-5),  # HiGHS stops with a larger dual error
    Case("qpsolvers:osqp", 1e-5, 1e-5, 2e-3, eps=1e-6),
    Case("qpsolvers:piqp", 1e-8, 1e-8, 1e-5),
    Case("qpsolvers:proxqp", 1e-6, 1e-6, 1e-4, eps=1e-6, problems=1),
    Case("qpsolvers:scs", 1e-6, 1e-6, 1e-3),
    Case("casadi:osqp", 1e-5, 1e-5, 2e-3, eps=1e-6),
    Case("casadi:qpoases", 1e-8, 1e-8, 1e-5, problems=0),  # seconds per recorded QP: planner test only
    Case("casadi:proxqp", 1e-4, 1e-4, 1e-3, eps=1e-6, problems=1),
    Case("casadi:daqp", 1e-5, 1e-6, 1e-4, problems=1),
    Case("casadi:piqp", 1e-8, 1e-8, 1e-5),
    Case("casadi:ipqp", 1e-7, 1e-7, 1e-5, problems=1),
    Case("casadi:hpipm", 1e-6, 1e-6, 1e-4),
)
IDS = [c.name for c in CASES]


def _usable(name: str) -> None:
    info = solver_info(name)
    if not info.usable:
        pytest.skip(f"{name}: {info.note}")


@pytest.fixture(scope="module")
def recorded() -> dict[str, list[RecordedQP]]:
    files = problem_files(ROOT / "problems")
    by: dict[str, list[RecordedQP]] = {}
    for f in files:
        by.setdefault(f.parent.name, []).append(load_problem(f))
    return by


@pytest.fixture(scope="module")
def reference() -> dict[str, float]:
    """Objective of each problem solved by clarabel at 1e-9 (cached by problem name)."""
    return {}


def _reference(cache: dict[str, float], qp: RecordedQP) -> float:
    if qp.name not in cache:
        be = make_backend("qpsolvers:clarabel", SolverOptions(1e-9, 0.0, None))
        be.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
        sol = be.solve()
        assert sol.success and sol.x is not None
        cache[qp.name] = qp.objective(sol.x)
    return cache[qp.name]


def _problems(case: Case, recorded: dict[str, list[RecordedQP]]) -> list[RecordedQP]:
    small = recorded["swap_planar_8"]
    chosen = [small[0], small[len(small) // 2], small[-1]][: case.problems]
    if case.all_sizes:
        chosen += [qps[0] for name, qps in recorded.items() if name != "swap_planar_8"]
    return chosen


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_backend_solves_recorded_problems(
    case: Case,
    recorded: dict[str, list[RecordedQP]],
    reference: dict[str, float],
    capfd: pytest.CaptureFixture[str],
) -> None:
    _usable(case.name)
    problems = _problems(case, recorded)
    if not problems:
        pytest.skip(f"{case.name} takes seconds per recorded QP here (see `mpcform bench solvers`)")
    refs = [_reference(reference, qp) for qp in problems]
    capfd.readouterr()
    backend = make_backend(case.name, SolverOptions(case.eps, case.eps, None))
    pattern = None
    for qp, f_ref in zip(problems, refs, strict=True):  # one backend: setup, then update when it can
        if pattern != (qp.A.indptr.tobytes(), qp.A.indices.tobytes()):
            backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
            pattern = (qp.A.indptr.tobytes(), qp.A.indices.tobytes())
        else:
            backend.update(qp.q, qp.l, qp.u, qp.A.data)
        if backend.needs_context:
            assert qp.context is not None
            backend.set_context(qp.context)
        sol = backend.solve(qp.x0 if backend.warm_starts else None)
        assert sol.success and sol.x is not None, f"{qp.name}: {sol.status}"
        residual, gap = qp.primal_residual(sol.x), abs(qp.objective(sol.x) - f_ref) / max(1.0, abs(f_ref))
        assert residual <= case.residual and gap <= case.objective, (
            f"{qp.name}: residual {residual:.1e}, gap {gap:.1e}"
        )
    assert capfd.readouterr() == ("", ""), "a backend printed during a solve"


def _active_state() -> tuple[ConstantReference, np.ndarray, float]:
    """A planar swap of 6 drones 1.5 s in (piqp closed loop): separation rows are active."""
    tpl = Template.polygon(6, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param(np.zeros(2)))
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), MPCSettings(horizon=6))
    res = simulate(planner, -tpl.offsets, 1.5)
    return ref, res.positions_m[-1], float(res.t_s[-1])


@pytest.fixture(scope="module")
def active_state() -> tuple[ConstantReference, np.ndarray, float, np.ndarray]:
    ref, p, t = _active_state()
    settings = MPCSettings(horizon=6, eps_abs=1e-9, eps_rel=1e-9, fast_path=False)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), settings, solver="piqp")
    planner.reset(t, p)
    out = planner.step(t, p)
    assert out.info.mode == "qp" and out.info.active_rows > 0  # the scenario has active constraints
    return ref, p, t, out.command_mps


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_planner_first_input_agrees(
    case: Case, active_state: tuple[ConstantReference, np.ndarray, float, np.ndarray]
) -> None:
    _usable(case.name)
    ref, p, t, want = active_state
    settings = MPCSettings(horizon=6, eps_abs=case.eps, eps_rel=case.eps, fast_path=False)
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), settings, solver=case.name)
    planner.reset(t, p)
    out = planner.step(t, p)
    assert out.info.mode == "qp", out.info.status
    np.testing.assert_allclose(out.command_mps, want, atol=case.first_input, rtol=0)


def test_exact_reference_is_below_the_qp_and_feasible(
    recorded: dict[str, list[RecordedQP]], reference: dict[str, float]
) -> None:
    _usable("casadi:ipopt")
    qp = recorded["swap_planar_8"][0]
    assert qp.context is not None
    backend = make_backend("casadi:ipopt", SolverOptions(1e-8, 1e-8, None))
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    assert not backend.solve().success  # without the context it cannot know the exact problem
    backend.set_context(qp.context)
    sol = backend.solve(qp.x0)
    assert sol.success and sol.x is not None
    assert exact_separation_residual(qp.context, sol.x) <= 1e-6
    assert qp.objective(sol.x) <= _reference(reference, qp) + 1e-6  # the linearisation is conservative


def test_qpsolvers_duals_satisfy_stationarity(recorded: dict[str, list[RecordedQP]]) -> None:
    qp = recorded["swap_planar_8"][0]
    backend = make_backend("qpsolvers:clarabel", SolverOptions(1e-10, 0.0, None))
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    sol = backend.solve()
    assert sol.success and sol.x is not None and sol.y is not None
    stationarity = full_symmetric(qp.P) @ sol.x + qp.q + qp.A.T @ sol.y
    assert np.abs(stationarity).max() < 1e-6
    ax = qp.A @ sol.x  # OSQP's sign convention: y > 0 only at an upper bound, y < 0 at a lower one
    assert np.all((sol.y <= 1e-7) | (ax >= qp.u - 1e-6)) and np.all((sol.y >= -1e-7) | (ax <= qp.l + 1e-6))


# ---- names, listing, errors, failures ---------------------------------------------------------
def test_listing_covers_every_family() -> None:
    infos = {i.name: i for i in solver_infos()}
    assert len(infos) == len(solver_infos())
    assert {"osqp", "piqp", "casadi:ipopt", *(f"casadi:{p}" for p in CASADI_CONIC_PLUGINS)} <= set(infos)
    assert infos["piqp"].usable and infos["piqp"].persistent and infos["osqp"].warm_start
    quadprog = infos["qpsolvers:quadprog"]
    assert not quadprog.usable and "positive-definite" in quadprog.note


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
    for name in ("osqp", "qpsolvers:gurobi", "casadi:hpipm", "casadi:ipopt"):
        assert check_solver_name(name) == name


def test_missing_solver_exits_2_with_the_hint(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    name = "qpsolvers:gurobi"
    if solver_info(name).installed:
        pytest.skip("gurobi is installed here")
    scenario = str(ROOT / "scenarios" / "swap_planar_8.toml")
    assert main(["run", scenario, "--solver", name, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mpcform: error:") and "pip install" in err and len(err.splitlines()) == 1


def test_a_solver_exception_is_a_failed_solve(
    recorded: dict[str, list[RecordedQP]], monkeypatch: pytest.MonkeyPatch
) -> None:
    import qpsolvers

    qp = recorded["swap_planar_8"][0]
    backend = make_backend("qpsolvers:clarabel", SolverOptions())
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)

    def broken(*args: object, **kwargs: object) -> None:
        raise ValueError("solver exploded")

    monkeypatch.setattr(qpsolvers, "solve_problem", broken)
    sol = backend.solve()
    assert not sol.success and sol.x is None and "solver exploded" in sol.status


def test_hpipm_reports_a_structure_it_cannot_take_and_the_planner_falls_back() -> None:
    _usable("casadi:hpipm")
    ref, p, t = _active_state()
    limits = Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=5.0)  # acceleration rows couple stages
    planner = MPCPlanner(ref, 0.1, limits, MPCSettings(horizon=6, fast_path=False), solver="casadi:hpipm")
    planner.reset(t, p)
    out = planner.step(t, p)
    assert out.info.mode == "fallback" and "optimal-control" in out.info.status
    assert np.all(np.isfinite(out.command_mps))


def test_backends_are_qpbackends() -> None:
    for case in CASES:
        if solver_info(case.name).usable:
            assert isinstance(make_backend(case.name, SolverOptions()), QPBackend)
