"""MPC settings: defaults are valid, each bad field is named in the error."""

import pytest

from mpcform.errors import ValidationError
from mpcform.mpc.settings import GROUPED_MODES, PLANNER_MODES, MPCSettings, mode_settings
from mpcform.mpc.strategy import PerDroneSolve, SparseSolve, SplitPolicy


def test_defaults_are_valid():
    settings = MPCSettings()
    assert settings.horizon >= 1 and settings.feedforward == "jacobian" and settings.fast_path


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("horizon", 0, "controller.horizon"),
        ("horizon", 2.0, "controller.horizon"),
        ("horizon", True, "controller.horizon"),
        ("gain_per_s", 0.0, "controller.gain"),
        ("feedforward", "euler", "controller.feedforward"),
        ("velocity_set", "ball", "controller.velocity_set"),
        ("facets", 3, "controller.facets"),
        ("slack_weight", 0.0, "controller.slack_weight"),
        ("slack_quadratic", -1.0, "controller.slack_quadratic"),
        ("margin_m", -1e-3, "controller.margin"),
        ("tie_break_rad", float("nan"), "controller.tie_break"),
    ],
)
def test_bad_settings_are_rejected(field, value, match):
    with pytest.raises(ValidationError, match=match):
        MPCSettings(**{field: value})


def test_mode_settings():
    monolithic = mode_settings("monolithic", 4)
    assert monolithic.grouping is False and monolithic.coupling == "joint"
    assert mode_settings("decoupled", 4).grouping and mode_settings("decoupled", 4).horizon == 4
    assert mode_settings("decoupled", 4).solves_per_drone
    sparse = mode_settings("decoupled-sparse", 4)
    assert sparse.coupling == "decoupled" and sparse.grouping and not sparse.solves_per_drone
    assert mode_settings("joint", 4).coupling == "joint" and mode_settings("joint", 4).grouping
    assert set(GROUPED_MODES) == set(PLANNER_MODES) - {"monolithic"}
    with pytest.raises(ValidationError, match="mode"):
        mode_settings("nope", 4)


def test_the_strategy_follows_the_coupling_unless_given():
    assert isinstance(MPCSettings().strategy, SparseSolve)
    assert MPCSettings(coupling="decoupled").strategy == PerDroneSolve()
    split = PerDroneSolve(split=SplitPolicy(3, budget_s=0.01))
    assert MPCSettings(coupling="decoupled", solve=split).strategy.split.iterations == 3  # type: ignore[union-attr]
    assert MPCSettings(coupling="decoupled", solve=SparseSolve()).solves_per_drone is False
    with pytest.raises(ValidationError, match="controller.solve.kind"):
        MPCSettings(coupling="joint", solve=PerDroneSolve())
