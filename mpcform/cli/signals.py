"""SIGTERM and SIGHUP end a command as Ctrl-C does: one line, the shell's status, nothing half-written.

:func:`terminating` turns either signal into :class:`Terminated`, a :class:`KeyboardInterrupt`, so
every ``except KeyboardInterrupt`` and every output claim (:mod:`mpcform.outputs.outdir`, which
removes what an interrupted command wrote) treats it as an interrupt; the command then prints
``mpcform: interrupted (SIGTERM)`` and exits with ``128 + signal``.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

SIGNALS = (signal.SIGTERM, signal.SIGHUP)


class Terminated(KeyboardInterrupt):
    """The command received ``signum`` (SIGTERM or SIGHUP)."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def _raise(signum: int, frame: FrameType | None) -> None:
    raise Terminated(signum)


@contextmanager
def terminating() -> Iterator[None]:
    """Within the block, SIGTERM and SIGHUP raise :class:`Terminated` (main thread only; the earlier
    handlers are restored after it)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    earlier = {s: signal.signal(s, _raise) for s in SIGNALS}
    try:
        yield
    finally:
        for s, handler in earlier.items():
            signal.signal(s, handler)
