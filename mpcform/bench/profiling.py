"""``--profile PATH`` of ``bench scale`` and ``bench online``: where a case's planner steps spend
their time.

Each case is run a second time, after its timed run and never timed itself (the profiler slows
every Python call, so under a deadline the profiled run may fall back where the timed one did
not), with :mod:`cProfile` enabled around the planner steps only (not the case's set-up). The
file holds one section per case: a header line starting ``#`` that names the case and the steps
profiled, then :mod:`pstats`' text of the top :data:`TOP` functions by internal time
(``tottime``; file names without their directories).
"""

from __future__ import annotations

import cProfile
import io
import pstats
from collections.abc import Sequence
from pathlib import Path

TOP = 30  # functions listed per case


def top_functions(profiler: cProfile.Profile, header: str, top: int = TOP) -> str:
    """``# header``, then the ``top`` functions by tottime of what ``profiler`` recorded."""
    text = io.StringIO()
    pstats.Stats(profiler, stream=text).strip_dirs().sort_stats("tottime").print_stats(top)
    return f"# {header}\n{text.getvalue().strip()}\n"


def write_profiles(path: str | Path, sections: Sequence[str]) -> None:
    """The cases' sections (:func:`top_functions`) into ``path``, a blank line between them."""
    Path(path).write_text("\n".join(sections))
