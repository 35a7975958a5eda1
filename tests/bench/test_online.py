"""bench online: the crossing planned online, its step times and deadline misses."""

from __future__ import annotations

from mpcform.bench.online import bench_online, markdown_table


def test_a_small_crossing_meets_its_deadline_and_keeps_d_min() -> None:
    row = bench_online(8, 40, 0.1)
    assert row["deadline_miss_share"] == 0.0 and row["overrun_max_ms"] == 0.0
    assert row["wall_p50_ms"] <= row["wall_p99_ms"] <= row["wall_max_ms"] < 100.0
    assert row["min_distance_m"] >= 0.5 - 1e-9
    assert "largest n with wall p99 < budget and no deadline miss: 8" in markdown_table([row])


def test_an_impossible_deadline_is_missed_and_reported() -> None:
    row = bench_online(8, 20, 1e-9)
    assert row["deadline_miss_share"] > 0.0 and row["overrun_max_ms"] > 0.0
    assert row["min_distance_m"] >= 0.5 - 1e-9  # the braking fallback keeps d_min
    assert markdown_table([row]).endswith("no deadline miss: none")
