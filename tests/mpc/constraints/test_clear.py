"""The fast path's clear test per pair: the pairs it leaves in doubt, and the rows tested on them only."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import bounds_of
from hypothesis import given, settings
from hypothesis import strategies as st

from mpcform.mpc.constraints.candidates import Candidates
from mpcform.mpc.constraints.separation import Separation, rollout_meets
from mpcform.mpc.settings import MPCSettings


def every_pair(n: int) -> Candidates:
    p = np.array([[i, k] for i in range(n) for k in range(i + 1, n)], dtype=np.intp)
    return Candidates(p, np.ones(p.shape[0], bool), np.empty((0, 2), np.intp), np.empty(0, bool), False)


@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_only_the_pairs_in_doubt_need_their_rows(coupling: str, seed: int) -> None:
    """Every pair :meth:`unclear_pairs` leaves out meets its joint rows, and when the rows of the
    pairs in doubt are met, the rows of all are (the fast path's answer unchanged)."""
    rng = np.random.default_rng(seed)
    n, h = 8, 4
    p0 = rng.uniform(-2.0, 2.0, (n, 2))
    steps = np.concatenate([np.zeros((1, n, 2)), rng.uniform(-0.1, 0.1, (h, n, 2))])
    guess = p0 + np.cumsum(steps, axis=0)
    x = np.cumsum(rng.uniform(-0.1, 0.1, (h, n, 2)), axis=0)
    positions = np.concatenate([p0[None], p0 + x])
    settings_ = MPCSettings(horizon=h, coupling=coupling)
    sep = Separation(2, bounds_of(v_max_mps=1.0, d_min_m=0.5), settings_, ())
    everything = every_pair(n)
    unclear = {tuple(pair) for pair in sep.clearing.unclear_pairs(guess, positions).tolist()}
    clear = [pair for pair in everything.pairs.tolist() if tuple(pair) not in unclear]
    if clear:
        c = np.array(clear, dtype=np.intp)
        part = Candidates(c, np.ones(len(clear), bool), everything.obstacles, everything.obstacle_on, False)
        assert sep.shortfall(x, sep.rows(p0, guess, part), 0.0, joint=True)[0] <= 0.0
    rows = sep.rows(p0, guess, everything)
    values = sep.single_values(x, rows)
    full = not sep.conflicted(x, rows, values).any()
    if coupling == "decoupled":
        full = full or sep.meets_joint(x, rows, values)
    if rollout_meets(sep, p0, guess, positions, x, everything):
        assert full
