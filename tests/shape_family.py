"""A seeded random family through poles and no-fly boxes (slow tests): swaps among poles and flights
across an arena of cylinders, boxes and spheres, on the ideal, lag and quadrotor plants.

Each run draws n 2-9 drones, d_min 0.3-0.6 m, v_max 0.5-2 m/s, dt 0.05-0.1 s, a horizon of 6-12,
both couplings, and 1-4 obstacles (vertical cylinders finite or floor to ceiling, axis-aligned
boxes, spheres) with clearances 0.1-0.3 m or unset (d_min / 2), inside a geofence 1.5 m beyond every
start and goal. Starts and goals keep d_min + 4 delta + 0.1 m (delta: the plant's margin) beyond a
shape's clearance, as in ``completion_family``; a swap's poles stand among its targets, so a draw may
put a goal inside a clearance: the loader must refuse it naming ``obstacles``.
:func:`true_clearances` measures the drones' distance to each shape with its own closed forms, not
the library's.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from completion_family import A_MAX_MPS2, draw_plant, spread

PARTS = ("swap", "crossing")
PLANTS = ("ideal", "lag", "quadrotor")
SEED = 20261207


def scenario(rng: np.random.Generator, index: int) -> dict[str, Any]:
    """Run ``index`` (its part and plant cycled by ``index``)."""
    from mpcform.scenario.load import scenario_from_dict

    part, plant_kind = PARTS[index % 2], PLANTS[(index // 2) % 3]
    dim = int(rng.choice([2, 3]))
    n = int(rng.integers(2, 10)) if plant_kind != "quadrotor" else int(rng.integers(2, 7))
    d_min, dt = float(rng.uniform(0.3, 0.6)), float(rng.choice([0.05, 0.06, 0.08, 0.1]))
    v_max = float(rng.uniform(0.5, 2.0))
    sc: dict[str, Any] = {
        "version": 1,
        "name": f"shapes_{index}_{part}_{plant_kind}",
        "dim": dim,
        "seed": int(rng.integers(1 << 30)),
        "template": {
            "shape": "explicit",
            "offsets": [[i - (n - 1) / 2] + [0.0] * (dim - 1) for i in range(n)],
        },
        "limits": {"v_max": v_max, "d_min": d_min},
        "controller": {
            "kind": "mpc",
            "gain": float(rng.uniform(1.0, 3.0)),
            "horizon": int(rng.integers(6, 13)),
            "coupling": str(rng.choice(["joint", "decoupled"])),
        },
        "simulation": {"dt": dt, "duration": 10.0},
        "reference": {"kind": "constant"},
    }
    plant = draw_plant(rng, plant_kind, dim)
    if plant is not None:
        sc["plant"] = plant
    probe = scenario_from_dict(sc | {"initial": {"centroid": [0.0] * dim}})
    if plant_kind == "quadrotor":
        sc["limits"]["v_max"] = v_max = min(v_max, 0.95 * probe.robustness.valid_speed_mps)
    gap = (d_min + 4.0 * probe.robustness.margin_m + 0.1) * float(rng.uniform(1.0, 1.5))
    offsets = spread(rng, n, dim, gap)
    if part == "swap":  # poles among the targets: every path crosses the centre
        scale = 1.0 + float(rng.uniform(0.5, 1.5))
        offsets *= scale
        start, goal_c = -offsets, np.zeros(dim)
        centers = [rng.uniform(-0.8, 0.8, dim) for _ in range(int(rng.integers(1, 3)))]
    else:  # across an arena: 6-12 m along a horizontal direction
        direction = np.zeros(dim)
        direction[:2] = rng.normal(size=2)
        direction /= np.linalg.norm(direction)
        length = float(rng.uniform(6.0, 12.0))
        start, goal_c = offsets - 0.5 * length * direction, 0.5 * length * direction
        centers = [
            rng.uniform(-0.3, 0.3) * length * direction + rng.uniform(-1.5, 1.5, dim)
            for _ in range(int(rng.integers(1, 5)))
        ]
    goal = goal_c + offsets
    sc["template"]["offsets"] = offsets.tolist()
    sc["initial"] = {"positions": start.tolist()}
    sc["reference"] |= {"centroid": goal_c.tolist(), "rotation": 0.0 if dim == 2 else [0.0] * 3, "scale": 1.0}
    sc["obstacles"] = [obstacle(rng, c, dim) for c in centers]
    sc["obstacles"] = [ob for ob in sc["obstacles"] if fair(ob, start, goal, d_min, gap)]
    if not sc["obstacles"]:
        del sc["obstacles"]
    ends = np.concatenate([start, goal])
    lo, hi = ends.min(axis=0) - 1.5, ends.max(axis=0) + 1.5
    sc["limits"] |= {"geofence_min": lo.tolist(), "geofence_max": hi.tolist()}
    far = float(np.linalg.norm(goal - start, axis=1).max())
    sc["simulation"]["duration"] = round(2.0 * far / v_max + 2.0 * v_max / A_MAX_MPS2 + 15.0, 2)
    return sc


def obstacle(rng: np.random.Generator, center: np.ndarray, dim: int) -> dict[str, Any]:
    """A cylinder, box or sphere about ``center``, its clearance 0.1-0.3 m or unset."""
    kind = str(rng.choice(["cylinder", "cylinder", "box", "box", "sphere"]))
    out: dict[str, Any] = {"shape": kind, "center": center.tolist()}
    if kind == "cylinder":
        out["radius"] = float(rng.uniform(0.1, 0.5))
        if dim == 3 and rng.random() < 0.5:
            out["height"] = float(rng.uniform(1.0, 3.0))
    elif kind == "box":
        out["size"] = rng.uniform(0.2, 1.2, dim).tolist()
    else:
        out["radius"] = float(rng.uniform(0.2, 0.8))
    if rng.random() < 0.7:
        out["clearance"] = float(rng.uniform(0.1, 0.3))
    return out


def surface_distances(ob: dict[str, Any], points: np.ndarray) -> np.ndarray:
    """Signed distance (...,) of points (..., d) to the obstacle's surface, from its keys alone."""
    rel = points - np.asarray(ob["center"])
    if ob["shape"] == "sphere" or (ob["shape"] == "cylinder" and points.shape[-1] == 2):
        return np.linalg.norm(rel, axis=-1) - ob["radius"]
    if ob["shape"] == "box":
        q = np.abs(rel) - 0.5 * np.asarray(ob["size"])
        return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)
    q = np.stack(
        [
            np.linalg.norm(rel[..., :2], axis=-1) - ob["radius"],
            np.abs(rel[..., 2]) - 0.5 * ob.get("height", np.inf),
        ],
        axis=-1,
    )
    return np.linalg.norm(np.maximum(q, 0.0), axis=-1) + np.minimum(q.max(axis=-1), 0.0)


