"""One whole run of a scenario: build its controller, simulate, compute the metrics, write the files."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mpcform.outputs.files import build_summary, write_outputs
from mpcform.scenario.build import build_controller
from mpcform.scenario.spec import Scenario
from mpcform.sim.metrics import run_metrics
from mpcform.sim.simulation import SimulationResult, simulate
from mpcform.sim.wind import Wind
from mpcform.solvers.base import QPBackend
from mpcform.world.limits import Limits


@dataclass(frozen=True)
class RunResult:
    """Outcome of :func:`run_scenario`: the time series, the summary dict, the output dir."""

    simulation: SimulationResult
    summary: dict[str, Any]
    out_dir: Path | None


def run_scenario(
    scenario: Scenario,
    out_dir: str | Path | None = None,
    controller: str | None = None,
    solver: str | QPBackend | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RunResult:
    """Simulate, compute the metrics and, when ``out_dir`` is given, write the output files.

    ``controller`` and ``solver`` override the scenario's controller kind and QP backend (a name or
    a :class:`~mpcform.solvers.base.QPBackend` instance: :func:`mpcform.scenario.build.build_controller`);
    ``progress(step, steps)`` is called after every step (e.g. :class:`mpcform.cli.progress.ProgressBar`).
    """
    ctrl = build_controller(scenario, controller, solver)
    sim = scenario.simulation
    result = simulate(
        ctrl,
        scenario.initial_positions_m,
        sim.duration_s,
        plant=scenario.plant,
        noise_std_m=sim.noise_std_m,
        seed=scenario.seed,
        progress=progress,
    )
    limits = scenario.limits
    is_mpc = (controller or scenario.controller.kind) == "mpc"
    summary = build_summary(
        scenario=scenario.name,
        n=scenario.n,
        dim=scenario.dim,
        dt_s=sim.dt_s,
        controller=ctrl.name,
        solver=getattr(ctrl, "solver_name", None) if is_mpc else None,  # "daqp (per drone)" if so
        v_max_mps=limits.v_max_mps,
        d_min_m=limits.d_min_m,
        seed=scenario.seed,
        scenario_file=scenario.source,
        scenario_sha256=scenario.source_sha256,
        metrics=run_metrics(result, scenario.world, goal_m=scenario.goal_after_end()),
        steps=result.commands_mps.shape[0],
        plant=plant_record(
            scenario, result.wind_clip_fraction, getattr(ctrl, "limits", None) if is_mpc else None
        )
        | result.plant_events,
        tracking_m=limits.tracking_m if is_mpc else 0.0,
        downwash_kappa=limits.downwash_kappa,
        v_max_z_mps=limits.v_max_z_mps if is_mpc else None,
    )
    path = None if out_dir is None else write_outputs(Path(out_dir), result, summary)
    return RunResult(result, summary, path)


def plant_record(
    scenario: Scenario, wind_clip_fraction: float, planned: Limits | None = None
) -> dict[str, Any]:
    """``summary.json``'s ``plant``: kind, robust margin [m] per drone, the acceleration bound
    [m/s^2] the margin assumes (``planned``: the MPC's, its default included; None: none), the speed
    it is valid below [m/s], the MPC rows' growth per interval in wind [m], the share of clipped
    gust samples, and whether the MPC's rows model the plant's velocity loop
    (``controller.plant_model``); with a wind, its :func:`wind_record`."""
    rob, spec = scenario.robustness, scenario.controller
    return {
        "kind": scenario.plant.kind,
        "margin": rob.margin_m,
        "a_max": rob.a_max_mps2 if planned is None else planned.a_max_mps2,
        "margin_valid_below_speed": rob.valid_speed_mps,
        "margin_growth": rob.growth_m,
        "wind_clip_fraction": wind_clip_fraction,
        "velocity_loop_modelled": bool(rob.loop) and spec.kind == "mpc" and spec.mpc.plant_model,
    } | ({} if (wind := getattr(scenario.plant, "wind", None)) is None else {"wind": wind_record(wind)})


def wind_record(wind: Wind) -> dict[str, Any]:
    """``plant.wind`` of ``summary.json``: the mean [m/s] (d,), the gusts' std [m/s], their bound
    [m/s] per axis and the field (figures and the viewer draw the mean as an arrow)."""
    return {
        "mean_mps": wind.mean_mps.tolist(),
        "gust_std_mps": wind.gust_std_mps,
        "gust_bound_mps": np.asarray(wind.gust_bound_mps, dtype=float).tolist(),
        "gust_field": wind.gust_field,
    }


def describe(scenario: Scenario) -> str:
    """One line: drones, template, reference, controller, steps."""
    space = "planar" if scenario.dim == 2 else "spatial"
    sim = scenario.simulation
    return (
        f"{scenario.name}: {scenario.n} drone{'s' * (scenario.n != 1)}, {space} "
        f"{scenario.template.name} template, {type(scenario.reference).__name__}, "
        f"{scenario.controller.kind} controller, {scenario.steps} steps of {sim.dt_s:g} s"
    )
