"""Claimed output directories: checked before the work, exactly mpcform's own files replaced,
the user's never; a lock per directory; an interrupted command leaves nothing half-written."""

from __future__ import annotations

from pathlib import Path

import pytest

from mpcform.errors import ValidationError
from mpcform.outputs.manifest import LOCK, MANIFEST, read_manifest
from mpcform.outputs.outdir import RUN_LAYOUT, check_root, claim_dir

NAMES = tuple(RUN_LAYOUT)


def _write_run(root: Path, plots: bool = True) -> None:
    """What a command writes into a claimed run directory (after ``clear``)."""
    for name in ("trajectory.npz", "trajectory.csv", "summary.json"):
        (root / name).write_text(f"mpcform's {name}")
    if plots:
        (root / "plots").mkdir()
        (root / "plots" / "top_view.png").write_text("png")


def _a_run(root: Path) -> None:
    with claim_dir(root, "run", NAMES) as claim:
        claim.clear()
        _write_run(root)


def test_a_new_directory_gets_a_manifest_of_what_was_written(tmp_path: Path) -> None:
    root = tmp_path / "a" / "b"
    _a_run(root)
    entries = read_manifest(root, "run")
    assert entries is not None
    assert sorted(entries) == [
        "plots",
        "plots/top_view.png",
        "summary.json",
        "trajectory.csv",
        "trajectory.npz",
    ]
    assert entries["summary.json"].bytes == len("mpcform's summary.json") and entries["plots"].type == "dir"
    assert (root / LOCK).is_file()


def test_reuse_removes_exactly_the_manifests_entries(tmp_path: Path) -> None:
    _a_run(tmp_path)
    (tmp_path / "notes.txt").write_text("mine")  # not a name mpcform writes: left alone
    with claim_dir(tmp_path, "run", NAMES) as claim:
        assert (tmp_path / "plots" / "top_view.png").exists()  # nothing removed before clear()
        assert claim.clear() == ["trajectory.npz", "trajectory.csv", "summary.json", "plots"]
        assert sorted(p.name for p in tmp_path.iterdir()) == [MANIFEST, LOCK, "notes.txt"]
        _write_run(tmp_path, plots=False)
    entries = read_manifest(tmp_path, "run")
    assert entries is not None and "plots" not in entries and (tmp_path / "notes.txt").read_text() == "mine"


@pytest.mark.parametrize(
    ("make", "says"),
    [
        (
            lambda r: (r / "plots" / "mine.png").write_text("mine"),
            "plots/mine.png: a file that mpcform did not write",
        ),
        (lambda r: (r / "formation.npz").mkdir(), "formation.npz: a directory that mpcform did not write"),
        (
            lambda r: (r / "viewer.html").symlink_to("/etc/hostname"),
            "viewer.html: a symbolic link that mpcform",
        ),
        (
            lambda r: (r / "summary.json").write_text("{}"),
            r"summary.json: has changed since mpcform wrote it \(2 bytes",
        ),
        (
            lambda r: (
                (r / "trajectory.csv").unlink(),
                (r / "trajectory.csv").mkdir(),
                (r / "trajectory.csv" / "x").touch(),
            ),
            "trajectory.csv: is a directory, but mpcform wrote a file there",
        ),
        (
            lambda r: ((r / "plots" / "top_view.png").unlink(), (r / "plots" / "top_view.png").mkdir()),
            "plots/top_view.png: is a directory, but mpcform wrote a file",
        ),
    ],
)
def test_what_mpcform_did_not_write_is_refused_and_kept(tmp_path: Path, make, says: str) -> None:
    _a_run(tmp_path)
    make(tmp_path)
    before = sorted(str(p) for p in tmp_path.rglob("*"))
    with pytest.raises(ValidationError, match=says):
        claim_dir(tmp_path, "run", NAMES)
    assert sorted(str(p) for p in tmp_path.rglob("*")) == before


def test_a_directory_of_its_own_is_new_empty_or_mpcforms(tmp_path: Path) -> None:
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "mine.txt").write_text("x")
    with pytest.raises(
        ValidationError, match=r"^--out: '.*d' is not empty \(mine.txt\) and has no \.mpcform-manifest\.json"
    ):
        claim_dir(tmp_path / "d", "run", NAMES, field="--out")
    assert sorted(p.name for p in (tmp_path / "d").iterdir()) == ["mine.txt"]  # nothing left
    (tmp_path / "e").mkdir()
    with claim_dir(tmp_path / "e", "run", NAMES):  # empty: taken
        pass


