"""The manifest of a directory mpcform writes into: every file and directory it wrote there.

:data:`MANIFEST` is a JSON object, one entry a line in sorted order::

    {"mpcform_manifest": 1, "kind": "run",
     "entries": {"plots": {"type": "dir"}, "plots/top_view.png": {"type": "file", "bytes": 80312},
                 "summary.json": {"type": "file", "bytes": 2113}}}

``kind`` is ``run`` (a run's directory: the names of :data:`RUN_LAYOUT`, and files directly in its
``plots/`` and ``export/``), ``plots`` or ``export`` (the ``--out`` of ``plot`` or ``export``: files
directly in it); every entry is a path relative to the directory, ``/``-separated, with its type
and, for a file, its size in bytes as written. A manifest is read (:func:`read_manifest`) only as a
regular file of at most :data:`MAX_MANIFEST_BYTES` listing at most :data:`MAX_ENTRIES` entries,
each one a name mpcform writes with the type it writes there; anything else is refused.
:mod:`mpcform.outputs.outdir` decides what a command may replace by it.
"""

from __future__ import annotations

import json
import os
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpcform._validate import file_kind, read_regular
from mpcform.errors import ValidationError, shown
from mpcform.outputs.files import SUMMARY_JSON, TRAJECTORY_CSV, TRAJECTORY_NPZ
from mpcform.outputs.rundata import FORMATION_NPZ

MANIFEST = ".mpcform-manifest.json"
MANIFEST_TMP = MANIFEST + ".tmp"
LOCK = ".mpcform.lock"
OWN_FILES = (MANIFEST, MANIFEST_TMP, LOCK)
"""mpcform's own bookkeeping in a directory it writes (an otherwise empty directory is empty)."""
FORMAT = 1
MAX_MANIFEST_BYTES = 16 * 2**20
"""The largest manifest read, 16 MiB (an entry takes about 60 bytes)."""
MAX_ENTRIES = 100_000
"""The most entries a manifest may list (an export of 1000 drones lists about 4000)."""
PLOTS_DIR, EXPORT_DIR, VIEWER_FILE = "plots", "export", "viewer.html"
RUN_LAYOUT = {
    TRAJECTORY_NPZ: "file",
    TRAJECTORY_CSV: "file",
    SUMMARY_JSON: "file",
    FORMATION_NPZ: "file",
    VIEWER_FILE: "file",
    PLOTS_DIR: "dir",
    EXPORT_DIR: "dir",
}
"""What a run's directory may hold of mpcform's, and its type (``plots/`` and ``export/``: files)."""
KINDS = {
    "run": "the outputs of a run",
    "plots": "the figures of `mpcform plot --out`",
    "export": "the files of `mpcform export --out`",
}


@dataclass(frozen=True)
class Entry:
    """One thing mpcform wrote: a ``file`` of ``bytes`` or a ``dir``."""

    type: str
    bytes: int | None = None

    def __post_init__(self) -> None:
        if self.type not in ("file", "dir"):
            raise ValidationError("type", f"expected 'file' or 'dir', got {shown(self.type)}")
        sized = isinstance(self.bytes, int) and not isinstance(self.bytes, bool) and self.bytes >= 0
        if (self.type == "file") != sized or (self.type == "dir" and self.bytes is not None):
            raise ValidationError("bytes", f"expected a size >= 0 for a file only, got {shown(self.bytes)}")

    def record(self) -> dict[str, Any]:
        return {"type": self.type} | ({} if self.bytes is None else {"bytes": self.bytes})


def allowed(kind: str, rel: str) -> str | None:
    """The type mpcform writes at ``rel`` in a directory of ``kind`` (None: it writes nothing there)."""
    parts = rel.split("/")
    if not all(p and p not in (".", "..") and "\0" not in p and len(p) <= 255 for p in parts):
        return None
    if kind != "run":
        return "file" if len(parts) == 1 and parts[0] not in OWN_FILES else None
    if len(parts) == 1:
        return RUN_LAYOUT.get(parts[0])
    return "file" if len(parts) == 2 and RUN_LAYOUT.get(parts[0]) == "dir" else None


def read_manifest(root: Path, kind: str, field: str | None = None) -> dict[str, Entry] | None:
    """The manifest's entries (None: no manifest), every one checked against the layout of ``kind``
    (a manifest of another kind: an error naming ``field``, default the directory)."""
    path = root / MANIFEST
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return None
    bad = f"expected the manifest mpcform writes (a JSON object, format {FORMAT}): remove the directory's "
    bad += "outputs yourself, or choose another --out"
    if not stat.S_ISREG(info.st_mode):
        raise ValidationError(str(path), f"is {file_kind(info.st_mode)}; {bad}")
    try:
        doc = json.loads(read_regular(path, MAX_MANIFEST_BYTES, "manifest of mpcform").decode("utf-8"))
    except ValidationError:
        raise
    except ValueError as exc:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise ValidationError(str(path), f"cannot read it as JSON ({exc}); {bad}") from None
    if not isinstance(doc, dict) or doc.get("mpcform_manifest") != FORMAT or doc.get("kind") not in KINDS:
        raise ValidationError(str(path), f"holds {shown(doc)}; {bad}")
    if doc["kind"] != kind:
        raise ValidationError(
            field or str(root),
            f"{str(root)!r} holds {KINDS[doc['kind']]}; expected a directory for {KINDS[kind]}",
        )
    entries = doc.get("entries")
    if not isinstance(entries, dict) or len(entries) > MAX_ENTRIES:
        raise ValidationError(str(path), f"entries: expected an object of at most {MAX_ENTRIES:,}; {bad}")
    checked = {}
    for rel, record in entries.items():
        try:
            entry = Entry(**record) if isinstance(record, dict) and set(record) <= {"type", "bytes"} else None
        except (TypeError, ValidationError):
            entry = None
        if entry is None or allowed(kind, rel) != entry.type:
            raise ValidationError(
                str(path), f"entry {shown(rel)}: {shown(record)} is not what mpcform writes; {bad}"
            )
        checked[rel] = entry
    return checked


def write_manifest(root: Path, kind: str, entries: dict[str, Entry]) -> None:
    """Replace ``root``'s manifest at once (written beside it, then renamed over it)."""
    head = json.dumps({"mpcform_manifest": FORMAT, "kind": kind})[:-1]
    rows = ",\n".join(f" {json.dumps(rel)}: {json.dumps(entries[rel].record())}" for rel in sorted(entries))
    text = f'{head}, "entries": {{\n{rows}\n}}}}\n' if rows else f'{head}, "entries": {{}}}}\n'
    tmp = root / MANIFEST_TMP
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
    with os.fdopen(fd, "w") as f:
        f.write(text)
    os.replace(tmp, root / MANIFEST)


def file_type(mode: int) -> str:
    return "file" if stat.S_ISREG(mode) else "dir" if stat.S_ISDIR(mode) else "other"
