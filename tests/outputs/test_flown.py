"""What the drones really did in the figures: a plant run's flown speeds, separation and paths,
drawn from the dense true path (peaks and minima from every sample); nothing for the ideal plant."""

from __future__ import annotations

from pathlib import Path

import pytest
from saved_runs import SCENARIOS, shortened

pytest.importorskip("matplotlib")

import numpy as np  # noqa: E402

from mpcform.formation.geometry import min_pair_distances  # noqa: E402
from mpcform.outputs import figures  # noqa: E402
from mpcform.outputs.drawing import FLOWN_GID  # noqa: E402
from mpcform.outputs.plan_views import top_view  # noqa: E402
from mpcform.outputs.rundata import load_run  # noqa: E402
from mpcform.run.runner import run_scenario  # noqa: E402
from mpcform.scenario.load import load_scenario  # noqa: E402
from mpcform.scenario.plant import with_plant_kind  # noqa: E402


def _flown(ax) -> list:
    return [line for line in ax.get_lines() if line.get_gid() == FLOWN_GID]


def test_a_lag_run_draws_its_true_peak_speed_minimum_and_paths(tmp_path: Path) -> None:
    scenario = with_plant_kind(shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), 40), "lag")
    run_scenario(scenario, tmp_path)
    run = load_run(tmp_path)
    true = run.flown
    assert true is not None and true.t_s.shape[0] > run.trajectory.t_s.shape[0]
    speed = np.linalg.norm(true.velocities_mps, axis=-1)
    ax = figures.speeds(run).axes[0]
    marks = [line for line in _flown(ax) if line.get_marker() == "^"]
    assert len(marks) == 1 and marks[0].get_ydata()[0] == pytest.approx(speed.max())
    assert ax.get_ylim()[1] >= speed.max()
    assert any(
        label.startswith(f"flown peak {speed.max():.3g} m/s") for label in ax.get_legend_handles_labels()[1]
    )
    sep = min_pair_distances(true.positions_m)
    ax = figures.separation(run).axes[0]
    low = [line for line in _flown(ax) if line.get_marker() == "v"]
    assert len(low) == 1 and low[0].get_ydata()[0] == pytest.approx(sep.min())
    plan = top_view(run).axes[0]
    assert len(_flown(plan)) == run.n  # one flown path per drone


def test_the_ideal_plant_draws_no_flown_path(tmp_path: Path) -> None:
    run_scenario(shortened(load_scenario(SCENARIOS / "swap_planar_8.toml"), 10), tmp_path)
    run = load_run(tmp_path)
    assert run.flown is None
    for fig in (figures.speeds(run), figures.separation(run), top_view(run)):
        assert _flown(fig.axes[0]) == []


def test_the_tracking_axis_stops_at_a_micrometre(tmp_path: Path) -> None:
    run_scenario(shortened(load_scenario(SCENARIOS / "worked_example.toml"), 60), tmp_path)
    ax = figures.tracking_error(load_run(tmp_path)).axes[0]
    assert ax.get_ylim()[0] >= figures.LOG_FLOOR_M
