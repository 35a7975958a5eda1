"""Closed-loop simulation: zero-order hold at ``dt`` and the exact single-integrator update.

The simulator drives a controller through its interface and owns no controller state. As the
single integrator abstracts an inner autopilot loop, it can add a first-order velocity lag
(time constant ``lag_s``) and seeded Gaussian position disturbances (``noise_std_m`` per step).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array, finite_array, positive
from mpcform.control.base import Controller, StepInfo
from mpcform.errors import MPCFormError, ValidationError
from mpcform.sim.trajectory import Trajectory


@dataclass(frozen=True, eq=False)
class SimulationResult(Trajectory):
    """A simulated :class:`~mpcform.sim.trajectory.Trajectory` and the controller's record of its
    T - 1 steps (fields ``t_s, positions_m, commands_mps, reference_m, infos, step_times_s,
    controller``, in this order)."""

    infos: tuple[StepInfo, ...]
    step_times_s: Array  # (T - 1,) wall-clock time of each controller call
    controller: str

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self.infos) != self.steps or self.step_times_s.shape != (self.steps,):
            raise ValidationError("simulation result", f"expected {self.steps} step infos and step times, "
                                  f"got {len(self.infos)} and shape {self.step_times_s.shape}")  # fmt: skip


def simulate(
    controller: Controller,
    initial_positions_m: object,
    duration_s: float,
    *,
    t0_s: float = 0.0,
    lag_s: float = 0.0,
    noise_std_m: float = 0.0,
    seed: int = 0,
    progress: object = None,
) -> SimulationResult:
    """Run ``controller`` for ``duration_s`` from ``initial_positions_m`` (n, d).

    ``progress``, if given, is called as ``progress(step, steps)`` after every step.
    """
    tpl = controller.reference.template
    p = finite_array("initial.positions", initial_positions_m, (tpl.n, tpl.dim)).copy()
    dt = controller.dt_s
    steps = max(1, int(round(positive("simulation.duration", duration_s) / dt)))
    lag = positive("simulation.lag", lag_s, allow_zero=True)
    noise = positive("simulation.noise", noise_std_m, allow_zero=True)
    rng = np.random.default_rng(seed)
    t = t0_s + dt * np.arange(steps + 1)
    pos = np.empty((steps + 1, tpl.n, tpl.dim))
    cmd = np.empty((steps, tpl.n, tpl.dim))
    times = np.empty(steps)
    infos: list[StepInfo] = []
    velocity = np.zeros_like(p)
    decay = np.exp(-dt / lag) if lag > 0 else 0.0
    pos[0] = p
    controller.reset(t0_s, p.copy())
    for j in range(steps):
        start = time.perf_counter()
        out = controller.step(float(t[j]), p.copy())
        times[j] = time.perf_counter() - start
        u = out.command_mps
        if u.shape != p.shape or not np.all(np.isfinite(u)):
            raise MPCFormError(f"controller {controller.name!r} returned a bad command at t = {t[j]:g} s")
        if lag > 0:  # exact first-order lag: v' = (u - v) / lag
            p = p + dt * u + (velocity - u) * lag * (1.0 - decay)
            velocity = u + (velocity - u) * decay
        else:
            p = p + dt * u
        if noise > 0:
            p = p + rng.normal(0.0, noise, p.shape)
        pos[j + 1], cmd[j] = p, u
        infos.append(out.info)
        if progress is not None:
            progress(j + 1, steps)  # type: ignore[operator]
    ref, _ = controller.reference.targets(t)
    return SimulationResult(t, pos, cmd, ref, tuple(infos), times, controller.name)
