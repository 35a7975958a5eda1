"""Every first row hard, lowered to one candidate (mpcform.mpc.safety.first_rows)."""

import numpy as np

from mpcform.mpc.constraints.separation_rows import SeparationRows
from mpcform.mpc.safety.first_rows import hard_first_rows


def test_hard_first_rows_lower_every_row_to_one_candidate() -> None:
    """Two drones' one-drone rows x_0 >= 1 and x_1 >= 1, and two candidate first positions that
    each meet one of them: the rows are lowered to the candidate that needs less lowering, so one
    command meets them all (a row-wise best would need (1, 1), which neither reaches)."""
    e = np.array([1.0, 0.0])
    rows = SeparationRows(
        pairs=np.zeros((0, 2), dtype=int),
        pair_coeffs=np.zeros((0, 2, 2)),
        pair_lower=np.zeros((0, 2)),
        pair_on=np.zeros(0, dtype=bool),
        singles=np.array([0, 1]),
        labels=np.array([[0, 1], [1, 0]]),
        single_coeffs=np.array([[e, e], [e, e]]),
        single_lower=np.ones((2, 2)),
        single_on=np.ones(2, dtype=bool),
        pair_hard=np.zeros(0, dtype=bool),
        single_hard=np.zeros(2, dtype=bool),
    )
    first = np.array([[[1.0, 0.0], [0.0, 0.0]], [[0.2, 0.0], [0.9, 0.0]]])  # short: 1.0, then 0.9
    hard, relaxed, best = hard_first_rows(rows, first)
    assert best == 1 and relaxed and hard.single_hard.all()
    np.testing.assert_allclose(hard.single_lower[:, 0], [0.2, 0.9])
    np.testing.assert_allclose(hard.single_lower[:, 1], 1.0)
