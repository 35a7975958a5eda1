"""``mpcform bench closed-loop``: each QP solver drives the same scenarios through the planner.

Each solver runs every scenario through :func:`mpcform.run.runner.run_scenario` with the
``mpc`` controller and that solver (in its own process, with a time limit per run): tracking
error, minimum separation along segments, slack, fallbacks and per-step times of QP steps. A
missing or unsupported solver is reported, not run.
Every scenario is loaded and its ``mpc`` controller built before the first run: an invalid one
is an error naming the file and key (no run starts), not a failed row per solver.
"""

from __future__ import annotations

import dataclasses
import multiprocessing as mp
import os
import time
from collections.abc import Callable, Sequence
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

from mpcform._validate import positive
from mpcform.bench.accuracy import default_solvers
from mpcform.bench.problems import DEFAULT_SCENARIOS
from mpcform.bench.report import shorten
from mpcform.bench.worker import BENCH_ENV
from mpcform.errors import MPCFormError, ScenarioError, ValidationError
from mpcform.outputs.tables import Column, markdown_table
from mpcform.scenario.build import build_controller
from mpcform.scenario.check import located_problem
from mpcform.scenario.load import load_scenario
from mpcform.scenario.spec import Scenario
from mpcform.solvers.registry import solver_info

CLOSED_LOOP_COLUMNS: list[Column] = [
    ("scenario", "scenario", "{}"),
    ("solver", "solver", "{}"),
    ("final_tracking_error_m", "final error [m]", "{:.2e}"),
    ("max_tracking_error_m", "max error [m]", "{:.3f}"),
    ("min_separation_m", "min separation [m]", "{:.4f}"),
    ("separation_violations", "violations", "{}"),
    ("max_slack_m", "max slack [m]", "{:.1e}"),
    ("qp_solves", "QP steps", "{}"),
    ("fallbacks", "fallbacks", "{}"),
    ("qp_step_median_ms", "QP step median [ms]", "{:.3g}"),
    ("qp_step_p90_ms", "p90 [ms]", "{:.3g}"),
    ("wall_s", "wall [s]", "{:.1f}"),
]


def load_bench_scenario(
    path: str | Path, duration_s: float | None = None, solver: str | None = None
) -> Scenario:
    """The scenario at ``path`` with its duration replaced by ``duration_s`` (if given), checked by
    building its ``mpc`` controller with ``solver`` (if given); errors name the file, key and line."""
    try:
        scenario = load_scenario(path)
        if duration_s is not None:
            duration_s, dt = positive("--duration", duration_s), scenario.simulation.dt_s
            if duration_s < dt:
                message = f"expected at least one step ({dt:g} s), got {duration_s:g} s"
                raise ValidationError("--duration", message)
            sim = dataclasses.replace(scenario.simulation, duration_s=duration_s)
            scenario = dataclasses.replace(scenario, simulation=sim)
        if solver is not None:
            build_controller(scenario, "mpc", solver)
    except ScenarioError as exc:
        raise MPCFormError(located_problem(exc, path).text(path)) from None
    return scenario


def _closed_loop_worker(conn: Connection, scenario: str, solver: str, duration_s: float | None) -> None:
    from mpcform.run.runner import run_scenario

    try:
        sc = load_bench_scenario(scenario, duration_s)
        start = time.perf_counter()
        run = run_scenario(sc, controller="mpc", solver=solver)
        conn.send(
            {
                "ok": True,
                "metrics": run.summary["metrics"],
                "wall_s": time.perf_counter() - start,
                "steps": run.summary["steps"],
                "scenario": sc.name,
            }
        )
    except Exception as exc:  # noqa: BLE001 - reported as this run's failure
        conn.send({"ok": False, "status": shorten(f"{type(exc).__name__}: {exc}", 300)})
    conn.close()


