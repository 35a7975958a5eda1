"""Seeded random scenario families (scenario dicts, as parsed TOML) for the closed-loop invariants.

Parts: planar swaps (antipodal rings and random permutations, n 2-32), spatial swaps (n 4-24),
fields of 1-6 spheres between start and goal, and close starts (1-3 pairs at 0.2-0.9 d_min).
v_max 0.5-2 m/s, d_min 0.3-0.7 m, dt 0.1 s, horizon 8-15, both couplings; the duration is
2 x (longest straight-line distance / v_max) + 10 s.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np
from scipy.spatial.distance import pdist

KINDS = ("swap_planar", "swap_spatial", "spheres", "close_start")
DT_S = 0.1


def _spread(rng: np.random.Generator, n: int, dim: int, d_min: float) -> np.ndarray:
    """n centred random offsets at least 1.5 d_min apart (rejection sampling in a growing box)."""
    side = max(1.0, 1.6 * d_min * n ** (1.0 / dim))
    while True:
        pts = rng.uniform(-side, side, (n, dim))
        if n < 2 or pdist(pts).min() >= 1.5 * d_min:
            return pts - pts.mean(axis=0)
        side *= 1.05


def _base(rng: np.random.Generator, name: str, dim: int, offsets: np.ndarray, d_min: float) -> dict[str, Any]:
    return {
        "version": 1,
        "name": name,
        "dim": dim,
        "seed": int(rng.integers(1000)),
        "template": {"shape": "explicit", "offsets": offsets.tolist()},
        "limits": {"v_max": float(rng.uniform(0.5, 2.0)), "d_min": d_min},
        "controller": {
            "kind": "mpc",
            "gain": 1.0,
            "horizon": int(rng.integers(8, 16)),
            "coupling": str(rng.choice(["joint", "decoupled"])),
        },
        "simulation": {"dt": DT_S},
    }


def _finish(sc: dict[str, Any], start: np.ndarray, goal: np.ndarray) -> dict[str, Any]:
    sc["initial"] = {"positions": start.tolist()}
    far = float(np.linalg.norm(goal - start, axis=1).max())
    sc["simulation"]["duration"] = round(2.0 * far / sc["limits"]["v_max"] + 10.0, 3)
    return sc


def swap_planar(rng: np.random.Generator, index: int) -> dict[str, Any]:
    n, d_min = int(rng.integers(2, 33)), float(rng.uniform(0.3, 0.7))
    if rng.random() < 0.5:  # antipodal ring: every path crosses the centre
        radius = max(1.5, 0.8 * d_min * n / np.pi)
        angle = 2 * np.pi * np.arange(n) / n
        offsets = radius * np.column_stack([np.cos(angle), np.sin(angle)])
        start = -offsets
    else:
        offsets = _spread(rng, n, 2, d_min)
        start = offsets[rng.permutation(n)]
    sc = _base(rng, f"swap_planar_{index}", 2, offsets, d_min)
    sc["reference"] = {"kind": "constant", "centroid": [0.0, 0.0], "rotation": 0.0, "scale": 1.0}
    return _finish(sc, start, offsets)


def swap_spatial(rng: np.random.Generator, index: int) -> dict[str, Any]:
    n, d_min = int(rng.integers(4, 25)), float(rng.uniform(0.3, 0.7))
    offsets = _spread(rng, n, 3, d_min)
    start = -offsets if rng.random() < 0.5 else offsets[rng.permutation(n)]
    sc = _base(rng, f"swap_spatial_{index}", 3, offsets, d_min)
    sc["reference"] = {
        "kind": "constant",
        "centroid": [0.0, 0.0, 0.0],
        "rotation": [0.0, 0.0, 0.0],
        "scale": 1.0,
    }
    return _finish(sc, start, offsets)


def spheres(rng: np.random.Generator, index: int) -> dict[str, Any] | None:
    """A formation flying 8-16 m through 1-6 spheres; None when a draw breaks the family's rules."""
    dim = int(rng.choice([2, 3]))
    n, d_min = int(rng.integers(2, 9)), float(rng.uniform(0.3, 0.7))
    offsets = _spread(rng, n, dim, d_min)
    direction = rng.normal(size=dim)
    direction /= np.linalg.norm(direction)
    length = float(rng.uniform(8.0, 16.0))
    goal_c, start_c = 0.5 * length * direction, -0.5 * length * direction
    start, goal = start_c + offsets, goal_c + offsets
    obstacles = []
    for _ in range(int(rng.integers(1, 7))):
        center = rng.uniform(-0.35, 0.35) * length * direction + rng.uniform(-2.0, 2.0, dim)
        radius, clearance = float(rng.uniform(0.3, 1.2)), float(rng.uniform(0.1, 0.3))
        keep_out = radius + clearance + d_min
        if (
            min(np.linalg.norm(start - center, axis=1).min(), np.linalg.norm(goal - center, axis=1).min())
            < keep_out
        ):
            return None
        obstacles.append({"center": center.tolist(), "radius": radius, "clearance": clearance})
    sc = _base(rng, f"spheres_{index}", dim, offsets, d_min)
    zero = 0.0 if dim == 2 else [0.0, 0.0, 0.0]
    sc["reference"] = {"kind": "constant", "centroid": goal_c.tolist(), "rotation": zero, "scale": 1.0}
    sc["obstacles"] = obstacles
    return _finish(sc, start, goal)