def test_a_run_directory_without_a_manifest_takes_new_names_only(tmp_path: Path) -> None:
    """An older mpcform's run (or the library's): plot, view and export add to it, replace nothing."""
    for name in ("trajectory.npz", "summary.json"):
        (tmp_path / name).write_text("old")
    with claim_dir(tmp_path, "run", ("plots",), own=False) as claim:
        claim.clear()
        (tmp_path / "plots").mkdir()
        (tmp_path / "plots" / "a.png").write_text("png")
    assert sorted(read_manifest(tmp_path, "run") or {}) == ["plots", "plots/a.png"]
    with pytest.raises(ValidationError, match="viewer.html: a file that mpcform did not write"):
        (tmp_path / "viewer.html").write_text("old viewer")
        claim_dir(tmp_path, "run", ("viewer.html",), own=False)


def test_a_second_claim_of_a_directory_is_refused_while_the_first_holds_it(tmp_path: Path) -> None:
    with claim_dir(tmp_path, "run", NAMES):
        with pytest.raises(
            ValidationError, match=r"^--out: '.*' is being written by another mpcform command \(pid \d+\)"
        ):
            claim_dir(tmp_path, "run", NAMES, field="--out")
    with claim_dir(tmp_path, "run", NAMES):  # released
        pass


def test_an_interrupted_command_removes_what_it_wrote(tmp_path: Path) -> None:
    _a_run(tmp_path / "old")
    with pytest.raises(KeyboardInterrupt), claim_dir(tmp_path / "old", "run", NAMES) as claim:
        claim.clear()
        (tmp_path / "old" / "trajectory.npz").write_text("half")
        raise KeyboardInterrupt
    assert sorted(p.name for p in (tmp_path / "old").iterdir()) == [MANIFEST, LOCK]
    assert read_manifest(tmp_path / "old", "run") == {}
    with pytest.raises(KeyboardInterrupt), claim_dir(tmp_path / "new" / "deeper", "run", NAMES) as claim:
        claim.clear()
        _write_run(tmp_path / "new" / "deeper")
        raise KeyboardInterrupt
    assert not (tmp_path / "new").exists()  # created for the command: gone with it


def test_a_failed_command_keeps_and_lists_what_it_wrote(tmp_path: Path) -> None:
    with pytest.raises(ValueError), claim_dir(tmp_path / "r", "run", NAMES) as claim:
        claim.clear()
        _write_run(tmp_path / "r", plots=False)
        raise ValueError("the export after the run failed")
    assert sorted(read_manifest(tmp_path / "r", "run") or {}) == [
        "summary.json",
        "trajectory.csv",
        "trajectory.npz",
    ]
    with pytest.raises(ValueError), claim_dir(tmp_path / "s", "run", NAMES):
        raise ValueError("failed before writing")
    assert not (tmp_path / "s").exists()


def test_a_whole_directory_of_plots(tmp_path: Path) -> None:
    with claim_dir(tmp_path / "figs", "plots") as claim:
        claim.clear()
        (tmp_path / "figs" / "top_view.png").write_text("png")
    with pytest.raises(
        ValidationError,
        match=r"holds the figures of `mpcform plot --out`; expected a directory for the outputs of a run",
    ):
        claim_dir(tmp_path / "figs", "run", NAMES)
    (tmp_path / "figs" / "notes.txt").write_text("mine")
    with pytest.raises(ValidationError, match="figs/notes.txt: a file that mpcform did not write"):
        claim_dir(tmp_path / "figs", "plots")


def test_roots_that_are_never_taken(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ValidationError, match=r"^--out: '/' is the filesystem root"):
        check_root("--out", "/")
    monkeypatch.setenv("HOME", str(tmp_path))
    with pytest.raises(ValidationError, match="is your home directory"):
        check_root("--out", tmp_path)
    for marker in ("pyproject.toml", ".git"):
        (tmp_path / marker[1:]).mkdir(exist_ok=True)
        (tmp_path / marker[1:] / marker).touch()
        with pytest.raises(ValidationError, match=rf"is a project root \(it holds {marker}\)"):
            check_root("--out", tmp_path / marker[1:])
    (tmp_path / "link").symlink_to("missing-target")
    with pytest.raises(
        ValidationError, match=r"'.*link' is a symbolic link to 'missing-target', which does not exist"
    ):
        check_root("--out", tmp_path / "link")
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValidationError, match="is an existing file; expected a directory"):
        check_root("--out", tmp_path / "f")
    check_root("--out", tmp_path / "new")
