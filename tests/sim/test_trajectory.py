"""The trajectory type: shapes checked on construction, sizes read off the arrays."""

import re

import numpy as np
import pytest

from mpcform.errors import ValidationError
from mpcform.sim.trajectory import Trajectory


def arrays(samples: int = 4, n: int = 3, dim: int = 2) -> dict[str, np.ndarray]:
    return {
        "t_s": np.arange(float(samples)),
        "positions_m": np.zeros((samples, n, dim)),
        "commands_mps": np.zeros((samples - 1, n, dim)),
        "reference_m": np.ones((samples, n, dim)),
    }


@pytest.mark.parametrize("dim", [2, 3])
def test_sizes_and_arrays_as_given(dim: int) -> None:
    given = arrays(5, 4, dim)
    trajectory = Trajectory(**given)
    assert (trajectory.n, trajectory.dim, trajectory.steps) == (4, dim, 4)
    assert all(getattr(trajectory, k) is v for k, v in given.items())  # no copy, no conversion
    assert trajectory.scale_estimates is None  # only controllers with estimates record them
    s_hat = np.ones((5, 4))
    assert Trajectory(**given, scale_estimates=s_hat).scale_estimates is s_hat


@pytest.mark.parametrize(
    ("change", "fragment"),
    [
        ({"t_s": np.arange(3.0)}, "t_s (T,)"),
        ({"positions_m": np.zeros((4, 3))}, "positions_m (T, n, 2 or 3)"),
        ({"positions_m": np.zeros((4, 3, 4))}, "positions_m (T, n, 2 or 3)"),
        ({"commands_mps": np.zeros((4, 3, 2))}, "commands_mps (T-1, n, d)"),
        ({"reference_m": np.zeros((4, 2, 2))}, "reference_m (T, n, d)"),
        ({"scale_estimates": np.ones((3, 3))}, "scale_estimates (T, n) = (4, 3), got (3, 3)"),
        ({"scale_estimates": np.ones(4)}, "scale_estimates (T, n)"),
    ],
)
def test_shapes_are_checked(change: dict[str, np.ndarray], fragment: str) -> None:
    with pytest.raises(ValidationError, match=r"^trajectory: .*" + re.escape(fragment)):
        Trajectory(**(arrays() | change))


def test_one_sample_is_not_a_trajectory() -> None:
    with pytest.raises(ValidationError, match="T >= 2"):
        Trajectory(**arrays(samples=1))