def close_pairs(rng: np.random.Generator, offsets: np.ndarray, d_min: float) -> np.ndarray:
    """Starts (n, d): ``offsets`` with 1-3 drones moved to 0.2-0.9 ``d_min`` from another."""
    n, dim = offsets.shape
    start = offsets.copy()
    movers = rng.choice(n, size=2 * min(int(rng.integers(1, 4)), n // 2), replace=False).reshape(-1, 2)
    for i, k in movers:
        direction = rng.normal(size=dim)
        start[i] = start[k] + rng.uniform(0.2, 0.9) * d_min * direction / np.linalg.norm(direction)
    return start


def close_start(rng: np.random.Generator, index: int) -> dict[str, Any]:
    """A formation (planar or spatial) whose start holds 1-3 pairs at 0.2-0.9 d_min."""
    dim = int(rng.choice([2, 3]))
    n, d_min = int(rng.integers(3, 13)), float(rng.uniform(0.3, 0.7))
    offsets = _spread(rng, n, dim, d_min)
    start = close_pairs(rng, offsets, d_min)
    shift = rng.uniform(-3.0, 3.0, dim)
    sc = _base(rng, f"close_start_{index}", dim, offsets, d_min)
    zero = 0.0 if dim == 2 else [0.0, 0.0, 0.0]
    sc["reference"] = {"kind": "constant", "centroid": shift.tolist(), "rotation": zero, "scale": 1.0}
    return _finish(sc, start, offsets + shift)


def family(seed: int, count: int) -> Iterator[dict[str, Any]]:
    """``count`` scenarios cycling through the parts (sphere draws that break the rules redrawn)."""
    rng = np.random.default_rng(seed)
    makers = {
        "swap_planar": swap_planar,
        "swap_spatial": swap_spatial,
        "spheres": spheres,
        "close_start": close_start,
    }
    made = 0
    while made < count:
        kind = KINDS[made % len(KINDS)]
        sc = makers[kind](rng, made)
        if sc is not None:
            made += 1
            yield sc


CLOSE_START_FREEZE: dict[str, Any] = {  # froze before close starts had their hard no-approach rows
    "version": 1,
    "name": "close_start_freeze",
    "dim": 2,
    "seed": 13,
    "template": {
        "shape": "explicit",
        "offsets": [
            [-0.9868547022787612, -0.5404046729473696],
            [-0.3845822424615776, -1.5829725384194102],
            [0.6385811673742307, -1.4570827785874187],
            [-1.441396278938159, 1.1408983667071637],
            [-0.1381720912265597, 1.10830619552998],
            [1.5747326245724236, -0.490351987473142],
            [0.737691522958403, 1.821607415190197],
        ],
    },
    "initial": {
        "positions": [
            [0.5842413546223961, 1.6079380233859193],
            [-0.3845822424615776, -1.5829725384194102],
            [0.6385811673742307, -1.4570827785874187],
            [-1.441396278938159, 1.1408983667071637],
            [-0.1381720912265597, 1.10830619552998],
            [0.14957701754708363, 1.3558148428083334],
            [0.737691522958403, 1.821607415190197],
        ]
    },
    "reference": {
        "kind": "constant",
        "centroid": [1.7625682249254604, 1.237208044722145],
        "rotation": 0.0,
        "scale": 1.0,
    },
    "limits": {"v_max": 1.0449597951536984, "d_min": 0.60699788707885},
    "controller": {"kind": "mpc", "gain": 2.0, "horizon": 8, "coupling": "decoupled"},
    "simulation": {"dt": 0.1, "duration": 27.666075437319197},
}


def outcome(sc: dict[str, Any], tol_m: float = 0.1) -> dict[str, Any]:
    """Run a scenario dict and measure what every run must meet: ``completion`` (fraction of drones
    within ``tol_m`` of their targets at the end), ``separation_violations`` (pairs that start at
    least d_min apart and come closer along a segment), ``approached`` / ``unseparated`` (pairs that
    start inside d_min and get closer along a segment / are not d_min apart at the end),
    ``obstacle_violations`` (drones inside a sphere's keep-out along a segment), and the run's
    ``infos``."""
    from mpcform.run.runner import run_scenario
    from mpcform.scenario.load import scenario_from_dict
    from mpcform.world.closest import closest_on_segments

    s = scenario_from_dict(sc)
    res = run_scenario(s).simulation
    p, d_min, tol = res.positions_m, s.limits.d_min_m or 0.0, 1e-6
    err = np.linalg.norm(p[-1] - res.reference_m[-1], axis=1)
    i, k = np.triu_indices(p.shape[1], 1)
    rel = p[:, i] - p[:, k]  # (T, P, d)
    pairs = zip(rel[:-1], rel[1:], strict=True)
    seg = np.array([np.linalg.norm(closest_on_segments(a, b), axis=1) for a, b in pairs])
    start = np.linalg.norm(rel[0], axis=1)
    close = start < d_min
    seg_min = seg.min(axis=0, initial=np.inf) if seg.size else start
    out = {
        "completion": float((err <= tol_m).mean()),
        "separation_violations": int((seg[:, ~close] < d_min - tol).sum()),
        "approached": int((seg_min[close] < start[close] - tol).sum()),
        "unseparated": int((np.linalg.norm(rel[-1], axis=1)[close] < d_min - tol).sum()),
        "obstacle_violations": 0,
        "infos": res.infos,
    }
    for ob in sc.get("obstacles", []):
        c, req = np.array(ob["center"]), ob["radius"] + ob["clearance"]
        steps = zip(p[:-1], p[1:], strict=True)
        gaps = [np.linalg.norm(closest_on_segments(a - c, b - c), axis=1) for a, b in steps]
        out["obstacle_violations"] += int((np.array(gaps) < req - tol).sum())
    return out


def _summary(sc: dict[str, Any]) -> dict[str, Any]:
    out = outcome(sc)
    out["finite_times"] = all(np.isfinite(info.solve_time_s) for info in out.pop("infos"))
    return out


def outcomes(scenarios: list[dict[str, Any]], workers: int = 2) -> list[dict[str, Any]]:
    """:func:`outcome` of each scenario on ``workers`` processes, in order; each run's ``infos``
    replaced by ``finite_times`` (whether every step's solve time is finite)."""
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(workers) as pool:
        return list(pool.map(_summary, scenarios))


def adversarial(rng: np.random.Generator, index: int) -> dict[str, Any]:
    """2-4 drones head-on or crossing, planar or spatial, with hard limits: ``a_max`` 0.2-2 m/s^2,
    ``v_max`` 0.5-8 m/s (a quadrotor's 0.3-1.5, below its valid speed), horizon 5-30 at dt
    0.05-0.1, a lag up to 0.3 s, a second-order loop or the quadrotor in gusts at their bound, and a
    corridor (geofence) or a sphere in the way. The braking terminal condition's family
    (:mod:`mpcform.mpc.constraints.braking`)."""
    dim, n = int(rng.choice([2, 3])), int(rng.integers(2, 5))
    d_min, dt = float(rng.uniform(0.3, 0.6)), float(rng.choice([0.05, 0.1]))
    plant_kind = str(rng.choice(["lag", "lag", "second_order", "quadrotor"]))
    v_max = float(
        rng.uniform(0.3, 1.5) if plant_kind == "quadrotor" else np.exp(rng.uniform(np.log(0.5), np.log(8.0)))
    )
    radius = max(2.0, 1.5 * v_max)
    angle = 2 * np.pi * np.arange(n) / n + rng.uniform(0, 2 * np.pi)
    start = np.zeros((n, dim))
    start[:, 0], start[:, 1] = radius * np.cos(angle), radius * np.sin(angle)
    crossing = rng.random() < 0.5  # else head-on: every drone to its antipode
    goal = np.roll(start, 1, axis=0) if crossing else -start
    if dim == 3:
        start[:, 2], goal[:, 2] = 1.5, 1.5 + rng.uniform(-0.5, 0.5)
    sc: dict[str, Any] = {
        "version": 1,
        "name": f"adversarial_{index}",
        "dim": dim,
        "seed": int(rng.integers(1000)),
        "template": {"shape": "explicit", "offsets": (goal - goal.mean(axis=0)).tolist()},
        "reference": {
            "kind": "constant",
            "centroid": goal.mean(axis=0).tolist(),
            "rotation": 0.0 if dim == 2 else [0.0, 0.0, 0.0],
            "scale": 1.0,
        },
        "limits": {"v_max": v_max, "d_min": d_min, "a_max": float(rng.uniform(0.2, 2.0))},
        "controller": {
            "kind": "mpc",
            "gain": float(rng.uniform(1.0, 3.0)),
            "horizon": int(rng.integers(5, 31)),
            "coupling": str(rng.choice(["joint", "decoupled"])),
        },
        "simulation": {"dt": dt},
    }
    if plant_kind == "lag":
        sc["plant"] = {"kind": "lag", "time_constant": float(rng.uniform(0.05, 0.3))}
    elif plant_kind == "second_order":
        sc["plant"] = {"kind": "second_order", "damping": float(rng.uniform(0.6, 1.0))}
    else:
        wind = np.zeros(dim)
        wind[0] = rng.uniform(0.0, 0.5)
        std = float(rng.uniform(0.05, 0.2))
        sc["plant"] = {
            "kind": "quadrotor",
            "wind": {"mean": wind.tolist(), "gust_std": std, "gust_bound": std},
        }
    extra = rng.random()
    if extra < 0.3:  # a corridor around the swap: the drones must pass inside it
        half = radius + 1.0
        lo, hi = [-half] * dim, [half] * dim
        lo[1], hi[1] = -radius - 0.3, radius + 0.3
        if dim == 3:
            lo[2], hi[2] = 0.5, 3.0
        sc["limits"] |= {"geofence_min": lo, "geofence_max": hi}
    elif extra < 0.6:  # a sphere off the centre, in the way of some of the paths
        c = np.zeros(dim)
        c[:2] = rng.uniform(-0.3, 0.3, 2) * radius
        if dim == 3:
            c[2] = 1.5
        sc["obstacles"] = [{"center": c.tolist(), "radius": float(rng.uniform(0.2, 0.5))}]
    return _finish(sc, start, goal)


ADVERSARIAL_SEED = 20261203


def adversarial_outcome(index: int) -> dict[str, Any]:
    """Run adversarial scenario ``index``: ``refused`` (the error's text) or its breaches along the
    dense true path (pairs closer than d_min, drones inside an obstacle's clearance or outside the
    fence, commands changing by more than ``a_max dt + 1e-9``), with its slack and lowered steps."""
    from mpcform.errors import MPCFormError
    from mpcform.run.runner import run_scenario
    from mpcform.scenario.load import scenario_from_dict

    sc = adversarial(np.random.default_rng([ADVERSARIAL_SEED, index]), index)
    try:
        scenario = scenario_from_dict(sc)
    except MPCFormError as exc:
        return {"index": index, "refused": str(exc)}
    run = run_scenario(scenario)
    m, u = run.summary["metrics"], run.simulation.commands_mps
    steps = np.abs(np.diff(np.concatenate([np.zeros((1,) + u.shape[1:]), u]), axis=0))
    return {
        "index": index,
        "refused": None,
        "separation": m["separation_violations_true"],
        "obstacle": m.get("obstacle_violations_true") or 0,
        "geofence": m["geofence_violations_true"],
        "jumps": int((steps > sc["limits"]["a_max"] * sc["simulation"]["dt"] + 1e-9).sum()),
        "slack_steps": m["slack_steps"],
        "growth_slack_steps": m["growth_slack_steps"],
        "lowered": m["lowered_first_rows"],
    }
