"""Closed-loop simulation: the controller's command is held for ``dt`` (zero-order hold) and a plant
turns it into motion.

The simulator drives a controller through its interface and owns no controller state. The plant
(:mod:`mpcform.sim.plants`; default: the ideal plant, the exact single integrator ``p+ = p + dt u``
that the planner assumes) integrates each interval and returns its dense true motion; the
controller sees the plant's measured positions. ``noise_std_m`` adds seeded Gaussian position
disturbances at the end of every interval (a process disturbance, drawn from ``seed`` itself, so
earlier seeded runs are unchanged); the plant's wind and measurement noise draw from their own
child streams of ``seed``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from mpcform._validate import Array, finite_array, positive
from mpcform.control.base import Controller, StepInfo
from mpcform.errors import MPCFormError, ValidationError
from mpcform.sim.plant_spec import IdealPlantSpec, PlantSpec
from mpcform.sim.plants import Plant, PlantSamples, concat_samples
from mpcform.sim.trajectory import Trajectory, TrueTrajectory


@dataclass(frozen=True, eq=False)
class SimulationResult(Trajectory):
    """A simulated :class:`~mpcform.sim.trajectory.Trajectory` and the controller's record of its
    T - 1 steps (fields ``t_s, positions_m, commands_mps, reference_m, infos, step_times_s,
    controller``, in this order; ``scale_estimates`` (T, n) of a consensus controller, row j the
    estimates at ``t_j``, those the step there uses); ``wind_clip_fraction``: the share of gust
    samples the wind's bound clipped (0 without wind); ``plant_events``: the plant's
    :attr:`~mpcform.sim.plants.Plant.events`, with ``planning_stopped_s``, the time [s] the
    controller stopped planning for each lost drone (:attr:`~mpcform.sim.plants.Plant.lost_drones`)
    when it did."""

    infos: tuple[StepInfo, ...]
    step_times_s: Array  # (T - 1,) wall-clock time of each controller call
    controller: str
    wind_clip_fraction: float = field(default=0.0, kw_only=True)
    plant_events: dict = field(default_factory=dict, kw_only=True)

    def __post_init__(self) -> None:
        super().__post_init__()
        if len(self.infos) != self.steps or self.step_times_s.shape != (self.steps,):
            raise ValidationError(
                "simulation result",
                f"expected {self.steps} step infos and step times, "
                f"got {len(self.infos)} and shape {self.step_times_s.shape}",
            )


def plant_seed(seed: int) -> np.random.SeedSequence:
    """The plant's own stream of a run's ``seed`` (a child, so the process noise keeps ``seed``)."""
    return np.random.SeedSequence(seed).spawn(1)[0]


def simulate(
    controller: Controller,
    initial_positions_m: ArrayLike,
    duration_s: float,
    *,
    t0_s: float = 0.0,
    plant: Plant | PlantSpec | None = None,
    noise_std_m: float = 0.0,
    seed: int = 0,
    progress: Callable[[int, int], object] | None = None,
) -> SimulationResult:
    """Run ``controller`` for ``duration_s`` from ``initial_positions_m`` (n, d) on ``plant`` (a
    plant, a :class:`~mpcform.sim.plant_spec.PlantSpec` built here with :func:`plant_seed`, or None
    for the ideal plant).

    ``progress``, if given, is called as ``progress(step, steps)`` after every step.
    """
    tpl = controller.reference.template
    p = finite_array("initial.positions", initial_positions_m, (tpl.n, tpl.dim)).copy()
    dt = controller.dt_s
    steps = max(1, int(round(positive("simulation.duration", duration_s) / dt)))
    noise = positive("simulation.noise", noise_std_m, allow_zero=True)
    if not isinstance(plant, Plant):
        plant = (plant or IdealPlantSpec()).build(tpl.n, tpl.dim, plant_seed(seed))
    rng = np.random.default_rng(seed)
    t = t0_s + dt * np.arange(steps + 1)
    pos = np.empty((steps + 1, tpl.n, tpl.dim))
    cmd = np.empty((steps, tpl.n, tpl.dim))
    times = np.empty(steps)
    infos: list[StepInfo] = []
    parts: list[PlantSamples] = []
    pos[0] = p
    plant.reset(p, t0_s=t0_s)
    controller.reset(t0_s, p.copy())
    s_hat = _estimates_record(controller, steps)
    active, stopped = controller, dict[int, float]()  # the controller of the drones it plans for
    for j in range(steps):
        start = time.perf_counter()
        out = active.step(float(t[j]), p.copy())
        times[j] = time.perf_counter() - start
        u = out.command_mps
        if u.shape != p.shape or not np.all(np.isfinite(u)):
            raise MPCFormError(f"controller {controller.name!r} returned a bad command at t = {t[j]:g} s")
        part = plant.advance(u, dt)
        p = part.p_measured_m
        if noise > 0:
            kick = rng.normal(0.0, noise, p.shape)
            plant.displace(kick)
            part.p_true_m[-1] = part.p_true_m[-1] + kick
            p = p + kick
        part.t_s[:] = t[j] + (part.t_s - part.t_s[0])  # the control samples exactly among the times
        part.t_s[-1] = t[j + 1]
        pos[j + 1], cmd[j] = p, u
        if (lost := plant.lost_drones).size > len(stopped):  # stop planning for them
            active = active.lose(lost, p.copy())
            stopped |= {int(i): float(t[j + 1]) for i in lost if int(i) not in stopped}
        if s_hat is not None:
            s_hat[j + 1] = controller.scale_estimates
        infos.append(out.info)
        parts.append(part)
        if progress is not None:
            progress(j + 1, steps)
    ref, _ = controller.reference.targets(t)
    dense = concat_samples(parts)
    true = TrueTrajectory(
        dense.t_s,
        dense.p_true_m,
        dense.v_true_mps,
        controller.reference.targets(dense.t_s)[0],
        dense.quat_xyzw,
        dense.thrust_N,
    )
    return SimulationResult(
        t,
        pos,
        cmd,
        ref,
        tuple(infos),
        times,
        controller.name,
        true=true,
        scale_estimates=s_hat,
        wind_clip_fraction=plant.wind_clip_fraction,
        plant_events=plant.events | ({"planning_stopped_s": stopped} if active.lost_drones.size else {}),
    )


def _estimates_record(controller: Controller, steps: int) -> Array | None:
    """(steps + 1, n) for the controller's scale estimates, its first row the estimates after the
    reset; None when the controller keeps none."""
    first = controller.scale_estimates
    if first is None:
        return None
    record = np.empty((steps + 1, first.shape[0]))
    record[0] = first
    return record
