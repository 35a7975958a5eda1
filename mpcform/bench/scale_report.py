"""The report of ``mpcform bench scale`` (:mod:`mpcform.bench.scale`): the cases' table, their CPU
times per step with the deadline misses and the bare solver floor, the growth exponents and the
acceptance targets of the scaling issue, each with what was measured."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mpcform.bench.growth import growth_exponent, growth_rows
from mpcform.bench.scale_cases import SCENARIOS
from mpcform.outputs import tables

COLUMNS = [
    ("scenario", "scenario", "{}"),
    ("n", "n", "{}"),
    ("mode", "mode", "{}"),
    ("steps_run", "steps", "{}"),
    ("qp_steps", "QP", "{}"),
    ("fast_path_steps", "fast", "{}"),
    ("fallback_steps", "fallback", "{}"),
    ("qp_drones_mean", "QP drones", "{:.0f}"),
    ("step_ms_median", "step med [ms]", "{:.2f}"),
    ("step_ms_p90", "step p90", "{:.2f}"),
    ("qp_ms_median", "QP med [ms]", "{:.2f}"),
    ("qp_ms_p90", "QP p90", "{:.2f}"),
    ("qp_cpu_ms_median", "QP CPU med", "{:.2f}"),
    ("qp_cpu_ms_p90", "QP CPU p90", "{:.2f}"),
    ("fast_ms_median", "fast med [ms]", "{:.2f}"),
    ("fast_ms_p90", "fast p90", "{:.2f}"),
    ("fast_cpu_ms_median", "fast CPU med", "{:.2f}"),
    ("rss_peak_mib", "peak RSS [MiB]", "{:.0f}"),
    ("rss_delta_mib", "RSS growth", "{:.0f}"),
    ("tracemalloc_peak_mib", "traced peak", "{:.0f}"),
    ("min_separation_segments", "min sep [m]", "{:.3f}"),
    ("note", "note", "{}"),
]

TIMING_COLUMNS = [
    ("scenario", "scenario", "{}"),
    ("n", "n", "{}"),
    ("mode", "mode", "{}"),
    ("steps_run", "steps", "{}"),
    ("cpu_ms_p50", "CPU p50 [ms]", "{:.2f}"),
    ("cpu_ms_p99", "CPU p99", "{:.2f}"),
    ("cpu_ms_max", "CPU max", "{:.2f}"),
    ("qp_cpu_ms_median", "QP CPU p50", "{:.2f}"),
    ("qp_cpu_ms_p99", "QP CPU p99", "{:.2f}"),
    ("qp_cpu_ms_max", "QP CPU max", "{:.2f}"),
    ("deadline_misses", "over dt", "{}"),
    ("solver_steps", "solver steps", "{}"),
    ("solved_ms_median", "their med [ms]", "{:.2f}"),
    ("solver_ms_median", "solver med [ms]", "{:.2f}"),
    ("solver_ratio", "step / solver", "{:.2f}"),
]
"""Every step's CPU time, then the QP steps'; steps whose wall time exceeded dt; the steps that
called the solver, their median wall time against the median wall time inside their solver calls
(the bare solver floor) and the ratio."""

GROWTH_COLUMNS = [
    ("scenario", "scenario", "{}"),
    ("mode", "mode", "{}"),
    ("step_exponent_fit", "step: fit n>=100", "{:.2f}"),
    ("step_exponent_100_1000", "step: 100->1000", "{:.2f}"),
    ("qp_exponent_fit", "QP step: fit n>=100", "{:.2f}"),
    ("qp_exponent_100_1000", "QP step: 100->1000", "{:.2f}"),
    ("qp_cpu_exponent_fit", "QP CPU: fit n>=100", "{:.2f}"),
    ("cpu_exponent_fit", "CPU p50: fit n>=100", "{:.2f}"),
    ("partial", "stopped early (n)", "{}"),
]


def markdown_table(rows: list[dict[str, Any]], columns: list[tuple[str, str, str]] | None = None) -> str:
    """The rows as a markdown table (missing or NaN entries shown as ``-``)."""
    return tables.markdown_table(rows, COLUMNS if columns is None else columns)


def target_lines(rows: list[dict[str, Any]], growth: list[dict[str, Any]], coupling: str) -> list[str]:
    """The acceptance targets of the scaling issue for the planner mode ``coupling``, each with what
    was measured (``-`` where not measured; cases stopped by their budget say so)."""

    def case(scenario: str, n: int) -> dict[str, Any]:
        match = [r for r in rows if (r["scenario"], r["n"], r["mode"]) == (scenario, n, coupling)]
        return match[0] if match and match[0].get("steps_run") else {}

    def num(value: float, fmt: str) -> str:
        return fmt.format(value) if np.isfinite(value) else "-"

    def verdict(value: float, limit: float, row: dict[str, Any] | None = None) -> str:
        if not np.isfinite(value):
            return "not measured"
        partial = row is not None and row["steps_run"] < row["steps"]
        return ("met" if value <= limit else "MISSED") + (f" ({row['note']})" if partial and row else "")

    form = case("formation", 1000)
    med, p90 = form.get("step_ms_median", math.nan), form.get("step_ms_p90", math.nan)
    lines = [
        f"formation n=1000 median step {num(med, '{:.1f}')} ms (p90 {num(p90, '{:.1f}')}) <= 100 ms: "
        f"{verdict(med, 100.0, form)}"
    ]
    cross = case("crossing", 100)
    qp = cross.get("qp_ms_median", math.nan)
    lines.append(f"crossing n=100 median QP step {num(qp, '{:.1f}')} ms <= 50 ms: {verdict(qp, 50.0, cross)}")
    for g in growth:
        if g["mode"] == coupling:
            e = g["step_exponent_100_1000"]
            partial = f" (from cases stopped early: n = {g['partial']})" if g["partial"] else ""
            text = f"{g['scenario']} growth exponent 100->1000 (median step) {num(e, '{:.2f}')} <= 1.2"
            lines.append(f"{text}: {verdict(e, 1.2)}{partial}")
    big = case("crossing", 1000)  # the performance targets (decoupled step at the solver floor)
    qp, qp_cpu = big.get("qp_ms_median", math.nan), big.get("qp_cpu_ms_median", math.nan)
    lines.append(
        f"crossing n=1000 median QP step {num(qp, '{:.1f}')} ms (CPU {num(qp_cpu, '{:.1f}')} ms) "
        f"<= 40 ms: {verdict(qp, 40.0, big)}"
    )
    p99 = big.get("qp_cpu_ms_p99", math.nan)
    lines.append(
        f"crossing n=1000 p99 QP step CPU {num(p99, '{:.1f}')} ms <= 100 ms: {verdict(p99, 100.0, big)}"
    )
    ratio, floor = big.get("solver_ratio", math.nan), big.get("solver_ms_median", math.nan)
    lines.append(
        f"crossing n=1000 ratio to the bare solver at the median {num(ratio, '{:.2f}')} (step "
        f"{num(big.get('solved_ms_median', math.nan), '{:.1f}')} ms, solver {num(floor, '{:.1f}')} ms) "
        f"<= 3: {verdict(ratio, 3.0, big)}"
    )
    for g in growth:
        if g["mode"] == coupling and g["scenario"] == "crossing":
            e = g.get("qp_cpu_exponent_fit", math.nan)
            lines.append(
                f"crossing growth exponent (median CPU per QP step, fit n>=100) {num(e, '{:.2f}')} "
                f"<= 1.1: {verdict(e, 1.1)}"
            )
    lines.append(f"formation n=1000 median step {num(med, '{:.2f}')} ms <= 2 ms: {verdict(med, 2.0, form)}")
    peaks = [case(s, 1000).get("rss_peak_mib", math.nan) for s in SCENARIOS]
    peak = max((x for x in peaks if np.isfinite(x)), default=math.nan)
    lines.append(f"peak RSS of the n=1000 runs {num(peak, '{:.0f}')} MiB <= 1 GiB: {verdict(peak, 1024.0)}")
    return lines


def report(rows: list[dict[str, Any]], coupling: str) -> tuple[str, list[dict[str, Any]]]:
    """Markdown (cases, their CPU times and solver floor, growth exponents, targets) and the growth
    records."""
    ran = [r for r in rows if r.get("steps_run")]
    growth = growth_rows(ran)
    for g in growth:  # the growth of the median CPU time per QP step and per step too
        case = [r for r in ran if (r["scenario"], r["mode"]) == (g["scenario"], g["mode"])]
        for key, name in (("qp_cpu_ms_median", "qp_cpu"), ("cpu_ms_p50", "cpu")):
            cpu_ms = [r.get(key, math.nan) for r in case]
            g[f"{name}_exponent_fit"] = growth_exponent([r["n"] for r in case], cpu_ms)
    text = "\n\n".join(
        [
            markdown_table(rows),
            markdown_table(rows, TIMING_COLUMNS),
            markdown_table(growth, GROWTH_COLUMNS),
            "\n".join(f"- {line}" for line in target_lines(rows, growth, coupling)),
        ]
    )
    return text, growth
