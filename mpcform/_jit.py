"""The optional compiled kernels' switch: numba (the ``fast`` extra) when it is installed.

:func:`njit` compiles a loop-style kernel with numba (cached on disk, compiled at its first call)
when numba is importable and ``MPCFORM_NUMBA`` is not ``0``; otherwise it returns the function
unchanged and :data:`ENABLED` is False, so callers keep their numpy path. The two paths give the
same plans within 1e-9 m (tests/test_jit.py flies both).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

try:  # pragma: no cover - depends on the installed extras
    import numba

    ENABLED = os.environ.get("MPCFORM_NUMBA", "1") != "0"
except ImportError:  # pragma: no cover
    numba = None  # type: ignore[assignment]
    ENABLED = False


def njit(fn: F) -> F:
    """``fn`` compiled by numba (no Python objects, cached), or ``fn`` itself without numba."""
    if numba is None:
        return fn
    return numba.njit(cache=True, nogil=True)(fn)  # type: ignore[return-value]
