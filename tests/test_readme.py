"""The README's Python snippets run as written, and its module paths exist."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
SNIPPETS = re.findall(r"```python\n(.*?)```", README, flags=re.S)


def test_the_readme_has_python_snippets() -> None:
    assert len(SNIPPETS) >= 2


@pytest.mark.parametrize("code", SNIPPETS, ids=[f"snippet{i}" for i in range(len(SNIPPETS))])
def test_snippet_runs(code: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {"__name__": "readme"})  # noqa: S102


def test_module_paths_named_in_the_layout_exist() -> None:
    table = README.split("| seed equation |", 1)[1].split("\n\n", 1)[0]
    for path in sorted(set(re.findall(r"`((?:formation|reference|control|mpc|sim)/\w+\.py)`", table))):
        assert (ROOT / "mpcform" / path).is_file(), path
