"""casadi conic backends: they solve the recorded problems to the reference, the planner gives
piqp's first input with each (without a_max), and hpipm is refused with a_max's rows."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from mpcform.errors import ValidationError
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend
from mpcform.world.limits import Limits

RECORDED: dict[str, dict[str, Any]] = {
    "casadi:osqp": dict(objective=1e-5, residual=1e-5, eps=1e-6),
    "casadi:proxqp": dict(objective=1e-4, residual=1e-4, eps=1e-6, problems=1),
    "casadi:daqp": dict(objective=1e-5, residual=1e-6, problems=1),
    "casadi:piqp": dict(objective=1e-8, residual=1e-8),
    "casadi:ipqp": dict(objective=1e-7, residual=1e-7, problems=1),
}
"""Tolerances on the relative objective gap and the primal residual, the eps given, and how many
of the small swap's problems (slow backends take one; hpipm none: their acceleration rows join
stages). qpOASES takes seconds per recorded QP here (see ``mpcform bench solvers``): it is
checked by the planner test only."""
FIRST_INPUT: dict[str, dict[str, Any]] = {
    "casadi:osqp": dict(tolerance_mps=2e-3, eps=1e-6),
    "casadi:qpoases": dict(tolerance_mps=1e-5),
    "casadi:proxqp": dict(tolerance_mps=1e-3, eps=1e-6),
    "casadi:daqp": dict(tolerance_mps=1e-4),
    "casadi:piqp": dict(tolerance_mps=1e-5),
    "casadi:ipqp": dict(tolerance_mps=1e-5),
    "casadi:hpipm": dict(tolerance_mps=1e-4),
}


@pytest.mark.parametrize("name", RECORDED)
def test_backend_solves_recorded_problems(name: str, solves_recorded: Callable[..., None]) -> None:
    solves_recorded(name, **RECORDED[name])


@pytest.mark.parametrize("name", FIRST_INPUT)
def test_planner_first_input_agrees(name: str, first_input_agrees: Callable[..., None]) -> None:
    first_input_agrees(name, **FIRST_INPUT[name])


def test_hpipm_reports_a_recorded_qp_it_cannot_put_in_stage_order(
    recorded: dict[str, list[Any]], require_usable: Callable[[str], None]
) -> None:
    require_usable("casadi:hpipm")
    qp = recorded["swap_planar_8"][0]
    backend = make_backend("casadi:hpipm", SolverOptions(1e-7, 1e-7, None))
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    backend.set_context(qp.context)
    sol = backend.solve()
    assert not sol.success and "no dynamics row (e.g. an acceleration limit)" in sol.status


def test_the_planner_refuses_hpipm_with_acceleration_rows(
    active_start: Any, require_usable: Callable[[str], None]
) -> None:
    """With a_max (the default too) hpipm is refused when the planner is built: its rows join two
    stages (hpipm's own stage-order check would fail every solve)."""
    require_usable("casadi:hpipm")
    ref, _, _ = active_start
    settings = MPCSettings(horizon=6, fast_path=False)
    for limits in (Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=5.0), Limits(v_max_mps=1.0, d_min_m=0.5)):
        with pytest.raises(ValidationError, match="controller.solver: 'casadi:hpipm' takes rows within one"):
            MPCPlanner(ref, 0.1, limits, settings, solver="casadi:hpipm")
