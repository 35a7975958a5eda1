"""Output directories that cannot destroy data: a manifest of what mpcform wrote, and a lock.

Every directory a command writes into (``run --out DIR``; ``plot``, ``view`` and ``export`` into a
run's directory or into their own ``--out``) carries :data:`MANIFEST`, a JSON object::

    {"mpcform_manifest": 1, "kind": "run",
     "entries": {"summary.json": {"type": "file", "bytes": 2113}, "plots": {"type": "dir"},
                 "plots/top_view.png": {"type": "file", "bytes": 80312}}}

``kind`` is ``run`` (a run's directory: the names of :data:`RUN_LAYOUT`, and files in ``plots/``
and ``export/``), ``plots`` or ``export`` (the ``--out`` of ``plot`` or ``export``: files only).
A command claims the names it writes (:func:`claim_dir`) before any work: each one that exists
must be in the manifest with its type (and a file with the size mpcform wrote), else the command is
refused naming the path (a user's directory named ``trajectory.npz``, ``plots/mine.png``, a
hand-made ``summary.json``, a file edited since). Just before writing, it removes exactly the
manifest's entries under those names (:meth:`DirClaim.clear`); on exit it lists what it wrote or,
interrupted (Ctrl-C, SIGTERM, SIGHUP), removes that again. A directory of the command's own
(``own``: ``--out``) is missing, empty or carries a manifest of its kind, and is never the
filesystem root, the home directory or a project root (:func:`check_root`). :data:`LOCK`, held
with ``flock`` while the command runs, refuses a second command writing into the same directory.
A run directory without a manifest (an older mpcform's, or written by the library) is read, and
``plot``, ``view`` and ``export`` add their names to it when absent; nothing in it is replaced.
"""

from __future__ import annotations

import fcntl
import os
import signal
import stat
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

from mpcform._validate import file_kind
from mpcform.errors import ValidationError
from mpcform.outputs.manifest import (
    EXPORT_DIR,
    LOCK,
    MANIFEST,
    MAX_ENTRIES,
    OWN_FILES,
    PLOTS_DIR,
    RUN_LAYOUT,
    VIEWER_FILE,
    Entry,
    allowed,
    file_type,
    read_manifest,
    write_manifest,
)

__all__ = ["EXPORT_DIR", "PLOTS_DIR", "RUN_LAYOUT", "VIEWER_FILE", "DirClaim", "check_root", "claim_dir"]
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
ADVICE = "move it away, or write elsewhere (--out)"


def check_root(field: str, path: str | Path) -> None:
    """Refuse (:class:`ValidationError` ``field``) a directory for outputs that is a dangling
    symbolic link, something other than a directory, the filesystem root, the home directory or a
    project root (a directory holding ``pyproject.toml`` or ``.git``)."""
    path = Path(path)
    if path.is_symlink() and not path.exists():
        raise ValidationError(
            field,
            f"{str(path)!r} is a symbolic link to {os.readlink(path)!r}, which does not exist; "
            "expected a directory, or a path where none exists yet (created)",
        )
    if path.exists() and not path.is_dir():
        raise ValidationError(
            field, f"{str(path)!r} is an existing file; expected a directory (created when missing)"
        )
    if not path.exists():
        return
    real = path.resolve()
    try:
        home = Path.home().resolve()
    except (RuntimeError, KeyError):  # no HOME and no password entry
        home = None
    marker = next((m for m in ("pyproject.toml", ".git") if os.path.lexists(real / m)), None)
    what = (
        "the filesystem root"
        if real == Path(real.anchor)
        else "your home directory"
        if real == home
        else f"a project root (it holds {marker})"
        if marker
        else None
    )
    if what is not None:
        raise ValidationError(
            field, f"{str(path)!r} is {what}; expected a directory of its own for mpcform's outputs"
        )