def fair(ob: dict[str, Any], start: np.ndarray, goal: np.ndarray, d_min: float, gap: float) -> bool:
    """Whether the obstacle is kept: every start and goal ``gap`` (d_min + 4 delta + 0.1 m or more)
    beyond its clearance (unset: d_min / 2), as the completion family keeps its spheres, or a goal
    inside the clearance (the loader's refusal to see)."""
    need = ob.get("clearance", 0.5 * d_min)
    to_goal = surface_distances(ob, goal).min()
    return bool(
        surface_distances(ob, start).min() >= need + gap and (to_goal >= need + gap or to_goal < need)
    )


def true_clearances(sc: dict[str, Any], path: np.ndarray, straight: bool) -> tuple[float, int]:
    """The least distance to any surface less its clearance along ``path`` (K, n, d), and the
    (sample, drone, obstacle) below it; ``straight``: the path is straight between its samples
    (sampled 16 times a segment)."""
    if straight:
        t = np.linspace(0.0, 1.0, 16, endpoint=False)[:, None, None, None]
        path = (path[:-1][None] * (1.0 - t) + path[1:][None] * t).reshape(-1, *path.shape[1:])
    worst, breaches = np.inf, 0
    for ob in sc.get("obstacles", []):
        margin = surface_distances(ob, path) - ob.get("clearance", 0.5 * sc["limits"]["d_min"])
        worst, breaches = min(worst, float(margin.min())), breaches + int((margin < -1e-6).sum())
    return worst, breaches


def family(count: int, seed: int = SEED) -> Iterator[dict[str, Any]]:
    """The first ``count`` runs (run ``i`` drawn from its own stream, so a prefix is stable)."""
    for index in range(count):
        yield scenario(np.random.default_rng([seed, index]), index)


def outcome(sc: dict[str, Any]) -> dict[str, Any]:
    """Load and run one scenario dict: a refusal at load (its message), or its completion and the
    violations on the dense true path (the plant's, else the control samples) of separation (pairs
    that start d_min apart), the obstacles' clearances (measured here) and the geofence."""
    from mpcform.errors import ScenarioError
    from mpcform.run.runner import run_scenario
    from mpcform.scenario.load import scenario_from_dict

    start = time.process_time()
    try:
        built = scenario_from_dict(sc)
    except ScenarioError as exc:
        return {"name": sc["name"], "refused": str(exc)}
    run = run_scenario(built)
    m, sim = run.summary["metrics"], run.simulation
    true = "_true" if "min_separation_true" in m else ""
    p = sim.positions_m if sim.true is None else sim.true.positions_m
    clearance, breaches = true_clearances(sc, p, straight=sim.true is None)
    return {
        "name": sc["name"],
        "refused": None,
        "completion": m["completion"],
        "separation_violations": m[f"separation_violations{true}"],
        "obstacle_violations": breaches,
        "library_obstacle_violations": m.get(f"obstacle_violations{true}", 0),
        "min_clearance": clearance,
        "geofence_violations": m[f"geofence_violations{true}"],
        "speed_violations": m["speed_violations"],
        "slack_steps": m["slack_steps"],
        "cpu_s": time.process_time() - start,
    }


def _run(args: tuple[int, int]) -> dict[str, Any]:
    index, seed = args
    return outcome(scenario(np.random.default_rng([seed, index]), index))


def campaign(count: int, seed: int = SEED, workers: int = 2) -> list[dict[str, Any]]:
    """Run the first ``count`` runs on ``workers`` processes."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_run, [(i, seed) for i in range(count)]))
