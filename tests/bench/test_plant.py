"""bench_plant flies the quadrotor plant through its fixed command sequence (times are the bench's to
report, not a test's to assert: the machine is shared)."""

from importlib import metadata

import pytest

from mpcform.sim import so_rpy

try:
    metadata.distribution(so_rpy.DISTRIBUTION)
except metadata.PackageNotFoundError:
    pytest.skip("needs drone-models (pip install 'mpcform[flight]')", allow_module_level=True)

from mpcform.bench.plant import bench_plant  # noqa: E402


def test_bench_counts_the_inner_steps_of_its_flight():
    result = bench_plant(n=20, duration_s=1.0)
    assert result["inner_steps"] == 1.0 * 500 and result["n"] == 20
    assert result["wall_s"] > 0 and result["cpu_s"] > 0


def test_bench_scales_down():
    result = bench_plant(n=2, duration_s=0.5, rate_hz=200.0, wind=False)
    assert result["inner_steps"] == 100


def test_run_reports_one_row_with_wall_and_cpu():
    from mpcform.bench.plant import markdown_table, run

    rows = run(n=3, duration_s=0.4, rate_hz=100.0, repeats=2, wind=False)
    assert len(rows) == 1 and rows[0]["inner_steps"] == 40 and rows[0]["wind"] == "none"
    assert float(rows[0]["cpu_med_s"]) > 0 and float(rows[0]["real_time"]) > 0
    assert markdown_table(rows).splitlines()[0].startswith("| drones |")
