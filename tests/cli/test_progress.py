"""The progress bar: silent off a terminal and for short runs, erased when the run ends; a
benchmark's plain lines: on any stream, flushed, one per case."""

from __future__ import annotations

import io

from mpcform.cli.progress import BAR_WIDTH, CaseLines, ProgressBar, format_line


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_silent_when_not_a_terminal() -> None:
    stream = io.StringIO()
    bar = ProgressBar("run", stream, delay_s=0.0, interval_s=0.0)
    assert not bar.enabled
    for step in range(1, 11):
        bar(step, 10)
    assert stream.getvalue() == ""


def test_draws_on_a_terminal_and_erases_itself() -> None:
    stream = FakeTerminal()
    bar = ProgressBar("run", stream, delay_s=0.0, interval_s=0.0)
    assert bar.enabled
    bar(5, 10)
    drawn = stream.getvalue()
    assert drawn.startswith("\rrun [") and " 50%" in drawn and "5/10 steps" in drawn
    bar(10, 10)
    out = stream.getvalue()
    assert out.endswith("\r") and out[len(drawn) :].strip() == ""  # the last write blanks the line


def test_short_runs_print_nothing() -> None:
    stream = FakeTerminal()
    bar = ProgressBar("run", stream, delay_s=60.0)
    for step in range(1, 101):
        bar(step, 100)
    assert stream.getvalue() == ""


def test_format_line() -> None:
    line = format_line("swap", 25, 100, 3.0)
    assert "#" * (BAR_WIDTH // 4) in line and " 25%" in line and "25/100 steps" in line
    assert "3.0 s" in line and "about 9.0 s left" in line
    assert "about" not in format_line("swap", 0, 100, 0.1)
    assert "2 min 05 s" in format_line("swap", 50, 100, 125.0)


class FlushCounter(io.StringIO):
    flushes = 0

    def flush(self) -> None:
        self.flushes += 1


def test_case_lines_print_on_a_pipe_one_flushed_line_each() -> None:
    stream = FlushCounter()  # not a terminal
    lines = CaseLines("bench x", stream)
    lines.say("2 cases")
    lines.case("a (piqp)", 1, 2)
    lines.case("b (piqp)", 2, 2)
    lines.done()
    out = stream.getvalue().splitlines()
    assert stream.flushes == 4 and len(out) == 4 and all(line.startswith("bench x: ") for line in out)
    assert out[0] == "bench x: 2 cases"
    assert out[1].startswith("bench x: 1/2 a (piqp), ") and out[1].endswith(" s elapsed")
    assert out[2].startswith("bench x: 2/2 b (piqp), ") and "left at this pace" in out[2]
    assert out[3].startswith("bench x: done: 2 cases in ")
