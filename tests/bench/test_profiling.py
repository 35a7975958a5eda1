"""``--profile``'s sections: a header line, then pstats' top functions by tottime."""

from __future__ import annotations

import cProfile
from pathlib import Path

from mpcform.bench.profiling import TOP, top_functions, write_profiles


def _busy(k: int) -> int:
    return sum(i * i for i in range(k))


def _elsewhere() -> int:
    return _busy(10)


def test_a_section_names_the_case_then_the_profiled_functions_only() -> None:
    _elsewhere()  # before the profiler: not in the section
    profiler = cProfile.Profile()
    profiler.enable()
    _busy(20_000)
    profiler.disable()
    text = top_functions(profiler, "case A: 1 step")
    lines = text.splitlines()
    assert lines[0] == "# case A: 1 step" and "Ordered by: internal time" in text
    assert "test_profiling.py" in text and "(_busy)" in text and "(_elsewhere)" not in text
    listed = [line for line in lines if "(" in line and ":" in line and not line.startswith("#")]
    assert 0 < len(listed) <= TOP


def test_at_most_top_functions_are_listed() -> None:
    profiler = cProfile.Profile()
    profiler.enable()
    for k in range(3):
        _busy(k)
        _elsewhere()
    sorted(range(5))
    profiler.disable()
    assert "List reduced from" in top_functions(profiler, "case", top=2)


def test_write_profiles_keeps_every_section(tmp_path: Path) -> None:
    out = tmp_path / "profile.txt"
    write_profiles(out, ["# one\nx\n", "# two\ny\n"])
    assert [line for line in out.read_text().splitlines() if line.startswith("#")] == ["# one", "# two"]
