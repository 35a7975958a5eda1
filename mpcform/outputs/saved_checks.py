"""A saved run's files checked as they are read back (``plot``, ``view``, ``export``, ``compare``).

Sizes before reading: ``summary.json`` is a regular file of at most :data:`MAX_SUMMARY_BYTES`, a
``.npz`` archive (``trajectory.npz``, ``formation.npz``) a regular file of at most
:data:`MAX_NPZ_BYTES` whose arrays, from their headers, hold real numbers of at most
:data:`MAX_NPZ_BYTES` together once decompressed (a device, a FIFO or a zip bomb is refused before
it is read). Then the arrays' shapes and values, and the summary's fields that the figures and
exports read. Every refusal is a :class:`RunDirError` naming the file and the array or field.
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib import format as npy_format

from mpcform._validate import Array, byte_size, open_regular, read_regular
from mpcform.errors import ValidationError, shown

MAX_SUMMARY_BYTES = 16 * 2**20
"""The largest ``summary.json`` read, 16 MiB (a run's summary takes a few KiB)."""
MAX_NPZ_BYTES = 4 * 2**30
"""The largest ``.npz`` archive read, and the most its arrays may hold decompressed: 4 GiB, the
default ``--max-memory`` of a whole run (every bundled run saves under 10 MiB)."""

TRAJECTORY_SHAPES = {
    "t": ("T",),
    "p": ("T", "n", "d"),
    "u": ("T-1", "n", "d"),
    "p_ref": ("T", "n", "d"),
    "t_true": ("K",),
    "p_true": ("K", "n", "d"),
    "v_true": ("K", "n", "d"),
    "p_ref_true": ("K", "n", "d"),
    "quat_true": ("K", "n", 4),
    "thrust_true": ("K", "n"),
    "scale_estimates": ("T", "n"),
}
"""The shape of each array of ``trajectory.npz`` (:mod:`mpcform.outputs.files`)."""
LIMITS = ("v_max", "d_min", "tracking", "downwash", "v_max_z")


class RunDirError(ValidationError):
    """A directory that does not hold the output files of a run (names the path)."""


@contextmanager
def load_npz(path: Path) -> Iterator[Any]:
    """``np.load`` of the archive ``path`` once its size and its arrays' headers are checked
    (module docstring); closed on exit."""
    try:
        f = open_regular(path, MAX_NPZ_BYTES, "numpy .npz archive")
    except ValidationError as exc:
        raise RunDirError(exc.field, exc.message) from None
    except FileNotFoundError:
        raise
    except OSError as exc:  # a symbolic link to itself, no permission: no raw errno
        raise RunDirError(str(path), f"cannot open it: {exc.strerror or exc}") from None
    with f:
        total = sum(_array_bytes(path, name, header) for name, header in _headers(f))
        if total > MAX_NPZ_BYTES:
            raise RunDirError(
                str(path),
                f"its arrays take {byte_size(total)} decompressed; expected at most "
                f"{byte_size(MAX_NPZ_BYTES)}",
            )
        f.seek(0)
        with np.load(f) as npz:
            yield npz


TEXT_ARRAYS = ("obstacle_records",)
"""Arrays that hold text (the obstacles' JSON records of ``formation.npz``)."""


def _headers(f: Any) -> Iterator[tuple[str, tuple[tuple[int, ...], bool, np.dtype[Any]]]]:
    with zipfile.ZipFile(f) as zf:
        for name in zf.namelist():
            with zf.open(name) as member:
                version = npy_format.read_magic(member)
                read = {(1, 0): npy_format.read_array_header_1_0, (2, 0): npy_format.read_array_header_2_0}
                if version not in read:
                    raise ValueError(f"array {name!r}: unsupported .npy format version {version}")
                yield name.removesuffix(".npy"), read[version](member)


def _array_bytes(path: Path, name: str, header: tuple[tuple[int, ...], bool, np.dtype[Any]]) -> int:
    shape, _, dtype = header
    if dtype.kind not in "biuf" and not (name in TEXT_ARRAYS and dtype.kind == "U"):
        raise RunDirError(str(path), f"array {name!r} holds {dtype}; expected real numbers")
    return math.prod(shape) * dtype.itemsize


def check_trajectory_arrays(path: Path, arrays: dict[str, Array]) -> None:
    """The arrays of ``trajectory.npz`` have the shapes of :data:`TRAJECTORY_SHAPES` (T >= 2,
    K >= 2, n >= 1, d = 2 or 3), finite values and increasing times ``t``."""
    p = arrays["p"]
    if p.ndim != 3 or p.shape[0] < 2 or p.shape[1] < 1 or p.shape[2] not in (2, 3):
        raise RunDirError(str(path), f"array 'p' has shape {p.shape}; expected (T, n, d), T >= 2, d = 2 or 3")
    t_len, n, d = p.shape
    k_len = arrays["t_true"].shape[0] if "t_true" in arrays and arrays["t_true"].ndim >= 1 else -1
    sizes = {"T": t_len, "T-1": t_len - 1, "K": k_len, "n": n, "d": d}
    for key, axes in TRAJECTORY_SHAPES.items():
        if key in arrays:
            expected = tuple(sizes[a] if isinstance(a, str) else a for a in axes)
            check_array(path, key, arrays[key], expected, "(" + ", ".join(map(str, axes)) + ")")
    if k_len != -1 and k_len < 2:
        raise RunDirError(str(path), f"array 't_true' has {k_len} samples; expected at least 2")
    if np.any(np.diff(arrays["t"]) <= 0.0):
        j = int(np.argmax(np.diff(arrays["t"]) <= 0.0))
        raise RunDirError(
            str(path), f"array 't' is not increasing at index {j + 1}; expected increasing times"
        )


def check_array(
    path: Path, key: str, value: Array, shape: tuple[int, ...], axes: str, inf: bool = False
) -> None:
    """``value`` (the array ``key`` of the file ``path``) has ``shape`` (named ``axes``) and finite
    values (``inf``: +-inf allowed, NaN never); else a :class:`RunDirError` naming both."""
    if value.shape != shape:
        raise RunDirError(str(path), f"array {key!r} has shape {value.shape}; expected {axes} = {shape}")
    bad = np.isnan(value) if inf else ~np.isfinite(value)
    if bad.any():
        at = tuple(int(i) for i in np.argwhere(bad)[0])
        finite = "numbers, no NaN" if inf else "finite numbers"
        raise RunDirError(str(path), f"array {key!r} holds {value[at]} at index {at}; expected {finite}")


def check_formation_arrays(path: Path, arrays: dict[str, Array], n: int, d: int, t_len: int) -> None:
    """The arrays of ``formation.npz`` other than the obstacles' records: ``offsets`` (n, d) and
    ``scale_ref`` (T,) finite, ``geofence`` (2, d) without NaN, ``graph_edges`` (m, 2) and
    ``leaders`` (k,) drone indices."""
    check_array(path, "offsets", arrays["offsets"], (n, d), "(n, d)")
    check_array(path, "scale_ref", arrays["scale_ref"], (t_len,), "(T,)")
    if "obstacles" in arrays:  # an older run's sphere rows
        check_obstacle_rows(path, arrays["obstacles"], d)
    if "geofence" in arrays:
        check_array(path, "geofence", arrays["geofence"], (2, d), "(2, d)", inf=True)
    for key, width in (("graph_edges", 2), ("leaders", None)):
        if key not in arrays:
            continue
        value = arrays[key]
        rows = value.shape[0] if value.ndim >= 1 else 0
        check_array(
            path,
            key,
            value,
            (rows,) if width is None else (rows, width),
            "(k,)" if width is None else "(m, 2)",
        )
        if value.size and (np.any(value != np.round(value)) or value.min() < 0 or value.max() >= n):
            raise RunDirError(
                str(path),
                f"array {key!r} holds {shown(value.tolist())}; expected drone indices in 0..{n - 1}",
            )


def check_obstacle_rows(path: Path, obstacles: Array, d: int) -> None:
    """``obstacles`` of ``formation.npz``: rows (k, d + 2) of a centre and a radius, finite, and a
    clearance, finite or NaN (unset, as older runs saved it); the format itself is rundata's."""
    width = d + 2
    if obstacles.ndim > 2 or obstacles.size % width or (obstacles.ndim == 2 and obstacles.shape[1] != width):
        raise RunDirError(
            str(path), f"array 'obstacles' has shape {obstacles.shape}; expected (k, d + 2) = (k, {width})"
        )
    rows = obstacles.reshape(-1, width)
    check_array(path, "obstacles", rows[:, : d + 1], rows[:, : d + 1].shape, "(k, d + 1) centres, radii")
    if np.any(rows[:, d] <= 0.0):
        k = int(np.argmax(rows[:, d] <= 0.0))
        raise RunDirError(
            str(path), f"array 'obstacles' holds the radius {rows[k, d]} in row {k}; expected a radius > 0"
        )
    clearance = rows[:, d + 1]
    if np.any(bad := np.isinf(clearance) | (clearance < 0.0)):
        k = int(np.argmax(bad))
        raise RunDirError(
            str(path),
            f"array 'obstacles' holds the clearance {clearance[k]} in row {k}; expected a finite "
            "number >= 0, or NaN (unset)",
        )


def read_summary(path: Path) -> dict[str, Any]:
    """``summary.json``: a regular file of at most :data:`MAX_SUMMARY_BYTES` holding a JSON object
    whose ``limits`` are finite numbers >= 0 or null and whose ``metrics``, ``plant`` and ``provenance`` are
    objects (or absent)."""
    try:
        summary = json.loads(read_regular(path, MAX_SUMMARY_BYTES, "summary.json").decode("utf-8"))
    except FileNotFoundError:
        raise RunDirError(str(path), "missing (write it with `mpcform run --out DIR`)") from None
    except ValidationError as exc:
        raise RunDirError(exc.field, exc.message) from None
    except OSError as exc:  # a symbolic link to itself, no permission: no raw errno
        raise RunDirError(str(path), f"cannot open it: {exc.strerror or exc}") from None
    except ValueError as exc:  # UnicodeDecodeError and JSONDecodeError are ValueErrors
        raise RunDirError(str(path), f"cannot read it as JSON: {exc}") from None
    if not isinstance(summary, dict):
        raise RunDirError(str(path), f"expected a JSON object, got {shown(summary)}")
    for key in ("limits", "metrics", "plant", "provenance"):
        if not isinstance(summary.get(key) or {}, dict):
            raise RunDirError(str(path), f"{key}: expected an object, got {shown(summary[key])}")
    for key in LIMITS:
        value = (summary.get("limits") or {}).get(key)
        if value is not None and not (_numbers([value]) and value >= 0.0):  # json reads NaN, Infinity
            raise RunDirError(
                str(path), f"limits.{key}: expected a finite number >= 0 or null, got {shown(value)}"
            )
    wind = (summary.get("plant") or {}).get("wind")
    if wind and not (
        isinstance(wind, dict)
        and _numbers(wind.get("mean_mps"))
        and _numbers([wind.get("gust_std_mps") or 0.0])
    ):
        raise RunDirError(
            str(path),
            f"plant.wind: expected an object of finite numbers mean_mps and gust_std_mps, got {shown(wind)}",
        )
    return summary


def _numbers(value: Any) -> bool:
    return isinstance(value, list) and all(
        isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x) for x in value
    )
