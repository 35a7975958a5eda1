"""``mpcform compare``'s records and table (``mpcform.outputs.compare``) on real saved runs: short runs
of ``swap_planar_8`` by the MPC and by the tracking law, read back from their directories."""

from __future__ import annotations

import dataclasses

import pytest
from scipy.integrate import trapezoid

from mpcform.outputs.compare import COLUMNS, comparison_records, markdown_table, run_labels
from mpcform.outputs.rundata import RunData, load_run
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario
from tests.saved_runs import SCENARIOS, short_run, shortened

STEPS = 20


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> list[RunData]:
    """[MPC run, tracking run, a second tracking run in another directory]."""
    root = tmp_path_factory.mktemp("compare")
    short_run("swap_planar_8", root / "mpc", steps=STEPS)
    scenario = shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), STEPS)
    for name in ("law_a", "law_b"):
        run_scenario(scenario, root / name, controller="tracking")
    return [load_run(root / name) for name in ("mpc", "law_a", "law_b")]


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line[2:-2].split(" | ")]


def test_labels_name_the_controller_and_tell_equal_runs_apart(runs: list[RunData]) -> None:
    assert run_labels(runs[:2]) == ["swap_planar_8 (mpc, piqp)", "swap_planar_8 (tracking)"]
    assert run_labels(runs) == [
        "swap_planar_8 (mpc, piqp)",
        "swap_planar_8 (tracking) [law_a]",
        "swap_planar_8 (tracking) [law_b]",
    ]


def test_records_are_the_runs_summary_metrics(runs: list[RunData]) -> None:
    records = comparison_records(runs)
    assert len(records) == len(runs)
    for rec, run in zip(records, runs, strict=True):
        m = run.summary["metrics"]
        assert rec["directory"] == str(run.directory) and rec["scenario"] == "swap_planar_8"
        assert rec["controller"] == run.summary["controller"] and rec["solver"] == run.summary["solver"]
        for key in ("final_tracking_error", "max_tracking_error", "min_separation_segments", "max_speed"):
            assert rec[key] == m[key], key
        for key in ("qp_solves", "fast_path_steps", "solver_failures"):
            assert rec[key] == m[key], key
        assert rec["violations"] == f"{m['separation_violations']}/{m['speed_violations']}"
    mpc, law = records[0], records[1]
    assert mpc["qp_solves"] == STEPS and law["qp_solves"] == 0 and law["solver"] is None


def test_step_times_are_of_the_qp_steps_or_else_of_the_runs_mode(runs: list[RunData]) -> None:
    mpc, law = comparison_records(runs[:2])
    assert mpc["step_mode"] == "qp"
    assert mpc["step_ms_median"] == runs[0].summary["metrics"]["step_time_ms"]["qp"]["median"]
    assert mpc["step_ms_p90"] == runs[0].summary["metrics"]["step_time_ms"]["qp"]["p90"]
    modes = runs[1].summary["metrics"]["step_time_ms"]
    assert law["step_mode"] == next(iter(modes)) and "qp" not in modes
    assert law["step_ms_median"] == modes[law["step_mode"]]["median"]


def test_tracking_cost_integrates_the_squared_error(runs: list[RunData]) -> None:
    for rec, run in zip(comparison_records(runs), runs, strict=True):
        traj = run.trajectory
        err2 = ((traj.positions_m - traj.reference_m) ** 2).sum(axis=(1, 2))
        assert rec["tracking_cost"] == pytest.approx(trapezoid(err2, traj.t_s), rel=1e-12)
        assert rec["tracking_cost"] > 0
    # both controllers start from the same positions, so the costs differ only by how they flew
    mpc, law, law_again = comparison_records(runs)
    assert law["tracking_cost"] == law_again["tracking_cost"] != mpc["tracking_cost"]


def test_the_table_rows_match_the_records(runs: list[RunData]) -> None:
    records = comparison_records(runs)
    lines = markdown_table(records).splitlines()
    assert _cells(lines[0]) == [title for _, title in COLUMNS]
    assert lines[1] == "| " + " | ".join("---" for _ in COLUMNS) + " |"
    assert len(lines) == 2 + len(runs)
    for line, rec in zip(lines[2:], records, strict=True):
        cells = dict(zip((key for key, _ in COLUMNS), _cells(line), strict=True))
        assert cells["run"] == rec["run"]
        for key in ("final_tracking_error", "max_tracking_error", "tracking_cost", "max_speed"):
            assert cells[key] == f"{rec[key]:.4g}", key
            assert float(cells[key]) == pytest.approx(rec[key], rel=1e-3)
        assert cells["qp_solves"] == str(rec["qp_solves"]) and cells["violations"] == rec["violations"]
    assert _cells(lines[3])[2] == "-"  # the tracking run has no solver


def test_a_run_without_metrics_shows_dashes_and_pipes_are_escaped(runs: list[RunData]) -> None:
    bare = dataclasses.replace(runs[1], summary={"scenario": "a|b", "controller": "tracking"})
    (rec,) = comparison_records([bare])
    assert rec["final_tracking_error"] is None and rec["violations"] == "-/-" and rec["step_mode"] is None
    cells = _cells(markdown_table([rec]).splitlines()[-1].replace("\\|", "\x00"))
    assert cells[0] == "a\x00b (tracking)"  # the pipe in the label is escaped, not a column break
    assert cells[3] == "-" and cells[4] == "-"  # final and max error: not in the summary
    assert cells[5] == f"{rec['tracking_cost']:.4g}"  # still computed from the trajectory
