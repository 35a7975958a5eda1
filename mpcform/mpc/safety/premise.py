"""The premise of the rows' growth in wind, checked every step: how far the wind moved the plan.

The rows grow along the horizon by ``g`` per drone and step
(:func:`mpcform.mpc.constraints.rows.step_growth`),
which keeps the shifted plan meeting the next step's rows, the first rows included, when the wind
moves each of its positions within the growth's window by at most ``g`` (constraint tightening,
Chisci, Rossiter and Zappa 2001). :class:`GrowthPremise` measures that move every step: where the
previous plan, shifted, now takes the drones (from the measured start and the loop's state,
:meth:`mpcform.mpc.prediction.Prediction.guess`) against where the previous step predicted the
same instants, over the drones whose rows grow
(:meth:`mpcform.mpc.constraints.separation.Separation.growing`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mpcform._validate import Array
from mpcform.mpc.plan import Plan
from mpcform.mpc.prediction import Prediction
from mpcform.mpc.step_info import MPCStepInfo
from mpcform.world.closest import vector_norms

PREMISE_TOL = 1e-9
"""Relative tolerance [-] of the check (a move of exactly ``g`` meets it)."""


@dataclass(frozen=True)
class GrowthPremise:
    """The check for a growth of ``growth_m`` [m] per drone and step over the position steps
    ``window`` (each new step ``e`` whose rows grow by one ``g`` more at ``e + 1``), with the
    planner's ``predict``."""

    growth_m: float
    window: Array
    predict: Prediction

    @classmethod
    def of(cls, growth: Array | None, growth_m: float, predict: Prediction) -> GrowthPremise | None:
        """The check for the rows' ``growth`` (H + T + 1,) per position step (None: no growth, or
        no velocity loop: the offset estimate and its residual need one)."""
        if growth is None or predict.loop is None:
            return None
        steps = np.arange(1, predict.horizon)
        return cls(growth_m, steps[growth[steps + 1] > growth[steps]], predict)

    def moved(self, about: Array, expected: Array | None, growing: Array | None) -> float | None:
        """The largest move [m] of the shifted plan's positions ``about`` (S + 1, n, d) (row 0 the
        start) within the window from where the last step ``expected`` them (:meth:`record`), over
        the drones with a share ``growing`` (n,) of the growth; None before the first plan or with
        no drone growing."""
        if expected is None or growing is None or not growing.any() or not self.window.size:
            return None
        moves = vector_norms(about[self.window] - expected[self.window])  # (W, n)
        return float(moves[:, growing > 0].max())

    def record(
        self, info: MPCStepInfo, moved_m: float | None, p0: Array, state: Array, plan: Plan
    ) -> tuple[MPCStepInfo, Array]:
        """The step's record ``info`` with the move ``moved_m`` (:meth:`moved`) and whether it
        exceeded the growth, and where its accepted ``plan`` takes the drones (S, n, d) (steps
        1..S) from ``p0`` (n, d) and the loop's ``state`` (n, d, s): what the next step expects."""
        expected = p0 + self.predict.points(state, plan.inputs_mps, plan.positions_m[1:] - p0)
        if moved_m is None:
            return info, expected
        over = moved_m > self.growth_m * (1.0 + PREMISE_TOL)
        return replace(info, wind_shift_m=moved_m, growth_exceeded=over), expected
