"""The README's Python snippets run as written, its module paths exist, and its Layout lists every module."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest
from crazyflie_fake import fake_crazyflie_py

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
SNIPPETS = re.findall(r"```python\n(.*?)```", README, flags=re.S)


def test_the_readme_has_python_snippets() -> None:
    assert len(SNIPPETS) >= 2


@pytest.mark.parametrize("code", SNIPPETS, ids=[f"snippet{i}" for i in range(len(SNIPPETS))])
def test_snippet_runs(code: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    if "crazyflie_py" in code:  # the Crazyswarm2 example: 8 recording fakes, in the repository
        monkeypatch.setitem(sys.modules, "crazyflie_py", fake_crazyflie_py([], 8))
        monkeypatch.chdir(ROOT)
    exec(compile(code, "README.md", "exec"), {"__name__": "readme"})  # noqa: S102


def test_module_paths_named_in_the_layout_exist() -> None:
    table = README.split("| seed equation |", 1)[1].split("\n\n", 1)[0]
    for path in sorted(set(re.findall(r"`((?:formation|reference|control|mpc|sim)/\w+\.py)`", table))):
        assert (ROOT / "mpcform" / path).is_file(), path


def _layout_rows() -> tuple[str, dict[str, str]]:
    """The Layout section's text block, and its rows by folder (``mpc/``: the names listed for it,
    continuation lines joined, parenthesised remarks dropped)."""
    section = README.split("\n## Layout\n", 1)[1].split("\n## ", 1)[0]
    block = section.split("```text\n", 1)[1].split("```", 1)[0]
    rows: dict[str, str] = {}
    folder = None
    for line in block.splitlines()[1:]:  # the first line is ``mpcform/``
        head = re.match(r"\s+((?:\w+/)+)\s{2,}(.*)", line)
        if head:
            folder = head.group(1)
            rows[folder] = head.group(2)
        elif folder is not None:
            rows[folder] += " " + line.strip()
    for key, text in rows.items():
        while re.search(r"\([^()]*\)", text):
            text = re.sub(r"\([^()]*\)", "", text)
        rows[key] = text
    return block, rows


def test_the_layout_lists_every_module() -> None:
    """Each module of the package is in the Layout block: a top-level one as ``name.py``, one in a
    subpackage by its name in its folder's row (or as ``folder/name.py``)."""
    block, rows = _layout_rows()
    missing = []
    for path in sorted((ROOT / "mpcform").rglob("*.py")):
        if path.name == "__init__.py":
            continue
        rel = path.relative_to(ROOT / "mpcform").as_posix()
        folder, _, name = rel.rpartition("/")
        if not folder:
            listed = re.search(rf"(?<![\w/]){re.escape(rel)}", block) is not None
        else:
            row = rows.get(folder + "/", "")
            listed = rel in block or re.search(rf"(?<![\w.]){path.stem}(?!\w)", row) is not None
        if not listed:
            missing.append(rel)
    assert not missing, f"modules missing from README.md's Layout section: {missing}"


def test_every_folder_of_the_layout_is_a_subpackage() -> None:
    _, rows = _layout_rows()
    assert rows, "no folder rows found in the Layout block"
    for folder in rows:
        assert (ROOT / "mpcform" / folder / "__init__.py").is_file(), folder
