"""``mpcform bench split``: the iterated split's QP cost against rounds and time
(:mod:`mpcform.mpc.solve.split`).

Each scenario is flown by the decoupled planner with ``split_iterations = max(rounds)`` (ideal
plant) for ``steps`` steps; every QP it solves is solved again with its split history recorded
(the best QP objective ``sum_i 0.5 ||v_i - c_i||^2`` after each round, and the wall and CPU time
so far) and as the joint QP with the same rows (same normals, the sides' bounds added) by
Clarabel at 1e-9 and by the planner's joint backend (PIQP, for its time). A row per scenario and
number of rounds: the mean wall and CPU milliseconds per QP step, and the mean and largest cost
gap to the joint optimum; the figure plots the mean gap against rounds and against CPU time.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from mpcform.errors import ScenarioError
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.solve.problem import StepQP
from mpcform.mpc.solve.sparse import SparseSolver
from mpcform.mpc.solve.split import SplitQP
from mpcform.mpc.strategy import PerDroneSolve, SplitPolicy, as_sparse
from mpcform.scenario.build import build_controller
from mpcform.scenario.load import load_scenario
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import DEFAULT_SOLVER, make_backend

DEFAULT_SCENARIOS = (
    "scenarios/swap_planar_8.toml",
    "scenarios/swap_spatial_12.toml",
    "scenarios/swap_spatial_20.toml",
)
DEFAULT_ROUNDS = (0, 1, 2, 5, 10, 20, 50)
ACCURATE = SolverOptions(1e-9, 1e-9, 10_000, 0.0)
FLOOR_PCT = 1e-4  # the figure's lowest gap [%]


def record(path: str, rounds: int, steps: int | None) -> tuple[MPCPlanner, list[StepQP]]:
    """Fly ``path`` decoupled with ``rounds`` split rounds; the planner and the QPs it solved."""
    sc = load_scenario(path)
    per_drone = PerDroneSolve(split=SplitPolicy(iterations=max(rounds, 1)))
    mpc = replace(sc.controller.mpc, coupling="decoupled", solve=per_drone)
    sc = replace(sc, controller=replace(sc.controller, mpc=mpc))
    planner = build_controller(sc, "mpc")
    if not isinstance(planner, MPCPlanner):  # build_controller makes the kind asked for
        raise ScenarioError("controller.kind", f"bench split flies the mpc planner, got {planner.name!r}")
    qps: list[StepQP] = []
    solve = planner.step_solver.solve

    def keep(qp: StepQP) -> Any:
        qps.append(qp)
        return solve(qp)

    planner.step_solver.solve = keep  # type: ignore[method-assign]
    dt = sc.simulation.dt_s
    count = sc.steps if steps is None else steps
    p = sc.initial_positions_m.copy()
    planner.reset(0.0, p)
    for j in range(count):
        p = p + dt * planner.step(j * dt, p).command_mps
    return planner, [qp for qp in qps if (qp.rows.labels[:, 1] >= 0).any()]


def curves(planner: MPCPlanner, qps: list[StepQP], rounds: int) -> dict[str, Array]:
    """Per QP (Q,) and round (rounds + 1): the best cost, wall and CPU seconds; the joint optimum
    and the joint backend's wall seconds (Q,)."""
    st = planner.settings
    split = SplitQP(planner.step_solver.per_drone, rounds, None)  # type: ignore[attr-defined]
    sparse = as_sparse(st.strategy)
    joint_st = replace(st, coupling="joint", solve=sparse)
    args = (
        planner.dim,
        planner.dt_s,
        planner.limits,
        joint_st,
        planner.steps.families,
        planner.steps.separation,
    )
    accurate = SparseSolver(make_backend("qpsolvers:clarabel", ACCURATE), *args)
    fast = SparseSolver(make_backend(DEFAULT_SOLVER, sparse.options), *args)
    out: dict[str, list[Any]] = {"cost": [], "wall": [], "cpu": [], "joint": [], "joint_wall": []}
    for qp in qps:
        hist = split.run(qp).history
        pad = np.vstack([hist, np.repeat(hist[-1:], rounds + 1 - hist.shape[0], axis=0)])
        pad[hist.shape[0] :, 1:] = hist[-1, 1:]  # stopped early (converged): no more time
        joint = replace(qp, given_rows=qp.rows.joint(), on_only=None, warm=None, rebuilt=True)
        accurate.reset()
        sol, _ = accurate.solve(joint)
        fast.reset()
        t0 = time.perf_counter()
        fast.solve(joint)
        out["joint_wall"].append(time.perf_counter() - t0)
        out["cost"].append(pad[:, 0])
        out["wall"].append(pad[:, 1])
        out["cpu"].append(pad[:, 2])
        out["joint"].append(_objective(planner, joint, sol.x) if sol.x is not None else np.nan)
    return {k: np.array(v) for k, v in out.items()}