def claim_dir(
    root: str | Path,
    kind: str,
    names: tuple[str, ...] | None = None,
    *,
    own: bool = True,
    field: str | None = None,
) -> DirClaim:
    """Claim ``names`` of the directory ``root`` (None: all of it) for a command writing outputs of
    ``kind`` (:data:`KINDS`), before its work: the root checked (:func:`check_root`; created when
    missing), locked, its manifest read, and everything under ``names`` found in it. ``own``: the
    command's own directory, which must be missing, empty or hold a manifest. Errors about the root
    name ``field`` (default: the path), errors about what is in it the path of that."""
    root, field = Path(root), field or str(root)
    check_root(field, root)
    created = create_dirs(field, root)
    try:
        fresh_lock = not os.path.lexists(root / LOCK)
        fd = _lock(field, root)
        try:
            entries = read_manifest(root, kind, field)
            if entries is None and own and (others := _others(root)):
                raise ValidationError(
                    field,
                    f"{str(root)!r} is not empty ({', '.join(others[:3])}{', ...' * (len(others) > 3)}) "
                    f"and has no {MANIFEST}: files of yours, or a run of an older mpcform; expected a new "
                    "or empty directory, or one mpcform wrote: choose another --out",
                )
            claim = DirClaim(root, kind, names, entries or {}, fd, created, entries is not None)
            claim.verify()
            return claim
        except BaseException:
            if fresh_lock:  # refused: nothing of mpcform's is left in a directory it did not use
                (root / LOCK).unlink(missing_ok=True)
            os.close(fd)
            raise
    except BaseException:
        if created is not None:
            _remove_created(root, created)
        raise


class DirClaim:
    """A directory claimed by :func:`claim_dir`: a context manager that, on exit, lists what was
    written under its names in the manifest (or removes it, interrupted) and releases the lock."""

    def __init__(
        self,
        root: Path,
        kind: str,
        names: tuple[str, ...] | None,
        entries: dict[str, Entry],
        fd: int,
        created: Path | None,
        listed: bool,
    ) -> None:
        self.root, self.kind, self.names, self.entries = root, kind, names, entries
        self._fd, self._created, self._listed, self.cleared = fd, created, listed, False

    def __enter__(self) -> DirClaim:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(interrupted=exc_type is not None and issubclass(exc_type, KeyboardInterrupt))

    def verify(self) -> None:
        """Everything under the claimed names is in the manifest, with its type and size."""
        for rel, info in self._present():
            entry, path, found = self.entries.get(rel), self.root / rel, file_kind(info.st_mode)
            if entry is None:
                where = str(self.root / MANIFEST) if self._listed else f"a manifest: {self.root} has none"
                raise ValidationError(
                    str(path),
                    f"{found} that mpcform did not write (not in {where}); expected only mpcform's own "
                    f"outputs where it writes: {ADVICE}",
                )
            if entry.type != file_type(info.st_mode):
                raise ValidationError(
                    str(path), f"is {found}, but mpcform wrote a {entry.type} there; expected that: {ADVICE}"
                )
            if entry.bytes is not None and entry.bytes != info.st_size:
                raise ValidationError(
                    str(path),
                    f"has changed since mpcform wrote it ({info.st_size:,} bytes, not {entry.bytes:,}); "
                    f"expected mpcform's own file, which it replaces: {ADVICE}",
                )

    def clear(self) -> list[str]:
        """Remove the manifest's entries under the claimed names, checked again first (call it just
        before writing); the names removed at the top. The manifest lists them no more before they
        go: a crash leaves a file refused, never a user's file taken for one of mpcform's."""
        with _signals_held():
            self.verify()
            doomed = sorted((r for r in self.entries if self._claims(r)), key=lambda r: -r.count("/"))
            self.entries = {r: e for r, e in self.entries.items() if not self._claims(r)}
            self._write()
            removed = []
            for rel in doomed:
                path = self.root / rel
                if not os.path.lexists(path):
                    continue
                if stat.S_ISDIR(os.lstat(path).st_mode):
                    path.rmdir()
                else:
                    path.unlink()
                if "/" not in rel:
                    removed.append(rel)
            self.cleared = True
        return [n for n in RUN_LAYOUT if n in removed] + sorted(set(removed) - set(RUN_LAYOUT))

    def close(self, interrupted: bool = False) -> None:
        """List what was written under the claimed names (``interrupted``: remove it), release the
        lock, and remove the directory if it was created for nothing."""
        with _signals_held():
            try:
                if self.cleared and interrupted:
                    self._discard()
                elif self.cleared:
                    self._record()
            finally:
                if self._created is not None and not _others(self.root):
                    _remove_created(self.root, self._created)
                os.close(self._fd)

    def _claims(self, rel: str) -> bool:
        return self.names is None or rel.split("/", 1)[0] in self.names

    def _present(self) -> Iterator[tuple[str, os.stat_result]]:
        """What exists under the claimed names, parents before children (nothing followed)."""
        tops = self.names if self.names is not None else _others(self.root)
        for name in tops:
            yield from _walk(self.root, name)

    def _record(self) -> None:
        for rel, info in self._present():
            kind = file_type(info.st_mode)
            if (
                rel not in self.entries
                and allowed(self.kind, rel) == kind
                and len(self.entries) < MAX_ENTRIES
            ):
                self.entries[rel] = Entry(kind, info.st_size if kind == "file" else None)
        self._write()

    def _discard(self) -> None:
        new = [(rel, info) for rel, info in self._present() if rel not in self.entries]
        for rel, info in reversed(new):  # children first
            path = self.root / rel
            if stat.S_ISREG(info.st_mode):
                path.unlink(missing_ok=True)
            elif stat.S_ISDIR(info.st_mode) and not any(path.iterdir()):
                path.rmdir()
        self._write()

    def _write(self) -> None:
        write_manifest(self.root, self.kind, self.entries)
        self._listed = True


