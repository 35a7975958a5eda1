"""The optional compiled kernels' switch: numba (the ``fast`` extra) when it is installed.

:data:`AVAILABLE`: numba is installed and ``MPCFORM_NUMBA`` is not ``0``. Loading the kernels
costs about a second (numba's import and its on-disk cache; minutes the very first time), so a
planner loads them when it is built for a swarm large enough to gain
(:func:`mpcform.mpc.constraints.kernels.warm_up`), never in the middle of a flight; from then on
:data:`USE` is True and the hot loops run compiled. Either way the plans are the same, bit for bit
(tests/test_jit.py flies both).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from importlib.util import find_spec
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

AVAILABLE = find_spec("numba") is not None and os.environ.get("MPCFORM_NUMBA", "1") != "0"
USE = False  # the kernels are loaded: the hot loops run compiled
MIN_DRONES = 100
"""Planners for this many drones or more load the kernels (below it numpy's step is short)."""


def njit(fn: F) -> F:
    """``fn`` compiled by numba (no Python objects, cached on disk), or ``fn`` itself without it."""
    return _compiled(fn, nogil=True)


def inline(fn: F) -> F:
    """A small helper of the kernels, inlined into each caller by numba (a call with array
    arguments costs more than the arithmetic), or ``fn`` itself without it."""
    return _compiled(fn, inline="always")


def _compiled(fn: F, **options: Any) -> F:
    if not AVAILABLE:
        return fn
    import numba

    return numba.njit(cache=True, **options)(fn)
