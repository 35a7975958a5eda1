"""The shared input checks (``mpcform._validate``): what each accepts and returns, what it refuses,
and that every refusal is a ValidationError naming the field and what was expected."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mpcform._validate import dimension, finite_array, positive
from mpcform.errors import MPCFormError, ValidationError

# ---- finite_array ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "shape"),
    [
        ([1, 2, 3], (3,)),
        ([[0, 1], [2, 3], [4, 5]], (None, 2)),
        (np.zeros((0, 3)), (None, 3)),
        (np.arange(6, dtype=np.int64).reshape(2, 3), (2, None)),
        (2.5, ()),
    ],
)
def test_finite_array_accepts_numbers_of_the_shape(value: Any, shape: tuple[int | None, ...]) -> None:
    arr = finite_array("offsets", value, shape)
    assert arr.dtype == np.float64 and arr.ndim == len(shape)
    assert all(s is None or s == a for s, a in zip(shape, arr.shape, strict=True))
    np.testing.assert_array_equal(arr, np.asarray(value, dtype=float))


def test_finite_array_returns_its_own_array() -> None:
    source = np.array([1.0, 2.0])
    arr = finite_array("x", source, (2,))
    source[0] = 9.0
    assert arr[0] == 1.0


@pytest.mark.parametrize(
    ("value", "shape", "expected"),
    [
        ([1, 2], (3,), "expected shape (3), got shape (2,)"),
        ([[1, 2, 3]], (None, 2), "expected shape (n, 2), got shape (1, 3)"),
        ([1, 2], (None, 2), "expected shape (n, 2), got shape (2,)"),
        ([[1.0, 2.0]], (2,), "expected shape (2), got shape (1, 2)"),
        ([1.0, float("nan")], (2,), "expected finite numbers, got [1.0, nan]"),
        ([float("inf"), 0.0], (None,), "expected finite numbers"),
        (["a", "b"], (2,), "expected numbers of shape (2), got ['a', 'b']"),
        ([[1, 2], [3]], (None, 2), "expected numbers of shape (n, 2)"),
        (None, (2,), "expected shape (2), got shape ()"),
    ],
)
def test_finite_array_refuses_and_names_the_field(
    value: Any, shape: tuple[int | None, ...], expected: str
) -> None:
    with pytest.raises(ValidationError) as info:
        finite_array("start.positions", value, shape)
    assert info.value.field == "start.positions"
    assert str(info.value).startswith("start.positions: ")
    assert expected in str(info.value)


# ---- positive -------------------------------------------------------------------------------


@pytest.mark.parametrize(("value", "expected"), [(1, 1.0), (0.25, 0.25), ("2.5", 2.5), (np.float32(3), 3.0)])
def test_positive_returns_a_float(value: Any, expected: float) -> None:
    out = positive("dt", value)
    assert type(out) is float and out == expected


@pytest.mark.parametrize("value", [0, 0.0, -1e-12, -3, float("nan"), float("inf"), -float("inf")])
def test_positive_refuses_zero_negative_and_non_finite(value: float) -> None:
    with pytest.raises(ValidationError, match=r"^dt: expected a finite number > 0, got ") as info:
        positive("dt", value)
    assert info.value.field == "dt"


def test_positive_allow_zero_takes_zero_only() -> None:
    assert positive("margin", 0, allow_zero=True) == 0.0
    assert positive("margin", 0.5, allow_zero=True) == 0.5
    for value in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValidationError, match=r"^margin: expected a finite number >= 0, got "):
            positive("margin", value, allow_zero=True)


@pytest.mark.parametrize("value", ["fast", None, [1.0], {}])
def test_positive_refuses_what_is_no_number(value: Any) -> None:
    with pytest.raises(ValidationError, match=r"^v_max: expected a number, got ") as info:
        positive("v_max", value)
    assert repr(value) in str(info.value)


# ---- dimension ------------------------------------------------------------------------------


@pytest.mark.parametrize(("value", "expected"), [(2, 2), (3, 3), (np.int64(3), 3), (2.0, 2)])
def test_dimension_takes_two_or_three(value: Any, expected: int) -> None:
    out = dimension("dim", value)
    assert type(out) is int and out == expected


@pytest.mark.parametrize("value", [1, 4, 0, -2, 2.5, "2", None, True, False])
def test_dimension_refuses_everything_else(value: Any) -> None:
    with pytest.raises(ValidationError) as info:
        dimension("template.dim", value)
    assert info.value.field == "template.dim"
    assert str(info.value) == f"template.dim: expected 2 (planar) or 3 (spatial), got {value!r}"


def test_every_refusal_is_an_mpcform_error_and_a_value_error() -> None:
    checks = [
        lambda: finite_array("f", [np.nan], (1,)),
        lambda: positive("p", -1),
        lambda: dimension("d", 5),
    ]
    for check in checks:
        with pytest.raises(MPCFormError) as info:
            check()
        assert isinstance(info.value, ValueError) and isinstance(info.value, ValidationError)
