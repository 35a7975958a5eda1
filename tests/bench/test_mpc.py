"""``mpcform bench mpc`` on a tiny case: every column is measured and the JSON records match."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mpcform.bench.mpc import RecordingBackend, bench_case, markdown_table, swap_case
from mpcform.cli.main import main
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend


def test_recording_backend_keeps_every_problem_and_solves_like_its_inner_backend() -> None:
    from mpcform.mpc.limits import Limits
    from mpcform.mpc.planner import MPCPlanner

    ref, start = swap_case(4, 2)
    rec = RecordingBackend(make_backend("piqp", SolverOptions()))
    planner = MPCPlanner(ref, 0.1, Limits(v_max_mps=1.0, d_min_m=0.5), solver=rec)
    planner.reset(0.0, start)
    infos = [planner.step(0.0, start).info]
    assert infos[0].mode == "qp" and len(rec.problems) == 1 and rec.problems[0]["setup"]
    pb = rec.problems[0]
    assert pb["A"].nnz == pb["Ax"].shape[0] and pb["l"].shape == pb["u"].shape == (pb["A"].shape[0],)


def test_bench_case_measures_qp_fast_path_and_references() -> None:
    row = bench_case(4, 2, steps=60, solver="piqp", coupling="joint", cvxpy_solver=None)
    assert row["qp_steps"] + row["fast_path_steps"] + row["fallback_steps"] == 60
    assert row["qp_steps"] > 0 and row["fast_path_steps"] > 0
    for key in ("qp_ms_median", "raw_ms_median", "overhead", "fast_ms_median", "rollout_ms_median"):
        assert np.isfinite(row[key]) and row[key] > 0
    table = markdown_table([row])
    assert table.count("\n") == 2 and "swap planar" in table


def test_cli_bench_mpc_writes_json(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "rows.json"
    argv = [
        "bench",
        "mpc",
        "--n",
        "3",
        "--spatial-n",
        "--steps",
        "5",
        "--cvxpy-max-n",
        "0",
        "--json",
        str(out),
    ]
    assert main(argv) == 0
    records = json.loads(out.read_text())
    assert [r["n"] for r in records] == [3] and "| case |" in capsys.readouterr().out
