"""Recorded problems: the npz format round-trips, the bundled set is consistent and small, the
qpsolvers form is the same problem, and recording/export through a backend wrapper works."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
from helpers import tiny_swap_toml

from mpcform.bench.problems import (
    DEFAULT_SCENARIOS,
    FORMAT,
    RecordedQP,
    export_problems,
    load_problem,
    load_problems,
    problem_files,
    record_scenario,
    save_problem,
)
from mpcform.cli.main import main
from mpcform.errors import MPCFormError, ValidationError
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend

ROOT = Path(__file__).resolve().parents[2]
TINY = tiny_swap_toml("tiny_swap", radius_m=1.5, horizon=5, duration_s=1.0)


@pytest.fixture(scope="module")
def bundled() -> list[RecordedQP]:
    return load_problems(ROOT / "problems")


def _same(a: RecordedQP, b: RecordedQP) -> None:
    for key in ("P", "A"):
        ma, mb = getattr(a, key), getattr(b, key)
        assert ma.shape == mb.shape and np.array_equal(ma.indptr, mb.indptr)
        assert np.array_equal(ma.indices, mb.indices) and np.array_equal(ma.data, mb.data)
    for key in ("q", "l", "u", "x0"):
        assert np.array_equal(getattr(a, key), getattr(b, key))
    assert a.meta == b.meta
    assert a.context is not None and b.context is not None
    for key in ("start_m", "pairs", "metric", "obstacle_drones", "obstacle_centers_m", "obstacle_distance_m"):
        assert np.array_equal(getattr(a.context, key), getattr(b.context, key))
    assert (a.context.n, a.context.dim, a.context.horizon) == (b.context.n, b.context.dim, b.context.horizon)
    assert a.context.separation_rows == b.context.separation_rows
    assert a.context.pair_distance_m == b.context.pair_distance_m


def test_round_trip(bundled: list[RecordedQP], tmp_path: Path) -> None:
    for qp in (bundled[0], bundled[-1]):
        path = save_problem(tmp_path / "x" / "step_0001.npz", qp)
        _same(qp, load_problem(path))
    with np.load(path, allow_pickle=False) as f:  # plain arrays: no pickles needed
        assert json.loads(str(f["meta"]))["format"] == FORMAT


def test_bundled_set_is_consistent_and_small(bundled: list[RecordedQP]) -> None:
    files = problem_files(ROOT / "problems")
    assert sum(f.stat().st_size for f in files) < 5 * 2**20
    assert {qp.meta["scenario"] for qp in bundled} == {p.stem for p in DEFAULT_SCENARIOS}
    for qp in bundled:
        m = qp.meta
        assert qp.P.shape == (qp.n_var, qp.n_var) and qp.A.shape == (qp.n_rows, qp.n_var)
        assert (m["n_var"], m["n_rows"], m["nnz_A"]) == (qp.n_var, qp.n_rows, qp.A.nnz)
        assert m["n_var"] == (2 * m["dim"] + 1) * m["n"] * m["horizon"]
        assert sp.triu(qp.P).nnz == qp.P.nnz  # upper triangle only
        assert np.all(qp.l <= qp.u) and qp.x0 is not None and qp.x0.shape == (qp.n_var,)
        assert m["event"] in ("setup", "update") and m["t_s"] == pytest.approx(0.1 * m["step"])
    for name in {qp.meta["scenario"] for qp in bundled}:
        steps = [qp.meta["step"] for qp in bundled if qp.meta["scenario"] == name]
        assert steps == sorted(steps) and len(steps) >= 8


def test_qpsolvers_form_is_the_same_problem(bundled: list[RecordedQP]) -> None:
    import qpsolvers

    qp = bundled[0]
    problem = qp.to_qpsolvers()
    eq = qp.l == qp.u
    finite_sides = int(np.isfinite(qp.u[~eq]).sum() + np.isfinite(qp.l[~eq]).sum())
    assert problem.A.shape == (int(eq.sum()), qp.n_var) and problem.G.shape == (finite_sides, qp.n_var)
    assert abs(problem.P - problem.P.T).max() == 0.0
    sol = qpsolvers.solve_problem(
        problem, solver="clarabel", tol_feas=1e-10, tol_gap_abs=1e-10, tol_gap_rel=0.0
    )
    assert sol.found
    backend = make_backend("qpsolvers:clarabel", SolverOptions(1e-10, 0.0, None))
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    ours = backend.solve()
    assert ours.x is not None
    assert abs(qp.objective(sol.x) - qp.objective(ours.x)) < 1e-7
    assert abs(sol.obj - qp.objective(sol.x)) < 1e-7 if sol.obj is not None else True
    assert qp.primal_residual(sol.x) < 1e-8
    dense = qp.to_qpsolvers(dense=True)
    assert isinstance(dense.P, np.ndarray) and np.array_equal(dense.P, problem.P.toarray())


def test_objective_and_residual() -> None:
    P = sp.csc_matrix(np.array([[2.0, 1.0], [0.0, 4.0]]))  # upper triangle of [[2, 1], [1, 4]]
    A = sp.csc_matrix(np.array([[1.0, 1.0]]))
    qp = RecordedQP(
        P, np.array([1.0, -1.0]), A, np.array([0.0]), np.array([1.0]), {"scenario": "s", "step": 0}
    )
    x = np.array([0.5, 1.0])
    assert qp.objective(x) == pytest.approx(0.5 * x @ np.array([[2.0, 1.0], [1.0, 4.0]]) @ x + 0.5 - 1.0)
    assert qp.primal_residual(x) == pytest.approx(0.5)
    assert qp.primal_residual(np.array([0.2, 0.3])) == 0.0


def test_bad_files_are_clear_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.npz"
    np.savez(bad, meta=np.array(json.dumps({"format": "other", "version": 1})))
    with pytest.raises(MPCFormError, match="expected format"):
        load_problem(bad)
    (tmp_path / "junk.npz").write_text("not an npz")
    with pytest.raises(MPCFormError, match="not a recorded QP"):
        load_problem(tmp_path / "junk.npz")
    with pytest.raises(MPCFormError, match="mpcform problems export"):
        problem_files(tmp_path / "empty")


def test_recording_and_export(tmp_path: Path) -> None:
    scenario = tmp_path / "tiny_swap.toml"
    scenario.write_text(TINY)
    problems = record_scenario(scenario)
    assert problems and problems[0].meta["event"] == "setup"
    assert all(p.meta["scenario"] == "tiny_swap" and p.meta["recorded_with"] == "piqp" for p in problems)
    steps = [p.meta["step"] for p in problems]
    assert steps == sorted(set(steps)) and max(steps) < 10  # one QP per step at most, 10 steps
    written = export_problems([scenario], tmp_path / "out", per_scenario=3)
    assert len(written) == min(3, len(problems)) and all(p.parent.name == "tiny_swap" for p in written)
    again = load_problems(tmp_path / "out")
    kept = [q.meta["step"] for q in again]
    first = steps.index(kept[0])
    assert kept == steps[first : first + len(kept)]  # a contiguous sequence, for warm-start replay
    for qp in again:  # the recorded warm start and context come back
        assert qp.x0 is not None and qp.context is not None and qp.context.n == qp.meta["n"]


def test_export_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = tmp_path / "tiny_swap.toml"
    scenario.write_text(TINY)
    out = tmp_path / "set"
    assert main(["problems", "export", str(scenario), "--out", str(out), "--per-scenario", "2"]) == 0
    assert "wrote 2 problems" in capsys.readouterr().out
    assert len(problem_files(out)) == 2
    assert main(["problems", "export", str(tmp_path / "missing.toml"), "--out", str(out)]) == 2


def test_a_scenario_without_any_qp_is_an_error_and_nothing_is_written(tmp_path: Path) -> None:
    swap = tmp_path / "tiny_swap.toml"
    swap.write_text(TINY)
    calm = tmp_path / "calm.toml"  # drones holding their start: every step is the fast path
    text = tiny_swap_toml("calm", 1.5, 4, 0.3)
    calm.write_text(text.replace("rotation = 3.141592653589793", "rotation = 0.0"))
    with pytest.raises(MPCFormError, match=r"calm.toml: no QP to record: the mpc planner never solved one"):
        export_problems([swap, calm], tmp_path / "out", per_scenario=2)
    assert not (tmp_path / "out").exists()


def test_export_checks_every_scenario_and_option_before_running(tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(TINY.replace("horizon = 5", "horizon = 0"))
    with pytest.raises(MPCFormError, match=r"bad.toml:\d+: controller.horizon: expected an integer >= 1"):
        export_problems([bad], tmp_path / "out")
    with pytest.raises(ValidationError, match="--per-scenario"):
        export_problems([bad], tmp_path / "out", per_scenario=0)
    decoupled = tmp_path / "decoupled.toml"
    decoupled.write_text(TINY.replace("horizon = 5", 'horizon = 5\ncoupling = "decoupled"'))
    with pytest.raises(MPCFormError, match="controller.solve.kind: 'piqp' solves the sparse QP"):
        export_problems([decoupled], tmp_path / "out")
