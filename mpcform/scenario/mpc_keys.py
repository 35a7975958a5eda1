"""The mpc controller's keys of ``[controller]`` and its solve table ``[controller.solve]``.

``[controller.solve]`` names the solve strategy (:mod:`mpcform.mpc.strategy`) with ``kind`` and
takes only the keys of that kind, so a setting the planner would ignore cannot be written. The
spellings of the last release in ``[controller]`` (``solver``, ``per_drone``, ``eps_abs``,
``split_iterations``, ...) still load, each with one deprecation line naming its new key
(:func:`mpcform.scenario.solve.solve_strategy`); a combination the code would ignore is refused
in either spelling.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from mpcform.mpc.settings import COUPLINGS, VELOCITY_SETS, MPCSettings
from mpcform.mpc.strategy import SOLVE_KINDS, PerDroneSolve, SparseSolve
from mpcform.scenario.key_types import Key, Table
from mpcform.solvers.registry import DEFAULT_PER_DRONE_SOLVER, DEFAULT_SOLVER

_MPC = ("mpc",)
_MPC_DEFAULTS = {f.name: f.default for f in dataclasses.fields(MPCSettings)}
MPC_FIELDS = {
    "gain": "gain_per_s",
    "margin": "margin_m",
    "tie_break": "tie_break_rad",
    "step_budget": "step_budget_s",
}
"""Scenario key -> MPCSettings field (the remaining mpc keys share their name with the field)."""
_SPARSE, _PER_DRONE = SparseSolve(), PerDroneSolve()
_SPARSE_ONLY, _PER_DRONE_ONLY = ("sparse",), ("per_drone",)
DEPRECATED = {
    "solver": "backend",
    "per_drone": "kind",
    "eps_abs": "eps_abs",
    "eps_rel": "eps_rel",
    "max_iter": "max_iter",
    "time_limit": "time_limit",
    "split_iterations": "split_iterations",
    "split_budget": "split_budget",
    "stalled_split": "stalled_split",
}
"""The last release's ``[controller]`` keys -> their key in ``[controller.solve]``."""


def _mpc_key(name: str, type_: str, doc: str, unit: str = "", **kw: Any) -> Key:
    default = _MPC_DEFAULTS[MPC_FIELDS.get(name, name)]
    return Key(name, type_, doc, unit, default, when=_MPC, **kw)


def _old_key(name: str, type_: str, **kw: Any) -> Key:
    new = DEPRECATED[name]
    doc = f"Deprecated: `[controller.solve]` `{new}`" + (
        " (`per_drone` or `sparse`)." if new == "kind" else "."
    )
    return Key(name, type_, doc, when=_MPC, **kw)


