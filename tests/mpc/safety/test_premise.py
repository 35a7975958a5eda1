"""The growth's premise, checked every step (mpcform.mpc.safety.premise)."""

from __future__ import annotations

import numpy as np
import pytest

from mpcform.formation.state import FormationState
from mpcform.formation.template import Template
from mpcform.mpc.constraints.rows import step_growth
from mpcform.mpc.planner import MPCPlanner
from mpcform.mpc.prediction import Prediction
from mpcform.mpc.safety.premise import GrowthPremise
from mpcform.mpc.settings import MPCSettings
from mpcform.mpc.velocity_loop import VelocityLoop
from mpcform.reference.base import ConstantReference
from mpcform.world.bounds import planning_bounds
from mpcform.world.limits import Limits

LAG = (np.array([[-5.0]]), np.array([5.0]), np.array([1.0]), (0, 1))


def test_the_window_is_where_the_rows_grow_one_step_more() -> None:
    """E = min(H, ceil(0.2 / 0.1)) = 2: the rows at steps 2 and 3 grow by g more than at 1 and 2."""
    predict = Prediction(0.1, 6, VelocityLoop.from_groups([LAG], 2, 0.1, 6), None, None)
    premise = GrowthPremise.of(step_growth(0.01, 0.1, 6, 3), 0.01, predict)
    assert premise is not None and premise.window.tolist() == [1, 2]
    assert GrowthPremise.of(None, 0.0, predict) is None
    assert GrowthPremise.of(step_growth(0.01, 0.1, 6), 0.01, Prediction(0.1, 6, None, None, None)) is None


def test_the_move_counts_the_window_and_the_growing_drones_only() -> None:
    premise = GrowthPremise(0.01, np.array([1, 2]), Prediction(0.1, 4, None, None, None))
    about, expected = np.zeros((5, 3, 2)), np.zeros((4, 3, 2))
    assert premise.moved(about, None, np.ones(3)) is None  # no plan yet
    about[3, 0, 0] = 1.0  # past the window
    about[2, 1, 1] = 0.004  # drone 1 within the window
    about[1, 2, 0] = 0.5  # drone 2 does not grow
    assert premise.moved(about, expected, np.array([1.0, 1.0, 0.0])) == pytest.approx(0.004)
    assert premise.moved(about, expected, np.zeros(3)) is None


def _planner(d_min_m: float = 0.5) -> MPCPlanner:
    tpl = Template(np.array([[-1.0, 0.0], [1.0, 0.0]]))
    ref = ConstantReference(tpl, FormationState.from_param([4.0, 0.0]))
    limits = planning_bounds(Limits(v_max_mps=1.0, d_min_m=d_min_m, a_max_mps2=2.0), (), 0.0, None, 0.01)[0]
    loop = VelocityLoop.from_groups([LAG], 2, 0.1, 6)
    return MPCPlanner(ref, 0.1, limits, MPCSettings(horizon=6, gain_per_s=2.0), loop=loop)


def test_drones_that_move_as_modelled_meet_the_premise_and_a_push_moves_the_plan_e_plus_one_times() -> None:
    """Drones that go exactly where the loop model takes them move the shifted plan by nothing
    (rounding); a push ``w`` moves its position at step ``e`` by ``(e + 1) |w|``: the start by ``w``
    and, through the velocity offset's estimate ``delta += w / dt`` held over the plan, the position
    e intervals on by ``e dt delta = e w`` more (the window ends at e = 2: ``3 |w|``). A push beyond
    ``g / 3`` exceeds the growth and is recorded."""
    planner = _planner()
    p = np.array([[-1.0, 0.0], [1.0, 0.0]])
    planner.reset(0.0, p)
    for k in range(6):
        info = planner.step(0.1 * k, p).info
        assert info.wind_shift_m < 1e-10 and not info.growth_exceeded  # type: ignore[attr-defined]
        p = planner._predicted.copy()  # where the model took them
    push = np.array([[0.002, 0.008 / 3.0], [0.0, 0.0]])  # 3.33 mm on drone 0
    info = planner.step(0.6, p + push).info
    assert info.wind_shift_m == pytest.approx(0.01, abs=1e-9)  # type: ignore[attr-defined]
    assert not info.growth_exceeded  # type: ignore[attr-defined]  # exactly g
    p = planner._predicted + 2.0 * push
    info = planner.step(0.7, p).info
    assert info.growth_exceeded  # type: ignore[attr-defined]


def test_tight_targets_and_calm_air_check_nothing() -> None:
    """Drones whose targets are too close to grow their rows, and a planner without growth, record
    no move."""
    tight = _planner(d_min_m=1.97)  # targets 2 m apart: within d_min + margin + 2 x 0.02 m
    p = np.array([[-1.0, 0.0], [1.0, 0.0]])
    tight.reset(0.0, p)
    for k in range(3):
        info = tight.step(0.1 * k, p + 0.01 * k).info
        assert info.wind_shift_m == 0.0 and not info.growth_exceeded  # type: ignore[attr-defined]


def test_the_survivors_keep_checking_where_the_plan_takes_them() -> None:
    """A lost drone's planner keeps what the last step expected of the others: drones that go on as
    modelled still move the plan by nothing."""
    planner = _planner()
    p = np.array([[-1.0, 0.0], [1.0, 0.0]])
    planner.reset(0.0, p)
    for k in range(3):
        planner.step(0.1 * k, p)
        p = planner._predicted.copy()
    survivors = planner.lose([0], p)
    assert survivors.inner.state.expected.shape[1] == 1  # type: ignore[attr-defined]
    info = survivors.step(0.3, p).info
    assert info.wind_shift_m < 1e-10 and not info.growth_exceeded  # type: ignore[attr-defined]
    p[1] = survivors.inner._predicted[0] + np.array([0.0, 0.003])  # type: ignore[attr-defined]
    info = survivors.step(0.4, p).info
    assert info.wind_shift_m == pytest.approx(0.009, abs=1e-9)  # type: ignore[attr-defined]
