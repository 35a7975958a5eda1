"""The report's tables: rows from real runs' summaries, the markers, the deterministic view and the
provenance line."""

from __future__ import annotations

from pathlib import Path

import pytest

from mpcform.errors import ValidationError
from mpcform.outputs import report_tables as rt
from mpcform.run.runner import RunResult, run_scenario
from mpcform.scenario.load import load_scenario

ROOT = Path(__file__).resolve().parents[2]
PROV = rt.Provenance("abc1234", False, "x86_64", 2, "3.11.7", "2.0.0", "2026-01-02")


def _short_run(tmp_path: Path, name: str, duration: str, short: str) -> RunResult:
    path = tmp_path / f"{name}.toml"
    text = (ROOT / "scenarios" / f"{name}.toml").read_text()
    assert f"duration = {duration}" in text
    path.write_text(text.replace(f"duration = {duration}", f"duration = {short}"))
    return run_scenario(load_scenario(path))


def test_a_row_reads_a_real_runs_summary(tmp_path: Path) -> None:
    run = _short_run(tmp_path, "worked_example", "10.0", "3.0")
    m = run.summary["metrics"]
    row = rt.scenario_row("worked_example.toml", run.summary, run.simulation.step_times_s, None)
    assert len(row) == len(rt.SCENARIO_COLUMNS)
    assert row[:5] == ("`worked_example.toml`", "3", "2", "tracking", "ideal")
    assert row[5] == f"{100 * m['completion']:.0f} % at {m['time_to_complete']:.1f} s"
    assert row[6] == f"{m['min_separation_true']:.3f} / 0.5"
    assert row[7] == f"{m['separation_violations_true']} / {m['speed_violations']} / — / 0"
    assert row[8] == "0 / 0 / 0"
    assert all(float(cell) >= 0 for cell in row[9:])


def test_an_mpc_row_names_its_coupling_and_counts_its_solves(tmp_path: Path) -> None:
    run = _short_run(tmp_path, "swap_planar_8", "12.0", "0.5")
    m = run.summary["metrics"]
    row = rt.scenario_row("swap_planar_8.toml", run.summary, run.simulation.step_times_s, "joint")
    assert row[3] == f"mpc: joint, {run.summary['solver']}"
    assert row[8] == f"{m['qp_solves']} / {m['fast_path_steps']} / {m['solver_failures']}"
    assert "%" in row[5] and row[6].endswith(" / 0.5")


def test_absent_values_show_a_dash() -> None:
    summary = {"n": 1, "dim": 2, "controller": "proportional", "metrics": {}, "limits": {}}
    row = rt.scenario_row("one.toml", summary, [], None)
    assert row[5:] == ("— % at —", "— / —", "— / — / — / —", "— / — / —", "—", "—")


def test_the_block_is_replaced_and_the_rest_kept_byte_for_byte() -> None:
    before = "# Title\r\n\nünïcode  \t\n" + rt.RESULTS.start
    after = rt.RESULTS.end + "\n\ntrailing without newline"
    text = rt.replace_block(f"{before}\nold\nrows\n{after}", rt.RESULTS, "new block\n", "F")
    assert text == f"{before}\nnew block\n{after}"
    assert rt.read_block(text, rt.RESULTS, "F") == "new block"
    assert rt.replace_block(text, rt.RESULTS, "new block", "F") == text


@pytest.mark.parametrize(
    "text",
    ["no markers", f"{rt.RESULTS.end} {rt.RESULTS.start}", f"{rt.RESULTS.start} {rt.RESULTS.start}"],
)
def test_missing_or_misordered_markers_name_the_file(text: str) -> None:
    with pytest.raises(ValidationError) as err:
        rt.read_block(text, rt.RESULTS, "scenarios/README.md")
    assert err.value.field == "scenarios/README.md" and rt.RESULTS.start in err.value.message


def _rows(median: str, n: str) -> list[tuple[str, ...]]:
    return [
        ("`b.toml`", "4", "2", "c", "ideal", "x", "y", "z", "w", "9.0", "9.9"),
        ("`a.toml`", n, "2", "c", "ideal", "x", "y", "z", "w", median, "1.0"),
    ]


def _block(median: str, n: str, prov: rt.Provenance = PROV) -> str:
    return rt.scenario_block(prov, _rows(median, n))


def test_the_check_ignores_timings_provenance_and_row_order() -> None:
    other = rt.Provenance("def5678", True, "arm64", 8, "3.12.0", "2.1.0", "2027-03-04")
    assert rt.compare_blocks("F", _block("0.1", "3"), _block("55.5", "3", other), rt.SCENARIO_TIMING) is None
    reordered = rt.scenario_block(PROV, _rows("0.1", "3")[::-1])
    assert reordered != _block("0.1", "3")
    assert rt.compare_blocks("F", _block("0.1", "3"), reordered, rt.SCENARIO_TIMING) is None
    view = rt.deterministic_view(_block("0.1", "3"), rt.SCENARIO_TIMING)
    assert not any(line.startswith(rt.PROVENANCE_PREFIX) for line in view)
    assert "`a.toml` | 3 | 2 | c | ideal | x | y | z | w | * | *" in view


def test_the_check_reports_a_changed_number_in_one_line() -> None:
    diff = rt.compare_blocks(
        "scenarios/README.md", _block("0.1", "3"), _block("0.1", "4"), rt.SCENARIO_TIMING
    )
    assert diff is not None and "\n" not in diff
    assert diff.startswith("scenarios/README.md: 1 line(s) differ") and "`a.toml` | 3" in diff
    dropped = rt.compare_blocks("F", "x\n- Machine: a\ny", "x\n- Machine: b\ny", (), ("- Machine:",))
    assert dropped is None
    assert (
        rt.compare_blocks("F", "x", "x\ny", ()) == "F: 1 line(s) differ; first: '(none)' in the file, 'y' now"
    )


def test_the_provenance_line_names_commit_machine_and_date() -> None:
    line = PROV.line()
    assert line.startswith(rt.PROVENANCE_PREFIX) and "`abc1234`" in line and "dirty" not in line
    assert "x86_64, 2 CPUs, Python 3.11.7, numpy 2.0.0, 2026-01-02 (UTC)" in line
    dirty = rt.Provenance("unknown", True, "arm64", None, "3.12", "2.1", "2027-01-01").line()
    assert "`unknown (dirty)`" in dirty and "? CPUs" in dirty


def test_headings_are_demoted_below_the_section() -> None:
    text = "# Title\n\n- item\n\n## Cold\n\n### default\n\n| a |\n"
    assert rt.demote_headings(text, levels=2) == "- item\n\n#### Cold\n\n##### default\n\n| a |"
