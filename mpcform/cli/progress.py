"""Progress: a one-line bar for long simulations (on a terminal only), and plain lines for benchmarks.

:class:`ProgressBar` is the ``progress(step, steps)`` callback of :func:`mpcform.simulate`.
It draws only when its stream is a terminal and the run has lasted ``delay_s`` (short runs
print nothing), redraws at most every ``interval_s``, and erases itself when the run ends so
that the summary table follows on a clean line. :class:`CaseLines` prints a benchmark's plan and
one line per case on stderr, on a terminal or a pipe (stdout keeps the tables and records).
"""

from __future__ import annotations

import sys
import time
from typing import TextIO

BAR_WIDTH = 30


class ProgressBar:
    """``label [#######.......]  42%  210/500 steps  1.2 s, about 1.6 s left``."""

    def __init__(
        self,
        label: str = "simulating",
        stream: TextIO | None = None,
        *,
        enabled: bool | None = None,
        delay_s: float = 0.5,
        interval_s: float = 0.1,
    ) -> None:
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.enabled = _is_terminal(self.stream) if enabled is None else enabled
        self.delay_s, self.interval_s = delay_s, interval_s
        self._start = time.perf_counter()
        self._last_draw = -float("inf")
        self._width = 0  # length of the line on screen (0: nothing drawn)

    def __call__(self, step: int, steps: int) -> None:
        if not self.enabled:
            return
        now = time.perf_counter()
        elapsed = now - self._start
        if step >= steps:
            self.close()
            return
        if elapsed < self.delay_s or now - self._last_draw < self.interval_s:
            return
        self._last_draw = now
        self._draw(format_line(self.label, step, steps, elapsed))

    def close(self) -> None:
        """Erase the bar (if drawn)."""
        if self._width:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
            self._width = 0

    def _draw(self, line: str) -> None:
        pad = " " * max(0, self._width - len(line))
        self.stream.write("\r" + line + pad)
        self.stream.flush()
        self._width = len(line)


class CaseLines:
    """A benchmark's progress as plain lines on stderr, on a terminal or a pipe alike (flushed):
    what it will do (:meth:`say`), one line as each case starts (:meth:`case`), the total at the end.

    ``bench mpc: 2/8 swap planar n=16 (piqp), 12.3 s elapsed, about 1 min 14 s left at this pace``:
    what is left is the mean time of the cases so far times the cases to go (a rough figure when
    the cases differ in size)."""

    def __init__(self, command: str, stream: TextIO | None = None) -> None:
        self.command = command
        self.stream = sys.stderr if stream is None else stream
        self._start = time.monotonic()
        self._cases = 0

    def say(self, text: str) -> None:
        """One line ``command: text``."""
        self.stream.write(f"{self.command}: {text}\n")
        self.stream.flush()

    def case(self, label: str, i: int, n: int) -> None:
        """Case ``i`` of ``n`` (from 1), ``label``, starts."""
        elapsed = time.monotonic() - self._start
        self._cases = max(self._cases, i)
        left = f", about {_duration(elapsed / (i - 1) * (n - i + 1))} left at this pace" if i > 1 else ""
        self.say(f"{i}/{n} {label}, {_duration(elapsed)} elapsed{left}")

    def done(self) -> None:
        """The closing line: how many cases, in how long."""
        cases = f"{self._cases} case{'' if self._cases == 1 else 's'}"
        self.say(f"done: {cases} in {_duration(time.monotonic() - self._start)}")


def format_line(label: str, step: int, steps: int, elapsed_s: float) -> str:
    """The text of the bar after ``step`` of ``steps`` steps and ``elapsed_s`` seconds."""
    frac = min(max(step / steps, 0.0), 1.0) if steps > 0 else 1.0
    filled = int(round(frac * BAR_WIDTH))
    bar = "#" * filled + "." * (BAR_WIDTH - filled)
    left = f", about {_duration(elapsed_s * (1.0 - frac) / frac)} left" if frac > 0 else ""
    return f"{label} [{bar}] {100 * frac:3.0f}%  {step}/{steps} steps  {_duration(elapsed_s)}{left}"


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.1f} s"
    minutes, sec = divmod(int(round(seconds)), 60)
    return f"{minutes} min {sec:02d} s"


def _is_terminal(stream: TextIO) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # a closed or foreign stream
        return False
