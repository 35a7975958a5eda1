"""Speed of the quadrotor plant: n drones flown through a fixed command sequence."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from mpcform.outputs import tables
from mpcform.sim.quadrotor import QuadrotorPlant, QuadrotorSpec
from mpcform.sim.wind import Wind


def bench_plant(
    n: int = 20,
    duration_s: float = 12.0,
    rate_hz: float = QuadrotorSpec.rate_hz,
    *,
    dt_s: float = 0.1,
    wind: bool = True,
) -> dict[str, float]:
    """Fly ``n`` drones (d = 3) for ``duration_s`` at control interval ``dt_s``; wall and CPU seconds.

    Commands: each drone turns a circle of 1 m/s in the horizontal plane (phase spread over the
    drones) with a 0.3 m/s vertical sine; wind (mean 1 m/s along x, gusts 0.5 m/s, 1 s) when
    ``wind``. The model parameters are loaded before the clock starts.
    """
    spec = QuadrotorSpec(rate_hz=rate_hz)
    gusts = Wind(np.array([1.0, 0.0, 0.0]), gust_std_mps=0.5, gust_time_s=1.0) if wind else None
    plant = QuadrotorPlant(n, 3, spec, wind=gusts, seed=0)
    steps = int(round(duration_s / dt_s))
    phase = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    t = dt_s * np.arange(steps)[:, None]
    commands = np.stack(
        [np.cos(0.5 * t + phase), np.sin(0.5 * t + phase), 0.3 * np.sin(1.0 * t + phase)], axis=-1
    )
    plant.reset(np.column_stack([np.cos(phase), np.sin(phase), np.ones(n)]) * 2.0)
    wall, cpu = time.perf_counter(), time.process_time()
    for u in commands:
        plant.advance(u, dt_s)
    return {
        "n": float(n),
        "duration_s": float(duration_s),
        "inner_steps": float(steps * plant.steps_per_interval(dt_s)),
        "wall_s": time.perf_counter() - wall,
        "cpu_s": time.process_time() - cpu,
    }


COLUMNS = (
    ("n", "drones", "{:.0f}"),
    ("duration_s", "flight [s]", "{:g}"),
    ("rate_hz", "rate [Hz]", "{:g}"),
    ("inner_steps", "inner steps", "{:.0f}"),
    ("wind", "wind", "{}"),
    ("wall_med_s", "wall med [s]", "{:.2f}"),
    ("wall_max_s", "wall max [s]", "{:.2f}"),
    ("cpu_med_s", "CPU med [s]", "{:.2f}"),
    ("cpu_max_s", "CPU max [s]", "{:.2f}"),
    ("real_time", "x real time (CPU)", "{:.1f}"),
)


def run(
    n: int,
    duration_s: float,
    rate_hz: float,
    repeats: int,
    *,
    wind: bool = True,
    progress: Callable[[str, int, int], None] | None = None,
) -> list[dict[str, object]]:
    """``repeats`` runs of :func:`bench_plant`; one row with wall and CPU medians and maxima;
    ``progress(label, i, n)`` is called as run ``i`` of ``n`` starts."""
    runs = []
    for i in range(1, max(1, repeats) + 1):
        if progress is not None:
            progress(f"run, {n} drones x {duration_s:g} s at {rate_hz:g} Hz", i, max(1, repeats))
        runs.append(bench_plant(n, duration_s, rate_hz, wind=wind))
    wall, cpu = (np.array([r[k] for r in runs]) for k in ("wall_s", "cpu_s"))
    row: dict[str, object] = {"n": n, "duration_s": duration_s, "rate_hz": rate_hz}
    row |= {"inner_steps": runs[0]["inner_steps"], "wind": "gusts" if wind else "none"}
    row |= {"wall_med_s": float(np.median(wall)), "wall_max_s": float(wall.max())}
    row |= {"cpu_med_s": float(np.median(cpu)), "cpu_max_s": float(cpu.max())}
    row["real_time"] = duration_s / float(np.median(cpu))
    return [row]


def markdown_table(rows: list[dict[str, object]]) -> str:
    """The rows of :func:`run` as a markdown table."""
    return tables.markdown_table(rows, COLUMNS)
