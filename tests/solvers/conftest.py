"""Shared by the backend tests: the recorded problems, their reference objectives, a planner state
with active separation rows, and the two checks every backend passes (``solves_recorded``,
``first_input_agrees``)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from mpcform.bench.problems import RecordedQP, load_problem, problem_files
from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.strategy import SparseSolve
from mpcform.reference.base import ConstantReference
from mpcform.sim.simulation import simulate
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend, solver_info
from mpcform.world.limits import Limits

ROOT = Path(__file__).resolve().parents[2]
ActiveStart = tuple[ConstantReference, np.ndarray, float]


def _require_usable(name: str) -> None:
    info = solver_info(name)
    if not info.usable:
        pytest.skip(f"{name}: {info.note}")


@pytest.fixture(scope="session")
def require_usable() -> Callable[[str], None]:
    """Skips the test when the named backend is not installed here (or cannot take this QP)."""
    return _require_usable


@pytest.fixture(scope="session")
def recorded() -> dict[str, list[RecordedQP]]:
    """The bundled recorded problems, by scenario."""
    by: dict[str, list[RecordedQP]] = {}
    for f in problem_files(ROOT / "problems"):
        by.setdefault(f.parent.name, []).append(load_problem(f))
    return by


@pytest.fixture(scope="session")
def reference_objective() -> Callable[[RecordedQP], float]:
    """Objective of a problem solved by clarabel at 1e-9 (cached by problem name)."""
    cache: dict[str, float] = {}

    def objective(qp: RecordedQP) -> float:
        if qp.name not in cache:
            be = make_backend("qpsolvers:clarabel", SolverOptions(1e-9, 0.0, None))
            be.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
            sol = be.solve()
            assert sol.success and sol.x is not None
            cache[qp.name] = qp.objective(sol.x)
        return cache[qp.name]

    return objective


@pytest.fixture
def solves_recorded(
    recorded: dict[str, list[RecordedQP]],
    reference_objective: Callable[[RecordedQP], float],
    capfd: pytest.CaptureFixture[str],
) -> Callable[..., None]:
    """Check that one backend solves recorded problems (setup, then update while the pattern
    holds) to the reference within ``objective`` (relative gap) and ``residual`` (primal), given
    ``eps``, without printing. ``problems``: how many of the small swap's problems (slow backends
    take one); ``all_sizes``: also the first problem of every other scenario."""

    def check(
        name: str,
        objective: float,
        residual: float,
        eps: float = 1e-7,
        problems: int = 3,
        all_sizes: bool = False,
    ) -> None:
        _require_usable(name)
        small = recorded["swap_planar_8"]
        chosen = [small[0], small[len(small) // 2], small[-1]][:problems]
        if all_sizes:
            chosen += [qps[0] for scenario, qps in recorded.items() if scenario != "swap_planar_8"]
        refs = [reference_objective(qp) for qp in chosen]
        capfd.readouterr()
        backend = make_backend(name, SolverOptions(eps, eps, None))
        pattern = None
        for qp, f_ref in zip(chosen, refs, strict=True):
            if pattern != (qp.A.indptr.tobytes(), qp.A.indices.tobytes()):
                backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
                pattern = (qp.A.indptr.tobytes(), qp.A.indices.tobytes())
            else:
                backend.update(qp.q, qp.l, qp.u, qp.A.data)
            if backend.needs_context:
                assert qp.context is not None
                backend.set_context(qp.context)
            sol = backend.solve(qp.x0 if backend.warm_starts else None)
            assert sol.success and sol.x is not None, f"{qp.name}: {sol.status}"
            res, gap = qp.primal_residual(sol.x), abs(qp.objective(sol.x) - f_ref) / max(1.0, abs(f_ref))
            assert res <= residual and gap <= objective, f"{qp.name}: residual {res:.1e}, gap {gap:.1e}"
        assert capfd.readouterr() == ("", ""), "a backend printed during a solve"

    return check


UNBOUNDED = Limits(v_max_mps=1.0, d_min_m=0.5, a_max_mps2=np.inf)
"""No a_max: every backend, hpipm too, plans the same QP."""


def _active_start() -> ActiveStart:
    """A planar swap of 6 drones 1.5 s in (piqp closed loop): separation rows are active."""
    tpl = Template.polygon(6, 2.0)
    ref = ConstantReference(tpl, FormationState.from_param(np.zeros(2)))
    planner = MPCPlanner(ref, 0.1, UNBOUNDED, MPCSettings(horizon=6))
    res = simulate(planner, -tpl.offsets, 1.5)
    return ref, res.positions_m[-1], float(res.t_s[-1])


@pytest.fixture(scope="session")
def active_start() -> ActiveStart:
    return _active_start()


@pytest.fixture(scope="session")
def active_command(active_start: ActiveStart) -> np.ndarray:
    """piqp's first input [m/s] at :func:`active_start`, solved at 1e-9."""
    ref, p, t = active_start
    settings = MPCSettings(
        horizon=6, solve=SparseSolve(options=SolverOptions(1e-9, 1e-9, 4000)), fast_path=False
    )
    planner = MPCPlanner(ref, 0.1, UNBOUNDED, settings, solver="piqp")
    planner.reset(t, p)
    out = planner.step(t, p)
    assert out.info.mode == "qp" and out.info.active_rows > 0  # the scenario has active constraints
    return out.command_mps


@pytest.fixture
def first_input_agrees(active_start: ActiveStart, active_command: np.ndarray) -> Callable[..., None]:
    """Check that the planner with one backend (given ``eps``) plans piqp's first input within
    ``tolerance_mps`` where separation rows are active."""

    def check(name: str, tolerance_mps: float, eps: float = 1e-7) -> None:
        _require_usable(name)
        ref, p, t = active_start
        settings = MPCSettings(
            horizon=6, solve=SparseSolve(options=SolverOptions(eps, eps, 4000)), fast_path=False
        )
        planner = MPCPlanner(ref, 0.1, UNBOUNDED, settings, solver=name)
        planner.reset(t, p)
        out = planner.step(t, p)
        assert out.info.mode == "qp", out.info.status
        np.testing.assert_allclose(out.command_mps, active_command, atol=tolerance_mps, rtol=0)

    return check
