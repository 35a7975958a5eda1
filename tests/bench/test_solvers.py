"""``mpcform bench solvers`` on a tiny subset of the bundled problems."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from mpcform.bench.problems import problem_files
from mpcform.bench.solvers import benchmark_tasks
from mpcform.bench.worker import MODES
from mpcform.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def tiny_problems(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two consecutive small problems (8 planar drones)."""
    out = tmp_path_factory.mktemp("problems")
    for f in problem_files(ROOT / "problems")[:2]:
        (out / f.parent.name).mkdir(exist_ok=True)
        shutil.copy(f, out / f.parent.name / f.name)
    return out


def test_bench_solvers_cli(tiny_problems: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    json_path, report = tmp_path / "rows.json", tmp_path / "report.md"
    argv = [
        "bench",
        "solvers",
        "--problems",
        str(tiny_problems),
        "--solvers",
        "piqp",
        "qpsolvers:quadprog",
        "--settings",
        "default",
        "high",
        "--no-exact",
        "--json",
        str(json_path),
        "--report",
        str(report),
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "## Cold start" in out and "## Warm-start replay" in out and "| piqp | 100 |" in out
    assert report.read_text().strip() == out.strip()
    rows = json.loads(json_path.read_text())
    piqp = [r for r in rows if r["solver"] == "piqp"]
    assert {(r["mode"], r["setting"]) for r in piqp} == {(m, s) for m in MODES for s in ("default", "high")}
    assert all(r["success_rate"] == 100.0 and r["problems"] == 2 for r in piqp)
    (quadprog,) = [r for r in rows if r["solver"] == "qpsolvers:quadprog"]
    assert quadprog["success_rate"] == 0.0 and "positive-definite" in quadprog["note"]


def test_bench_solvers_rejects_an_unknown_solver(
    tiny_problems: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["bench", "solvers", "--problems", str(tiny_problems), "--solvers", "nope"]) == 2
    assert "unknown solver" in capsys.readouterr().err


def test_tasks_replay_each_scenario_from_its_first_problem() -> None:
    paths = ["d/a/step_0001.npz", "d/a/step_0002.npz", "d/b/step_0005.npz"]
    tasks = benchmark_tasks(paths, "piqp", ["low", "default"], ["cold", "warm"], 0.5)
    assert [(t.mode, t.setting) for t in tasks[::3]] == [
        ("cold", "low"),
        ("cold", "default"),
        ("warm", "low"),
        ("warm", "default"),
    ]
    assert [t.first for t in tasks[:3]] == [True, False, True]  # b starts its own sequence
    assert [t.index for t in tasks[:3]] == [0, 1, 2] and [t.eps for t in tasks[::3]] == [1e-3, None] * 2
    assert all(t.solver == "piqp" and t.time_limit_s == 0.5 for t in tasks)
