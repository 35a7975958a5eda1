"""``mpcform sweep``: one scenario file run over a grid of seeds and parameter values, in parallel.

A job is one scenario run: the TOML document with the job's overrides (``--set KEY=V1,V2`` over
dotted keys, e.g. ``controller.horizon=5,10``, parsed by :mod:`mpcform.cli.sweep_commands`) and
its top-level ``seed``. Jobs are the Cartesian product of the seeds and every ``--set`` list (at
most :data:`MAX_RUNS`). A seed changes the initial
``perturbation`` and the simulation ``noise`` (both seeded); a scenario with neither gives the
same run for every seed.

Jobs run in worker processes (:class:`~concurrent.futures.ProcessPoolExecutor`, spawned, one
thread of BLAS each; see :mod:`mpcform.run.parallel`): QP solver objects cannot be pickled, so a
worker loads and runs a whole scenario and returns a plain record. ``executor="dask"`` sends
the same jobs to a dask.distributed cluster (``pip install "dask[distributed]"``).

A run is a **success** when it raised nothing, no sample pair is closer than ``d_min`` and
no pair along the straight segments either (``min_separation_segments``; where ``d_min`` is
set), no command exceeds ``v_max``, and the final tracking error (max over drones of
``||p_i - p*_i||``) is at most the tolerance.
"""

from __future__ import annotations

import copy
import itertools
import math
import time
import tomllib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mpcform.errors import SolverError, ValidationError
from mpcform.outputs import tables
from mpcform.run.parallel import process_pool, single_threaded_env
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import load_scenario, scenario_from_dict, scenario_text
from mpcform.scenario.size import check_memory, check_work, read_scenario_bytes
from mpcform.scenario.spec import Scenario
from mpcform.sim.metrics import REL_TOL
from mpcform.solvers.registry import check_solver_name

EXECUTORS = ("process", "dask")
DEFAULT_TOLERANCE_M = 0.1
MAX_RUNS = 100_000
"""The most runs a sweep may have (seeds x every ``--set`` list): its job list is built at once, and
a sweep of that many runs of the smallest scenario already takes hours."""

Override = tuple[str, Any]


@dataclass(frozen=True)
class SweepJob:
    """One run: the scenario file, its overrides (dotted key, value) and its seed (None: the file's)."""

    path: str
    overrides: tuple[Override, ...]
    seed: int | None
    solver: str | None = None
    tolerance_m: float = DEFAULT_TOLERANCE_M


# ---- jobs ------------------------------------------------------------------------------------
def build_jobs(
    path: str | Path,
    seeds: Sequence[int] | None,
    sets: Sequence[tuple[str, Sequence[Any]]],
    solver: str | None = None,
    tolerance_m: float = DEFAULT_TOLERANCE_M,
) -> list[SweepJob]:
    """The Cartesian product of the ``--set`` lists and the seeds (None: the file's seed)."""
    if not 0.0 <= tolerance_m < float("inf"):
        raise ValidationError("--tol", f"expected a final tracking error >= 0 [m], got {tolerance_m!r}")
    if solver is not None:  # a bad name is one error now, not a failed row per job
        try:
            check_solver_name(solver)
        except SolverError as exc:
            raise ValidationError("--solver", str(exc)) from None
    keys = [key for key, _ in sets]
    if len(set(keys)) != len(keys):
        raise ValidationError("--set", f"a key is given twice: {keys}")
    sizes = [len(seeds) if seeds else 1, *(len(values) for _, values in sets)]
    if (runs := math.prod(sizes)) > MAX_RUNS:
        flag = "--seeds" if sizes[0] == max(sizes) else "--set"
        counts = " x ".join(f"{s:,}" for s in sizes)
        raise ValidationError(
            flag, f"the sweep would make {runs:,} runs ({counts}), above the limit of {MAX_RUNS:,}"
        )
    combos = itertools.product(*[values for _, values in sets])
    return [
        SweepJob(str(path), tuple(zip(keys, combo, strict=True)), seed, solver, tolerance_m)
        for combo in combos
        for seed in (seeds if seeds else [None])
    ]


def load_job(job: SweepJob, max_memory_gib: float | None = None) -> Scenario:
    """The job's scenario: the file with its overrides and seed, validated (``max_memory_gib``:
    see :func:`~mpcform.scenario.load.scenario_from_dict`)."""
    base = load_scenario(
        job.path, max_memory_gib=max_memory_gib
    )  # readable, valid TOML (errors name the file)
    data = tomllib.loads(scenario_text(read_scenario_bytes(job.path)))
    data = apply_overrides(data, job.overrides + ((("seed", job.seed),) if job.seed is not None else ()))
    return scenario_from_dict(
        data,
        source=base.source,
        source_sha256=base.source_sha256,
        default_name=Path(job.path).stem,
        max_memory_gib=max_memory_gib,
    )


