"""The manifest of an output directory: written whole, read back only as mpcform writes it."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from mpcform.errors import ValidationError
from mpcform.outputs.manifest import (
    MANIFEST,
    MAX_ENTRIES,
    MAX_MANIFEST_BYTES,
    Entry,
    allowed,
    read_manifest,
    write_manifest,
)

RUN = {
    "summary.json": Entry("file", 12),
    "plots": Entry("dir"),
    "plots/top_view.png": Entry("file", 0),
    "export": Entry("dir"),
    "export/fly.py": Entry("file", 3),
}


def test_a_manifest_round_trips_one_entry_a_line(tmp_path: Path) -> None:
    write_manifest(tmp_path, "run", RUN)
    text = (tmp_path / MANIFEST).read_text()
    assert text.splitlines()[0] == '{"mpcform_manifest": 1, "kind": "run", "entries": {'
    assert ' "plots/top_view.png": {"type": "file", "bytes": 0},' in text.splitlines()
    assert read_manifest(tmp_path, "run") == RUN
    assert json.loads(text)["entries"]["plots"] == {"type": "dir"}
    write_manifest(tmp_path, "plots", {})
    assert read_manifest(tmp_path, "plots") == {} and not (tmp_path / f"{MANIFEST}.tmp").exists()
    assert read_manifest(tmp_path / "missing", "run") is None


def test_entries_are_files_with_a_size_or_directories() -> None:
    for bad in (("link", None), ("file", None), ("file", -1), ("file", True), ("dir", 3)):
        with pytest.raises(ValidationError):
            Entry(*bad)  # type: ignore[arg-type]


def test_the_layout_of_each_kind() -> None:
    assert allowed("run", "trajectory.npz") == "file" and allowed("run", "plots") == "dir"
    assert allowed("run", "plots/anything.png") == "file" and allowed("run", "export/fly.py") == "file"
    for never in (
        "notes.txt",
        "summary.json/x",
        "plots/a/b",
        "../summary.json",
        "plots/..",
        "",
        ".mpcform.lock",
    ):
        assert allowed("run", never) is None, never
    assert allowed("plots", "top_view.png") == "file" and allowed("export", "fly.py") == "file"
    for never in ("sub/x.png", "..", MANIFEST, ".mpcform.lock"):
        assert allowed("plots", never) is None, never


@pytest.mark.parametrize(
    ("doc", "says"),
    [
        ("{not json", "cannot read it as JSON"),
        (
            '{"mpcform_manifest": 2, "kind": "run", "entries": {}}',
            "holds {'entries': {}, 'kind': 'run', 'mpcform_manifest': 2}",
        ),
        ('{"mpcform_manifest": 1, "kind": "mine", "entries": {}}', "holds"),
        ('{"mpcform_manifest": 1, "kind": "run", "entries": []}', "entries: expected an object"),
        (
            '{"mpcform_manifest": 1, "kind": "run", "entries": {"notes.txt": {"type": "file", "bytes": 4}}}',
            "entry 'notes.txt': {'bytes': 4, 'type': 'file'} is not what mpcform writes",
        ),
        (
            '{"mpcform_manifest": 1, "kind": "run", "entries": {"trajectory.npz": {"type": "dir"}}}',
            "entry 'trajectory.npz'",
        ),
        (
            '{"mpcform_manifest": 1, "kind": "run", "entries": {"../x": {"type": "file", "bytes": 1}}}',
            "entry '../x'",
        ),
        (
            '{"mpcform_manifest": 1, "kind": "run", "entries": {"summary.json": {"type": "file"}}}',
            "entry 'summary.json'",
        ),
    ],
)
def test_anything_but_what_mpcform_writes_is_refused(tmp_path: Path, doc: str, says: str) -> None:
    """A hand-made or damaged manifest never makes a user's file look like mpcform's."""
    (tmp_path / MANIFEST).write_text(doc)
    with pytest.raises(ValidationError, match=rf"^{tmp_path / MANIFEST}: .*" + says.replace("{", r"\{")):
        read_manifest(tmp_path, "run")


def test_a_manifest_of_another_kind_names_the_field(tmp_path: Path) -> None:
    write_manifest(tmp_path, "plots", {})
    with pytest.raises(
        ValidationError,
        match=r"^--out: '.*' holds the figures of `mpcform plot --out`; expected a directory for the "
        "outputs of a run",
    ):
        read_manifest(tmp_path, "run", "--out")


def test_the_manifest_itself_is_a_small_regular_file(tmp_path: Path) -> None:
    path = tmp_path / MANIFEST
    path.symlink_to("/dev/zero")
    with pytest.raises(ValidationError, match="is a symbolic link; expected the manifest mpcform writes"):
        read_manifest(tmp_path, "run")
    path.unlink()
    path.mkdir()
    with pytest.raises(ValidationError, match="is a directory; expected the manifest"):
        read_manifest(tmp_path, "run")
    path.rmdir()
    with open(path, "wb") as f:
        f.truncate(MAX_MANIFEST_BYTES + 1)
    with pytest.raises(ValidationError, match="is 16 MiB .* expected a manifest of mpcform"):
        read_manifest(tmp_path, "run")
    entries = {f"plots/{k}.png": {"type": "file", "bytes": 1} for k in range(MAX_ENTRIES + 1)}
    path.write_text(json.dumps({"mpcform_manifest": 1, "kind": "run", "entries": entries}))
    with pytest.raises(ValidationError, match="entries: expected an object of at most 100,000"):
        read_manifest(tmp_path, "run")
    assert os.path.getsize(path) < MAX_MANIFEST_BYTES
