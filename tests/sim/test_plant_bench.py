"""bench_plant: 20 quadrotors for 12 s at 500 Hz within 10 s of wall time on the 2-core machine."""

from importlib import metadata

import pytest

from mpcform.sim import so_rpy

try:
    metadata.distribution(so_rpy.DISTRIBUTION)
except metadata.PackageNotFoundError:
    pytest.skip("needs drone-models (pip install 'mpcform[flight]')", allow_module_level=True)

from mpcform.sim.plant_bench import bench_plant  # noqa: E402


def test_default_bench_is_within_its_budget():
    result = bench_plant()
    assert result["inner_steps"] == 12 * 500
    assert result["wall_s"] <= 10.0, result
    assert result["cpu_s"] <= 10.0, result


def test_bench_scales_down():
    result = bench_plant(n=2, duration_s=0.5, rate_hz=200.0, wind=False)
    assert result["inner_steps"] == 100
