"""Side-by-side metrics of several saved runs (``mpcform compare``): records and a markdown table."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from mpcform.outputs.rundata import RunData
from mpcform.sim.metrics import tracking_cost_m2s

COLUMNS = (
    ("run", "run"),
    ("controller", "controller"),
    ("solver", "solver"),
    ("final_tracking_error", "final error [m]"),
    ("max_tracking_error", "max error [m]"),
    ("tracking_cost", "tracking cost [m^2 s]"),
    ("min_separation_segments", "min separation [m]"),
    ("max_speed", "max speed [m/s]"),
    ("violations", "violations (sep/speed)"),
    ("qp_solves", "QP solves"),
    ("fast_path_steps", "fast-path steps"),
    ("solver_failures", "failures"),
    ("step_mode", "steps timed"),
    ("step_ms_median", "step median [ms]"),
    ("step_ms_p90", "step p90 [ms]"),
)


def run_labels(runs: Sequence[RunData]) -> list[str]:
    """Each run's label; runs sharing one also get their directory name."""
    labels = [r.label for r in runs]
    return [
        f"{lab} [{r.directory.name}]" if labels.count(lab) > 1 else lab
        for lab, r in zip(labels, runs, strict=True)
    ]


def comparison_records(runs: Sequence[RunData]) -> list[dict[str, Any]]:
    """One record per run: identity, the main metrics and the step times over all steps."""
    records = []
    for label, run in zip(run_labels(runs), runs, strict=True):
        s, m = run.summary, run.summary.get("metrics", {})
        times = m.get("step_time_ms") or {}
        # step times of the QP steps when there are any, else of the run's (first) other mode
        mode = "qp" if "qp" in times else next(iter(times), None)
        stats = times.get(mode) or {}
        records.append(
            {
                "run": label,
                "directory": str(run.directory),
                "scenario": run.name,
                "controller": s.get("controller"),
                "solver": s.get("solver"),
                "final_tracking_error": m.get("final_tracking_error"),
                "max_tracking_error": m.get("max_tracking_error"),
                "tracking_cost": tracking_cost_m2s(run.trajectory),
                "min_separation_segments": m.get("min_separation_segments"),
                "max_speed": m.get("max_speed"),
                "violations": f"{m.get('separation_violations', '-')}/{m.get('speed_violations', '-')}",
                "qp_solves": m.get("qp_solves"),
                "fast_path_steps": m.get("fast_path_steps"),
                "solver_failures": m.get("solver_failures"),
                "step_mode": mode,
                "step_ms_median": stats.get("median"),
                "step_ms_p90": stats.get("p90"),
            }
        )
    return records


def markdown_table(records: Sequence[dict[str, Any]]) -> str:
    """The records as a markdown table (columns :data:`COLUMNS`)."""
    lines = [
        "| " + " | ".join(title for _, title in COLUMNS) + " |",
        "| " + " | ".join("---" for _ in COLUMNS) + " |",
    ]
    for rec in records:
        lines.append("| " + " | ".join(_cell(rec.get(key)) for key, _ in COLUMNS) + " |")
    return "\n".join(lines)


def _cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value).replace("|", "\\|")
