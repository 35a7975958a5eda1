"""The online loop flown with Crazyswarm2's Python API (``crazyflie_py``).

Every control period :func:`fly_online` reads each drone's position from Crazyswarm2 (the
``/cfN/pose`` topic: ``Crazyflie.get_position()``, motion capture or the onboard estimate), steps
the :class:`~mpcform.online.loop.OnlineLoop`, and streams the interval's full-state setpoints with
``Crazyflie.cmdFullState`` at the setpoint rate (``TimeHelper.sleepForRate``); after the last
interval it calls ``notifySetpointsStop`` so that a high-level ``land`` may follow. Takeoff, the
move to the start positions and the landing are the script's (see the README).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mpcform._validate import positive
from mpcform.errors import ValidationError, shown
from mpcform.online.loop import OnlineLoop, OnlineStep


def fly_online(
    loop: OnlineLoop, swarm: Any, duration_s: float, names: list[str] | None = None
) -> list[OnlineStep]:
    """Fly ``loop`` for ``duration_s`` [s] with Crazyswarm2's ``swarm`` (a
    ``crazyflie_py.Crazyswarm``): its drones ``names`` in the planner's drone order (None: the
    server's order, ``allcfs.crazyflies``). Returns every step (its command, setpoints and times);
    stops early when Crazyswarm2 shuts down."""
    allcfs, clock = swarm.allcfs, swarm.timeHelper
    n, dim = loop.n, loop.dim
    positive("duration_s", duration_s)
    cfs = allcfs.crazyflies if names is None else _by_name(allcfs.crazyfliesByName, names, n)
    if len(cfs) != n:
        raise ValidationError("names", f"expected {n} Crazyflies (one per drone of the plan), got {len(cfs)}")
    steps: list[OnlineStep] = []
    for k in range(int(round(duration_s / loop.dt_s))):
        if clock.isShutdown():
            break
        p = np.array([cf.get_position() for cf in cfs], dtype=float)[:, :dim]
        step = loop.step(k * loop.dt_s, p)
        sp = step.setpoints
        for j in range(sp.t_s.shape[0]):
            for i, cf in enumerate(cfs):
                cf.cmdFullState(
                    sp.pos_m[j, i],
                    sp.vel_mps[j, i],
                    sp.acc_mps2[j, i],
                    sp.yaw_rad[j, i],
                    sp.omega_rad_s[j, i],
                )
            clock.sleepForRate(loop.setpoint_rate_hz)
        steps.append(step)
    for cf in cfs:
        cf.notifySetpointsStop()
    return steps


def _by_name(by_name: dict[str, Any], names: list[str], n: int) -> list[Any]:
    """The Crazyflies ``names``, checked before any is commanded: n distinct names of the swarm."""
    names = list(names)
    if len(names) != n:
        raise ValidationError(
            "names", f"expected {n} Crazyflie names (one per drone of the plan), got {len(names)}"
        )
    unknown = [name for name in names if not isinstance(name, str) or name not in by_name]
    if unknown:
        known = ", ".join(sorted(map(str, by_name))[:8]) + (", ..." if len(by_name) > 8 else "")
        raise ValidationError(
            "names", f"no Crazyflie named {shown(unknown[0])} in the swarm (it has {known or 'none'})"
        )
    if len(set(names)) != n:
        twice = next(name for name in names if names.count(name) > 1)
        raise ValidationError("names", f"expected distinct names, got {twice!r} more than once")
    return [by_name[name] for name in names]
