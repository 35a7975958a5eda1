"""Output paths of the commands, checked before any work: a long run must not fail at its end
because ``--out`` names a file or ``--json`` a missing directory.

Every command's output options are checked by their argparse destination: ``out`` (a directory,
created with its parents when missing; never the filesystem root, the home directory or a project
root) and ``json``, ``report``, ``figure``, ``out_file``, ``profile`` (files, written into an existing
directory). What a command may replace in a directory it writes is decided by the directory's
manifest, when the command claims it (:mod:`mpcform.outputs.outdir`).
"""

from __future__ import annotations

import argparse
import os
import shutil
from pathlib import Path

from mpcform.errors import ValidationError, shown
from mpcform.outputs.outdir import check_root, create_dirs

DIRECTORY_OPTIONS = ("out",)
FILE_OPTIONS = ("json", "report", "figure", "out_file", "profile")
FLAGS = {"out_file": "--out"}
"""Destinations whose flag is not ``--`` + the destination (``view --out HTML`` is a file)."""


def check_output_paths(args: argparse.Namespace) -> None:
    """Raise :class:`ValidationError` naming the option when one of ``args``' output paths is empty
    (``--out ''`` would write into the current directory), cannot be written (``--figure`` only
    when a figure is drawn) or is a file another option writes too (``--json`` and ``--profile``
    naming one file: the second would overwrite the first)."""
    for dest in (*DIRECTORY_OPTIONS, *FILE_OPTIONS):
        if isinstance(value := getattr(args, dest, None), str) and not value.strip():
            raise ValidationError(_flag(dest), f"expected a path, got {shown(value)}")
    for dest in DIRECTORY_OPTIONS:
        value = getattr(args, dest, None)
        if value is not None:
            check_output_dir(_flag(dest), value)
    written: dict[Path, str] = {}  # each file written, by the option that names it
    for dest in FILE_OPTIONS:
        value = getattr(args, dest, None)
        if value is not None and not (dest == "figure" and getattr(args, "no_figure", False)):
            check_output_file(_flag(dest), value)
            if (same := written.setdefault(Path(value).resolve(), _flag(dest))) != _flag(dest):
                raise ValidationError(
                    _flag(dest), f"{str(value)!r} is the file {same} writes; expected another path"
                )


def check_output_dir(flag: str, path: str | Path) -> None:
    """``path`` is a directory, or can be created: not a file nor a dangling symbolic link, not
    ``/``, the home directory or a project root, its nearest existing ancestor a writable
    directory."""
    path = Path(path)
    check_root(flag, path)  # a file, a dangling symbolic link, /, the home directory, a project root
    _writable_ancestor(flag, path)
    if not path.exists():
        _try_create(flag, path)


def check_output_file(flag: str, path: str | Path) -> None:
    """``path`` can be written as a file: not a directory, in an existing writable directory."""
    path = Path(path)
    if path.is_dir():
        raise ValidationError(flag, f"{str(path)!r} is a directory; expected a file path")
    parent = path.parent
    if not parent.is_dir():
        what = "is not a directory" if parent.exists() else "does not exist"
        raise ValidationError(flag, f"cannot write {str(path)!r}: the directory {str(parent)!r} {what}")
    if path.exists() and not os.access(path, os.W_OK):
        raise ValidationError(flag, f"cannot write {str(path)!r}: permission denied")
    if not path.exists() and not os.access(parent, os.W_OK | os.X_OK):
        raise ValidationError(flag, f"cannot write {str(path)!r}: {str(parent)!r} is not writable")


def _writable_ancestor(flag: str, path: Path) -> None:
    ancestor = path
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise ValidationError(flag, f"cannot create {str(path)!r}: {str(ancestor)!r} is a file")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ValidationError(flag, f"cannot write into {str(path)!r}: {str(ancestor)!r} is not writable")


def _try_create(flag: str, path: Path) -> None:
    """Create the missing ``path`` and remove what was created: a writable-looking ancestor may still
    refuse it (``/proc``, a read-only mount), and nothing is left on disk before the work starts."""
    first = create_dirs(flag, path)
    if first is not None:
        shutil.rmtree(first)


def _flag(dest: str) -> str:
    return FLAGS.get(dest, "--" + dest.replace("_", "-"))
