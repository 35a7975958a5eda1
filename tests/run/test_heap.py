"""keep_heap: freed blocks stay in the heap (no page faults to reuse them), here and in children.

Each case runs in a fresh interpreter: the setting is process-wide and cannot be undone."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

from mpcform.run.heap import SETTINGS

pytestmark = pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's allocator only")

# four 320 kB arrays allocated and freed 50 times: page faults counted over the loop
CHURN = """
import resource, sys
import numpy as np
from mpcform.run.heap import keep_heap
print(keep_heap() if sys.argv[1] == "keep" else None)
blocks = [np.ones(40_000) for _ in range(4)]
del blocks
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    blocks = [np.ones(40_000) for _ in range(4)]
    del blocks
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _run(code: str, *args: str, env: dict[str, str] | None = None) -> list[str]:
    clean = {k: v for k, v in os.environ.items() if k not in SETTINGS}
    out = subprocess.run(
        [sys.executable, "-c", code, *args],
        env={**clean, **(env or {})},
        capture_output=True,
        text=True,
        check=True,
    )
    return out.stdout.split()


def test_freed_blocks_are_reused_without_page_faults() -> None:
    applied, faults = _run(CHURN, "keep")
    assert applied == "True"
    assert int(faults) < 50  # 200 blocks of 79 pages each would fault about 16,000 times
    assert int(_run(CHURN, "default")[1]) > 1000  # glibc's default returns them: the test can fail


CHILD = """
import subprocess, sys
from mpcform.run.heap import keep_heap
print(keep_heap())
show = "import os; print(os.environ['MALLOC_TRIM_THRESHOLD_'], os.environ['MALLOC_MMAP_THRESHOLD_'])"
subprocess.run([sys.executable, "-c", show], check=True)
"""
COMMAND = """
import os
from mpcform.cli.main import main
main(["keys"])
print(os.environ["MALLOC_TRIM_THRESHOLD_"])
"""
TRIM, MMAP = (str(value) for _, value in SETTINGS.values())


def test_children_inherit_the_setting_and_the_callers_choice_is_kept() -> None:
    assert _run(CHILD) == ["True", TRIM, MMAP]
    assert _run(CHILD, env={"MALLOC_TRIM_THRESHOLD_": "1000"}) == ["True", "1000", MMAP]


def test_the_command_keeps_the_heap() -> None:
    assert _run(COMMAND)[-1] == TRIM
