"""Output paths checked before any work: a directory option must not name a file, a file option
must name a file in an existing directory."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from mpcform.cli.paths import check_output_dir, check_output_file, check_output_paths
from mpcform.errors import ValidationError


def test_a_directory_may_exist_or_be_created(tmp_path: Path) -> None:
    check_output_dir("--out", tmp_path)
    check_output_dir("--out", tmp_path / "new" / "deeper")


def test_a_directory_option_is_never_the_root_the_home_or_a_dangling_link(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """What a command may replace in it is its manifest's business (mpcform.outputs.outdir)."""
    with pytest.raises(ValidationError, match=r"^--out: '/' is the filesystem root"):
        check_output_dir("--out", "/")
    monkeypatch.setenv("HOME", str(tmp_path))
    with pytest.raises(ValidationError, match=r"^--out: '.*' is your home directory"):
        check_output_dir("--out", tmp_path)
    (tmp_path / "o").symlink_to(tmp_path / "gone")
    with pytest.raises(
        ValidationError, match=r"^--out: '.*o' is a symbolic link to '.*gone', which does not"
    ):
        check_output_dir("--out", tmp_path / "o")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]


def test_a_directory_option_naming_a_file(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    with pytest.raises(ValidationError, match=r"^--out: '.*f' is an existing file; expected a directory"):
        check_output_dir("--out", tmp_path / "f")
    with pytest.raises(ValidationError, match=r"^--out: cannot create '.*f/sub': '.*f' is a file"):
        check_output_dir("--out", tmp_path / "f" / "sub")


def test_a_file_option(tmp_path: Path) -> None:
    check_output_file("--json", tmp_path / "rows.json")
    (tmp_path / "old.json").write_text("[]")
    check_output_file("--json", tmp_path / "old.json")  # overwritten
    with pytest.raises(ValidationError, match=r"^--json: '.*' is a directory; expected a file path"):
        check_output_file("--json", tmp_path)
    with pytest.raises(ValidationError, match=r"^--report: cannot write .*: the directory .* does not exist"):
        check_output_file("--report", tmp_path / "missing" / "r.md")
    with pytest.raises(ValidationError, match="is not a directory"):
        check_output_file("--json", tmp_path / "old.json" / "rows.json")


def test_every_output_option_of_a_namespace_is_checked(tmp_path: Path) -> None:
    (tmp_path / "f").write_text("x")
    check_output_paths(argparse.Namespace(out=None, json=None, scenario="whatever"))
    for dest, flag in (("out", "--out"), ("json", "--json"), ("report", "--report"), ("figure", "--figure")):
        bad = tmp_path / "f" if dest == "out" else tmp_path
        with pytest.raises(ValidationError, match=f"^{flag}: "):
            check_output_paths(argparse.Namespace(**{dest: str(bad)}))
    check_output_paths(argparse.Namespace(figure=str(tmp_path), no_figure=True))  # no figure drawn
    with pytest.raises(ValidationError, match="^--out: .* is a directory; expected a file path"):
        check_output_paths(argparse.Namespace(out_file=str(tmp_path)))  # view --out HTML: a file
    check_output_paths(argparse.Namespace(out_file=str(tmp_path / "f")))


def test_two_file_options_never_name_one_file(tmp_path: Path) -> None:
    same = tmp_path / "bench.json"
    with pytest.raises(ValidationError, match="^--profile: .*bench.json' is the file --json writes"):
        check_output_paths(argparse.Namespace(json=str(same), profile=str(tmp_path / "." / "bench.json")))
    check_output_paths(argparse.Namespace(json=str(same), profile=str(tmp_path / "profile.txt")))


def test_a_directory_the_system_refuses_is_named_and_nothing_is_left(tmp_path: Path) -> None:
    """``/proc`` looks writable to root but refuses a new directory: the error names the option."""
    with pytest.raises(ValidationError, match=r"--out: cannot (create|write into) '/proc/nope'"):
        check_output_dir("--out", "/proc/nope")
    check_output_dir("--out", tmp_path / "a" / "b" / "c")  # creatable: checked, then removed
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("dest", ["out", "json", "report", "figure"])
@pytest.mark.parametrize("value", ["", " "])
def test_an_empty_path_is_refused_not_taken_for_the_current_directory(dest: str, value: str) -> None:
    with pytest.raises(ValidationError, match=f"^--{dest}: expected a path, got '{value}'$"):
        check_output_paths(argparse.Namespace(**{dest: value}))
