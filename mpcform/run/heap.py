"""Keep freed memory in the process's heap (glibc), so that large runs stop paying page faults.

A step of hundreds of drones allocates and frees arrays of hundreds of kB (the targets of 1000
drones over a horizon of 10 are 264 kB each). With glibc's defaults, freed memory at the top of
the heap beyond twice the largest block freed so far is returned to the system, and the next
step's arrays fault their pages in again. Measured on the formation flight of 1000 drones of
``mpcform bench scale`` (100 planner steps in one process, CPU medians, three runs each): 1.8-2.1
ms per step with the defaults, 1.2-1.5 ms with this setting. Results are bitwise the same: only
where memory comes from changes.

:func:`keep_heap` raises the trim threshold to :data:`TRIM_THRESHOLD_B` and fixes the mmap
threshold at :data:`MMAP_THRESHOLD_B` (glibc's largest), through ``mallopt`` in this process and
through glibc's ``MALLOC_*_`` variables for the processes it starts later (benchmarks and sweeps
spawn theirs). A variable the caller's environment already sets is kept, and that parameter is left
as glibc read it at start. The ``mpcform`` command calls it first; a program using the library
calls it once, before its run. Elsewhere than with glibc it does nothing.
"""

from __future__ import annotations

import ctypes
import os
import platform

TRIM_THRESHOLD_B = 256 << 20
"""Freed memory at the top of the heap kept before any is returned to the system [B]."""
MMAP_THRESHOLD_B = 32 << 20
"""Blocks from this size [B] up are mapped on their own (and unmapped when freed)."""
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3  # mallopt's parameters (malloc.h)
SETTINGS = {
    "MALLOC_TRIM_THRESHOLD_": (_M_TRIM_THRESHOLD, TRIM_THRESHOLD_B),
    "MALLOC_MMAP_THRESHOLD_": (_M_MMAP_THRESHOLD, MMAP_THRESHOLD_B),
}
"""glibc's environment variable for each setting: its ``mallopt`` parameter and our value."""


def keep_heap() -> bool:
    """Apply the setting of the module docstring to this process and to the processes it starts;
    whether it was applied (False without glibc: nothing is changed)."""
    if platform.libc_ver()[0] != "glibc":
        return False
    mallopt = ctypes.CDLL(None).mallopt
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    applied = True
    for name, (param, value) in SETTINGS.items():
        if name in os.environ:  # the caller's choice, read by glibc at start
            continue
        os.environ[name] = str(value)
        applied = mallopt(param, value) == 1 and applied
    return applied