MPC_KEYS: tuple[Key, ...] = (
    _mpc_key("horizon", "int", "Plan length H in steps.", bound=">= 1"),
    _mpc_key("velocity_set", "string", "Speed constraint set inscribed in the ball.",
             choices=VELOCITY_SETS),
    _mpc_key("facets", "int", "Half-spaces of the velocity polytope (auto: 16 planar, "
             "32 spatial).", bound=">= 4", shown_default="auto"),
    _mpc_key("slack_weight", "float", "Exact L1 penalty on separation slack.", "1/m",
             bound="> 0"),
    _mpc_key("slack_quadratic", "float", "Quadratic slack penalty (conditioning).", "1/m^2",
             bound=">= 0"),
    _mpc_key("margin", "float", "Tightening of separation and obstacle rows.", "m",
             bound=">= 0"),
    _mpc_key("tie_break", "float", "Right turn of conflicted drones' desired velocities, "
             "so symmetric swaps circulate; grows while a drone stays stalled (0: off).", "rad",
             bound=">= 0"),
    _mpc_key("coupling", "string", "`joint` pair rows, or `decoupled` per-drone rows about "
             "the pair midpoint (block-diagonal QP, for large swarms).", choices=COUPLINGS),
    _mpc_key("grouping", "bool", "Solve only the groups of drones that hold a conflict; the others "
             "take their eq. 14 rollout (exact)."),
    _mpc_key("fast_path", "bool", "Skip the solver when the eq. 14 rollout meets every row."),
    _mpc_key("plant_model", "bool", "With a `lag`, `second_order` or `quadrotor` plant (its hover "
             "linearisation): separation rows on where its velocity loop really takes the drones "
             "(a braking drone overshoots its commands), with the last interval's velocity offset "
             "(wind) estimated, held over the plan and cancelled in the command (offset-free: "
             "eq. 14 less the offset when no row is active)."),
    _mpc_key("braking", "bool", "End every plan where the drones can still stop, braking within "
             "`limits.a_max` or its default (the plans' terminal condition: a horizon shorter "
             "than the braking keeps d_min; off with `limits.a_max = inf`)."),
    _mpc_key("step_budget", "float", "Deadline of one step (online planning): no split round "
             "starts too close to it (counted in `budget_cuts`, the only steps the machine's load "
             "can change), and a step that ends later still sends its certified command (counted "
             "in `deadline_misses`). Unset: none.", "s",
             bound="> 0"),
    Key("solve", "table", "`[controller.solve]`: how the QP is solved (below).", when=_MPC),
    _old_key("solver", "string"),
    _old_key("per_drone", "bool"),
    _old_key("eps_abs", "float", bound="> 0"),
    _old_key("eps_rel", "float", bound=">= 0"),
    _old_key("max_iter", "int", bound=">= 1"),
    _old_key("time_limit", "float", unit="s", bound=">= 0"),
    _old_key("split_iterations", "int", bound=">= 0"),
    _old_key("split_budget", "float", unit="s", bound="> 0"),
    _old_key("stalled_split", "int", bound=">= 0"),
)  # fmt: skip # keys read best with their text aligned under them
"""The mpc controller's keys of ``[controller]``."""

SOLVE_TABLE = Table(
    "controller.solve",
    "How the mpc controller solves its QP (the solve strategy; `coupling` chooses the rows). "
    "Absent: `per_drone` when `coupling = \"decoupled\"`, else `sparse`, with the defaults below.",
    (
        Key("kind", "string", "`sparse`: one sparse QP with `backend` (either coupling); `per_drone` "
            "(`coupling = \"decoupled\"` only): each conflicted drone's small dense QP.",
            required=True, choices=SOLVE_KINDS),
        Key("backend", "string", "QP backend: sparse `osqp`, `piqp`, `qpsolvers:<name>`, "
            "`casadi:<plugin>`; per drone `daqp` or `qpsolvers:<name>` (see `mpcform solvers`). "
            "`mpcform run --solver` overrides a sparse one.",
            shown_default=f'"{DEFAULT_SOLVER}" (sparse), "{DEFAULT_PER_DRONE_SOLVER}" (per_drone)'),
        Key("eps_abs", "float", "Absolute tolerance.", default=_SPARSE.options.eps_abs,
            when=_SPARSE_ONLY, bound="> 0"),
        Key("eps_rel", "float", "Relative tolerance.", default=_SPARSE.options.eps_rel,
            when=_SPARSE_ONLY, bound=">= 0"),
        Key("time_limit", "float", "Time limit per QP (0: none).", "s",
            default=_SPARSE.options.time_limit_s, when=_SPARSE_ONLY, bound=">= 0"),
        Key("max_iter", "int", "Iteration limit per QP (per drone: per drone's QP).",
            default=_PER_DRONE.max_iter, bound=">= 1"),
        Key("split_iterations", "int", "Rounds that move each pair row's split point from the "
            "midpoint towards the joint optimum at every step (every round's plans meet the joint "
            "pair rows; 0: the midpoint split).", default=_PER_DRONE.split.iterations,
            when=_PER_DRONE_ONLY, bound=">= 0"),
        Key("stalled_split", "int", "With `split_iterations = 0`: split rounds in the steps where "
            "a drone is stalled in conflict (rings the midpoint split jams pass; 0: never).",
            default=_PER_DRONE.split.stalled, when=_PER_DRONE_ONLY, bound=">= 0"),
        Key("split_budget", "float", "Wall time of a step's split rounds after which no new round "
            "starts.", "s", when=_PER_DRONE_ONLY, bound="> 0", shown_default="none"),
    ),
    required=False,
    selector="kind",
)  # fmt: skip # keys read best with their text aligned under them