def run_closed_loop(
    scenarios: Sequence[str | Path] = DEFAULT_SCENARIOS[:2],
    solvers: Sequence[str] | None = None,
    timeout_s: float = 600.0,
    duration_s: float | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """Each solver drives each scenario (controller ``mpc``) in its own process; one record per run.
    ``progress(label, i, n)`` is called as run ``i`` of ``n`` starts (one not run too)."""
    infos = [solver_info(n) for n in (default_solvers() if solvers is None else solvers)]  # unknown: raises
    usable = next((info.name for info in infos if info.usable), None)
    for scenario in scenarios:  # an invalid scenario is an error here, not a failed row per solver
        load_bench_scenario(scenario, duration_s, usable)
    ctx = mp.get_context("spawn")
    rows: list[dict[str, Any]] = []
    os.environ.update(BENCH_ENV)
    for scenario in scenarios:
        for info in infos:
            name = info.name
            if progress is not None:
                why = "" if info.usable else f": not run, {shorten(info.note, 60)}"
                label = f"{Path(scenario).stem} ({name}{why})"
                progress(label, len(rows) + 1, len(scenarios) * len(infos))
            if not info.usable:  # missing or unsupported: reported, not run
                rows.append(_closed_loop_row(Path(scenario).stem, name, {"ok": False, "status": info.note}))
                continue
            receiver, sender = ctx.Pipe(duplex=False)
            proc = ctx.Process(
                target=_closed_loop_worker, args=(sender, str(scenario), name, duration_s), daemon=True
            )
            proc.start()
            sender.close()
            try:
                out = (
                    receiver.recv()
                    if receiver.poll(timeout_s)
                    else {"ok": False, "status": f"timeout ({timeout_s:g} s)"}
                )
            except EOFError:
                proc.join(1.0)
                out = {"ok": False, "status": f"crashed (exit code {proc.exitcode})"}
            if proc.is_alive():
                proc.kill()
            proc.join()
            receiver.close()
            rows.append(_closed_loop_row(Path(scenario).stem, name, out))
    return rows


def _closed_loop_row(scenario: str, solver: str, out: dict[str, Any]) -> dict[str, Any]:
    if not out["ok"]:
        return {"scenario": scenario, "solver": solver, "ok": False, "status": out["status"]}
    m = out["metrics"]
    qp_ms = m["step_time_ms"].get("qp", {})
    return {
        "scenario": scenario,
        "solver": solver,
        "ok": True,
        "status": "ok",
        "steps": out["steps"],
        "final_tracking_error_m": m["final_tracking_error"],
        "max_tracking_error_m": m["max_tracking_error"],
        "min_separation_m": m["min_separation_segments"],
        "separation_violations": m["separation_violations"],
        "max_slack_m": m["max_slack"],
        "qp_solves": m["qp_solves"],
        "fallbacks": m["solver_failures"],
        "qp_step_median_ms": qp_ms.get("median"),
        "qp_step_p90_ms": qp_ms.get("p90"),
        "wall_s": out["wall_s"],
    }


def _error_cell(value: Any) -> str:
    return value.replace("|", "\\|") if isinstance(value, str) else "-" if value is None else f"{value:.2e}"


def closed_loop_markdown(rows: Sequence[dict[str, Any]]) -> str:
    """The markdown table of a closed-loop benchmark."""
    out = [
        "# Closed-loop solver benchmark",
        "",
        "Each solver drives the scenario through `MPCPlanner(solver=...)` (the scenario's settings, one "
        "process per run). Tracking errors are max over drones of |p_i - p*_i| [m]; min separation is "
        "along the straight segments [m]; QP-step times exclude fast-path steps.",
        "",
    ]
    table = [
        r if r["ok"] else {**r, "final_tracking_error_m": f"failed: {shorten(r['status'], 100)}"}
        for r in rows
    ]
    out.append(markdown_table(table, CLOSED_LOOP_COLUMNS, {"final_tracking_error_m": _error_cell}))
    return "\n".join(out) + "\n"
