"""``mpcform bench closed-loop`` on a short run: usable solvers drive it, unusable ones are reported."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpcform.cli.main import main

ROOT = Path(__file__).resolve().parents[2]


def test_bench_closed_loop_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    json_path = tmp_path / "rows.json"
    scenario = str(ROOT / "scenarios" / "swap_planar_8.toml")
    argv = [
        "bench",
        "closed-loop",
        scenario,
        "--solvers",
        "piqp",
        "osqp",
        "qpsolvers:quadprog",
        "--duration",
        "0.5",
        "--json",
        str(json_path),
    ]
    assert main(argv) == 0
    assert "| swap_planar_8 | piqp |" in capsys.readouterr().out
    rows = json.loads(json_path.read_text())
    assert [r["solver"] for r in rows] == ["piqp", "osqp", "qpsolvers:quadprog"]
    assert all(r["ok"] and r["steps"] == 5 and r["separation_violations"] == 0 for r in rows[:2])
    assert not rows[2]["ok"] and "positive-definite" in rows[2]["status"]  # reported, not run
