"""The ordinary-day family: seeded random runs as broad as the settings users fly.

Each run draws, independently: the part (planar and spatial swaps, formations, spheres, missions,
close starts: :mod:`completion_family`), 2-30 drones, the plant (ideal, lag, second order,
quadrotor, cycled), dt 0.05-0.1 s (in steps of 0.01 s), the horizon 3-30 (log-uniform), ``a_max``
0.2 m/s^2 to the default (log-uniform; the default itself in a quarter of the runs), ``v_max``
0.5-4 m/s (a
quadrotor's below the valid speed of its margin), a steady wind of 0-2 m/s with gusts on every
plant but the ideal one, the coupling and the velocity set, and a geofence around the flight in
a third of the runs. The duration is twice the longest straight-line travel at the velocity set's
slowest speed, plus the time to speed up and brake at the drawn ``a_max``, the reference's own
time and 10 s. A run the loader refuses (a wind no margin covers, a quadrotor speed past its valid
speed) is counted with its reason, not flown.

``python tests/broad_family.py [COUNT] [--seed S] [--workers W]`` runs a campaign on ``W`` processes
(2), prints one line per run to stderr as it ends (its name, completion, violations, CPU), then the
counts per plant and coupling, the refusals and every failure.
"""

from __future__ import annotations

import sys
from collections import Counter
from typing import Any

import numpy as np
from completion_family import A_MAX_MPS2, PARTS, PLANTS, _zero, outcome, placed, report

SEED = 20261207
DT_S = (0.05, 0.06, 0.07, 0.08, 0.09, 0.1)  # multiples of the quadrotor's 2 ms inner step
FENCE_SHARE = 1.0 / 3.0
FENCE_ROOM_M = 1.0  # the fence's distance from the flight's bounding box [m]


def _log_uniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _plant(rng: np.random.Generator, kind: str, dim: int) -> dict[str, Any] | None:
    """The plant of ``kind`` with a steady wind of 0-2 m/s (horizontal) and gusts, None: ideal."""
    if kind == "ideal":
        return None
    mean = np.zeros(dim)
    mean[:2] = rng.normal(size=2)
    mean *= rng.uniform(0.0, 2.0) / max(float(np.linalg.norm(mean)), 1e-9)
    wind = {"mean": mean.tolist(), "gust_std": float(rng.uniform(0.0, 0.5)), "gust_time": 1.0}
    if kind == "lag":
        return {"kind": "lag", "time_constant": float(rng.choice([0.1, 0.2, 0.3])), "wind": wind}
    if kind == "second_order":
        return {"kind": "second_order", "damping": float(rng.uniform(0.6, 1.0)), "wind": wind}
    return {"kind": "quadrotor", "wind": wind}


def scenario(rng: np.random.Generator, index: int) -> dict[str, Any]:
    """Run ``index`` of the family (its plant cycled by ``index``, every other draw random)."""

    part, plant_kind = PARTS[int(rng.integers(len(PARTS)))], PLANTS[index % len(PLANTS)]
    dim = 2 if part == "swap_planar" else 3 if part == "swap_spatial" else int(rng.choice([2, 3]))
    n = max(3 if part == "close_start" else 2, int(_log_uniform(rng, 2.0, 30.99)))
    d_min, dt = float(rng.uniform(0.3, 0.7)), float(rng.choice(DT_S))
    a_max = A_MAX_MPS2 if rng.random() < 0.25 else _log_uniform(rng, 0.2, A_MAX_MPS2)
    v_max = _log_uniform(rng, 0.5, 4.0)
    sc: dict[str, Any] = {
        "version": 1,
        "name": f"broad_{index}_{part}_{plant_kind}",
        "dim": dim,
        "seed": int(rng.integers(1 << 30)),
        "template": {
            "shape": "explicit",
            "offsets": [[i - (n - 1) / 2] + [0.0] * (dim - 1) for i in range(n)],
        },
        "limits": {"v_max": v_max, "d_min": d_min, "a_max": a_max},
        "controller": {
            "kind": "mpc",
            "gain": float(rng.uniform(1.0, 3.0)),
            "horizon": int(_log_uniform(rng, 3.0, 30.99)),
            "coupling": str(rng.choice(["joint", "decoupled"])),
            "velocity_set": str(rng.choice(["polytope", "box"])),
        },
        "simulation": {"dt": dt, "duration": 10.0},
        "initial": {"centroid": [0.0] * dim, "rotation": _zero(dim), "scale": 1.0},
        "reference": {"kind": "constant"},
    }
    if (plant := _plant(rng, plant_kind, dim)) is not None:
        sc["plant"] = plant
    fence = FENCE_ROOM_M if rng.random() < FENCE_SHARE else None
    return placed(rng, sc, part, plant_kind, a_max, fence)


def drawn(index: int, seed: int = SEED) -> dict[str, Any] | str:
    """Run ``index``'s scenario dict, or the reason it was refused (the loader's error)."""
    from mpcform.errors import MPCFormError
    from mpcform.scenario.load import scenario_from_dict

    try:
        sc = scenario(np.random.default_rng([seed, index]), index)
        scenario_from_dict(sc)
    except MPCFormError as err:
        return str(err)
    return sc


def _run(args: tuple[int, int]) -> dict[str, Any]:
    sc = drawn(*args)
    if isinstance(sc, str):
        return {"name": f"broad_{args[0]}", "refused": sc}
    return outcome(sc) | {"refused": None}


def _line(result: dict[str, Any]) -> str:
    if result["refused"]:
        return f"{result['name']}: refused ({result['refused']})"
    flown = f"completion {result['completion']:.2f}, {result['violations']} violations"
    return f"{result['name']} (n {result['n']}, {result['coupling']}): {flown}, {result['cpu_s']:.1f} s CPU"


def campaign(count: int, seed: int = SEED, workers: int = 2, progress: bool = False) -> list[dict[str, Any]]:
    """Run the first ``count`` runs on ``workers`` processes (``progress``: a line per run to stderr)."""
    from concurrent.futures import ProcessPoolExecutor

    results = []
    with ProcessPoolExecutor(workers) as pool:
        for result in pool.map(_run, [(i, seed) for i in range(count)]):
            results.append(result)
            if progress:
                print(f"[{len(results)}/{count}] {_line(result)}", file=sys.stderr, flush=True)
    return results


def refusals(results: list[dict[str, Any]]) -> str:
    """The refused runs' count per reason (the error's field)."""
    reasons = Counter(r["refused"].split(":")[0] for r in results if r["refused"])
    return ", ".join(f"{field}: {count}" for field, count in reasons.most_common()) or "none"


if __name__ == "__main__":
    count = int(sys.argv[1]) if len(sys.argv) > 1 and not sys.argv[1].startswith("-") else 60
    seed = int(sys.argv[sys.argv.index("--seed") + 1]) if "--seed" in sys.argv else SEED
    workers = int(sys.argv[sys.argv.index("--workers") + 1]) if "--workers" in sys.argv else 2
    results = campaign(count, seed, workers, progress=True)
    flown = [r for r in results if not r["refused"]]
    print(f"{len(results) - len(flown)} of {len(results)} refused ({refusals(results)})")
    print(report(flown))
