"""One exception tree for mpcform: every error carries the context a user needs."""

from __future__ import annotations

import reprlib

_SHORT = reprlib.Repr()
_SHORT.maxlist = _SHORT.maxtuple = 6
_SHORT.maxstring = _SHORT.maxother = 60


def shown(value: object) -> str:
    """``repr(value)`` cut short (``[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, ...]``): a bad value echoed in an
    error message stays one readable line, however large it is."""
    return _SHORT.repr(value)


class MPCFormError(Exception):
    """Base class of every error raised by mpcform."""


class ValidationError(MPCFormError, ValueError):
    """Bad input: names the field, the value received and what was expected."""

    def __init__(self, field: str, message: str) -> None:
        self.field, self.message = field, message
        super().__init__(f"{field}: {message}")

    def __reduce__(self) -> tuple[type, tuple[str, str]]:  # pickles (a worker's error reaches its caller)
        return type(self), (self.field, self.message)


class ScenarioError(ValidationError):
    """A scenario file that cannot be read or does not follow the format."""


class SolverError(MPCFormError):
    """A QP backend that is unknown, not installed, or failed outside the planning loop."""

    def __init__(self, solver: str, message: str) -> None:
        self.solver, self.message = solver, message
        super().__init__(f"solver {solver!r}: {message}")

    def __reduce__(self) -> tuple[type, tuple[str, str]]:
        return type(self), (self.solver, self.message)
