"""The shared input checks (``mpcform._validate``): what each accepts and returns, what it refuses,
and that every refusal is a ValidationError naming the field and what was expected."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mpcform._validate import byte_size, dimension, finite_array, open_regular, positive, read_regular
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


@pytest.mark.parametrize(
    ("value", "expected"),
    [
        (np.array([1.0 + 2.0j, 0.0]), "expected real numbers of shape (2), got array([1.+2.j, 0.+0.j])"),
        ([1j, 0.0], "expected real numbers of shape (2), got [1j, 0.0]"),
        (["1", "2"], "expected numbers of shape (2), got ['1', '2']"),
        ([1.0, "2"], "expected numbers of shape (2), got [1.0, '2']"),
    ],
)
def test_finite_array_takes_real_numbers_only(value: Any, expected: str) -> None:
    """A complex value would lose its imaginary part and a string be parsed: both refused."""
    with pytest.raises(ValidationError) as info:
        finite_array("positions", value, (2,))
    assert str(info.value) == f"positions: {expected}"


def test_finite_array_cuts_a_long_value_short() -> None:
    value = np.full(10_000, np.nan)
    message = str(pytest.raises(ValidationError, finite_array, "p", value, (None,)).value)
    assert len(message) < 200 and message.startswith("p: expected finite numbers, got [nan, nan")


# ---- open_regular, read_regular -------------------------------------------------------------


def test_read_regular_reads_a_small_file(tmp_path: Path) -> None:
    (tmp_path / "s.toml").write_bytes(b"dim = 2\n")
    assert read_regular(tmp_path / "s.toml", 100, "scenario file") == b"dim = 2\n"
    with open_regular(tmp_path / "s.toml", 100, "scenario file") as f:
        assert f.read() == b"dim = 2\n"


@pytest.mark.parametrize(
    ("path", "kind"),
    [("/dev/zero", "a character device"), ("/dev/urandom", "a character device"), ("/", "a directory")],
)
def test_read_regular_refuses_what_is_no_regular_file_at_once(path: str, kind: str) -> None:
    with pytest.raises(ValidationError) as info:
        read_regular(path, 2**20, "scenario file")
    assert str(info.value) == (
        f"{path}: is {kind}, not a regular file; expected a scenario file (a regular file of at most 1 MiB)"
    )


def test_read_regular_refuses_a_fifo_without_waiting_for_a_writer(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "pipe")
    with pytest.raises(ValidationError, match=r"pipe: is a FIFO \(named pipe\), not a regular file"):
        read_regular(tmp_path / "pipe", 2**20, "ground file")


def test_read_regular_refuses_a_large_file_before_reading_it(tmp_path: Path) -> None:
    """A sparse file of 1 GiB (no byte on disk) is refused from its size alone."""
    big = tmp_path / "big.toml"
    with big.open("wb") as f:
        f.truncate(2**30)
    with pytest.raises(ValidationError) as info:
        read_regular(big, 16 * 2**20, "scenario file")
    assert str(info.value) == (
        f"{big}: is 1 GiB (1,073,741,824 bytes); expected a scenario file (a regular file of at most 16 MiB)"
    )
    with pytest.raises(FileNotFoundError):
        read_regular(tmp_path / "missing", 10, "scenario file")


def test_byte_size() -> None:
    assert [byte_size(n) for n in (812, 2048, 16 * 2**20, 3 * 2**29)] == [
        "812 bytes",
        "2 KiB",
        "16 MiB",
        "1.5 GiB",
    ]


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
