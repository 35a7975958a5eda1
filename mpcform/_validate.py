"""Input checks shared by the dataclasses: each names the field and what was expected."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from mpcform.errors import ValidationError, shown

Array = NDArray[Any]  # float arrays mostly; index arrays share the alias


def finite_array(field: str, value: Any, shape: tuple[int | None, ...]) -> Array:
    """Return ``value`` as a float array of ``shape`` (None = any length), finite everywhere."""
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
        raise ValidationError(field, f"expected finite numbers, got {arr.tolist()}")
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
