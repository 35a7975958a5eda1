"""Offset-free tracking in a steady wind (issue 57, item 1): the velocity offset's estimate is held
over the plan and cancelled in the command (mpcform.mpc.velocity_loop), so a formation holding or
translating slowly arrives within 0.02 m, and the growth's premise fails on its first steps only."""

from __future__ import annotations

from importlib import metadata

import numpy as np
import pytest

from mpcform.run.runner import run_scenario
from mpcform.scenario.load import scenario_from_dict
from mpcform.sim.completion import completion_metrics

try:
    metadata.distribution("drone-models")
    FLIGHT = True
except metadata.PackageNotFoundError:
    FLIGHT = False

TOL_M = 0.02
PLANTS = {
    "lag": {"kind": "lag", "time_constant": 0.3},
    "second_order": {"kind": "second_order", "damping": 0.7, "natural_frequency": 6.0},
    "quadrotor": {"kind": "quadrotor"},
}


def ring(dim: int, plant: str, coupling: str, wind_mps: float, move: bool = False, n: int = 10) -> dict:
    """``n`` drones on a ring of 3 m (spatial: tilted) in a steady wind ``wind_mps`` along x + y,
    holding it, or (``move``) flying it 1.5 m at up to 0.1 m/s (a mission)."""
    mean = wind_mps * np.array([1.0, 1.0, 0.0][:dim]) / np.sqrt(2.0)
    table = dict(PLANTS[plant]) | {"wind": {"mean": mean.tolist()}}
    template = {"shape": "polygon", "n": n, "radius": 3.0} if dim == 2 else {"shape": "sphere", "n": n}
    if dim == 3:
        template["radius"] = 3.0
    reference: dict = {"kind": "constant", "centroid": [0.0] * dim}
    duration = 20.0
    if move:
        goal = [1.5] + [0.0] * (dim - 1)
        keys = [{"centroid": goal}]
        reference = {"kind": "mission", "keyframes": keys, "max_velocity": {"centroid": 0.1}}
        duration = 30.0
    return {
        "version": 1,
        "name": f"ring_{dim}d_{plant}_{coupling}",
        "dim": dim,
        "seed": 0,
        "template": template,
        "initial": {"centroid": [0.0] * dim},
        "reference": reference,
        "limits": {"v_max": 1.0, "d_min": 0.5},
        "controller": {"kind": "mpc", "gain": 1.0, "horizon": 8, "coupling": coupling},
        "simulation": {"dt": 0.1, "duration": duration},
        "plant": table,
    }


def arrived(data: dict) -> tuple[float, dict]:
    """The largest true final error [m] and the run's metrics."""
    run = run_scenario(scenario_from_dict(data))
    m = run.summary["metrics"]
    assert m["separation_violations_true"] == 0 and m["speed_violations"] == 0
    done = completion_metrics(run.simulation, TOL_M)
    assert done["completion"] == 1.0, done
    traj = run.simulation
    return float(np.linalg.norm(traj.positions_m[-1] - traj.reference_m[-1], axis=-1).max()), m


def test_a_lag_ring_in_a_steady_wind_arrives_and_meets_the_premise() -> None:
    """Issue 57's ring: 10 drones, lag 0.3 s, 1.7 m/s. Without the cancellation every drone stayed
    ``c tau |w| / k`` = 0.235 m off; the premise failed on 299 of 300 steps (the plan moved by the
    wind's mean). Now the error is gone, and the plan moves by what the estimate misses: past the
    growth only while the wind's push builds up (5 of 300 steps, the first)."""
    data = ring(2, "lag", "joint", 1.7) | {"simulation": {"dt": 0.1, "duration": 30.0}}
    error_m, m = arrived(data)
    assert error_m < 1e-6
    assert m["growth_exceeded_steps"] <= 10 and m["max_wind_shift"] > 0.0


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("coupling", ["joint", "decoupled"])
@pytest.mark.parametrize(
    "plant", ["lag", "second_order", pytest.param("quadrotor", marks=pytest.mark.slow)]
)  # a quadrotor run takes 4-17 s (its PID cascade at 500 Hz); its integral action alone arrived
@pytest.mark.parametrize("move", [False, True], ids=["hold", "translate"])
def test_a_formation_in_a_steady_wind_arrives_within_two_centimetres(
    dim: int, coupling: str, plant: str, move: bool
) -> None:
    """1 m/s of steady wind: the lag and the second-order loop ended 0.138 m and 0.108 m off (every
    drone, holding or translating) and failed the premise on every step but the first (the
    quadrotor's integral action arrived, failing it on 17); now all arrive to rounding and the premise
    fails on the first 3-5 steps only."""
    if plant == "quadrotor" and not FLIGHT:
        pytest.skip("needs drone-models: pip install -e '.[flight]'")
    n = 6 if plant == "quadrotor" else 10
    error_m, m = arrived(ring(dim, plant, coupling, 1.0, move, n))
    assert error_m <= TOL_M
    assert m["growth_exceeded_steps"] <= 8, m["growth_exceeded_steps"]
