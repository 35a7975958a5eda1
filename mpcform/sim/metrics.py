"""Metrics of a run: per-sample series of a :class:`Trajectory` and the summary's ``metrics`` record.

:func:`run_metrics` gives the ``metrics`` of ``summary.json``: ``final_tracking_error`` and
``max_tracking_error`` (max over drones of ``||p_i - p*_i||`` [m], at the end / over time),
``min_separation`` (smallest distance between two drones over the samples [m]) and
``min_separation_segments`` (along the straight segments between samples; both null for one
drone), ``max_speed`` (largest ``||u_i||`` [m/s]), ``separation_violations`` (count of
(sample, pair) closer than d_min) and ``speed_violations`` (count of (step, drone) faster than
v_max), ``qp_solves``, ``fast_path_steps``, ``solver_failures``, ``max_slack`` [m],
``slack_steps`` (steps whose plan needed slack, or that start inside a required distance, by
more than :data:`mpcform.mpc.planner.SLACK_REPORT_M`) and
``lowered_first_rows`` (steps whose first separation rows were lowered to what braking reaches,
:func:`mpcform.mpc.safety.first_rows.hard_first_rows`), ``max_growth_slack`` [m] and
``growth_slack_steps`` (in wind, steps whose plan reached into its rows' growth along the horizon
but kept every required distance: the growth's buffer, not slack), ``max_wind_shift`` [m] and
``growth_exceeded_steps`` (in wind, how far the wind moved the previous plan within the growth's
window, and the steps it moved farther than the growth per step: the growth's premise,
:mod:`mpcform.mpc.safety.premise`),
``stall_events``, ``resolutions`` and ``circling_resets`` (drones that started to stall,
escalated tie-breaks that ended, and circling drones whose escalation was reset,
:mod:`mpcform.mpc.liveness`), ``deadline_misses`` (steps that ended past
``controller.step_budget``: their certified command was sent late), ``budget_cuts`` (steps whose
split rounds the wall clock stopped: the only steps whose plan the machine's load can change), and
``step_time_ms`` (median, p90 and max of the controller's wall-clock time per step mode). The
figures draw the same series (:func:`tracking_errors_m`, :func:`min_separations_m`,
:func:`command_speeds_mps`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mpcform._validate import Array
from mpcform.formation.geometry import count_pairs_within, min_pair_distances
from mpcform.formation.kinematics import fit_formation
from mpcform.formation.template import Template
from mpcform.sim.completion import COMPLETION_TOL_M, completion_metrics
from mpcform.sim.safety import (
    downwash_metric,
    geofence_violations,
    min_separation_along,
    obstacle_metrics,
    separation_violations,
)
from mpcform.sim.simulation import SimulationResult
from mpcform.sim.trajectory import Trajectory, TrueTrajectory
from mpcform.world.limits import Limits
from mpcform.world.obstacles import Obstacle
from mpcform.world.world import World

REL_TOL = 1e-9  # violations are counted beyond this relative tolerance


# ---- series ------------------------------------------------------------------------------
def tracking_errors_m(trajectory: Trajectory) -> Array:
    """``||p_i - p*_i||`` [m] at every sample, (T, n)."""
    return np.asarray(np.linalg.norm(trajectory.positions_m - trajectory.reference_m, axis=-1))


def min_separations_m(trajectory: Trajectory) -> Array:
    """Smallest distance between two drones at every sample [m], (T,); inf for one drone."""
    return min_pair_distances(trajectory.positions_m)


def command_speeds_mps(trajectory: Trajectory) -> Array:
    """``||u_i||`` [m/s] of every command (held over its step), (T - 1, n)."""
    return np.asarray(np.linalg.norm(trajectory.commands_mps, axis=-1))


def fitted_scales(offsets_m: Array, positions_m: Array) -> Array:
    """Best-fit (Umeyama, eq. 13 inverted) scale of ``positions_m`` (T, n, d) over the template
    ``offsets_m`` (n, d), centred here, at every sample, (T,)."""
    template = Template(offsets_m - offsets_m.mean(axis=0))
    return np.array([fit_formation(template, p).state.scale for p in positions_m])


def tracking_cost_m2s(trajectory: Trajectory) -> float:
    """``integral of sum_i ||p_i - p*_i||^2 dt`` over the run [m^2 s] (trapezoidal rule over the
    samples): one number for how closely a whole run followed its reference."""
    err2 = ((trajectory.positions_m - trajectory.reference_m) ** 2).sum(axis=(1, 2))
    return float(np.sum(0.5 * (err2[1:] + err2[:-1]) * np.diff(trajectory.t_s)))


# ---- the summary's metrics ---------------------------------------------------------------
def run_metrics(
    result: SimulationResult,
    world: World | None = None,
    *,
    completion_tol_m: float = COMPLETION_TOL_M,
    goal_m: Array | None = None,
) -> dict[str, Any]:
    """Tracking, separation, speed, solver, timing and completion metrics of one run (JSON-ready);
    with a ``world`` (:class:`~mpcform.world.world.World`: its limits' ``v_max`` and ``d_min``, its
    obstacles with their resolved clearances) also the speed and separation violations, the
    geofence, downwash and obstacle metrics, and with the plant's dense motion (``result.true``)
    the ``*_true`` metrics."""
    limits = None if world is None else world.limits
    obstacles = () if world is None else world.obstacles
    v_max_mps = None if limits is None else limits.v_max_mps
    d_min_m = None if limits is None else limits.d_min_m
    err = tracking_errors_m(result).max(axis=1)
    speed = command_speeds_mps(result)
    pos = result.positions_m
    sample_min = float(min_separations_m(result).min())
    seg_min = min_separation_along(pos)
    sep_viol = 0
    if d_min_m is not None:
        limit = d_min_m * (1.0 - REL_TOL)
        sep_viol = count_pairs_within(pos, limit)
    modes = np.array([i.mode for i in result.infos])
    return {
        "final_tracking_error": float(err[-1]),
        "max_tracking_error": float(err.max()),
        "min_separation": _finite_or_none(sample_min),
        "min_separation_segments": _finite_or_none(seg_min),
        "max_speed": float(speed.max()),
        "separation_violations": int(sep_viol),
        "speed_violations": 0 if v_max_mps is None else int((speed > v_max_mps * (1 + REL_TOL)).sum()),
        "qp_solves": int(sum(i.mode in ("qp", "fallback") for i in result.infos)),
        "fast_path_steps": int((modes == "fast_path").sum()),
        "solver_failures": int((modes == "fallback").sum()),
        # the planner's records (mpc.step_info.MPCStepInfo) carry these; other controllers' steps count 0
        "max_slack": float(max((getattr(i, "max_slack_m", 0.0) for i in result.infos), default=0.0)),
        "slack_steps": int(sum(getattr(i, "max_slack_m", 0.0) > 0.0 for i in result.infos)),
        "lowered_first_rows": int(sum(getattr(i, "lowered", False) for i in result.infos)),
        "max_growth_slack": float(
            max((getattr(i, "growth_slack_m", 0.0) for i in result.infos), default=0.0)
        ),
        "growth_slack_steps": int(sum(getattr(i, "growth_slack_m", 0.0) > 0.0 for i in result.infos)),
        "max_wind_shift": float(max((getattr(i, "wind_shift_m", 0.0) for i in result.infos), default=0.0)),
        "growth_exceeded_steps": int(sum(getattr(i, "growth_exceeded", False) for i in result.infos)),
        "stall_events": int(sum(getattr(i, "stalled", 0) for i in result.infos)),
        "resolutions": int(sum(getattr(i, "resolved", 0) for i in result.infos)),
        "circling_resets": int(sum(getattr(i, "unwound", 0) for i in result.infos)),
        "deadline_misses": int(sum(getattr(i, "deadline_missed", False) for i in result.infos)),
        "budget_cuts": int(sum(getattr(i, "budget_cut", False) for i in result.infos)),
        "step_time_ms": {
            mode: _stats(1e3 * result.step_times_s[modes == mode]) for mode in sorted(set(modes.tolist()))
        },
        **_path_metrics(result.positions_m, "", limits, obstacles),
        **({} if result.true is None else _true_metrics(result.true, limits, obstacles)),
        **completion_metrics(result, completion_tol_m, goal_m),
    }


def _path_metrics(
    path: Array, suffix: str, limits: Limits | None, obstacles: tuple[Obstacle, ...]
) -> dict[str, Any]:
    """Obstacle, geofence and downwash separation of a path (straight between its samples)."""
    out: dict[str, Any] = {}
    if obstacles:
        clearance, violations = obstacle_metrics(path, obstacles)
        out |= {f"min_obstacle_clearance{suffix}": clearance, f"obstacle_violations{suffix}": violations}
    if limits is not None:
        out[f"geofence_violations{suffix}"] = geofence_violations(path, limits)
        metric = downwash_metric(limits, path.shape[-1])
        if metric is not None:
            out[f"min_separation_downwash{suffix}"] = _finite_or_none(min_separation_along(path, metric))
    return out


def _true_metrics(
    true: TrueTrajectory, limits: Limits | None, obstacles: tuple[Obstacle, ...]
) -> dict[str, Any]:
    """The safety and tracking metrics of the plant's dense true motion (distances linear between
    dense samples)."""
    p, d_min_m = true.positions_m, None if limits is None else limits.d_min_m
    out: dict[str, Any] = {
        "min_separation_true": _finite_or_none(min_separation_along(p)),
        "separation_violations_true": 0 if d_min_m is None else separation_violations(p, d_min_m),
        "max_speed_true": float(np.linalg.norm(true.velocities_mps, axis=-1).max()),
        "max_tracking_error_true": float(np.linalg.norm(p - true.reference_m, axis=-1).max()),
    }
    if obstacles:
        clearance, violations = obstacle_metrics(p, obstacles)
        out |= {"min_obstacle_clearance_true": clearance, "obstacle_violations_true": violations}
    return out | _path_metrics(p, "_true", limits, ())


def _stats(ms: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(ms)),
        "p90": float(np.percentile(ms, 90)),
        "max": float(ms.max()),
    }


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None
