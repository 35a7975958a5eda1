"""What the drones really did, in the time-series figures: a plant run's dense true path.

A run on a plant other than the ideal one (:attr:`~mpcform.outputs.rundata.RunData.flown`) records
every sample of its plant (:class:`~mpcform.sim.trajectory.TrueTrajectory`;
10 per control step, crazyflow's every physics step). The figures draw it beside what the planner
saw at the control samples: at most about :data:`~mpcform.outputs.drawing.DISPLAY_SAMPLES` points
per line, but the peak speed and the minimum separation marked are those of every sample.
"""

from __future__ import annotations

import numpy as np
from matplotlib.axes import Axes

from mpcform.formation.geometry import min_pair_distances
from mpcform.outputs.drawing import (
    FLOWN_COLOUR,
    FLOWN_GID,
    PER_DRONE_MAX,
    display_rows,
    envelope,
    per_drone_style,
)
from mpcform.outputs.rundata import RunData


def flown_speeds(ax: Axes, run: RunData) -> float:
    """The true speeds ``||v_i||`` (dotted per drone, or a band and median), their peak marked;
    returns the peak [m/s] (0 without a true path)."""
    true = run.flown
    if true is None:
        return 0.0
    speed = np.linalg.norm(true.velocities_mps, axis=-1)  # (K, n)
    rows = display_rows(speed.shape[0])
    k, i = (int(x) for x in np.unravel_index(int(np.argmax(speed)), speed.shape))
    if run.n <= PER_DRONE_MAX:
        for j in range(run.n):
            ax.plot(
                true.t_s[rows], speed[rows, j], gid=FLOWN_GID, **(per_drone_style(j) | {"lw": 0.8, "ls": ":"})
            )
    else:
        envelope(ax, true.t_s[rows], speed[rows], FLOWN_COLOUR, "flown speed")
    label = f"flown peak {speed[k, i]:.3g} m/s (drone {i}, t = {true.t_s[k]:.3g} s)"
    ax.plot(true.t_s[k], speed[k, i], "^", color=FLOWN_COLOUR, ms=7, zorder=5, label=label, gid=FLOWN_GID)
    return float(speed[k, i])


def flown_separation(ax: Axes, run: RunData) -> float:
    """The true minimum distance between two drones, its lowest point marked; returns its
    highest value [m] (0 without a true path)."""
    true = run.flown
    if true is None:
        return 0.0
    sep = min_pair_distances(true.positions_m)
    rows, low = display_rows(sep.shape[0]), int(np.argmin(sep))
    ax.plot(true.t_s[rows], sep[rows], color=FLOWN_COLOUR, lw=1.0, label="flown (true, dense)", gid=FLOWN_GID)
    label = f"flown minimum {sep[low]:.3g} m at t = {true.t_s[low]:.3g} s"
    ax.plot(true.t_s[low], sep[low], "v", color=FLOWN_COLOUR, ms=7, zorder=5, label=label, gid=FLOWN_GID)
    return float(sep.max())
