"""Both step solvers take a StepQP and answer in the sparse layout: with no row active, the eq. 14 rollout."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import bounds_of

from mpcform.mpc.constraints.candidates import Candidates
from mpcform.mpc.constraints.limits import limit_rows
from mpcform.mpc.constraints.separation import Separation
from mpcform.mpc.plan import rollout
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.solve.per_drone import PerDroneQP
from mpcform.mpc.solve.problem import StepQP, StepSolver
from mpcform.mpc.solve.sparse import SparseSolver
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.daqp_dense import DaqpBackend
from mpcform.solvers.registry import make_backend

DT = 0.1


@pytest.mark.parametrize("kind", ["sparse", "per drone"])
def test_solvers_return_the_rollout_when_no_row_is_active(kind: str) -> None:
    options = SolverOptions(1e-9, 1e-9, 4000)
    st = MPCSettings(horizon=4, gain_per_s=2.0, coupling="decoupled")
    lim = bounds_of(v_max_mps=10.0, d_min_m=0.5)
    families, sep = limit_rows(2, DT, lim, st), Separation(2, lim, st, ())
    solver: StepSolver
    if kind == "sparse":
        solver = SparseSolver(make_backend("piqp", options), 2, DT, lim, st, families, sep)
    else:
        solver = PerDroneQP(2, DT, lim, st, families, DaqpBackend())
    p0 = np.array([[0.0, 0.0], [2.0, 0.0], [4.0, 1.0]])
    c = np.random.default_rng(0).uniform(-1.0, 1.0, (4, 3, 2))
    cand = Candidates(np.array([[0, 1]]), np.ones(1, bool), np.empty((0, 2), int), np.empty(0, bool), True)
    rows = sep.rows(p0, np.broadcast_to(p0, (5, 3, 2)), cand)  # far apart: the rows hold slack
    u_nom, x_nom = rollout(c, st.gain_per_s, DT)
    warm = np.stack([u_nom, x_nom]) if solver.warm_starts else None
    sol, _ = solver.solve(StepQP(3, np.arange(3), p0, c, np.zeros((3, 2)), rows, True, warm))
    assert sol.success and sol.x is not None and sol.x.shape == (2 * 24 + 12,)
    np.testing.assert_allclose(sol.x[:24].reshape(4, 3, 2), u_nom, atol=1e-6)
    np.testing.assert_allclose(sol.x[24:48].reshape(4, 3, 2), x_nom, atol=1e-6)
    np.testing.assert_allclose(sol.x[48:], 0.0, atol=1e-6)


def test_rows_over_all_drones_are_selected_for_the_qps_drones() -> None:
    """Rows given over all drones (``on_only`` set): :attr:`StepQP.rows` are the subset over the
    QP's drones, and the per-drone solver, which picks them from all (``places``), solves the QP
    as it solves the one given the subset, bit for bit."""
    st = MPCSettings(horizon=4, gain_per_s=2.0, coupling="decoupled")
    lim = bounds_of(v_max_mps=2.0, d_min_m=0.5)
    families, sep = limit_rows(2, DT, lim, st), Separation(2, lim, st, ())
    p0 = np.array([[0.0, 0.0], [0.6, 0.0], [1.2, 0.1], [5.0, 5.0]])
    c = np.random.default_rng(1).uniform(-1.0, 1.0, (4, 4, 2))
    pairs = np.array([[0, 1], [1, 2], [0, 2], [2, 3]])
    cand = Candidates(
        pairs, np.array([True, True, True, False]), np.empty((0, 2), int), np.empty(0, bool), True
    )
    rows = sep.rows(p0, np.broadcast_to(p0, (5, 4, 2)), cand)
    drones = np.array([2, 0, 1])
    whole = StepQP(4, drones, p0[drones], c[:, drones], np.zeros((3, 2)), rows, True, None, on_only=True)
    sub = rows.subset(drones, 4, on_only=True)
    assert whole.rows.singles.tolist() == sub.singles.tolist() and np.array_equal(
        whole.rows.single_lower, sub.single_lower
    )
    assert whole.places().tolist() == [1, 2, 0, -1]
    given = StepQP(4, drones, p0[drones], c[:, drones], np.zeros((3, 2)), sub, True, None)
    assert given.places() is None and given.rows is sub
    solver = PerDroneQP(2, DT, lim, st, families, DaqpBackend())
    a, _ = solver.solve(whole)
    b, _ = solver.solve(given)
    assert a.success and a.x is not None and b.x is not None and np.array_equal(a.x, b.x)
