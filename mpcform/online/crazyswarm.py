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

from mpcform.errors import ValidationError
from mpcform.online.loop import OnlineLoop, OnlineStep


def fly_online(
    loop: OnlineLoop, swarm: Any, duration_s: float, names: list[str] | None = None
) -> list[OnlineStep]:
    """Fly ``loop`` for ``duration_s`` [s] with Crazyswarm2's ``swarm`` (a
    ``crazyflie_py.Crazyswarm``): its drones ``names`` in the planner's drone order (None: the
    server's order, ``allcfs.crazyflies``). Returns every step (its command, setpoints and times);
    stops early when Crazyswarm2 shuts down."""
    allcfs, clock = swarm.allcfs, swarm.timeHelper
    cfs = allcfs.crazyflies if names is None else [allcfs.crazyfliesByName[name] for name in names]
    n, dim = loop.n, loop.dim
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
