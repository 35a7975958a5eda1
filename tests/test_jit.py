"""The compiled kernels' switch (:mod:`mpcform._jit`): with numba and without, the same plans.

Flown both ways on bundled scenarios that build every kernel's rows (decoupled pairs, braking
stop splits, a velocity loop, obstacles, growth in wind): commands and positions within 1e-9 and
every integer metric equal."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

from mpcform import _jit
from mpcform.mpc.constraints import kernels
from mpcform.run.runner import run_scenario
from mpcform.scenario.load import scenario_from_dict

pytest.importorskip("numba")
SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


def _run(name: str, changes: dict[str, dict[str, object]], seconds: float):
    data = tomllib.loads((SCENARIOS / name).read_text())
    for table, values in changes.items():
        data.setdefault(table, {}).update(values)
    data["simulation"]["duration"] = seconds
    return run_scenario(scenario_from_dict(data))


@pytest.mark.parametrize(
    ("name", "changes", "seconds"),
    [
        ("swap_planar_8.toml", {"controller": {"coupling": "decoupled"}}, 6.0),
        ("swap_spatial_20.toml", {"controller": {"coupling": "decoupled"}}, 4.0),
        ("poles_box_planar.toml", {"controller": {"coupling": "decoupled"}}, 5.0),
        ("swap_spatial_12_quadrotor_wind.toml", {"controller": {"coupling": "decoupled"}}, 4.0),
    ],
)
def test_kernels_fly_the_numpy_plans(
    monkeypatch: pytest.MonkeyPatch, name: str, changes: dict[str, dict[str, object]], seconds: float
) -> None:
    kernels.warm_up()
    monkeypatch.setattr(_jit, "USE", False)
    plain = _run(name, changes, seconds)
    monkeypatch.setattr(_jit, "USE", True)
    fast = _run(name, changes, seconds)
    a, b = plain.simulation, fast.simulation
    np.testing.assert_allclose(b.commands_mps, a.commands_mps, rtol=0.0, atol=1e-9)
    np.testing.assert_allclose(b.positions_m, a.positions_m, rtol=0.0, atol=1e-9)
    ints = {k: v for k, v in plain.summary["metrics"].items() if isinstance(v, int)}
    assert ints and ints == {k: fast.summary["metrics"][k] for k in ints}
    modes = [i.mode for i in a.infos]
    assert modes == [i.mode for i in b.infos] and "qp" in modes  # the kernels' rows were built


def test_without_numba_the_decorator_returns_the_function(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_jit, "AVAILABLE", False)

    def f(x: float) -> float:
        return 2.0 * x

    assert _jit.njit(f) is f


def test_a_large_swarms_planner_loads_the_kernels(monkeypatch: pytest.MonkeyPatch) -> None:
    from mpcform.bench.scale_cases import DT_S, LIMITS, make_case
    from mpcform.mpc.planner import MPCPlanner
    from mpcform.mpc.settings import MPCSettings

    monkeypatch.setattr(_jit, "USE", False)
    ref, _ = make_case("formation", _jit.MIN_DRONES - 1)
    MPCPlanner(ref, DT_S, LIMITS, MPCSettings(coupling="decoupled"))
    assert not _jit.USE  # a small swarm's planner never imports numba
    ref, _ = make_case("formation", _jit.MIN_DRONES)
    MPCPlanner(ref, DT_S, LIMITS, MPCSettings(coupling="decoupled"))
    assert _jit.USE