def _objective(planner: MPCPlanner, qp: StepQP, z: Array) -> float:
    """The QP objective of ``z`` (``[u | x | s]``) as the split history reports it."""
    st, m = planner.settings, qp.drones.shape[0]
    nud = st.horizon * m * planner.dim
    u, x = z[:nud].reshape(st.horizon, m, -1), z[nud : 2 * nud].reshape(st.horizon, m, -1)
    x = np.concatenate([np.zeros_like(x[:1]), x[:-1]])  # the cost's x_j, j < H (x_0 = 0)
    s = z[2 * nud :]
    track = 0.5 * float(np.sum((u + st.gain_per_s * x - qp.targets_mps) ** 2))
    return track + st.slack_weight * float(s.sum()) + 0.5 * max(st.slack_quadratic, 1e-6) * float(s @ s)


def run(
    scenarios: tuple[str, ...] = DEFAULT_SCENARIOS,
    rounds: tuple[int, ...] = DEFAULT_ROUNDS,
    steps: int | None = None,
    figure: str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """The table's rows (and the figure at ``figure``, a PNG); ``progress(label, i, n)`` is called
    as scenario ``i`` of ``n`` starts."""
    rows, drawn = [], []
    for i, path in enumerate(scenarios, 1):
        if progress is not None:
            label = f"{Path(path).stem} (decoupled, {max(rounds)} rounds; joint: clarabel, {DEFAULT_SOLVER})"
            progress(label, i, len(scenarios))
        planner, qps = record(path, max(rounds), steps)
        got = curves(planner, qps, max(rounds))
        gap = got["cost"] / got["joint"][:, None] - 1.0
        name = Path(path).stem
        drawn.append((name, gap.mean(axis=0), 1e3 * got["cpu"].mean(axis=0)))
        for k in rounds:
            rows.append(
                {
                    "scenario": name,
                    "rounds": k,
                    "qp_steps": len(qps),
                    "wall_ms": 1e3 * float(got["wall"][:, k].mean()),
                    "cpu_ms": 1e3 * float(got["cpu"][:, k].mean()),
                    "gap_mean_pct": 100 * float(gap[:, k].mean()),
                    "gap_max_pct": 100 * float(gap[:, k].max()),
                    "joint_wall_ms": 1e3 * float(got["joint_wall"].mean()),
                }
            )
    if figure:
        draw(drawn, figure)
    return rows


def draw(drawn: list[tuple[str, Array, Array]], path: str) -> None:
    """Mean cost gap [%] against rounds and against CPU time [ms] (the machine may be shared), one
    line per scenario; gaps below :data:`FLOOR_PCT` (the midpoint split already optimal) at it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (by_round, by_time) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for name, gap, wall in drawn:
        pct = np.maximum(100 * gap, FLOOR_PCT)
        by_round.semilogy(np.arange(pct.shape[0]), pct, marker=".", label=name)
        by_time.loglog(wall, pct, marker=".", label=name)
    by_round.set(xlabel="split rounds", ylabel="QP cost above the joint QP's [%], mean over steps")
    by_time.set(xlabel="CPU time per QP step [ms]", ylabel="QP cost above the joint QP's [%]")
    for ax in (by_round, by_time):
        ax.axhline(1.0, color="0.6", lw=0.8, ls="--")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.suptitle(f"Iterated split points (round 0: the midpoint split; below {FLOOR_PCT:g} %: at it)")
    fig.savefig(path, dpi=120)
    plt.close(fig)


def markdown_table(rows: list[dict[str, Any]]) -> str:
    """The rows as a markdown table."""
    head = (
        "| scenario | rounds | QP steps | wall ms/step | CPU ms/step | gap mean % | gap max % | "
        "joint (PIQP) ms/step |\n|---|---:|---:|---:|---:|---:|---:|---:|"
    )
    body = [
        f"| {r['scenario']} | {r['rounds']} | {r['qp_steps']} | {r['wall_ms']:.2f} | "
        f"{r['cpu_ms']:.2f} | {r['gap_mean_pct']:.4f} | {r['gap_max_pct']:.4f} | "
        f"{r['joint_wall_ms']:.2f} |"
        for r in rows
    ]
    return "\n".join([head, *body])


Array = np.ndarray
