"""Stop planning for lost drones: the planner of the drones still flying, in the swarm's numbering.

A drone that flipped or lies on the floor (a plant's
:attr:`~mpcform.sim.plants.Plant.lost_drones`, or an online loop's :meth:`lose`) follows no
command. :meth:`mpcform.mpc.planner.MPCPlanner.lose` stops planning for it: the others are
planned over their own columns of the reference (:class:`mpcform.reference.subset.SubsetReference`:
the formation keeps its centroid, rotation and scale, eq. 13), keep the pair distance from where
the lost drones are (a sphere of radius and clearance ``d_min / 2`` at each, ``d_min`` as the
planner keeps it, allowances included), and continue from the previous plan (its commands, plan
and loop state: every change stays within ``a_max dt``). A lost drone is commanded zero.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mpcform._validate import Array
from mpcform.control.base import Controller, ControlStep
from mpcform.errors import ValidationError
from mpcform.mpc.step_info import MPCStepInfo
from mpcform.world.shapes.sphere import Sphere

EVERY_DRONE_LOST = MPCStepInfo("fallback", status="every drone is lost: nothing to plan, commands zero")


class Survivors(Controller):
    """``inner`` (a planner of the drones ``keep``, None when none is left) stepped in the
    numbering of ``full``'s ``n`` drones; ``lost`` (sorted) are commanded zero. The inner
    planner's obstacles from index ``obstacles`` on are the lost drones, in order: its step
    records name them as drones."""

    def __init__(self, full: Controller, lost: Array, inner: Controller | None, obstacles: int) -> None:
        self._full = full
        self.name, self.reference, self.dt_s = full.name, full.reference, full.dt_s
        self.n, self.dim = full.reference.template.n, full.reference.template.dim
        self.lost = np.asarray(lost, dtype=int)
        self.keep = np.setdiff1d(np.arange(self.n), self.lost)
        self.inner, self._obstacles = inner, obstacles

    def step(self, t_s: float, positions_m: Array) -> ControlStep:
        """The inner planner's step from the kept drones' ``positions_m``; zero for the lost."""
        p = self._check_positions(positions_m)
        u = np.zeros_like(p)
        if self.inner is None:
            return ControlStep(u, EVERY_DRONE_LOST)
        out = self.inner.step(t_s, p[self.keep])
        u[self.keep] = out.command_mps
        info = out.info
        if isinstance(info, MPCStepInfo) and info.slack_pairs:
            info = replace(info, slack_pairs=tuple(sorted({self._label(a, b) for a, b in info.slack_pairs})))
        return ControlStep(u, info)

    def lose(self, drones: Array, positions_m: Array) -> Controller:
        """Stop planning for ``drones`` too (swarm numbering; ``positions_m`` (n, d) where all are)."""
        p = self._check_positions(positions_m)
        drones = np.setdiff1d(split_lost(drones, self.n)[0], self.lost)
        if self.inner is None or drones.size == 0:
            return self
        inner = self.inner.lose(np.searchsorted(self.keep, drones), p[self.keep])
        return Survivors(self._full, self.lost, inner, self._obstacles)

    @property
    def lost_drones(self) -> Array:
        """Every lost drone (sorted), in the swarm's numbering."""
        inner = np.zeros(0, dtype=int) if self.inner is None else self.inner.lost_drones
        return np.union1d(self.lost, self.keep[inner])

    def _label(self, a: int, b: int) -> tuple[int, int]:
        """An inner item label in the swarm's numbering: a lost drone's sphere is that drone."""
        if b >= 0:
            return int(self.keep[a]), int(self.keep[b])
        obstacle = -1 - b
        if obstacle >= self._obstacles:
            i, k = sorted((int(self.keep[a]), int(self.lost[obstacle - self._obstacles])))
            return i, k
        return int(self.keep[a]), b


def split_lost(drones: Array, n: int) -> tuple[Array, Array]:
    """The lost ``drones`` (sorted, unique) and the others of ``n``."""
    lost = np.unique(np.asarray(drones, dtype=int))
    if lost.size and (lost[0] < 0 or lost[-1] >= n):
        raise ValidationError("drones", f"expected drone indices in 0..{n - 1}, got {lost.tolist()}")
    return lost, np.setdiff1d(np.arange(n), lost)


def lost_spheres(positions_m: Array, d_min_m: float | None) -> tuple[Sphere, ...]:
    """A sphere of radius and clearance ``d_min / 2`` at each lost drone's position (k, d): a
    drone keeps ``d_min`` from its centre, as from a partner (none without ``d_min``)."""
    if not d_min_m:
        return ()
    r = 0.5 * d_min_m
    return tuple(Sphere(p, r, r) for p in positions_m)
