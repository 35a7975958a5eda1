"""``mpcform bench closed-loop`` on a short run: usable solvers drive it, unusable ones are reported."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpcform.bench.closed_loop import closed_loop_markdown, load_bench_scenario
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


def test_an_invalid_scenario_is_an_error_not_a_table_cell(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.toml"
    text = (ROOT / "scenarios" / "swap_planar_8.toml").read_text()
    bad.write_text(text.replace("gain = 1.0", "gain = 100.0"))  # gain * dt > 1
    line = next(k for k, row in enumerate(bad.read_text().splitlines(), 1) if row.startswith("gain"))
    assert main(["bench", "closed-loop", str(bad), "--solvers", "piqp"]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.strip().splitlines() == [err.strip()]  # one line, no table
    assert err.startswith(f"mpcform: error: {bad}:{line}: controller.gain: ")


@pytest.mark.parametrize("duration", ["-1", "0.01"])
def test_a_bad_duration_is_an_error(duration: str, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["bench", "closed-loop", str(ROOT / "scenarios" / "swap_planar_8.toml"), "--solvers", "piqp"]
    assert main([*argv, "--duration", duration]) == 2
    assert capsys.readouterr().err.startswith("mpcform: error: --duration: ")


def test_load_bench_scenario_replaces_the_duration() -> None:
    s = load_bench_scenario(ROOT / "scenarios" / "swap_planar_8.toml", 0.5, "piqp")
    assert s.steps == 5


def test_a_failed_run_shows_a_whole_phrase() -> None:
    status = "ValueError: " + "word " * 40 + "end"
    text = closed_loop_markdown([{"scenario": "s", "solver": "x", "ok": False, "status": status}])
    cell = text.splitlines()[-1].split(" | ")[2]
    assert cell.startswith("failed: ValueError: word") and cell.endswith("word...") and len(cell) <= 110