def apply_overrides(data: Mapping[str, Any], overrides: Iterable[Override]) -> dict[str, Any]:
    """A deep copy of the TOML document with each dotted key set (missing tables are created)."""
    out = copy.deepcopy(dict(data))
    for key, value in overrides:
        node: Any = out
        parts = key.split(".")
        for depth, part in enumerate(parts[:-1]):
            node = _child(node, part, key, depth)
        last = parts[-1]
        if isinstance(node, list):
            node[_index(node, last, key)] = value
        elif isinstance(node, dict):
            node[last] = value
        else:
            raise ValidationError("--set", f"{key}: {'.'.join(parts[:-1])} is not a table")
    return out


def _child(node: Any, part: str, key: str, depth: int) -> Any:
    if isinstance(node, list):
        return node[_index(node, part, key)]
    if not isinstance(node, dict):
        raise ValidationError("--set", f"{key}: {'.'.join(key.split('.')[:depth])} is not a table")
    return node.setdefault(part, {})


def _index(node: list[Any], part: str, key: str) -> int:
    if not part.isdigit() or int(part) >= len(node):
        raise ValidationError("--set", f"{key}: {part!r} is not an index of a list of {len(node)}")
    return int(part)


def run_job(job: SweepJob) -> dict[str, Any]:
    """Run one job (in a worker) and return its record; an error is recorded, never raised."""
    record: dict[str, Any] = {"table": "runs", "params": dict(job.overrides), "seed": job.seed}
    start = time.perf_counter()
    try:
        scenario = load_job(job)
        record["seed"] = scenario.seed
        run = run_scenario(scenario, None, solver=job.solver)
    except Exception as exc:  # noqa: BLE001 - one failed job must not end the sweep
        record.update(
            success=False,
            error=f"{type(exc).__name__}: {' '.join(str(exc).split())}",
            failed_checks=["error"],
            wall_s=time.perf_counter() - start,
        )
        return record
    m, sim = run.summary["metrics"], run.simulation
    record.update(
        {
            key: m[key]
            for key in (
                "final_tracking_error",
                "max_tracking_error",
                "min_separation",
                "min_separation_segments",
                "max_speed",
                "separation_violations",
                "speed_violations",
                "qp_solves",
                "fast_path_steps",
                "solver_failures",
                "max_slack",
                "completion",
            )
        }
    )
    modes = np.array([info.mode for info in sim.infos])
    ms = 1e3 * sim.step_times_s
    qp = ms[(modes == "qp") | (modes == "fallback")]
    record["step_ms_median"] = float(np.median(ms))
    record["qp_ms_median"] = float(np.median(qp)) if qp.size else float("nan")
    record["qp_ms_p90"] = float(np.percentile(qp, 90)) if qp.size else float("nan")
    d_min = scenario.limits.d_min_m
    seg = m["min_separation_segments"]
    separated = d_min is None or seg is None or seg >= d_min * (1.0 - REL_TOL)
    checks = {
        "separation": m["separation_violations"] > 0 or not separated,
        "speed": m["speed_violations"] > 0,
        "tracking": m["final_tracking_error"] > job.tolerance_m,
        "completion": m["completion"] < 1.0,
    }
    record["error"] = None
    record["failed_checks"] = [name for name, failed in checks.items() if failed]
    record["success"] = not record["failed_checks"]
    record["wall_s"] = time.perf_counter() - start
    return record


# ---- running ---------------------------------------------------------------------------------
def run_sweep(
    jobs: Sequence[SweepJob],
    workers: int = 1,
    executor: str = "process",
    scheduler: str | None = None,
    progress: Callable[[int, int], None] | None = None,
    max_memory_gib: float | None = None,
    max_work: float | None = None,
) -> list[dict[str, Any]]:
    """Run every job and return the records in job order.

    ``workers == 1`` with the process executor runs in this process (no pool). Every distinct
    parameter combination is validated here first, so a bad ``--set`` fails before any run, and
    so does a run estimated to need more than ``max_memory_gib`` GiB or a plant's work above
    ``max_work`` (None: no limit; see :mod:`mpcform.scenario.size`).
    """
    if executor not in EXECUTORS:
        raise ValidationError("--executor", f"expected one of {EXECUTORS}, got {executor!r}")
    if workers < 1:
        raise ValidationError("--jobs", f"expected an integer >= 1, got {workers}")
    for overrides in {repr(j.overrides): j.overrides for j in jobs}.values():  # list values: unhashable
        scenario = load_job(SweepJob(jobs[0].path, overrides, jobs[0].seed), max_memory_gib)
        if max_memory_gib is not None:
            check_memory(scenario, max_memory_gib, files=False)
        if max_work is not None:
            check_work(scenario, max_work)
    results: list[dict[str, Any] | None] = [None] * len(jobs)
    done = 0
    for index, record in _execute(jobs, workers, executor, scheduler):
        results[index] = record
        done += 1
        if progress is not None:
            progress(done, len(jobs))
    return [r for r in results if r is not None]


