"""The run metrics of DESIGN.md section 5, computed from a :class:`SimulationResult`."""

from __future__ import annotations

from typing import Any

import numpy as np

from mpcform.formation.geometry import min_pair_distance, min_segment_distance, pairs_within
from mpcform.sim.simulation import SimulationResult

REL_TOL = 1e-9  # violations are counted beyond this relative tolerance


def run_metrics(result: SimulationResult, v_max_mps: float | None, d_min_m: float | None) -> dict[str, Any]:
    """Tracking, separation, speed, solver and timing metrics of one run (JSON-ready)."""
    err = np.linalg.norm(result.positions_m - result.reference_m, axis=-1).max(axis=1)
    speed = np.linalg.norm(result.commands_mps, axis=-1)
    pos = result.positions_m
    sample_min = min(min_pair_distance(p) for p in pos)
    seg_min = min(min_segment_distance(a, b) for a, b in zip(pos[:-1], pos[1:], strict=True))
    sep_viol = 0
    if d_min_m is not None:
        limit = d_min_m * (1.0 - REL_TOL)
        sep_viol = sum(pairs_within(p, limit).shape[0] for p in pos)
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
        "max_slack": float(max((i.max_slack_m for i in result.infos), default=0.0)),
        "step_time_ms": {
            mode: _stats(1e3 * result.step_times_s[modes == mode]) for mode in sorted(set(modes.tolist()))
        },
    }


def _stats(ms: np.ndarray) -> dict[str, float]:
    return {
        "median": float(np.median(ms)),
        "p90": float(np.percentile(ms, 90)),
        "max": float(ms.max()),
    }


def _finite_or_none(x: float) -> float | None:
    return float(x) if np.isfinite(x) else None
