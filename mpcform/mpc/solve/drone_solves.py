"""What the per-drone solves return (:class:`DroneSolves`): every drone's solution, slacks, cost
and multipliers in the backend's order, and the rows they were solved with."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpcform._validate import Array


@dataclass(frozen=True)
class DroneSolves:
    """Every drone's DAQP solve (n drones, K separation rows kept, in drone order)."""

    v: Array  # (n, H d) the solutions in v = M u
    s: Array  # (n, H) slacks (zero where the hard QP was feasible)
    cost: Array  # (n,) objective values 0.5 ||v||^2 - c^T v (+ the slack penalty)
    flags: Array  # (n,) the backend's exit flags
    ok: Array  # (n,) the solves that succeeded
    soft: Array  # (n,) the drones solved with slacks
    lams: list[Array]  # per drone, the rows' multipliers (soft: the slacks' H bounds, then constant
    # rows, then separation rows; a row at its lower bound has a multiplier <= 0)
    rows: Array  # (K,) the separation rows kept, as flat ``item * R + row`` indices
    offsets: Array  # (n + 1,) drone i's rows are ``rows[offsets[i]:offsets[i + 1]]``
    sep_c: Array  # (K, d) their coefficients
    sep_end: Array  # (K,) their position steps
    sep_lo: Array  # (K,) their lower bounds
    const_lo: Array  # (n or 1, rows) the constant rows' bounds (one row: the same for every drone)
    const_hi: Array
    iterations: int
    time_s: float  # inside DAQP
    horizon: int
    n_const: int  # constant rows per drone

    def multipliers(self, i: int, everything: bool = False) -> Array:
        """Drone i's multipliers of its separation rows (>= 0: the derivative of its optimal cost in
        the rows' lower bounds), or with ``everything`` of its constant rows first."""
        lam = self.lams[i][self.horizon if self.soft[i] else 0 :]
        return lam if everything else -lam[self.n_const :]

    def separation_multipliers(self) -> list[Array]:
        """Every drone's :meth:`multipliers` of its separation rows, negated in one pass (views of
        one array)."""
        hard, soft = self.n_const, self.n_const + self.horizon  # rows to skip
        parts = [lam[soft if s else hard :] for lam, s in zip(self.lams, self.soft.tolist(), strict=True)]
        mu, cuts = -np.concatenate(parts), self.offsets.tolist()
        return [mu[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
