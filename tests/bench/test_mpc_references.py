"""The floors of ``bench mpc``: the stopwatch's CPU time, the raw replay (one bare object per
pattern, the same solutions as our backend), the DAQP meter, the rollout, and cvxpy (the same QP's
optimum, checked with clarabel; the replay within its budget)."""

from __future__ import annotations

import time

import numpy as np
import pytest
import scipy.sparse as sp

from mpcform.bench.mpc import RecordingBackend, generated_case
from mpcform.bench.mpc_references import (
    RawReplay,
    Stopwatch,
    cvxpy_replay,
    cvxpy_solve,
    daqp_meter,
    rollout_ms,
)
from mpcform.solvers.base import QPSolution, SolverOptions
from mpcform.solvers.registry import make_backend


class _Keeping(RecordingBackend):
    """Also keeps every solution."""

    def solve(self, x0: np.ndarray | None = None) -> QPSolution:
        sol = super().solve(x0)
        self.solutions.append(sol)
        return sol


def _recorded(n: int, steps: int) -> _Keeping:
    """The QPs the joint planner sends on an n-drone planar swap, and their solutions."""
    case = generated_case(n, 2, steps, "joint")
    settings = case.settings
    rec = _Keeping(make_backend("piqp", SolverOptions(1e-9, 1e-9)))
    rec.solutions = []
    planner = case.planner(settings, rec)
    p = case.start_m.copy()
    planner.reset(0.0, p)
    for j in range(steps):
        p = p + 0.1 * planner.step(0.1 * j, p).command_mps
    return rec


def test_stopwatch_cpu_time_follows_work_not_waiting() -> None:
    clock = Stopwatch()
    time.sleep(0.2)  # the process's other threads (OpenBLAS spinning after work) may accrue a little
    wall, cpu = clock.ms()
    assert wall >= 200 and cpu < 0.5 * wall
    clock = Stopwatch()
    np.linalg.eigvalsh(np.random.default_rng(0).normal(size=(300, 300)) + 0.0)
    while clock.ms()[0] < 30:
        pass
    wall, cpu = clock.ms()
    assert cpu > 0.3 * wall  # busy: CPU time accrues (the machine may be shared)


def test_raw_replay_solves_like_our_backend_with_one_object_per_pattern() -> None:
    rec = _recorded(4, 40)
    problems, solutions = rec.problems, rec.solutions
    assert len(problems) == len(solutions) and sum(pb["setup"] for pb in problems) >= 2
    replay = RawReplay("piqp", SolverOptions(1e-9, 1e-9))
    for pb, sol in zip(problems, solutions, strict=True):
        wall, cpu = replay.run(pb)
        assert wall > 0 and cpu > 0
        assert sol.x is not None and np.max(np.abs(replay.x - sol.x)) < 1e-7
    keys = {tuple(pb["A"].indices) + tuple(pb["A"].indptr) for pb in problems if pb["setup"]}
    assert replay.objects == len(keys)


def test_daqp_meter_times_the_calls_and_restores_daqp() -> None:
    daqp = pytest.importorskip("daqp")
    inner = daqp.solve
    with daqp_meter() as spent:
        x, *_ = daqp.solve(np.eye(2), np.array([1.0, -1.0]), np.eye(2), np.ones(2), -np.ones(2))
        assert spent[0] > 0 and spent[1] > 0
    assert daqp.solve is inner and np.allclose(x, [-1.0, 1.0])


def test_rollout_takes_time() -> None:
    case = generated_case(4, 2, 1, "joint")
    planner = case.planner(case.settings, "piqp")
    wall, cpu = rollout_ms(planner, 0.0, case.start_m)
    assert wall > 0 and cpu >= 0


def test_cvxpy_replay_solves_each_qp_or_stops_at_its_budget() -> None:
    pytest.importorskip("cvxpy")
    problems = _recorded(3, 8).problems
    done = cvxpy_replay(problems, "piqp", 60.0)
    assert not done.skipped and len(done.times) == len(problems)
    assert done.whole[0] == pytest.approx(sum(t[0] for t in done.times)) and done.whole[0] > 0
    stopped = cvxpy_replay(problems, "piqp", 1e-6)
    assert stopped.skipped.startswith("estimated") and "budget 1e-06 s" in stopped.skipped
    assert len(stopped.times) == 1  # the first QP alone is over


def test_cvxpy_solves_the_recorded_qp() -> None:
    pytest.importorskip("cvxpy")
    rec = _recorded(4, 6)
    for pb, sol in zip(rec.problems, rec.solutions, strict=True):
        _, x = cvxpy_solve(pb, "clarabel")
        a = pb["A"].copy()
        a.data = pb["Ax"]
        assert x is not None and sol.x is not None
        assert np.all(a @ x >= pb["l"] - 1e-6) and np.all(a @ x <= pb["u"] + 1e-6)

        p_full = pb["P"] + sp.triu(pb["P"], 1).T
        cost = [float(0.5 * z @ (p_full @ z) + pb["q"] @ z) for z in (x, sol.x)]
        assert cost[0] == pytest.approx(cost[1], rel=1e-6, abs=1e-8)
