"""bench split: per scenario and number of rounds, the QP cost gap to the joint optimum falls with
the rounds and never goes below it; the figure is written; the CLI checks its options."""

from pathlib import Path

import numpy as np
import pytest

from mpcform.bench.split import curves, markdown_table, record, run
from mpcform.cli.main import main

SPATIAL = str(Path(__file__).resolve().parents[2] / "scenarios" / "swap_spatial_12.toml")


def test_the_gap_falls_with_the_rounds_and_stays_above_the_joint() -> None:
    planner, qps = record(SPATIAL, 5, 12)  # the first 12 steps' QPs (the swap's conflicts start at once)
    assert qps
    got = curves(planner, qps, 5)
    gap = got["cost"] / got["joint"][:, None] - 1.0
    assert gap.shape == (len(qps), 6)
    assert np.all(np.diff(got["cost"], axis=1) <= 1e-9 * np.abs(got["cost"][:, :1]))  # the best never rises
    assert gap.min() >= -1e-6  # the joint QP is the lower bound
    assert np.all(np.diff(got["wall"], axis=1) >= 0) and np.all(got["cpu"] >= 0)


def test_run_writes_the_figure_and_a_row_per_round(tmp_path: Path) -> None:
    png = tmp_path / "split.png"
    rows = run((SPATIAL,), (0, 2), steps=10, figure=str(png))
    assert [r["rounds"] for r in rows] == [0, 2] and png.read_bytes()[:4] == b"\x89PNG"
    assert rows[1]["gap_mean_pct"] <= rows[0]["gap_mean_pct"] + 1e-9
    assert markdown_table(rows).splitlines()[0].startswith("| scenario | rounds |")


@pytest.mark.parametrize("bad", [["--rounds", "-1"], ["--steps", "0"]])
def test_the_cli_rejects_bad_options(bad: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "split", "--scenarios", SPATIAL, *bad]) == 2
    assert "--rounds" in capsys.readouterr().err
