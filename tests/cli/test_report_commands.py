"""``mpcform report``: real runs into a copy of the repository's files, the text outside the markers
kept, ``--check`` after regenerating and after a changed number, progress, errors, provenance."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from mpcform.cli.main import build_parser, main
from mpcform.cli.report_commands import DEFAULT_SOLVERS, bench_solvers, provenance
from mpcform.outputs import report_tables as rt

ROOT = Path(__file__).resolve().parents[2]
BEFORE = "# Scenarios\r\n\n- `short.toml`: ünïcode\n\n## Results\n\n"
AFTER = "\n\n## Key reference\n\nkept as it is"


def _root(tmp_path: Path, block: str = "stale") -> Path:
    """A checkout of one short scenario (the worked example, 1 s) and its README."""
    (tmp_path / "scenarios").mkdir()
    text = (
        (ROOT / "scenarios" / "worked_example.toml").read_text().replace("duration = 10.0", "duration = 1.0")
    )
    (tmp_path / "scenarios" / "short.toml").write_text(text)
    readme = f"{BEFORE}{rt.RESULTS.start}\n{block}\n{rt.RESULTS.end}{AFTER}"
    (tmp_path / "scenarios" / "README.md").write_bytes(readme.encode())
    return tmp_path


def _report(root: Path, *flags: str) -> int:
    return main(["report", "--root", str(root), *flags])


def test_report_writes_the_block_and_keeps_the_rest(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _root(tmp_path)
    assert _report(root, "--scenarios") == 0
    out, err = capsys.readouterr()
    assert err.splitlines()[0] == "report: scenario 1/1: short.toml" and "wrote scenarios/README.md" in out
    text = (root / "scenarios" / "README.md").read_bytes().decode()
    assert text.startswith(BEFORE + rt.RESULTS.start + "\n") and text.endswith(rt.RESULTS.end + AFTER)
    block = rt.read_block(text, rt.RESULTS, "F")
    assert (
        block.startswith(rt.PROVENANCE_PREFIX) and "commit `unknown`" in block
    )  # tmp_path is no git checkout
    assert "| `short.toml` | 3 | 2 | tracking | ideal |" in block and "stale" not in block


def test_check_passes_after_regenerating_and_fails_after_a_changed_number(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = _root(tmp_path)
    readme = root / "scenarios" / "README.md"
    assert _report(root, "--scenarios") == 0
    written = readme.read_bytes()
    assert _report(root, "--scenarios", "--check") == 0
    assert readme.read_bytes() == written  # --check writes nothing
    row = next(line for line in written.decode().splitlines() if line.startswith("| `short.toml`"))
    cells = row.split(" | ")
    timing = " | ".join([*cells[:-2], "123.45", "678.90 |"])
    readme.write_bytes(written.decode().replace(row, timing).encode())
    assert _report(root, "--scenarios", "--check") == 0  # timings are not checked
    readme.write_bytes(written.decode().replace(row, row.replace("| 3 | 2 |", "| 4 | 2 |")).encode())
    capsys.readouterr()
    assert _report(root, "--scenarios", "--check") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("mpcform: report differs: scenarios/README.md: 1 line(s) differ")
    assert "| 4 | 2 |" in err[-1] and "| 3 | 2 |" in err[-1]


def test_the_bench_block_on_a_recorded_problem(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    problems = tmp_path / "problems" / "swap_planar_8"
    problems.mkdir(parents=True)
    for name in ("step_0022.npz",):
        shutil.copy(ROOT / "problems" / "swap_planar_8" / name, problems / name)
    (tmp_path / "problems" / "README.md").write_text(f"intro\n{rt.BENCH.start}\n{rt.BENCH.end}\nrest\n")
    flags = ("--problems", "--solvers", "piqp", "--settings", "default", "--mpc-steps", "2")
    assert _report(tmp_path, *flags) == 0
    text = (tmp_path / "problems" / "README.md").read_text()
    assert text.startswith(f"intro\n{rt.BENCH.start}\n") and text.endswith(f"{rt.BENCH.end}\nrest\n")
    assert "#### Cold start" in text and "| piqp | 100 |" in text and "| swap planar | 8 | 2 |" in text
    assert "report: solver benchmark: piqp" in capsys.readouterr().err
    assert _report(tmp_path, *flags, "--check") == 0


def test_errors_name_the_file_or_the_option(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = _root(tmp_path)
    (root / "scenarios" / "README.md").write_text("no markers\n")
    assert _report(root, "--scenarios") == 2
    err = capsys.readouterr().err
    assert err.startswith("mpcform: error: scenarios/README.md: expected one <!-- results:start -->")
    assert "report: scenario" not in err  # the markers are checked before any run
    assert _report(root, "--problems", "--mpc-steps", "0") == 2
    assert "--mpc-steps" in capsys.readouterr().err
    assert _report(root, "--problems", "--solvers", "no-such-solver") == 2
    assert "mpcform: error: --solvers:" in capsys.readouterr().err
    assert _report(root, "--problems", "--time-limit", "0") == 2
    assert "--time-limit" in capsys.readouterr().err


def test_the_defaults_and_the_parser() -> None:
    args = build_parser().parse_args(["report"])
    assert not (args.scenarios or args.problems or args.check) and args.root == "."
    assert bench_solvers(None)[: len(DEFAULT_SOLVERS)] == DEFAULT_SOLVERS
    assert "report" in build_parser().format_help()


def test_the_provenance_names_the_commit() -> None:
    head = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    prov = provenance(ROOT)
    if not head:
        pytest.skip("not a git checkout")
    assert prov.commit == head and f"`{head}" in prov.line()
