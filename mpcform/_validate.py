"""Input checks shared by the dataclasses: each names the field and what was expected."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from mpcform.errors import ValidationError, shown

Array = NDArray[Any]  # float arrays mostly; index arrays share the alias


def finite_array(field: str, value: Any, shape: tuple[int | None, ...]) -> Array:
    """Return ``value`` as a float array of ``shape`` (None = any length), finite everywhere. Real
    numbers only: complex values (their imaginary part would be dropped) and strings (``"1"`` would
    be parsed) are refused."""
    kind = value.dtype.kind if isinstance(value, np.ndarray) else _kind(value)
    if kind in "cUSV":
        real = "real numbers" if kind == "c" else "numbers"
        raise ValidationError(field, f"expected {real} of shape {_shape(shape)}, got {shown(value)}")
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValidationError(
            field, f"expected numbers of shape {_shape(shape)}, got {shown(value)}"
        ) from exc
    if arr.ndim != len(shape) or any(
        s is not None and s != a for s, a in zip(shape, arr.shape, strict=False)
    ):
        raise ValidationError(field, f"expected shape {_shape(shape)}, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValidationError(field, f"expected finite numbers, got {shown(arr.tolist())}")
    return arr


def positive(field: str, value: Any, *, allow_zero: bool = False) -> float:
    """Return ``value`` as a finite float > 0 (>= 0 with ``allow_zero``)."""
    try:
        x = float(value)
    except (TypeError, ValueError) as exc:
        raise ValidationError(field, f"expected a number, got {shown(value)}") from exc
    ok = np.isfinite(x) and (x >= 0 if allow_zero else x > 0)
    if not ok:
        raise ValidationError(
            field, f"expected a finite number {'>= 0' if allow_zero else '> 0'}, got {shown(value)}"
        )
    return x


def dimension(field: str, value: Any) -> int:
    if value not in (2, 3) or isinstance(value, bool):
        raise ValidationError(field, f"expected 2 (planar) or 3 (spatial), got {shown(value)}")
    return int(value)


def _shape(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"


def _kind(value: Any) -> str:
    """The numpy dtype kind of ``value`` ("O" when it has none: ragged or mixed)."""
    try:
        return str(np.asarray(value).dtype.kind)
    except (TypeError, ValueError):
        return "O"


def byte_size(n: int) -> str:
    """``n`` bytes for a message: ``16 MiB``, ``1.5 GiB``, ``812 bytes``."""
    for unit, size in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


def open_regular(path: str | Path, max_bytes: int, what: str) -> BinaryIO:
    """Open ``path`` for reading once ``fstat`` shows a regular file of at most ``max_bytes``:
    before a byte is read, a device (``/dev/zero``, ``/dev/urandom``), a FIFO (opened without
    waiting for a writer), a directory or a larger file (a sparse one included) is refused with a
    :class:`ValidationError` naming the path and the cap (``what`` names the kind of file). An
    ``OSError`` (missing, no permission) passes through."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        info = os.fstat(fd)
        expected = f"expected a {what} (a regular file of at most {byte_size(max_bytes)})"
        if not stat.S_ISREG(info.st_mode):
            raise ValidationError(str(path), f"is {file_kind(info.st_mode)}, not a regular file; {expected}")
        if info.st_size > max_bytes:
            raise ValidationError(
                str(path), f"is {byte_size(info.st_size)} ({info.st_size:,} bytes); {expected}"
            )
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | Path, max_bytes: int, what: str) -> bytes:
    """The bytes of ``path``, checked as by :func:`open_regular` (and refused when the file grew
    beyond ``max_bytes`` while it was read)."""
    with open_regular(path, max_bytes, what) as f:
        data = f.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise ValidationError(
            str(path), f"grew beyond {byte_size(max_bytes)} while read; expected a {what} of at most that"
        )
    return data


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, in words (``a directory``, ``a FIFO (named pipe)``)."""
    kinds = (
        (stat.S_ISREG, "a file"),
        (stat.S_ISDIR, "a directory"),
        (stat.S_ISLNK, "a symbolic link"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISSOCK, "a socket"),
    )
    return next((name for test, name in kinds if test(mode)), "a special file")
