"""The Newton model of one drone's QP (:func:`mpcform.mpc.solve.sensitivity.drone_sensitivity`) against
finite differences of DAQP re-solves."""

from __future__ import annotations

import daqp
import numpy as np
import pytest

from mpcform.mpc.solve.sensitivity import drone_sensitivity

INF = 1e30


def _solve(
    c: np.ndarray, const: np.ndarray, lo: np.ndarray, hi: np.ndarray, sep: np.ndarray, sep_lo: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``min 0.5 ||v - c||^2`` s.t. ``lo <= const v <= hi``, ``sep v >= sep_lo`` (DAQP, tight)."""
    a = np.vstack([const, sep])
    v, _, flag, info = daqp.solve(
        np.eye(c.shape[0]),
        -c,
        a,
        np.concatenate([hi, np.full(sep.shape[0], INF)]),
        np.concatenate([lo, sep_lo]),
        primal_tol=1e-12,
    )
    assert flag == 1
    return v, info["lam"]


@pytest.mark.parametrize("seed", range(4))
def test_the_optimum_moves_with_the_active_rows_bounds_as_the_model_says(seed: int) -> None:
    rng = np.random.default_rng(seed)
    nv, nc, ns = 6, 4, 5
    c = rng.normal(size=nv)
    const, sep = rng.normal(size=(nc, nv)), rng.normal(size=(ns, nv))
    lo, hi = np.full(nc, -1.0), np.full(nc, 1.0)
    sep_lo = sep @ c + rng.uniform(0.1, 1.0, ns)  # every separation row violated at c
    v, lam = _solve(c, const, lo, hi, sep, sep_lo)
    sens = drone_sensitivity(lam, v, np.vstack([const, -const]), sep, lo, hi, sep_lo)
    assert sens.active.size >= 1
    h = 1e-6
    for a, row in enumerate(sens.active):
        moved = [sep_lo.copy(), sep_lo.copy()]
        moved[0][row] += h
        moved[1][row] -= h
        (v_up, lam_up), (v_down, lam_down) = (_solve(c, const, lo, hi, sep, b) for b in moved)
        np.testing.assert_allclose((v_up - v_down) / (2 * h), sens.dv[:, a], atol=1e-6)
        dmu = -(lam_up[nc + row] - lam_down[nc + row]) / (2 * h)  # DAQP: a lower bound's multiplier <= 0
        assert dmu == pytest.approx(sens.hessian[a, a], rel=1e-5, abs=1e-6)
    off_rows = np.concatenate([np.vstack([const, -const])[sens.const_off], sens.sep_rows])
    np.testing.assert_allclose(sens.rate(sens.dv[:, 0]), off_rows @ sens.dv[:, 0], atol=1e-12)
    assert np.all(sens.slack > 0.0)
