"""A recording fake of the ``crazyflie_py`` calls the online loop's Crazyswarm2 example makes.

Each drone tracks perfectly: ``takeoff`` and ``goTo`` put it where they aim, and after each
``sleepForRate(rate)`` a drone streaming full-state setpoints is at ``pos + vel / rate``.
"""

from __future__ import annotations

import types

import numpy as np


def fake_crazyflie_py(calls: list[tuple], n: int) -> types.ModuleType:
    """The module, with ``n`` drones ``cf1 .. cfn`` on the ground 1 m apart along x."""

    class Crazyflie:
        def __init__(self, name: str, x: float) -> None:
            self.name, self.position, self.streaming = name, np.array([x, 0.0, 0.0]), None

        def get_position(self):  # noqa: D102
            return self.position.tolist()

        def goTo(self, goal, yaw, duration, relative=False, groupMask=0):  # noqa: N802, N803
            calls.append(("goTo", self.name, list(goal), duration))
            self.position = np.array(goal, dtype=float)

        def cmdFullState(self, pos, vel, acc, yaw, omega):  # noqa: N802
            calls.append(("cmdFullState", self.name))
            self.streaming = (np.array(pos, dtype=float), np.array(vel, dtype=float))

        def notifySetpointsStop(self, remainValidMillisecs=100, groupMask=0):  # noqa: N802, N803
            calls.append(("notifySetpointsStop", self.name))

    class Server:
        def __init__(self) -> None:
            self.crazyflies = [Crazyflie(f"cf{i + 1}", float(i)) for i in range(n)]
            self.crazyfliesByName = {cf.name: cf for cf in self.crazyflies}  # noqa: N815

        def takeoff(self, targetHeight, duration, groupMask=0):  # noqa: N803
            calls.append(("takeoff", targetHeight, duration))
            for cf in self.crazyflies:
                cf.position[2] = targetHeight

        def land(self, targetHeight, duration, groupMask=0):  # noqa: N803
            calls.append(("land", targetHeight, duration))

    class TimeHelper:
        def __init__(self, server: Server) -> None:
            self.server, self.now = server, 0.0

        def time(self) -> float:
            return self.now

        def sleep(self, duration: float) -> None:
            calls.append(("sleep", duration))
            self.now += duration

        def sleepForRate(self, rateHz: float) -> None:  # noqa: N802, N803
            self.now += 1.0 / rateHz
            for cf in self.server.crazyflies:
                if cf.streaming is not None:
                    pos, vel = cf.streaming
                    cf.position = pos + vel / rateHz

        def isShutdown(self) -> bool:  # noqa: N802
            return False

    class Crazyswarm:
        def __init__(self) -> None:
            self.allcfs = Server()
            self.timeHelper = TimeHelper(self.allcfs)  # noqa: N815

    module = types.ModuleType("crazyflie_py")
    module.Crazyswarm = Crazyswarm  # type: ignore[attr-defined]
    return module