def _lock(field: str, root: Path) -> int:
    """The descriptor of ``root``'s lock file, held (``flock``, exclusive, not waiting)."""
    path = root / LOCK
    for _ in range(3):
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
        except OSError as exc:
            if not os.path.lexists(path):
                raise ValidationError(field, f"cannot write into {str(root)!r}: {exc.strerror}") from None
            raise ValidationError(
                str(path), f"cannot open it ({exc.strerror}); expected mpcform's lock file, or none"
            ) from None
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise ValidationError(
                    str(path), "is not a regular file; expected mpcform's lock file, or none"
                )
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                pid = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
                raise ValidationError(
                    field,
                    f"{str(root)!r} is being written by another mpcform command"
                    f"{f' (pid {pid})' if pid.isdigit() else ''}; expected one command at a time per "
                    "directory: wait for it, or choose another --out",
                ) from None
            if _same_file(fd, path):  # not a lock file removed meanwhile with its directory
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
                return fd
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)
    raise ValidationError(
        field, f"{str(root)!r}: its lock file keeps changing; expected one command at a time"
    )


def _same_file(fd: int, path: Path) -> bool:
    try:
        a, b = os.fstat(fd), os.lstat(path)
    except FileNotFoundError:
        return False
    return (a.st_dev, a.st_ino) == (b.st_dev, b.st_ino)


def create_dirs(field: str, root: Path) -> Path | None:
    """Create the missing ``root`` with its parents; the first directory created (None: none)."""
    if root.exists():
        return None
    first = root
    while not first.parent.exists():
        first = first.parent
    try:
        root.mkdir(parents=True)
    except OSError as exc:
        raise ValidationError(field, f"cannot create {str(root)!r}: {exc.strerror or exc}") from None
    return first


def _remove_created(root: Path, first: Path) -> None:
    """Remove mpcform's own files from ``root``, then ``root`` and its parents up to ``first``."""
    for name in OWN_FILES:
        (root / name).unlink(missing_ok=True)
    path = root
    while True:
        try:
            path.rmdir()
        except OSError:
            return
        if path == first:
            return
        path = path.parent


def _others(root: Path) -> list[str]:
    """What ``root`` holds besides mpcform's own bookkeeping, sorted."""
    return sorted(name for name in os.listdir(root) if name not in OWN_FILES)


def _walk(root: Path, rel: str) -> Iterator[tuple[str, os.stat_result]]:
    try:
        info = os.lstat(root / rel)
    except FileNotFoundError:
        return
    yield rel, info
    if stat.S_ISDIR(info.st_mode):
        for name in sorted(os.listdir(root / rel)):
            yield from _walk(root, f"{rel}/{name}")


@contextmanager
def _signals_held() -> Iterator[None]:
    """Ctrl-C, SIGTERM and SIGHUP held back until the block ends (the manifest is kept whole)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)
