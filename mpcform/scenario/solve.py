"""The solve strategy a scenario's ``[controller]`` table asks for (:mod:`mpcform.mpc.strategy`):
its ``[controller.solve]`` table, or the last release's keys with a deprecation line each."""

from __future__ import annotations

from typing import Any

from mpcform.errors import ScenarioError, SolverError
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.strategy import PerDroneSolve, SolveStrategy, SparseSolve, SplitPolicy
from mpcform.scenario.mpc_keys import DEPRECATED, SOLVE_TABLE
from mpcform.scenario.parse import parse_keys
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import DEFAULT_PER_DRONE_SOLVER, DEFAULT_SOLVER, check_solver_name


def solve_strategy(controller: dict[str, Any], coupling: str, deprecations: list[str]) -> SolveStrategy:
    """The solve strategy of a parsed mpc ``[controller]`` table: its ``solve`` table parsed against
    :data:`SOLVE_TABLE`, or the last release's keys (each adds a line to ``deprecations``). A
    per-drone solve with joint rows, a key the strategy would ignore or an unknown backend raise a
    :class:`ScenarioError` naming the key as written."""
    old = {k: controller[k] for k in DEPRECATED if controller.get(k) is not None}
    solve = controller.get("solve")
    if solve is not None and old:
        key = next(iter(old))
        message = f"give it as [controller.solve] {DEPRECATED[key]}, not beside a [controller.solve] table"
        raise ScenarioError(f"controller.{key}", message)
    if solve is None and not old:
        return MPCSettings(coupling=coupling).strategy
    values = _from_old(old, coupling, deprecations) if solve is None else _parse(solve, coupling)
    backend = values["backend"]
    if values["kind"] == "per_drone":
        split = SplitPolicy(values["split_iterations"], values["stalled_split"], values["split_budget"])
        strategy: SolveStrategy = PerDroneSolve(
            backend or DEFAULT_PER_DRONE_SOLVER, values["max_iter"], split
        )
    else:
        options = SolverOptions(
            values["eps_abs"], values["eps_rel"], values["max_iter"], values["time_limit"]
        )
        strategy = SparseSolve(backend or DEFAULT_SOLVER, options)
    try:
        check_solver_name(strategy.backend, per_drone=isinstance(strategy, PerDroneSolve))
    except SolverError as exc:
        raise ScenarioError(values["backend_key"], str(exc)) from None
    return strategy


def _parse(solve: dict[str, Any], coupling: str) -> dict[str, Any]:
    """The keys of a ``[controller.solve]`` table, its kind fitting ``coupling``."""
    values = parse_keys(SOLVE_TABLE, solve, "controller.solve", 2, None)
    if values["kind"] == "per_drone" and coupling != "decoupled":
        raise ScenarioError(
            "controller.solve.kind",
            f"'per_drone' needs coupling = 'decoupled' (joint pair rows couple the drones), got {coupling!r}",
        )
    return {**values, "backend_key": "controller.solve.backend"}


def _from_old(old: dict[str, Any], coupling: str, deprecations: list[str]) -> dict[str, Any]:
    """The ``[controller.solve]`` keys that the last release's ``[controller]`` keys ``old`` stand
    for (each refused where the strategy would ignore it)."""
    if "per_drone" in old and coupling != "decoupled":
        raise ScenarioError(
            "controller.per_drone", f"applies only to coupling = 'decoupled', got {coupling!r}"
        )
    kind = "per_drone" if coupling == "decoupled" and old.get("per_drone", True) else "sparse"
    table: dict[str, Any] = {"kind": kind}
    for key, value in old.items():
        new = DEPRECATED[key]
        if new == "kind":
            deprecations.append(f'controller.{key} is deprecated: write [controller.solve] kind = "{kind}"')
            continue
        applies = SOLVE_TABLE.key(new).when
        if applies and kind not in applies:
            other = "sparse" if kind == "per_drone" else "per_drone"
            raise ScenarioError(
                f"controller.{key}",
                f"does not apply to this {kind.replace('_', '-')} solve ({_why(kind, coupling)}); it "
                f'applies to [controller.solve] kind = "{other}"',
            )
        if key == "solver" and kind == "per_drone":
            raise ScenarioError(
                "controller.solver",
                f"{value!r} solves the sparse QP, but coupling = 'decoupled' solves each drone's QP "
                f'with {DEFAULT_PER_DRONE_SOLVER!r} here; write [controller.solve] kind = "sparse", '
                f"backend = {value!r} to use it",
            )
        deprecations.append(f"controller.{key} is deprecated: write [controller.solve] {new} = {value!r}")
        table[new] = value
    return {**parse_keys(SOLVE_TABLE, table, "controller.solve", 2, None), "backend_key": "controller.solver"}


def _why(kind: str, coupling: str) -> str:
    if kind == "sparse":
        return f"coupling = {coupling!r}" if coupling != "decoupled" else "per_drone = false"
    return "coupling = 'decoupled' solves each drone's QP on its own"