def _execute(
    jobs: Sequence[SweepJob], workers: int, executor: str, scheduler: str | None
) -> Iterator[tuple[int, dict[str, Any]]]:
    if executor == "dask":
        yield from _execute_dask(jobs, workers, scheduler)
    elif workers == 1:
        for index, job in enumerate(jobs):
            yield index, run_job(job)
    else:
        with process_pool(workers) as pool:
            futures = {pool.submit(run_job, job): index for index, job in enumerate(jobs)}
            for future in as_completed(futures):
                yield futures[future], future.result()


def _execute_dask(
    jobs: Sequence[SweepJob], workers: int, scheduler: str | None
) -> Iterator[tuple[int, dict[str, Any]]]:
    """On the dask.distributed cluster at ``scheduler`` (or a local one of ``workers`` processes)."""
    try:
        from dask.distributed import Client, LocalCluster
        from dask.distributed import as_completed as dask_completed
    except ImportError:
        raise ValidationError(
            "--executor", 'dask needs dask.distributed: pip install "dask[distributed]"'
        ) from None
    cluster = None
    if scheduler is None:  # its spawned workers inherit single-threaded BLAS
        with single_threaded_env():
            cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True)
    client = Client(scheduler if cluster is None else cluster)
    try:
        futures = client.map(run_job, list(jobs), pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        for future in dask_completed(futures):
            yield index[future.key], future.result()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


# ---- aggregation -----------------------------------------------------------------------------
def aggregate(records: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """One record per parameter combination (over its seeds), in first-seen order.

    Times are medians over the runs of each run's median (or p90); separation is the minimum
    over runs, tracking errors the median and the maximum over runs that finished.
    """
    groups: dict[tuple[tuple[str, str], ...], list[dict[str, Any]]] = {}
    for r in records:
        groups.setdefault(tuple((k, repr(v)) for k, v in r["params"].items()), []).append(r)
    out = []
    for runs in groups.values():
        ok = [r for r in runs if r.get("error") is None]
        wins = sum(bool(r["success"]) for r in runs)

        def values(key: str, rs: list[dict[str, Any]] = ok) -> list[float]:
            return [float(r[key]) for r in rs if r.get(key) is not None and np.isfinite(r[key])]

        final, seps = values("final_tracking_error"), values("min_separation_segments")
        out.append(
            {
                "table": "groups",
                "params": runs[0]["params"],
                "runs": len(runs),
                "successes": wins,
                "success_rate": wins / len(runs),
                "errors": len(runs) - len(ok),
                "min_separation_segments": min(seps, default=float("nan")),
                "final_tracking_error_median": _median(final),
                "final_tracking_error_max": max(final, default=float("nan")),
                "max_tracking_error": max(values("max_tracking_error"), default=float("nan")),
                "separation_violations": int(sum(values("separation_violations"))),
                "speed_violations": int(sum(values("speed_violations"))),
                "solver_failures": int(sum(values("solver_failures"))),
                "step_ms_median": _median(values("step_ms_median")),
                "qp_ms_median": _median(values("qp_ms_median")),
                "qp_ms_p90": _median(values("qp_ms_p90")),
                "wall_s": float(sum(values("wall_s", runs))),
            }
        )
    return out


def _median(xs: list[float]) -> float:
    return float(np.median(xs)) if xs else float("nan")


def params_text(params: Mapping[str, Any]) -> str:
    """``key=value, ...`` (``-`` for none)."""
    return ", ".join(f"{k}={v}" for k, v in params.items()) or "-"


COLUMNS = [
    ("params", "parameters", "{}"),
    ("runs", "runs", "{}"),
    ("success_rate", "success", "{:.0%}"),
    ("errors", "errors", "{}"),
    ("min_separation_segments", "min sep [m]", "{:.3f}"),
    ("final_tracking_error_median", "final err med [m]", "{:.3f}"),
    ("final_tracking_error_max", "final err max", "{:.3f}"),
    ("max_tracking_error", "max err", "{:.3f}"),
    ("solver_failures", "fallbacks", "{}"),
    ("step_ms_median", "step med [ms]", "{:.2f}"),
    ("qp_ms_median", "QP med [ms]", "{:.2f}"),
    ("qp_ms_p90", "QP p90", "{:.2f}"),
    ("wall_s", "wall [s]", "{:.1f}"),
]


def markdown_table(groups: Sequence[dict[str, Any]]) -> str:
    """The groups as a markdown table (NaN shown as ``-``)."""
    return tables.markdown_table(groups, COLUMNS, {"params": lambda v: params_text(v or {})})


def failures_text(records: Sequence[dict[str, Any]]) -> str:
    """One line per failed run: its parameters, seed and why (its error, or the checks it failed)."""
    lines = []
    for r in records:
        if r["success"]:
            continue
        why = r.get("error") or "failed " + ", ".join(r["failed_checks"])
        lines.append(f"- {params_text(r['params'])} seed {r['seed']}: {why}")
    return "\n".join(lines)
