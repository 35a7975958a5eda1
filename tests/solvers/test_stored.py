"""What the set-up-every-call backends share (``mpcform.solvers.stored``), on the bundled recorded
problems: the full symmetric ``P``, output silenced at the file-descriptor level and restored, and
:class:`StoredQP`'s keeping of the problem (copies; update checked against the pattern; errors
naming the solver). Exercised through a real subclass, the qpsolvers backend with clarabel."""

from __future__ import annotations

import ctypes
import os
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from mpcform.bench.problems import RecordedQP, load_problem
from mpcform.errors import MPCFormError, SolverError
from mpcform.solvers.base import SolverOptions
from mpcform.solvers.registry import make_backend
from mpcform.solvers.stored import StoredQP, full_symmetric, quiet_fds

PROBLEMS = Path(__file__).resolve().parents[2] / "problems"
SOLVER = "qpsolvers:clarabel"


@pytest.fixture(scope="module")
def planar() -> list[RecordedQP]:
    """Three recorded steps of the planar swap, the first one and two later ones that share A's
    pattern."""
    files = sorted((PROBLEMS / "swap_planar_8").glob("step_*.npz"))
    return [load_problem(f) for f in (files[0], files[2], files[3])]


def _backend() -> StoredQP:
    backend = make_backend(SOLVER, SolverOptions(1e-9, 1e-9, None))
    assert isinstance(backend, StoredQP)
    return backend


@pytest.mark.parametrize("scenario", ["swap_planar_8", "swap_spatial_12", "swap_spatial_20"])
def test_full_symmetric_of_the_recorded_upper_triangles(scenario: str) -> None:
    qp = load_problem(sorted((PROBLEMS / scenario).glob("step_*.npz"))[0])
    assert sp.tril(qp.P, -1).nnz == 0  # recorded P: upper triangular, as the backends are given it
    full = full_symmetric(qp.P)
    assert isinstance(full, sp.csc_matrix) and full.shape == qp.P.shape
    assert abs(full - full.T).max() == 0
    assert abs(sp.triu(full) - qp.P).max() == 0  # the upper triangle (diagonal included) unchanged
    z = np.random.default_rng(0).standard_normal(qp.P.shape[0])
    # z^T P_full z: the upper triangle once and its strict part a second time (as its transpose)
    assert z @ (full @ z) == pytest.approx(z @ (qp.P @ z) + z @ (sp.triu(qp.P, 1) @ z), rel=1e-12)


def test_full_symmetric_ignores_the_lower_triangle() -> None:
    upper = sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [0.0, 3.0, -1.0], [0.0, 0.0, 4.0]]))
    expected = np.array([[2.0, 1.0, 0.0], [1.0, 3.0, -1.0], [0.0, -1.0, 4.0]])
    np.testing.assert_array_equal(full_symmetric(upper).toarray(), expected)
    junk_below = upper + sp.csc_matrix(np.array([[0.0, 0, 0], [7.0, 0, 0], [0, 9.0, 0]]))
    np.testing.assert_array_equal(full_symmetric(junk_below).toarray(), expected)


def _open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def test_quiet_fds_silences_c_and_fd_writes_and_restores(capfd: pytest.CaptureFixture[str]) -> None:
    libc = ctypes.CDLL(None)
    before, inode = _open_fds(), (os.fstat(1).st_ino, os.fstat(2).st_ino)
    os.write(1, b"before\n")
    with quiet_fds():
        os.write(1, b"fd 1 inside\n")
        os.write(2, b"fd 2 inside\n")
        libc.puts(b"libc inside")  # buffered by C stdio: flushed on the way out, still silenced
    os.write(2, b"after\n")
    assert capfd.readouterr() == ("before\n", "after\n")
    assert (os.fstat(1).st_ino, os.fstat(2).st_ino) == inode and _open_fds() == before


def test_quiet_fds_restores_after_an_error(capfd: pytest.CaptureFixture[str]) -> None:
    before = _open_fds()
    with pytest.raises(RuntimeError, match="solver crashed"), quiet_fds():
        os.write(1, b"lost\n")
        raise RuntimeError("solver crashed")
    os.write(1, b"back\n")
    assert capfd.readouterr().out == "back\n" and _open_fds() == before


def test_update_before_setup_names_the_solver(planar: list[RecordedQP]) -> None:
    qp = planar[0]
    with pytest.raises(
        SolverError, match=r"^solver 'qpsolvers:clarabel': update\(\) before setup\(\)$"
    ) as info:
        _backend().update(qp.q, qp.l, qp.u, qp.A.data)
    assert info.value.solver == SOLVER and isinstance(info.value, MPCFormError)


def test_update_refuses_values_of_another_pattern(planar: list[RecordedQP]) -> None:
    backend = _backend()
    qp = planar[0]
    backend.setup(qp.P, qp.q, qp.A, qp.l, qp.u)
    with pytest.raises(SolverError, match=rf"A has {qp.A.nnz - 1} values, the pattern has {qp.A.nnz}"):
        backend.update(qp.q, qp.l, qp.u, qp.A.data[:-1])


def test_setup_keeps_copies(planar: list[RecordedQP]) -> None:
    qp = planar[0]
    backend = _backend()
    q, lo, hi, A = qp.q.copy(), qp.l.copy(), qp.u.copy(), qp.A.copy()
    backend.setup(qp.P, q, A, lo, hi)
    first = backend.solve()
    q[:], lo[:], hi[:], A.data[:] = 1e3, -1e-3, 1e-3, 0.0  # the caller reuses its buffers
    again = backend.solve()
    assert first.success and again.success and first.x is not None and again.x is not None
    np.testing.assert_array_equal(first.x, again.x)
    assert qp.primal_residual(first.x) < 1e-6


def test_update_solves_as_a_fresh_setup(planar: list[RecordedQP]) -> None:
    _, this, nxt = planar
    assert np.array_equal(this.A.indices, nxt.A.indices) and np.array_equal(this.A.indptr, nxt.A.indptr)
    updated = _backend()
    updated.setup(this.P, this.q, this.A, this.l, this.u)
    assert updated.solve().success
    data = nxt.A.data.copy()
    updated.update(nxt.q, nxt.l, nxt.u, data)
    data[:] = 0.0  # copied on update too
    fresh = _backend()
    fresh.setup(nxt.P, nxt.q, nxt.A, nxt.l, nxt.u)
    a, b = updated.solve(), fresh.solve()
    assert a.success and b.success and a.x is not None and b.x is not None
    np.testing.assert_allclose(a.x, b.x, atol=1e-7, rtol=0)
    assert nxt.primal_residual(a.x) < 1e-6
