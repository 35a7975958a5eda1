"""The description of a drone's linear velocity loop, per group of axes.

A plant declares its loop as groups ``(A, B, c, axes)``: per axis in ``axes``,
``xi' = A xi + B u``, ``v = c^T xi`` (:mod:`mpcform.sim.plant_spec`); the planner discretises
them (:class:`mpcform.mpc.velocity_loop.VelocityLoop`).
"""

from __future__ import annotations

from mpcform._validate import Array

LoopGroup = tuple[Array, Array, Array, tuple[int, ...]]  # (A (s, s), B (s,), c (s,), axes)
